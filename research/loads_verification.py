"""The verification figures of point loads, initial shapes and global-frame ends
(issue 37), printed: the cantilever under a dead tip load against Mattiasson's table and
its order in Δs, the follower tip load against its own elastica, the hanging cable
against the catenary and the towed rod against the integrated Morison drag.

Run: ``PYTHONPATH=$PWD python -m research.loads_verification`` (about 10 s after the
kernels are compiled). The cases are those of tests/solver/test_point_loads.py and
tests/solver/test_global_ends.py, which assert the bounds (docs/case-spec.md quotes the
figures); this prints what they measure.
"""
from __future__ import annotations

import math

import numpy as np

import test_global_ends as G
from test_global_ends import catenary_spec  # noqa: F401 (energy_check reads it here)
import test_point_loads as P
from hockle.api import catenary_parameter
from solver.case import Case
from solver.simulation import integrate


def mattiasson():
    for load in (1, 2, 10):
        w, x, _ = P.settled_tip(P.cantilever(load, 100))
        wr, xr = P.MATTIASSON[load]
        print(f"dead tip load P L²/EI = {load:2d}, 100 segments: w/L = {w:.6f} "
              f"({(w / wr - 1) * 100:+.4f} %), x/L = {x:.6f} ({(x / xr - 1) * 100:+.4f} %)")
    wr, xr = P.tip_elastica(1.0)
    errs = [math.hypot(*(np.array(P.settled_tip(P.cantilever(1, n))[:2]) - (wr, xr)))
            for n in (10, 20, 40)]
    orders = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    print(f"dead tip load 1, tip error at 10/20/40 segments: "
          f"{', '.join(f'{e:.3e}' for e in errs)} (orders {orders[0]:.3f}, {orders[1]:.3f})")


def follower():
    wr, xr = P.tip_elastica(2.0, follower=True)
    for n in (25, 50, 100):
        w, x, _ = P.settled_tip(P.cantilever(2, n, body=True))
        print(f"follower tip load P L²/EI = 2, {n:3d} segments: w/L = {w:.6f} "
              f"({(w / wr - 1) * 100:+.4f} %), x/L = {x:.6f} ({(x / xr - 1) * 100:+.4f} %)")


def catenary():
    L, X, D, rho, rho_f = 1.0, 0.8, 0.01, 7800.0, 1000.0
    case = Case.model_validate(catenary_spec())
    ds = integrate(case)
    start_end = np.linalg.norm(ds.position.values[0, -1]
                               - np.asarray(case.initial.centreline.points[-1]))
    print(f"catenary, 40 segments: the start's s = L end {start_end:.2g} m from the arc's "
          "last point (the space route of the resampled κ)")
    a = catenary_parameter(L, X)
    sag = a * (math.cosh(X / (2 * a)) - 1)
    w = (rho - rho_f) * math.pi * D**2 / 4 * 9.81
    tension = w * a * math.cosh(X / (2 * a))
    z = ds.position.values[:, :, 2]
    f = ds.f.values[-1]
    print(f"catenary, 40 segments: start sag {(-z[0].min() / sag - 1) * 100:+.2f} % off, "
          f"settled sag {-z[-1].min():.6f} m against {sag:.6f} "
          f"({(-z[-1].min() / sag - 1) * 100:+.3f} %), end tensions "
          f"{(np.linalg.norm(f[0]) / tension - 1) * 100:+.3f} %, "
          f"{(np.linalg.norm(f[-1]) / tension - 1) * 100:+.3f} %, pins' pull H "
          f"{(-ds.reaction_force_start.values[-1][0] / (w * a) - 1) * 100:+.3f} %")


def tow():
    U, D, rho_f, cdt = 0.5, 0.02, 1000.0, 0.05
    d = np.array([1.0, 0.0, 1.0]) / math.sqrt(2)
    start = {"frame": "global",
             "translation": [{"velocity": {"t": [0.0, 1.0], "value": [0.0, v]}}
                             for v in -U * d], "rotation": G.FIXED}
    spec = G._spec(start, G.FREE, fluid={"density": rho_f, "added_mass_coefficient": 1.0,
                                         "drag_coefficient_normal": 1.2,
                                         "drag_coefficient_tangential": cdt},
                   initial={"tangent": d.tolist(), "normal": [d[2], 0.0, -d[0]]},
                   output={"fields": ["f"]})
    spec["numerics"] = {"n_segments": 20, "dt": 0.05, "t_end": 3.0, "rho_inf": 0.5}
    ds = integrate(Case.model_validate(spec))
    expected = 0.5 * rho_f * math.pi * D * cdt * U**2 * 1.0
    print(f"towed rod: tension at the tow point / integrated Morison drag = "
          f"{ds.f.values[-1, 0, 2] / expected:.10f}")


if __name__ == "__main__":
    mattiasson()
    follower()
    catenary()
    tow()
