"""The cascaded digital controller: position (P or PI) → speed PI → current PI → voltages.

It runs at its own sample period ``sample_time`` (sample instants t0 + j·T_s), whatever the
master's communication step: in a step [t, t + h) it executes every sample instant that falls
in it, reading its inputs at that instant (from the values and slopes the master gives, i.e.
the master's extrapolation), and its outputs are the commands of the latest sample, held
(discrete ports).  The speed loop runs every ``speed_divider`` samples and the position loop
every ``position_divider`` samples (multi-rate, as drives do).

Loops (the current loop with decoupling and back-EMF feed-forward)::

    position:  ω* = sat(K_px e_x + I_x + v*_ff / c, ±ω_max)     e_x = x* − x   [m]
    speed:     i_q* = sat(K_pω e_ω + I_ω, ±I_max)             e_ω = ω* − ω   [rad/s]
    current:   v_d = K_pi (0 − i_d) + I_d − ω_e L i_q
               v_q = K_pi (i_q* − i_q) + I_q + ω_e (L i_d + ψ)
               (v_d, v_q) limited to the circle of radius V_max, d axis first

c = Σ L_k / 2π is the rod travel per screw radian.  Every integrator has back-calculation
anti-windup: I += T (K_i e + (u_sat − u_unsat) / T_t) with tracking time T_t = K_p / K_i, so an
integrator stops growing once its loop saturates and leaves saturation without overshoot from
stored error.

Modes: ``position`` (the cascade), ``speed`` (ω* from the reference profile), ``current``
(i_q* from the reference profile).  Gains come from :meth:`ControllerParams.design`, which
places the loops' bandwidths a decade apart (module :func:`ControllerParams.design`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable

from .blocks import Port, PythonBlock, StepRefused
from .motor import MotorParams

_isfinite, _sqrt = math.isfinite, math.sqrt

__all__ = ["ControllerParams", "PI", "CascadeController", "MODES"]

MODES = ("position", "speed", "current")


@dataclass(frozen=True)
class ControllerParams:
    """Gains, limits and sample rates of the cascade, SI units.

    Use :meth:`design` to get gains from the plant; the fields can then be overridden.
    """

    sample_time: float = 1e-4          #: current-loop period [s] (10 kHz)
    speed_divider: int = 1             #: speed loop every n samples
    position_divider: int = 10         #: position loop every n samples (1 kHz)
    current_kp: float = 6.28           #: [V/A]
    current_ki: float = 1571.0         #: [V/(A s)]
    speed_kp: float = 0.2              #: [A/(rad/s)]
    speed_ki: float = 15.0             #: [A/rad]
    position_kp: float = 1.97e4        #: [(rad/s)/m]
    position_ki: float = 0.0           #: [(rad/s)/(m s)] (0: P control)
    velocity_feedforward: float = 0.0  #: fraction of the reference's rate fed to the speed loop
    current_limit: float = 20.0        #: |i_q*| limit [A]
    voltage_limit: float = 155.88      #: |v| limit [V]
    speed_limit: float = 140.0         #: |ω*| limit [rad/s]
    decoupling: bool = True            #: dq decoupling and back-EMF feed-forward

    @classmethod
    def design(cls, motor: MotorParams, inertia: float, lead_per_radian: float,
               sample_time: float = 1e-4, current_bandwidth: float = 2.0 * math.pi * 500.0,
               speed_ratio: float = 10.0, position_ratio: float = 5.0,
               speed_divider: int = 1, position_divider: int = 10) -> "ControllerParams":
        """Gains from the plant by pole placement, the loops a decade apart.

        * current PI, plant 1/(R + Ls) (decoupled): K_p = L ω_c, K_i = R ω_c, cancelling the
          electrical pole so the closed loop is ω_c/(s + ω_c); ω_c = 2π·500 Hz is 1/20 of the
          10 kHz sampling (the sampling and one-sample delay cost ≈ 18° of phase).
        * speed PI, plant k_t/(J s) with J the total inertia on the screw (rotor, screws, nut
          masses, load mass reflected): K_p = J ω_s / k_t gives crossover ω_s = ω_c/10; the
          integral zero at ω_s/4 (K_i = K_p ω_s/4) keeps ≈ 76° of phase margin and rejects a
          constant load torque with no steady error.
        * position P: K_p = ω_p / c, ω_p = ω_s/5 (≈ 63 rad/s), so the position loop is close to a
          first-order lag of time constant 1/ω_p on top of the speed loop, whose lag costs
          atan(1/5) ≈ 11° of the position loop's 90° phase margin (little overshoot); the speed
          loop's integrator removes the steady error against a spring or a constant force.
        * limits: i_q* ≤ the motor's current limit, V ≤ V_dc/√3, ω* ≤ 0.9 × the no-load speed.

        Parameters
        ----------
        motor : MotorParams
        inertia : float
            Total inertia on the screw axis [kg·m²].
        lead_per_radian : float
            Rod travel per screw radian c = Σ L_k / 2π [m/rad].
        sample_time : float
            Current-loop sample period [s].
        current_bandwidth : float
            ω_c [rad/s].
        speed_ratio, position_ratio : float
            ω_c/ω_s and ω_s/ω_p.
        speed_divider, position_divider : int
            Loop rates as divisors of the sample rate.
        """
        wc = current_bandwidth
        ws = wc / speed_ratio
        wp = ws / position_ratio
        kps = inertia * ws / motor.torque_constant
        return cls(sample_time=sample_time, speed_divider=speed_divider,
                   position_divider=position_divider,
                   current_kp=motor.inductance * wc, current_ki=motor.resistance * wc,
                   speed_kp=kps, speed_ki=kps * ws / 4.0,
                   position_kp=wp / lead_per_radian, position_ki=0.0,
                   current_limit=motor.current_limit, voltage_limit=motor.voltage_limit,
                   speed_limit=0.9 * motor.no_load_speed)

    def with_changes(self, **changes) -> "ControllerParams":
        return replace(self, **changes).validate()

    def validate(self) -> "ControllerParams":
        """Check every field; ValueError naming the field, its value and the range."""
        for f in ("sample_time", "current_limit", "voltage_limit", "speed_limit"):
            v = getattr(self, f)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
                raise ValueError(f"controller.{f} = {v!r} is out of range: must be a finite "
                                 "number > 0")
        for f in ("current_kp", "current_ki", "speed_kp", "speed_ki", "position_kp",
                  "position_ki", "velocity_feedforward"):
            v = getattr(self, f)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"controller.{f} = {v!r} is out of range: must be a finite "
                                 "number >= 0")
        for f in ("speed_divider", "position_divider"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"controller.{f} = {v!r} is out of range: must be an integer >= 1")
        for loop in ("current", "speed"):
            if getattr(self, f"{loop}_kp") <= 0.0:
                raise ValueError(f"controller.{loop}_kp = 0 is out of range: must be > 0")
        return self


class PI:
    """Discrete PI with output saturation and back-calculation anti-windup.

    ``u = sat(K_p e + I + ff)``; then ``I += T (K_i e + (u − u_unsat)/T_t)`` with
    ``T_t = K_p/K_i`` (for K_i = 0 the integrator stays at its value).
    """

    __slots__ = ("kp", "ki", "ts", "kaw", "integral")

    def __init__(self, kp: float, ki: float, ts: float, integral: float = 0.0) -> None:
        self.kp, self.ki, self.ts = kp, ki, ts
        self.kaw = ki / kp if (ki > 0.0 and kp > 0.0) else 0.0
        self.integral = integral

    def unsaturated(self, error: float, ff: float = 0.0) -> float:
        return self.kp * error + self.integral + ff

    def commit(self, error: float, u_unsat: float, u_sat: float) -> None:
        """Integrator update after the output ``u_sat`` was applied."""
        if self.ki > 0.0:
            self.integral += self.ts * (self.ki * error + self.kaw * (u_sat - u_unsat))

    def update(self, error: float, lo: float, hi: float, ff: float = 0.0) -> float:
        u = self.unsaturated(error, ff)
        us = min(hi, max(lo, u))
        self.commit(error, u, us)
        return us


class CascadeController(PythonBlock):
    """The cascade as a co-simulation block (module docstring).

    Parameters
    ----------
    params : ControllerParams
    motor : MotorParams
        The controller's model of the motor (decoupling, back-EMF feed-forward).
    lead_per_radian : float
        c = Σ L_k/2π [m/rad] (position loop output in screw speed, velocity feed-forward).
    reference : callable
        t [s] -> reference: rod position [m] (position mode), screw speed [rad/s] (speed
        mode) or q current [A] (current mode).
    mode : {"position", "speed", "current"}
    t0 : float
        Start time: sample instants are t0 + j·sample_time.
    initial : dict, optional
        Initial integrators and commands: ``i_d``, ``i_q``, ``speed``, ``position`` (integrator
        values), ``v_d``, ``v_q``, ``speed_ref``, ``i_q_ref`` (commands before the first sample).
    """

    inputs = (Port("position", "m", "measured rod position"),
              Port("speed", "rad/s", "measured screw (rotor) speed"),
              Port("i_d", "A", "measured d-axis current"),
              Port("i_q", "A", "measured q-axis current"))
    #: unit of the ``reference`` output in each mode
    REFERENCE_UNIT = {"position": "m", "speed": "rad/s", "current": "A"}
    interpolates_inputs = True
    _state_attrs = ("j", "cmd", "integrals")

    def __init__(self, params: ControllerParams, motor: MotorParams, lead_per_radian: float,
                 reference: Callable[[float], float], mode: str = "position", t0: float = 0.0,
                 initial: dict | None = None, name: str = "controller") -> None:
        if mode not in MODES:
            raise ValueError(f"controller.mode = {mode!r} is not allowed: must be one of "
                             f"{', '.join(MODES)}")
        self.params = params.validate()
        self.outputs = (
            Port("v_d", "V", "d-axis voltage command", discrete=True),
            Port("v_q", "V", "q-axis voltage command", discrete=True),
            Port("reference", self.REFERENCE_UNIT[mode], f"{mode} reference at the last sample",
                 discrete=True),
            Port("speed_ref", "rad/s", "screw speed reference (position loop output or the "
                 "speed reference)", discrete=True),
            Port("i_q_ref", "A", "q current reference (speed loop output)", discrete=True),
            Port("samples", "1", "samples executed since the start", discrete=True))
        super().__init__(name)
        self.motor = motor
        self.c = float(lead_per_radian)
        self.reference = reference
        self.mode = mode
        self.t0 = float(t0)
        ini = dict(initial or {})
        unknown = set(ini) - {"i_d", "i_q", "speed", "position", "v_d", "v_q", "speed_ref",
                              "i_q_ref"}
        if unknown:
            raise ValueError(f"controller initial values: unknown name(s) {sorted(unknown)}")
        #: index of the next sample
        self.j = 0
        #: v_d, v_q, reference, speed_ref, i_q_ref, samples
        self.cmd = [ini.get("v_d", 0.0), ini.get("v_q", 0.0), reference(t0),
                    ini.get("speed_ref", 0.0), ini.get("i_q_ref", 0.0), 0.0]
        #: integrators: position, speed, d current, q current
        self.integrals = [ini.get("position", 0.0), ini.get("speed", 0.0), ini.get("i_d", 0.0),
                          ini.get("i_q", 0.0)]
        p = self.params
        #: anti-windup gains K_i/K_p of the position, speed and current loops (as :class:`PI`)
        self._kaw_position = PI(p.position_kp, p.position_ki, p.sample_time).kaw
        self._kaw_speed = PI(p.speed_kp, p.speed_ki, p.sample_time).kaw
        self._kaw_current = PI(p.current_kp, p.current_ki, p.sample_time).kaw
        self._motor_c: tuple | None = None       # _motor_constants

    def _motor_constants(self) -> tuple:
        """(motor, p as a float, L [H], ψ [Wb]) of the controller's motor model, worked out
        once per motor (p·ω as a float product: the same value as int · float)."""
        mc = self._motor_c
        m = self.motor
        if mc is None or mc[0] is not m:
            mc = self._motor_c = (m, float(m.pole_pairs), m.inductance, m.flux_linkage)
        return mc

    def _sample(self, t: float, x: float, w: float, idd: float, iq: float) -> None:
        """One sample at ``t`` [s] with the measurements x [m], ω [rad/s], i_d, i_q [A].

        The loops are :class:`PI` updates written out (no objects per sample); the arithmetic
        is :meth:`PI.update`'s, term by term.  Its saturation ``min(hi, max(lo, u))`` is written
        as those builtins decide: max(lo, u) is u only if u > lo, min(hi, v) is v only if
        v < hi (a NaN gives the limit, as with the builtins)."""
        p = self.params
        ts = p.sample_time
        j = self.j
        cmd, integ = self.cmd, self.integrals
        ref = self.reference(t)
        cmd[2] = ref
        mode = self.mode
        # position loop (PI with period ts · position_divider)
        if mode == "position" and j % p.position_divider == 0:
            tp = ts * p.position_divider
            ff = 0.0
            if p.velocity_feedforward > 0.0:     # the planned trajectory's rate, central difference
                ff = p.velocity_feedforward * (self.reference(t + tp) - self.reference(t - tp)) \
                    / (2.0 * tp * self.c)
            e = ref - x
            u = p.position_kp * e + integ[0] + ff
            hi = p.speed_limit
            lo = -hi
            us = u if u > lo else lo
            us = us if us < hi else hi
            ki = p.position_ki
            if ki > 0.0:
                integ[0] += tp * (ki * e + self._kaw_position * (us - u))
            cmd[3] = us
        elif mode == "speed":
            cmd[3] = min(p.speed_limit, max(-p.speed_limit, ref))
        # speed loop (PI with period ts · speed_divider)
        if mode != "current" and j % p.speed_divider == 0:
            e = cmd[3] - w
            u = p.speed_kp * e + integ[1] + 0.0
            hi = p.current_limit
            lo = -hi
            us = u if u > lo else lo
            us = us if us < hi else hi
            ki = p.speed_ki
            if ki > 0.0:
                integ[1] += (ts * p.speed_divider) * (ki * e + self._kaw_speed * (us - u))
            cmd[4] = us
        elif mode == "current":
            cmd[4] = min(p.current_limit, max(-p.current_limit, ref))
        # current loop, d axis first on the voltage circle
        _, pole_pairs, ell, psi = self._motor_constants()
        we = pole_pairs * w
        if p.decoupling:
            ffd, ffq = -we * ell * iq, we * (ell * idd + psi)
        else:
            ffd = ffq = 0.0
        vmax = p.voltage_limit
        kp, ki, kaw = p.current_kp, p.current_ki, self._kaw_current
        ed = 0.0 - idd
        vd_u = kp * ed + integ[2] + ffd
        lo = -vmax
        vd = vd_u if vd_u > lo else lo
        vd = vd if vd < vmax else vmax
        room = vmax * vmax - vd * vd
        vq_lim = _sqrt(room if room > 0.0 else 0.0)
        eq = cmd[4] - iq
        vq_u = kp * eq + integ[3] + ffq
        lo = -vq_lim
        vq = vq_u if vq_u > lo else lo
        vq = vq if vq < vq_lim else vq_lim
        if ki > 0.0:
            integ[2] += ts * (ki * ed + kaw * (vd - vd_u))
            integ[3] += ts * (ki * eq + kaw * (vq - vq_u))
        cmd[0], cmd[1] = vd, vq
        cmd[5] += 1.0
        self.j = j + 1

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        ts = self.params.sample_time
        eps = 1e-9 * min(h, ts)
        u, du = self.u, self.du
        u0, u1, u2, u3 = u
        s0, s1, s2, s3 = du
        if not (all(map(_isfinite, u)) and all(map(_isfinite, du))):
            raise StepRefused(self.name, t, h, f"non-finite measurement: {u}, slopes {du}")
        t_end = t + h - eps
        tj = self.t0 + self.j * ts
        # the sample instants only grow, so only the first can lie before the step, and then
        # nothing has been executed yet: the state is unchanged when the step is refused
        if tj < t - eps and tj < t_end:
            raise StepRefused(self.name, t, h, f"sample {self.j} at t = {tj!r} s lies "
                              "before the step: steps must be contiguous")
        while tj < t_end:
            dt = tj - t
            self._sample(tj, u0 + s0 * dt, u1 + s1 * dt, u2 + s2 * dt, u3 + s3 * dt)
            tj = self.t0 + self.j * ts

    def get_outputs(self) -> list[float]:
        return list(self.cmd)
