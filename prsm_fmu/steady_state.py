"""Steady state of a multi-stage PRSM found by root finding, independently of time stepping.

This module is the independent check of the dynamic and quasi-static levels: it writes the
per-body balances of docs/model.md §3 with every acceleration set to zero, *as residuals*,
and solves them with :func:`scipy.optimize.root`.  It uses only the contact geometry
(:mod:`prsm_fmu.geometry`), the parameters and the friction laws; it does not use
``prsm_fmu.mechanics`` or ``prsm_fmu.models``.

Unknowns for an n-stage mechanism at screw speed ω ≠ 0 and load F (4n − 1 of them)
------------------------------------------------------------------------------------
* ζ_k = ω_Pk / ω, the carrier speed ratios (k = 1..n);
* F_k ≥ 0, the normal force per roller at the screw–roller contact (k = 1..n);
* M_Sk, the torque driving screw k (M_S1 is the motor torque; k = 1..n);
* B_k, the axial force of the thrust bearing between nut k and screw k+1 (k = 1..n−1).

Residuals (4n − 1), with s_k = ω a_k + ζ_k ω b_k, u_k = s_k φ(|s_k|) (friction.py),
f_k = −µ_SR F_k u_k − µ_1 n_tk s_k (Coulomb spin sliding and the lubricant's viscous force per
roller, the friction-torque article), ℓ_k = L_Sk / 2π, A_n = F and A_k = B_k (k < n):

* carrier k:           G_Pk = N_Rk f_k · b_k = 0;
* rollers of stage k:  N_Rk (F_k n_z + f_k,z) − A_k = 0;
* screw k ≥ 2, axial:  B_(k−1) − A_k − h_k + h_(k+1) = 0,
  h_k = µ_SS |M_Sk| / r_SSk · sgñ(ω ℓ_(k−1)), h_1 = h_(n+1) = 0;
* screw k, torque:     M_Sk − M_S(k+1) + N_Rk [P_k × (F_k n_k + f_k)]_z + T_b,k + T_d,k = 0,
  T_b,k = −µ_NS |B_(k−1)| r_NS,(k−1) sgñ(ω r_NS,(k−1)) (k ≥ 2), M_S(n+1) = 0, and the friction-torque article's
  differential-sliding torque T_d,k = −µ_3 N_Rk F_k sgñ(ω r_k), r_k = |P_k,xy| the contact
  radius;

sgñ is :func:`prsm_fmu.friction.regularised_sign` with v_ε = ``slip_velocity_scale``.  The
contact of stage k is the "+" flank of :func:`prsm_fmu.geometry.contact_geometry` when the
stage's axial force A_k ≥ 0 and its mirror image otherwise.

Degenerate carriers.  If (µ_SR = 0 or F = 0) and µ_1 = 0, G_Pk vanishes for every ζ_k: the
carriers are in neutral equilibrium and the steady state does not fix their speed.  The carrier
residual is then replaced by its µ_SR·F_k → 0⁺ limit, u_k · b_k = 0, so the ratio returned is
the one the mechanism approaches with vanishing friction (:func:`carrier_equilibrium_ratio`).
With a viscous term (µ_1 > 0) the carriers are never neutral: the lubricant's force along the
slip holds them at the same ratio, s_k · b_k = 0, at any load including zero.

All quantities are SI: m, N, N·m, rad/s, m/s, W.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from .friction import regularised_factor, regularised_sign
from .geometry import ContactGeometry, contact_geometry
from .params import MechanismParams

__all__ = ["steady_state", "carrier_equilibrium_ratio", "default_initial_guess",
           "unknown_names"]

#: largest accepted norm of the scaled (dimensionless) residual vector at the solution
RESIDUAL_TOL = 1e-10


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _StageContact:
    """Contact data of one stage on one flank, as numpy arrays."""

    point: np.ndarray      # contact point P [m] (only x, y used)
    normal: np.ndarray     # unit normal, force on the screw [-]
    a: np.ndarray          # ∂s/∂ω_S [m/rad]
    b: np.ndarray          # ∂s/∂ω_P [m/rad]


def _stage_contact(geom: ContactGeometry) -> _StageContact:
    a, b = geom.slip_jacobians()
    return _StageContact(point=np.array(geom.point, dtype=float),
                         normal=np.array(geom.normal, dtype=float),
                         a=np.array(a, dtype=float), b=np.array(b, dtype=float))


def _contact(params: MechanismParams, k: int, flank: int) -> _StageContact:
    """Contact of stage ``k`` (1-based) on flank ``flank`` (+1 or −1)."""
    geom = contact_geometry(params.stages[k - 1])
    return _stage_contact(geom if flank > 0 else geom.mirrored())


def _check_stage_index(params: MechanismParams, k: int) -> None:
    if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= params.n_stages:
        raise ValueError(f"k = {k!r} is out of range: must be an integer in "
                         f"[1, {params.n_stages}]")


def _check_finite(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number")
    return v


def _cross_z(p: np.ndarray, f: np.ndarray) -> float:
    """z component of p × f."""
    return float(p[0] * f[1] - p[1] * f[0])


# ---------------------------------------------------------------------------------------------
# public helpers
# ---------------------------------------------------------------------------------------------
def carrier_equilibrium_ratio(params: MechanismParams, k: int) -> float:
    """Closed-form steady carrier speed ratio ζ*_k = −(a_k·b_k)/(b_k·b_k) of stage k.

    At this ratio the screw–roller slip is perpendicular to b_k, so the friction force does no
    virtual work on the carrier (docs/model.md §4).  The value is the same on both flanks.

    Parameters
    ----------
    params : MechanismParams
        The mechanism.
    k : int
        Stage index, 1-based.

    Returns
    -------
    float
        ζ*_k = ω_Pk / ω_S [-].

    Raises
    ------
    ValueError
        If ``k`` is not a stage index.
    """
    _check_stage_index(params, k)
    c = _contact(params, k, +1)
    return float(-np.dot(c.a, c.b) / np.dot(c.b, c.b))


def unknown_names(params: MechanismParams) -> list[str]:
    """Names of the 4n − 1 unknowns in the order used by ``initial_guess``.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (n = ``params.n_stages``).

    Returns
    -------
    list of str
        ``stage[k].carrier_speed_ratio`` (ζ_k [-]), ``stage[k].normal_force`` (F_k [N]),
        ``stage[k].driven_torque`` (M_Sk [N·m]) for k = 1..n, then ``stage[k].bearing_force``
        (B_k [N]) for k = 1..n−1.
    """
    n = params.n_stages
    names = [f"stage[{k}].carrier_speed_ratio" for k in range(1, n + 1)]
    names += [f"stage[{k}].normal_force" for k in range(1, n + 1)]
    names += [f"stage[{k}].driven_torque" for k in range(1, n + 1)]
    names += [f"stage[{k}].bearing_force" for k in range(1, n)]
    return names


def default_initial_guess(params: MechanismParams, load_force: float) -> np.ndarray:
    """Frictionless, pure-rolling estimate of the unknowns (order of :func:`unknown_names`).

    ζ_k = r_S/(r_S + r_N), F_k = |F| / (N_Rk |n_z,k|), M_Sk = F Σ_{i≥k} ℓ_i, B_k = F.

    Parameters
    ----------
    params : MechanismParams
        The mechanism.
    load_force : float
        Load F on the last nut [N], positive resisting extension.

    Returns
    -------
    numpy.ndarray
        The 4n − 1 physical unknowns [-, N, N·m, N].
    """
    load = _check_finite("load_force", load_force)
    stages = params.stages
    n = len(stages)
    ells = [st.screw_lead / (2.0 * math.pi) for st in stages]
    zeta = [st.screw_radius / (st.screw_radius + st.nut_radius) for st in stages]
    normal = [abs(load) / (st.n_rollers * abs(contact_geometry(st).normal[2])) for st in stages]
    torque = [load * sum(ells[k:]) for k in range(n)]
    bearing = [load] * (n - 1)
    return np.array(zeta + normal + torque + bearing, dtype=float)


# ---------------------------------------------------------------------------------------------
# the equilibrium
# ---------------------------------------------------------------------------------------------
class _Problem:
    """Scaled residuals of the steady-state balances for fixed flanks."""

    def __init__(self, params: MechanismParams, omega: float, load: float,
                 flanks: Sequence[int]) -> None:
        self.p = params
        self.omega = omega
        self.load = load
        self.n = params.n_stages
        self.v_eps = params.slip_velocity_scale
        self.contacts = [_contact(params, k, flanks[k - 1]) for k in range(1, self.n + 1)]
        self.ells = [st.screw_lead / (2.0 * math.pi) for st in params.stages]
        self.c_n = sum(self.ells)
        # scales of the unknowns and residuals: force, torque
        self.f_scale = abs(load) if load != 0.0 else 1.0
        self.m_scale = self.f_scale * self.c_n
        self.degenerate = ((params.mu_screw_roller == 0.0 or load == 0.0)
                           and params.mu_viscous == 0.0)
        # viscous coefficient per roller µ_1 n_t [N·s/m]
        self.visc = [params.mu_viscous * st.threads_per_roller for st in params.stages]
        n = self.n
        self.x_scale = np.array([1.0] * n
                                + [self.f_scale / st.n_rollers for st in params.stages]
                                + [self.m_scale] * n + [self.f_scale] * (n - 1))

    # -- pieces shared by residuals and post-processing ---------------------------------------
    def slip(self, k: int, zeta: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(s_k, u_k, φ_k) of stage k (1-based): slip, regularised direction, law factor."""
        c = self.contacts[k - 1]
        s = self.omega * c.a + zeta * self.omega * c.b
        phi = regularised_factor(math.sqrt(float(np.dot(s, s))), self.v_eps)
        return s, s * phi, phi

    def differential_sign(self, k: int) -> float:
        """sgñ(ω r_k) of stage k's differential-sliding torque (r_k the contact radius)."""
        c = self.contacts[k - 1]
        return regularised_sign(self.omega * math.hypot(c.point[0], c.point[1]), self.v_eps)

    def spline_friction(self, k: int, torque: float) -> float:
        """h_k [N] on screw k from screw k−1 (0 for k = 1)."""
        if k == 1 or self.p.mu_spline == 0.0:
            return 0.0
        st = self.p.stages[k - 1]
        return (self.p.mu_spline * abs(torque) / st.spline_radius
                * regularised_sign(self.omega * self.ells[k - 2], self.v_eps))

    def bearing_torque(self, k: int, bearing_force: float) -> float:
        """T_b,k [N·m] on screw k from the bearing to nut k−1 (0 for k = 1)."""
        if k == 1 or self.p.mu_nut_screw == 0.0:
            return 0.0
        r_ns = self.p.stages[k - 2].bearing_radius
        return (-self.p.mu_nut_screw * abs(bearing_force) * r_ns
                * regularised_sign(self.omega * r_ns, self.v_eps))

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Physical unknowns (ζ, F, M_S, B) from the scaled vector."""
        y = x * self.x_scale
        n = self.n
        return y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]

    def axial(self, bearing: np.ndarray) -> list[float]:
        """A_k (k = 1..n): B_k for k < n, the load for k = n."""
        return list(bearing) + [self.load]

    # -- residuals ---------------------------------------------------------------------------
    def residual(self, x: np.ndarray) -> np.ndarray:
        zeta, normal, torque, bearing = self.unpack(x)
        n = self.n
        axial = self.axial(bearing)
        mu = self.p.mu_screw_roller
        h = [self.spline_friction(k, torque[k - 1]) for k in range(1, n + 1)] + [0.0]
        r_carrier = np.empty(n)
        r_roller = np.empty(n)
        r_torque = np.empty(n)
        r_screw = np.empty(n - 1)
        for k in range(1, n + 1):
            st = self.p.stages[k - 1]
            c = self.contacts[k - 1]
            n_r = st.n_rollers
            s, u, _q = self.slip(k, zeta[k - 1])
            f = -mu * normal[k - 1] * u - self.visc[k - 1] * s
            b_norm = float(np.linalg.norm(c.b))
            if self.degenerate:
                r_carrier[k - 1] = float(np.dot(u, c.b)) / b_norm
            else:
                g_p = n_r * float(np.dot(f, c.b))
                # force scale of the carrier's friction: Coulomb µF, viscous µ_1 n_t |ω| |b|
                g_scale = (mu * self.f_scale + n_r * self.visc[k - 1] * abs(self.omega) * b_norm)
                r_carrier[k - 1] = g_p / (g_scale * b_norm)
            r_roller[k - 1] = (n_r * (normal[k - 1] * c.normal[2] + f[2]) - axial[k - 1]) \
                / self.f_scale
            contact_torque = n_r * _cross_z(c.point, normal[k - 1] * c.normal + f)
            t_d = -self.p.mu_differential * n_r * normal[k - 1] * self.differential_sign(k)
            m_next = torque[k] if k < n else 0.0
            t_b = self.bearing_torque(k, bearing[k - 2]) if k >= 2 else 0.0
            r_torque[k - 1] = (torque[k - 1] - m_next + contact_torque + t_b + t_d) / self.m_scale
            if k >= 2:
                r_screw[k - 2] = (bearing[k - 2] - axial[k - 1] - h[k - 1] + h[k]) / self.f_scale
        return np.concatenate((r_carrier, r_roller, r_torque, r_screw))

    def solve(self, guess: np.ndarray) -> tuple[np.ndarray, float]:
        """Solve from the physical guess; returns (scaled solution, residual norm)."""
        x0 = np.asarray(guess, dtype=float) / self.x_scale
        from scipy.optimize import root   # on demand: importing scipy.optimize costs ~0.8 s

        sol = root(self.residual, x0, method="hybr", options={"xtol": 1e-14})
        x = sol.x
        # polish with Newton steps on a central-difference Jacobian (the problem is smooth
        # away from M_Sk = 0 and B_k = 0, which a loaded mechanism never reaches)
        for _ in range(4):
            r0 = self.residual(x)
            if not np.all(np.isfinite(r0)) or np.max(np.abs(r0)) < 1e-16:
                break
            jac = np.empty((x.size, x.size))
            for j in range(x.size):
                dx = np.zeros(x.size)
                dx[j] = 1e-7 * max(1.0, abs(x[j]))
                jac[:, j] = (self.residual(x + dx) - self.residual(x - dx)) / (2.0 * dx[j])
            try:
                x_new = x - np.linalg.solve(jac, r0)
            except np.linalg.LinAlgError:
                break
            if np.linalg.norm(self.residual(x_new)) < np.linalg.norm(r0):
                x = x_new
            else:
                break
        res = self.residual(x)
        norm = float(np.linalg.norm(res)) if np.all(np.isfinite(res)) else math.inf
        return x, norm


def steady_state(params: MechanismParams, screw_speed: float, load_force: float, *,
                 initial_guess: Optional[Sequence[float]] = None) -> dict[str, float]:
    """Steady state of the mechanism at a constant screw speed under a constant load.

    Solves the zero-acceleration per-body balances of docs/model.md §3 (carriers, rollers,
    screws' axial and torque balances; see the module docstring) for the carrier speed ratios,
    the normal forces, the driven torques and the bearing forces with
    :func:`scipy.optimize.root` (``hybr``, xtol 1e-14, then Newton polishing).

    Parameters
    ----------
    params : MechanismParams
        The mechanism (validated here).
    screw_speed : float
        Screw 1 speed ω [rad/s], finite and non-zero.
    load_force : float
        Load F on the last nut [N] along +z; positive resists extension (Li et al.'s (2021) F_N).
    initial_guess : sequence of float, optional
        Physical starting values in the order of :func:`unknown_names`; default
        :func:`default_initial_guess`.  The solution does not depend on it.

    Returns
    -------
    dict of str to float
        ``screw_speed`` ω [rad/s]; ``screw_torque`` M_S1 [N·m]; ``rod_velocity``
        ω ΣL_S/2π [m/s] (positive = extension); ``load_force`` F [N]; per stage k (1-based)
        ``stage[k].carrier_speed_ratio`` ζ_k [-], ``stage[k].normal_force`` F_k [N] per roller,
        ``stage[k].contact_force`` F_k n_z [N], the axial part of the normal force per roller
        (positive on the "+" flank), ``stage[k].driven_torque`` M_Sk [N·m] (M_S1 for k = 1),
        ``stage[k].spline_friction`` h_k [N] (0 for k = 1); ``efficiency`` [-], the ratio of
        the power delivered to the power supplied: F v_rod / (M_S1 ω) in forward drive
        (Li et al. (2021) Eq. 28), M_S1 ω / (F v_rod) when the load drives the motor (back-driving),
        NaN when no power flows (F = 0); ``friction_power`` M_S1 ω − F v_rod [W] (≥ 0);
        ``friction_power_coulomb``, ``friction_power_viscous``, ``friction_power_differential``
        and ``friction_power_joints`` [W], the same power from each term's own law at the
        solution (screw–roller µ_SR F_k u_k·s_k, µ_1 n_t |s_k|² and µ_3 F_k ω sgñ(ω r_k) per
        roller; splines and thrust bearings), whose sum equals ``friction_power`` when the
        balances hold; ``screw_friction_torque`` M_S1 − F ΣL/2π [N·m] (the friction-torque article's M_f at steady
        state); ``residual_norm``, the 2-norm of the dimensionless residual vector [-].

    Raises
    ------
    ValueError
        If ``screw_speed`` is zero or not finite (at standstill the carriers' ratio is
        undefined, there is no unique steady state), if ``load_force`` is not finite, if
        ``initial_guess`` has the wrong length, or if ``params`` is invalid.
    RuntimeError
        If the solver does not converge or the flank that carries each stage's load cannot be
        made consistent with the sign of its axial force.
    """
    omega = _check_finite("screw_speed", screw_speed)
    if omega == 0.0:
        raise ValueError(
            f"screw_speed = {screw_speed!r} rad/s is out of range: must be non-zero (at "
            "standstill the carriers' speed ratio is undefined, there is no unique steady "
            "state)")
    load = _check_finite("load_force", load_force)
    params.validate()
    n = params.n_stages
    if initial_guess is None:
        guess = default_initial_guess(params, load)
    else:
        guess = np.asarray(initial_guess, dtype=float)
        if guess.shape != (4 * n - 1,):
            raise ValueError(f"initial_guess has shape {guess.shape}: must have 4n - 1 = "
                             f"{4 * n - 1} entries (see unknown_names)")

    # The flank of stage k follows the sign of its axial force A_k; start from the sign of the
    # load and iterate until the solution's A_k agree with the flanks assumed.
    flanks = [1 if load >= 0.0 else -1] * n
    for _ in range(n + 2):
        prob = _Problem(params, omega, load, flanks)
        x, res_norm = prob.solve(guess)
        zeta, normal, torque, bearing = prob.unpack(x)
        axial = prob.axial(bearing)
        new_flanks = [flanks[k] if axial[k] == 0.0 else (1 if axial[k] > 0.0 else -1)
                      for k in range(n)]
        if new_flanks == flanks:
            break
        flanks = new_flanks
        guess = np.concatenate((zeta, np.abs(normal), torque, bearing))
    else:
        raise RuntimeError(f"steady_state: the loaded flanks do not settle (screw_speed = "
                           f"{omega!r} rad/s, load_force = {load!r} N)")
    if not res_norm <= RESIDUAL_TOL:
        raise RuntimeError(f"steady_state did not converge: residual norm {res_norm:.3e} > "
                           f"{RESIDUAL_TOL:g} (screw_speed = {omega!r} rad/s, load_force = "
                           f"{load!r} N)")
    tol = 1e-9 * prob.f_scale
    if np.any(normal < -tol):
        raise RuntimeError("steady_state: a normal force came out negative "
                           f"({normal.tolist()} N): the flank assumption is inconsistent")

    c_n = prob.c_n
    rod_velocity = omega * c_n
    m_s1 = float(torque[0])
    p_in = m_s1 * omega
    p_out = load * rod_velocity
    supplied = max(p_in, 0.0) + max(-p_out, 0.0)
    delivered = max(p_out, 0.0) + max(-p_in, 0.0)
    efficiency = delivered / supplied if supplied > 0.0 else math.nan

    out: dict[str, float] = {
        "screw_speed": omega,
        "screw_torque": m_s1,
        "rod_velocity": rod_velocity,
        "load_force": load,
    }
    for k in range(1, n + 1):
        c = prob.contacts[k - 1]
        out[f"stage[{k}].carrier_speed_ratio"] = float(zeta[k - 1])
        out[f"stage[{k}].normal_force"] = float(normal[k - 1])
        out[f"stage[{k}].contact_force"] = float(normal[k - 1] * c.normal[2])
        out[f"stage[{k}].driven_torque"] = float(torque[k - 1])
        out[f"stage[{k}].spline_friction"] = float(prob.spline_friction(k, torque[k - 1]))
    out["efficiency"] = efficiency
    out["friction_power"] = p_in - p_out
    terms = {"coulomb": 0.0, "viscous": 0.0, "differential": 0.0, "joints": 0.0}
    mu = params.mu_screw_roller
    for k in range(1, n + 1):
        n_r = params.stages[k - 1].n_rollers
        s, u, _q = prob.slip(k, zeta[k - 1])
        terms["coulomb"] += n_r * mu * float(normal[k - 1]) * float(np.dot(u, s))
        terms["viscous"] += n_r * prob.visc[k - 1] * float(np.dot(s, s))
        terms["differential"] += (n_r * params.mu_differential * float(normal[k - 1])
                                  * prob.differential_sign(k) * omega)
        if k >= 2:
            # spline: screw k slides at −ω ℓ_(k−1) along screw k−1 (h opposes it); bearing:
            # its torque T_b on screw k turning at ω
            terms["joints"] += (float(prob.spline_friction(k, torque[k - 1])) * omega
                                * prob.ells[k - 2]
                                - prob.bearing_torque(k, bearing[k - 2]) * omega)
    for term, value in terms.items():
        out[f"friction_power_{term}"] = value
    out["screw_friction_torque"] = m_s1 - load * c_n
    out["residual_norm"] = res_norm
    return out
