"""The contact suite (issue 41): every case completes with a right answer or ends with a
clear status, and what contact costs against the same run before contact.

Cases (each run once, in one process after a warm-up that compiles the kernels, with
``numerics.energy_tolerance`` at its default unless ``--energy-tolerance 0``, and a
wall-clock budget per case, past which the run ends ``stopped``):

* ``seed``: the seed example, cases/goyal-writhing.yaml (N = 1000, Δt = 0.1 s, 45 s);
* ``tension``: its tension variant, cases/goyal-writhing-tension.yaml;
* ``seed-twist-x2``, ``seed-twist-x0.5``: the seed with its slow twist rate (0.3 rad/s
  after 5 s) doubled and halved;
* ``thin-plectoneme``: the thin rod of research/thin_plectoneme.py (L/D = 100: the
  plectoneme with D = 1 cm, :func:`thin_case`), N = 200, Δt = 0.02 s, 16 s;
* ``pyelastica-0.8``: PyElastica's plectoneme as benchmarks/peer_compare.py runs it,
  ρ∞ = 0.8, N = 25, Δt = 0.1 s, to 12 s;
* ``cantilever``: the steel cantilever under a dead tip load P L²/EI = 10 ramped over
  2 s (:func:`cantilever_spec`, the rod of tests/solver/test_energy_check.py), N = 100,
  Δt = 0.1 s, 8 s, ρ∞ = 0 (no contact: the
  tip's x/L against Mattiasson's 0.44501 is its answer);
* ``seed-in-air``: a case no setting was tuned on: the seed example without its fluid
  (no drag, no added mass), to 45 s.

Per case: status (and reason), wall time (s), Newton iterations per nominal step, the
smallest accepted step (s, every substep counted), refused attempts by reason, the
first contact time (s) and the cost per simulated second in contact over the cost before
contact (wall s per simulated s after the first contact over the same before it), with its
three factors (:func:`phase_factors`): how many more steps per simulated second contact
takes, how many more Newton iterations per step, and how much more each iteration costs.
The processor's name and clock head the table: wall times compare on one host only.

Run: ``python -m benchmarks.contact_suite [--only a,b] [--write-docs]``
(10-19 min alone on 2 cores, by the machine; ``--merge earlier.json`` keeps an earlier
run's rows for the cases not run now, ``--table-only --merge x.json`` only prints the
table);
``--write-docs`` puts the table into docs/benchmarks.md (its ``contact_suite`` section,
also written by ``python -m benchmarks.report``); the figures go to
benchmarks/results/contact_suite.json.

``--spread`` runs each case of ``--only`` again with ``numerics.newton.tolerance`` scaled
by each of :data:`SPREAD` and prints each run's outcome and Newton iterations per nominal
step, its energy at the end and its largest net energy injection over two nominal steps
(:func:`window_injection`; nothing saved): a case whose count moves that much under a
perturbation of the tolerance cannot rank two codes by one run. PyElastica's plectoneme at
ρ∞ = 0.8, N = 25, Δt = 0.1 s is such a case (docs/contact.md § 4). ``--factors
F1,F2,...`` replaces SPREAD; ``--set FIELD=VALUE`` (repeatable) sets a case field in
every run. ``--newton ATTR=VALUE[,...]`` sets class attributes of
:class:`solver.newton.NewtonSolver` for every run (:mod:`benchmarks.tuning`, as
``benchmarks.seed_accuracy``'s option).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import time
from pathlib import Path

import numpy as np

from solver.case import Numerics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

RESULTS = HERE / "results" / "contact_suite.json"
DOC = ROOT / "docs" / "benchmarks.md"
MARK = "<!-- section: contact_suite -->"
#: the energy check's tolerance in every case: the default (0.5, the lowest that leaves
#: the right dead-load cantilever at Δt = 0.02 s unrefused while every Δt up to 0.2 s
#: settles within 0.1 % of the elastica; docs/numerics.md § 8)
ENERGY_TOLERANCE = Numerics.model_fields["energy_tolerance"].default
#: wall-clock budget per case, s: the seed without its fluid takes ~450 s where the seed
#: example takes 22 s and ~800 s where it takes 42 s (docs/contact.md § 4), and should
#: complete on either
BUDGET_S = 1500.0
#: ``--spread``: the factors on numerics.newton.tolerance (within ±25 %, each a setting a
#: user could equally have chosen)
SPREAD = (0.8, 0.9, 1.0, 1.1, 1.25)
#: :func:`window_injection`'s window, in nominal steps Δt
WINDOW_STEPS = 2
X_TIP = 0.44501           # Mattiasson's tip x/L under P L²/EI = 10


def _seed(path="cases/goyal-writhing.yaml", twist=1.0, fluid=True):
    from solver.case import Case
    spec = Case.from_file(ROOT / path).model_dump(mode="json")
    if twist != 1.0:
        table = spec["boundary"]["start"]["rotation"][2][0]["angular_velocity"]
        table["value"] = [v if t < 5.0 else v * twist
                          for t, v in zip(table["t"], table["value"])]
    if not fluid:
        spec["fluid"] = None
    return spec


#: the thin rod's diameter, m (L/D = 100)
THIN_DIAMETER = 0.01


def thin_case(n: int, dt: float, t_end: float = 16.0):
    """PyElastica's plectoneme case (``pyelastica_compare.hockle_plectoneme_case``) with
    D = 1 cm and the contact tolerance 2D: n segments, time step dt (s), to t_end (s),
    outputs every 0.02 s. Returns a validated ``solver.Case``."""
    from solver.case import Case

    from benchmarks import pyelastica_compare as pc

    spec = pc.hockle_plectoneme_case(n, dt, t_end).model_dump(mode="json")
    spec["rod"]["diameter"] = THIN_DIAMETER
    spec["contact"]["tolerance"] = 2.0 * THIN_DIAMETER
    return Case.model_validate(spec)


def _thin():
    return thin_case(200, 0.02).model_dump(mode="json")


def _pyelastica():
    from benchmarks import peer_compare as pcmp
    spec = pcmp.hockle_case(25, 0.1, 12.0).model_dump(mode="json")
    spec["numerics"]["rho_inf"] = 0.8
    return spec


def cantilever_spec(dt=0.1, n=100, t_end=8.0):
    """The steel cantilever (L = 1 m, D = 1 cm, E = 210 GPa, G = 81 GPa, 7850 kg/m³, no
    gravity) clamped along z at s = 0 under a dead tip load P = 10 EI/L² along +x, ramped on
    over 2 s; ρ∞ = 0, the energy check at its default (the rod of
    tests/solver/test_energy_check.py)."""
    E, D, L = 2.1e11, 0.01, 1.0
    EI = E * math.pi * D**4 / 64
    return {
        "schema_version": 1, "name": "dead-load cantilever",
        "rod": {"length": L, "youngs_modulus": E, "shear_modulus": 8.1e10, "density": 7850.0,
                "diameter": D},
        "point_loads": [{"s": L, "value": [10.0 * EI / L**2, 0.0, 0.0],
                         "factor": {"t": [0.0, 2.0], "value": [0.0, 1.0]}}],
        "boundary": {"start": {"translation": [{"velocity": 0.0}] * 3,
                               "rotation": [{"angular_velocity": 0.0}] * 3},
                     "end": {"translation": [{"force": 0.0}] * 3,
                             "rotation": [{"moment": 0.0}] * 3}},
        "numerics": {"n_segments": n, "dt": dt, "t_end": t_end, "rho_inf": 0.0,
                     "energy_tolerance": ENERGY_TOLERANCE},
        "output": {"fields": ["position", "energies"]},
    }


def _cantilever():
    from solver.case import Case

    return Case.model_validate(cantilever_spec()).model_dump(mode="json")


#: name -> (description, spec builder)
CASES = {
    "seed": ("seed example (N = 1000, Δt = 0.1 s, 45 s)", _seed),
    "tension": ("tension variant", lambda: _seed("cases/goyal-writhing-tension.yaml")),
    "seed-twist-x2": ("seed, slow twist rate ×2", lambda: _seed(twist=2.0)),
    "seed-twist-x0.5": ("seed, slow twist rate ×0.5", lambda: _seed(twist=0.5)),
    "thin-plectoneme": ("thin-rod plectoneme (L/D = 100, N = 200, Δt = 0.02 s)", _thin),
    "pyelastica-0.8": ("PyElastica's plectoneme, ρ∞ = 0.8, N = 25, Δt = 0.1 s", _pyelastica),
    "cantilever": ("dead-load cantilever, Δt = 0.1 s, ρ∞ = 0 (no contact)", _cantilever),
    "seed-in-air": ("seed without its fluid (untuned)", lambda: _seed(fluid=False)),
}


def _refused(ds) -> dict:
    text = ds.attrs.get("hockle_refused_attempts", "")
    out = {}
    for item in text.split(", "):
        if item:
            k, v = item.rsplit(" ", 1)
            if int(v):
                out[k] = int(v)
    return out


def with_sets(spec: dict, sets=()) -> dict:
    """``spec`` (a case as a dict) with each "dotted.field=VALUE" of ``sets`` applied in
    place (VALUE read as YAML: ``seabed.friction=null``, ``contact=null``,
    ``numerics.backward_euler_retry=true``) and returned. Raises SystemExit naming a
    field of ``sets`` whose parent the spec does not hold."""
    import yaml

    for item in sets:
        key, _, text = item.partition("=")
        *path, last = key.split(".")
        node = spec
        for part in path:
            if not isinstance(node.get(part), dict):
                raise SystemExit(f"--set {item}: the case has no {key}")
            node = node[part]
        value = yaml.safe_load(text)
        if isinstance(value, str):
            try:
                value = float(value)          # YAML 1.1 reads 3e5 as a string
            except ValueError:
                pass
        node[last] = value
    return spec


def run_case(name: str, energy_tolerance: float | None, budget: float = BUDGET_S,
             tolerance_scale: float = 1.0, sets=()) -> dict:
    """One suite case: simulate it with the progress traced and every accepted attempt's
    Δt seen (a wrapper around RodRun.try_step for the run's duration); with
    ``tolerance_scale`` its ``numerics.newton.tolerance`` times that factor, with
    ``sets`` its fields set as :func:`with_sets` does."""
    from solver.case import Case
    from solver.run import RodRun
    from solver.simulation import SolverDivergence, integrate

    spec = with_sets(CASES[name][1](), sets)
    spec["numerics"]["energy_tolerance"] = energy_tolerance
    spec["numerics"]["wall_clock_budget"] = budget
    if tolerance_scale != 1.0:
        spec["numerics"]["newton"]["tolerance"] *= tolerance_scale
    case = Case.model_validate(spec)
    trace, smallest, attempts, balances = [], [math.inf], [], []
    original = RodRun.try_step

    def try_step(self, h, *args, **kwargs):
        t_start, w0 = self.state.t, time.perf_counter()
        att = original(self, h, *args, **kwargs)
        restart = kwargs.get("restart", False)
        attempts.append((t_start, bool(att.ok) and not restart, att.iterations,
                         time.perf_counter() - w0))
        if att.ok and not restart:
            smallest[0] = min(smallest[0], h)
            bal = self.last_balance
            if bal is not None:
                balances.append((self.state.t, bal.error, bal.energy))
        return att

    RodRun.try_step = try_step
    status, reason = "completed", ""
    t0 = time.perf_counter()
    try:
        ds = integrate(case, progress=lambda p: trace.append((p.t, p.wall_time,
                                                             p.contact_count)))
        status = ds.attrs["hockle_status"]
        reason = ds.attrs.get("hockle_stop_reason", "")
    except SolverDivergence as exc:
        ds, status, reason = exc.partial, "failed", f"{exc.reason} at t = {exc.t:.3f} s"
    finally:
        RodRun.try_step = original
    wall = time.perf_counter() - t0
    tr = np.array(trace) if trace else np.zeros((0, 3))
    num = case.numerics
    t_reached = float(ds.step_time.values[-1]) if ds.sizes.get("step", 0) else 0.0
    nominal = max(1, int(round(t_reached / num.dt)))
    out = {"case": name, "what": CASES[name][0], "status": status, "reason": reason,
           "wall_s": wall, "t_end": num.t_end, "t_reached": t_reached,
           "newton_per_step": float(ds.step_newton_iterations.values.sum()) / nominal,
           "smallest_dt": smallest[0], "refused": _refused(ds),
           "t_contact": math.nan, "contact_cost_ratio": math.nan}
    touched = np.flatnonzero(tr[:, 2] > 0) if len(tr) else np.zeros(0, int)
    if touched.size:
        k = int(touched[0])
        t_c, w_c = (float(tr[k - 1, 0]), float(tr[k - 1, 1])) if k > 0 else (0.0, 0.0)
        out["t_contact"] = float(tr[k, 0])
        t_last, w_last = float(tr[-1, 0]), float(tr[-1, 1])
        if t_c > 0 and t_last > t_c:
            out["contact_cost_ratio"] = ((w_last - w_c) / (t_last - t_c)) / (w_c / t_c)
            out["phases"] = phase_factors(attempts, t_c, t_last)
    if name == "cantilever":
        x = float(ds.position.values[-1, -1, 2])
        out["answer"] = f"tip x/L {x:.5f} ({(x / X_TIP - 1) * 100:+.3f} % off the elastica)"
    if balances:
        b = np.array(balances)
        out["energy_final"] = float(b[-1, 2])
        out["energy_window"] = window_injection(b[:, 0], b[:, 1], b[:, 2],
                                                WINDOW_STEPS * num.dt)
    if "step_energy_error" in ds:
        e = ds.step_energy_error.values
        out["energy_error_max"] = float(np.nanmax(e)) if np.isfinite(e).any() else math.nan
    return out


def window_injection(t, error, energy, width: float) -> tuple[float, float]:
    """The largest net energy the accepted steps put in over any window of ``width`` (s),
    as a share of the largest energy in it, and the window's end (s): max over the steps
    j of Σ ε_i over the steps i ending in (t_j − width, t_j], over max E_i there. t (n,):
    each step's end (s, increasing); error (n,): its balance error ε (J,
    :class:`solver.balance.StepBalance`); energy (n,): the rod's energy at its end (J).
    The per-step check bounds each ε by a share of the kinetic energy, which grows with
    what the steps put in: a run whose steps each pass can still gain energy step after
    step (docs/contact.md § 3, "Right or refused over many steps"); the sum over a window
    is where that shows. (NaN, NaN) without steps."""
    t, error, energy = (np.asarray(a, dtype=float) for a in (t, error, energy))
    if t.size == 0:
        return math.nan, math.nan
    csum = np.concatenate([[0.0], np.cumsum(error)])
    first = np.searchsorted(t, t - width, side="right")
    best, at = -math.inf, math.nan
    for j in range(t.size):
        i = first[j]
        share = (csum[j + 1] - csum[i]) / max(float(energy[i:j + 1].max()), 1e-300)
        if share > best:
            best, at = share, float(t[j])
    return float(best), at


def phase_factors(attempts, t_c: float, t_last: float) -> dict:
    """What the cost per simulated second is made of before contact (attempts starting
    before t_c, s) and in contact (from t_c to t_last): accepted steps per simulated
    second (restarts not counted), Newton iterations per accepted step (every attempt's,
    refused and restarts included) and wall seconds per Newton iteration (the attempts'
    own wall: the outputs' topology and the progress hook are outside it). attempts:
    (t at the attempt's start (s), accepted, Newton iterations, wall (s)) per attempt.
    The product of the three ratios contact/before is the ratio of the attempts' wall per
    simulated second."""
    out = {}
    for name, lo, hi in (("before", 0.0, t_c), ("contact", t_c, t_last)):
        sel = [a for a in attempts if lo <= a[0] < hi]
        steps = sum(1 for a in sel if a[1])
        its = sum(a[2] for a in sel)
        wall = sum(a[3] for a in sel)
        out[name] = {"steps_per_s": steps / (hi - lo), "its_per_step":
                     its / steps if steps else math.nan,
                     "wall_per_it_ms": 1e3 * wall / its if its else math.nan}
    b, c = out["before"], out["contact"]
    out["ratios"] = [c[k] / b[k] if b[k] else math.nan
                     for k in ("steps_per_s", "its_per_step", "wall_per_it_ms")]
    return out


def warm_up() -> None:
    """Compile (or load) the kernels outside the timed cases: PyElastica's plectoneme to
    8 s, past its first contact (~7.2 s), so that the contact kernels are compiled too
    (a run that stopped before contact left their compilation, ~50 s on a fresh
    install, in the first timed case)."""
    from solver.case import Case
    from solver.simulation import integrate
    spec = _pyelastica()
    spec["numerics"]["t_end"] = 8.0
    spec["numerics"]["energy_tolerance"] = ENERGY_TOLERANCE
    integrate(Case.model_validate(spec))


def _fmt(x, f="{:.2f}"):
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f.format(x)


def _status(r: dict) -> str:
    """A result row's status with its reason."""
    return r["status"] + (f" ({r['reason']})" if r["reason"] else "")


def _refused_text(r: dict) -> str:
    """A result row's refused attempts by reason ("none" without any)."""
    return ", ".join(f"{k} {v}" for k, v in sorted(r["refused"].items())) or "none"


def _energy_text(r: dict) -> str:
    """The run's energy at its end and its largest net injection over a window
    (:func:`window_injection`), or "" where the energy check did not measure."""
    if "energy_window" not in r:
        return ""
    share, at = r["energy_window"]
    return (f"; energy at the end {r['energy_final']:.3f} J, largest net injection over "
            f"{WINDOW_STEPS} Δt {100 * share:.1f} % of E (at {at:.2f} s)")


def _factors(r: dict) -> str:
    """A result row's contact/before ratios of steps per simulated second, Newton
    iterations per step and wall per Newton iteration (:func:`phase_factors`), with the
    before-contact figures of the last two."""
    ph = r.get("phases")
    if not ph:
        return "–"
    a, b, c = ph["ratios"]
    bf, cf = ph["before"], ph["contact"]
    return (f"{a:.1f} × {b:.1f} ({bf['its_per_step']:.1f} → {cf['its_per_step']:.1f}) × "
            f"{c:.1f} ({bf['wall_per_it_ms']:.2f} → {cf['wall_per_it_ms']:.2f} ms)")


def table(rows: list) -> str:
    """The suite's markdown table."""
    lines = ["| case | status | wall (s) | Newton its / nominal step | smallest Δt (s) | "
             "refused attempts | first contact (s) | cost in contact / before | "
             "= steps × Newton its per step × wall per Newton it |",
             "|---|---|---:|---:|---:|---|---:|---:|---|"]
    for r in rows:
        status = _status(r)
        if r["status"] != "completed":
            status += f", reached {r['t_reached']:.2f} of {r['t_end']:g} s"
        if r.get("answer"):
            status += f"; {r['answer']}"
        refused = _refused_text(r)
        lines.append(f"| {r['what']} | {status} | {r['wall_s']:.1f} | "
                     f"{r['newton_per_step']:.1f} | {_fmt(r['smallest_dt'], '{:.3g}')} | "
                     f"{refused} | {_fmt(r['t_contact'])} | "
                     f"{_fmt(r['contact_cost_ratio'], '{:.1f}×')} | {_factors(r)} |")
    return "\n".join(lines)


def section_text(res: dict) -> str:
    """The docs section of a result (the JSON this script writes)."""
    return "\n".join([
        "## Contact suite: completed or refused, and what contact costs",
        "",
        "Written by `benchmarks/contact_suite.py` (docstring: the cases and what each column "
        f"measures) on {res['stamp']}; one run per case, one after another in one process "
        f"after a warm-up run"
        + (f" ({res['parts']} invocations, merged)" if res.get("parts", 1) > 1 else "")
        + f"; 1-min load {res['load_start']:.1f} at the start, "
        f"{res['load_end']:.1f} at the end (2 cores, shared"
        + (f", {res['host']}" if res.get("host") else "") + "). "
        + (f"Energy check on (`numerics.energy_tolerance: {res['energy_tolerance']}`). "
           if res["energy_tolerance"] else "Energy check off. ")
        + (res.get("budget_note") or f"Wall-clock budget {res['budget_s']:.0f} s per case.")
        + f" Total {res['total_s']:.0f} s.",
        "",
        table(res["rows"]),
        "",
        "Newton iterations per nominal step: all iterations (refused attempts and restarts "
        "included) over t/Δt. Smallest Δt: the smallest accepted step, substeps included. "
        "Cost in contact / before: wall seconds per simulated second after the first "
        "contact over the same before it (the before-phase includes the buckling); its "
        "factors, each contact over before: accepted steps per simulated second, Newton "
        "iterations per accepted step (refused attempts included) and the step "
        "attempts' own wall per Newton iteration, with the before and contact figures of "
        "the last two in brackets; their product is the ratio of the attempts' wall alone, "
        "which leaves out the outputs (the writhe every 0.1 s) and the rest around the "
        "steps, a larger share of the cheap steps before contact. "
        "One run per case: where a case's count moves under a ±25 % change of Newton's "
        "tolerance (`--only CASE --spread` prints it; PyElastica's plectoneme at ρ∞ = 0.8 "
        "does, docs/contact.md § 4), a difference between two tables is not one between "
        "two codes.",
        ""])


def write_docs(text: str) -> None:
    """Put ``text`` into docs/benchmarks.md between the section's marker and the next
    section marker (the marker appended at the end when the page has none)."""
    page = DOC.read_text()
    if MARK in page:
        page = re.sub(re.escape(MARK) + r"\n.*?(?=\n<!-- section: |\Z)",
                      lambda m: MARK + "\n" + text.rstrip() + "\n", page, flags=re.S)
    else:
        page = page.rstrip() + "\n" + MARK + "\n" + text.rstrip() + "\n"
    DOC.write_text(page)


def host() -> str:
    """The processor the suite ran on (/proc/cpuinfo's model name and clock; "" where it
    cannot be read): wall times compare only on one host."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return ""
    model = re.search(r"^model name\s*:\s*(.+)$", info, re.M)
    mhz = re.search(r"^cpu MHz\s*:\s*([\d.]+)", info, re.M)
    return ((model.group(1).strip() if model else "")
            + (f" at {float(mhz.group(1)) / 1000:.1f} GHz" if mhz else "")).strip()


def collect(names, energy_tolerance, budget=BUDGET_S, log=print) -> dict:
    load_start = os.getloadavg()[0]
    t0 = time.perf_counter()
    warm_up()
    rows = []
    from datetime import datetime, timezone
    for name in names:
        log(f"-- {name}: {CASES[name][0]}", flush=True)
        r = run_case(name, energy_tolerance, budget)
        log(f"   {r}", flush=True)
        rows.append(r)
        res = {"stamp": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
               "host": host(),
               "energy_tolerance": energy_tolerance, "budget_s": budget,
               "load_start": load_start, "load_end": os.getloadavg()[0],
               "total_s": time.perf_counter() - t0, "rows": rows}
        save(res)            # after every case: a later failure keeps the rows so far
    return res


def save(res: dict) -> None:
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(res, indent=1, default=float))


def merged(res: dict, earlier: dict) -> dict:
    """``res`` with the rows of ``earlier`` (a result of this script) for the cases it
    did not run, in the order of CASES (``--merge``: the suite in parts)."""
    rows = {r["case"]: r for r in earlier["rows"]}
    rows.update({r["case"]: r for r in res["rows"]})
    out = dict(res)
    out["rows"] = [rows[k] for k in CASES if k in rows]
    out["total_s"] = res["total_s"] + earlier.get("total_s", 0.0)
    out["load_start"] = max(res["load_start"], earlier.get("load_start", 0.0))
    out["load_end"] = max(res["load_end"], earlier.get("load_end", 0.0))
    out["parts"] = earlier.get("parts", 1) + 1
    return out


def section(figdir=None, quick: bool = False) -> str:
    """The section for benchmarks/report.py (``quick``: the cantilever and PyElastica's
    plectoneme only)."""
    names = ["pyelastica-0.8", "cantilever"] if quick else list(CASES)
    res = collect(names, ENERGY_TOLERANCE)
    save(res)
    return section_text(res)


def spread(names, energy_tolerance, budget=BUDGET_S, factors=SPREAD, sets=()) -> None:
    """Print each case's outcome, Newton iterations per nominal step and energy
    (:func:`_energy_text`) at ``numerics.newton.tolerance`` times each of ``factors``
    (default SPREAD; after a warm-up run), and the counts' range and median; ``sets``
    as :func:`run_case`'s."""
    warm_up()
    for name in names:
        counts = []
        for f in factors:
            r = run_case(name, energy_tolerance, budget, tolerance_scale=f, sets=sets)
            print(f"{name}: tolerance × {f:g}: {_status(r)}, {r['newton_per_step']:.1f} "
                  f"Newton iterations per nominal step, refused {_refused_text(r)}"
                  f"{_energy_text(r)}" + (f"; {r['answer']}" if "answer" in r else ""),
                  flush=True)
            if r["status"] == "completed":
                counts.append(r["newton_per_step"])
        if counts:
            print(f"{name}: {len(counts)} of {len(factors)} completed; Newton iterations per "
                  f"nominal step {min(counts):.1f}-{max(counts):.1f}, median "
                  f"{float(np.median(counts)):.1f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma-separated case names")
    ap.add_argument("--energy-tolerance", type=float, default=ENERGY_TOLERANCE,
                    help="numerics.energy_tolerance of every case (0: the check off)")
    ap.add_argument("--budget", type=float, default=BUDGET_S, help="wall s per case")
    ap.add_argument("--write-docs", action="store_true")
    ap.add_argument("--merge", default="", help="an earlier result JSON whose rows are "
                    "kept for the cases not run now")
    ap.add_argument("--newton", default="", help="Newton class attributes (or VERLET_SKIN) "
                    "ATTR=VALUE[,...] for every run (as seed_accuracy.py --newton)")
    ap.add_argument("--spread", action="store_true", help="each case at newton.tolerance "
                    "times each of SPREAD: outcome and Newton iterations (nothing saved)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="with --spread: a case field for every run, as contact_steps.py's "
                    "(e.g. numerics.backward_euler_retry=true); repeatable")
    ap.add_argument("--factors", default="", help="with --spread: the factors on "
                    "newton.tolerance, comma-separated (default: SPREAD)")
    ap.add_argument("--table-only", action="store_true",
                    help="print (and with --write-docs write) the table of --merge")
    args = ap.parse_args()
    names = [x for x in args.only.split(",") if x] or list(CASES)
    for x in names:
        if x not in CASES:
            ap.error(f"unknown case {x!r}; known: {', '.join(CASES)}")
    if args.newton:
        from benchmarks.tuning import set_newton
        set_newton(args.newton)
    if args.spread:
        factors = tuple(float(x) for x in args.factors.split(",") if x) or SPREAD
        spread(names, args.energy_tolerance or None, args.budget, factors, args.set)
        return
    earlier = json.loads(Path(args.merge).read_text()) if args.merge else None
    if args.table_only:
        res = earlier
    else:
        res = collect(names, args.energy_tolerance or None, args.budget)
        if earlier is not None:
            res = merged(res, earlier)
        save(res)
    text = section_text(res)
    print(text)
    if args.write_docs:
        write_docs(text)
        print(f"wrote {DOC}")


if __name__ == "__main__":
    main()
