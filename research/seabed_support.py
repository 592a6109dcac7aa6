"""How evenly the sea floor carries a cable lying on it (issue 38): cases/catenary-
touchdown.yaml run to 20 s (its pull ramps from 2 to 12 s), printing at 1, 2, 3, 5, 10,
15 and 20 s over the lying part (the nodes 0.3 m or more short of the last touching
cell): the range of the nodes' reaction and of the cells' over the submerged weight w,
the cells carrying less than w/4, the largest second difference of the node heights
(the time route's odd-even mode), the largest distance between the output `position`
(integrated from κ) and the time route (`position_route_difference`), and the Newton
iterations so far. docs/seabed.md, "Per cell", quotes its figures.

Run: ``PYTHONPATH=$PWD python -m research.seabed_support`` (a few seconds).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from solver.case import Case
from solver.kinematics import quat_to_matrix
from solver.run import RodRun

CASE = Path(__file__).resolve().parents[1] / "cases" / "catenary-touchdown.yaml"


def main():
    case = Case.from_file(CASE)
    run = RodRun(case)
    dt = case.numerics.dt
    w = 500.0 * np.pi * 0.01**2 * 9.81
    marks = {int(round(t / dt)) for t in (1, 2, 3, 5, 10, 15, 20)}
    its = 0
    s = run.props.s
    for k in range(1, int(round(20.0 / dt)) + 1):
        run.advance(k * dt)
        its += run.last_iterations
        if k not in marks:
            continue
        Fn = run.seabed_loads()[0]
        F, _, pc = run.system.seabed.cell_loads(run.state.r_time, run.state.v_global_time,
                                         quat_to_matrix(run.state.q_time), run.state.Y[:, 3:6])
        end = 0.5 * (s[:-1] + s[1:])[pc > 0].max()
        lying = np.flatnonzero(s < end - 0.3)
        nodes = Fn[lying, 2] / w
        cells = F[lying[:-1], 2] / w
        z = run.state.r_time[lying, 2]
        zig = np.abs(z[1:-1] - 0.5 * (z[:-2] + z[2:])).max()
        route = np.linalg.norm(run.state.r - run.state.r_time, axis=1).max()
        print(f"t = {run.state.t:5.2f} s  lying nodes {lying.size:2d}  nodes' reaction/w "
              f"{nodes.min():.3f}-{nodes.max():.3f}  cells' {cells.min():.3f}-{cells.max():.3f}"
              f"  cells < w/4: {np.sum(cells < 0.25):2d}  node heights' 2nd difference "
              f"{zig * 1e6:6.1f} um  route difference {route * 1e3:.2f} mm  Newton its {its}")


if __name__ == "__main__":
    main()
