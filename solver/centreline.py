"""The dynamic rod on the statics' centreline: positions and frames as the unknowns.

The static rows of :mod:`solver.statics` (box rule in s on r, the unit quaternion p, the
internal force n and moment m per node, all global; 7 rows at s = 0, 13 per cell, 6 at
s = L) become the dynamic rows by adding the inertia and fluid loads of the seed's eqs.
4-5 (Goyal, Perkins & Lee, J. Comput. Phys. 2005) to the force and moment rows, as
distributed loads per length at the nodes::

    n' + f + f_fluid − M r̈ = 0,                M r̈ = ρA r̈ + C_a ρ_f A (r̈ − (a3·r̈) a3)
    m' + r' × n − R (I Ẇ + W × I W) = 0,       I = diag(ρJ1, ρJ2, ρJ3)

with ṙ the global velocity and W the body angular velocity (R' of the frame R = R(p):
Ṙ = R [W]×), f the dead loads of the statics and f_fluid Morison's drag in still water,
B_d = −½ ρ_f D C_dn |v_n| v_n − ½ ρ_f π D C_dt |v_t| v_t on the body velocity v = Rᵀ ṙ
(the same law as :mod:`solver.loads`), plus with ``fluid.viscosity`` resistive-force
theory's Stokes drag −R(ζ_n v_n + ζ_t v_t e3) and its moment −ζ_r W3 a3 about the axis
(:mod:`solver.resistive_force`; the moment in the moment row, beside the inertia's). The
cell rows take the trapezoid of the nodal loads, so a cell row reads exactly as its
static row with f + f_fluid − M r̈ in place of f: one discretisation of the rod in s for statics and dynamics, and a static equilibrium
is a dynamic state at rest (and a dynamic state a static solver's start) with nothing
converted. Compatibility (r' = a3) and inextensibility are the kinematic rows of that
centreline, so every position the run reports satisfies them to Newton's tolerance.

Time: generalized-α on the Lie group R³ × SO(3) per node (Brüls & Cardona, J. Comput.
Nonlinear Dyn. 5, 2010; Arnold, Brüls & Cardona, Numer. Math. 129, 2015), with
the equilibrium at t_n+1 (the index-3 form of Arnold & Brüls, Multibody Syst. Dyn. 18,
2007). Per node, with the velocity X = (ṙ, W), the acceleration Ẋ and the algebraic
acceleration a (each (6,))::

    (1 − α_m) a_n+1 + α_m a_n = (1 − α_f) Ẋ_n+1 + α_f Ẋ_n
    X_n+1 = X_n + h (1 − γ) a_n + h γ a_n+1
    Δ_n+1 = h X_n + h² (½ − β) a_n + h² β a_n+1,  r_n+1 = r_n + Δr,  p_n+1 = p_n ⊗ cay(Δθ)

α_m = (2ρ∞ − 1)/(ρ∞ + 1), α_f = ρ∞/(ρ∞ + 1), γ = ½ + α_f − α_m, β = ¼(γ + ½)² (Chung &
Hulbert, J. Appl. Mech. 60, 1993). The rotation increment Δθ (body frame at t_n) is read
off the two quaternions by the Cayley map's inverse, Δθ = 2 vec(d)/w(d) with
d = p̄_n ⊗ p_n+1 (cay agrees with exp to O(|Δθ|³), which keeps the scheme's second order;
Brüls & Cardona 2010, § 4). Newton's unknowns are the statics' (r, p, n, m) at t_n+1;
every velocity and acceleration is an affine function of them, so the Jacobian is the
static band (:func:`solver.statics.band_jacobian`) plus each node's 6 × 7 block of its
inertia and fluid loads, exact to rounding by the complex step (Squire & Trapp, SIAM Rev.
40, 1998), and one band LU (LAPACK ``dgbtrf``) per iteration.

Start: a rod at rest whose loads switch on at t = 0 has accelerations Ẋ(0) ≠ 0 that the
scheme needs as its starting value (Arnold & Brüls 2007: a_0 = Ẋ_0 keeps the order; a
zero start costs an order). :meth:`CentrelineRod.start` finds them by Taylor steps from
the start, r(δ) = r_0 + δ ṙ_0 + δ²/2 r̈_0 + O(δ³), on the same rows (δ, δ/2 and δ/4,
Richardson), so the start is consistent to O(δ³).

Ends: the statics' end rows at t_n+1 (:func:`solver.statics.problem_at`): held
translations at the positions the end's velocities integrate to, held rotations turning
about the end's tangent, free ends under dead forces and zero moments. What the static
end rows cannot say (follower end loads) is refused by :meth:`CentrelineRod.from_case`
with the field named.

Self-contact and the sea floor are nodal loads on the same rows (:meth:`CentrelineRod.
contact_terms`, :meth:`CentrelineRod.seabed_terms`), their laws those of the seed
scheme's run at the nodes' own r, ṙ and frames; the statics take the same laws at rest.
Screened electrostatics (``electrostatics``, :mod:`solver.electrostatics`) depends on the
positions alone and is the statics' own term (:func:`solver.statics.electrostatic_loads`
in the static rows of the step's problem), its Jacobian ∂L/∂r added on the force rows
and position columns beside the contact's (:meth:`CentrelineRod.pair_load_jacobian`).
Thermal fluctuations (``thermal``, :mod:`solver.thermal`) add the step's random force and
axial moment per length to the nodal loads, constant through the step (drawn by
:meth:`CentrelineRod.step` at the old level's tangents), so the Jacobian is unchanged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from . import statics as st
from .centreline_loads import node_motion_kernel, nodal_loads_kernel, rounding_level
from .kinematics import skew
from .static_band import KL, KU, BandSingular, BorderedBandLU

__all__ = ["AlphaParameters", "CentrelineState", "CentrelineRod", "CentrelineError",
           "StepFailure", "cayley_quaternion", "cayley_vector", "meet_held_ends"]

NV = st.NV


class CentrelineError(ValueError):
    """A case the centreline scheme does not take; the message names the field."""


class StepFailure(ArithmeticError):
    """A step that Newton did not converge (or met a singular Jacobian); ``reason``."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class AlphaParameters:
    """Generalized-α's parameters of one ρ∞ in [0, 1] (Chung & Hulbert 1993, eqs. 25-26;
    the Lie-group form of Arnold, Brüls & Cardona 2015 uses the same)."""

    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float

    @classmethod
    def from_rho_inf(cls, rho: float) -> "AlphaParameters":
        """α_m = (2ρ∞ − 1)/(ρ∞ + 1), α_f = ρ∞/(ρ∞ + 1), γ = ½ + α_f − α_m,
        β = ¼(γ + ½)² (Chung & Hulbert 1993, eqs. 25-26). Raises
        :class:`CentrelineError` for ρ∞ outside [0, 1]."""
        rho = float(rho)
        if not 0.0 <= rho <= 1.0:
            raise CentrelineError(f"numerics.rho_inf: {rho} is not in [0, 1]")
        am = (2.0 * rho - 1.0) / (rho + 1.0)
        af = rho / (rho + 1.0)
        g = 0.5 + af - am
        return cls(am, af, g, 0.25 * (g + 0.5) ** 2)


@dataclass
class CentrelineState:
    """The rod at one time level.

    t : s;  Y : (N+1, 13) r (m), p (unit quaternion w, x, y, z), n (N), m (N m), global
    X : (N+1, 6) ṙ (m/s, global) and W (rad/s, body);  Xd : (N+1, 6) their time
    derivatives;  a : (N+1, 6) generalized-α's algebraic acceleration;  load_rate :
    (N+1, 6) the change of n, m over the last step per second (N/s, N m/s; Newton's
    predictor, zeros by default)
    """

    t: float
    Y: np.ndarray
    X: np.ndarray
    Xd: np.ndarray
    a: np.ndarray
    load_rate: np.ndarray = None

    def __post_init__(self):
        if self.load_rate is None:
            self.load_rate = np.zeros((self.Y.shape[0], 6))

    def copy(self) -> "CentrelineState":
        return CentrelineState(self.t, self.Y.copy(), self.X.copy(), self.Xd.copy(),
                               self.a.copy(), self.load_rate.copy())


@dataclass(frozen=True)
class _Coefficients:
    """A step's affine maps of the increment Δ (N+1, 6) to Ẋ = cXd Δ + dXd and
    X = cX Δ + dX."""

    cXd: float
    dXd: np.ndarray
    cX: float
    dX: np.ndarray


def cayley_quaternion(c):
    """The unit quaternion (..., 4) of the Cayley map of the rotation vector c (..., 3)
    (rad): ∝ (1, c/2), a rotation by 2 atan(|c|/2) about c."""
    c = np.asarray(c)
    q = np.concatenate([np.ones(c.shape[:-1] + (1,), dtype=c.dtype), 0.5 * c], axis=-1)
    return q / np.sqrt(np.sum(q * q, axis=-1, keepdims=True))


def cayley_vector(p_old, p_new):
    """The inverse: Δθ (..., 3) with p_new = p_old ⊗ cay(Δθ), 2 vec(d)/w(d) with
    d = p̄_old ⊗ p_new (complex-step safe; needs a turn below π, w(d) > 0)."""
    d = st._qmul(st._qconj(p_old), p_new)
    return 2.0 * d[..., 1:] / d[..., 0:1]


class CentrelineRod:
    """The rod of a case on the centreline scheme: its rows, its steps, its start.

    Build it with :meth:`from_case`. Attributes: ``props`` (:class:`solver.properties.
    RodProperties`), ``params`` (:class:`AlphaParameters` of ``numerics.rho_inf``),
    ``q0``, ``r0`` (N+1, 4), (N+1, 3): the initial frames and the centreline the box
    rule builds from them (m), ``tolerance`` Newton's on the scaled update.
    """

    #: Newton's test on the update scaled by :meth:`solver.statics.StaticProblem.scales`
    TOLERANCE = 1e-10
    #: the same test on the internal force n, the position rows' multiplier: a residual
    #: δ in the force rows moves the positions by about δ over the inertia's
    #: c_A = 1/(β Δt²) but n by δ itself, so n's update is the force rows' residual
    #: while the positions' is far below it (the seed example's twisting phase: r and p
    #: at 3e-12 while n's update is 3.5e-9; its first 8 s take 255 iterations with n to
    #: 1e-7, 301 with n to 1e-10, the centrelines 2.5e-13 m apart)
    N_TOLERANCE = 1e-7
    #: a chord iteration whose update is not this much smaller than the last refactors
    CHORD_CONTRACTION = 0.25
    #: the largest scaled update taken as rounding's floor when it stops contracting
    FLOOR = 1e-6
    #: the least rounding level of the residual (max over the rows, each in its scale);
    #: a step's own is :func:`rounding_floor` where larger
    RESIDUAL_FLOOR = 1e-8
    MAX_ITERATIONS = 25
    #: with ``thermal``, the largest change of a quaternion's component in one Newton
    #: update (a turn of about 2·0.2 rad): a longer update is shortened to it (a thermal
    #: step's random kicks turn sections by tenths of a radian, and the Cayley map's
    #: velocity 2 vec(d)/w(d) is singular at a half turn: full updates from the old
    #: level overshot there and diverged)
    LARGEST_TURN = 0.2

    #: the largest turn of a node's frame in one step, rad (π/2): a longer step is
    #: refused and cut. The Cayley increment 2 tan(θ/2) grows without bound towards a
    #: half turn, where Newton can land on the other side: the twisted rod of
    #: tests/solver/test_solver_misc.py at Δt = 1 s, ρ∞ 0.5, turned its middle node by
    #: 3.13 rad in a step in which its ends did not turn, a full turn of twist too many
    #: (elastic energy 12 times the work put in)
    LARGEST_STEP_TURN = 0.5 * math.pi

    def __init__(self, case, props, q0, r0):
        self.case = case
        self.props = props
        self.params = AlphaParameters.from_rho_inf(case.numerics.rho_inf)
        self.q0 = q0
        self.r0 = r0
        self.n = props.s.size
        self.h = float(props.ds)
        self.mass = np.asarray(props.rho_a, float)
        self.added = np.asarray(props.added_mass, float)
        self.inertia = np.asarray(props.inertia, float)
        fl = case.fluid
        #: resistive-force theory's Stokes drag coefficients per length (N+1,) each: ζ_n,
        #: ζ_t (N s/m²) and ζ_r (N s) with ``fluid.viscosity``, else None
        self.stokes = None
        if fl is not None and fl.viscosity is not None:
            from .resistive_force import resistive_force_coefficients
            ell = case.rod.length if fl.slenderness_length is None else fl.slenderness_length
            self.stokes = resistive_force_coefficients(fl.viscosity, props.diameter, ell)
        #: the fluid's factors per node for :func:`solver.centreline_loads.
        #: nodal_loads_kernel`: the Stokes drag's (ζ_n, ζ_t, ζ_r) (N+1, 3) and Morison's
        #: drag (½ρ_f D C_dn, ½ρ_f πD C_dt) (N+1, 2) kg/m², zeros where absent
        self.fluid_factors = (np.zeros((self.n, 3)), np.zeros((self.n, 2)))
        if self.stokes is not None:
            self.fluid_factors[0][:] = np.stack(np.broadcast_arrays(*self.stokes), axis=1)
        if fl is not None:
            self.fluid_factors[1][:, 0] = (0.5 * fl.density * props.diameter
                                           * fl.drag_coefficient_normal)
            self.fluid_factors[1][:, 1] = (0.5 * fl.density * np.pi * props.diameter
                                           * fl.drag_coefficient_tangential)
        self.seabed = None
        #: the nodes the sea floor's spring holds on in a Newton solve ((N+1,) bool,
        #: None outside one; :meth:`solve`), and the damper's branch each node is held on
        #: ((N+1,) −1: the law's clamp, 0, 1, 2: :func:`solver.seabed.seabed_points`)
        self.seabed_hold = self.seabed_modes = None
        self._frictionless = self.has_friction = False
        if case.seabed is not None:
            from .seabed import SeabedContact
            self.seabed = SeabedContact(case.seabed, props.diameter)
            scal = np.array(self.seabed.data.scalars, float)
            self.has_friction = bool(scal[4] > 0.0 or scal[5] > 0.0)
            scal[4] = scal[5] = 0.0
            self._frictionless_data = self.seabed.data._replace(scalars=scal)
        self.contact = None
        if case.contact is not None:
            from .contact import SelfContact
            self.contact = SelfContact(case.contact, props.s, props.diameter, props.rho_a,
                                       closed=bool(getattr(case.rod, "closed", False)))
        #: the random loads of ``thermal`` (:class:`solver.thermal.ThermalForcing`), or None
        self.thermal = None
        if getattr(case, "thermal", None) is not None and self.stokes is not None:
            from .thermal import ThermalForcing
            self.thermal = ThermalForcing(case.thermal.temperature, case.thermal.seed,
                                          self.stokes, props.quad_weights)
        self.factorizations = 0            # band LUs so far
        self.paths = {}
        self._last_problem = None          # (t, the problem at t): a step reads it thrice
        #: where an end held after a load phase was when the phase ended: {(item's
        #: field, t_a): r (3,) m} (:func:`solver.statics._dof`), recorded by the run
        self.anchors = {}
        for name, k in (("start", 0), ("end", self.n - 1)):
            ec = getattr(case.boundary, name)
            if EndPath.applies(ec):
                self.paths[name] = EndPath(ec, q0[k], r0[k], case.numerics.t_end,
                                           start=name == "start")
        self._band_index()

    @classmethod
    def from_case(cls, case) -> "CentrelineRod":
        """The rod of a validated case. Raises :class:`CentrelineError` naming the field
        the statics' end rows cannot say."""
        from .initial import initial_pose, node_frames
        from .properties import RodProperties

        props = RodProperties.from_case(case)
        q = node_frames(case, props.s)
        r = initial_pose(case, props.s)[1]
        q = q / np.linalg.norm(q, axis=1)[:, None]
        r = box_centreline(q, r[0], props.ds)
        if not getattr(case.rod, "closed", False):
            try:
                ends = st.problem_at(case, 0.0, props, q, r)
            except st.StaticsError as exc:
                raise CentrelineError(str(exc)) from exc
            q, r = meet_held_ends(q, r, props.s, ends.start, ends.end)
        rod = cls(case, props, q, r)
        rod._check_thermal()
        try:
            rod.problem(0.0)
            # an end held after a load phase: checked with a stand-in for where it stops
            for name, where, t_a in st.load_to_held_switches(case):
                rod.anchors[(where, t_a)] = rod.r0[0 if name == "start" else -1]
            rod.problem(case.numerics.t_end)
        except st.StaticsError as exc:
            raise CentrelineError(str(exc)) from exc
        finally:
            rod.anchors.clear()
            rod._last_problem = None
        return rod

    def anchor(self, where: str, t_a: float, r) -> None:
        """Record that the end of the translation item ``where`` held from t_a (s) on,
        after a load phase, was at r (3,) m then (:func:`solver.statics._dof`)."""
        self.anchors[(where, float(t_a))] = np.array(r, float)
        self._last_problem = None

    def _check_thermal(self) -> None:
        """Refuse a thermal case whose ρ∞ and Δt cannot hold its temperature
        (:func:`solver.thermal.check_step`: the resolved modes at this m/(ζΔt), and the
        lowest bending mode). Raises :class:`CentrelineError` naming ``numerics.rho_inf``
        or ``numerics.dt``."""
        if self.thermal is None:
            return
        from .plausibility import lowest_bending_relaxation_time
        from .thermal import check_step

        num = self.case.numerics
        refused = check_step(self.params, num.dt, self.inertial_time(),
                             lowest_bending_relaxation_time(self.case))
        if refused is not None:
            field, why = refused
            raise CentrelineError(f"{field}: {why}")

    # ------------------------------------------------------------------ the rows
    def problem(self, t: float) -> st.StaticProblem:
        """The static rows' problem at time t (s): ends and dead loads then; an end
        turned by body-frame angular velocities takes its frame and held position from
        its :class:`EndPath`."""
        if self._last_problem is not None and self._last_problem[0] == t:
            return self._last_problem[1]
        prob = st.problem_at(self.case, t, self.props, self.q0, self.r0,
                             skip=tuple(self.paths), anchors=self.anchors)
        if prob.seabed is not None or prob.contact is not None:
            # the dynamic laws' (seabed_terms, contact_terms)
            prob = replace(prob, seabed=None, contact=None)
        if self.paths:
            prob = replace(prob, **{name: path.spec(t, getattr(prob, name).force)
                                    for name, path in self.paths.items()})
        self._last_problem = (t, prob)
        return prob

    def increments(self, Y, old: CentrelineState):
        """Δ (..., N+1, 6): Δr (m) and the body rotation increment Δθ (rad) of Y
        (..., N+1, 13) from the old level (complex-step safe)."""
        dr = Y[..., 0:3] - old.Y[:, 0:3]
        dth = cayley_vector(old.Y[:, 3:7], Y[..., 3:7])
        return np.concatenate([dr, dth], axis=-1)

    def nodal_loads(self, Y, old: CentrelineState, co: _Coefficients, want: bool = False):
        """Inertia and fluid loads per length at the nodes (N+1, 6), global: force
        f_fluid − M r̈ (N/m) and moment −R(I Ẇ + W × I W) − ζ_r W3 a3 (N m/m), of Y
        (N+1, 13) at the new level; with ``want`` also their derivative by each node's
        (r, p), (N+1, 6, 7), exact by the complex step (else None). f_fluid is Morison's
        drag (module docstring) plus, with ``fluid.viscosity``, resistive-force theory's
        Stokes drag −R(ζ_n v_n + ζ_t v_t e3) on the body velocity v = Rᵀṙ (:mod:`solver.
        resistive_force`); with ``thermal``, plus the step's random loads
        (:attr:`solver.thermal.ThermalForcing.load`, a constant of the step). Compiled:
        :func:`solver.centreline_loads.nodal_loads_kernel`."""
        n1 = self.n
        L = np.empty((n1, 6))
        dL = np.empty((n1, 6, 7)) if want else np.empty((0, 6, 7))
        zeta, drag = self.fluid_factors
        nodal_loads_kernel(np.ascontiguousarray(Y, dtype=float), old.Y, float(co.cXd),
                           np.ascontiguousarray(co.dXd, dtype=float), float(co.cX),
                           np.ascontiguousarray(co.dX, dtype=float),
                           self.mass, self.added, self.inertia, zeta, drag, bool(want),
                           L, dL)
        if self.thermal is not None and self.thermal.load is not None:
            L += self.thermal.load                 # the step's random loads, constant
        return L, (dL if want else None)

    def seabed_terms(self, Y, old: CentrelineState, co: _Coefficients, want: bool,
                     laws=None):
        """The sea floor's loads per length at the nodes (N+1, 6), global (normal
        reaction plus Coulomb friction, N/m; friction's moment about the centreline,
        N m/m), the law of :mod:`solver.seabed` at each node's r, ṙ, Ω, a3 and radius
        (:func:`solver.seabed.seabed_points`), the same nodal law and trapezoid as the
        statics' normal spring (:func:`solver.statics.seabed_loads`); the loads
        (N+1, 6) split as (normal (N+1, 3), friction (N+1, 3), moment (N+1, 3),
        penetration (N+1,) m); and with ``want`` their exact derivative (N+1, 6, 7) with
        respect to each node's (r, p): the law's partials by (x, u, Ω, t) chained with
        ∂(r, ṙ)/∂r = (I, c_X I) and ∂(Ω, a3)/∂p by the complex step (4 evaluations).
        The damper's branch of each node is ``seabed_modes``' (None: the law's clamp
        everywhere; :meth:`_held_solve`); ``laws`` (N+1,), where given, receives the law's
        own branch at each touching node (−1 elsewhere). None without a seabed."""
        if self.seabed is None:
            return None
        from .seabed import seabed_points

        n1 = self.n
        x = np.ascontiguousarray(Y[:, 0:3], dtype=float)
        u, Om, t = np.empty((n1, 3)), np.empty((n1, 3)), np.empty((n1, 3))
        dOm, dt = (np.empty((n1, 3, 4)), np.empty((n1, 3, 4))) if want else (
            np.empty((0, 3, 4)), np.empty((0, 3, 4)))
        node_motion_kernel(np.ascontiguousarray(Y, dtype=float), old.Y, float(co.cX),
                           np.ascontiguousarray(co.dX, dtype=float), bool(want),
                           u, Om, t, dOm, dt)
        F, M = np.empty((n1, 6)), np.empty((n1, 3))
        DF, DM = np.empty((n1, 3, 12)), np.empty((n1, 3, 12))
        pen = np.empty(n1)
        hold = self.seabed_hold if self.seabed_hold is not None else np.zeros(n1, bool)
        modes = self.seabed_modes if self.seabed_modes is not None else np.full(n1, -1.0)
        laws = np.empty(n1) if laws is None else laws
        data = self._frictionless_data if self._frictionless else self.seabed.data
        seabed_points(x, u, Om, t, self.seabed.radius, data, bool(want),
                      hold, modes, F, M, DF, DM, pen, laws)
        L = np.concatenate([F[:, 0:3] + F[:, 3:6], M], axis=1)
        split = (F[:, 0:3], F[:, 3:6], M, pen)
        if not want:
            return L, split, None
        chain = np.zeros((n1, 12, 7))
        chain[:, 0:3, 0:3] = np.eye(3)
        chain[:, 3:6, 0:3] = co.cX * np.eye(3)
        chain[:, 6:9, 3:7] = dOm
        chain[:, 9:12, 3:7] = dt
        block = np.einsum("kij,kjl->kil", np.concatenate([DF, DM], axis=1), chain)
        return L, split, block

    def contact_terms(self, Y, old: CentrelineState, co: _Coefficients, want: bool):
        """Self-contact's loads per length at the nodes (N+1, 3) N/m, global: the model of
        :mod:`solver.contact.model` (its law with the approach rate's damping, between
        each node and the closest point of the partner curve) at the nodes' r and ṙ of Y
        (N+1, 13), the candidates searched afresh (within the tolerance) so that the
        loads are a function of Y; the :class:`solver.contact.ContactEvaluation`; and with
        ``want`` their derivative ∂L/∂r (3(N+1), 3(N+1)) sparse
        (:func:`solver.contact.assemble_nodal_jacobian` with ∂F/∂r + c_X ∂F/∂v, as
        ṙ = c_X Δr + d_X; the pair derivatives of the seed scheme's contact, exact). None
        without ``contact``; (zeros, None, None) where no pair is within the tolerance.
        The loads act on positions only (the aperture's tangent test picks the
        candidates, a choice, not a load)."""
        if self.contact is None:
            return None
        from .contact import assemble_nodal, assemble_nodal_jacobian

        n1 = self.n
        Yr = np.real(Y)
        r = np.ascontiguousarray(Yr[:, 0:3], dtype=float)
        if not np.all(np.isfinite(r)):
            raise StepFailure("non-finite positions")
        u = np.ascontiguousarray(co.cX * (Yr[:, 0:3] - old.Y[:, 0:3]) + co.dX[:, 0:3])
        a3 = np.ascontiguousarray(st._a3(Yr[:, 3:7]))
        cand = self.contact.search(r, a3)
        ev = None
        if cand is not None:
            try:
                ev = self.contact.evaluate(cand, r, u)
            except ValueError as exc:
                raise StepFailure(f"contact: {exc}") from exc
        if ev is None or ev.count == 0:
            return np.zeros((n1, 3)), ev, None
        L = assemble_nodal(ev, n1)
        if not want:
            return L, ev, None
        dL = assemble_nodal_jacobian(ev, n1, ev.d_force_d_r + co.cX * ev.d_force_d_v)
        return L, ev, dL

    def residual(self, Y, old, co, prob, seabed=None) -> np.ndarray:
        """The 13(N+1) dynamic rows (the static rows, with electrostatics where the case
        has it, plus the nodal loads' trapezoid on the force and moment rows: inertia,
        fluid, the sea floor and self-contact) of Y (N+1, 13);
        ``seabed``: :meth:`seabed_terms` at Y already evaluated (None: evaluated here)."""
        try:
            G = st.residual(Y, prob)
        except st.StaticsError as exc:            # the electrostatics' pairs
            raise StepFailure(str(exc)) from exc
        L = self.nodal_loads(Y, old, co)[0]
        sb = self.seabed_terms(Y, old, co, want=False) if seabed is None else seabed
        if sb is not None:
            L = L + sb[0]
        if self.contact is not None:
            L[:, 0:3] += self.contact_terms(Y, old, co, want=False)[0]
        cells = G[st.N_START:-st.N_END].reshape(self.n - 1, NV)
        cells[:, 7:13] += 0.5 * self.h * (L[:-1] + L[1:])
        return G

    def _band_index(self):
        """Where each node's 6 × 7 load block lands in the band storage (rows, cols)."""
        N = self.n - 1
        k = np.arange(N + 1)
        a = np.arange(6)
        b = np.arange(7)
        rows, cols, nodes = [], [], []
        for cell in (k - 1, k):                      # the cells left and right of node k
            ok = (cell >= 0) & (cell < N)
            kk, cc = k[ok], cell[ok]
            rr = st.N_START + NV * cc[:, None, None] + 7 + a[None, :, None] + 0 * b
            col = NV * kk[:, None, None] + b[None, None, :] + 0 * a[:, None]
            rows.append(rr)
            cols.append(col)
            nodes.append(kk)
        rows = np.concatenate(rows).ravel()
        cols = np.concatenate(cols).ravel()
        #: the nodes' load blocks' entries in the band storage (2 KL + KU + 1, 13(N+1)),
        #: Fortran-ordered, as indices into its flat view; and the node of each block
        self._band_at = (KL + KU + rows - cols + (2 * KL + KU + 1) * cols,
                         np.concatenate(nodes))

    def jacobian(self, Y, old, co, prob) -> np.ndarray:
        """∂G/∂Y in LAPACK band storage, exact to rounding: the static band
        (:func:`solver.statics.band_jacobian`) plus h/2 of each node's load block
        ∂L_k/∂(r_k, p_k), by the complex step (7 evaluations, all nodes at once). The
        pairs' loads (self-contact, electrostatics) are not a band:
        :meth:`pair_load_jacobian`."""
        ab = st.band_jacobian(Y, st.without_pair_loads(prob))
        block = self.nodal_loads(Y, old, co, want=True)[1]     # (N+1, 6, 7)
        sb = self.seabed_terms(Y, old, co, want=True)
        if sb is not None:
            block = block + sb[2]
        self._add_blocks(ab, block)
        return ab

    def _add_blocks(self, ab, block) -> None:
        """Adds h/2 of each node's 6 × 7 block (N+1, 6, 7) to the force and moment rows of
        the cells either side of it in ``ab`` (LAPACK band storage, Fortran-ordered),
        each entry once, through ab's flat view (its own memory). Raises ValueError
        where ab is not Fortran-contiguous (the flat view would be a copy)."""
        if not ab.flags.f_contiguous:
            raise ValueError("the band storage must be Fortran-ordered")
        flat, nodes = self._band_at
        ab.reshape(-1, order="F")[flat] += 0.5 * self.h * block[nodes].ravel()

    def growth_rate(self, state: CentrelineState, shift: float, v0=None):
        """The fastest growth rate near ``shift`` (1/s) of the dynamics linearised about
        a level: (σ (1/s, −inf where none is found), the eigenvector (2·13(N+1),) in
        the scaled unknowns) of
        :func:`solver.stepping.guard.pencil_growth_rate` on :meth:`pencil`, or None
        where the level has pairs (self-contact or electrostatics within reach) or is
        a closed rod (their couplings are not in the band; the contact law's stiffness
        is no instability), in a viscous fluid (on cases/dna-tweezers.yaml, a straight
        DNA spun at 4400 rad/s, 0.25 turns below Greenhill's twist, the pencil's rates
        kept pace with the shift at every cut, 1.2e6 to 4.6e10 1/s, and ended the run),
        or where the level is not near a static balance (:meth:`dynamic_share` above
        QUASI_STATIC). Columns scaled by
        :meth:`solver.statics.StaticProblem.scales`."""
        import scipy.sparse as sp

        from .static_band import band_to_sparse
        from .stepping.guard import pencil_growth_rate

        prob = self.problem(state.t)
        rest = _Coefficients(0.0, state.Xd, 0.0, state.X)
        if (prob.closed or self.stokes is not None
                or self.dynamic_share(state, prob) > self.QUASI_STATIC
                or self.pair_load_jacobian(state.Y, state, rest, prob) is not None):
            return None
        s = float(shift)
        K, C, M = self.pencil(state, prob)
        d = np.tile(prob.scales(), self.n)
        D = sp.diags(d)
        try:
            lu = BorderedBandLU(K + s * C + s * s * M)
        except BandSingular:
            return -math.inf, None
        return pencil_growth_rate(lambda b: lu.solve(b) / d, band_to_sparse(M[KL:]) @ D,
                                  band_to_sparse(C[KL:]) @ D, s, v0)

    #: the largest :meth:`dynamic_share` at which :meth:`growth_rate` estimates σ
    QUASI_STATIC = 0.1

    def dynamic_share(self, state: CentrelineState, prob) -> float:
        """How far a level is from a static balance: the largest inertia and fluid force
        per length at its nodes (:meth:`nodal_loads`, N/m) over the static force scale
        B/L³ + max |f| + max |n|/L (B the largest bending stiffness, f the dead loads
        per length, n the level's internal force). 0 at rest. The growth guard's
        frozen rates are those of an instability growing from a near balance: on the
        DNA-like rod of tests/solver/test_stability.py twisted past Greenhill and at
        rest (share 8e-13) σ = 9.03e3 1/s, and a run perturbed along the mode grows at
        9.02e3 1/s; once it buckles (shares 0.4 to 6) the frozen pencil has rates of
        5e4 to 5e6 1/s where runs perturbed along the mode, at steps of 0.05/σ, decay
        (``python -m research.centreline_growth_rate``)."""
        L = self.nodal_loads(state.Y, state, _Coefficients(0.0, state.Xd, 0.0, state.X))[0]
        B = float(np.max(self.props.stiffness[:, :2]))
        length = float(self.props.s[-1])
        scale = (B / length**3 + float(np.abs(prob.load).max())
                 + float(np.abs(state.Y[:, 7:10]).max()) / length)
        return float(np.abs(L[:, 0:3]).max()) / scale

    def pencil(self, state: CentrelineState, prob):
        """(K, C, M), each (2KL + KU + 1, 13(N+1)) in LAPACK band storage: the dynamics
        linearised about a level, M ÿ + C ẏ + K y = 0 for a perturbation y of its
        (r, p, n, m), frozen at its velocities and accelerations.

        A step's rows are affine in generalized-α's coefficients of Ẋ = c_Ẋ Δ + d_Ẋ and
        X = c_X Δ + d_X (:meth:`coefficients`); about the level itself (old = the level,
        Δ = 0, d_Ẋ and d_X its own Ẋ and X) the nodal loads' blocks at (c_Ẋ, c_X) =
        (1, 0), (0, 1) and (0, 0) give M (the inertia) and C (the fluid's, the sea
        floor's and the gyroscopic rate terms) by differences, and K is the step's
        Jacobian at (0, 0). A body-frame perturbation η of a frame moving at W changes
        its angular velocity by δW = η̇ + W × η and δẆ = η̈ + W × η̇ + Ẇ × η (from
        R exp(η̂)); the step's Cayley increments leave that transport to the group, so
        it is added here: with A = ∂L/∂Ẇ and B = ∂L/∂W per node (the p-columns of M and
        C through Θ⁺ = Θᵀ/4, Θ = ∂Δθ/∂p = 2 vec(p̄ ⊗ ·)), K gains (A [Ẇ]× + B [W]×) Θ
        and C gains A [W]× Θ. Raises nothing of its own (what :meth:`jacobian` and
        :meth:`nodal_loads` raise on a non-finite level)."""
        Y = state.Y

        def blocks(c1, c2):
            co = _Coefficients(c1, state.Xd, c2, state.X)
            b = self.nodal_loads(Y, state, co, want=True)[1]
            sb = self.seabed_terms(Y, state, co, want=True)
            return b if sb is None else b + sb[2]

        b0 = blocks(0.0, 0.0)
        Mb, Cb = blocks(1.0, 0.0) - b0, blocks(0.0, 1.0) - b0
        p = Y[:, 3:7]
        theta = np.empty((self.n, 3, 4))
        for j in range(4):
            e = np.zeros_like(p)
            e[:, j] = 1.0
            theta[:, :, j] = 2.0 * st._qmul(st._qconj(p), e)[:, 1:]
        A = Mb[:, :, 3:7] @ theta.transpose(0, 2, 1) / 4.0
        B = Cb[:, :, 3:7] @ theta.transpose(0, 2, 1) / 4.0
        W, Wd = skew(state.X[:, 3:6]), skew(state.Xd[:, 3:6])
        Kt, Ct = np.zeros_like(b0), np.zeros_like(b0)
        Kt[:, :, 3:7] = (A @ Wd + B @ W) @ theta
        Ct[:, :, 3:7] = A @ W @ theta
        K = self.jacobian(Y, state, _Coefficients(0.0, state.Xd, 0.0, state.X), prob)
        out = []
        for blk in (Kt, Cb + Ct, Mb):
            ab = np.zeros_like(K) if blk is not Kt else K
            self._add_blocks(ab, blk)
            out.append(ab)
        return tuple(out)

    # ------------------------------------------------------------------ the step
    def coefficients(self, old: CentrelineState, h: float) -> _Coefficients:
        """Generalized-α's affine maps Δ -> Ẋ, X for a step h (s) from ``old``."""
        p = self.params
        cA = 1.0 / (p.beta * h * h)
        dA = -(h * old.X + h * h * (0.5 - p.beta) * old.a) * cA
        cXd = (1.0 - p.alpha_m) / (1.0 - p.alpha_f) * cA
        dXd = ((1.0 - p.alpha_m) * dA + p.alpha_m * old.a - p.alpha_f * old.Xd) / (1.0 - p.alpha_f)
        cX = h * p.gamma * cA
        dX = old.X + h * (1.0 - p.gamma) * old.a + h * p.gamma * dA
        return _Coefficients(cXd, dXd, cX, dX)

    def predict(self, old: CentrelineState, h: float) -> np.ndarray:
        """Newton's start: the increment of a_n+1 = a_n; n and m extrapolated along
        their rate over the last step (``old.load_rate``; zero after a start)."""
        D = h * old.X + 0.5 * h * h * old.a
        Y = old.Y.copy()
        Y[:, 7:13] += h * old.load_rate
        Y[:, 0:3] += D[:, 0:3]
        Y[:, 3:7] = st._qmul(old.Y[:, 3:7], cayley_quaternion(D[:, 3:6]))
        return Y

    #: re-decisions of the sea floor's held contact set in one step
    REDECISIONS = 30
    #: the scaled update below which a round of the sea floor's held contact set ends and
    #: the set is re-decided (:meth:`_held_solve`); the last round converges to TOLERANCE
    REDECIDE_AT = 0.1

    def solve(self, old, co, prob, Y) -> tuple[np.ndarray, int, float]:
        """Newton on the dynamic rows from Y (:meth:`newton`); (Y, iterations, scaled
        update). With a sea floor, Newton holds a contact set: the nodes touching at the
        old level or at Y hold the spring's line through p = 0 (pulling where an iterate
        lifts them, :func:`solver.seabed.seabed_points`), so that the iterates do not
        cycle between nodes touching and lifted (the force's kink at p = 0); a solution
        where a held node does not touch releases it and Newton goes on from there, up
        to REDECISIONS times; the rounds before the first in which no held node is
        pulled end once Newton's scaled update is below REDECIDE_AT (the set is re-decided
        from a near solution: a cable lifting off the bottom peels a node or two a round,
        and converging every round to TOLERANCE was wasted work). A solution where no
        held node is pulled is the law's (the
        primal-dual active-set strategy as a semismooth Newton method: M. Hintermüller,
        K. Ito, K. Kunisch, SIAM J. Optim. 13, 2002); a node an iterate presses into the
        bottom joins the held set. Where the damper's slope in the step exceeds the
        spring's (c c_X > k, c_X = γ/(βh): a step short against c/k), the damper's clamp
        (N between 0 and 2kp) is held the same way: each node touching at Newton's start
        keeps the law's branch there (N = 0, the free kp − c n·ṙ, or 2kp) through a
        round, and a round whose solution has a node on a branch the law does not take
        there re-decides it (:func:`next_branches`) and goes on. There the clamp's slope
        jumps by c c_X/k across its bounds, which swap with the sign of n·ṙ between
        iterates: Newton cycled (the seed scheme holds its cells' branches alike:
        :mod:`solver.seabed`). Raises :class:`StepFailure`."""
        if self.seabed is None:
            return self.newton(old, co, prob, Y)
        rest = _Coefficients(0.0, old.Xd, 0.0, old.X)
        hold = (self._penetration(Y, old, co) >= 0.0) | (self._penetration(old.Y, old, rest) >= 0.0)
        try:
            return self._held_solve(old, co, prob, Y, hold)
        except StepFailure:
            if not self.has_friction:
                raise
        # friction's force scales with the normal one: from iterates pressed deep into the
        # bottom it threw Newton off; settle the normal contact first
        self._frictionless = True
        try:
            Y, its_a, _ = self._held_solve(old, co, prob, Y, hold)
        finally:
            self._frictionless = False
        Y, its, err = self._held_solve(old, co, prob, Y, self._penetration(Y, old, co) > 0.0)
        return Y, its_a + its, err

    def _penetration(self, Y, old, co, laws=None) -> np.ndarray:
        """The nodes' surface penetration (N+1,) m into the bottom (negative: the gap);
        ``laws`` (N+1,), where given, receives the law's damper branch at each touching
        node (−1 elsewhere)."""
        return self.seabed_terms(Y, old, co, False, laws)[1][3]

    def _held_solve(self, old, co, prob, Y, hold):
        """:meth:`newton` holding the contact set ``hold`` (N+1,) bool and each touching
        node's damper branch, re-decided where a held node is pulled or a node's held
        branch is not the law's at the round's solution (:meth:`solve`): to REDECIDE_AT
        until a round needs neither, from then on to TOLERANCE."""
        total = 0
        loose = True
        laws = np.empty(self.n)
        scal = self.seabed.data.scalars
        # the law's branches at Newton's start, held where the damper's slope in the
        # step, c c_X, exceeds the spring's k (else the clamp's kinks are mild: None)
        modes = None
        if scal[3] * co.cX > scal[2]:
            self._penetration(Y, old, co, laws)
            modes = laws.copy()
        try:
            for _ in range(self.REDECISIONS + 1):
                self.seabed_hold, self.seabed_modes = hold, modes
                Y, its, err = self.newton(old, co, prob, Y,
                                          self.REDECIDE_AT if loose else None)
                total += its
                hold = self.seabed_hold
                self.seabed_hold = None
                pulled = hold & (self._penetration(Y, old, co, laws) <= 0.0)
                off = (False if modes is None
                       else ((modes >= 0.0) & (laws >= 0.0) & (modes != laws)).any())
                if not pulled.any() and not off:
                    if not loose:
                        return Y, total, err
                    loose = False                 # the same set, to TOLERANCE
                    continue
                hold = hold & ~pulled
                if modes is not None:
                    modes = next_branches(modes, laws)
        finally:
            self.seabed_hold = self.seabed_modes = None
        raise StepFailure(f"the sea floor's contact set did not settle in "
                          f"{self.REDECISIONS} re-decisions")

    def newton(self, old, co, prob, Y, tolerance=None) -> tuple[np.ndarray, int, float]:
        """Newton on the dynamic rows from Y; (Y, iterations, scaled update);
        ``tolerance`` the scaled update to stop at (default TOLERANCE).

        Chord iterations: the band LU of the first iterate is kept while the updates
        contract by CHORD_CONTRACTION or better, and refactored at the current iterate
        where they do not (a full Newton step; the Jacobian is exact). Converged when the
        update scaled by :meth:`solver.statics.StaticProblem.scales` (n and m by their
        largest value at the start instead, where larger) is below TOLERANCE in r, p and
        m and below N_TOLERANCE (or ``tolerance`` where larger) in n, or below FLOOR and
        no longer contracting (rounding's floor: the step's matrix grows as 1/(β Δt²),
        and so does the rounding of its solve), or when an update no longer halves from a
        residual below its rounding level (:meth:`_factor`) in the rows' scales (an
        inextensible rod between held ends: its tension is rounding's noise at 1e-5 of
        B/L², the residual at 1e-10 of it). Raises :class:`StepFailure` without
        convergence in MAX_ITERATIONS, on a singular Jacobian or a non-finite update."""
        scale = self._update_scales(Y, prob)
        weights = 1.0 / st._row_scales(prob)
        tol = self.TOLERANCE if tolerance is None else tolerance
        # the tension's updates relative to the others' tolerance (n_tol / tol >= 1)
        slack = max(tol, self.N_TOLERANCE) / tol
        err = math.inf
        lu = None
        trial = None      # the line search's residual and chord update at the full step
        for it in range(1, self.MAX_ITERATIONS + 1):
            sb = None
            if self.seabed_hold is not None and it > 1:
                sb, grown = self._grow_hold(Y, old, co)
                if grown:
                    lu = trial = None
            if trial is not None:
                G, dY = trial          # this iterate's, computed by the line search
                trial = None
            else:
                G = self.residual(Y, old, co, prob, sb)
                if lu is None:
                    lu, floor = self._factor(Y, old, co, prob, weights)
                    fresh = True
                dY = lu.solve(G, refine=False).reshape(Y.shape)
            if not np.all(np.isfinite(dY)):
                raise StepFailure("non-finite Newton update")
            turn = float(np.abs(dY[:, 3:7]).max())
            if self.thermal is not None and turn > self.LARGEST_TURN:
                dY = dY * (self.LARGEST_TURN / turn)
            q = np.abs(dY) / scale
            prev, err = err, float(q.max())
            at_floor = float(np.max(np.abs(G) * weights)) < floor
            if at_floor and it > 1 and err > 0.5 * prev:
                # the residual is rounding's and the update no longer contracts: the
                # update is the solve's rounding (the step's matrix grows as 1/(β Δt²))
                return Y, it, prev
            if not fresh and err > self.CHORD_CONTRACTION * prev:
                lu = None                                  # refactor here, redo
                err = prev
                continue
            if fresh and err > self.FLOOR:
                # a fresh Newton step: take the part of it that passes the natural
                # monotonicity test (full steps cycled on the friction's saturation and
                # overshot into the contact law); where none does, the whole step
                # unless it grew tenfold
                lam, trial = self._line_search(Y, dY, old, co, prob, lu, scale)
                if lam == 0.0 and err > 10.0 * prev:
                    raise StepFailure(f"Newton diverging (scaled update {prev:.3g} -> "
                                      f"{err:.3g} with a fresh Jacobian, no descent along it)")
                if 0.0 < lam < 1.0:
                    Y = Y - lam * dY
                    lu = None
                    err = prev
                    continue
                # at λ = 1 the test's residual and correction are the next chord
                # iteration's (the same iterate Y − dY and factor): kept for it
            stalled = err > 0.5 * prev
            at_rounding = fresh and stalled and at_floor
            fresh = False
            Y = Y - dY
            if (_tension_relaxed(q, slack) < tol or (err < self.FLOOR and stalled)
                    or at_rounding):
                return Y, it, err
        raise StepFailure(f"Newton did not converge in {self.MAX_ITERATIONS} iterations "
                          f"(scaled update {err:.3g})")

    @staticmethod
    def _update_scales(Y, prob) -> np.ndarray:
        """The scales (13,) of the unknowns' Newton updates: the problem's
        (:meth:`solver.statics.StaticProblem.scales`), n and m relative to their largest
        value in Y where that exceeds B/L², B/L (a rod pressed by loads far above its
        stiffness's scale: the updates of n then sit at the rounding of the loads, not of
        B/L²)."""
        scale = prob.scales().copy()
        scale[7:10] = max(scale[7], float(np.abs(Y[:, 7:10]).max()))
        scale[10:13] = max(scale[10], float(np.abs(Y[:, 10:13]).max()))
        return scale

    def _grow_hold(self, Y, old, co):
        """The sea floor's terms at Y (:meth:`seabed_terms`, no derivative) and whether the
        held contact set grew: a node an iterate presses into the bottom (p > 0) joins it
        for the rest of the round (its load is the law's either way, so the terms serve
        the residual too)."""
        sb = self.seabed_terms(Y, old, co, False)
        touch = sb[1][3] > 0.0
        if np.any(touch & ~self.seabed_hold):
            self.seabed_hold = self.seabed_hold | touch
            return sb, True
        return sb, False

    def _factor(self, Y, old, co, prob, weights):
        """The step's Jacobian at Y factored (the band LU; SuperLU where self-contact's
        pairs or a closed rod's join couple nodes outside the band, :class:`_SparseLU`)
        and the residual's rounding level there (at least RESIDUAL_FLOOR,
        :func:`rounding_floor`). Raises :class:`StepFailure` on a singular Jacobian."""
        ab = self.jacobian(Y, old, co, prob)
        dL = self.pair_load_jacobian(Y, old, co, prob)
        extra = None
        if dL is not None:
            extra = st._load_rows(prob) @ dL @ st._position_columns(prob)
        if prob.closed:
            join = st.join_coupling(Y, prob)
            extra = join if extra is None else extra + join
        try:
            if extra is None:
                lu = BorderedBandLU(ab)
                floor = rounding_floor(ab, Y, weights)
            else:
                lu = _SparseLU(ab, extra)
                floor = lu.rounding_floor(Y, weights)
        except (BandSingular, RuntimeError) as exc:
            raise StepFailure(f"singular Jacobian ({exc})") from exc
        self.factorizations += 1
        return lu, max(self.RESIDUAL_FLOOR, floor)

    def pair_load_jacobian(self, Y, old, co, prob):
        """The pairs' load derivative ∂L/∂r (3(N+1), 3(N+1)) sparse, N/m², at Y
        (N+1, 13): self-contact's (:meth:`contact_terms`, with its velocities' c_X) plus
        the electrostatics' (position only: :func:`solver.statics.electrostatic_loads`
        of the step's problem); None where neither has a pair. Raises
        :class:`StepFailure` as :meth:`residual`."""
        ct = self.contact_terms(Y, old, co, want=True)
        dL = None if ct is None else ct[2]
        if prob.electrostatics is not None:
            try:
                de = st._electrostatic_load_jacobian(Y, prob)
            except st.StaticsError as exc:
                raise StepFailure(str(exc)) from exc
            if de.nnz:
                dL = de if dL is None else dL + de
        return dL

    #: the smallest fraction of a Newton step the line search takes (2⁻⁸)
    SMALLEST_STEP = 2.0 ** -8

    def _line_search(self, Y, dY, old, co, prob, lu, scale):
        """(λ, trial): the first λ of 1, ½, ¼ ... (down to SMALLEST_STEP) that passes the
        natural monotonicity test: the simplified Newton correction at Y − λ dY,
        J⁻¹G(Y − λ dY) with the same factor ``lu``, is smaller than (1 − λ/4) of dY's in
        the unknowns' scaled 2-norm (``scale`` (13,) per kind of unknown); 0 where none
        does; ``trial`` the residual G (13(N+1),) and that correction (N+1, 13) at λ = 1
        where it passes (else None).
        Deuflhard, *Newton Methods for Nonlinear Problems*, 2004, § 3.3 (NLEQ-ERR): the
        test is affine invariant, so rows of very different stiffness (self-contact's
        law, the sea floor's spring and friction) do not decide it as they did a
        backtracking on the residual's norm (§ 3.1), which took steps of 1/8 … 1/64
        through a collapse into contact and cut Δt (measured on the seed example's
        contact phase, 17.5-20 s: 95 steps and 799 factorizations against 29 and 134)."""
        n0 = float(np.sqrt(np.mean((dY / scale) ** 2)))
        lam = 1.0
        while lam > self.SMALLEST_STEP:
            with np.errstate(over="ignore", invalid="ignore"):
                try:
                    G = self.residual(Y - lam * dY, old, co, prob)
                    bar = lu.solve(G).reshape(Y.shape)
                    nt = float(np.sqrt(np.mean((bar / scale) ** 2)))
                except StepFailure:
                    nt = math.inf
            if math.isfinite(nt) and nt <= (1.0 - 0.25 * lam) * n0:
                return lam, ((G, bar) if lam == 1.0 else None)
            lam *= 0.5
        return 0.0, None

    def _start_guess(self, old, co, prob, h) -> np.ndarray:
        """Newton's start for a step of h from ``old``: :meth:`predict`; with self-contact,
        the old level instead where its residual is smaller in the rows' scaled 2-norm
        (an extrapolation across a collapse pushes strands deep into the contact law,
        whose residual Newton does not come back from); the same with ``thermal`` (the
        last step's velocity is its random kick, which the next step does not repeat) and
        with a sea floor (a cable lifting off the bottom changes n by tens of newtons in a
        cut step, and n extrapolated along that rate over the next step threw Newton
        off)."""
        Y = self.predict(old, h)
        if self.contact is None and self.thermal is None and self.seabed is None:
            return Y
        weights = 1.0 / st._row_scales(prob)
        with np.errstate(over="ignore", invalid="ignore"):
            g_pred = float(np.linalg.norm(self.residual(Y, old, co, prob) * weights))
            g_old = float(np.linalg.norm(self.residual(old.Y, old, co, prob) * weights))
        return old.Y.copy() if g_old < g_pred or not math.isfinite(g_pred) else Y

    def step(self, old: CentrelineState, h: float,
             t: float | None = None) -> tuple[CentrelineState, int, float]:
        """One generalized-α step of h (s) from ``old``: (the new state, Newton
        iterations, last scaled update); ``t`` the new level's time where it is exactly a
        breakpoint (default old.t + h), whose loads and conditions are then their left
        limits (those of the last float below t: a load switched on at t acts from the
        next step on, a restart's, :class:`solver.centreline_run.CentrelineRun`).
        ``old`` is not changed. With ``thermal``, the attempt's random loads are drawn
        first (:meth:`solver.thermal.ThermalForcing.prepare`: the same interval gives the
        same loads until the run accepts it). Raises :class:`StepFailure`."""
        if t is None:
            t = old.t + h
            prob = self.problem(t)
        else:
            t = float(t)
            prob = self.problem(float(np.nextafter(t, -np.inf)))
        co = self.coefficients(old, h)
        if self.thermal is not None:
            # the random loads of this attempt, a3 at the old level (solver.thermal)
            self.thermal.prepare(old.t, h, st._a3(old.Y[:, 3:7]))
        Y, its, err = self.solve(old, co, prob, self._start_guess(old, co, prob, h))
        D = self.increments(Y, old)
        turn = 2.0 * float(np.arctan(0.5 * np.sqrt(np.max(np.sum(D[:, 3:6] ** 2, axis=1)))))
        if turn > self.LARGEST_STEP_TURN:
            raise StepFailure(f"a node turned by {turn:.3g} rad in the step (more than "
                              f"{self.LARGEST_STEP_TURN:.3g})")
        p = self.params
        a = (D - h * old.X - h * h * (0.5 - p.beta) * old.a) / (p.beta * h * h)
        new = CentrelineState(t, Y, co.cX * D + co.dX, co.cXd * D + co.dXd, a,
                              (Y[:, 7:13] - old.Y[:, 7:13]) / h)
        return new, its, err

    #: the impact step's length as a share of the run's Δt (:meth:`impact`)
    IMPACT_STEP = 1e-6

    def impact(self, level: CentrelineState) -> np.ndarray:
        """The velocities X+ (N+1, 6) (ṙ m/s, body angular velocity W rad/s) just after
        ``level``, where a condition that holds an end took over from a load (an
        impulsive constraint: the end's velocity jumps, and with it the rod's): one backward-Euler step of δ = IMPACT_STEP Δt on the
        rows in force after level.t, Ẋ = (X+ − X−)/δ, X+ = Δ/δ. As δ → 0 its rows are
        the impulse–momentum balance M (X+ − X−) = the constraints' impulse with X+
        satisfying the constraints' velocity form (a perfectly inelastic impact; Pfeiffer
        & Glocker, *Multibody Dynamics with Unilateral Contacts*, 1996, ch. 6); its
        positions, δ X+ away, are not kept. Raises :class:`StepFailure`."""
        delta = self.IMPACT_STEP * self.case.numerics.dt
        co = _Coefficients(1.0 / delta ** 2, -level.X / delta, 1.0 / delta,
                           np.zeros_like(level.X))
        Y = self.solve(level, co, self.problem(level.t + delta), level.Y.copy())[0]
        return co.cX * self.increments(Y, level) + co.dX

    # ------------------------------------------------------------------ the start
    def rest_state(self, t: float = 0.0, Y=None) -> CentrelineState:
        """The rod at rest at t (s) in Y (N+1, 13) (default: the initial pose, n = 0,
        m = R K κ of the pose's frames), accelerations zero."""
        if Y is None:
            Y = np.zeros((self.n, NV))
            Y[:, 0:3] = self.r0
            Y[:, 3:7] = self.q0
        z = np.zeros((self.n, 6))
        return CentrelineState(float(t), np.array(Y, float), z, z.copy(), z.copy())

    def _taylor_step(self, first: CentrelineState, delta: float):
        """The step of δ from ``first`` along its Taylor polynomial, Δ = δ X_0 + δ²/2 Ẋ
        (Ẋ = 2(Δ − δX_0)/δ², X = X_0 + δ Ẋ): (Y at δ, Ẋ)."""
        X0 = first.X
        co = _Coefficients(2.0 / delta**2, -2.0 * X0 / delta, 2.0 / delta, -X0)
        prob = self.problem(first.t + delta)
        Y0 = self.predict(first, delta)
        Y, _, _ = self.solve(first, co, prob, Y0)
        return Y, co.cXd * self.increments(Y, first) + co.dXd

    #: a start from rest whose Δt exceeds this many of the viscous drag's inertial
    #: times starts on the overdamped (slow) manifold (:meth:`start`): a step longer
    #: than the inertial layer does not resolve it (tests/solver/test_viscous.py)
    SLOW_START_STEPS = 1.0

    def inertial_time(self) -> float:
        """The viscous drag's longest inertial time (s) over the nodes, the largest of
        (ρA + C_a ρ_f A)/ζ_n, ρA/ζ_t and ρJ3/ζ_r; 0 without ``fluid.viscosity``."""
        if self.stokes is None:
            return 0.0
        zn, zt, zr = self.stokes
        return float(max(np.max((self.mass + self.added) / zn), np.max(self.mass / zt),
                         np.max(self.inertia[:, 2] / zr)))

    def start(self, Y=None, t: float = 0.0, X=None, delta: float | None = None,
              slow: bool | None = None) -> CentrelineState:
        """A consistent start in Y (N+1, 13) (default the initial pose) at t (s) with the
        velocities X (N+1, 6) (default rest): the accelerations Ẋ(t) and the internal
        loads (n, m)(t) from three Taylor steps of δ, δ/2 and δ/4 (default δ = Δt/4),
        extrapolated (Richardson, to O(δ³)) to δ → 0; a = Ẋ.

        ``slow`` (default: from rest, with ``fluid.viscosity``, at a Δt beyond
        SLOW_START_STEPS inertial times, :meth:`inertial_time`): start on the overdamped
        manifold instead, where the drag balances the loads at t+ (the velocities X(0+)
        and n, m of the same Taylor steps with the inertia left out, extrapolated alike;
        Ẋ = a = 0). From rest, the consistent start's Ẋ(0) = f/m belongs to the inertial
        layer of duration τ, which such a step does not resolve and which the algebraic
        acceleration would carry into the positions (docs/numerics.md § 9); the slow
        start skips that layer, as an overdamped model does (the positions then differ
        from the inertial ones by the layer's travel, v∞ τ). Raises :class:`StepFailure`
        when a Taylor step does not converge."""
        first = self.rest_state(t, Y)
        if X is not None:
            first.X = np.array(X, float)
        if slow is None:
            slow = (X is None and self.stokes is not None and self.case.numerics.dt
                    > self.SLOW_START_STEPS * self.inertial_time())
        delta = 0.25 * self.case.numerics.dt if delta is None else float(delta)
        saved = self.mass, self.added, self.inertia
        if slow:
            self.mass, self.added, self.inertia = (np.zeros_like(a) for a in saved)
        try:
            steps = [self._taylor_step(first, f * delta) for f in (1.0, 0.5, 0.25)]
        finally:
            self.mass, self.added, self.inertia = saved
        (Y1, A1), (Y2, A2), (Y4, A4) = steps
        # Richardson on three halvings: the terms in δ and δ² cancel
        first.Y[:, 7:13] = (8.0 * Y4[:, 7:13] - 6.0 * Y2[:, 7:13] + Y1[:, 7:13]) / 3.0
        if slow:
            # the velocity at δ, X0 + δẊ, of the inertia-free steps, extrapolated alike
            X1, X2, X4 = (first.X + f * delta * A for f, A in ((1.0, A1), (0.5, A2),
                                                                 (0.25, A4)))
            first.X = (8.0 * X4 - 6.0 * X2 + X1) / 3.0
            first.Xd = np.zeros_like(first.X)
            first.a = np.zeros_like(first.X)
            return first
        Xd = (8.0 * A4 - 6.0 * A2 + A1) / 3.0
        first.Xd = Xd
        first.a = Xd.copy()
        return first

    # ------------------------------------------------------------------ outputs
    def body_fields(self, state: CentrelineState) -> dict:
        """The seed's body-frame fields of a state: v, ω, f (Rᵀ n), κ (K⁻¹ Rᵀ m + κ⁰),
        each (N+1, 3), with the positions r (N+1, 3) and quaternions q (N+1, 4)."""
        Y = state.Y
        R = st._rot(Y[:, 3:7])
        body = lambda x: np.einsum("kji,kj->ki", R, x)     # noqa: E731
        return {"v": body(state.X[:, 0:3]), "omega": state.X[:, 3:6].copy(),
                "f": body(Y[:, 7:10]),
                "kappa": body(Y[:, 10:13]) / self.props.stiffness + self.problem(state.t).kappa0,
                "r": Y[:, 0:3].copy(), "q": Y[:, 3:7].copy()}

    def energies(self, state: CentrelineState) -> dict:
        """Kinetic ½∫(ṙ·M ṙ + W·I W) ds, elastic ½∫(κ − κ⁰)·K(κ − κ⁰) ds and the dead loads'
        potential −∫f·r ds − Σ F·r over the ends' loaded components (J, trapezoid in s;
        :func:`solver.statics.fields`)."""
        w = self.props.quad_weights
        fl = self.body_fields(state)
        v = fl["v"]
        m = self.mass[:, None] + np.stack([self.added, self.added, 0 * self.added], 1)
        kin = 0.5 * float(np.sum(w * (np.sum(m * v * v, 1)
                                      + np.sum(self.inertia * fl["omega"] ** 2, 1))))
        static = st.fields(state.Y, self.problem(state.t))
        return {"kinetic": kin, "elastic": static["elastic_energy"],
                "potential": static["load_potential"]}


class _SparseLU:
    """The step's Jacobian where entries lie outside the band: the band ``ab`` (LAPACK
    storage) plus ``extra`` (13(N+1))² sparse — the pairs' load derivative (self-contact,
    electrostatics) on the force rows of the cells either side of each node (h/2 each)
    and the position columns, which couples nodes far apart along the rod, and a closed
    rod's join rows on nodes 0 and N (:func:`solver.statics.join_coupling`); factored by
    SuperLU (scipy's ``splu``, COLAMD ordering). ``solve`` takes the band LU's
    arguments."""

    def __init__(self, ab, extra):
        import scipy.sparse.linalg as spla

        from .static_band import band_to_sparse

        self.A = (band_to_sparse(ab[KL:]) + extra).tocsc()
        self._lu = spla.splu(self.A)

    def rounding_floor(self, Y, weights) -> float:
        """:func:`rounding_floor` of this matrix (the contact's stiff pairs included)."""
        acc = abs(self.A) @ np.abs(np.ravel(Y))
        return float(np.finfo(float).eps * np.max(weights * acc))

    def solve(self, b, refine: bool = False):
        return self._lu.solve(np.asarray(b, float))


def _tension_relaxed(q, slack: float) -> float:
    """The largest scaled update of q (N+1, 13) with n's (columns 7-9) divided by
    ``slack`` (:attr:`CentrelineRod.N_TOLERANCE` over the tolerance in force)."""
    return max(float(q[:, 0:7].max()), float(q[:, 10:13].max()),
               float(q[:, 7:10].max()) / slack)


def rounding_floor(ab, Y, weights) -> float:
    """The rounding level of the residual near Y (N+1, 13): ε max_i w_i Σ_j |J_ij| |Y_j|
    (the bound on a backward-stable evaluation of J Y; Higham, *Accuracy and Stability of
    Numerical Algorithms*, 2002, § 3.5), J in LAPACK band storage ``ab`` (2KL + KU + 1,
    13(N+1)) and w (13(N+1),) the rows' weights. A step of Δt cut small has a matrix
    growing as 1/(β Δt²) acting on positions of order the rod's length, so Newton's
    residual stalls there above any fixed floor. Compiled:
    :func:`solver.centreline_loads.rounding_level`."""
    return float(rounding_level(ab, KL, KU, np.ravel(Y).astype(float),
                                np.ascontiguousarray(weights, dtype=float)))


def box_centreline(q, r_start, h: float) -> np.ndarray:
    """The centreline (N+1, 3) m of the box rule's position rows from frames q (N+1, 4):
    r_i+1 = r_i + h/2 (a3_i + a3_i+1), from r_start (3,) m (the kinematic rows of
    :mod:`solver.statics` hold exactly for it)."""
    a3 = st._rot(q)[:, :, 2]
    r = np.empty_like(a3)
    r[0] = r_start
    r[1:] = r_start + np.cumsum(0.5 * h * (a3[:-1] + a3[1:]), axis=0)
    return r


def next_branches(modes, laws) -> np.ndarray:
    """The damper's branches (N+1,) after a round of :meth:`CentrelineRod._held_solve`,
    from the held ones ``modes`` and the law's own at the round's solution ``laws``
    (each −1: none, or not touching; 0: N = 0, 1: free, 2: N = 2kp): the law's, except
    that a node held at one bound whose law gives the other goes to the free branch
    between them (the seed scheme's rule, :func:`solver.seabed._next_mode`: N is
    monotone in the penetration rate, so the root lies between the two bounds')."""
    swap = (modes >= 0.0) & (modes != 1.0) & (laws >= 0.0) & (laws != 1.0) & (modes != laws)
    return np.where(swap, 1.0, laws)


def meet_held_ends(q, r, s, start: st.EndSpec, end: st.EndSpec):
    """The box rule's initial centreline moved onto the case's held end positions at t = 0.

    The frames q (N+1, 4) of the case's curve build the centreline r (N+1, 3) m by the
    box rule's position rows from its first point (:func:`box_centreline`), whose last
    point misses the curve's by the rule's O(Δs²) error; an end held at a given
    ``position`` (a catenary pinned above the bottom) would then start off its hold, and
    the start's Taylor steps would have to move it there in a fraction of a step (n ∝
    1/δ²; the start's Newton does not converge on the catenary touchdown). Here the
    start's held components shift the whole pose, and the end's held components are met
    by turning the frames: each node's frame turned by φ_k = c_k a3_k × λ (global), the
    λ (3,) of least norm whose turned tangents move the end onto its hold to first order
    (δr_N = Σ_k w_k c_k (I − a3_k a3_kᵀ) λ, w the trapezoid's weights), repeated until
    the end is held to 1e-13 L; c(s) = 1, times s/L where the start's rotation is held
    and (L − s)/L where the end's is, so held frames stay as they are. The turn is
    smooth along s and of the size of the miss over L. ``start``, ``end``: the t = 0 end
    conditions (:class:`solver.statics.EndSpec`); s (N+1,) m the nodes' arclengths.
    Returns (q, r); both unchanged (the same arrays) where every held component already
    holds to 1e-13 L. Raises :class:`CentrelineError` naming
    ``boundary.end.translation`` where turning the frames cannot reach the hold (a
    straight initial centreline cannot lengthen)."""
    from .kinematics import quat_exp

    length = float(s[-1] - s[0])
    tol = 1e-13 * length
    h = float(s[1] - s[0])
    P = start.axes[:, start.held]
    miss = P @ (P.T @ (start.position - r[0]))
    if np.max(np.abs(miss), initial=0.0) > tol:
        r = r + miss
    E = end.axes[:, end.held]
    if E.shape[1] == 0:
        return q, r
    c = np.ones_like(s)
    if start.rotation_held:
        c = c * (s - s[0]) / length
    if end.rotation_held:
        c = c * (s[-1] - s) / length
    w = np.full(s.shape, h)
    w[[0, -1]] = 0.5 * h
    gap = E.T @ (end.position - r[-1])
    first = float(np.max(np.abs(gap)))
    for _ in range(20):
        if np.max(np.abs(gap)) <= tol:
            return q, r
        a3 = st._rot(q)[:, :, 2]
        A = np.einsum("k,kij->ij", w * c, np.eye(3) - a3[:, :, None] * a3[:, None, :])
        lam = np.linalg.lstsq(E.T @ A, gap, rcond=1e-12)[0]
        q = st._qmul(quat_exp(c[:, None] * np.cross(a3, lam)), q)
        q = q / np.linalg.norm(q, axis=1)[:, None]
        r = box_centreline(q, r[0], h)
        gap = E.T @ (end.position - r[-1])
    raise CentrelineError(
        f"boundary.end.translation: the held position lies {first:.3g} m from where the "
        f"initial centreline's frames put the end, and turning the frames does not reach "
        f"it (an initial centreline too short or straight to reach the hold)")


class EndPath:
    """The prescribed motion of an end held by body-frame angular velocities (every
    rotation item ``angular_velocity``, one phase) and, per translation item, a velocity
    or a force: the frame q(t) from q̇ = ½ q ⊗ (0, ω(t)) and the held point from
    ṙ = Σ_i v_i(t) a_i(t) over the velocity items, integrated once by DOP853 (Hairer,
    Nørsett & Wanner, *Solving ODEs I*, 1993, § II.5; scipy's ``solve_ivp``, rtol 1e-13)
    between the tables' knots, where the rates have corners. Built for
    :class:`CentrelineRod`, whose end rows then hold the end on this path: a rotation about
    a normal is path-dependent, which the statics' end rows (twist about a3 only) do not
    carry."""

    def __init__(self, ec, q0, r0, t_end: float, start: bool = False):
        from scipy.integrate import solve_ivp

        from .case import Table

        self.ec = ec
        #: the sign of the load its force items apply (:func:`solver.statics.applied_sign`)
        self.sign = st.applied_sign("start" if start else "end")
        rates = [ec.rotation[i][0] for i in range(3)]
        moves = [ec.translation[i][0] for i in range(3)]
        self.held = np.array([m.kind == "velocity" for m in moves])
        self.force_items = [(i, m) for i, m in enumerate(moves) if m.kind == "force"]
        knots = {0.0, float(t_end)}
        for c in rates + moves:
            if isinstance(c.value, Table):
                knots.update(float(x) for x in c.value.t if 0.0 < x < t_end)
        self.knots = np.array(sorted(knots))

        def rates_at(t):
            """(ω (3,) rad/s, v (3,) m/s) of the items at t: body frame, v 0 where free."""
            return (np.array([c.value_at(t) for c in rates], float),
                    np.array([moves[i].value_at(t) if self.held[i] else 0.0
                              for i in range(3)]))

        y = np.concatenate([q0, r0])
        self.pieces = []
        for a, b in zip(self.knots[:-1], self.knots[1:]):
            # between two knots every table is linear in t: the rates are their values
            # at the knots interpolated, without the tables' lookup in each evaluation
            (w_a, v_a), (w_b, v_b) = rates_at(a), rates_at(b)
            sol = solve_ivp(_path_rhs, (a, b), y, method="DOP853", rtol=1e-13, atol=1e-15,
                            dense_output=True,
                            args=(a, w_a, (w_b - w_a) / (b - a), v_a, (v_b - v_a) / (b - a)))
            if not sol.success:
                raise CentrelineError(f"boundary: the end's prescribed motion did not "
                                      f"integrate ({sol.message})")
            self.pieces.append(sol.sol)
            y = sol.y[:, -1]

    @staticmethod
    def applies(ec) -> bool:
        """Whether an end condition needs a path: body frame, one phase per item, every
        rotation item an angular velocity and some turn about a normal (items 0, 1)."""
        if ec.frame != "body":
            return False
        if any(len(items) != 1 for items in list(ec.rotation) + list(ec.translation)):
            return False
        if not all(ec.rotation[i][0].kind == "angular_velocity" for i in range(3)):
            return False
        from .case import Table
        return any(isinstance(ec.rotation[i][0].value, Table) or ec.rotation[i][0].value != 0
                   for i in (0, 1))

    def at(self, t: float):
        """(q (4,), r (3,) m) of the end at time t (s)."""
        j = int(np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0,
                        len(self.pieces) - 1))
        y = self.pieces[j](t)
        q = y[0:4] / np.linalg.norm(y[0:4])
        return q, y[4:7]

    def spec(self, t: float, extra_force) -> st.EndSpec:
        """The statics' :class:`solver.statics.EndSpec` of the end at t: the frame held at
        q(t); velocity items held at the path's point along a_i(t); force items the
        internal force F_i a_i(t) (N; the load applied at s = 0 is its negative), plus
        ``extra_force`` (3,) N (point loads there, applied)."""
        q, r = self.at(t)
        axes = st._rot(q)
        force = np.asarray(extra_force, float).copy()
        for i, m in self.force_items:
            force = force + self.sign * m.value_at(t) * axes[:, i]
        return st.EndSpec(axes=axes, held=self.held.copy(), position=r, force=force,
                          rotation_held=True, quaternion=q, twist=0.0)


def _path_rhs(t, y, a, w_a, dw, v_a, dv):
    """The end path's rates (:class:`EndPath`) on a knot interval from a (s), where the
    body angular velocity ω = w_a + (t − a) dw (rad/s) and the held velocity
    v = v_a + (t − a) dv (m/s, body) are linear: (q̇ = ½ q ⊗ (0, ω), ṙ = R(q) v) for
    y = (q (4,), r (3,)), R(q) the quadratic form of :func:`solver.statics._rot` (q stays
    unit to the integration's tolerance)."""
    w0, x, yq, z = y[0], y[1], y[2], y[3]
    wx, wy, wz = w_a + (t - a) * dw
    vx, vy, vz = v_a + (t - a) * dv
    dq = 0.5 * np.array([-x * wx - yq * wy - z * wz,
                         w0 * wx + yq * wz - z * wy,
                         w0 * wy + z * wx - x * wz,
                         w0 * wz + x * wy - yq * wx])
    ww, xx, yy, zz = w0 * w0, x * x, yq * yq, z * z
    R = np.array([[ww + xx - yy - zz, 2 * (x * yq - w0 * z), 2 * (x * z + w0 * yq)],
                  [2 * (x * yq + w0 * z), ww - xx + yy - zz, 2 * (yq * z - w0 * x)],
                  [2 * (x * z - w0 * yq), 2 * (yq * z + w0 * x), ww - xx - yy + zz]])
    return np.concatenate([dq, R @ np.array([vx, vy, vz])])
