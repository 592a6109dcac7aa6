"""Static equilibria and their continuation (solver/statics.py, solver/continuation.py)
against analytic results: Mattiasson's cantilever, Euler's clamped-clamped column and its
elastica, Greenhill's twisted rod; the unstable-mode counts; bad input."""
import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

from solver import statics as st
from solver.continuation import ContinuationError, branch_dataset, continuation
from solver.static_band import KL, KU, BorderedBandLU, band_storage, band_to_sparse

#: Mattiasson's table: P L²/EI -> (w/L, x/L) of the tip under a dead load
#: (also in tests/solver/test_point_loads.py, for the dynamic scheme)
MATTIASSON = {1: (0.30172, 0.94357), 2: (0.49346, 0.83936), 10: (0.81061, 0.44501)}
#: Greenhill: a clamped-clamped rod under a twisting moment M and no axial force buckles at
#: M L / B = 2.8606 π (Greenhill 1883; Love, Treatise §272; van der Heijden & Thompson 2000)
GREENHILL = 8.9868


def euler_column(P, N=100, B=(1.0, 2.0, 1.0), L=1.0):
    """Clamped at s = 0; at s = L clamped in rotation and laterally, sliding along z under
    the compressive force P (N). B1 < B2: the first buckling mode is simple."""
    return st.uniform(L, N, B, st.clamp([0, 0, 0], [1, 0, 0, 0]),
                      st.clamp([0, 0, L], [1, 0, 0, 0], held=(True, True, False),
                               force=(0, 0, -P)))


def test_jacobian_matches_central_differences():
    rng = np.random.default_rng(3)
    prob = st.uniform(1.0, 6, (1.0, 2.0, 0.7), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                      st.free_end([0.3, -0.2, 0.1]), load=(0.1, 0.0, -0.5))
    Y = rng.standard_normal((7, st.NV))
    J = st.jacobian(Y, prob).toarray()
    Jf = np.zeros_like(J)
    e = 1e-6
    for j in range(J.shape[1]):
        d = np.zeros(Y.size)
        d[j] = e
        Jf[:, j] = (st.residual(Y + d.reshape(Y.shape), prob)
                    - st.residual(Y - d.reshape(Y.shape), prob)) / (2 * e)
    assert np.max(np.abs(J - Jf)) < 1e-7 * np.max(np.abs(J))


def _random_problems(rng):
    """Problems whose end rows take every form: clamped, free, a held rotation with
    sliding translation, a non-uniform stiffness and a distributed load, and ends whose
    translation axes are turned, some held and some loaded, one frame held at a turned
    quaternion, the other free."""
    free = st.uniform(1.0, 6, (1.0, 2.0, 0.7), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                      st.free_end([0.3, -0.2, 0.1]), load=(0.1, 0.0, -0.5))
    twisted = st.uniform(1.0, 9, (1.0, 1.0, 0.7), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                         st.clamp([0, 0, 1.0], st.quat_axis_angle([0, 0, 1], 0.4), 0.4,
                                  held=(True, True, False), force=(0, 0, -0.3)))
    uneven = st.StaticProblem(length=2.0, n_segments=5,
                              stiffness=rng.uniform(0.5, 2.0, (6, 3)),
                              load=rng.standard_normal((6, 3)), start=free.start,
                              end=free.end)
    axes = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    turned = st.quat_axis_angle(rng.standard_normal(3), 1.1)
    skew = st.uniform(1.0, 5, (1.0, 1.5, 0.7),
                      st.EndSpec(axes=axes, held=np.array([True, False, True]),
                                 position=rng.standard_normal(3),
                                 force=rng.standard_normal(3), rotation_held=False,
                                 quaternion=np.array([1.0, 0, 0, 0])),
                      st.clamp([0.2, 0.1, 1.0], turned, 1.1, axes=axes.T,
                               held=(False, True, False), force=(0.1, 0.2, -0.3)))
    return free, twisted, uneven, skew


def test_band_jacobian_and_compiled_residual_are_the_sparse_ones():
    """The band Jacobian (compiled, closed form in r, n, m, complex step in p) is the
    sparse complex-step one to rounding, at random states (quaternions not unit); the
    compiled residual is the numpy one to rounding."""
    rng = np.random.default_rng(5)
    for prob in _random_problems(rng):
        Y = rng.standard_normal((prob.n_segments + 1, st.NV))
        J = st.jacobian(Y, prob).toarray()
        Jb = band_to_sparse(st.band_jacobian(Y, prob)[KL:]).toarray()
        assert np.max(np.abs(Jb - J)) <= 1e-13 * np.max(np.abs(J))
        G, Gc = st.residual(Y, prob), st.residual(Y.astype(complex), prob).real
        assert np.max(np.abs(G - Gc)) <= 1e-14 * np.max(np.abs(Gc))


def test_bordered_band_lu_solves_and_signs_as_the_sparse_lu():
    """Block elimination on the band LU (one or two borders) against scipy's sparse LU of
    the whole bordered matrix: the solution to 1e-10 and the determinant's sign; and with
    J singular to rounding (its bordered matrix regular, as at a fold), the refined solve
    leaves a residual of rounding size."""
    import scipy.sparse as sp

    rng = np.random.default_rng(7)
    for prob in _random_problems(rng):
        Y = st.solve(prob).Y if prob.n_segments != 5 else \
            rng.standard_normal((6, st.NV))
        J = st.jacobian(Y, prob)
        n = J.shape[0]
        for k in (1, 2):
            W, C, D = rng.standard_normal((n, k)), rng.standard_normal((n, k)), np.zeros((k, k))
            A = sp.bmat([[J, sp.csc_matrix(W)], [sp.csc_matrix(C.T), sp.csc_matrix(D)]],
                        format="csc")
            lu, ref = BorderedBandLU(st.band_jacobian(Y, prob), W, C, D), st.factor(A)
            b = rng.standard_normal(n + k)
            assert np.allclose(lu.solve(b), ref.solve(b), rtol=1e-10, atol=1e-10)
            assert lu.det_sign == st.lu_det_sign(ref)
    # J singular to rounding: one diagonal entry moved by 1/(J⁻¹)_ii (Sherman-Morrison)
    prob = _random_problems(rng)[0]
    Y = rng.standard_normal((prob.n_segments + 1, st.NV))
    Jd = st.jacobian(Y, prob).toarray()
    i = int(np.argmax(np.abs(np.diag(np.linalg.inv(Jd)))))
    Jd[i, i] -= 1.0 / np.linalg.inv(Jd)[i, i]
    assert np.linalg.svd(Jd, compute_uv=False)[-1] < 1e-13 * np.linalg.norm(Jd, 2)
    ab = band_storage(Jd.shape[0])
    for i, j in zip(*np.nonzero(Jd)):
        ab[KL + KU + i - j, j] = Jd[i, j]
    null = np.linalg.svd(Jd)[2][-1]
    g, c = rng.standard_normal(Jd.shape[0]), null + 0.1 * rng.standard_normal(Jd.shape[0])
    A = np.block([[Jd, g[:, None]], [c[None, :], np.zeros((1, 1))]])
    b = rng.standard_normal(A.shape[0])
    lu = BorderedBandLU(ab, g, c)
    for refine in (True, False):      # unrefined only where J is well conditioned
        assert np.max(np.abs(A @ lu.solve(b, refine=refine) - b)) < 1e-10 * np.max(np.abs(b))


def test_nearest_eigenvalues_counts_a_double_eigenvalue_twice():
    """A single-vector Krylov search finds a double eigenvalue once where the start vector
    is symmetric in its eigenspace; the deflated, checked search finds the copy, and no
    spurious one: a diagonal operator (1, 1, 1/3, ...) and the same made non-normal by an
    upper-triangular similarity, against the exact spectra."""
    import scipy.sparse.linalg as spla

    n = 60
    d = 1.0 / (1.0 + np.arange(n))
    d[1] = d[0]
    diag = spla.LinearOperator((n, n), matvec=lambda x: d * x, dtype=float)
    plain = spla.eigs(diag, k=4, which="LM", return_eigenvectors=False, v0=np.ones(n))
    assert np.sum(np.isclose(plain.real, 1.0)) == 1          # the copy is missed
    assert np.allclose(np.sort(st.nearest_eigenvalues(diag, n, 4).real)[::-1],
                       [1.0, 1.0, 1 / 3, 1 / 4])
    rng = np.random.default_rng(0)
    S = np.eye(n) + 0.3 * np.triu(rng.standard_normal((n, n)), 1)
    A = S @ np.diag(d) @ np.linalg.inv(S)
    dense = spla.LinearOperator((n, n), matvec=lambda x: A @ x, dtype=float)
    assert np.allclose(np.sort(st.nearest_eigenvalues(dense, n, 4).real)[::-1],
                       [1.0, 1.0, 1 / 3, 1 / 4])


def test_round_column_pair_counts_two_with_the_band_lu():
    """The round column past its pair (1.03 P_c, 100 segments): two unstable modes with
    the band LU's solves, the pair's two equal eigenvalues both in the list."""
    P = 1.03 * 4 * np.pi**2
    prob = st.uniform(1.0, 100, (1.0, 1.0, 0.8), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                      st.clamp([0, 0, 1.0], [1, 0, 0, 0], held=(True, True, False),
                               force=(0, 0, -P)))
    Y = st.straight_guess(prob)
    Y[:, 9] = -P                     # the straight column's internal force, exact
    assert np.abs(st.residual(Y, prob)).max() < 1e-12
    count, mu = st.unstable_modes(Y, prob, lu=st.factor_jacobian(Y, prob))
    assert count == 2 and np.isclose(mu[0].real, mu[1].real, rtol=1e-6)


@pytest.mark.parametrize("load", [1, 2, 10])
def test_cantilever_dead_tip_load_mattiasson(load):
    """Within 0.1 % of Mattiasson's table at 100 segments (measured 0.002-0.01 %)."""
    prob = st.uniform(1.0, 100, (1.0, 1.0, 0.8), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                      st.free_end([-load, 0, 0]))
    sol = st.solve(prob)
    w, x = -sol.Y[-1, 0], sol.Y[-1, 2]
    w_ref, x_ref = MATTIASSON[load]
    assert abs(w / w_ref - 1) < 1e-3 and abs(x / x_ref - 1) < 1e-3
    assert np.allclose(np.linalg.norm(sol.Y[:, 3:7], axis=1), 1.0, atol=1e-12)


def test_euler_branch_point_modes_and_elastica():
    """First branch point at 4π²B/L² within 0.1 % at 100 segments; 0 unstable modes below
    it, 1 above on the straight branch, 0 on the buckled branch; end shortening of the
    elastica against the elliptic-integral solution within 0.5 % from P = 1.25 P_c."""
    pc = 4 * np.pi**2
    br = continuation(lambda P: euler_column(P), 0.0, 1.5 * pc, switch=True, max_points=80)
    assert br.stopped == "reached the target value"
    bps = [b for b in br.bifurcations if b.kind == "branch_point"]
    assert len(bps) == 1 and bps[0].simple
    assert abs(bps[0].parameter / pc - 1) < 1e-3
    k = br.switched_at
    P = np.asarray(br.parameter)
    u = np.asarray(br.unstable)
    assert np.all(u[:k][P[:k] < bps[0].parameter] == 0)
    assert u[k] == 1 and P[k] > bps[0].parameter       # straight, just past the branch point
    assert np.all(u[k + 1:] == 0)                       # the buckled branch is stable

    def shortening(p):   # clamped-clamped: K(m) = (L/4)√(P/B), Δ/L = 2(1 − E/K)
        m = brentq(lambda m: ellipk(m) - 0.25 * np.sqrt(p), 0.0, 1 - 1e-15)
        return 2 * (1 - ellipe(m) / ellipk(m))

    checked = 0
    for p, Y in zip(P[k + 1:], br.Y[k + 1:]):
        if p >= 1.25 * pc:
            assert abs((1 - (Y[-1, 2] - Y[0, 2])) / shortening(p) - 1) < 5e-3
            checked += 1
    assert checked >= 3


def test_greenhill_twisted_rod():
    """Branch point at M L/B = 8.9868 within 0.1 % (M = GJ Θ/L on the straight branch);
    the helical pair of an isotropic rod: two modes become unstable together."""
    L, B, C = 1.0, 1.0, 1.0 / 1.3

    def prob(theta):
        return st.uniform(L, 100, (B, B, C), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                          st.clamp([0, 0, L], st.quat_axis_angle([0, 0, 1], theta), theta,
                                   held=(True, True, False)))

    tc = GREENHILL * B / C
    br = continuation(prob, 0.0, 1.2 * tc, max_points=60)
    bps = [b for b in br.bifurcations if b.kind == "branch_point"]
    assert len(bps) == 1 and not bps[0].simple
    assert abs(bps[0].parameter * C / B / GREENHILL - 1) < 1e-3
    u = np.asarray(br.unstable)
    assert set(u[: bps[0].after + 1]) == {0} and set(u[bps[0].after + 1:]) == {2}
    ds = branch_dataset(br, "theta")
    M = ds["end_moment"].sel(xyz="z").values
    straight = ds["parameter"].values < tc
    assert np.allclose(M[straight], C * ds["parameter"].values[straight] / L, rtol=1e-3)
    assert ds["bifurcation_kind"].values.tolist() == ["branch_point"]
    assert np.allclose(ds["link"], ds["parameter"] / (2 * np.pi))
    assert np.allclose(ds["twist"][straight], ds["link"][straight], rtol=1e-3)


def greenhill(theta, N=100, L=1.0, B=1.0, C=1.0 / 1.3):
    """Clamped-clamped round rod (B1 = B2 = B, GJ = C), the end turned by theta about the
    axis and free to slide along it (no axial force)."""
    return st.uniform(L, N, (B, B, C), st.clamp([0, 0, 0], [1, 0, 0, 0]),
                      st.clamp([0, 0, L], st.quat_axis_angle([0, 0, 1], theta), theta,
                               held=(True, True, False)))


def test_greenhill_switches_onto_the_buckled_branch_of_the_pair():
    """At Greenhill's pair (a double zero eigenvalue) --switch leaves the straight rod along
    one mode of the pair, the phase condition fixing the rotation about the axis: every
    switched point is an equilibrium (residual at rounding, the unfolding ε = 0), its lateral
    displacement grows from 0 past 0.15 L, and it has 1 unstable mode (the neutral
    rotation about the axis left out) between the straight rod's 0 before the pair and 2
    after it; the end rotation decreases along it (measured: subcritical). A resume after
    the switch repeats it to the last bit."""
    B, C = 1.0, 1.0 / 1.3
    run = dict(max_points=40, switch=True)
    br = continuation(lambda a: greenhill(a, N=40), 0.0, 1.2 * GREENHILL * B / C, **run)
    [bp] = br.bifurcations
    assert not bp.simple and abs(bp.parameter * C / B / GREENHILL - 1) < 5e-3
    k = br.switched_at
    assert k == bp.after + 1 and br.unstable[k - 1] == 0 and br.unstable[k] == 2
    lam = np.asarray(br.parameter[k + 1:])
    amp = np.array([np.abs(Y[:, 0:2]).max() for Y in br.Y[k + 1:]])
    assert len(lam) >= 15 and amp[0] < 0.01 and amp[-1] > 0.15 and np.all(np.diff(amp) > 0)
    assert np.all(lam < bp.parameter) and np.all(np.diff(lam) < 0)
    assert set(br.unstable[k + 1:]) == {1}
    for a, Y in zip(lam, br.Y[k + 1:]):
        assert np.abs(st.residual(Y, greenhill(a, N=40))).max() < 1e-12
    ds = branch_dataset(br, "theta")
    assert ds["branch"].values.tolist() == [0] * (k + 1) + [1] * len(lam)
    states, seen = [], []
    continuation(lambda a: greenhill(a, N=40), 0.0, 1.2 * GREENHILL * B / C, **run,
                 should_stop=lambda: len(seen) >= k + 4 and "stop",
                 checkpoint=states.append, on_point=lambda i, x: seen.append(i))
    again = continuation(lambda a: greenhill(a, N=40), 0.0, 1.2 * GREENHILL * B / C, **run,
                         resume=states[-1])
    _same_branch(again, br)


def test_a_round_column_switches_at_its_pair_onto_the_elastica():
    """B1 = B2: Euler's first branch point is a pair (buckling in any plane through the
    axis); --switch leaves it along one mode with the phase condition and the branch is
    the clamped-clamped elastica: end shortening within 0.5 % of the elliptic-integral
    solution from P = 1.25 P_c (100 segments), as for the simple branch point of B1 < B2
    above."""
    pc = 4 * np.pi**2
    br = continuation(lambda P: euler_column(P, B=(1.0, 1.0, 1 / 1.3)), 0.0, 1.35 * pc,
                      switch=True, max_points=60)
    [bp] = br.bifurcations
    assert not bp.simple and abs(bp.parameter / pc - 1) < 1e-3
    k = br.switched_at
    assert k is not None and set(br.unstable[k + 1:]) == {0}

    def shortening(p):
        m = brentq(lambda m: ellipk(m) - 0.25 * np.sqrt(p), 0.0, 1 - 1e-15)
        return 2 * (1 - ellipe(m) / ellipk(m))

    checked = [abs((1 - (Y[-1, 2] - Y[0, 2])) / shortening(p) - 1)
               for p, Y in zip(br.parameter[k + 1:], br.Y[k + 1:]) if p >= 1.25 * pc]
    assert len(checked) >= 2 and max(checked) < 5e-3


def _same_branch(a, b):
    assert len(a.parameter) == len(b.parameter) and a.stopped == b.stopped
    assert a.parameter == b.parameter and a.unstable == b.unstable
    assert all(np.array_equal(x, y) for x, y in zip(a.Y, b.Y))
    assert np.array_equal(a.mu, b.mu, equal_nan=True) and a.switched_at == b.switched_at
    assert [(f.kind, f.parameter) for f in a.bifurcations] == \
        [(f.kind, f.parameter) for f in b.bifurcations]


@pytest.mark.parametrize("stop_after", [3, 14])        # before and after the switch
def test_a_resumed_continuation_repeats_the_uninterrupted_one(stop_after):
    """Stopped after ``stop_after`` points (should_stop, as a worker's shutdown does) and
    resumed from the last state handed to ``checkpoint`` (through BranchCheckpoint's
    bytes): the branch equals the uninterrupted one to the last bit, switch included."""
    from solver.checkpoint import BranchCheckpoint, CheckpointError

    pc = 4 * np.pi**2
    run = dict(switch=True, max_points=25, ds_max=0.1)
    whole = continuation(lambda P: euler_column(P, N=20), 0.0, 1.5 * pc, **run)
    assert whole.switched_at is not None and 3 < whole.switched_at < 14 < len(whole.Y)
    states, seen = [], []
    first = continuation(lambda P: euler_column(P, N=20), 0.0, 1.5 * pc, **run,
                         should_stop=lambda: len(seen) >= stop_after and "shutdown",
                         checkpoint=states.append, on_point=lambda i, lam: seen.append(i))
    assert first.stopped == "stopped: shutdown" and len(first.parameter) == stop_after
    data = BranchCheckpoint("k", states[-1]).dumps()
    ck = BranchCheckpoint.loads(data, "k")
    assert ck.points == stop_after and ck.parameter == first.parameter[-1]
    with pytest.raises(CheckpointError, match="another continuation"):
        BranchCheckpoint.loads(data, "other")
    with pytest.raises(CheckpointError, match="not a hockle branch checkpoint"):
        BranchCheckpoint.loads(b"{}\n", "k")
    again = continuation(lambda P: euler_column(P, N=20), 0.0, 1.5 * pc, **run,
                         resume=ck.state)
    _same_branch(again, whole)
    with pytest.raises(ContinuationError, match="grid"):
        continuation(lambda P: euler_column(P, N=10), 0.0, 1.5 * pc, **run, resume=ck.state)


def test_an_exception_mid_branch_keeps_the_points_so_far():
    """An unexpected exception at the sixth point leaves with the five before it."""
    pc = 4 * np.pi**2
    calls = []

    def prob(P):
        calls.append(P)
        if len(set(calls)) > 40:
            raise RuntimeError("lost the mesh")
        return euler_column(P, N=20)

    seen = []
    with pytest.raises(RuntimeError, match="lost the mesh") as info:
        continuation(prob, 0.0, 1.5 * pc, max_points=60,
                     on_point=lambda i, lam: seen.append(lam))
    partial = info.value.partial_branch
    assert partial.parameter == seen and len(seen) >= 2
    assert partial.stopped == "failed: RuntimeError: lost the mesh"
    ds = branch_dataset(partial, "P")
    assert ds.sizes["point"] == len(seen)


def test_bad_input_refused_before_work():
    with pytest.raises(ContinuationError, match="does not move"):
        continuation(lambda P: euler_column(P, N=10), 1.0, 1.0)
    # both ends free: a rigid-body motion, no unique equilibrium
    free = st.uniform(1.0, 10, (1, 1, 1), st.free_end(), st.free_end())
    with pytest.raises(ContinuationError, match="singular"):
        continuation(lambda a: free, 0.0, 1.0)


# --------------------------------------------------------------------------- from a case

def _column_case(n=40):
    from pathlib import Path

    from solver.case import parse_text

    doc = parse_text(Path("cases/euler-column.yaml").read_text(), "yaml")
    doc["numerics"]["n_segments"] = n
    return doc


FORCE = "boundary.end.translation.2.force"


def test_case_static_problem_and_equilibrium():
    """The example case: EJ from the diameter, the end force read in the end's body frame,
    the equilibrium straight and stable under 0.1 N of compression."""
    from hockle.api import equilibrium
    from solver.case import Case

    case = Case.model_validate(_column_case())
    prob = st.static_problem(case)
    ej = 2.0e8 * np.pi * 0.005**4 / 64
    assert np.allclose(prob.stiffness[:, 0], ej) and np.allclose(prob.stiffness[:, 2], ej / 1.25)
    assert list(prob.end.held) == [True, True, False] and prob.end.force[2] == -0.1
    ds = equilibrium(case)
    assert ds["unstable_modes"].values.tolist() == [0]
    assert np.allclose(ds["end_force"].values[0], [0, 0, -0.1])
    assert abs(ds["end_position"].values[0, 2] - 1.0) < 1e-12      # inextensible


def test_cli_continue_and_plot(tmp_path, capsys):
    """hockle continue: the round column's first branch point (a pair of modes) at
    -4π² EJ/L² within 0.1 %, written for hockle plot; bad input exits 2 before any work."""
    import json

    from hockle.cli import main
    from hockle.io import open_result

    path = tmp_path / "column.json"
    path.write_text(json.dumps(_column_case(100)))
    out = tmp_path / "branch.nc"
    assert main(["continue", str(path), "--parameter", FORCE, "--to", "-0.3", "-q",
                 "-o", str(out)]) == 0
    ds = open_result(out)
    pc = -4 * np.pi**2 * 2.0e8 * np.pi * 0.005**4 / 64
    assert ds["bifurcation_kind"].values.tolist() == ["branch_point"]
    assert abs(float(ds["bifurcation_parameter"][0]) / pc - 1) < 1e-3
    assert ds["bifurcation_simple"].values.tolist() == [0]
    u = ds["unstable_modes"].values
    assert u[0] == 0 and u[-1] == 2
    assert ds.attrs["parameter_path"] == FORCE and ds["position"].dims == ("point", "node", "xyz")
    assert main(["plot", str(out), "-o", str(tmp_path / "plots")]) == 0
    assert (tmp_path / "plots" / "branch_bifurcation.png").stat().st_size > 0
    capsys.readouterr()
    for argv, words in (([FORCE[:-6], "--to", "1"], "not a scalar"),
                        (["rod.nowhere", "--to", "1"], "not a field"),
                        ([FORCE, "--to", "-0.1"], "does not move"),
                        (["rod.diameter", "--to", "-1"], "invalid")):
        assert main(["continue", str(path), "--parameter", *argv, "-q",
                     "-o", str(tmp_path / "x.nc")]) == 2
        assert words in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()


def test_dynamic_run_starts_from_the_equilibrium():
    """A cantilever under gravity started at rest in its static equilibrium stays there:
    its largest velocity over five steps is below 1e-3 of that of the same run started
    straight (measured 3.1e-4 m/s against 0.56 m/s; the rest is the O(Δs²) difference
    between the static and the dynamic box rule); with its critical mode added, the start
    moves off the equilibrium by the amplitude asked for."""
    from hockle.api import equilibrium_start, simulate

    doc = {
        "schema_version": 1, "name": "cantilever-gravity",
        "rod": {"length": 1.0, "youngs_modulus": 2.0e8, "shear_modulus": 8.0e7,
                "density": 1500.0, "diameter": 0.01},
        "gravity": [-9.81, 0.0, 0.0],
        "initial": {"tangent": [0, 0, 1], "normal": [1, 0, 0]},
        "boundary": {
            "start": {"translation": [{"velocity": 0}] * 3,
                      "rotation": [{"angular_velocity": 0}] * 3},
            "end": {"translation": [{"force": 0}] * 3, "rotation": [{"moment": 0}] * 3}},
        "numerics": {"n_segments": 40, "dt": 0.01, "t_end": 0.05},
        "output": {"fields": ["v", "position"]},
    }
    start = equilibrium_start(doc)
    moved = simulate(doc, start=start)
    straight = simulate(doc)
    v_eq = float(np.abs(moved["v"].values).max())
    v_straight = float(np.abs(straight["v"].values).max())
    assert v_eq < 1e-3 * v_straight
    assert np.allclose(moved["position"].values[0], start.r)
    kicked = equilibrium_start(doc, amplitude=1e-3)
    assert abs(np.max(np.abs(kicked.r - start.r)) - 1e-3) < 1e-9


def test_case_ends_integrated_and_point_loads():
    """End rotations are ∫ω dt (a table integrated piecewise), held positions ∫v dt; an
    interior point load (linear regime) gives the cantilever's tip deflection
    P a²(3L − a)/(6EJ) within 0.1 % at 100 segments; a follower point load is refused."""
    from solver.case import Case

    doc = _column_case(100)
    doc["boundary"]["start"]["rotation"][2] = {"angular_velocity": {"t": [0, 1, 2],
                                                                    "value": [0, 2.0, 2.0]}}
    doc["boundary"]["start"]["translation"][2] = {"velocity": 0.01}
    doc["numerics"]["t_end"] = 2.0
    prob = st.static_problem(Case.model_validate(doc))
    assert prob.start.twist == pytest.approx(3.0)              # 1 + 2 rad
    assert np.allclose(prob.start.quaternion, st.quat_axis_angle([0, 0, 1], 3.0))
    assert np.allclose(prob.start.position, [0, 0, 0.02])
    cant = _column_case(100)
    cant["boundary"]["end"] = {"translation": [{"force": 0}] * 3, "rotation": [{"moment": 0}] * 3}
    P, a = 1e-5, 0.6
    cant["point_loads"] = [{"s": a, "value": [P, 0, 0]}]
    case = Case.model_validate(cant)
    prob = st.static_problem(case)
    Y = st.solve(prob).Y
    ej = prob.stiffness[0, 0]
    assert Y[-1, 0] == pytest.approx(P * a**2 * (3 - a) / (6 * ej), rel=1e-3)
    cant["point_loads"][0]["body"] = True
    with pytest.raises(st.StaticsError, match="point_loads.0.body"):
        st.static_problem(Case.model_validate(cant))


# --------------------------------------------------------------------------- contact, seabed

def _barrier(s, D=0.02, g_hat=0.004, kappa=1e4, rho_a=0.5):
    from solver.contact import SelfContact
    return SelfContact(dict(aperture=90.0, tolerance=0.04, k1=0, k2=0, k3=0, k4=0,
                            law="barrier", barrier_gap=g_hat, barrier_stiffness=kappa),
                       s, np.full(s.size, D), np.full(s.size, rho_a))


def _hairpin(N=100, L=1.0, D=0.02, g_hat=0.004, B=1e-5, q=1.0, rho_a=0.5, kappa=1e4):
    """A rod folded into a hairpin (arms along z, a half circle between them), clamped at
    s = 0, free at s = L, its arms pressed together by a dead load q (N/m) on each (away
    from the bend), and its guess (N+1, 13)."""
    s = np.linspace(0, L, N + 1)
    R = 0.5 * (D + 0.6 * g_hat)
    s1, s2 = 0.5 * (L - np.pi * R), 0.5 * (L + np.pi * R)
    load = np.zeros((N + 1, 3))
    load[s < s1 - 0.05, 0] = q
    load[s > s2 + 0.05, 0] = -q
    prob = st.StaticProblem(L, N, np.tile([B, B, 0.8 * B], (N + 1, 1)), load,
                            st.clamp([-R, 0, 0], [1, 0, 0, 0]), st.free_end(),
                            contact=_barrier(s, D, g_hat, kappa, rho_a))
    Y = np.zeros((N + 1, st.NV))
    for k, sk in enumerate(s):
        th = float(np.clip((sk - s1) / R, 0.0, np.pi))
        if sk < s1:
            Y[k, 0:3] = [-R, 0, sk]
        elif sk > s2:
            Y[k, 0:3] = [R, 0, L - sk]
        else:
            Y[k, 0:3] = [-R * np.cos(th), 0, s1 + R * np.sin(th)]
            Y[k, 11] = B / R
        Y[k, 3:7] = st.quat_axis_angle([0, 1, 0], th)
    return prob, Y


def _seabed(k=2e3, elevation=0.0, diameter=None):
    from solver.case import Seabed
    from solver.seabed import SeabedContact
    return SeabedContact(Seabed(elevation=elevation, normal_stiffness=k, normal_damping=50.0,
                                friction={"axial": 0.5, "lateral": 0.8}), diameter)


def test_contact_and_seabed_jacobian_match_central_differences():
    """The load Jacobians of self-contact (the dynamic model's pair derivatives) and the
    seabed (its kernel's derivative propagation) against central differences of the
    residual, on a hairpin with both strands inside the barrier and its lower nodes in
    the bottom: 1e-7 of the largest entry (the differences' own error)."""
    prob, Y = _hairpin(N=60)
    rng = np.random.default_rng(5)
    Y = Y + 1e-4 * rng.standard_normal(Y.shape)
    prob = st.with_load(prob, seabed=_seabed(elevation=0.1, diameter=np.full(61, 0.02)))
    assert np.any(st.contact_loads(Y, prob) != 0) and np.any(st.seabed_loads(Y, prob) != 0)
    J = st.jacobian(Y, prob)
    cols = [st.NV * k + c for k in range(Y.shape[0]) for c in range(3)]
    Jd = J[:, cols].toarray()
    Jf = np.zeros_like(Jd)
    e = 1e-7
    for n, j in enumerate(cols):
        d = np.zeros(Y.size)
        d[j] = e
        Jf[:, n] = (st.residual(Y + d.reshape(Y.shape), prob)
                    - st.residual(Y - d.reshape(Y.shape), prob)) / (2 * e)
    assert np.max(np.abs(Jd - Jf)) < 1e-7 * np.max(np.abs(Jd))


def test_pressed_hairpin_gap_is_the_barrier_law_s():
    """Two straight strands pressed together by q per unit length: in equilibrium each
    receives q from the other, so the gap solves ρĀ P(g) = q (the barrier law inverted,
    BarrierLaw.equilibrium_gap): within 1e-7 relative (measured 1.2e-8) at 100 segments; the
    equilibrium is stable. Along a branch in q from 1 to 4 N/m the gap follows the law
    within 1e-6 and stays inside (0, ĝ): the barrier holds."""
    from solver.contact.laws import BarrierLaw

    q0, rho_a, g_hat, D = 1.0, 0.5, 0.004, 0.02
    law = BarrierLaw(g_hat, 1e4, 0, 0, 1e-3 * D)
    prob, Y = _hairpin(q=q0)
    sol = st.solve(prob, Y, tol=1e-8, ramp=False, max_iterations=40)
    mid = 25
    gap = np.linalg.norm(sol.Y[mid, 0:3] - sol.Y[100 - mid, 0:3]) - D
    assert abs(gap / law.equilibrium_gap(q0 / rho_a) - 1) < 1e-7
    assert st.unstable_modes(sol.Y, prob)[0] == 0

    def at(q):
        return st.with_load(prob, load=prob.load * (q / q0))

    br = continuation(at, q0, 4.0, sol.Y, stability=False, tol=1e-6, max_points=60)
    assert br.stopped == "reached the target value" and len(br.parameter) > 3
    for q, Yq in zip(br.parameter, br.Y):
        g = np.linalg.norm(Yq[mid, 0:3] - Yq[100 - mid, 0:3]) - D
        assert abs(g / law.equilibrium_gap(q / rho_a) - 1) < 1e-6
        assert 0 < st.contact_gap(Yq, at(q)) < g_hat


def test_rod_on_the_seabed_sinks_by_weight_over_stiffness():
    """A horizontal rod under its weight w per length on a flat bottom of stiffness k:
    beyond ten decay lengths (4B/k)^¼ from the clamped end the surface penetration is w/k
    (within 1e-6 relative); the static
    bottom has no friction (a dead axial end load is carried unchanged along the rod)."""
    N, L, D, k, w = 100, 2.0, 0.02, 2e4, 3.0
    sb = _seabed(k=k, diameter=np.full(N + 1, D))
    q = st.quat_axis_angle([0, 1, 0], np.pi / 2)            # a3 along +x
    prob = st.uniform(L, N, (0.05, 0.05, 0.04), st.clamp([0, 0, D / 2], q),
                      st.free_end([0.1, 0.0, 0.0]), load=(0.0, 0.0, -w), seabed=sb)
    sol = st.solve(prob)
    pen = D / 2 - sol.Y[N // 2:, 2]
    assert np.max(np.abs(pen / (w / k) - 1)) < 1e-6
    assert np.max(np.abs(sol.Y[:, 7] - 0.1)) < 1e-9     # no friction takes the axial load


def test_dna_in_si_units_solves_through_the_equilibrated_lu():
    """cases/dna-tweezers.yaml's statics at 1.9 turns (before it buckles): 200 nm of DNA
    in SI units, whose rows span ~1e27 (a moment row's N m against a quaternion row's 1),
    so the pivots of J itself were below 1e-14 of the largest and the solve was refused
    as singular; through the equilibrated Dr J Dc (statics.EquilibratedLU) Newton
    converges, the rod stays straight at 200 nm with the torque 2πC n/L of the straight
    twisted rod (to the box rule's 3e-4, measured), and it is stable."""
    import math
    from pathlib import Path

    from solver.case import Case

    case = Case.from_file(Path(__file__).resolve().parents[2] / "cases" / "dna-tweezers.yaml")
    prob = st.static_problem(case, 2.0e-3)
    sol = st.solve(prob)
    turns = prob.end.twist / (2 * math.pi)
    torque = 2 * math.pi * 4.11e-28 * turns / 2e-7
    assert sol.Y[-1, 12] == pytest.approx(torque, rel=1e-3)
    assert sol.Y[-1, 2] - sol.Y[0, 2] == pytest.approx(2e-7, rel=1e-9)
    assert st.unstable_modes(sol.Y, prob)[0] == 0
