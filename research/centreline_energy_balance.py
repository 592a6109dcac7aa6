"""What an energy check on the centreline scheme would measure: each accepted step's
balance ε on the one centreline, the check itself not built (issue 79).

Per step from level n to n+1 (:class:`solver.centreline.CentrelineState`)::

    ε = [T + U_el + U_b + U_e]^{n+1} − [T + U_el + U_b + U_e]^n − U_c change − W

T and U_el the kinetic and elastic energies of :meth:`solver.centreline.CentrelineRod.
energies` (trapezoid in s); U_b the sea floor's spring, Σ w_k ½ k max(p_k, 0)² over the
nodes (the nodal law of the scheme); U_e the screened electrostatics' energy; the change of
the self-contact law's potential with the new level's candidates; W the work of the dead
loads Σ w_k ½(f^n + f^{n+1})·Δr_k, of the ends n·Δr and m·(R^n Δθ) (½ of both levels'
loads; Δθ the Cayley increment, the same vector in either frame) and of the step's thermal
loads. Drag, the sea floor's damper and friction and the law's damping only dissipate and
are left out (a one-sided check, as :mod:`solver.balance`). Printed per case: the largest
ε over three scales, max(T^n, T^{n+1}) floored at share × the stored energy, and with
c × max(|ΔU_el|, |W|), with the number of steps past 0.5.

Run: ``python -m research.centreline_energy_balance [--only cantilever|cable|rest|hockle]``
(a few seconds to a minute each).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from research import loads_verification as LV
import test_energy_check as EC
import test_seabed as SB
from solver import centreline as C
from solver import statics as st
from solver.case import Case
from solver.simulation import integrate

ROOT = Path(__file__).resolve().parents[1]


def _stored(rod, level, prob):
    """(T + U_el + U_b + U_e, T, U_el) of a level, J."""
    w = rod.props.quad_weights
    e = rod.energies(level)
    u = e["kinetic"] + e["elastic"]
    if rod.seabed is not None:
        co = C._Coefficients(0.0, level.Xd, 0.0, level.X)
        pen = rod.seabed_terms(level.Y, level, co, want=False)[1][3]
        u += float(np.sum(w * 0.5 * rod.seabed.data.scalars[2] * np.maximum(pen, 0.0) ** 2))
    if prob.electrostatics is not None:
        u += prob.electrostatics.energy(level.Y[:, 0:3])
    return u, e["kinetic"], e["elastic"]


def _work(rod, old, new, p_old, p_new):
    """The dead loads', the ends' and the thermal loads' work over a step, J."""
    w = rod.props.quad_weights
    dr = new.Y[:, 0:3] - old.Y[:, 0:3]
    work = float(np.sum(w * np.sum(0.5 * (p_old.load + p_new.load) * dr, axis=1)))
    dth = np.einsum("kij,kj->ki", st._rot(old.Y[:, 3:7]),
                    C.cayley_vector(old.Y[:, 3:7], new.Y[:, 3:7]))
    n = 0.5 * (old.Y[:, 7:10] + new.Y[:, 7:10])
    m = 0.5 * (old.Y[:, 10:13] + new.Y[:, 10:13])
    work += n[-1] @ dr[-1] - n[0] @ dr[0] + m[-1] @ dth[-1] - m[0] @ dth[0]
    th = rod.thermal
    if th is not None and th.load is not None:
        work += float(np.sum(w * (np.sum(th.load[:, 0:3] * dr, axis=1)
                                  + np.sum(th.load[:, 3:6] * dth, axis=1))))
    return work


class Recorder:
    """Wraps :meth:`solver.centreline.CentrelineRod.step` to log every converged step's
    (t, ε, T, stored, W, |ΔU_el|)."""

    def __init__(self):
        self.rows = []
        self._step = C.CentrelineRod.step

    def __enter__(self):
        rec, step = self, self._step

        def logged(rod, old, h, landed=None):
            out = step(rod, old, h, landed)
            new = out[0]
            p_old, p_new = rod.problem(old.t), rod.problem(new.t)
            u0, t0, el0 = _stored(rod, old, p_old)
            u1, t1, el1 = _stored(rod, new, p_new)
            du_c = 0.0
            if rod.contact is not None:
                a3 = np.ascontiguousarray(st._rot(new.Y[:, 3:7])[:, :, 2])
                cand = rod.contact.search(np.ascontiguousarray(new.Y[:, 0:3]), a3)
                if cand is not None:
                    du_c = (rod.contact.potential(cand, new.Y[:, 0:3])
                            - rod.contact.potential(cand, old.Y[:, 0:3]))
            work = _work(rod, old, new, p_old, p_new)
            rec.rows.append((new.t, u1 - u0 + du_c - work, max(t0, t1), u1, work,
                             abs(el1 - el0)))
            return out

        C.CentrelineRod.step = logged
        return self

    def __exit__(self, *exc):
        C.CentrelineRod.step = self._step


def report(name, rows, floor):
    """One line per scale: the largest ε/scale, where, and the steps past 0.5."""
    t, eps, kin, stored, work, d_el = np.array(rows).T
    for share, c in ((1e-5, 0.0), (1e-4, 0.0), (1e-5, 0.01)):
        scale = np.maximum.reduce([kin, share * np.abs(stored), c * np.maximum(d_el, np.abs(work)),
                                   np.full_like(kin, floor)])
        rel = eps / scale
        i = int(np.argmax(rel))
        print(f"  {name}: scale max(T, {share:g} stored, {c:g} max(|dU_el|, |W|)): "
              f"largest eps/scale {rel[i]:.3g} at t = {t[i]:.4g} s (eps {eps[i]:.3g} J, "
              f"T {kin[i]:.3g} J, W {work[i]:.3g} J); steps past 0.5: {(rel > 0.5).sum()} "
              f"of {len(t)}; sum of eps {eps.sum():.3g} J")


def _centreline(spec, **numerics):
    spec = dict(spec)
    spec["numerics"] = dict(spec["numerics"], formulation="centreline",
                            energy_tolerance=None, **numerics)
    return Case.model_validate(spec)


def measure(name, case):
    """Run ``case`` with the steps logged and print the report."""
    t0 = time.perf_counter()
    with Recorder() as rec:
        try:
            status = integrate(case).attrs["hockle_status"]
        except Exception as exc:                      # noqa: BLE001 (a study: report it)
            status = f"{type(exc).__name__}: {exc}"[:120]
    print(f"{name}: {status}, {time.perf_counter() - t0:.1f} s of wall")
    if rec.rows:
        rod = case.rod
        ei = rod.youngs_modulus * np.pi * float(np.max(rod.diameter)) ** 4 / 64
        report(name, rec.rows, 1e-9 * ei / rod.length)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=["cantilever", "cable", "rest", "hockle"])
    only = ap.parse_args(argv).only
    if only in (None, "cantilever"):
        for dt in (0.1, 0.02):
            measure(f"dead-load cantilever, dt {dt}",
                    EC.cantilever(dt, n=50, energy_tolerance=None, formulation="centreline"))
        measure("dead-load cantilever, rho_inf 1, dt 0.005, 10 segments",
                EC.cantilever(0.005, n=10, t_end=0.4, rho_inf=1.0, energy_tolerance=None,
                              formulation="centreline"))
    if only in (None, "cable"):
        for dt in (0.2, 0.05):
            measure(f"soft hanging cable, dt {dt}", _centreline(LV.catenary_spec(dt, None)))
    if only in (None, "rest"):
        measure("cable resting on the bottom, dt 1e-4",
                _centreline(SB._spec({"elevation": -SB.D / 2}, dt=1e-4, t_end=0.05)))
    if only in (None, "hockle"):
        spec = Case.from_file(ROOT / "cases" / "seabed-hockle.yaml").model_dump(mode="json")
        measure("seabed-hockle to 3 s", _centreline(spec, t_end=3.0))


if __name__ == "__main__":
    main()
