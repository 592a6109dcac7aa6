"""The energy check of every step (``numerics.energy_tolerance``, solver/balance.py):
the balance closes on a conservative case, a step that injects energy is refused with
the reason ``energy`` and Δt cut, and the ``step_energy_error`` series is written.

The injecting case is issue 41's: a steel cantilever (L = 1 m, D = 1 cm, ρ∞ = 0, no
gravity) under a dead tip load P L²/EI = 10 ramped on over 2 s; at Δt = 0.1 s its large
steps pump energy into an oscillation that never settles (docs/numerics.md § 8). The
reference is Mattiasson's elastica (tests/solver/test_point_loads.py).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from solver.case import Case, Numerics
from solver.simulation import RodRun, integrate

E, G, RHO, D, L = 2.1e11, 8.1e10, 7850.0, 0.01, 1.0
EI = E * math.pi * D**4 / 64
CLAMPED = {"translation": [{"velocity": 0.0}] * 3, "rotation": [{"angular_velocity": 0.0}] * 3}
FREE = {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}
#: Mattiasson's tip x/L (along the clamped tangent) under P L²/EI = 10
X_TIP = 0.44501


#: the default energy tolerance (``numerics.energy_tolerance``)
DEFAULT = Numerics.model_fields["energy_tolerance"].default


def cantilever(dt, n=20, t_end=8.0, rho_inf=0.0, energy_tolerance=DEFAULT, **numerics):
    """The steel cantilever under a dead tip load P = 10 EI/L² along +x, ramped on over
    2 s (clamped along z at s = 0); the energy check at ``energy_tolerance`` (None: off;
    by default the case's default)."""
    spec = {
        "schema_version": 1, "name": "dead-load cantilever",
        "rod": {"length": L, "youngs_modulus": E, "shear_modulus": G, "density": RHO,
                "diameter": D},
        "point_loads": [{"s": L, "value": [10.0 * EI / L**2, 0.0, 0.0],
                         "factor": {"t": [0.0, 2.0], "value": [0.0, 1.0]}}],
        "boundary": {"start": CLAMPED, "end": FREE},
        "numerics": {"n_segments": n, "dt": dt, "t_end": t_end, "rho_inf": rho_inf,
                     "energy_tolerance": energy_tolerance, **numerics},
        "output": {"fields": ["position", "energies"]},
    }
    return Case.model_validate(spec)


def test_balance_closes_on_a_conservative_case():
    """ρ∞ = 1 (the trapezoidal rule conserves a linear system's energy) at a Δt of a
    fiftieth of the rod's first period, through the ramp: every step's ε is within
    2e-4 of the rod's energy (measured: 6.4e-5, in the first steps), and the energy at
    the end is the loads' work within 1e-3 of it (each step's balance summed; measured
    6.3e-4)."""
    case = cantilever(0.005, n=10, t_end=0.4, rho_inf=1.0, energy_tolerance=1.0)
    run = RodRun(case)
    run.advance(0.005)                  # the restart's steps are not measured
    energy0 = run.state.balance["energy"]
    worst, work = 0.0, 0.0
    while run.state.t < 0.4 - 1e-12:
        run.advance(run.state.t + 0.005)
        bal = run.last_balance
        worst = max(worst, abs(bal.error) / bal.energy)
        work += sum(bal.work.values())
    assert worst < 2e-4, worst
    assert abs(bal.energy - energy0 - work) < 1e-3 * bal.energy
    assert run.control.refusals.get("energy", 0) == 0


def test_injecting_steps_are_refused_and_the_cantilever_settles():
    """At Δt = 0.1 s the check at its default refuses the injecting steps (reason
    ``energy``), the run cuts Δt and settles within 0.5 % of the elastica (50 segments;
    measured +0.008 %, 22 refusals); without it the rod still moves at 8 s and the tip
    is > 1 % off (measured +3.8 %)."""
    ds = integrate(cantilever(0.1, n=50))
    assert ds.attrs["hockle_status"] == "completed"
    assert "energy" in ds.attrs["hockle_refused_attempts"]
    refused = dict(item.rsplit(" ", 1) for item in
                   ds.attrs["hockle_refused_attempts"].split(", "))
    assert int(refused["energy"]) > 0
    x = ds.position.values[-1, -1, 2] / L
    assert abs(x / X_TIP - 1) < 0.005
    assert ds.energy_kinetic.values[-1] < 1e-3
    off = integrate(cantilever(0.1, n=50, energy_tolerance=None))
    assert abs(off.position.values[-1, -1, 2] / L / X_TIP - 1) > 0.01
    assert off.energy_kinetic.values[-1] > 1e-3


def test_series_written_with_the_check_only():
    ds = integrate(cantilever(0.1, t_end=0.5))
    err = ds.step_energy_error.values
    assert err.shape == ds.step_time.shape
    assert np.isfinite(err).all()
    assert np.all(err[np.isfinite(err)] <= DEFAULT)
    assert "step_energy_error" not in integrate(cantilever(0.1, t_end=0.5,
                                                         energy_tolerance=None))


def test_turned_shape_points_its_chord_at_the_held_end():
    """GlobalLoadWork.turned: a rigid rotation about node 0 (node 0 stays, every
    distance is kept, the frames turn with the shape) that points the chord at the
    target; a shape whose chord already points there is returned as it is."""
    from solver.balance import GlobalLoadWork
    from solver.kinematics import quat_to_matrix

    rng = np.random.default_rng(3)
    r = np.cumsum(rng.normal(size=(9, 3)) * 0.1, axis=0)
    q = rng.normal(size=(9, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    target = r[0] + 2.0 * np.array([0.3, -0.5, 0.8])
    q2, r2 = GlobalLoadWork.turned(q, r, target)
    np.testing.assert_allclose(r2[0], r[0], atol=1e-15)
    chord = r2[-1] - r2[0]
    direction = (target - r[0]) / np.linalg.norm(target - r[0])
    np.testing.assert_allclose(chord / np.linalg.norm(chord), direction, atol=1e-12)
    d, d2 = r[:, None] - r[None], r2[:, None] - r2[None]
    np.testing.assert_allclose(np.linalg.norm(d2, axis=2), np.linalg.norm(d, axis=2),
                               atol=1e-12)
    # the frames turned by the same rotation as the centreline: R_k' R_k^T is one matrix
    turn = quat_to_matrix(q2) @ np.transpose(quat_to_matrix(q), (0, 2, 1))
    np.testing.assert_allclose(turn, np.broadcast_to(turn[0], turn.shape), atol=1e-12)
    np.testing.assert_allclose((r[3] - r[0]) @ turn[0].T, r2[3] - r2[0], atol=1e-12)
    q3, r3 = GlobalLoadWork.turned(q, r, r[-1])
    assert q3 is q and r3 is r


def test_held_cable_keeps_its_answer_at_the_default():
    """The soft hanging cable (test_global_ends.catenary_spec; both ends held in
    position in the global frame) at Δt = 0.1 s: with the loads' work measured on the
    κ-shape turned onto the held end (GlobalLoadWork.turned) the default check refuses
    no step and the run is the unchecked one. Measured on the κ-shape anchored at node 0
    alone, the first measured step read ε = 8.4 T and the sag ended 1.3 % off the
    catenary (−0.14 % without the check; docs/numerics.md § 8)."""
    from test_global_ends import catenary_spec

    spec = catenary_spec(0.1, DEFAULT)
    spec["numerics"]["t_end"] = 4.0
    checked = integrate(Case.model_validate(spec))
    spec["numerics"]["energy_tolerance"] = None
    plain = integrate(Case.model_validate(spec))
    assert "energy" not in checked.attrs["hockle_refused_attempts"]
    assert np.isfinite(checked.step_energy_error.values).all()
    np.testing.assert_array_equal(checked.position.values, plain.position.values)


def test_energy_tolerance_validated():
    with pytest.raises(Exception) as info:
        cantilever(0.1, energy_tolerance=-1.0)
    assert "energy_tolerance" in str(info.value)


def test_no_trusted_step_ends_failed_with_the_reason():
    """A tolerance no step can meet within the allowed cuts ends the run ``failed``,
    saying that the steps put in energy, not that Newton failed."""
    from solver.simulation import SolverDivergence
    case = cantilever(0.1, energy_tolerance=1e-9, max_dt_cuts=1)
    with pytest.raises(SolverDivergence) as info:
        integrate(case)
    assert "numerics.energy_tolerance" in str(info.value)
    assert "energy" in info.value.partial.attrs["hockle_refused_attempts"]
    assert info.value.partial.attrs["hockle_status"] == "failed"


# --------------------------------------------------------------------- self-contact
# The contact law's stored potential (solver/contact/laws.py, law_potential) and its
# account (solver/balance.py, ContactWork): −dΨ/dd is the law's force, −∇U_c the nodal
# contact forces, and in a run the account's −ΔU_c is the repulsion's work.

def _laws():
    from solver.contact.laws import BarrierLaw, SeedLaw
    # the seed example's law (k1 = 1e-7 m⁴/s², k2 = 3, tolerance 4 cm) and a barrier
    return (SeedLaw(1e-7, 3.0, 1e-6, 1.0, 0.04, 2e-5),
            BarrierLaw(5e-3, 10.0, 1e-6, 1.0, 2e-5))


@pytest.mark.parametrize("which", [0, 1])
def test_contact_potential_is_the_law_force(which):
    """Ψ(d) = ∫_d^{d_off} φ P: against adaptive quadrature of the law's force (1e-9,
    measured ≤ 1.2e-10 seed, 5e-14 barrier) and −dΨ/dd against the force at ḋ = 0 by
    central differences (1e-5, measured ≤ 8e-6), across the linear floor, the power law,
    the cut-off band and beyond d_off (Ψ = 0)."""
    from scipy.integrate import quad
    law = _laws()[which]
    dbar = 0.02
    d_on, d_off = (float(x) for x in law.cutoff(dbar))
    d = dbar + np.array([-1e-5, 1e-5, 3.5e-4, 2e-3, 0.7 * (d_on - dbar),
                         0.5 * (d_on + d_off) - dbar, 0.9 * (d_off - dbar)])
    psi = law.potential(d, dbar)
    force = law(d, 0.0, dbar, 1.0)[0]

    def integrand(x):
        return law(np.array([x]), 0.0, dbar, 1.0)[0][0]

    for dk, pk in zip(d, psi):
        ref = quad(integrand, dk, d_off, points=[d_on] if dk < d_on else None,
                   limit=200, epsabs=0.0, epsrel=1e-12)[0]
        assert abs(pk - ref) <= 1e-9 * abs(ref), (dk, pk, ref)
    h = 1e-4 * np.minimum(np.abs(d - dbar), d_off - d)
    slope = -(law.potential(d + h, dbar) - law.potential(d - h, dbar)) / (2 * h)
    np.testing.assert_allclose(slope, force, rtol=1e-5)
    assert law.potential(np.array([d_off, d_off + 1e-3]), dbar).tolist() == [0.0, 0.0]


@pytest.mark.parametrize("law", ["seed", "barrier"])
def test_contact_potential_gradient_is_the_nodal_force(law):
    """U_c = Σ ½ Δs_i ρĀ Ψ(d_i) over the runs (SelfContact.potential): −∇U_c by central
    differences equals the nodal contact forces Δs_a Σ w_a F at ḋ = 0 (the closest point
    stationary along the partner curve), on a loop whose ends overlap at a 1-5-mm gap
    (26 pairs); within 1e-6 of the largest force (measured 1.4e-9, 6e-10)."""
    from solver.contact.model import SelfContact, assemble_nodal
    n = 121
    s = np.linspace(0.0, 1.2, n)
    u = np.linspace(-0.3, 2 * math.pi + 0.3, n)
    r = np.stack([0.19 * np.cos(u), 0.19 * np.sin(u),
                  0.012 * (u - math.pi) / math.pi + 0.003 * np.sin(3 * u)], 1)
    spec = dict(aperture=90.0, tolerance=0.04, k1=1e-7, k2=3.0, k3=0.0, k4=1.0, law=law,
                barrier_gap=0.01, barrier_stiffness=10.0)
    c = SelfContact(spec, s, np.full(n, 0.02), np.full(n, 0.5))
    cand = c.candidates(r, np.gradient(r, axis=0), 0.0)
    ev = c.evaluate(cand, r, np.zeros_like(r))
    assert ev.count > 10
    force = assemble_nodal(ev, n) * c.weights[:, None]
    grad = np.zeros_like(r)
    step = 1e-7
    for a in np.unique(ev.nodes):
        for k in range(3):
            rp, rm = r.copy(), r.copy()
            rp[a, k] += step
            rm[a, k] -= step
            grad[a, k] = -(c.potential(cand, rp) - c.potential(cand, rm)) / (2 * step)
    assert np.abs(force - grad).max() < 1e-6 * np.abs(force).max()


def crossing_loop(dt, law="seed", t_end=0.005):
    """A free rod (L ≈ 1.25 m, D = 2 cm, the seed example's material, no fluid) laid as
    one turn of radius 0.19 m whose ends overlap 1 mm apart (0.6 rad): the turn opens and
    the ends push off each other; undamped contact (k3 = 0), ρ∞ = 1, the energy check on
    with a tolerance no step meets (every step measured, none refused)."""
    u = np.linspace(-0.3, 2 * math.pi + 0.3, 2001)
    pts = np.stack([0.19 * np.cos(u), 0.19 * np.sin(u), 0.0105 * (u - math.pi) / math.pi], 1)
    length = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    contact = {"aperture": 90.0, "tolerance": 0.04, "k1": 1e-7, "k2": 3.0, "k3": 0.0,
               "k4": 1.0, "law": law}
    if law == "barrier":
        contact.update(barrier_gap=0.005, barrier_stiffness=1e4)
    spec = {"schema_version": 1, "name": "crossing loop",
            "rod": {"length": length, "youngs_modulus": 1.25e7, "shear_modulus": 5e6,
                    "density": 1500.0, "diameter": 0.02},
            "initial": {"centreline": {"points": pts.tolist()}},
            "boundary": {"start": FREE, "end": FREE}, "contact": contact,
            "numerics": {"n_segments": 120, "dt": dt, "t_end": t_end, "rho_inf": 1.0,
                         "energy_tolerance": 1e9},
            "output": {"fields": ["position"]}}
    return Case.model_validate(spec)


def contact_work_in_run(dt, law="seed", t_end=0.005):
    """Sum over the measured steps of (the account's −ΔU_c, the trapezoid of the nodal
    contact forces on the node displacements, the same forces' work along each step's
    chord by 8-point Gauss-Legendre), J, and the number of steps."""
    from solver.contact.model import assemble_nodal
    run = RodRun(crossing_loop(dt, law, t_end))
    c = run.contact
    xg, wg = np.polynomial.legendre.leggauss(8)
    booked = trap = chord = 0.0
    steps = 0
    run.advance(dt)                          # the restart's steps are not measured
    while run.state.t < t_end - 1e-12:
        r0 = run.state.r.copy()
        run.advance(run.state.t + dt)
        bal = run.last_balance
        assert bal is not None               # contact steps are measured
        r1 = run.state.r
        cand = c.candidates(r0, np.gradient(r0, axis=0), 0.05)

        def work(frac, r=None):
            rq = r0 + frac * (r1 - r0) if r is None else r
            F = assemble_nodal(c.evaluate(cand, rq, np.zeros_like(rq)), c.n_nodes)
            return float(np.sum(c.weights[:, None] * F * (r1 - r0)))

        trap += 0.5 * (work(0.0) + work(1.0))
        chord += sum(0.5 * w * work(0.5 * (1.0 + x)) for x, w in zip(xg, wg))
        booked += bal.work["contact"]
        steps += 1
    return booked, trap, chord, steps


@pytest.mark.parametrize("law", ["seed", "barrier"])
def test_contact_account_is_the_contact_force_work_in_a_run(law):
    """In the push-off of the crossing loop at Δt = 1e-4 s, the account's −ΔU_c equals
    the contact forces' work along each step's chord (path independence of a potential
    force; 1e-4, measured 9e-8 seed, 1.4e-7 barrier) and the trapezoid on the two
    levels within 5 % (measured 2.3 % and 1.4 %; 0.7 % and 0.6 % at Δt = 2.5e-5 s over
    10 ms, ``contact_work_in_run(2.5e-5, law, 0.01)``)."""
    booked, trap, chord, steps = contact_work_in_run(1e-4, law)
    assert steps >= 40
    assert booked > 1e-4                      # the push-off releases stored energy
    assert abs(booked - chord) < 1e-4 * booked
    assert abs(booked - trap) < 0.05 * booked


@pytest.mark.parametrize("law", ["seed", "barrier"])
def test_contact_account_reads_the_solution_from_the_contact_summary(law, monkeypatch):
    """The account's new-level U_c comes from the fresh evaluation the step's contact
    summary made at the solution (RodSystem.summary_potential), not from finding the
    closest points again: at every measured step of the crossing loop it is available
    and equals SelfContact.potential at the solution's positions bit for bit; at any
    other positions it is not offered."""
    from solver import balance

    step = balance.ContactWork.step
    pairs = []

    def checked(self, run, prob, sol, old):
        r = sol.pose[2]
        pairs.append((run.system.summary_potential(r), run.contact.potential(sol.candidates, r),
                      run.system.summary_potential(r.copy())))
        return step(self, run, prob, sol, old)

    monkeypatch.setattr(balance.ContactWork, "step", checked)
    run = RodRun(crossing_loop(1e-4, law, 0.002))
    while run.state.t < 0.002 - 1e-12:
        run.advance(run.state.t + 1e-4)
    assert len(pairs) >= 15 and any(b > 0.0 for _, b, _ in pairs)
    assert all(a == b for a, b, _ in pairs), pairs
    assert all(c is None for _, _, c in pairs)


@pytest.mark.parametrize("law", ["seed", "barrier"])
def test_contact_account_reuses_the_old_level_energy_it_carries(law, monkeypatch):
    """Where a step keeps the last step's candidates (the kept search's very object) from
    the very positions the level carries, the account's old-level U_c is the one it
    carried, equal bit for bit to SelfContact.potential there; where the candidates are
    new, it is evaluated again (both happen in the crossing loop)."""
    from solver import balance

    step = balance.ContactWork.step
    seen = []

    def checked(self, run, prob, sol, old):
        cand = sol.candidates
        if cand is not None and cand.runs:
            kept = isinstance(old, tuple) and old[1] is cand and old[2] is run.state.r
            seen.append((kept, old[0] if kept else None, run.contact.potential(cand, run.state.r)))
        return step(self, run, prob, sol, old)

    monkeypatch.setattr(balance.ContactWork, "step", checked)
    run = RodRun(crossing_loop(1e-4, law, 0.002))
    while run.state.t < 0.002 - 1e-12:
        run.advance(run.state.t + 1e-4)
    kept = [(a, b) for k, a, b in seen if k]
    assert len(kept) >= 5 and len(kept) < len(seen), [k for k, _, _ in seen]
    assert any(b > 0.0 for _, b in kept)
    assert all(a == b for a, b in kept), kept
