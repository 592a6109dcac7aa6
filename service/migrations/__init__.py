"""Schema migrations of the job registry (Alembic), configured from hockle's settings.

The registry's schema is defined by the models in :mod:`service.registry` and brought to them
by the revisions in ``service/migrations/versions/``. No ``alembic.ini`` is needed: the Alembic
configuration is built here, with the registry URL of the settings (``HOCKLE_DATABASE_URL``,
default the SQLite file under ``HOCKLE_DATA_DIR``). The applied revision is kept in the table
``hockle_alembic_version`` (not ``alembic_version``, so that a database shared with another
application keeps both apart).

- :func:`upgrade` runs ``upgrade head`` under a lock, so that several processes starting at
  once (an API and its workers) migrate once: PostgreSQL takes a transaction-level advisory
  lock and runs the whole upgrade in that transaction (DDL is transactional there: a failed
  upgrade leaves nothing half done); SQLite takes the database's write lock (``BEGIN
  IMMEDIATE``) for the upgrade, and retries when another process holds it too long.
- :func:`ensure_schema` is what the API and the workers call at start-up: ``upgrade head``
  when ``HOCKLE_AUTO_MIGRATE`` is true (the default), else a check that the registry is at
  head, with an error that says what to run.
- Registries made before Alembic (hockle created the tables at start-up and added new columns
  by ``ALTER TABLE``) need nothing special: the first revisions create only what is missing,
  so they adopt such a registry whatever columns it had, keeping its rows.

Operators who prefer to migrate explicitly: ``hockle db upgrade`` / ``hockle db current`` /
``hockle db check`` (or ``python -m service.migrations ...``) with ``HOCKLE_AUTO_MIGRATE=false``.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from sqlalchemy import create_engine, event, inspect, text
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import OperationalError
from sqlalchemy.pool import NullPool

__all__ = [
    "VERSION_TABLE",
    "SchemaNotCurrent",
    "alembic_config",
    "check",
    "current",
    "downgrade",
    "ensure_schema",
    "head",
    "upgrade",
]

HERE = Path(__file__).resolve().parent
VERSION_TABLE = "hockle_alembic_version"
# pg_advisory_xact_lock key of the upgrade: a fixed 63-bit number ("hockle" + "mig" in ASCII)
PG_LOCK_KEY = 0x686F636B6C656D69 & 0x7FFF_FFFF_FFFF_FFFF
# SQLite: how many times an upgrade that found the database locked is tried again
SQLITE_TRIES = 10


class SchemaNotCurrent(RuntimeError):
    """The registry is not at the schema revision this hockle needs, and
    ``HOCKLE_AUTO_MIGRATE`` is false."""


def alembic_config(connection: Connection | None = None, url: str | None = None):
    """An Alembic :class:`~alembic.config.Config` for hockle's migrations, no ini file.

    ``connection``: run on this connection (in its transaction); else ``url``; else the
    registry URL of the settings (``HOCKLE_DATABASE_URL``). ``env.py`` reads both from
    ``config.attributes``.
    """
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(HERE))
    config.attributes["connection"] = connection
    config.attributes["url"] = url
    return config


def _script():
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(alembic_config())


def head() -> str:
    """The head revision of hockle's migrations (the schema this code needs)."""
    heads = _script().get_heads()
    if len(heads) != 1:
        raise RuntimeError(f"service/migrations has {len(heads)} heads ({heads}): merge them")
    return heads[0]


def _is_sqlite(url: str) -> bool:
    return url.startswith("sqlite")


def _engine(url: str, busy_timeout: float) -> Engine:
    """An engine for one migration run (no pool). SQLite: driver autocommit, and every
    transaction begins with ``BEGIN IMMEDIATE`` (the write lock, DDL included), the
    SQLAlchemy recipe for pysqlite's transactions."""
    if not _is_sqlite(url):
        return create_engine(url, poolclass=NullPool)
    engine = create_engine(url, poolclass=NullPool,
                           connect_args={"timeout": busy_timeout, "check_same_thread": False})

    @event.listens_for(engine, "connect")
    def _connect(dbapi_connection, _record) -> None:
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute(f"PRAGMA busy_timeout={int(busy_timeout * 1000)}")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _begin(conn) -> None:
        conn.exec_driver_sql("BEGIN IMMEDIATE")

    return engine


@contextmanager
def _locked(engine: Engine) -> Iterator[Connection]:
    """One transaction that holds the migration lock (see the module's doc)."""
    with engine.begin() as conn:
        if conn.dialect.name == "postgresql":
            conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": PG_LOCK_KEY})
        yield conn


def _database_locked(exc: OperationalError) -> bool:
    return "locked" in str(exc.orig).lower() or "busy" in str(exc.orig).lower()


def upgrade(url: str, revision: str = "head", *, busy_timeout: float = 30.0) -> None:
    """Upgrade the registry at ``url`` to ``revision`` (default head), under the migration
    lock: safe when several processes do it at once, and a no-op when it is there already.

    ``busy_timeout``: SQLite, seconds to wait for the write lock on each of
    :data:`SQLITE_TRIES` tries.
    """
    _run_locked(url, "upgrade", revision, busy_timeout)


def _run_locked(url: str, action: str, revision: str, busy_timeout: float) -> None:
    """``alembic.command.<action>(revision)`` in one transaction that holds the lock."""
    from alembic import command

    engine = _engine(url, busy_timeout)
    try:
        for attempt in range(SQLITE_TRIES):
            try:
                with _locked(engine) as conn:
                    getattr(command, action)(alembic_config(conn), revision)
                return
            except OperationalError as exc:
                if (not _is_sqlite(url) or not _database_locked(exc)
                        or attempt == SQLITE_TRIES - 1):
                    raise
                time.sleep(min(0.2 * 2 ** attempt, 5.0))
    finally:
        engine.dispose()


def downgrade(url: str, revision: str, *, busy_timeout: float = 30.0) -> None:
    """Downgrade the registry at ``url`` to ``revision`` (``-1``: one back, ``base``: no
    tables), under the migration lock. Drops what the revisions above it made, rows too."""
    _run_locked(url, "downgrade", revision, busy_timeout)


def current(url: str, *, busy_timeout: float = 30.0) -> str | None:
    """The revision the registry at ``url`` is at; None for a database that Alembic has
    not migrated yet (empty, or made by a hockle before Alembic)."""
    from alembic.runtime.migration import MigrationContext

    engine = create_engine(url, poolclass=NullPool, **(
        {"connect_args": {"timeout": busy_timeout}} if _is_sqlite(url) else {}))
    try:
        with engine.connect() as conn:
            context = MigrationContext.configure(conn, opts={"version_table": VERSION_TABLE})
            return context.get_current_revision()
    finally:
        engine.dispose()


def include_name(name: str | None, type_: str, _parent_names: dict[str, Any]) -> bool:
    """Autogenerate looks at hockle's tables only: a shared database may hold others (the
    Celery/kombu broker tables of the SQL transport, another application's)."""
    if type_ == "table":
        from service.models import Base

        return name in Base.metadata.tables
    return True


def check(url: str) -> list[Any]:
    """The differences autogenerate finds between the models (:mod:`service.registry`) and
    the registry at ``url``: ``[]`` when they agree. Run it on a registry at head to see
    that the migrations build the schema the models define (the test suite does)."""
    from alembic.autogenerate import compare_metadata
    from alembic.runtime.migration import MigrationContext

    from service.models import Base

    engine = create_engine(url, poolclass=NullPool)
    try:
        with engine.connect() as conn:
            context = MigrationContext.configure(conn, opts={
                "version_table": VERSION_TABLE, "compare_type": True,
                "include_name": include_name})
            return list(compare_metadata(context, Base.metadata))
    finally:
        engine.dispose()


def ensure_schema(url: str, *, auto_migrate: bool = True, busy_timeout: float = 30.0) -> None:
    """Start-up: bring the registry to head (``auto_migrate``, ``HOCKLE_AUTO_MIGRATE``), or
    check that it is there and raise :class:`SchemaNotCurrent` saying what to run."""
    if auto_migrate:
        upgrade(url, busy_timeout=busy_timeout)
        return
    want, have = head(), current(url, busy_timeout=busy_timeout)
    if have != want:
        where = "has no hockle schema revision (new, or made before migrations)" \
            if have is None else f"is at schema revision {have}"
        raise SchemaNotCurrent(
            f"the job registry {_safe(url)} {where}; this hockle needs revision {want}. "
            "HOCKLE_AUTO_MIGRATE is false: run `hockle db upgrade` (or `python -m "
            "service.migrations upgrade`) with the same settings, or set "
            "HOCKLE_AUTO_MIGRATE=true to upgrade at start-up")


def _safe(url: str) -> str:
    """The URL without its password, for messages."""
    from sqlalchemy.engine import make_url

    try:
        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - a message must not fail
        return "(unparsable URL)"


def tables(url: str) -> dict[str, set[str]]:
    """Table name -> column names of the database at ``url`` (for tests and ``db current``)."""
    engine = create_engine(url, poolclass=NullPool)
    try:
        inspector = inspect(engine)
        return {name: {c["name"] for c in inspector.get_columns(name)}
                for name in inspector.get_table_names()}
    finally:
        engine.dispose()
