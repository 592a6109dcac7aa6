"""Profile of the seed example (issue 5): cProfile over the seed's case at its resolution
(1000 segments, Δt = 0.1 s) from t = 0 through buckling into the first self-contact, the
top of the profile by own time and by cumulative time.

Run: ``python -m benchmarks.profile_seed [--t-end 20.5] [--quick]``; the full stats are
written to ``benchmarks/results/profile_seed.pstats`` (open with ``python -m pstats`` or
snakeviz).
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import time
from pathlib import Path

from solver import Case, SolverDivergence, integrate

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "cases" / "goyal-writhing.yaml"
RESULTS = ROOT / "benchmarks" / "results"


def profile(t_end: float, n_segments: int | None = None, top: int = 22) -> dict:
    spec = Case.from_file(SEED).model_dump(mode="json")
    spec["numerics"]["t_end"] = t_end
    if n_segments is not None:
        spec["numerics"].pop("ds")
        spec["numerics"]["n_segments"] = n_segments
    case = Case.model_validate(spec)
    warm = dict(spec, numerics=dict(spec["numerics"], t_end=0.2))
    warm["numerics"].pop("ds", None)
    warm["numerics"]["n_segments"] = 20
    integrate(Case.model_validate(warm))         # imports and caches outside the profile
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    try:
        ds = integrate(case)
    except SolverDivergence as exc:
        ds = exc.partial
    prof.disable()
    wall = time.perf_counter() - t0
    RESULTS.mkdir(parents=True, exist_ok=True)
    prof.dump_stats(RESULTS / "profile_seed.pstats")
    tables = {}
    for key in ("tottime", "cumulative"):
        buf = io.StringIO()
        st = pstats.Stats(prof, stream=buf)
        st.strip_dirs().sort_stats(key).print_stats(top)
        text = buf.getvalue()
        # keep the table only (from the column header on)
        tables[key] = text[text.index("   ncalls"):].rstrip()
    contact = ds["contact_count"].values if "contact_count" in ds else None
    info = {"t_end": float(ds.time[-1]), "wall_s": wall, "steps": int(ds.sizes["step"]),
            "newton_iterations": int(ds.step_newton_iterations.sum()),
            "min_dt": float(ds.step_dt.min()),
            "factorizations": int(ds.attrs.get("factorizations", -1)),
            "steps_with_contact": None if contact is None else int((contact > 0).sum()),
            "n_segments": case.numerics.n_segments}
    (RESULTS / "profile_seed.json").write_text(json.dumps(info, indent=1))
    return {"info": info, "tables": tables}


def section(figdir: Path, quick: bool = False) -> str:
    """Profile the seed example and return its Markdown section."""
    res = profile(1.0 if quick else 20.5, n_segments=200 if quick else None)
    info = res["info"]
    return "\n".join([
        "## Profile of the seed example",
        "",
        f"cProfile of `cases/goyal-writhing.yaml` at {info['n_segments']} segments, "
        f"Δt = 0.1 s, from 0 to {info['t_end']:.1f} s (buckling near 17.5 s, first contact "
        f"near 18.3 s): {info['wall_s']:.1f} s under the profiler, {info['steps']} nominal "
        f"steps, {info['newton_iterations']} Newton iterations, "
        f"{info['factorizations']} band factorisations, smallest Δt {info['min_dt']:.3g} s, "
        f"{info['steps_with_contact']} outputs with active contact. Written by "
        "`benchmarks/profile_seed.py`; the full stats are in "
        "`benchmarks/results/profile_seed.pstats`.",
        "",
        "Top by own time:",
        "",
        "```",
        res["tables"]["tottime"],
        "```",
        "",
        "Top by cumulative time:",
        "",
        "```",
        res["tables"]["cumulative"],
        "```",
        "",
    ])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--t-end", type=float, default=20.5)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        print(section(Path("."), quick=True))
        return
    res = profile(args.t_end)
    print(json.dumps(res["info"], indent=1))
    print(res["tables"]["tottime"])
    print(res["tables"]["cumulative"])


if __name__ == "__main__":
    main()
