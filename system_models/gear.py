"""Gear reduction between the motor and the screw: ratio, mesh losses, backlash, compliance.

Laws (pure functions, each tested against its closed form in tests/test_actuator_blocks.py):

* **Mesh losses** (:func:`mesh_loss`), the law of MSL 4.1
  ``Modelica.Mechanics.Rotational.Components.LossyGear``: with τ_a the torque the input side
  puts into the mesh and ω_a the input speed, the loss torque (input side) is

  ==================================  ===========================  ===============================
  case                                loss τ_loss                   the output receives N (τ_a − τ_loss)
  ==================================  ===========================  ===============================
  ω_a > 0, τ_a ≥ 0 (input drives)     (1 − η_f) τ_a + τ_bf          N (η_f τ_a − τ_bf)
  ω_a > 0, τ_a < 0 (output drives)    (1 − 1/η_b) τ_a + τ_bf        N (τ_a/η_b − τ_bf)
  ω_a < 0, τ_a ≥ 0 (output drives)    (1 − 1/η_b) τ_a − τ_bf        N (τ_a/η_b + τ_bf)
  ω_a < 0, τ_a < 0 (input drives)     (1 − η_f) τ_a − τ_bf          N (η_f τ_a + τ_bf)
  ==================================  ===========================  ===============================

  η_f, η_b: mesh efficiencies with the input or the output driving; τ_bf: bearing friction
  torque (input side).  **Stuck mode**: at ω_a = 0 the gear holds any output torque between the
  ω → 0⁻ and ω → 0⁺ values (for τ_a > 0: between N (η_f τ_a − τ_bf) and N (τ_a/η_b + τ_bf)).
  It is regularised as Coulomb friction is elsewhere in the project: inside
  |ω_a| < ``stick_speed`` the loss moves linearly between the two limits, a stiff viscous band
  in which the gear creeps at most ``stick_speed``.
* **Backlash and compliance** (:func:`elasto_backlash_torque`), MSL ``ElastoBacklash``: no
  torque inside the dead zone |φ_rel| ≤ b/2; outside, c (φ_rel ∓ b/2) + d ω_rel, limited so the
  teeth only push (the damping cannot pull the flanks together).

The block :class:`RigidGear` couples a motor (input inertia J_m) to the PRSM's screw (the
output).  The motor's rotor is *lumped* into the PRSM (``stage[1].screw_inertia`` gains N² J_m;
docs/ema.md explains why two rigidly coupled inertias are not co-simulated), so the block sends
the PRSM the torque that makes the lumped body move as the geared one:
``screw_torque = N (T_m − τ_loss)``.  The loss depends on the torque through the mesh, found
from the light output side: the mesh gives the screw side τ_out = J_out α_s + c F (its own
inertia J_out, the screw's acceleration α_s from the PRSM, the load force F on the rod and the
lead per radian c), and τ_a follows from τ_out = N (τ_a − τ_loss(τ_a)) (:func:`mesh_input_torque`).
Check: the lumped body then obeys (J_out + N² J_m) α_s = N (T_m − τ_loss) − c F, which is the
geared pair's J_m α_m = T_m − τ_a, J_out α_s = τ_out − c F with α_m = N α_s.  The gear's compliance and backlash are resolved
quasi-statically on the output side, valid when the output side is light (its torsional mode
√(c/J_out) and its damping pole d/J_out far above the loop's bandwidth; in the MSL actuator
example 3e4 rad/s and 9e6 1/s against a 40 rad/s speed loop): the backlash is a play whose
flank follows the sign of the transmitted torque (the free traverse is instantaneous), and the
elastic deflection δ obeys c δ + d δ' = −τ_out, so the relative angle over the gear is
φ_rel = β + δ with β = ±b/2 (MSL's ``gearbox.phi_rel``, positive when the output leads).  The
motor angle the controller measures is N (θ_s − φ_rel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .blocks import Port, PythonBlock, StepRefused
from .filters import lag_step

__all__ = ["GearParams", "mesh_loss", "mesh_input_torque", "elasto_backlash_torque", "play",
           "RigidGear"]


@dataclass(frozen=True)
class GearParams:
    """Gear reduction data, SI units (module docstring for the laws).

    Attributes
    ----------
    ratio : float
        N = input angle / output angle [-], > 0.
    efficiency_forward : float
        η_f, the mesh efficiency when the input (motor) drives, in (0, 1].
    efficiency_backward : float
        η_b, the mesh efficiency when the output (load) drives, in (0, 1].
    bearing_torque : float
        τ_bf, bearing friction torque at the input [N·m], >= 0.
    backlash : float
        b, total backlash at the output [rad], >= 0.
    stiffness : float
        c, torsional stiffness at the output [N·m/rad], > 0 (``inf``: rigid).
    damping : float
        d, torsional damping at the output [N·m·s/rad], >= 0.
    stick_speed : float
        Input speed below which the stuck mode is regularised [rad/s], > 0.
    """

    ratio: float = 1.0
    efficiency_forward: float = 1.0
    efficiency_backward: float = 1.0
    bearing_torque: float = 0.0
    backlash: float = 0.0
    stiffness: float = math.inf
    damping: float = 0.0
    stick_speed: float = 1e-2

    def validate(self) -> "GearParams":
        """Check every field; ValueError naming the field, its value and the range."""
        def num(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool) and not math.isnan(v)

        checks = (("ratio", self.ratio, math.isfinite(self.ratio) and self.ratio > 0, "> 0"),
                  ("efficiency_forward", self.efficiency_forward,
                   0 < self.efficiency_forward <= 1, "in (0, 1]"),
                  ("efficiency_backward", self.efficiency_backward,
                   0 < self.efficiency_backward <= 1, "in (0, 1]"),
                  ("bearing_torque", self.bearing_torque,
                   math.isfinite(self.bearing_torque) and self.bearing_torque >= 0, ">= 0"),
                  ("backlash", self.backlash, math.isfinite(self.backlash) and self.backlash >= 0,
                   ">= 0"),
                  ("stiffness", self.stiffness, self.stiffness > 0, "> 0 (inf: rigid)"),
                  ("damping", self.damping, math.isfinite(self.damping) and self.damping >= 0,
                   ">= 0"),
                  ("stick_speed", self.stick_speed,
                   math.isfinite(self.stick_speed) and self.stick_speed > 0, "> 0"))
        for name, v, ok, rng in checks:
            if not (num(v) and ok):
                raise ValueError(f"gear.{name} = {v!r} is out of range: must be a number {rng}")
        return self


def _rolling_loss(tau_a: float, positive: bool, p: GearParams) -> float:
    """Loss torque when rolling forward (ω_a > 0) or backward (ω_a < 0)."""
    ef, eb, bf = p.efficiency_forward, p.efficiency_backward, p.bearing_torque
    if positive:
        return (1.0 - ef) * tau_a + bf if tau_a >= 0.0 else (1.0 - 1.0 / eb) * tau_a + bf
    return (1.0 - 1.0 / eb) * tau_a - bf if tau_a >= 0.0 else (1.0 - ef) * tau_a - bf


def mesh_loss(tau_a: float, w_a: float, p: GearParams) -> float:
    """Loss torque at the input [N·m] for mesh torque ``tau_a`` [N·m] and input speed ``w_a``
    [rad/s] (module docstring; stuck mode regularised over |w_a| < stick_speed)."""
    ws = p.stick_speed
    if w_a >= ws:
        return _rolling_loss(tau_a, True, p)
    if w_a <= -ws:
        return _rolling_loss(tau_a, False, p)
    lo, hi = _rolling_loss(tau_a, False, p), _rolling_loss(tau_a, True, p)
    return lo + (hi - lo) * (w_a + ws) / (2.0 * ws)


def mesh_input_torque(tau_t: float, w_a: float, p: GearParams) -> float:
    """The mesh torque τ_a [N·m] at the input that delivers ``tau_t`` [N·m] to the output side.

    Solves τ_a − τ_loss(τ_a, ω_a) = τ_t / N; the left side is piecewise linear and increasing in
    τ_a (slopes η_f, 1/η_b or their blend in the stuck band), with its kink at τ_a = 0, so the
    root is found branch by branch.
    """
    target = tau_t / p.ratio
    g0 = -mesh_loss(0.0, w_a, p)                 # value of the left side at τ_a = 0
    probe = 1.0 if target >= g0 else -1.0        # the branch the root lies on
    slope = ((probe - mesh_loss(probe, w_a, p)) - g0) / probe
    return (target - g0) / slope


def elasto_backlash_torque(phi_rel: float, w_rel: float, backlash: float, stiffness: float,
                           damping: float) -> float:
    """Torque [N·m] of an elastic gear mesh with backlash (MSL ``ElastoBacklash``).

    Zero inside the dead zone |φ_rel| ≤ b/2; outside, c (φ_rel − sign(φ_rel) b/2) + d ω_rel,
    limited to the sign of the deflection (the teeth push, never pull).
    """
    b2 = 0.5 * backlash
    if phi_rel > b2:
        return max(stiffness * (phi_rel - b2) + damping * w_rel, 0.0)
    if phi_rel < -b2:
        return min(stiffness * (phi_rel + b2) + damping * w_rel, 0.0)
    return 0.0


def play(side: float, output_torque: float, backlash: float) -> float:
    """The backlash flank β [rad] after the output torque ``output_torque`` [N·m] acts.

    A gear that drives the output forward (torque > 0) has the output lagging: β = −b/2; one
    that holds the output back (torque < 0) has it leading: β = +b/2; at zero torque the flank
    does not change (hysteresis: the dead zone's width b is crossed only when the torque
    reverses).
    """
    if output_torque > 0.0:
        return -0.5 * backlash
    if output_torque < 0.0:
        return 0.5 * backlash
    return side


class RigidGear(PythonBlock):
    """Gear between the motor and the screw with the rotor lumped into the PRSM (module docstring).

    Inputs: ``motor_torque`` [N.m] (the motor's electromagnetic torque), ``screw_angle`` [rad],
    ``screw_speed`` [rad/s], ``screw_acceleration`` [rad/s²] (the PRSM's outputs),
    ``load_force`` [N] (on the rod, positive resists extension).
    Outputs: ``screw_torque`` (to the PRSM), ``motor_angle``, ``motor_speed``,
    ``output_torque`` (what the mesh applies to the screw side), ``loss_torque``, ``phi_rel``,
    ``deflection``.  Feedthrough: the outputs follow the inputs at the same instant.

    Parameters
    ----------
    params : GearParams
    input_inertia : float
        J_m, inertia on the input shaft (the rotor) [kg·m²], lumped into the PRSM by the assembly.
    output_inertia : float
        J_out, the screw side's own inertia on the screw axis [kg·m²] (the PRSM without the rotor).
    lead_per_radian : float
        c, rod travel per screw radian [m/rad].
    initial_screw_angle : float
        θ_s(t0) [rad].
    initial_side : {-1, 0, 1}
        Initial flank: β(t0) = side·b/2 (0: centred).
    initial_deflection : float
        δ(t0) [rad].
    initial_motor_angle : float
        Motor angle at t0 [rad] (the offset of the motor's angle sensor).
    """

    inputs = (Port("motor_torque", "N.m", "motor electromagnetic torque on the input shaft"),
              Port("screw_angle", "rad", "screw angle (gear output)"),
              Port("screw_speed", "rad/s", "screw speed (gear output)"),
              Port("screw_acceleration", "rad/s2", "screw acceleration (gear output)"),
              Port("load_force", "N", "force on the rod, positive resists extension"))
    outputs = (Port("screw_torque", "N.m", "torque on the lumped screw + rotor: N (T_m − τ_loss)"),
               Port("motor_angle", "rad", "motor (input) angle N (θ_s − φ_rel) + offset"),
               Port("motor_speed", "rad/s", "motor (input) speed"),
               Port("output_torque", "N.m", "torque the mesh applies to the screw side"),
               Port("loss_torque", "N.m", "mesh and bearing loss torque (input side)"),
               Port("phi_rel", "rad", "angle over the gear's backlash and compliance (output side)"),
               Port("deflection", "rad", "elastic deflection δ (output side)"))
    interpolates_inputs = True
    feedthrough = True
    _state_attrs = ("beta", "delta")

    def __init__(self, params: GearParams, input_inertia: float, output_inertia: float,
                 lead_per_radian: float, name: str = "gear",
                 initial_screw_angle: float = 0.0, initial_side: int = 0,
                 initial_deflection: float = 0.0, initial_motor_angle: float = 0.0) -> None:
        self.params = params.validate()
        super().__init__(name)
        if not (math.isfinite(input_inertia) and input_inertia >= 0.0):
            raise ValueError(f"gear input_inertia = {input_inertia!r} kg·m² is out of range: must "
                             "be a finite number >= 0")
        if initial_side not in (-1, 0, 1):
            raise ValueError(f"gear.initial_side = {initial_side!r} is not allowed: must be -1, 0 or 1")
        self.jm, self.jout, self.c = float(input_inertia), float(output_inertia), float(lead_per_radian)
        self.beta = 0.5 * params.backlash * initial_side
        self.delta = float(initial_deflection) if math.isfinite(params.stiffness) else 0.0
        n = params.ratio
        self.offset = initial_motor_angle - n * (initial_screw_angle - self.beta - self.delta)
        self.u[1] = float(initial_screw_angle)

    def _torques(self, tm: float, ws: float, acc: float, force: float) -> tuple[float, float, float]:
        """(screw_torque, output_torque, loss) at motor torque, screw speed and acceleration,
        load force."""
        p = self.params
        n = p.ratio
        tout = self.jout * acc + self.c * force
        w_a = n * ws
        loss = mesh_loss(mesh_input_torque(tout, w_a, p), w_a, p)
        return n * (tm - loss), tout, loss

    def _deflection_rate(self, tout: float) -> float:
        p = self.params
        if not math.isfinite(p.stiffness) or p.damping == 0.0:
            return 0.0
        return (-tout - p.stiffness * self.delta) / p.damping

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        u, du = self.u, self.du
        if not all(math.isfinite(v) for v in u + du):
            raise StepRefused(self.name, t, h, f"non-finite input: {u}, slopes {du}")
        p = self.params
        if math.isfinite(p.stiffness):
            t0 = self._torques(u[0], u[2], u[3], u[4])[1]
            t1 = self._torques(u[0] + du[0] * h, u[2] + du[2] * h, u[3] + du[3] * h,
                               u[4] + du[4] * h)[1]
            if p.damping > 0.0:       # c δ + d δ' = −τ_out, τ_out linear over the step: exact
                self.delta = lag_step(self.delta, -t0 / p.stiffness, -(t1 - t0) / (p.stiffness * h),
                                      h, p.damping / p.stiffness)
            else:
                self.delta = -t1 / p.stiffness
            self.beta = play(self.beta, t1, p.backlash)

    def update_outputs(self, t: float) -> None:
        p = self.params
        tout = self._torques(self.u[0], self.u[2], self.u[3], self.u[4])[1]
        self.beta = play(self.beta, tout, p.backlash)
        if math.isfinite(p.stiffness) and p.damping == 0.0:
            self.delta = -tout / p.stiffness

    def get_outputs(self) -> list[float]:
        n = self.params.ratio
        tm, th, ws, acc, force = self.u
        ts, tout, loss = self._torques(tm, ws, acc, force)
        phi = self.beta + self.delta
        return [ts, n * (th - phi) + self.offset, n * (ws - self._deflection_rate(tout)), tout,
                loss, phi, self.delta]
