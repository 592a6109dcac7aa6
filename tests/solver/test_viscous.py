"""The viscous fluid (``fluid.viscosity``): resistive-force theory's Stokes drag on the
centreline scheme (solver/resistive_force.py, solver/centreline.py), against analytic
results: the terminal velocities f/ζ_n and f/ζ_t of a straight rod and its inertial
transient, the same at steps 100 times the inertial time m/ζ (the overdamped limit) with
the scheme's amplification there, the steady spin of a rod turned at one end, the decay
of a pinned rod's first bending mode at B k⁴/ζ_n, an exact Jacobian, and the case's
refusals naming the field."""
import math

import numpy as np
import pytest

from rodcases import free_end, refused
from solver.case import Case
from solver.centreline import AlphaParameters, CentrelineRod
from solver.resistive_force import resistive_force_coefficients

E, G, D, L = 1.25e7, 5.0e6, 0.01, 1.0
AREA = math.pi * D**2 / 4
FREE_ROT = [{"moment": 0.0}] * 3


def viscous_spec(*, mu=1.0, rho=1500.0, n=10, dt=0.01, t_end=1.0, rho_inf=0.5,
                 start=None, end=None, forces=(), **sections) -> dict:
    """A 1-m rod (D = 1 cm, E = 12.5 MPa) along z in a viscous fluid of viscosity ``mu``
    (Pa s) and density 1000 kg/m³ (added mass C_a = 1, no Morison drag), free at both
    ends unless told, on the centreline scheme."""
    spec = {"schema_version": 1, "name": "viscous",
            "rod": {"length": L, "youngs_modulus": E, "shear_modulus": G, "density": rho,
                    "diameter": D},
            "fluid": {"density": 1000.0, "viscosity": mu, "drag_coefficient_normal": 0.0},
            "boundary": {"start": start or free_end(), "end": end or free_end()},
            "distributed_forces": list(forces),
            "numerics": {"n_segments": n, "dt": dt, "t_end": t_end, "rho_inf": rho_inf,
                         "formulation": "centreline"}}
    spec.update(sections)
    return spec


def zeta(mu=1.0):
    """(ζ_n, ζ_t, ζ_r) of the test rod: ln(L/d) = ln 100."""
    zn, zt, zr = resistive_force_coefficients(mu, np.array([D]), L)
    return float(zn[0]), float(zt[0]), float(zr[0])


def run(rod, state, dt, steps, record=None):
    for _ in range(steps):
        state, _, _ = rod.step(state, dt)
        if record is not None:
            record.append(state)
    return state


def test_the_coefficients_are_the_cited_ones():
    """ζ_n = 4πμ/(ln(ℓ/d) + 0.84), ζ_t = 2πμ/(ln(ℓ/d) − 0.20) (Tirado & García de la
    Torre 1979, Table I, p⁻¹ = 0), ζ_r = πμd² = 4πμa², here at ℓ/d = 100."""
    zn, zt, zr = zeta(2.0)
    assert zn == pytest.approx(8 * math.pi / (math.log(100) + 0.84), rel=1e-15)
    assert zt == pytest.approx(4 * math.pi / (math.log(100) - 0.20), rel=1e-15)
    assert zr == pytest.approx(4 * math.pi * 2.0 * (D / 2) ** 2, rel=1e-15)


@pytest.mark.parametrize("axis", [0, 2], ids=["across", "along"])
def test_terminal_velocity_and_its_inertial_transient(axis):
    """A straight free rod under a uniform force per length f = 0.1 N/m, from rest:
    v(t) = (f/ζ)(1 − exp(−t/τ)), τ = m/ζ with m = ρA + C_a ρ_f A across (0.196 kg/m,
    τ = 0.085 s) and ρA along (0.118 kg/m, τ = 0.082 s). At Δt = 0.005 s (≈ τ/17, ρ∞
    0.5) the transient is followed to 3e-4 of f/ζ (measured 1.65e-4 across, 1.74e-4
    along) and at 2 s (24 τ) every node moves at f/ζ to 1e-6 (measured 6e-11, 3e-11),
    nothing turns."""
    zn, zt, _ = zeta()
    force = [0.0, 0.0, 0.0]
    force[axis] = 0.1
    rod = CentrelineRod.from_case(Case.model_validate(viscous_spec(
        dt=0.005, t_end=2.0, forces=[{"value": force}])))
    z = zn if axis == 0 else zt
    m = 1500.0 * AREA + (1000.0 * AREA if axis == 0 else 0.0)
    tau, v_inf = m / z, 0.1 / z
    states = []
    end = run(rod, rod.start(), 0.005, 400, states)
    transient = max(float(np.abs(s.X[:, axis] / v_inf - (1 - math.exp(-s.t / tau))).max())
                    for s in states)
    assert transient < 3e-4, transient
    assert np.abs(end.X[:, axis] / v_inf - 1).max() < 1e-6
    others = [i for i in range(3) if i != axis]
    assert np.abs(end.X[:, others]).max() < 1e-12 * v_inf
    assert np.abs(end.X[:, 3:6]).max() < 1e-10


def _amplification(rho_inf, h_over_tau):
    """The spectral radius of generalized-α's step on m Ẋ + ζ X = 0 (Δt/τ = h_over_tau),
    its state (X, h a) once Ẋ = −X/τ holds (CentrelineRod's relations, a scalar)."""
    p = AlphaParameters.from_rho_inf(rho_inf)
    am, af, g, h = p.alpha_m, p.alpha_f, p.gamma, h_over_tau
    den = (1 - am) + (1 - af) * h * g
    a_row = np.array([-1.0, -am - (1 - af) * h * (1 - g)]) / den   # a_n+1 from (X_n, a_n)
    x_row = np.array([1.0, h * (1 - g)]) + h * g * a_row
    return float(np.abs(np.linalg.eigvals(np.array([x_row, a_row]))).max())


@pytest.mark.parametrize("rho_inf,steps", [(0.0, 20), (0.5, 30)])
def test_the_overdamped_limit_keeps_the_terminal_velocity(rho_inf, steps):
    """Neutrally buoyant (ρ = ρ_f) and Δt = 100 m/ζ_n (6.8 s against τ = 0.068 s): the
    exact velocity f/ζ is the scheme's fixed point at any ρ∞, and the inertial start's
    layer (``slow=False``; by default such a start skips it), which no step resolves,
    dies at the scheme's amplification for m Ẋ + ζ X = 0
    at Δt/τ = 100, not at exp(−100): per step the larger of ρ∞ and |1 − 3ρ∞|/(3 − ρ∞)
    as Δt/τ → ∞ (1/3 at ρ∞ = 0, 0.17 at ρ∞ = 3 − 2√2, ρ∞ from 1/3 up; at ρ∞ = 1 it never
    dies). Measured: the error's ratio per step 0.32867 and 0.45318 (predicted 0.32867,
    0.45318), the velocity right to 6e-11 and 2e-11 after 20 and 30 steps."""
    zn, _, _ = zeta()
    tau = 2000.0 * AREA / zn
    dt = 100 * tau
    v_inf = 0.1 / zn
    rod = CentrelineRod.from_case(Case.model_validate(viscous_spec(
        rho=1000.0, dt=dt, t_end=steps * dt, rho_inf=rho_inf,
        forces=[{"value": [0.1, 0.0, 0.0]}])))
    states = []
    run(rod, rod.start(slow=False), dt, steps, states)
    err = np.array([float(np.abs(s.X[:, 0] / v_inf - 1).max()) for s in states])
    assert err[-1] < 1e-6, err
    ratio = err[-4] / err[-5]
    assert ratio == pytest.approx(_amplification(rho_inf, 100.0), rel=0.02), ratio


def test_at_rho_inf_1_the_overdamped_transient_does_not_die():
    """ρ∞ = 1 (no numerical dissipation, the trapezoid rule on m Ẋ + ζ X = f): the
    velocity's error is multiplied per step by −(Δt/2τ − 1)/(Δt/2τ + 1), −49/51 at
    Δt = 100 τ and → −1 as Δt/τ → ∞; from the inertial start (``slow=False``) after 30
    steps the velocity is still 6.5 % off (measured; the ratio 0.96078431 per step). The
    default start at this Δt, on the overdamped manifold, has no transient to damp: the
    velocity is f/ζ_n from the first step to rounding."""
    zn, _, _ = zeta()
    dt = 100 * 2000.0 * AREA / zn
    rod = CentrelineRod.from_case(Case.model_validate(viscous_spec(
        rho=1000.0, dt=dt, t_end=30 * dt, rho_inf=1.0, forces=[{"value": [0.1, 0.0, 0.0]}])))
    states = []
    run(rod, rod.start(slow=False), dt, 30, states)
    err = [float(np.abs(s.X[:, 0] * zn / 0.1 - 1).max()) for s in states]
    assert err[-1] > 0.05, err
    assert err[-1] / err[-2] == pytest.approx(49 / 51, rel=1e-6)
    states = []
    run(rod, rod.start(), dt, 30, states)
    assert max(float(np.abs(s.X[:, 0] * zn / 0.1 - 1).max()) for s in states) < 1e-12


def _overdamped_travel(rho_inf, ramp_steps):
    """(the travel's error (m) after 40 steps of Δt = 100 τ against the overdamped
    v∞ (t − t_ramp/2 − τ), in units of v∞ Δt) of the neutrally buoyant rod under 0.1 N/m
    switched on at t = 0 (ramp_steps 0) or ramped on over ramp_steps steps."""
    zn, _, _ = zeta()
    tau = 2000.0 * AREA / zn
    dt, v_inf = 100 * tau, 0.1 / zn
    force = {"value": [0.1, 0.0, 0.0]}
    if ramp_steps:
        force["factor"] = {"t": [0.0, ramp_steps * dt], "value": [0.0, 1.0]}
    rod = CentrelineRod.from_case(Case.model_validate(viscous_spec(
        rho=1000.0, dt=dt, t_end=40 * dt, rho_inf=rho_inf, forces=[force])))
    start = rod.start()
    end = run(rod, start, dt, 40)
    travel = end.Y[:, 0] - start.Y[:, 0]
    exact = v_inf * (end.t - 0.5 * ramp_steps * dt - tau)
    return float(np.abs(travel - exact).max()) / (v_inf * dt)


def test_a_ramped_load_travels_right_at_steps_beyond_the_inertial_time():
    """The same rod with the load ramped on over 5 steps (a ``factor`` table): its
    travel after 40 steps is the overdamped one, v∞ (t − t_ramp/2 − τ), to rounding
    (measured 4e-14 and 1e-14 of a step's travel at ρ∞ 0.5 and 0 from the default start
    on the overdamped manifold)."""
    err = _overdamped_travel(0.5, 5)
    assert err < 1e-9, err


@pytest.mark.parametrize("rho_inf", [0.0, 0.5])
def test_a_load_switched_on_travels_right_at_steps_beyond_the_inertial_time(rho_inf):
    """The load switched on at t = 0 at Δt = 100 τ: the default start, on the overdamped
    manifold (:meth:`solver.centreline.CentrelineRod.start`), travels v∞ t, the
    overdamped answer, which the inertial one v∞ (t − τ) leads by τ = 0.01 step
    (measured 0.0100 at ρ∞ 0 and 0.5). The inertial start lagged by 1.0 step's travel at
    ρ∞ 0.5 and 6.2 at ρ∞ 0: its Ẋ(0) = f/m belongs to the inertial layer, which the
    step does not resolve."""
    err = _overdamped_travel(rho_inf, 0)
    assert abs(err - 0.01) < 1e-6, err


def test_a_rod_turned_at_one_end_spins_against_the_rotational_drag():
    """A straight rod held at s = 0 and turned there about its axis at Ω = 2 rad/s, its
    s = L end free: once the twist has diffused (ζ_r L²/GJ = 0.064 s; 0.5 s run) every
    section spins at the held end's rate and the moment along the axis is
    m3(s) = −ζ_r W3 (L − s), at the held end the whole rod's drag ζ_r W3 L = M (the spin
    is M/(ζ_r L)). The scheme's W is the Cayley map's rate of the step's rotation,
    2 tan(ΩΔt/2)/Δt = Ω (1 + (ΩΔt)²/12 + ...), 8.3e-6 above Ω at Δt = 0.005 s (second
    order); against it W3 and m3 agree to 1e-9 (measured 1.7e-11 and 7.9e-12)."""
    _, _, zr = zeta()
    omega, dt = 2.0, 0.005
    held = {"translation": [{"velocity": 0.0}] * 3,
            "rotation": [{"angular_velocity": 0.0}] * 2 + [{"angular_velocity": omega}]}
    rod = CentrelineRod.from_case(Case.model_validate(viscous_spec(
        n=20, dt=dt, t_end=0.5, start=held)))
    end = run(rod, rod.start(), dt, 100)
    spin = 2.0 * math.tan(0.5 * omega * dt) / dt
    assert np.abs(end.X[:, 5] / spin - 1).max() < 1e-9
    assert abs(spin / omega - 1 - (omega * dt) ** 2 / 12) < 1e-9
    a3 = end.Y[-1, 0:3] - end.Y[0, 0:3]
    m3 = end.Y[:, 10:13] @ (a3 / np.linalg.norm(a3))
    expected = -zr * spin * (L - rod.props.s)
    assert np.abs(m3 - expected).max() < 1e-9 * zr * spin * L
    assert np.abs(end.X[:, 0:5]).max() < 1e-10


def _bent_spec(n, mu, dt, t_end, amplitude=1e-3, length=L):
    """A rod bent into A sin(πs/L) (A = 1 mm), pinned at s = 0 (held, free to turn), on
    a roller at s = L (held across its initial axes, free along a3 and to turn):
    moment-free ends, where the first bending mode of the linear rod is exactly
    sin(πs/L); neutrally buoyant in a fluid of viscosity mu."""
    s = np.linspace(0.0, length, 4001)
    k = math.pi / length
    x = amplitude * np.sin(k * s)
    dz = np.sqrt(1.0 - (amplitude * k * np.cos(k * s)) ** 2)
    z = np.concatenate([[0.0], np.cumsum(0.5 * (dz[1:] + dz[:-1]) * np.diff(s))])
    pin = {"translation": [{"velocity": 0.0}] * 3, "rotation": FREE_ROT}
    roller = {"translation": [{"velocity": 0.0}] * 2 + [{"force": 0.0}], "rotation": FREE_ROT}
    spec = viscous_spec(mu=mu, rho=1000.0, n=n, dt=dt, t_end=t_end, rho_inf=0.0,
                        start=pin, end=roller,
                        initial={"centreline": {"points": np.stack([x, 0 * s, z], 1).tolist()}})
    spec["rod"]["length"] = length
    return spec


def _mode_amplitude(rod, state):
    """The first mode's amplitude (m): (2/L) ∫ x sin(πs/L) ds by the trapezoid."""
    s = rod.props.s
    length = s[-1]
    return 2.0 / length * float(np.sum(rod.props.quad_weights * state.Y[:, 0]
                                       * np.sin(math.pi * s / length)))


def _bending_decay(n, steps_per_tau):
    """(the fitted decay rate over σ, the fit's amplitude at t = 0 over A(0) minus 1: the
    offset the start leaves) of the pinned rod's first mode in a fluid of 10 Pa s (σ = B k⁴/ζ_n =
    0.026 /s, τ = m/ζ_n = 6.8 ms: τσ = 1.8e-4) at Δt = steps_per_tau τ, ρ∞ 0, the rate
    fitted to log A over the steps after the first 10."""
    mu = 10.0
    zn, _, _ = zeta(mu)
    B = E * math.pi * D**4 / 64
    sigma = B * (math.pi / L) ** 4 / zn
    tau = 2000.0 * AREA / zn
    dt = steps_per_tau * tau
    steps = int(round(1.0 / (sigma * dt)))
    rod = CentrelineRod.from_case(Case.model_validate(_bent_spec(n, mu, dt, steps * dt)))
    states = [rod.start()]
    run(rod, states[0], dt, steps, states)
    t = np.array([s.t for s in states])
    amp = np.array([_mode_amplitude(rod, s) for s in states])
    slope, intercept = np.polyfit(t[10:], np.log(amp[10:]), 1)
    return -slope / sigma, math.exp(intercept) / amp[0] - 1.0


def test_a_bent_rod_relaxes_at_b_k4_over_zeta_n():
    """Overdamped bending relaxation ζ_n ẇ = −B w'''': the first mode of the pinned rod
    decays at σ = B k⁴/ζ_n, k = π/L. At Δt = 100 τ (σΔt = 0.018, ρ∞ 0) the fitted rate is
    σ within 1 % on 32 segments (measured +3.50e-3; +1.33e-2 on 16 and +1.08e-3 on 64:
    second order in s, the box rule's k⁴; the inertia adds τσ = 1.8e-4). The start, on
    the overdamped manifold at these steps, leaves the mode's amplitude where the
    overdamped decay puts it: the fit's amplitude at t = 0 is A(0) within 2.6e-6 and
    8.4e-5 at Δt = 10 and 100 τ (measured on 32 segments; the inertial start, whose
    layer the step does not resolve, offset it by 4.1e-3 and 0.11)."""
    rate32, offset = _bending_decay(32, 100)
    rate16, _ = _bending_decay(16, 100)
    assert abs(rate32 - 1.0) < 1e-2, rate32
    assert abs(offset) < 1e-3, offset
    assert 3.0 < (rate16 - 1.0) / (rate32 - 1.0) < 5.0, (rate16, rate32)
    rate, offset = _bending_decay(32, 10)
    assert abs(rate - 1.0) < 1e-2 and abs(offset) < 1e-4, (rate, offset)


def _dna_spec(dt, steps):
    """500 nm of DNA (d = 2 nm, persistence length 50 nm: B = kT·50 nm = 2.05e-28 N m²,
    E = 2.61e8 Pa; 1700 kg/m³) in water at 25 °C (8.9e-4 Pa s, 1000 kg/m³, the
    Morison defaults kept), bent into 0.5 nm sin(πs/L) between a pin and a roller, on 32
    segments, ρ∞ 0."""
    length, d = 5e-7, 2e-9
    bend = 4.1e-21 * 50e-9
    spec = _bent_spec(32, 8.9e-4, dt, steps * dt, amplitude=1e-3 * length, length=length)
    spec["rod"].update(youngs_modulus=bend / (math.pi * d**4 / 64), density=1700.0, diameter=d)
    spec["rod"]["shear_modulus"] = spec["rod"]["youngs_modulus"] / 1.5
    spec["fluid"] = {"density": 1000.0, "viscosity": 8.9e-4}
    return spec, bend


def test_dna_in_water_relaxes_at_steps_of_ten_million_inertial_times():
    """The overdamped limit at the scale it is for: 500 nm of DNA in water, τ = m/ζ_n =
    4.8 ps, the first mode's σ = B k⁴/ζ_n = 182 /s, Δt = 0.02/σ = 110 µs = 2.3e7 τ. Newton
    converges, the fitted rate is σ within 1 % (measured +3.36e-3, the box rule's error on
    32 segments as above) and the case has no plausibility warning (the mode is
    overdamped: the step is compared with its relaxation time, not with its inertial
    period of 1 µs); at 10 relaxation times it has one, naming that time."""
    from solver.plausibility import lowest_bending_relaxation_time, plausibility_warnings

    probe, bend = _dna_spec(1e-4, 1)
    zn = float(resistive_force_coefficients(8.9e-4, np.array([2e-9]), 5e-7)[0][0])
    sigma = bend * (math.pi / 5e-7) ** 4 / zn
    dt = 0.02 / sigma
    spec, _ = _dna_spec(dt, 50)
    case = Case.model_validate(spec)
    assert plausibility_warnings(case) == []
    assert lowest_bending_relaxation_time(case) == pytest.approx(1 / sigma, rel=1e-12)
    rod = CentrelineRod.from_case(case)
    states = [rod.start()]
    run(rod, states[0], dt, 50, states)
    t = np.array([s.t for s in states])
    amp = np.array([_mode_amplitude(rod, s) for s in states])
    rate = -np.polyfit(t[10:], np.log(amp[10:]), 1)[0]
    assert abs(rate / sigma - 1.0) < 1e-2, rate / sigma
    coarse, _ = _dna_spec(10.0 / sigma, 1)
    found = plausibility_warnings(Case.model_validate(coarse))
    assert [(w["loc"], w["type"]) for w in found] == [("numerics.dt", "dt_unresolved")]
    assert "relaxation time" in found[0]["msg"]


def test_the_jacobian_with_viscous_and_morison_drag_is_exact():
    """The band Jacobian against central differences of the residual in the middle of a
    cantilever's swing in a fluid with both drags (viscous and Morison, summed)."""
    from test_centreline import jacobian_error

    spec = viscous_spec(n=6, dt=0.01, t_end=0.2, mu=0.5, gravity=[-9.81, 0.0, 0.0],
                        start={"translation": [{"velocity": 0.0}] * 3,
                               "rotation": [{"angular_velocity": 0.0}] * 3})
    spec["fluid"].update(drag_coefficient_normal=1.2, drag_coefficient_tangential=0.05)
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    state = run(rod, rod.start(), 0.01, 20)
    assert np.abs(state.X[:, 0:3]).max() > 0.1                 # it moves
    err, size = jacobian_error(rod, state, 0.01)
    assert err < 1e-5 * size, err


def test_integrate_runs_a_viscous_case():
    """Through the time loop (solver.simulation.integrate): the body-frame velocity
    output of the rod settling at f/ζ_n."""
    from solver.simulation import integrate

    zn, _, _ = zeta()
    spec = viscous_spec(dt=0.01, t_end=2.0, forces=[{"value": [0.1, 0.0, 0.0]}])
    spec["output"] = {"every": 200, "fields": ["v"]}
    ds = integrate(Case.model_validate(spec))
    assert ds.attrs["hockle_status"] == "completed"
    v = ds["v"].isel(time=-1).values
    assert np.abs(v[:, 0] * zn / 0.1 - 1).max() < 1e-6
    assert "viscous" in ds.attrs["summary"]


# --------------------------------------------------------------- the case language


@pytest.mark.parametrize("mu", [0.0, -8.9e-4])
def test_viscosity_must_be_positive(mu):
    refused(viscous_spec(mu=mu), ("fluid", "viscosity"), "greater than 0")


def test_the_goyal_scheme_refuses_viscosity_at_the_field():
    spec = viscous_spec()
    del spec["numerics"]["formulation"]                       # the default, goyal
    refused(spec, ("fluid", "viscosity"), "numerics.formulation: centreline")


def test_slenderness_length_is_read_with_viscosity_only_and_must_leave_a_slender_rod():
    spec = viscous_spec()
    del spec["fluid"]["viscosity"]
    spec["fluid"]["slenderness_length"] = 0.5
    refused(spec, ("fluid", "slenderness_length"), "only read with fluid.viscosity")
    spec = viscous_spec()
    spec["fluid"]["slenderness_length"] = 0.015                  # ℓ/d = 1.5
    refused(spec, ("fluid", "slenderness_length"), "ℓ/d = 1.5")
    spec = viscous_spec()
    spec["rod"]["length"] = 0.015
    spec["numerics"]["n_segments"] = 2
    refused(spec, ("fluid", "viscosity"), "rod.length")
    spec = viscous_spec()
    spec["rod"]["diameter"] = {"s": [0.0, 1.0], "value": [0.01, 0.6]}
    refused(spec, ("fluid", "viscosity"), "largest rod.diameter 0.6")


def test_a_slenderness_length_sets_the_logarithm():
    spec = viscous_spec()
    spec["fluid"]["slenderness_length"] = 0.2
    rod = CentrelineRod.from_case(Case.model_validate(spec))
    assert rod.stokes[0][0] == pytest.approx(4 * math.pi / (math.log(20) + 0.84), rel=1e-15)


def test_a_fluid_without_viscosity_keeps_its_canonical_json():
    """viscosity and slenderness_length are written only when given: the spec_hash of
    every earlier case with a fluid is unchanged; a viscous case round-trips."""
    plain = viscous_spec()
    del plain["fluid"]["viscosity"]
    case = Case.model_validate(plain)
    fluid = case.model_dump(mode="json")["fluid"]
    assert "viscosity" not in fluid and "slenderness_length" not in fluid
    viscous = viscous_spec(mu=8.9e-4)
    viscous["fluid"]["slenderness_length"] = 0.3
    case = Case.model_validate(viscous)
    again = Case.model_validate_json(case.canonical_json())
    assert again.spec_hash() == case.spec_hash()
    assert again.fluid.viscosity == 8.9e-4 and again.fluid.slenderness_length == 0.3
