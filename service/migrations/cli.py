"""``hockle db`` (and ``python -m service.migrations``): the registry's schema migrations,
for operators who migrate explicitly (``HOCKLE_AUTO_MIGRATE=false``) and for developers who
write the next revision.

    hockle db current              the revision the registry is at, and the code's head
    hockle db upgrade [REVISION]   upgrade (default: to head), under the migration lock
    hockle db downgrade REVISION   downgrade (e.g. to the revision before), same lock
    hockle db check                exit 1 unless at head with models and schema agreeing
    hockle db history              the revisions, oldest first
    hockle db revision -m MESSAGE [--autogenerate]   write a new revision file

The registry is the settings' (``HOCKLE_DATABASE_URL``, default the SQLite file under
``HOCKLE_DATA_DIR``) unless ``--url`` names one. Exit status 0 ok, 1 failed or not current.
"""
from __future__ import annotations

import argparse
import sys

from sqlalchemy.exc import SQLAlchemyError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--url", default=None, metavar="URL",
                        help="registry URL (default: HOCKLE_DATABASE_URL, or the SQLite file "
                        "under HOCKLE_DATA_DIR)")
    sub = parser.add_subparsers(dest="db_command", metavar="ACTION", required=True)
    sub.add_parser("current", help="the revision the registry is at, and the code's head")
    p = sub.add_parser("upgrade", help="upgrade the registry (default: to head)")
    p.add_argument("revision", nargs="?", default="head")
    p = sub.add_parser("downgrade", help="downgrade the registry to REVISION (-1: one back)")
    p.add_argument("revision")
    sub.add_parser("check", help="exit 1 unless the registry is at head and agrees with the "
                   "models (autogenerate finds nothing)")
    sub.add_parser("history", help="the revisions, oldest first")
    p = sub.add_parser("revision", help="write a new revision file into "
                       "service/migrations/versions/ (developers)")
    p.add_argument("-m", "--message", required=True)
    p.add_argument("--autogenerate", action="store_true",
                   help="fill it with the differences between the models and the registry "
                   "(which must be at head); read and edit it before committing")


def _registry_url(args: argparse.Namespace) -> str:
    if args.url:
        url = args.url
        if url.startswith(("postgresql://", "postgres://")):
            url = "postgresql+psycopg://" + url.split("://", 1)[1]
        return url
    from service.settings import get_settings

    settings = get_settings()
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    return settings.registry_url


def run(args: argparse.Namespace) -> int:
    from service import migrations as m

    out = sys.stdout
    try:
        url = _registry_url(args)
        shown = m._safe(url)
        action = args.db_command
        if action == "current":
            have, want = m.current(url), m.head()
            state = "at head" if have == want else "behind: run `hockle db upgrade`"
            print(f"{shown}: {have or '(no revision)'}; head {want} ({state})", file=out)
            return 0
        if action == "upgrade":
            before = m.current(url)
            m.upgrade(url, args.revision)
            print(f"{shown}: {before or '(no revision)'} -> {m.current(url)}", file=out)
            return 0
        if action == "downgrade":
            before = m.current(url)
            m.downgrade(url, args.revision)
            print(f"{shown}: {before or '(no revision)'} -> {m.current(url) or '(base)'}",
                  file=out)
            return 0
        if action == "check":
            have, want = m.current(url), m.head()
            if have != want:
                print(f"{shown}: at {have or '(no revision)'}, head is {want}: run "
                      "`hockle db upgrade`", file=out)
                return 1
            diffs = m.check(url)
            for diff in diffs:
                print(f"  differs from the models: {diff!r}", file=out)
            print(f"{shown}: at head {want}; " + (
                "models and schema agree" if not diffs else
                f"{len(diffs)} difference(s): write a revision (hockle db revision "
                "--autogenerate -m ...)"), file=out)
            return 0 if not diffs else 1
        if action == "history":
            for script in reversed(list(m._script().walk_revisions())):
                print(f"{script.revision}  {script.doc.splitlines()[0] if script.doc else ''}",
                      file=out)
            return 0
        if action == "revision":
            from alembic import command

            script = command.revision(m.alembic_config(url=url), message=args.message,
                                      autogenerate=args.autogenerate)
            print(f"wrote {script.path}" if script is not None else "no revision written",
                  file=out)
            return 0
    except SQLAlchemyError as exc:
        where = "--url" if args.url else "HOCKLE_DATABASE_URL"
        print(f"hockle db {args.db_command}: the registry ({where}) failed: "
              f"{type(exc).__name__}: {exc}".splitlines()[0], file=sys.stderr)
        return 1
    raise AssertionError(args.db_command)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m service.migrations", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    return run(parser.parse_args(argv))
