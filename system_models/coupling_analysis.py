"""Linearised co-simulation stability of the actuator loop: the spectral radius of the macro step.

What this predicts: for the actuator loop of :mod:`system_models.ema` stepped by the master of
:mod:`system_models.master`, the largest communication step h at which the coupled loop stays
stable, for each coupling scheme (Jacobi / Gauss–Seidel, input extrapolation of order 0 / 1) and
load stiffness.  The model below is written from the blocks' physics and parameters and from
the master's documented scheme (docs/ema.md §3–4), not by calling the blocks' code, so the real
nonlinear loop can be measured against it (``benchmarks/cosim_stability.py``).

Operating point (:func:`stability_scene`)
-----------------------------------------
Speed mode at a constant screw speed ω0 = 50 rad/s (rod speed v0 = c ω0, c = Σ L_k/2π)
against a spring whose anchor moves with the rod's nominal motion and a damper,
F = F0 + k (x − v0 t) + c_d v + ΔF·1(t ≥ t_d): the load's external force is the ``points``
profile −k v0 t (plus the step ΔF that excites the loop), so the steady state is stationary
whatever k.  F0 = 1 kN keeps the load force positive (the PRSM drives: fixed flank and friction
sign pattern) and ω0 = 50 rad/s is far outside the friction band, so the quasi-static PRSM is
exactly linear there (prsm_fmu/models/slaved.py): α = (M − K_F F)/K_α.  The motor runs at
50 V of back-EMF, far from the 156 V voltage limit; i_q ≈ 3 A, far from the 20 A limit.

Linear model (:class:`LinearLoop`, :func:`macro_step_map`), deviations from that steady state
-----------------------------------------------------------------------------------------------
* Motor (dq, L_d = L_q = L, ω_e = p ω, i_d0 = 0), linearised at (ω0, i_q0)::

      L di_d/dt = v_d − R i_d + p L (ω0 i_q + i_q0 ω)
      L di_q/dt = v_q − R i_q − p L (ω0 i_d + i_d0 ω) − p ψ ω

  The voltages are held over the macro step (discrete ports); the speed input is the master's
  extrapolation ω_k + s_ω τ.  Solved exactly: the matrix exponential of the system augmented
  with (ω_in, s_ω, v_d, v_q) as states (ω_in' = s_ω, the rest constant).  (The block itself
  integrates with RK4 on ≤ 20 µs substeps; its error, ≈ 1e-12, is neglected.)
* PRSM (quasi-static, rigid rotor and load mass lumped in): α = (M − K_F F)/K_α with both
  inputs held over the step, so θ' = θ + ω h + α h²/2, ω' = ω + α h exactly.  K_F and K_α are
  the partial derivatives of the model's ``screw_acceleration`` output at the operating point
  (:func:`prsm_law`; exact there, the law is linear for a fixed sign pattern).  Rod position
  x = c θ, rod velocity v = c ω.
* Load: F = k x + c_d v (feedthrough): recomputed at t_(k+1) from the PRSM's new x and v.
* Controller (speed mode, no saturation, anti-windup inactive), at each sample instant t_j in
  [t_k, t_k + h), with inputs ω̂, î_d, î_q = the master's extrapolations at t_j::

      e = −ω̂;  i_q* = K_pω e + I_ω;  I_ω += T_s K_iω e
      v_d = −K_pi î_d + I_d − p L (ω0 î_q + i_q0 ω̂)
      v_q = K_pi (i_q* − î_q) + I_q + p L ω0 î_d + p (L i_d0 + ψ) ω̂
      I_d += T_s K_ii (−î_d);  I_q += T_s K_ii (i_q* − î_q)

  (decoupling and back-EMF feed-forward linearised); the held commands are those of the last
  sample.  The speed loop runs every sample (speed mode: the position loop is off), so the
  sample pattern repeats with the period T_s.
* Master (docs/ema.md §4).  Jacobi: every block steps from the values at t_k: the motor gets
  the commands held at t_k, the PRSM the torque k_t i_q and the load force extrapolated from
  t_k.  Gauss–Seidel, in block order controller, motor, PRSM, load: the controller steps from
  t_k's values, the motor gets the commands of this step's last sample (and the speed
  extrapolated from t_k: the PRSM has not stepped yet), the PRSM the motor's new torque
  (order 0: held at its t_(k+1) value; order 1: the mean of the line from t_k to t_(k+1),
  (T_k + T_(k+1))/2) and the load force extrapolated from t_k.  Extrapolation order
  0 holds the value at t_k; order 1 uses the slope (y_k − y_(k−1))/h: a block that
  interpolates (controller, motor) sees y_k + s τ, the PRSM (held inputs) the mean
  y_k + s h/2.  The previous communication values (i_d, i_q, θ, ω at t_(k−1)) are then extra
  states.  The load's output is its feedthrough update from the PRSM's state at t_(k+1).

State z = (i_d, i_q, θ, ω, I_ω, I_d, I_q, v_d, v_q [, i_d, i_q, θ, ω at t_(k−1)]) at t_k;
z_(k+1) = A_k z_k.

Prediction
----------
With h/T_s = p/q (a rational in lowest terms: exactly, if the ratio is one with q ≤ 4096,
else a rational with a small q within a relative 1e-3, :func:`step_ratio`), the sample offsets
inside the macro steps repeat after q steps; the loop is stable if the spectral radius of
the product A_(q−1)⋯A_0 is below 1; :func:`spectral_radius` returns its q-th root, the
growth factor per macro step.  The sample phase matters: where the last sample of a step falls
late in the step, the controller acts on inputs extrapolated over most of the step, and the
spectral radius can jump between neighbouring h (at k = 1e5 N/m, Gauss–Seidel with
extrapolation 1: at h = 2.5 T_s, samples at most 0.8 h into a step, ρ = 0.964 per step; at
2.6 T_s, samples up to 0.92 h into a step, ρ = 1.041).  So the real loop is compared at the
same h (:func:`snap_step`), whose sample pattern repeats exactly; a float h near a rational
with a small q would drift through the phases over a long run.

One eigenvalue is exactly 1 and is removed (the one closest to 1) before taking the radius:
in speed mode the steady states form a line (the speed PI holds ω0 at any spring compression
δ: k_t i_q = K_F k δ, I_ω = i_q, I_q = v_q = R i_q, v_d = −p ω0 L i_q, i_d = I_d = 0), and a
fixed point of the loop is a fixed point of the co-simulation map for every h
(tests/test_cosim_stability.py checks it).  It is the loop's physics (a speed-controlled
actuator has no memory of its position), not a co-simulation effect: after a disturbance a
stable run settles on a point of that line, which depends (slightly) on the path.

:func:`predicted_boundary` scans h geometrically and bisects the first crossing of ρ = 1 (the
smallest unstable h, relative 1e-3): the predicted largest stable communication step.

Assumptions (beyond those above): no saturation is active (current, voltage, speed limits);
the disturbance keeps the PRSM in one sign pattern outside the friction band; the master takes
plain macro steps (no retry); the run has passed its first step (order 1 extrapolates from the
second step on); t0 = 0 lies on a sample instant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache

import numpy as np

from prsm_fmu.models import make_model

from .ema import System, build_system
from .master import ORDERS
from .scenes import Scene, parse_scene

__all__ = ["LinearLoop", "stability_scene", "build_stability_system", "prsm_law", "linear_loop",
           "step_ratio", "snap_step", "sample_offsets", "motor_transition", "macro_step_map",
           "period_map", "spectral_radius", "critical_mode", "predicted_boundary",
           "predicted_stable_step", "SPEED", "PRELOAD", "DISTURBANCE", "DISTURBANCE_TIME",
           "STATE_NAMES"]

SPEED = 50.0                  #: screw speed of the operating point ω0 [rad/s]
PRELOAD = 1000.0              #: spring preload F0 [N] (load force ≈ 1.16 kN with the damper)
DISTURBANCE = 100.0           #: step ΔF of the external force that excites the loop [N]
DISTURBANCE_TIME = 2e-3       #: when the step comes [s]
RATIO_RTOL = 1e-3             #: relative accuracy of the rational h/T_s (module docstring)

#: names of the linear state, in order (order-1 extrapolation appends the ``*_prev`` four)
STATE_NAMES = ("i_d", "i_q", "theta", "omega", "I_speed", "I_d", "I_q", "v_d", "v_q",
               "i_d_prev", "i_q_prev", "theta_prev", "omega_prev")


# ---- the operating point as a scene ---------------------------------------------------------
def stability_scene(stiffness: float, t_end: float = 0.2, damping: float | None = None,
                    speed: float = SPEED, preload: float = PRELOAD,
                    disturbance: float = DISTURBANCE,
                    disturbance_time: float = DISTURBANCE_TIME) -> Scene:
    """The loop at the operating point of the module docstring, as a scene.

    Speed mode at ``speed`` [rad/s], steady start; load spring ``stiffness`` [N/m] with its
    anchor moving at the rod's nominal speed (external force ramp −k v0 t, a ``points``
    profile), ``preload`` [N], damper ``damping`` [N·s/m] (None: the default
    :class:`~system_models.load.LoadParams` value), and a step of ``disturbance`` [N] in the
    external force at ``disturbance_time`` [s].  Runs to ``t_end`` [s]; the step, order and
    extrapolation are set by :func:`build_stability_system`.
    """
    from .prsm import mechanism_params

    c = mechanism_params("PRSM2").total_lead / (2.0 * math.pi)
    ramp = -stiffness * c * speed           # [N/s]
    # the profile holds its last value: end the ramp far beyond any run's end
    td, te = disturbance_time, 10.0 * max(t_end, disturbance_time) + 1.0
    load = {"stiffness": float(stiffness), "preload": float(preload),
            "external_force": {"kind": "points", "time": [0.0, td, td, te],
                               "value": [0.0, ramp * td, ramp * td + disturbance,
                                         ramp * te + disturbance]}}
    if damping is not None:
        load["damping"] = float(damping)
    data = {"description": f"co-simulation stability: speed {speed:g} rad/s against k = "
                           f"{stiffness:g} N/m (moving anchor), {disturbance:g} N step",
            "t_end": float(t_end), "step": 1e-4, "order": "gauss-seidel", "extrapolation": 1,
            "fidelity": "quasi-static",
            "controller": {"mode": "speed", "reference": float(speed)},
            "load": load, "initial": {"screw_speed": float(speed), "steady": True}}
    return parse_scene(data, "cosim_stability")


def build_stability_system(stiffness: float, step: float, order: str, extrapolation: int,
                           t_end: float = 0.2, **scene_options) -> System:
    """The real loop at the operating point (plain Python PRSM, quasi-static), ready to run."""
    return build_system(stability_scene(stiffness, t_end, **scene_options), prsm="python",
                        fidelity="quasi-static", step=step, order=order,
                        extrapolation=extrapolation)


# ---- the linear loop ------------------------------------------------------------------------
@dataclass(frozen=True)
class LinearLoop:
    """Parameters of the linearised loop (SI units).

    Attributes
    ----------
    R, L : float
        Motor phase resistance [Ω] and inductance [H].
    p : int
        Pole pairs.
    psi, kt : float
        Magnet flux linkage [Wb], torque constant [N·m/A].
    Ts : float
        Controller sample time [s].
    kp_i, ki_i : float
        Current PI gains [V/A], [V/(A·s)].
    kp_w, ki_w : float
        Speed PI gains [A/(rad/s)], [A/rad].
    c : float
        Rod travel per screw radian [m/rad].
    K_F, K_alpha : float
        PRSM law α = (M − K_F F)/K_α: [m] (torque per unit load force), [kg·m²].
    k, c_d : float
        Load stiffness [N/m] and damping [N·s/m].
    w0, iq0, id0 : float
        Operating point: screw speed [rad/s], currents [A].
    """

    R: float
    L: float
    p: int
    psi: float
    kt: float
    Ts: float
    kp_i: float
    ki_i: float
    kp_w: float
    ki_w: float
    c: float
    K_F: float
    K_alpha: float
    k: float
    c_d: float
    w0: float
    iq0: float
    id0: float = 0.0

    @property
    def rod_mass(self) -> float:
        """Mass the load force accelerates at the rod, K_α / (c K_F) [kg]."""
        return self.K_alpha / (self.c * self.K_F)

    def with_changes(self, **changes) -> "LinearLoop":
        """A copy with some parameters replaced (for studies and closed-form checks)."""
        from dataclasses import replace

        return replace(self, **changes)


def prsm_law(system: System, speed: float, load_force: float) -> tuple[float, float]:
    """(K_F [m], K_α [kg·m²]) of α = (M − K_F F)/K_α at (``speed`` [rad/s], ``load_force`` [N]).

    Central differences of the quasi-static model's ``screw_acceleration`` output (with the
    rotor and load mass lumped in, as the loop's PRSM block has them), in the torque about the
    steady torque K_F F and in the force: the law is linear for a fixed sign pattern, so the
    differences are exact up to rounding.
    """
    model = make_model(system.prsm.params(), "quasi-static", "torque")

    def acc(torque: float, force: float) -> float:
        u = (torque, force)
        x = model.initial_state(u, screw_speed=speed, carrier_ratio=None)
        return float(model.outputs(0.0, x, u)["screw_acceleration"])

    m_guess = system.lead_per_radian * load_force       # any torque in the pattern will do
    dm, df = 0.05 * abs(m_guess) + 0.1, 0.05 * abs(load_force) + 1.0
    da_dm = (acc(m_guess + dm, load_force) - acc(m_guess - dm, load_force)) / (2.0 * dm)
    da_df = (acc(m_guess, load_force + df) - acc(m_guess, load_force - df)) / (2.0 * df)
    return -da_df / da_dm, 1.0 / da_dm


def linear_loop(system: System) -> LinearLoop:
    """The linearised loop of a built speed-mode system at its steady start (module docstring).

    The operating current is i_q0 = K_F F0 / k_t (zero acceleration under the PRSM's linear
    law), found here independently of the assembly's root finder.
    """
    if system.scene.controller.get("mode") != "speed":
        raise ValueError("linear_loop: the controller must be in speed mode (module docstring)")
    m, cp, ld = system.motor, system.controller, system.load
    if cp.speed_divider != 1:
        raise ValueError(f"linear_loop: speed_divider = {cp.speed_divider} is not supported "
                         "(the sample pattern is assumed to repeat every sample)")
    w0 = float(system.initial["screw_speed"])
    f0 = float(system.initial["load_force"])
    k_f, k_a = prsm_law(system, w0, f0)
    return LinearLoop(R=m.resistance, L=m.inductance, p=m.pole_pairs, psi=m.flux_linkage,
                      kt=m.torque_constant, Ts=cp.sample_time, kp_i=cp.current_kp,
                      ki_i=cp.current_ki, kp_w=cp.speed_kp, ki_w=cp.speed_ki,
                      c=system.lead_per_radian, K_F=k_f, K_alpha=k_a, k=ld.stiffness,
                      c_d=ld.damping, w0=w0, iq0=k_f * f0 / m.torque_constant)


# ---- one macro step -------------------------------------------------------------------------
def step_ratio(h: float, ts: float, rtol: float = RATIO_RTOL) -> Fraction:
    """h/T_s as a rational: exactly if it is one with a denominator ≤ 4096 (to 1e-12), else
    the one with the smallest denominator (searched in powers of 2) within ``rtol``."""
    x = h / ts
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"h = {h!r} s is out of range: must be a finite number > 0")
    r = Fraction(x).limit_denominator(4096)
    if abs(float(r) - x) <= 1e-12 * x:
        return r
    q = 1
    while True:
        r = Fraction(x).limit_denominator(q)
        if r > 0 and abs(float(r) - x) <= rtol * x:
            return r
        q *= 2


def snap_step(h: float, ts: float) -> float:
    """The communication step the analysis represents exactly: T_s times :func:`step_ratio`.

    Run the real loop at this h [s] to compare it with the prediction: the sample pattern then
    repeats exactly as in the analysis (a float ratio close to a rational p/q with a small q
    would drift through the sample phases over a long run).
    """
    return float(step_ratio(h, ts)) * ts


def sample_offsets(ratio: Fraction, k: int, ts: float) -> tuple[float, ...]:
    """Offsets τ [s] from t_k = k h of the controller samples j T_s in [t_k, t_k + h)."""
    start, end = k * ratio, (k + 1) * ratio
    j0 = math.ceil(start)
    return tuple(float(j - start) * ts for j in range(j0, math.ceil(end)))


def motor_transition(loop: LinearLoop, h: float) -> np.ndarray:
    """Transition matrix over h of the motor augmented with its inputs.

    State (i_d, i_q, ω_in, s_ω, v_d, v_q): the linearised dq equations with the speed input
    ω_in' = s_ω (linear extrapolation) and the voltages held.  Returns expm(A h), 6×6.
    """
    lp = loop
    a = np.zeros((6, 6))
    a[0, 0], a[0, 1], a[0, 2], a[0, 4] = -lp.R / lp.L, lp.p * lp.w0, lp.p * lp.iq0, 1.0 / lp.L
    a[1, 0], a[1, 1] = -lp.p * lp.w0, -lp.R / lp.L
    a[1, 2], a[1, 5] = -lp.p * lp.id0 - lp.p * lp.psi / lp.L, 1.0 / lp.L
    a[2, 3] = 1.0
    from scipy.linalg import expm   # on demand: scipy costs ~0.5 s to import

    return expm(a * h)


def macro_step_map(loop: LinearLoop, h: float, offsets: tuple[float, ...], order: str,
                   extrapolation: int, phi: np.ndarray | None = None) -> np.ndarray:
    """A_k: z_(k+1) = A_k z_k over one macro step h [s] (module docstring).

    Parameters
    ----------
    loop : LinearLoop
    h : float
        Communication step [s].
    offsets : tuple of float
        The controller's sample instants in the step, as offsets from its start [s].
    order : {"jacobi", "gauss-seidel"}
    extrapolation : {0, 1}
    phi : ndarray, optional
        :func:`motor_transition` over h (computed if not given).
    """
    if order not in ORDERS:
        raise ValueError(f"order = {order!r} is not allowed: must be one of {', '.join(ORDERS)}")
    if extrapolation not in (0, 1):
        raise ValueError(f"extrapolation = {extrapolation!r} is not allowed: must be 0 or 1")
    lp = loop
    gs = order == "gauss-seidel"
    n = 13 if extrapolation else 9
    e = np.eye(n)
    i_d, i_q, th, w = e[0], e[1], e[2], e[3]
    if extrapolation:
        s_id, s_iq, s_th, s_w = (e[0] - e[9]) / h, (e[1] - e[10]) / h, \
            (e[2] - e[11]) / h, (e[3] - e[12]) / h
    else:
        s_id = s_iq = s_th = s_w = np.zeros(n)
    force = lp.k * lp.c * th + lp.c_d * lp.c * w            # load force at t_k
    s_force = lp.k * lp.c * s_th + lp.c_d * lp.c * s_w
    # controller: its samples inside the step, inputs extrapolated from t_k
    i_w, i_di, i_qi, v_d, v_q = e[4], e[5], e[6], e[7], e[8]
    for tau in offsets:
        w_s, id_s, iq_s = w + tau * s_w, i_d + tau * s_id, i_q + tau * s_iq
        err = -w_s
        iq_ref = lp.kp_w * err + i_w
        i_w = i_w + lp.Ts * lp.ki_w * err
        ff_d = -lp.p * lp.L * (lp.w0 * iq_s + lp.iq0 * w_s)
        ff_q = lp.p * lp.L * lp.w0 * id_s + lp.p * (lp.L * lp.id0 + lp.psi) * w_s
        v_d = -lp.kp_i * id_s + i_di + ff_d
        v_q = lp.kp_i * (iq_ref - iq_s) + i_qi + ff_q
        i_di = i_di + lp.Ts * lp.ki_i * (-id_s)
        i_qi = i_qi + lp.Ts * lp.ki_i * (iq_ref - iq_s)
    # motor: commands held (Jacobi: those at t_k; Gauss-Seidel: this step's last sample's),
    # speed extrapolated
    if phi is None:
        phi = motor_transition(lp, h)
    held = (v_d, v_q) if gs else (e[7], e[8])
    currents = phi[:2] @ np.vstack([i_d, i_q, w, s_w, held[0], held[1]])
    # PRSM: torque and load force held over the step
    if gs:
        torque = lp.kt * (0.5 * (i_q + currents[1]) if extrapolation else currents[1])
    else:
        torque = lp.kt * (i_q + 0.5 * h * s_iq)
    alpha = (torque - lp.K_F * (force + 0.5 * h * s_force)) / lp.K_alpha
    rows = [currents[0], currents[1], th + h * w + 0.5 * h * h * alpha, w + h * alpha,
            i_w, i_di, i_qi, v_d, v_q]
    if extrapolation:
        rows += [i_d, i_q, th, w]
    return np.vstack(rows)


def period_map(loop: LinearLoop, h: float, order: str,
               extrapolation: int) -> tuple[np.ndarray, int]:
    """(A_(q−1)⋯A_0, q): the map over one period of the sample pattern (module docstring)."""
    ratio = step_ratio(h, loop.Ts)
    h_eff = float(ratio) * loop.Ts
    phi = motor_transition(loop, h_eff)
    cache: dict[tuple, np.ndarray] = {}
    prod = None
    for k in range(ratio.denominator):
        offs = sample_offsets(ratio, k, loop.Ts)
        a = cache.get(offs)
        if a is None:
            a = cache[offs] = macro_step_map(loop, h_eff, offs, order, extrapolation, phi)
        prod = a if prod is None else a @ prod
    return prod, ratio.denominator


def _without_neutral(eig: np.ndarray) -> np.ndarray:
    """The eigenvalues without the one closest to 1 (the line of steady states)."""
    i = int(np.argmin(np.abs(eig - 1.0)))
    return np.delete(eig, i)


def spectral_radius(loop: LinearLoop, h: float, order: str, extrapolation: int) -> float:
    """Growth factor per macro step: ρ(period map)^(1/q), the neutral eigenvalue removed."""
    prod, q = period_map(loop, h, order, extrapolation)
    rest = _without_neutral(np.linalg.eigvals(prod))
    return float(np.max(np.abs(rest))) ** (1.0 / q)


def critical_mode(loop: LinearLoop, h: float, order: str, extrapolation: int) -> dict:
    """The least stable mode at h: its growth per step and where its energy sits.

    Returns ``rho`` (per macro step) and ``mechanical_share``: the spring's and the rod mass's
    energy, ½ k |x|² + ½ M |v|², over that plus the motor's magnetic energy ¾ L |i|², in the
    eigenvector of the period map (1: the load's spring coupling; 0: the motor and controller).
    """
    prod, q = period_map(loop, h, order, extrapolation)
    eig, vec = np.linalg.eig(prod)
    keep = np.ones(len(eig), bool)
    keep[int(np.argmin(np.abs(eig - 1.0)))] = False
    idx = np.flatnonzero(keep)[int(np.argmax(np.abs(eig[keep])))]
    lam, v = eig[idx], vec[:, idx]
    x, vel = loop.c * v[2], loop.c * v[3]
    e_mech = 0.5 * loop.k * abs(x) ** 2 + 0.5 * loop.rod_mass * abs(vel) ** 2
    e_el = 0.75 * loop.L * (abs(v[0]) ** 2 + abs(v[1]) ** 2)
    return {"rho": float(abs(lam)) ** (1.0 / q),
            "mechanical_share": e_mech / (e_mech + e_el) if e_mech + e_el > 0 else math.nan}


# ---- the boundary ---------------------------------------------------------------------------
def predicted_boundary(loop: LinearLoop, order: str, extrapolation: int, h_min: float = 1e-6,
                       h_max: float = 1e-2, per_decade: int = 12, rtol: float = 1e-3) -> float:
    """Predicted largest stable communication step [s].

    Scans h geometrically from ``h_min`` (``per_decade`` points per decade) for the first h
    with spectral radius ≥ 1 and bisects (geometric mean) between it and the last stable h
    until they differ by ``rtol`` (relative).  Returns the last stable h (as :func:`snap_step`
    represents it); ``math.inf`` if every h up to ``h_max`` is stable.

    Raises
    ------
    ValueError
        If the loop is already unstable at ``h_min``.
    """
    if spectral_radius(loop, h_min, order, extrapolation) >= 1.0:
        raise ValueError(f"the linear loop is unstable already at h_min = {h_min:g} s "
                         f"({order}, extrapolation {extrapolation})")
    n = math.ceil(per_decade * math.log10(h_max / h_min))
    lo = h_min
    for i in range(1, n + 1):
        h = h_min * (h_max / h_min) ** (i / n)
        if spectral_radius(loop, h, order, extrapolation) >= 1.0:
            hi = h
            break
        lo = h
    else:
        return math.inf
    while hi / lo > 1.0 + rtol:
        mid = math.sqrt(lo * hi)
        if spectral_radius(loop, mid, order, extrapolation) >= 1.0:
            hi = mid
        else:
            lo = mid
    return snap_step(lo, loop.Ts)


@lru_cache(maxsize=64)
def _loop_for(stiffness: float, damping: float | None) -> LinearLoop:
    system = build_stability_system(stiffness, 1e-4, "gauss-seidel", 1, damping=damping)
    return linear_loop(system)


def predicted_stable_step(order: str, extrapolation: int, stiffness: float,
                          damping: float | None = None) -> float:
    """Predicted largest stable communication step [s] of the loop at the operating point of
    :func:`stability_scene` with load stiffness ``stiffness`` [N/m] (and ``damping`` [N·s/m],
    None: the default), for the master's ``order`` and ``extrapolation``."""
    return predicted_boundary(_loop_for(float(stiffness), damping), order, extrapolation)
