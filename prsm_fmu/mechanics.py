"""Forces, torques and accelerations of a multi-stage PRSM at one instant (the hot path).

Given the screw speed ω [rad/s], the carrier speeds ω_Pk [rad/s], the load on the last nut and
either the motor torque (torque drive) or the screw acceleration (speed drive), this module
solves the per-body balances of docs/model.md §3:

* nut assembly k (nut, rollers, carriers), axial:   A_k = B_k + m_Ak c_k α
* screw k (k ≥ 2), axial:                           B_(k−1) = A_k + h_k − h_(k+1) + m_Sk c_(k−1) α
* screw k, torque:                                  M_Sk = J_Sk α + M_S(k+1) − κ_k A_k − T_b,k
* carrier k (Lagrange, generalized force):          J_Pk α_Pk = γ_k A_k

with A_k the axial force the rollers of stage k take from their screw, B_k the force that
screw k+1 puts on nut k through the thrust bearing (B_n = the external load), h_k the spline
friction on screw k, T_b,k the bearing friction torque on screw k, α = dω/dt and c_k = Σ_{i≤k}
L_Si / 2π.  Every quantity is affine in α once the signs of A_k (which flank carries the load),
M_Sk and B_k are fixed, so the chain is solved exactly from the last stage down to stage 1
with (value, d value/dα) pairs; the signs are found by a short deterministic fixed-point
iteration starting from α = 0, so the result is a pure function of its arguments.

The contact coefficients per unit of transmitted axial force (κ: torque on the screw, γ:
generalized force on the carrier, π: friction power) follow from the contact geometry
(:mod:`prsm_fmu.geometry`) and the friction laws (:mod:`prsm_fmu.friction`): the regularised
Coulomb force µF_N along the slip, the lubricant's viscous force µ_1 n_t s per roller and the
differential-sliding torque µ_3 F_N on the screw (the friction-torque article;
docs/model.md §3).  The viscous force does not scale with the normal force: its axial part
V_z = N_R µ_1 n_t ω ℓ adds to the axial force the threads carry, so every per-unit quantity is
taken per unit of the *effective* axial force Ã = A + V_z (N_R F_N = Ã q), and the viscous
torque, carrier force and power are added on their own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .friction import regularised_factor, regularised_sign, viscous_coefficient
from .geometry import contact_geometry
from .kinematics import ideal_carrier_speed_ratio
from .param_ranges import fmt
from .params import MechanismParams

TWO_PI = 2.0 * math.pi

#: number of sign-pattern iterations before the last pattern is accepted
MAX_SIGN_ITERATIONS = 8


class _Flank:
    """Per-flank constants of one stage's screw–roller contact (plain floats for speed)."""

    __slots__ = ("px", "py", "nx", "ny", "nz", "ax", "ay", "az", "bx", "by", "consts", "radius")

    def __init__(self, geo) -> None:
        (self.px, self.py, _), (self.nx, self.ny, self.nz) = geo.point, geo.normal
        (ax, ay, az), (bx, by, bz) = geo.slip_jacobians()
        if abs(bz) > 1e-15:
            raise ValueError("carrier slip Jacobian has an axial part; geometry inconsistent")
        self.ax, self.ay, self.az, self.bx, self.by = ax, ay, az, bx, by
        #: the slip Jacobians, the contact point, the axial normal and [P × n]_z (the normal
        #: force's torque per unit); :class:`Mechanism` appends the stage's friction constants
        #: to make what :meth:`Mechanism._coefficients` reads
        self.consts = (ax, ay, az, bx, by, self.px, self.py, self.nz,
                       self.px * self.ny - self.py * self.nx)
        #: contact radius |P_xy| [m]: the screw's surface speed there, ω r, is the sliding speed
        #: that regularises the differential-sliding torque's sign (a square root, not
        #: math.hypot, whose rounding libm's hypot does not share: the engine's
        #: prsm_stage_contact computes it so)
        self.radius = math.sqrt(self.px * self.px + self.py * self.py)

    def steady_ratio(self) -> float:
        """Carrier/screw speed ratio at which the slip has no component along b [-]."""
        return -(self.ax * self.bx + self.ay * self.by) / (self.bx * self.bx + self.by * self.by)


class _Stage:
    """Constants of stage k used by the recursion."""

    __slots__ = ("n_rollers", "ell", "c", "c_prev", "m_assembly", "m_screw", "j_screw",
                 "j_carrier", "flanks", "e_spline", "g_bearing", "spline_speed_factor",
                 "bearing_speed_factor", "zeta_geometric", "zeta_ideal", "min_normal_z",
                 "c_viscous")

    def __init__(self, params: MechanismParams, k: int) -> None:
        st = params.stages[k]
        leads = [s.screw_lead for s in params.stages]
        self.n_rollers = float(st.n_rollers)
        self.ell = st.screw_lead / TWO_PI
        # added left to right (Python 3.12's sum() compensates; the engine's C adds plainly)
        leads_below = 0.0
        for lead in leads[:k]:
            leads_below = leads_below + lead
        self.c = (leads_below + leads[k]) / TWO_PI
        self.c_prev = leads_below / TWO_PI
        self.m_assembly = st.nut_mass + st.n_rollers * st.roller_mass + st.carriers * st.carrier_mass
        self.m_screw = st.screw_mass if k > 0 else 0.0
        self.j_screw = st.screw_inertia
        self.j_carrier = (st.carriers * st.carrier_inertia
                          + st.n_rollers * st.roller_inertia * (st.screw_starts - 1) ** 2
                          + st.n_rollers * st.roller_mass * (st.screw_radius + st.roller_radius) ** 2)
        geo = contact_geometry(st)
        self.flanks = (_Flank(geo), _Flank(geo.mirrored()))
        self.min_normal_z = min(abs(self.flanks[0].nz), abs(self.flanks[1].nz))
        self.e_spline = params.mu_spline / st.spline_radius if (k > 0 and params.mu_spline > 0) else 0.0
        below = params.stages[k - 1] if k > 0 else None
        self.g_bearing = (params.mu_nut_screw * below.bearing_radius
                          if (below is not None and params.mu_nut_screw > 0) else 0.0)
        # sliding speeds per unit screw speed [m/rad]: spline slides at ω·ℓ_(k−1); the bearing
        # face slides at ω·r_NS
        self.spline_speed_factor = leads[k - 1] / TWO_PI if k > 0 else 0.0
        self.bearing_speed_factor = below.bearing_radius if below is not None else 0.0
        self.zeta_geometric = self.flanks[0].steady_ratio()
        self.zeta_ideal = ideal_carrier_speed_ratio(st)
        #: viscous coefficient of all the stage's rollers together, N_R µ_1 n_t [N·s/m]
        self.c_viscous = viscous_coefficient(params.mu_viscous, st.n_rollers,
                                             st.threads_per_roller)


def _sign_slope(v: float, v_scale: float) -> float:
    """d/dv of :func:`~prsm_fmu.friction.regularised_sign`: (2 − 2|v|/v_ε)/v_ε inside the band,
    0 outside [1/(m/s)]."""
    av = abs(v)
    return 0.0 if av >= v_scale else (2.0 - 2.0 * av / v_scale) / v_scale


@dataclass
class Solution:
    """Everything the balances determine at one instant (SI units).

    Attributes
    ----------
    screw_acceleration : float
        α = dω/dt [rad/s²].
    carrier_accelerations : list of float
        dω_Pk/dt [rad/s²] (zero for fidelity levels that slave the carriers).
    motor_torque : float
        M_S1, torque on screw 1 [N·m].
    friction_power : float
        Total power dissipated by friction [W] (≥ 0).
    friction_power_terms : dict of str to float
        ``friction_power`` split by term [W]: ``coulomb`` (screw–roller spin sliding),
        ``viscous`` (screw–roller lubricant), ``differential`` (differential sliding) and
        ``joints`` (spline and thrust-bearing Coulomb friction); they sum to
        ``friction_power``.
    stage_axial_force : list of float
        A_k, axial force the rollers of stage k take from screw k [N] (all rollers).
    contact_force : list of float
        Axial component of the screw–roller contact force per roller [N], signed: > 0 when the
        flank that resists extension carries the load (Li et al.'s (2021) F_Srzk, Eq. 25).
    normal_force : list of float
        Magnitude of the screw–roller normal contact force per roller [N] (Li et al.'s (2021) F_Srk).
    driven_torque : list of float
        M_Sk, torque driving screw k [N·m] (M_S1 is the motor torque).
    spline_friction : list of float
        Axial spline friction force on screw k from screw k−1 [N] (0 for k = 1).
    bearing_force : list of float
        B_k, axial force screw k+1 puts on nut k through the thrust bearing [N] (B_n = load).
    stage_friction_power : list of float
        Power dissipated at stage k's screw–roller contacts, its spline and the bearing under
        its screw [W].
    consistent : bool
        False when the rigid contacts with Coulomb friction admit no acceleration that balances
        the motor torque (a Painlevé-type inconsistency: carriers far from equilibrium with a
        self-locking slip direction); the returned α then minimises the imbalance.
    """

    screw_acceleration: float
    carrier_accelerations: list
    motor_torque: float
    friction_power: float
    stage_axial_force: list | None = None
    contact_force: list | None = None
    normal_force: list | None = None
    driven_torque: list | None = None
    spline_friction: list | None = None
    bearing_force: list | None = None
    stage_friction_power: list | None = None
    friction_power_terms: dict | None = None
    consistent: bool = True


class Mechanism:
    """Precomputed constants of a mechanism and the instantaneous force solution.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (validated here).
    carriers : {"dynamic", "equilibrium", "ideal"}
        How carrier speeds are obtained: from the state (``dynamic``), held at the force
        equilibrium ratio ζ* of the contact geometry (``equilibrium``, quasi-static level), or at
        the pure-rolling ratio r_S/(r_S + r_N) with all friction off (``ideal``, kinematic level).
    """

    def __init__(self, params: MechanismParams, carriers: str = "dynamic") -> None:
        if carriers not in ("dynamic", "equilibrium", "ideal"):
            raise ValueError(f"carriers = {carriers!r}: must be 'dynamic', 'equilibrium' or 'ideal'")
        params.validate()
        self.params = params
        self.mode = carriers
        self.stages = [_Stage(params, k) for k in range(params.n_stages)]
        frictionless = carriers == "ideal"
        self.mu = 0.0 if frictionless else params.mu_screw_roller
        #: differential-sliding coefficient µ_3 [m] (0 in the frictionless ideal mode)
        self.mu3 = 0.0 if frictionless else params.mu_differential
        if frictionless:
            for s in self.stages:
                s.e_spline = 0.0
                s.g_bearing = 0.0
                s.c_viscous = 0.0
        #: whether any contact has a viscous term (the slaved levels' closed-form step is then
        #: not exact, models/slaved.py)
        self.viscous = any(s.c_viscous > 0.0 for s in self.stages)
        limit = min(s.min_normal_z for s in self.stages)
        if self.mu >= limit:
            raise ValueError(
                f"mu_screw_roller = {fmt(self.mu)} is out of range for this geometry: must be < "
                f"{limit:.4f} (the axial part of the contact normal); above it the thread self-locks "
                "and the rigid model has no solution")
        self.v_eps = params.slip_velocity_scale
        self.c_out = self.stages[-1].c
        if carriers == "dynamic":
            self.zeta = None
        else:
            self.zeta = [s.zeta_ideal if frictionless else s.zeta_geometric for s in self.stages]
            for s, z in zip(self.stages, self.zeta):
                # carriers slaved to the screw: their inertia is driven through the screw
                s.j_screw = s.j_screw + s.j_carrier * z * z
        # the hot path's constants, now final, as tuples: per stage in sweep order (last
        # first) what _sweep reads -- the screw inertia, screw k's mass term m_Sk c_(k−1),
        # spline and bearing friction with their sliding speeds per unit ω, the mass term
        # m_A c of the stage below, the viscous axial force per unit ω (N_R µ_1 n_t ℓ) and
        # both flanks' _Flank.consts with the stage's friction constants (N_R µ_1 n_t, µ_3 and
        # the contact radius) appended -- and what _rates reads
        plan = []
        for k, s in enumerate(self.stages):
            below = self.stages[k - 1].m_assembly * self.stages[k - 1].c if k > 0 else 0.0
            flank_consts = tuple(fl.consts + (s.c_viscous, self.mu3, fl.radius)
                                 for fl in s.flanks)
            plan.append((k, (s.j_screw, s.m_screw * s.c_prev, s.e_spline, s.spline_speed_factor,
                             s.g_bearing, s.bearing_speed_factor, below,
                             s.c_viscous * s.flanks[0].az, flank_consts)))
        self._plan = tuple(reversed(plan))
        self._last_mass = self.stages[-1].m_assembly * self.stages[-1].c
        self._n_cache = 2 * len(self.stages)
        self._rate_consts = tuple((s.j_carrier, s.spline_speed_factor) for s in self.stages)
        #: :meth:`equivalent_inertia`, final now (the outputs read it at every step)
        self._j_eq = self.equivalent_inertia()

    # ------------------------------------------------------------------------------------
    def equivalent_inertia(self) -> float:
        """Inertia reflected to the screw of everything slaved to it [kg·m²] (Eq. 11's θ̇_S² term,
        plus the carriers' J_Pk ζ_k² when they are slaved)."""
        j = 0.0
        for s in self.stages:
            j += s.j_screw + s.m_assembly * s.c * s.c + s.m_screw * s.c_prev * s.c_prev
        return j

    def kinetic_energy(self, omega: float, carrier_speeds) -> float:
        """Kinetic energy of the whole mechanism [J] (Li et al. (2021) Eq. 11)."""
        t = 0.5 * self._j_eq * omega * omega
        if self.zeta is None:
            for s, wp in zip(self.stages, carrier_speeds):
                t += 0.5 * s.j_carrier * wp * wp
        return t

    def carrier_speeds(self, omega: float, carrier_state) -> list:
        """Carrier speeds [rad/s]: the state's for the dynamic level, ζ_k ω otherwise."""
        if self.zeta is None:
            return list(carrier_state)
        return [z * omega for z in self.zeta]

    # ------------------------------------------------------------------------------------
    def _coefficients(self, flank: tuple, omega: float, wp: float) -> tuple:
        """The contact of a stage with the constants ``flank`` (:attr:`_Flank.consts` plus
        N_R µ_1 n_t, µ_3 and the contact radius r), at screw speed ω and carrier speed ω_P.

        Returns the tuple (κ, γ, π, q, τ_v, γ_v, p_v, π_c, π_d): per unit effective axial
        force Ã = A + V_z (module docstring) the torque on the screw κ, the generalized force
        on the carrier γ, the friction power π = π_c + π_d (Coulomb, differential sliding) and
        q = 1/(n_z − µ u_z) (the normal force of all rollers is Ã q); then the viscous force's
        own torque on the screw τ_v = −N_R µ_1 n_t [P × s]_z, generalized force on the carrier
        γ_v = −N_R µ_1 n_t (s·b) and power p_v = N_R µ_1 n_t |s|².

        With u = s φ(|s|) the regularised slip direction and σ = sgñ(ω r):
        κ = ([P × (n − µ u)]_z − µ_3 σ) q, γ = −µ (u·b) q, π_c = µ (u·s) q, π_d = µ_3 σ ω q.
        """
        ax, ay, az, bx, by, px, py, nz, pn, cv, mu3, radius = flank
        sx = omega * ax + wp * bx
        sy = omega * ay + wp * by
        sz = omega * az
        v2 = sx * sx + sy * sy + sz * sz
        v = math.sqrt(v2)
        # φ(v) = 1/v outside the band (friction.py), written out on the hot path
        mphi = self.mu * (1.0 / v if v >= self.v_eps else regularised_factor(v, self.v_eps))
        q = 1.0 / (nz - mphi * sz)
        kappa = pn - mphi * (px * sy - py * sx)
        p_c = mphi * v2 * q
        p_d = 0.0
        if mu3:
            w = omega * radius   # sgñ(w) = ±1 outside the band (friction.py)
            sg = 1.0 if w >= self.v_eps else -1.0 if w <= -self.v_eps else regularised_sign(
                w, self.v_eps)
            kappa -= mu3 * sg
            p_d = mu3 * sg * omega * q
        sb = sx * bx + sy * by
        return (kappa * q, -mphi * sb * q, p_c + p_d, q, -cv * (px * sy - py * sx), -cv * sb,
                cv * v2, p_c, p_d)

    def solve(self, omega: float, carrier_state, load: float, *, torque: float | None = None,
              acceleration: float | None = None, detail: bool = False) -> Solution:
        """Solve the balances at one instant.

        Parameters
        ----------
        omega : float
            Screw speed ω [rad/s].
        carrier_state : sequence of float
            Carrier speeds ω_Pk [rad/s] (ignored unless the carriers are dynamic).
        load : float
            External axial force on the last nut [N], positive resisting extension.
        torque : float, optional
            Motor torque on screw 1 [N·m] (torque drive).  Exactly one of ``torque`` and
            ``acceleration`` is given.
        acceleration : float, optional
            Prescribed screw acceleration [rad/s²] (speed drive).
        detail : bool
            Also fill the per-stage force lists of :class:`Solution`.

        Returns
        -------
        Solution
        """
        wps = carrier_state if self.zeta is None else self.carrier_speeds(omega, carrier_state)
        alpha, rec, consistent = self._balance(omega, wps, load, torque, acceleration)
        sol = self._assemble(omega, wps, load, alpha, rec, detail)
        sol.consistent = consistent
        return sol

    def rates(self, omega: float, carrier_state, load: float, torque: float | None = None,
              acceleration: float | None = None) -> tuple:
        """The hot path of :meth:`solve` (``detail=False``) without the :class:`Solution`.

        Parameters are those of :meth:`solve`.

        Returns
        -------
        tuple
            (α [rad/s²], motor torque M_S1 [N·m], carrier accelerations [rad/s²] (list),
            friction power [W]).  All NaN where the rigid contact has no solution
            (:attr:`Solution.consistent` False): no stepper can integrate through such a
            state, and :meth:`diagnose` says why.
        """
        wps = carrier_state if self.zeta is None else self.carrier_speeds(omega, carrier_state)
        alpha, ((m0, m1), per_stage), consistent = self._balance(omega, wps, load, torque,
                                                                 acceleration)
        if not consistent:
            nan = math.nan
            return nan, nan, [nan] * len(per_stage), nan
        acc, p_fric = self._rates(omega, alpha, per_stage)
        return alpha, m0 + m1 * alpha, acc, p_fric

    def rates_jacobian(self, omega: float, carrier_state, load: float,
                       torque: float | None = None, acceleration: float | None = None) -> tuple:
        """Derivatives of :meth:`rates` with respect to the screw speed and the carrier speeds.

        Differentiates the recursion itself (docs/model.md §3): with the sign pattern of the
        solution held, every quantity of the sweep is affine in α with coefficients that are
        smooth functions of (ω, ω_Pk); the contact coefficients κ, γ, π, q and the viscous
        terms depend on them through the slip s = ω a + ω_P b and the regularised factor
        φ(|s|) (friction.py), the spline and bearing signs through ω alone, and these
        derivatives are carried down the sweep beside the values.  Dynamic carriers only.

        Parameters are those of :meth:`rates`.

        Returns
        -------
        tuple
            (the values of :meth:`rates`, dα, dM_S1, [d carrier acceleration_k], dP_f), each
            derivative a list over (ω, ω_P1, …, ω_Pn) [SI units per rad/s].  All NaN where
            :meth:`rates` is NaN.
        """
        if self.zeta is not None:
            raise ValueError("rates_jacobian needs dynamic carriers (carriers = 'dynamic')")
        wps = carrier_state
        alpha, rec, consistent = self._balance(omega, wps, load, torque, acceleration)
        (m0, m1), per_stage = rec
        n = len(per_stage)
        m = n + 1
        if not consistent:
            nan = math.nan
            row = [nan] * m
            return ((nan, nan, [nan] * n, nan), row, list(row), [list(row) for _ in range(n)],
                    list(row))
        acc, p_fric = self._rates(omega, alpha, per_stage)
        v_eps = self.v_eps
        zero = [0.0] * m
        # d(quantity)/d(ω, ω_P1 … ω_Pn) of the sweep's pairs, carried from the last stage down
        da0, da1 = zero, zero
        dmn0 = dmn1 = dhn0 = dhn1 = zero
        drec = [None] * n
        for k, (j_screw, m_sc, e_spline, spline_f, g_bearing, bearing_f, mass_below,
                vz_factor, flanks) in self._plan:
            fi, ae0, a1, co, mk0, mk1, h0, h1, b0, b1, e, g, sm, sb = per_stage[k]
            dco = self._coefficient_derivatives(flanks[fi], omega, wps[k], k + 1, m)
            dkappa, dtv = dco[0], dco[4]
            kappa = co[0]
            dae0 = list(da0)
            dae0[0] += vz_factor
            dx0 = [p - dk * ae0 - kappa * q - dt for p, dk, q, dt in zip(dmn0, dkappa, dae0, dtv)]
            dx1 = [p - dk * a1 - kappa * q for p, dk, q in zip(dmn1, dkappa, da1)]
            if k == 0:
                drec[0] = (dae0, da1, dco, zero, zero, zero, zero)
                dm0, dm1 = dx0, dx1
                break
            dy0 = [p - q for p, q in zip(da0, dhn0)]
            dy1 = [p - q for p, q in zip(da1, dhn1)]
            # the spline's and the bearing's regularised signs depend on ω inside their bands
            de = _sign_slope(omega * spline_f, v_eps) * e_spline * spline_f if e_spline else 0.0
            dg = _sign_slope(omega * bearing_f, v_eps) * g_bearing * bearing_f if g_bearing else 0.0
            if g:
                den = 1.0 - g * sb * e * sm
                # m = (x + g σ_B y)/den, den = 1 − g σ_B e σ_M: recover x, y from the record
                y0 = b0 - e * sm * mk0
                y1 = b1 - e * sm * mk1
                dden = [0.0] * m
                dden[0] = -sb * sm * (dg * e + g * de)
                dm0 = [(p + g * sb * q - mk0 * r) / den for p, q, r in zip(dx0, dy0, dden)]
                dm1 = [(p + g * sb * q - mk1 * r) / den for p, q, r in zip(dx1, dy1, dden)]
                dm0[0] += dg * sb * y0 / den
                dm1[0] += dg * sb * y1 / den
            else:
                dm0, dm1 = dx0, dx1
            dh0 = [e * sm * p for p in dm0]
            dh1 = [e * sm * p for p in dm1]
            dh0[0] += de * sm * mk0
            dh1[0] += de * sm * mk1
            db0 = [p + q for p, q in zip(dy0, dh0)]
            db1 = [p + q for p, q in zip(dy1, dh1)]
            drec[k] = (dae0, da1, dco, dh0, dh1, db0, db1, dg)
            da0, da1 = db0, db1
            dmn0, dmn1, dhn0, dhn1 = dm0, dm1, dh0, dh1
        if acceleration is None:
            dalpha = [-(p + alpha * q) / m1 for p, q in zip(dm0, dm1)]
        else:
            dalpha = zero
        dmotor = [p + alpha * q + m1 * r for p, q, r in zip(dm0, dm1, dalpha)]
        dacc = []
        dpf = [0.0] * m
        for k in range(n):
            fi, ae0, a1, co, mk0, mk1, h0, h1, b0, b1, e, g, sm, sb = per_stage[k]
            dae0, da1k, dco = drec[k][0], drec[k][1], drec[k][2]
            a = ae0 + a1 * alpha
            da = [p + alpha * q + a1 * r for p, q, r in zip(dae0, da1k, dalpha)]
            j_carrier, spline_f = self._rate_consts[k]
            dgam, dpi, dgv, dpv = dco[1], dco[2], dco[5], dco[6]
            dacc.append([(p * a + co[1] * q + r) / j_carrier
                         for p, q, r in zip(dgam, da, dgv)])
            dpf = [f + p * a + co[2] * q + r for f, p, q, r in zip(dpf, dpi, da, dpv)]
            if k > 0:
                dh0, dh1, db0, db1, dg = drec[k][3:]
                if e:
                    h = h0 + h1 * alpha
                    dpf = [f + (p + alpha * q + h1 * r) * omega * spline_f
                           for f, p, q, r in zip(dpf, dh0, dh1, dalpha)]
                    dpf[0] += h * spline_f
                if g:
                    b = b0 + b1 * alpha
                    dpf = [f + g * sb * (p + alpha * q + b1 * r) * omega
                           for f, p, q, r in zip(dpf, db0, db1, dalpha)]
                    dpf[0] += g * sb * b + dg * sb * b * omega
        return (alpha, m0 + m1 * alpha, acc, p_fric), dalpha, dmotor, dacc, dpf

    def _coefficient_derivatives(self, flank: tuple, omega: float, wp: float, j: int,
                                 m: int) -> tuple:
        """Derivatives of :meth:`_coefficients` with respect to (ω, ω_P1, …): lists of length
        ``m`` for (κ, γ, π, q, τ_v, γ_v, p_v), non-zero at ω (index 0) and at this stage's
        carrier speed (index ``j``)."""
        ax, ay, az, bx, by, px, py, nz, pn, cv, mu3, radius = flank
        sx = omega * ax + wp * bx
        sy = omega * ay + wp * by
        sz = omega * az
        v2 = sx * sx + sy * sy + sz * sz
        v = math.sqrt(v2)
        v_eps = self.v_eps
        mu = self.mu
        if v >= v_eps:
            phi, dphi = 1.0 / v, -1.0 / v2
        else:
            phi, dphi = (2.0 - v / v_eps) / v_eps, -1.0 / (v_eps * v_eps)
        mphi = mu * phi
        sa = sx * ax + sy * ay + sz * az
        sbv = sx * bx + sy * by
        # d(µφ)/dω = µ φ'(v) (s·a)/v, d(µφ)/dω_P = µ φ'(v) (s·b)/v (0 at s = 0: φ s is C¹)
        dm_w = mu * dphi * sa / v if v > 0.0 else 0.0
        dm_p = mu * dphi * sbv / v if v > 0.0 else 0.0
        q = 1.0 / (nz - mphi * sz)
        dq_w = q * q * (dm_w * sz + mphi * az)
        dq_p = q * q * dm_p * sz
        cross = px * sy - py * sx
        dc_w = px * ay - py * ax
        dc_p = px * by - py * bx
        kr = pn - mphi * cross
        dkr_w = -dm_w * cross - mphi * dc_w
        dkr_p = -dm_p * cross - mphi * dc_p
        dpd_w = dpd_p = 0.0
        if mu3:
            # differential sliding: κ ⊃ −µ_3 σ q, π_d = µ_3 σ ω q with σ = sgñ(ω r)
            w = omega * radius
            sg = 1.0 if w >= v_eps else -1.0 if w <= -v_eps else regularised_sign(w, v_eps)
            dsg = _sign_slope(w, v_eps) * radius
            kr -= mu3 * sg
            dkr_w -= mu3 * dsg
            dpd_w = mu3 * (dsg * omega * q + sg * q + sg * omega * dq_w)
            dpd_p = mu3 * sg * omega * dq_p
        # κ = kr q, γ = −µφ (s·b) q, π = µφ v² q + π_d
        ab = ax * bx + ay * by
        bb = bx * bx + by * by

        def col(dw: float, dp: float) -> list:
            c = [0.0] * m
            c[0] = dw
            c[j] = dp
            return c

        return (col(dkr_w * q + kr * dq_w, dkr_p * q + kr * dq_p),
                col(-(dm_w * sbv * q + mphi * ab * q + mphi * sbv * dq_w),
                    -(dm_p * sbv * q + mphi * bb * q + mphi * sbv * dq_p)),
                col(dm_w * v2 * q + mphi * 2.0 * sa * q + mphi * v2 * dq_w + dpd_w,
                    dm_p * v2 * q + mphi * 2.0 * sbv * q + mphi * v2 * dq_p + dpd_p),
                col(dq_w, dq_p),
                col(-cv * dc_w, -cv * dc_p),
                col(-cv * ab, -cv * bb),
                col(cv * 2.0 * sa, cv * 2.0 * sbv))

    def diagnose(self, omega: float, carrier_state, load: float, torque: float) -> str | None:
        """Why the rigid contact has no solution at this torque-driven state, or None if it has.

        Parameters are those of :meth:`solve` (torque drive).

        Returns
        -------
        str or None
            A one-line reason naming the quantity: the screw's effective inertia
            dM_S1/dα [kg·m²], which is ≤ 0 for large accelerations of one sign when a
            carrier's slip direction makes its thread self-locking, and the carriers' speed
            ratios against their equilibrium ratios.
        """
        wps = carrier_state if self.zeta is None else self.carrier_speeds(omega, carrier_state)
        sol = self.solve(omega, wps, load, torque=torque)
        if sol.consistent:
            return None
        cache = [None] * self._n_cache
        slopes = []
        for a in (-1e9, -1e6, 1e6, 1e9):
            rec = self._sweep(omega, wps, load, a, cache)
            slopes.append((rec[0][1], a, rec[0][0] + rec[0][1] * a))
        j_eff, a_at, _ = min(slopes)
        ratios = ", ".join(
            f"carrier {k + 1} at {w / omega if omega else 0.0:.4g} x screw speed "
            f"(equilibrium {s.zeta_geometric:.4g})" for k, (s, w) in enumerate(zip(self.stages, wps)))
        return (f"rigid contact with Coulomb friction has no solution (Painlevé): the screw's "
                f"effective inertia dM_S1/dα = {j_eff:.3g} kg·m² is <= 0 for large "
                f"{'positive' if a_at > 0 else 'negative'} accelerations, so no acceleration balances "
                f"screw_torque = {torque:.6g} N·m at screw speed {omega:.6g} rad/s, load "
                f"{load:.6g} N; {ratios}")

    def _balance(self, omega, wps, load, torque, acceleration):
        """α, the sweep record whose signs hold at α, and the consistency flag: the sign
        iteration of the module docstring, with :meth:`_bracket` when it cycles."""
        # contact coefficients per (stage, flank), computed on first use (see _sweep)
        cache = [None] * self._n_cache
        if acceleration is not None:
            return acceleration, self._sweep(omega, wps, load, acceleration, cache), True
        alpha_guess = 0.0
        visited = []
        for _ in range(MAX_SIGN_ITERATIONS):
            rec = self._sweep(omega, wps, load, alpha_guess, cache)
            m0, m1 = rec[0]
            alpha = (torque - m0) / m1
            if m1 > 0.0 and self._signs_hold(rec, alpha):
                return alpha, rec, True
            visited.append(alpha_guess)
            alpha_guess = alpha
        return self._bracket(omega, wps, load, torque, visited, cache)

    def _bracket(self, omega, wps, load, torque, visited, cache):
        """Root of the continuous, piecewise-affine M_S1(α) − torque when the sign iteration
        cycles (docs/model.md §3, "Rigid-contact inconsistency").

        Returns (α, sweep record, consistent); ``consistent`` is False when no α balances the
        motor torque (no root), in which case the α of smallest imbalance is returned.
        """
        def g(a):
            rec = self._sweep(omega, wps, load, a, cache)
            return rec[0][0] + rec[0][1] * a - torque, rec

        samples = sorted(set(visited + [0.0] + [sgn * 10.0 ** e for e in range(0, 13, 2)
                                                 for sgn in (-1.0, 1.0)]))
        vals = [(a,) + g(a) for a in samples]
        roots = []
        for (a_lo, g_lo, _), (a_hi, g_hi, _) in zip(vals, vals[1:]):
            if g_lo == 0.0:
                roots.append(a_lo)
            elif (g_lo < 0.0) != (g_hi < 0.0):
                lo, hi = a_lo, a_hi
                for _ in range(200):
                    mid = 0.5 * (lo + hi)
                    gm = g(mid)[0]
                    if (gm < 0.0) == (g_lo < 0.0):
                        lo = mid
                    else:
                        hi = mid
                    if hi - lo <= 1e-15 * max(1.0, abs(mid)):
                        break
                roots.append(0.5 * (lo + hi))
        if roots:
            # several roots: the one of least |α| (the rigid model's non-uniqueness; the
            # smallest acceleration is the one reached continuously from rest)
            a = min(roots, key=abs)
            return a, g(a)[1], True
        a = min(vals, key=lambda v: abs(v[1]))[0]
        return a, g(a)[1], False

    def _sweep(self, omega, wps, load, ag, cache):
        """One pass from the last stage down with signs chosen at α = ag; returns the record
        ((M_S1 at α = 0, dM_S1/dα), per-stage tuples (flank, the effective axial force
        Ã = A + V_z, coefficients, M_Sk, h_k, B_(k−1) as (value, d/dα) pairs, spline and bearing
        factors, signs of M_Sk and B_(k−1)))."""
        v_eps = self.v_eps
        coefficients = self._coefficients
        a0, a1 = load, self._last_mass
        mn0 = mn1 = hn0 = hn1 = 0.0
        per_stage = [None] * len(self.stages)
        for k, (j_screw, m_sc, e_spline, spline_f, g_bearing, bearing_f, mass_below,
                vz_factor, flanks) in self._plan:
            # the threads carry the effective axial force Ã = A + V_z (module docstring)
            ae0 = a0 + vz_factor * omega
            fi = 0 if ae0 + a1 * ag >= 0.0 else 1
            co = cache[2 * k + fi]
            if co is None:
                co = cache[2 * k + fi] = coefficients(flanks[fi], omega, wps[k])
            kappa = co[0]
            x0 = mn0 - kappa * ae0 - co[4]
            x1 = j_screw + mn1 - kappa * a1
            if k == 0:
                per_stage[0] = (fi, ae0, a1, co, x0, x1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1, 1)
                return (x0, x1), per_stage
            y0 = a0 - hn0
            y1 = a1 - hn1 + m_sc
            e = 0.0
            if e_spline:
                v = omega * spline_f  # sgñ(v) = ±1 outside the band (friction.py)
                e = (e_spline if v >= v_eps else -e_spline if v <= -v_eps
                     else e_spline * regularised_sign(v, v_eps))
            if g_bearing:
                g = g_bearing * regularised_sign(omega * bearing_f, v_eps)
                sm = 1.0 if x0 + x1 * ag >= 0.0 else -1.0
                sb = 1.0 if y0 + y1 * ag >= 0.0 else -1.0
                for _ in range(3):
                    den = 1.0 - g * sb * e * sm
                    m0 = (x0 + g * sb * y0) / den
                    m1 = (x1 + g * sb * y1) / den
                    b0 = y0 + e * sm * m0
                    b1 = y1 + e * sm * m1
                    sm_new = 1.0 if m0 + m1 * ag >= 0.0 else -1.0
                    sb_new = 1.0 if b0 + b1 * ag >= 0.0 else -1.0
                    if sm_new == sm and sb_new == sb:
                        break
                    sm, sb = sm_new, sb_new
            else:
                # no bearing friction: M_Sk does not depend on B_(k−1)
                g, sb = 0.0, 1.0
                m0, m1 = x0, x1
                sm = 1.0 if x0 + x1 * ag >= 0.0 else -1.0
                b0 = y0 + e * sm * m0
                b1 = y1 + e * sm * m1
            h0, h1 = e * sm * m0, e * sm * m1
            per_stage[k] = (fi, ae0, a1, co, m0, m1, h0, h1, b0, b1, e, g, sm, sb)
            a0, a1 = b0, b1 + mass_below
            mn0, mn1, hn0, hn1 = m0, m1, h0, h1
        raise AssertionError("unreachable: the sweep returns at stage 1")

    @staticmethod
    def _signs_hold(rec, alpha) -> bool:
        """Whether the signs used in a sweep are those of the quantities at ``alpha``."""
        for fi, a0, a1, _, m0, m1, _, _, b0, b1, e, g, sm, sb in rec[1]:
            if (0 if a0 + a1 * alpha >= 0.0 else 1) != fi:
                return False
            # the spline friction uses the sign of M_Sk; the bearing friction that of B_(k−1)
            # (without bearing friction the sweep does not use B's sign at all)
            if (e or g) and (1.0 if m0 + m1 * alpha >= 0.0 else -1.0) != sm:
                return False
            if g and (1.0 if b0 + b1 * alpha >= 0.0 else -1.0) != sb:
                return False
        return True

    def _assemble(self, omega, wps, load, alpha, rec, detail) -> Solution:
        stages = self.stages
        n = len(stages)
        (m0, m1), per_stage = rec
        motor = m0 + m1 * alpha
        if not detail:
            acc, p_fric = self._rates(omega, alpha, per_stage)
            return Solution(alpha, acc, motor, p_fric)
        dyn = self.zeta is None
        acc = [0.0] * n
        p_fric = 0.0
        axial, contact, normal, torque, spline, bearing, stage_p = ([0.0] * n for _ in range(7))
        terms = {"coulomb": 0.0, "viscous": 0.0, "differential": 0.0, "joints": 0.0}
        for k in range(n):
            fi, a0, a1, co, x0, x1, h0, h1, b0, b1, e, g, sm, sb = per_stage[k]
            s = stages[k]
            a = a0 + a1 * alpha                  # effective axial force Ã = A + V_z
            kappa, gamma, pw, q, _, gamma_v, p_v, p_c, p_d = co
            if dyn:
                acc[k] = (gamma * a + gamma_v) / s.j_carrier
            pk = pw * a + p_v
            terms["coulomb"] += p_c * a
            terms["differential"] += p_d * a
            terms["viscous"] += p_v
            if k > 0:
                h = h0 + h1 * alpha
                b = b0 + b1 * alpha
                # spline: screw k slides at −ω ℓ_(k−1) relative to screw k−1; bearing: at ω r_NS
                # g = µ_NS r_NS sgñ(ω r_NS); |B| = σ_B B with the sweep's sign (equal at the
                # solution; keeps one record one affine law in α)
                p_joint = h * omega * s.spline_speed_factor + g * sb * b * omega
                pk += p_joint
                terms["joints"] += p_joint
            p_fric += pk
            fl = s.flanks[fi]
            f_normal = a * q / s.n_rollers
            axial[k] = a - s.c_viscous * fl.az * omega
            normal[k] = f_normal
            contact[k] = f_normal * fl.nz
            torque[k] = motor if k == 0 else x0 + x1 * alpha
            spline[k] = 0.0 if k == 0 else h0 + h1 * alpha
            if k > 0:
                bearing[k - 1] = b0 + b1 * alpha
            stage_p[k] = pk
        sol = Solution(alpha, acc, motor, p_fric)
        bearing[n - 1] = load
        sol.stage_axial_force, sol.contact_force, sol.normal_force = axial, contact, normal
        sol.driven_torque, sol.spline_friction, sol.bearing_force = torque, spline, bearing
        sol.stage_friction_power = stage_p
        sol.friction_power_terms = terms
        return sol

    def _rates(self, omega, alpha, per_stage) -> tuple:
        """The hot path of :meth:`_assemble`: (carrier accelerations, friction power)."""
        p_fric = 0.0
        acc = []
        for (j_carrier, spline_f), (_, a0, a1, co, _, _, h0, h1, b0, b1, e, g, _, sb) in zip(
                self._rate_consts, per_stage):
            a = a0 + a1 * alpha
            acc.append((co[1] * a + co[5]) / j_carrier)
            p_fric += co[2] * a + co[6]
            if e:
                p_fric += (h0 + h1 * alpha) * omega * spline_f
            if g:
                p_fric += g * sb * (b0 + b1 * alpha) * omega
        if self.zeta is not None:
            acc = [0.0] * len(per_stage)
        return acc, p_fric

    def sliding_velocities(self, omega: float, carrier_state) -> list:
        """Sliding velocity of every regularised friction law that acts [m/s], in the order of
        :meth:`kink_speeds`.

        Per stage and thread flank the slip velocity s = ω a + ω_P b (three components, with
        µ_SR > 0) and the differential-sliding speed ω r (with µ_3 > 0); then the spline's
        ω ℓ_(k−1) and the bearing face's ω r_NS (where they have friction).  The laws of
        friction.py act on these through |s| and, for the one-component ones, their sign.

        Parameters
        ----------
        omega : float
            Screw speed [rad/s].
        carrier_state : sequence of float
            The carrier speeds [rad/s] (dynamic level; ignored when the carriers are slaved).

        Returns
        -------
        list of tuple of float
            One tuple per law: its sliding velocity's components [m/s].
        """
        wps = self.carrier_speeds(omega, carrier_state)
        out = []
        mu, mu3 = self.mu, self.mu3
        for s, wp in zip(self.stages, wps):
            for fl in s.flanks:
                if mu:
                    out.append((omega * fl.ax + wp * fl.bx, omega * fl.ay + wp * fl.by,
                                omega * fl.az))
                if mu3:
                    out.append((omega * fl.radius,))
            if s.e_spline:
                out.append((omega * s.spline_speed_factor,))
            if s.g_bearing:
                out.append((omega * s.bearing_speed_factor,))
        return out

    def kink_speeds(self) -> tuple:
        """Per entry of :meth:`sliding_velocities`, the sliding speeds |s| [m/s] at which its law
        is only C¹.

        The regularised Coulomb law µ|N| r(2 − r), r = |s|/v_ε (friction.py), meets exact
        Coulomb at |s| = v_ε with equal value and slope but not curvature, and its one-component
        form s φ(|s|) has the same break where s changes sign.  So a one-component law has the
        kinks (0, v_ε), a three-component one v_ε alone (its slip vector does not pass through
        zero unless every component does at once).

        Returns
        -------
        tuple of tuple of float
            One tuple of kink speeds [m/s] per law.
        """
        v = self.v_eps
        signed, vector = (0.0, v), (v,)
        out = []
        for s in self.stages:
            for _ in s.flanks:
                if self.mu:
                    out.append(vector)
                if self.mu3:
                    out.append(signed)
            if s.e_spline:
                out.append(signed)
            if s.g_bearing:
                out.append(signed)
        return tuple(out)

    def fastest_time_constant(self, omega: float, carrier_state, load: float) -> float:
        """Smallest carrier time constant J_Pk / |∂G_Pk/∂ω_Pk| at this point [s] (inf if none;
        Coulomb and viscous friction both damp the carriers).

        Used for step selection, stability predictions and the ``auto`` fidelity choice.
        """
        if self.zeta is not None:
            return math.inf
        sol = self.solve(omega, carrier_state, load, acceleration=0.0, detail=True)
        tau = math.inf
        for s, wp, a_axial in zip(self.stages, carrier_state, sol.stage_axial_force):
            a = a_axial + s.c_viscous * s.flanks[0].az * omega     # effective: Ã = A + V_z
            fl = s.flanks[0 if a >= 0 else 1]
            sx = omega * fl.ax + wp * fl.bx
            sy = omega * fl.ay + wp * fl.by
            sz = omega * fl.az
            v = math.sqrt(sx * sx + sy * sy + sz * sz)
            phi = regularised_factor(v, self.v_eps)
            # dφ/dv: −1/v² outside the band, −1/v_ε² inside (friction.py)
            dphi = -1.0 / (v * v) if v >= self.v_eps else -1.0 / (self.v_eps * self.v_eps)
            sb = sx * fl.bx + sy * fl.by
            bb = fl.bx * fl.bx + fl.by * fl.by
            nr = s.n_rollers
            d = abs(nr * (fl.nz - self.mu * sz * phi))
            # ∂(u·b)/∂ω_P with u = s φ(|s|): |b|² φ + φ'(v) (s·b)²/v
            rate = nr * self.mu * abs(a) / d * (bb * phi + (dphi * sb * sb / v if v > 0.0 else 0.0))
            # the viscous force's generalized force −N_R µ_1 n_t (s·b) adds N_R µ_1 n_t |b|²
            rate += s.c_viscous * bb
            if rate > 0.0:
                tau = min(tau, s.j_carrier / rate)
        return tau

