"""``fidelity = "auto"``: the cheapest level whose estimated model error is within tolerance.

The levels cost, cheapest first: kinematic, quasi-static, dynamic (the dynamic level has the
stiff carrier states; the other two step in closed form).  The estimate is the *model* error of a
level against the dynamic level, in the error measure of docs/accuracy.md §1 (max over outputs of
|y − y_ref| / max|y_ref|); the stepper's own error is controlled by the tolerance and is not part
of it.  docs/accuracy.md §4 derives it and checks it against the work-precision data.

* **dynamic**: 0 (it is the reference model).
* **quasi-static**: the carriers' lag behind their equilibrium ζ*ω, which the quasi-static level
  drops.  With τ the *slowest* carrier's linearised time constant at the operating point
  (:func:`carrier_time_constants`, carriers at equilibrium; τ ∝ ω/F: for Li et al. (2021) at 100 rad/s
  and 5 kN 14.3 µs for carrier 1 — ``model.fastest_time_constant`` — and 31.5 µs for carrier 2):

  - a deviation d₀ = |ω_P/ω − ζ*|/ζ* present at the start shows undamped at the first output
    (the carriers at rest under a turning screw: d₀ = 1);
  - a step Δω of a prescribed screw speed (speed drive) later in the run shows at the next
    communication point damped to (Δω/ω)·exp(−h/τ);
  - in steady acceleration α the carriers trail their equilibrium by ζ*·α·τ, relative to the
    carrier speed ζ*ω: |α|·τ/|ω| (= |α|·c/F: independent of the speed, large when the axial
    force, and with it the friction that drives the carriers, is small).  τ is evaluated at the
    effective axial force F + m·c_out·α (the load plus the last nut's inertia, into which an
    actuator lumps its load mass): while a loop decelerates a mass against a spring that force
    passes through zero and the carriers are not driven at all.

  E_qs = max of the three.
* **kinematic**: E_qs plus what the kinematic level leaves out on top: the friction loss
  |η/η₀ − 1| (η the quasi-static level's steady forward efficiency, independent of speed and load
  outside the friction band; η₀ the kinematic level's constant efficiency, 1 by default: then
  it is 1 − η ≈ 0.2 for Li et al. (2021)), the pure-rolling carrier ratio's offset from ζ*,
  max_k |ζ_ideal,k/ζ*_k − 1|, and its friction outputs (:func:`friction_output_gap`: no spline
  friction at all, so 1 for a mechanism with spline friction such as Li et al.'s (2021) two stages —
  over the FMU's outputs the kinematic level is then never within a tolerance below 1).

The communication step h enters only through the damping of input jumps; when it is not known
(the FMU chooses at initialization, before the first step) it is taken as 0 (no damping: the
conservative side).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..mechanics import Mechanism
from ..params import MechanismParams

#: the levels, cheapest first
COST_ORDER = ("kinematic", "quasi-static", "dynamic")

#: the choice accepts a level when its estimated error times this margin is within the tolerance
#: (the estimate is a linearisation: on the loop scenes it came within 25 % of the measured
#: error, docs/accuracy.md §4)
MARGIN = 2.0

#: operating point at which the steady efficiency is evaluated when the run's own point has no
#: load or speed (outside the friction band the Coulomb efficiency depends on neither)
_EFFICIENCY_POINT = (100.0, 1000.0)      # screw speed [rad/s], load [N]


@dataclass(frozen=True)
class AutoChoice:
    """What ``fidelity = "auto"`` chose and why.

    Attributes
    ----------
    fidelity : str
        The chosen level.
    errors : dict
        Estimated model error per level (docs/accuracy.md §1 measure).
    terms : dict
        The estimate's terms: ``start_deviation``, ``speed_jump``, ``lag``, ``friction_loss``,
        ``carrier_ratio``, ``friction_outputs``.
    tau : float
        Slowest carrier time constant at the (start) operating point [s] (inf if undriven).
    efficiency : float
        Steady forward efficiency of the quasi-static level [-].
    tolerance : float
        The tolerance the estimate was held against.
    comm_step : float or None
        The communication step used for the damping of input jumps [s].
    """

    fidelity: str
    errors: dict = field(default_factory=dict)
    terms: dict = field(default_factory=dict)
    tau: float = math.inf
    efficiency: float = math.nan
    tolerance: float = math.nan
    comm_step: float | None = None

    def describe(self) -> str:
        """One line: the choice and the estimated errors."""
        est = ", ".join(f"{k} {v:.2g}" for k, v in self.errors.items())
        return (f"{self.fidelity!r} (estimated model errors: {est}; tolerance {self.tolerance:g}; "
                f"slowest carrier time constant {self.tau:.3g} s)")


def carrier_time_constant(params: MechanismParams, screw_speed: float, load_force: float) -> float:
    """Fastest linearised carrier time constant [s] with the carriers at their equilibrium."""
    mech = Mechanism(params, "dynamic")
    wp = [s.zeta_geometric * screw_speed for s in mech.stages]
    return mech.fastest_time_constant(float(screw_speed), wp, float(load_force))


def carrier_time_constants(params: MechanismParams, screw_speed: float,
                           load_force: float) -> list[float]:
    """Each carrier's linearised time constant −1/(∂ω̇_Pk/∂ω_Pk) [s] with the carriers at their
    equilibrium and the screw speed held (inf where the carrier is not driven).

    A central difference of the dynamic level's right-hand side (speed drive); the smallest of
    them is :func:`carrier_time_constant`'s closed form.  The slower carriers lag the most.
    """
    model = _dynamic_speed_model(params)
    omega, load = float(screw_speed), float(load_force)
    u = (0.0, load)
    x = model.initial_state(u, screw_speed=omega, carrier_ratio=None)
    v_eps = params.slip_velocity_scale
    taus = []
    for k, s in enumerate(model.mechanism.stages):
        i = 2 + k
        fl = s.flanks[0]
        # a thousandth of the carrier speed change that moves the slip across the friction band
        # (|b| as sqrt(bx² + by²): IEEE operations only, which C repeats bit for bit, as the
        # engine's auto must (fmu_build/native/prsm_auto.c); libm's hypot and Python's
        # math.hypot differ in the last bit in ~1 of 700 cases)
        dw = max(1e-3 * v_eps / math.sqrt(fl.bx * fl.bx + fl.by * fl.by),
                 1e-9 * max(abs(x[i]), 1.0))
        xp, xm = list(x), list(x)
        xp[i] += dw
        xm[i] -= dw
        rate = -(model.rhs(0.0, xp, u)[i] - model.rhs(0.0, xm, u)[i]) / (2.0 * dw)
        taus.append(1.0 / rate if rate > 0.0 else math.inf)
    return taus


_MODELS: dict = {}


def _dynamic_speed_model(params: MechanismParams):
    from .dynamic import DynamicModel

    key = id(params)
    hit = _MODELS.get(key)
    if hit is None or hit[0] is not params:
        if len(_MODELS) > 16:
            _MODELS.clear()
        hit = _MODELS[key] = (params, DynamicModel(params, "speed"))
    return hit[1]


def effective_load(params: MechanismParams, load_force: float, acceleration: float) -> float:
    """Axial force that presses the threads [N]: the load plus the inertia of the last nut
    (and of whatever mass is lumped into it, e.g. the actuator's load), m·c_out·α."""
    c_out = params.total_lead / (2.0 * math.pi)
    return float(load_force) + params.stages[-1].nut_mass * c_out * float(acceleration)


def estimate_along(params: MechanismParams, tolerance: float, screw_speed, acceleration,
                   load_force, *, comm_step: float, start_deviation: float = 0.0,
                   kinematic_efficiency: float = 1.0) -> AutoChoice:
    """:func:`choose_fidelity` for a run whose operating point moves (an actuator loop).

    The lag term is integrated along a trajectory sampled every communication step h (a run of
    the quasi-static level, or a planned motion): each carrier's linearised lag d = ω_P/ζ* − ω
    obeys d' = −α − d/τ (τ that carrier's time constant, :func:`carrier_time_constants`), so over a step with α and τ held

        d ← d·exp(−h/τ) − α·τ·(1 − exp(−h/τ))      (d ← d − α·h where τ = ∞),

    which tends to the steady lag α·τ when τ ≪ h and grows as ∫α dt while the carriers are not
    driven (τ → ∞, the axial force passing through zero).  The lag term is max |d| / max |ω|
    (relative to the largest carrier speed, the error measure's scale); τ at (ω, effective axial
    force).  The other terms as in :func:`estimate_errors` (at the trajectory's start).

    Parameters
    ----------
    screw_speed, acceleration, load_force : sequences of float
        The trajectory at t_k = t_0 + k·h [rad/s], [rad/s²], [N].
    comm_step : float
        h [s].
    """
    w = [float(v) for v in screw_speed]
    a = [float(v) for v in acceleration]
    f = [float(v) for v in load_force]
    h = float(comm_step)
    w_max = max(abs(v) for v in w)
    n = params.n_stages
    d = [0.0] * n
    d_max = 0.0
    for wi, ai, fi in zip(w, a, f):
        taus = carrier_time_constants(params, wi, effective_load(params, fi, ai))
        for k, tau in enumerate(taus):
            if math.isfinite(tau) and tau > 0.0:
                e = math.exp(-h / tau)
                d[k] = d[k] * e - ai * tau * (1.0 - e)
            else:
                d[k] -= ai * h
            d_max = max(d_max, abs(d[k]))
    lag = d_max / w_max if w_max > 0.0 else (0.0 if d_max == 0.0 else math.inf)
    start = choose_fidelity(params, tolerance, screw_speed=w[0], load_force=f[0],
                            comm_step=comm_step, start_deviation=start_deviation,
                            kinematic_efficiency=kinematic_efficiency)
    terms = dict(start.terms, lag=lag)
    e_qs = max(terms["start_deviation"], terms["speed_jump"], lag)
    errors = {"kinematic": max(e_qs, terms["friction_loss"], terms["carrier_ratio"],
                               terms["friction_outputs"]),
              "quasi-static": e_qs, "dynamic": 0.0}
    level = _pick(errors, tolerance)
    return AutoChoice(level, errors, terms, start.tau, start.efficiency, float(tolerance),
                      comm_step)


def _steady_outputs(params: MechanismParams) -> dict:
    """The quasi-static level's outputs in steady forward motion, outside the friction band."""
    from .quasi_static import QuasiStaticModel

    model = QuasiStaticModel(params, "speed")
    omega, load = _EFFICIENCY_POINT
    u = (0.0, load)
    return model.outputs(0.0, model.initial_state(u, screw_speed=omega), u)


def steady_efficiency(params: MechanismParams) -> float:
    """Forward efficiency of the quasi-static level in steady motion, outside the friction band."""
    return _steady_outputs(params)["efficiency"]


def friction_output_gap(params: MechanismParams, kinematic_efficiency: float = 1.0) -> float:
    """Relative error of the kinematic level's friction outputs [-].

    The kinematic level has no friction forces: its spline friction is 0 (error 1 wherever the
    mechanism has spline friction), and its friction power is (1 − η₀)·P_in against the
    quasi-static level's (1 − η)·P_in, a relative error |η − η₀| / (1 − η).
    """
    y = _steady_outputs(params)
    eta = y["efficiency"]
    spline = any(y[f"stage[{k}].spline_friction"] != 0.0 for k in range(1, params.n_stages + 1))
    power = abs(eta - float(kinematic_efficiency)) / (1.0 - eta) if eta < 1.0 else 0.0
    return max(1.0 if spline else 0.0, power)


def estimate_errors(params: MechanismParams, *, screw_speed: float, load_force: float,
                    acceleration: float = 0.0, comm_step: float | None = None,
                    start_deviation: float = 0.0, speed_jump: float = 0.0,
                    kinematic_efficiency: float = 1.0) -> AutoChoice:
    """Estimated model error of each level at an operating point (module docstring).

    Parameters
    ----------
    params : MechanismParams
    screw_speed : float
        Screw speed at the operating point [rad/s].
    load_force : float
        Load force at the operating point [N].
    acceleration : float
        Screw acceleration at the operating point [rad/s²] (the largest expected).
    comm_step : float, optional
        Communication step [s]; None: unknown (no damping of input jumps).
    start_deviation : float
        |ω_P/ω − ζ*|/ζ* of the carriers at the start [-] (0 at equilibrium, 1 at rest).
    speed_jump : float
        Largest step of a prescribed screw speed during the run, relative to the speed [-].
    kinematic_efficiency : float
        The kinematic level's constant efficiency η₀ [-].

    Returns
    -------
    AutoChoice
        With ``fidelity`` empty (see :func:`choose_fidelity`).
    """
    omega, load, alpha = float(screw_speed), float(load_force), float(acceleration)
    tau = max(carrier_time_constants(params, omega, effective_load(params, load, alpha)))
    h = 0.0 if comm_step is None else float(comm_step)
    jump = speed_jump * (math.exp(-h / tau) if math.isfinite(tau) and tau > 0.0 else 1.0)
    if alpha == 0.0:
        lag = 0.0
    elif omega == 0.0 or not math.isfinite(tau):
        lag = math.inf
    else:
        lag = abs(alpha) * tau / abs(omega)
    e_qs = max(float(start_deviation), jump, lag)
    eta = steady_efficiency(params)
    loss = abs(eta / float(kinematic_efficiency) - 1.0)
    mech = Mechanism(params, "dynamic")
    ratio = max(abs(s.zeta_ideal / s.zeta_geometric - 1.0) for s in mech.stages)
    gap = friction_output_gap(params, kinematic_efficiency)
    errors = {"kinematic": max(e_qs, loss, ratio, gap), "quasi-static": e_qs, "dynamic": 0.0}
    terms = {"start_deviation": float(start_deviation), "speed_jump": jump, "lag": lag,
             "friction_loss": loss, "carrier_ratio": ratio, "friction_outputs": gap}
    return AutoChoice("", errors, terms, tau, eta, math.nan, comm_step)


def _pick(errors: dict, tolerance: float) -> str:
    """The cheapest level with MARGIN × estimated error ≤ tolerance."""
    return next(lv for lv in COST_ORDER if MARGIN * errors[lv] <= tolerance)


def choose_fidelity(params: MechanismParams, tolerance: float, **operating_point) -> AutoChoice:
    """The cheapest level whose estimated model error is within ``tolerance`` (with the
    safety factor :data:`MARGIN`).

    Parameters
    ----------
    params : MechanismParams
    tolerance : float
        Accepted error [-] (> 0).
    **operating_point
        Keywords of :func:`estimate_errors`.

    Returns
    -------
    AutoChoice
    """
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0.0):
        raise ValueError(f"tolerance = {tolerance!r} is out of range: must be a finite number > 0")
    est = estimate_errors(params, **operating_point)
    level = _pick(est.errors, tolerance)
    return AutoChoice(level, est.errors, est.terms, est.tau, est.efficiency, float(tolerance),
                      est.comm_step)


def choose_for_start(params: MechanismParams, tolerance: float, drive: str, inputs: tuple, *,
                     screw_speed: float = 0.0, carrier_ratio: float | None = 0.0,
                     comm_step: float | None = None, kinematic_efficiency: float = 1.0,
                     acceleration: float | None = None) -> AutoChoice:
    """:func:`choose_fidelity` at the start of a run (what simulate and the FMU use).

    The operating point is the start: screw speed ``screw_speed``, load ``inputs[1]``; the
    acceleration, unless given, is the quasi-static level's under the start inputs (torque
    drive) or the prescribed one, ``inputs[0]`` (speed drive); the start deviation is the
    carriers' (``carrier_ratio`` None: at equilibrium) if the screw turns.

    Parameters
    ----------
    params : MechanismParams
    tolerance : float
    drive : {"torque", "speed"}
    inputs : tuple
        Inputs at the start (drive input, load force).
    screw_speed : float
        Screw speed at the start [rad/s].
    carrier_ratio : float or None
        Carrier speeds at the start as a fraction of the screw speed (None: equilibrium).
    comm_step : float, optional
        Communication step [s] (None: unknown).
    kinematic_efficiency : float
    acceleration : float, optional
        Largest expected screw acceleration [rad/s²] (default: at the start, see above).
    """
    from .quasi_static import QuasiStaticModel

    load = float(inputs[1])
    omega = float(screw_speed)
    if acceleration is None:
        if drive == "torque":
            qs = QuasiStaticModel(params, "torque")
            u = (float(inputs[0]), load)
            acceleration = qs.outputs(0.0, qs.initial_state(u, screw_speed=omega), u)[
                "screw_acceleration"]
        else:
            acceleration = float(inputs[0])
    deviation = 0.0
    if omega != 0.0 and carrier_ratio is not None:
        mech = Mechanism(params, "dynamic")
        deviation = max(abs(float(carrier_ratio) / s.zeta_geometric - 1.0) for s in mech.stages)
    return choose_fidelity(params, tolerance, screw_speed=omega, load_force=load,
                           acceleration=acceleration, comm_step=comm_step,
                           start_deviation=deviation, kinematic_efficiency=kinematic_efficiency)


__all__ = ["AutoChoice", "COST_ORDER", "MARGIN", "carrier_time_constant", "carrier_time_constants",
           "steady_efficiency", "friction_output_gap",
           "effective_load", "estimate_along",
           "estimate_errors", "choose_fidelity", "choose_for_start"]
