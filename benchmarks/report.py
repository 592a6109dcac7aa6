"""Regenerate every benchmark figure and table into ``docs/benchmarks.md`` (issue 5).

One command: ``python -m benchmarks.report``. It runs, in order, the work-precision
study, the error-controlled steps against their tolerance, the stability map, the cost of
each feature, the profile of the seed example, the seed example at its resolution, the
side-by-side run with PyElastica (which installs its own requirements,
``benchmarks/requirements-pyelastica.txt``), the contact suite and the first-run
compilation of the kernels, and writes the
Markdown page with the figures under ``docs/figures/benchmarks/``. Each section module
exposes ``section(figdir, quick) -> str`` and leaves its numbers in
``benchmarks/results/<name>.json``.

Options: ``--quick`` (small sizes, one repeat: a smoke run of the whole pipeline, a few
minutes; the page then says so), ``--only a,b`` / ``--skip a,b`` (section names below;
sections not run keep their previous text, read back from the existing page).
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import re
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DOC = ROOT / "docs" / "benchmarks.md"
FIGDIR = ROOT / "docs" / "figures" / "benchmarks"
RESULTS = HERE / "results"

#: (name, module, what it is), in the order of the page
SECTIONS = [
    ("work_precision", "work_precision", "error against wall time, observed orders"),
    ("adaptive", "adaptive_precision", "error-controlled steps against the tolerance"),
    ("stability", "stability_map", "stability map over Δt and ρ∞"),
    ("feature_cost", "feature_cost", "cost per step of each feature"),
    ("profile", "profile_seed", "profile of the seed example"),
    ("seed", "bench_seed", "the seed example at its resolution"),
    ("pyelastica", "peer_compare", "PyElastica side by side, interleaved, same drag law"),
    ("contact_suite", "contact_suite", "contact suite: completed or refused, contact cost"),
    ("compile_time", "compile_time", "first-run compilation of the kernels"),
]
MARK = "<!-- section: {} -->"
#: sections written by hand (or by a benchmark of their own) that the page keeps after a
#: generated one: "eta", the ETA accuracy of benchmarks/eta_accuracy.py, after "seed"
KEPT_AFTER = {"seed": ["eta"]}


def _load(name: str) -> dict | None:
    path = RESULTS / f"{name}.json"
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError:
        return None


def headline() -> list[str]:
    """Headline figures read back from the sections' result files (best effort: a
    section that has not run, or that stores its figures differently, is left out)."""
    out = []
    seed = _load("bench_seed")
    if seed:
        out.append(f"Seed example at its resolution ({seed['n_segments']} segments, "
                   f"Δt = {seed['dt']} s, to {seed['t_reached']:.0f} s with self-contact): "
                   f"**{seed['wall_s']:.0f} s** wall time on this machine (bar 120 s, goal "
                   f"20 s); {seed['ms_per_step_without_contact'] or float('nan'):.0f} ms per "
                   "step without contact.")
    for name in ("work_precision", "adaptive_precision", "peer_compare", "stability_map",
                 "feature_cost"):
        res = _load(name)
        if res and isinstance(res.get("headline"), list):
            out.extend(str(x) for x in res["headline"])
    comp = _load("compile_time")
    if comp:
        out.append(f"First run after installing: the kernels compile in "
                   f"**{comp['total_s']:.0f} s** on this machine ({comp['signatures']} "
                   "function signatures); later runs load them in about 2 s.")
    return out


def machine() -> str:
    import numpy
    import scipy

    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{os.cpu_count()} cores ({cpu}), Python {platform.python_version()}, "
            f"numpy {numpy.__version__}, scipy {scipy.__version__}")


def previous_sections() -> dict:
    """Section texts of the existing page, by name (to keep those not re-run)."""
    if not DOC.exists():
        return {}
    text = DOC.read_text()
    found = {}
    for name in [n for n, _, _ in SECTIONS] + [k for v in KEPT_AFTER.values() for k in v]:
        m = re.search(re.escape(MARK.format(name)) + r"\n(.*?)(?=\n<!-- section: |\Z)", text,
                      flags=re.S)
        if m:
            found[name] = m.group(1).rstrip() + "\n"
    return found


def ensure_pyelastica() -> None:
    """Install the PyElastica benchmark's own requirements if PyElastica is missing
    (benchmark-only: neither hockle nor its tests need it)."""
    from importlib.util import find_spec

    if find_spec("elastica") is not None:
        return
    req = HERE / "requirements-pyelastica.txt"
    print(f"    installing {req.name} (PyElastica, numba) ...", flush=True)
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "-r", str(req)],
                   check=True)
    importlib.invalidate_caches()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", default="")
    ap.add_argument("--skip", default="")
    args = ap.parse_args()
    names = [s[0] for s in SECTIONS]
    only = [x for x in args.only.split(",") if x]
    skip = [x for x in args.skip.split(",") if x]
    for x in only + skip:
        if x not in names:
            ap.error(f"unknown section {x!r}; known: {', '.join(names)}")
    FIGDIR.mkdir(parents=True, exist_ok=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    texts, timings = {}, {}
    t_all = time.perf_counter()
    for name, module, what in SECTIONS:
        if (only and name not in only) or name in skip:
            texts[name] = None          # filled from the page as it is when we write
            continue
        print(f"==> {name}: {what}", flush=True)
        if name == "pyelastica":
            ensure_pyelastica()
        t0 = time.perf_counter()
        mod = importlib.import_module(f"benchmarks.{module}")
        texts[name] = mod.section(FIGDIR, quick=args.quick).rstrip() + "\n"
        timings[name] = time.perf_counter() - t0
        print(f"<== {name}: {timings[name]:.0f} s", flush=True)
    total = time.perf_counter() - t_all
    # sections not run keep their text from the page as it is now (another invocation
    # with other sections may have written it meanwhile)
    keep = previous_sections()
    for name, _, what in SECTIONS:
        if texts[name] is None:
            texts[name] = keep.get(name, f"## {what}\n\n(not run yet)\n")
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    head = ["# Benchmarks: accuracy against cost, stability, what each feature costs, "
            "and PyElastica side by side",
            "",
            "Generated by `python -m benchmarks.report` (one command; every figure and "
            "table below comes from it) on " + stamp + ", " + machine() + ". "
            "The machine is shared and noisy: timings are medians of repeated runs where "
            "timing matters, and comparisons are ratios measured in one run."
            + (" **Quick mode: small sizes and one repeat, a smoke run, not the "
               "figures to quote.**" if args.quick else ""),
            "",
            "Sections run this time: " + (", ".join(f"{k} ({v:.0f} s)" for k, v in
                                                    timings.items()) or "none")
            + f"; total {total:.0f} s.",
            "",
            "## Headline figures",
            ""]
    head += [f"* {x}" for x in headline()] or ["* (no section has run yet)"]
    head.append("")
    body = []
    for name, _, _ in SECTIONS:
        body.append(MARK.format(name))
        body.append(texts[name])
        for kept in KEPT_AFTER.get(name, []):
            if kept in keep:
                body.append(MARK.format(kept))
                body.append(keep[kept])
    DOC.write_text("\n".join(head) + "\n" + "\n".join(body))
    print(f"wrote {DOC} in {total:.0f} s")


if __name__ == "__main__":
    main()
