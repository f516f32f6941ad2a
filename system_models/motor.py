"""The motor: a surface-mounted permanent-magnet synchronous machine in the rotor (dq) frame.

Model (amplitude-invariant Park transform, L_d = L_q = L, rotor speed ω [rad/s] from the screw,
electrical speed ω_e = p ω, magnet flux linkage ψ = k_t / (1.5 p))::

    L di_d/dt = v_d − R i_d + ω_e L i_q
    L di_q/dt = v_q − R i_q − ω_e L i_d − ω_e ψ
    T_e       = 1.5 p ψ i_q = k_t i_q                      (no reluctance torque: L_d = L_q)

Power, with P = 1.5 (v_d i_d + v_q i_q) the electrical input of the three phases::

    P = 1.5 R (i_d² + i_q²)  +  d/dt [0.75 L (i_d² + i_q²)]  +  T_e ω
        copper losses           magnetic energy                 air-gap power

The cross-coupling terms ±ω_e L i_d i_q cancel, so the identity holds pointwise.  The block
integrates the currents and the three energy integrals (electrical input, copper losses,
air-gap work) together with RK4 on substeps of at most ``max_substep`` (the electrical time
constant L/R is 4 ms and ω_e ≤ 600 rad/s, so 20 µs substeps keep the RK4 error ≈ 1e-12).

The rotor's inertia is *not* a state of this block: the rotor is rigidly coupled to screw 1,
so the assembly adds it to the screw's inertia inside the PRSM (``stage[1].screw_inertia``),
which integrates the common speed (docs/ema.md, "Coupling").  The speed input is the screw speed.

The inverter cannot apply more than ``voltage_limit`` (the space-vector PWM linear range
V_dc/√3): a larger command is scaled onto that circle.  A current above
``trip_factor · current_limit`` trips the drive: the step is refused with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .blocks import Port, PythonBlock, StepRefused

__all__ = ["MotorParams", "Motor"]


@dataclass(frozen=True)
class MotorParams:
    """Electrical and mechanical data of the PMSM, SI units.

    Representative values chosen for this actuator, not one manufacturer's datasheet; each
    with its reason:

    * ``pole_pairs = 4``: common for servo PMSMs of this size (8 poles).
    * ``torque_constant = 1.5`` N·m/A (peak phase current, i_d = 0): with the 20 A current limit
      the peak torque is 30 N·m, enough to drive the seed 000 screw (20 mm per revolution,
      efficiency ≈ 0.8) against ≈ 7.5 kN, or to accelerate the reflected inertia at 2e4 rad/s².
      ψ = k_t/(1.5 p) = 0.25 Wb, so the back-EMF is 1.0 V per rad/s (phase peak).
    * ``resistance = 0.5`` Ω, ``inductance = 2e-3`` H (per phase): electrical time constant
      L/R = 4 ms, typical of servo motors of this torque class (1–10 ms); copper loss at the
      20 A limit 1.5 R I² = 300 W.
    * ``rotor_inertia = 3e-4`` kg·m²: ≈ 0.66× the PRSM's own reflected inertia (4.54e-4 kg·m²);
      reflected to the rod (÷ (Σ L/2π)² = 1.01e-5 m²) it is 30 kg.
    * ``bus_voltage = 270`` V: the aircraft high-voltage DC bus (MIL-STD-704); the phase
      voltage limit is V_dc/√3 = 156 V (space-vector PWM, linear range), so the no-load
      speed is 156 rad/s (rod 0.50 m/s).
    * ``current_limit = 20`` A: the peak rating the controller respects; the drive trips at
      ``trip_factor`` (1.5) times it.
    """

    pole_pairs: int = 4
    resistance: float = 0.5
    inductance: float = 2.0e-3
    torque_constant: float = 1.5
    rotor_inertia: float = 3.0e-4
    bus_voltage: float = 270.0
    current_limit: float = 20.0
    trip_factor: float = 1.5

    @property
    def flux_linkage(self) -> float:
        """Magnet flux linkage ψ = k_t / (1.5 p) [Wb]."""
        return self.torque_constant / (1.5 * self.pole_pairs)

    @property
    def voltage_limit(self) -> float:
        """Largest phase-voltage amplitude V_dc/√3 [V] (space-vector PWM, linear range)."""
        return self.bus_voltage / math.sqrt(3.0)

    @property
    def no_load_speed(self) -> float:
        """Speed at which the back-EMF equals the voltage limit [rad/s]."""
        return self.voltage_limit / (self.pole_pairs * self.flux_linkage)

    def validate(self) -> "MotorParams":
        """Check every field; ValueError naming the field, its value and the range."""
        if not (isinstance(self.pole_pairs, int) and self.pole_pairs >= 1):
            raise ValueError(f"motor.pole_pairs = {self.pole_pairs!r} is out of range: must be an "
                             "integer >= 1")
        for f in ("resistance", "inductance", "torque_constant", "rotor_inertia", "bus_voltage",
                  "current_limit"):
            v = getattr(self, f)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
                raise ValueError(f"motor.{f} = {v!r} is out of range: must be a finite number > 0")
        if not (math.isfinite(self.trip_factor) and self.trip_factor >= 1.0):
            raise ValueError(f"motor.trip_factor = {self.trip_factor!r} is out of range: must be "
                             ">= 1")
        return self

    def steady_voltages(self, speed: float, i_q: float, i_d: float = 0.0) -> tuple[float, float]:
        """(v_d, v_q) [V] that hold the currents constant at a constant speed [rad/s]."""
        we = self.pole_pairs * speed
        return (self.resistance * i_d - we * self.inductance * i_q,
                self.resistance * i_q + we * (self.inductance * i_d + self.flux_linkage))


class Motor(PythonBlock):
    """The PMSM as a co-simulation block (module docstring).

    Inputs: ``v_d``, ``v_q`` [V] (the controller's commands, discrete), ``speed`` [rad/s] (the
    screw speed; first-order extrapolation is used if the master gives a slope).
    Outputs: currents, torque, the powers at the communication point and the energies since
    the start.
    """

    inputs = (Port("v_d", "V", "d-axis voltage command", discrete=True),
              Port("v_q", "V", "q-axis voltage command", discrete=True),
              Port("speed", "rad/s", "rotor (= screw 1) speed"))
    outputs = (Port("i_d", "A", "d-axis current"),
               Port("i_q", "A", "q-axis (torque) current"),
               Port("current", "A", "current amplitude sqrt(i_d² + i_q²)"),
               Port("torque", "N.m", "electromagnetic torque k_t i_q on screw 1"),
               Port("v_d", "V", "d-axis voltage applied by the inverter"),
               Port("v_q", "V", "q-axis voltage applied by the inverter"),
               Port("electrical_power", "W", "electrical input 1.5 (v_d i_d + v_q i_q)"),
               Port("copper_power", "W", "copper losses 1.5 R (i_d² + i_q²)"),
               Port("electrical_energy", "J", "electrical energy input since the start"),
               Port("copper_energy", "J", "copper losses since the start"),
               Port("airgap_energy", "J", "air-gap work ∫ T_e ω dt since the start (motor's view of ω)"),
               Port("magnetic_energy", "J", "energy stored in the inductances 0.75 L (i_d² + i_q²)"))
    interpolates_inputs = True
    _state_attrs = ("x",)

    def __init__(self, params: MotorParams = MotorParams(), name: str = "motor",
                 i_d: float = 0.0, i_q: float = 0.0, max_substep: float = 2e-5) -> None:
        self.params = params.validate()
        super().__init__(name)
        if not (math.isfinite(max_substep) and max_substep > 0.0):
            raise ValueError(f"max_substep = {max_substep!r} is out of range: must be > 0")
        self.max_substep = max_substep
        #: state: i_d, i_q [A], electrical, copper and air-gap energy [J]
        self.x = [float(i_d), float(i_q), 0.0, 0.0, 0.0]
        p = params
        self._c = (p.resistance, p.inductance, p.pole_pairs, p.flux_linkage, p.torque_constant)

    def _applied(self) -> tuple[float, float]:
        """The voltages the inverter applies: the command, scaled onto the limit circle."""
        vd, vq = self.u[0], self.u[1]
        vmax = self.params.voltage_limit
        mag = math.hypot(vd, vq)
        if mag > vmax:
            s = vmax / mag
            return vd * s, vq * s
        return vd, vq

    def _rhs(self, x, vd, vq, w):
        r, ell, p, psi, kt = self._c
        idd, iq = x[0], x[1]
        we = p * w
        did = (vd - r * idd + we * ell * iq) / ell
        diq = (vq - r * iq - we * ell * idd - we * psi) / ell
        return (did, diq, 1.5 * (vd * idd + vq * iq), 1.5 * r * (idd * idd + iq * iq), kt * iq * w)

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        if not all(math.isfinite(v) for v in self.u + self.du):
            raise StepRefused(self.name, t, h, f"non-finite input: u = {self.u}, slopes = {self.du}")
        vd, vq = self._applied()
        w0, dw = self.u[2], self.du[2]
        n = max(1, math.ceil(h / self.max_substep - 1e-9))
        dt = h / n
        x = list(self.x)
        f = self._rhs
        for j in range(n):
            tau = j * dt
            wa, wm, wb = w0 + dw * tau, w0 + dw * (tau + 0.5 * dt), w0 + dw * (tau + dt)
            k1 = f(x, vd, vq, wa)
            k2 = f([a + 0.5 * dt * b for a, b in zip(x, k1)], vd, vq, wm)
            k3 = f([a + 0.5 * dt * b for a, b in zip(x, k2)], vd, vq, wm)
            k4 = f([a + dt * b for a, b in zip(x, k3)], vd, vq, wb)
            x = [a + dt / 6.0 * (b + 2.0 * c + 2.0 * d + e)
                 for a, b, c, d, e in zip(x, k1, k2, k3, k4)]
        if not all(math.isfinite(v) for v in x):
            raise StepRefused(self.name, t, h, f"the motor state became non-finite: {x}")
        trip = self.params.trip_factor * self.params.current_limit
        mag = math.hypot(x[0], x[1])
        if mag > trip:
            raise StepRefused(self.name, t, h, f"overcurrent: |i| = {mag:.4g} A exceeds the trip "
                              f"level {trip:.4g} A (trip_factor x current_limit): the drive trips")
        self.x = x

    def get_outputs(self) -> list[float]:
        idd, iq, e_el, e_cu, e_ag = self.x
        vd, vq = self._applied()
        r, ell, _, _, kt = self._c
        i2 = idd * idd + iq * iq
        return [idd, iq, math.sqrt(i2), kt * iq, vd, vq, 1.5 * (vd * idd + vq * iq), 1.5 * r * i2,
                e_el, e_cu, e_ag, 0.75 * ell * i2]
