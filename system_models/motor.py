"""The motor: a surface-mounted permanent-magnet synchronous machine in the rotor (dq) frame.

Model (amplitude-invariant Park transform, L_d = L_q = L, rotor speed ω [rad/s] from the screw,
electrical speed ω_e = p ω, magnet flux linkage ψ = k_t / (1.5 p))::

    L di_d/dt = v_d − R i_d + ω_e L i_q
    L di_q/dt = v_q − R i_q − ω_e L i_d − ω_e ψ
    T_e       = 1.5 p ψ i_q = k_t i_q                      (no reluctance torque: L_d = L_q)

Power, with P = 1.5 (v_d i_d + v_q i_q) the electrical input of the three phases::

    P = 1.5 R (i_d² + i_q²)  +  d/dt [0.75 L (i_d² + i_q²)]  +  T_e ω
        copper losses           magnetic energy                 air-gap power

The cross-coupling terms ±ω_e L i_d i_q cancel, so the identity holds pointwise.

Time stepping (``integrator``).  In the complex current I = i_d + j i_q the electrical part is
one linear equation, ``dI/dt = −a I + c`` with ``a = R/L + j ω_e`` and
``c = (v − j ω_e ψ)/L`` (v = v_d + j v_q): linear and time-invariant while the voltages and the
speed are held.  ``"exponential"`` steps it exactly under held values (zero-order
hold): I(τ) = I_∞ + (I_0 − I_∞) e^{−a τ}, I_∞ = c/a, and the three energy integrals
(electrical input, copper losses, air-gap work) are the closed-form integrals of that
trajectory, so the block's own energy balance closes to rounding.  The voltages are held over a
step (discrete commands); the speed is not when the master gives it a slope: then the step is
cut into substeps of at most ``max_substep``, each with the speed held at the substep's
midpoint (the rotation and the back-EMF integrated exactly for that speed; the error of holding
it is of second order in the substep, ∝ p (dω/dt) τ³ |v + R ψ/L| / (12 L) per substep).
With a held speed a step is exact whatever its length.  ``"rk4"`` (the default) integrates
the currents with the speed varying linearly and the energies together with classic RK4 on
substeps of at most ``max_substep`` (the electrical time constant L/R is 4 ms and
ω_e ≤ 600 rad/s, so 20 µs substeps keep its error ≈ 1e-12).  In the actuator loop the master
gives the speed a slope, so the exponential step holds it piecewise: against a scipy reference
of the same loop (benchmarks/loop_cost.py) one RK4 step is within 6.5e-9 of max|i_d| and the
exponential one 4.1e-4; over the position step the loops differ from the reference by 8.5e-9
and 7.7e-4 (motor.i_d), and the exponential step is not cheaper there (five substeps either way).

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

_isfinite = math.isfinite

__all__ = ["MotorParams", "Motor"]


@dataclass(frozen=True)
class MotorParams:
    """Electrical and mechanical data of the PMSM, SI units.

    Representative values chosen for this actuator, not one manufacturer's datasheet; each
    with its reason:

    * ``pole_pairs = 4``: common for servo PMSMs of this size (8 poles).
    * ``torque_constant = 1.5`` N·m/A (peak phase current, i_d = 0): with the 20 A current limit
      the peak torque is 30 N·m, enough to drive the Li et al. (2021) screw (20 mm per revolution,
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

    #: accepted values of ``integrator`` (module docstring)
    INTEGRATORS = ("rk4", "exponential")

    def __init__(self, params: MotorParams = MotorParams(), name: str = "motor",
                 i_d: float = 0.0, i_q: float = 0.0, max_substep: float = 2e-5,
                 integrator: str = "rk4") -> None:
        self.params = params.validate()
        super().__init__(name)
        if not (math.isfinite(max_substep) and max_substep > 0.0):
            raise ValueError(f"max_substep = {max_substep!r} is out of range: must be > 0")
        if integrator not in self.INTEGRATORS:
            raise ValueError(f"integrator = {integrator!r} is not allowed: must be one of "
                             f"{', '.join(self.INTEGRATORS)}")
        self.max_substep = max_substep
        self.integrator = integrator
        #: state: i_d, i_q [A], electrical, copper and air-gap energy [J]
        self.x = [float(i_d), float(i_q), 0.0, 0.0, 0.0]
        p = params
        # the pole pairs as a float: p·ω is then a float product (the same value as int · float)
        self._c = (p.resistance, p.inductance, float(p.pole_pairs), p.flux_linkage,
                   p.torque_constant)
        self._alpha = p.resistance / p.inductance          # 1/(electrical time constant) [1/s]
        self._vmax = p.voltage_limit
        self._trip = p.trip_factor * p.current_limit

    def _applied(self) -> tuple[float, float]:
        """The voltages the inverter applies: the command, scaled onto the limit circle."""
        vd, vq = self.u[0], self.u[1]
        vmax = self._vmax
        mag = math.sqrt(vd * vd + vq * vq)      # (not hypot: C's and Python's round apart)
        if mag > vmax:
            s = vmax / mag
            return vd * s, vq * s
        return vd, vq

    def _exponential(self, x: list[float], vd: float, vq: float, w: float,
                     dt: float) -> list[float]:
        """State after ``dt`` [s] with the voltages [V] and the speed ``w`` [rad/s] held: the
        exact solution of the current equation and the closed-form energy integrals."""
        r, ell, p, psi, kt = self._c
        alpha = self._alpha
        we = p * w
        a = complex(alpha, we)
        i_inf = complex(vd, vq - we * psi) / (ell * a)      # I_∞ = c/a
        d = complex(x[0], x[1]) - i_inf                       # I_0 − I_∞
        em = math.expm1(-alpha * dt)                          # e^{−α dt} − 1
        th = we * dt
        cs, sn = math.cos(th), math.sin(th)
        e = em + 1.0
        s2 = math.sin(0.5 * th)
        # 1 − e^{−a dt} without cancellation for small a dt
        one_minus = complex(2.0 * s2 * s2 - em * cs, e * sn)
        i1 = i_inf + d * complex(e * cs, -e * sn)             # I(dt)
        q = d * one_minus / a                                 # ∫ (I − I_∞) dτ
        s1 = i_inf * dt + q                                   # ∫ I dτ
        # ∫ |I|² dτ = |I_∞|² dt + 2 Re(conj(I_∞) q) + |d|² (1 − e^{−2α dt}) / (2α)
        s_sq = ((i_inf.real * i_inf.real + i_inf.imag * i_inf.imag) * dt
                + 2.0 * (i_inf.real * q.real + i_inf.imag * q.imag)
                - (d.real * d.real + d.imag * d.imag) * math.expm1(-2.0 * alpha * dt) / (2.0 * alpha))
        return [i1.real, i1.imag, x[2] + 1.5 * (vd * s1.real + vq * s1.imag),
                x[3] + 1.5 * r * s_sq, x[4] + kt * w * s1.imag]

    def do_step(self, t: float, h: float) -> None:
        u, du = self.u, self.du
        finite = _isfinite
        if not (finite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        if not (finite(u[0]) and finite(u[1]) and finite(u[2])
                and finite(du[0]) and finite(du[1]) and finite(du[2])):
            raise StepRefused(self.name, t, h, f"non-finite input: u = {u}, slopes = {du}")
        vd, vq = self._applied()
        w0, dw = u[2], du[2]
        x = self.x
        if self.integrator == "exponential":
            if dw == 0.0:
                x = self._exponential(x, vd, vq, w0, h)
            else:
                n = max(1, math.ceil(h / self.max_substep - 1e-9))
                dt = h / n
                for j in range(n):
                    x = self._exponential(x, vd, vq, w0 + dw * ((j + 0.5) * dt), dt)
        else:
            x = self._rk4(x, vd, vq, w0, dw, h)
        if not all(map(finite, x)):
            raise StepRefused(self.name, t, h, f"the motor state became non-finite: {x}")
        mag = math.sqrt(x[0] * x[0] + x[1] * x[1])
        if mag > self._trip:
            raise StepRefused(self.name, t, h, f"overcurrent: |i| = {mag:.4g} A exceeds the trip "
                              f"level {self._trip:.4g} A (trip_factor x current_limit): the drive trips")
        self.x = x

    def _rk4(self, x: list[float], vd: float, vq: float, w0: float, dw: float,
             h: float) -> list[float]:
        """State after ``h`` [s] by classic RK4 on substeps of at most ``max_substep``, with the
        speed w0 + dw τ [rad/s] varying linearly (the reference integrator).

        Unrolled over the state's components (the equations of the module docstring and the
        RK4 stages term by term, as the stage vectors were computed before): the energies do
        not enter the derivatives, only their rates are accumulated."""
        r, ell, p, psi, kt = self._c
        c_cu = 1.5 * r
        n = max(1, math.ceil(h / self.max_substep - 1e-9))
        dt = h / n
        hdt = 0.5 * dt
        dt6 = dt / 6.0
        i0, i1, e_el, e_cu, e_ag = x
        for j in map(float, range(n)):     # j·dt: the same product as with the integer j
            tau = j * dt
            wa, wm, wb = w0 + dw * tau, w0 + dw * (tau + hdt), w0 + dw * (tau + dt)
            # stage 1 at (i0, i1), speed wa
            we = p * wa
            wl = we * ell
            d1 = (vd - r * i0 + wl * i1) / ell
            q1 = (vq - r * i1 - wl * i0 - we * psi) / ell
            pe1 = 1.5 * (vd * i0 + vq * i1)
            pc1 = c_cu * (i0 * i0 + i1 * i1)
            pa1 = kt * i1 * wa
            # stage 2 at the half step with k1, speed wm
            a0, a1 = i0 + hdt * d1, i1 + hdt * q1
            we = p * wm
            wl = we * ell
            wp = we * psi
            d2 = (vd - r * a0 + wl * a1) / ell
            q2 = (vq - r * a1 - wl * a0 - wp) / ell
            pe2 = 1.5 * (vd * a0 + vq * a1)
            pc2 = c_cu * (a0 * a0 + a1 * a1)
            pa2 = kt * a1 * wm
            # stage 3 at the half step with k2, speed wm
            a0, a1 = i0 + hdt * d2, i1 + hdt * q2
            d3 = (vd - r * a0 + wl * a1) / ell
            q3 = (vq - r * a1 - wl * a0 - wp) / ell
            pe3 = 1.5 * (vd * a0 + vq * a1)
            pc3 = c_cu * (a0 * a0 + a1 * a1)
            pa3 = kt * a1 * wm
            # stage 4 at the full step with k3, speed wb
            a0, a1 = i0 + dt * d3, i1 + dt * q3
            we = p * wb
            wl = we * ell
            d4 = (vd - r * a0 + wl * a1) / ell
            q4 = (vq - r * a1 - wl * a0 - we * psi) / ell
            pe4 = 1.5 * (vd * a0 + vq * a1)
            pc4 = c_cu * (a0 * a0 + a1 * a1)
            pa4 = kt * a1 * wb
            i0 = i0 + dt6 * (d1 + 2.0 * d2 + 2.0 * d3 + d4)
            i1 = i1 + dt6 * (q1 + 2.0 * q2 + 2.0 * q3 + q4)
            e_el = e_el + dt6 * (pe1 + 2.0 * pe2 + 2.0 * pe3 + pe4)
            e_cu = e_cu + dt6 * (pc1 + 2.0 * pc2 + 2.0 * pc3 + pc4)
            e_ag = e_ag + dt6 * (pa1 + 2.0 * pa2 + 2.0 * pa3 + pa4)
        return [i0, i1, e_el, e_cu, e_ag]

    def get_outputs(self) -> list[float]:
        idd, iq, e_el, e_cu, e_ag = self.x
        vd, vq = self._applied()
        r, ell, _, _, kt = self._c
        i2 = idd * idd + iq * iq
        return [idd, iq, math.sqrt(i2), kt * iq, vd, vq, 1.5 * (vd * idd + vq * iq), 1.5 * r * i2,
                e_el, e_cu, e_ag, 0.75 * ell * i2]
