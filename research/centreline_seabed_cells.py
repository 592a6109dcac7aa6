"""Does the sea floor's law per cell (at each cell's midpoint, as the seed scheme takes it:
docs/seabed.md, "Per cell") cure the centreline scheme's Newton failures where a cable
touches down? A prototype, patched over :class:`solver.centreline.CentrelineRod` for the
run of this script only (the statics keep their nodal spring; nothing here is the
product's).

The centreline scheme applies the law at the nodes, and its box rule sees a node's load
only through the means of the two cells beside it (``residual``: h/2 (L_i + L_i+1) per
cell), the seed scheme's first, nodal, law's flaw: loads alternating from node to node are
invisible to the rows. On cases/catenary-touchdown.yaml the nodes at the touchdown take
penetrations alternating in sign (+7e-5, −7e-5, +1.7e-4, −4e-5 m against w/k = 5e-7 m),
Newton cycles between two iterates there, and the run cuts Δt 3-4 times every step (to
1 s: 61 156 factorisations, 895 refused attempts). Here each cell's rows take h L(x̄) of
the law at the cell's midpoint state: x̄, ū, Ω̄ the means of the cell's two nodes and the
tangent their mean normalised (the position rows make it the chord), with the exact
derivative through both nodes.

Run: ``python -m research.centreline_seabed_cells [--only touchdown|hockle] [--t-end T]``;
prints per variant (nodal, per cell): status, wall, step attempts refused, factorisations.
"""
from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

import numpy as np

from solver import centreline as C
from solver import centreline_run as CR
from solver import statics as st
from solver.case import Case
from solver.centreline_loads import node_motion_kernel
from solver.seabed import seabed_points, to_nodes
from solver.static_band import KL, KU
from solver.simulation import integrate

ROOT = Path(__file__).resolve().parents[1]
NV = st.NV


def cell_terms(rod, Y, old, co, want):
    """The law at the cells' midpoints: (loads (N, 6) per length, (normal, friction,
    moment (N, 3), penetration (N,)), None or the derivative blocks (N, 6, 7) by the
    left and by the right node's (r, p))."""
    if rod.seabed is None:
        return None
    n1 = rod.n
    nc = n1 - 1
    Yr = np.ascontiguousarray(np.real(Y), dtype=float)
    u, Om, t = np.empty((n1, 3)), np.empty((n1, 3)), np.empty((n1, 3))
    dOm, dtn = (np.empty((n1, 3, 4)), np.empty((n1, 3, 4))) if want else (
        np.empty((0, 3, 4)), np.empty((0, 3, 4)))
    node_motion_kernel(Yr, old.Y, float(co.cX), np.ascontiguousarray(co.dX, dtype=float),
                       bool(want), u, Om, t, dOm, dtn)
    mid = lambda a: np.ascontiguousarray(0.5 * (a[:-1] + a[1:]))      # noqa: E731
    x, uc, Oc, tr = mid(Yr[:, 0:3]), mid(u), mid(Om), mid(t)
    norm = np.linalg.norm(tr, axis=1)
    tc = np.ascontiguousarray(tr / norm[:, None])
    radius = mid(np.broadcast_to(rod.seabed.radius, (n1,)).astype(float))
    F, M = np.empty((nc, 6)), np.empty((nc, 3))
    DF, DM = np.empty((nc, 3, 12)), np.empty((nc, 3, 12))
    pen = np.empty(nc)
    hold = rod.seabed_hold if rod.seabed_hold is not None else np.zeros(nc, bool)
    data = rod._frictionless_data if rod._frictionless else rod.seabed.data
    seabed_points(x, uc, Oc, tc, radius, data, bool(want), hold, F, M, DF, DM, pen)
    L = np.concatenate([F[:, 0:3] + F[:, 3:6], M], axis=1)
    split = (F[:, 0:3], F[:, 3:6], M, pen)
    if not want:
        return L, split, None
    proj = (np.eye(3) - tc[:, :, None] * tc[:, None, :]) / norm[:, None, None]
    D = np.concatenate([DF, DM], axis=1)
    blocks = []
    for k in (slice(0, -1), slice(1, None)):          # the left node, the right node
        chain = np.zeros((nc, 12, 7))
        chain[:, 0:3, 0:3] = 0.5 * np.eye(3)
        chain[:, 3:6, 0:3] = 0.5 * co.cX * np.eye(3)
        chain[:, 6:9, 3:7] = 0.5 * dOm[k]
        chain[:, 9:12, 3:7] = 0.5 * np.einsum("kij,kjl->kil", proj, dtn[k])
        blocks.append(np.einsum("kij,kjl->kil", D, chain))
    return L, split, tuple(blocks)


def residual(rod, Y, old, co, prob, seabed=None):
    """:meth:`solver.centreline.CentrelineRod.residual` with the sea floor per cell."""
    try:
        G = st.residual(Y, prob)
    except st.StaticsError as exc:
        raise C.StepFailure(str(exc)) from exc
    L = rod.nodal_loads(Y, old, co)[0]
    if rod.contact is not None:
        L[:, 0:3] += rod.contact_terms(Y, old, co, want=False)[0]
    cells = G[st.N_START:-st.N_END].reshape(rod.n - 1, NV)
    cells[:, 7:13] += 0.5 * rod.h * (L[:-1] + L[1:])
    sb = rod.seabed_terms(Y, old, co, want=False) if seabed is None else seabed
    if sb is not None:
        cells[:, 7:13] += rod.h * sb[0]
    return G


def jacobian(rod, Y, old, co, prob):
    """:meth:`solver.centreline.CentrelineRod.jacobian` with the sea floor per cell."""
    ab = st.band_jacobian(Y, st.without_pair_loads(prob))
    block = rod.nodal_loads(Y, old, co, want=True)[1]
    rows, cols, nodes = rod._band_at
    ab[rows, cols] += 0.5 * rod.h * block[nodes].ravel()
    sb = rod.seabed_terms(Y, old, co, want=True)
    if sb is not None:
        nc = rod.n - 1
        i = np.arange(nc)[:, None, None]
        a = np.arange(6)[None, :, None]
        b = np.arange(7)[None, None, :]
        r = st.N_START + NV * i + 7 + a + 0 * b
        for shift, blk in zip((0, 1), sb[2]):
            c = NV * (i + shift) + b + 0 * a
            np.add.at(ab, (KL + KU + r - c, c), rod.h * blk)
    return ab


def seabed_split(run, state):
    """The run's node outputs of the cells' loads (:func:`solver.seabed.to_nodes`)."""
    co = C._Coefficients(0.0, state.Xd, 0.0, state.X)          # X = 0·Δ + X: its own
    Fn, Ff, M, pen = cell_terms(run.rod, state.Y, state, co, False)[1]
    return to_nodes(Fn), to_nodes(Ff), to_nodes(M), to_nodes(pen)


@contextlib.contextmanager
def per_cell():
    """The prototype patched in for the block."""
    saved = (C.CentrelineRod.seabed_terms, C.CentrelineRod.residual,
             C.CentrelineRod.jacobian, CR.CentrelineRun._seabed_split)
    C.CentrelineRod.seabed_terms = cell_terms
    C.CentrelineRod.residual = residual
    C.CentrelineRod.jacobian = jacobian
    CR.CentrelineRun._seabed_split = seabed_split
    try:
        yield
    finally:
        (C.CentrelineRod.seabed_terms, C.CentrelineRod.residual,
         C.CentrelineRod.jacobian, CR.CentrelineRun._seabed_split) = saved


class Counted:
    """Counts the run's factorisations and refusals (the run object is built inside
    :func:`integrate`)."""

    def __enter__(self):
        self.runs = []
        self._init = CR.CentrelineRun.__init__
        runs, init = self.runs, self._init

        def counted(run, *a, **k):
            init(run, *a, **k)
            runs.append(run)

        CR.CentrelineRun.__init__ = counted
        return self

    def __exit__(self, *exc):
        CR.CentrelineRun.__init__ = self._init


def measure(name, case, variant):
    t0 = time.perf_counter()
    with Counted() as c, (per_cell() if variant == "per cell" else contextlib.nullcontext()):
        try:
            ds = integrate(case)
            status = f"{ds.attrs['hockle_status']} to {float(ds.time[-1]):.3g} s"
        except Exception as exc:                       # noqa: BLE001 (a study: report it)
            status = f"{type(exc).__name__}: {exc}"[:140]
            ds = None
    run = c.runs[-1] if c.runs else None
    refused = sum(run.control.refusals.values()) if run else -1
    fact = run.rod.factorizations if run else -1
    print(f"{name}, {variant}: {status}; {time.perf_counter() - t0:.1f} s of wall, "
          f"{refused} refused attempts, {fact} factorisations", flush=True)
    return ds


def _case(file, t_end):
    spec = Case.from_file(ROOT / "cases" / file).model_dump(mode="json")
    spec["numerics"].update(formulation="centreline", t_end=t_end)
    return Case.model_validate(spec)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=["touchdown", "hockle"])
    ap.add_argument("--t-end", type=float, default=None)
    args = ap.parse_args(argv)
    if args.only in (None, "touchdown"):
        case = _case("catenary-touchdown.yaml", args.t_end or 0.5)
        for variant in ("per cell", "nodal"):
            measure("catenary-touchdown", case, variant)
    if args.only in (None, "hockle"):
        case = _case("seabed-hockle.yaml", args.t_end or 3.0)
        for variant in ("per cell", "nodal"):
            measure("seabed-hockle", case, variant)


if __name__ == "__main__":
    main()
