"""``fidelity = "auto"`` along a run: the dynamic level while the carriers lag, the quasi-static
level while they follow their equilibrium.

The quasi-static level is the dynamic level's slow manifold: it drops the carriers' lag behind
ζ*ω and nothing else (docs/model.md §4).  Where that lag is below the tolerance it gives the same
outputs for a fraction of the cost (a closed-form step instead of a stiff integration); where the
carriers spin up, or a strong acceleration makes them trail, only the dynamic level is right.
A run's operating point moves, so the choice is made again at every communication step:

* **state** — always the dynamic level's layout (carrier speeds included).  While quasi-static,
  the carriers are stored at ζ*ω and the step is the quasi-static level's (closed form).
* **dynamic → quasi-static** after a dynamic step, when the carriers' deviation from ζ*ω,
  relative to the largest carrier speed of the run so far, is within ``tolerance / (2·MARGIN)``
  and — confirmed — so is every output's change on switching: the quasi-static outputs at the
  state against the dynamic ones, each relative to a scale of its kind at that point (forces:
  the largest contact or normal force and the load; torques: the largest driven torque; powers:
  the largest of input, output and friction power; carrier speeds: ζ* times the largest screw
  speed so far; screw acceleration: the largest torque over the inertia on the screw; ratios: 1).
  The scales are magnitudes at the current point, so the check is conservative against the
  error measure of docs/accuracy.md §1 (relative to the run's maxima).  A failed confirmation
  records how much more the outputs moved than the carriers (the gain err/deviation; near the
  equilibrium it is a constant of the linearised outputs) and the next confirmation waits
  until the deviation times that gain is within the limit; where that does not predict it
  (no deviation, or no larger gain), it waits 1, 2, 4 … (at most 64) steps.
* **quasi-static → dynamic** when the carriers' estimated lag exceeds ``tolerance / MARGIN``.
  The lag d_k = ω_Pk/ζ*_k − ω of each carrier is integrated along the quasi-static run with the
  linearised carrier equation d' = −α − d/τ_k (exact over a step with α and τ held; d ← d − αh
  where the carrier is not driven), the formula of :func:`prsm_fmu.models.auto.estimate_along`.
  τ_k = c_k·|ω|/|F_eff| (the carrier time constant is proportional to the speed over the
  effective axial force, :func:`~prsm_fmu.models.auto.effective_load`; c_k is computed once per
  drive direction from :func:`~prsm_fmu.models.auto.carrier_time_constants`).  A prescribed
  speed that jumps (speed drive) enters d as −Δω.  The step in which the estimate crosses the
  limit is redone with the dynamic level from its start, the carriers put at the estimated lag
  ζ*_k(ω + d_k) (the first-order slow manifold) rather than at ζ*ω.

``MARGIN`` and the factor 2 of hysteresis keep the level from switching back and forth at the
limit.  The active level is part of the stepper's memory, so an FMU state saved and restored
reproduces the run bit for bit; :meth:`AdaptiveModel.outputs` gives the active level's outputs.
docs/accuracy.md §4 checks the result against the work-precision data.
"""

from __future__ import annotations

import math
from typing import Any

from ..steppers import ClosedForm, StepStats, Stepper, make_stepper
from ..steppers.options import TOLERANCE_FACTOR, TUNED_OPTIONS
from .auto import MARGIN, carrier_time_constants, effective_load
from .dynamic import DynamicModel
from .quasi_static import QuasiStaticModel

__all__ = ["AdaptiveModel", "SwitchingStepper", "MODES", "MAX_WAIT", "EXPLICIT_STEP_PER_TAU"]

#: the two levels a run switches between
MODES = ("dynamic", "quasi-static")

#: longest wait between two confirmations of a dynamic → quasi-static switch [steps]
MAX_WAIT = 64

#: with the ``default`` stepper, a dynamic step is explicit (Dormand–Prince 5(4)) where the
#: communication step is at most this many fastest carrier time constants, stiff (exponential or
#: ROS34PW2, :class:`SwitchingStepper`) elsewhere: DP5(4) is stable to 3.3 τ on the real axis;
#: the margin covers the screw–carrier coupling and a speed that falls within the step (τ ∝ ω)
EXPLICIT_STEP_PER_TAU = 1.5

#: outputs compared before a switch, by the kind of scale they are measured against
_KINDS = {"contact_force": "force", "normal_force": "force", "spline_friction": "force",
          "driven_torque": "torque", "carrier_speed": "carrier", "carrier_speed_ratio": "ratio"}
_HEAD_KINDS = {"screw_torque": "torque", "screw_acceleration": "acceleration",
               "efficiency": "ratio", "friction_power": "power", "input_power": "power",
               "output_power": "power", "kinetic_energy": "energy"}


class AdaptiveModel(DynamicModel):
    """The dynamic level's state, stepped by the dynamic or the quasi-static level (module doc).

    Parameters
    ----------
    params : MechanismParams
    drive : {"torque", "speed"}
    tolerance : float
        Accepted model error [-] (docs/accuracy.md §1 measure), > 0.
    start : {"dynamic", "quasi-static"}
        Level of the first step.
    choice : AutoChoice, optional
        The start's choice (reported as ``auto_choice``).
    """

    fidelity = "auto"

    def __init__(self, params, drive: str = "torque", *, tolerance: float,
                 start: str = "dynamic", choice=None) -> None:
        super().__init__(params, drive)
        if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0.0):
            raise ValueError(f"tolerance = {tolerance!r} is out of range: must be a finite number > 0")
        if start not in MODES:
            raise ValueError(f"start = {start!r} is not allowed: must be one of {', '.join(MODES)}")
        self.tolerance = float(tolerance)
        self.start = start
        #: the level whose outputs :meth:`outputs` gives (set by the stepper)
        self.mode = start
        self.auto_choice = choice
        #: the quasi-static level and the plain dynamic level the steppers integrate
        self.quasi_static = QuasiStaticModel(params, drive)
        self.dynamic = DynamicModel(params, drive)
        self.zeta = tuple(self.quasi_static.mechanism.zeta)
        self._coef: dict = {}
        #: m·c_out of the last nut [kg·m/rad]: F_eff = F + m·c_out·α (auto.effective_load)
        self._nut_term = effective_load(params, 0.0, 1.0)
        stages = self.mechanism.stages
        # inertia on the screw axis with the carriers slaved (scale of the acceleration check)
        self.slaved_inertia = 2.0 * self.quasi_static.kinetic_energy(
            self.quasi_static.initial_state((1.0, 0.0), screw_speed=1.0), (1.0, 0.0))
        self._names = tuple(self.output_names)
        self._n = len(stages)

    # ---- the two layouts ---------------------------------------------------------------
    def reduced(self, x: list[float]) -> list[float]:
        """The quasi-static level's state (carrier speeds dropped)."""
        i = self._i_carrier
        return x[:i] + x[i + self._n:]

    def expanded(self, xr: list[float], omega: float) -> list[float]:
        """The dynamic layout of a quasi-static state, carriers at ζ*ω [rad/s]."""
        i = self._i_carrier
        return xr[:i] + [z * omega for z in self.zeta] + xr[i:]

    def screw_speed(self, x: list[float], u: tuple) -> float:
        """Screw speed of a state [rad/s]."""
        return x[1]

    # ---- outputs of the active level -----------------------------------------------------
    def outputs(self, t: float, x: list[float], u: tuple) -> dict[str, float]:
        """All outputs of the active level (``mode``) at the state."""
        if self.mode == "quasi-static":
            return self.quasi_static.outputs(t, self.reduced(x), u)
        return super().outputs(t, x, u)

    def kinetic_energy(self, x: list[float], u: tuple) -> float:
        """Kinetic energy of the active level [J]."""
        if self.mode == "quasi-static":
            return self.quasi_static.kinetic_energy(self.reduced(x), u)
        return super().kinetic_energy(x, u)

    # ---- the switching criteria ------------------------------------------------------------
    def lag_coefficients(self, forward: bool) -> tuple[float, ...]:
        """c_k = τ_k |F| / |ω| of each carrier [N·s²/rad] for a driving (``forward``: ω F > 0)
        or back-driven mechanism (τ_k ∝ |ω|/|F| outside the friction band)."""
        c = self._coef.get(forward)
        if c is None:
            omega, load = 100.0, (1000.0 if forward else -1000.0)
            taus = carrier_time_constants(self.params, omega, load)
            c = self._coef[forward] = tuple(t * abs(load) / omega for t in taus)
        return c

    def advance_lag(self, d: list[float], alpha: float, omega: float, load: float,
                    h: float) -> list[float]:
        """Each carrier's lag d_k [rad/s] after a step h [s] at screw acceleration α [rad/s²],
        mean screw speed ω [rad/s] and load force F [N] (module docstring)."""
        if alpha == 0.0 and not any(d):
            return list(d)                        # nothing to lag behind: stays 0
        f_eff = load + self._nut_term * alpha      # effective_load, inlined (hot path)
        out = []
        if omega == 0.0:
            return [0.0] * self._n
        if f_eff == 0.0:
            return [dk - alpha * h for dk in d]
        coef = self.lag_coefficients(omega * f_eff > 0.0)
        ratio = abs(omega) / abs(f_eff)
        for dk, ck in zip(d, coef):
            tau = ck * ratio
            if not math.isfinite(tau):
                out.append(dk - alpha * h)
            elif tau == 0.0:
                out.append(0.0)
            else:
                e = math.exp(-h / tau)
                out.append(dk * e - alpha * tau * (1.0 - e))
        return out

    def deviation(self, x: list[float], u: tuple, omega_scale: float) -> float:
        """Largest |ω_Pk − ζ*_k ω| / (|ζ*_k| ω_max) of the state's carriers [-]."""
        omega = self.screw_speed(x, u)
        i = self._i_carrier
        dev = 0.0
        for k, z in enumerate(self.zeta):
            diff = abs(x[i + k] - z * omega)
            if diff == 0.0:
                continue
            scale = abs(z) * omega_scale
            if scale == 0.0:
                return math.inf
            dev = max(dev, diff / scale)
        return dev

    def switch_error(self, t: float, x: list[float], u: tuple, omega_scale: float) -> float:
        """Largest change of an output on switching to the quasi-static level here [-]
        (each relative to the scale of its kind, module docstring)."""
        yd = DynamicModel.outputs(self, t, x, u)
        yq = self.quasi_static.outputs(t, self.reduced(x), u)
        n = self._n
        forces = [abs(yd["load_force"])]
        torques = [abs(yd["screw_torque"])]
        for k in range(1, n + 1):
            forces += [abs(yd[f"stage[{k}].contact_force"]), abs(yd[f"stage[{k}].normal_force"])]
            torques.append(abs(yd[f"stage[{k}].driven_torque"]))
        scale = {"force": max(forces), "torque": max(torques), "ratio": 1.0,
                 "power": max(abs(yd["input_power"]), abs(yd["output_power"]),
                              abs(yd["friction_power"])),
                 "energy": max(abs(yd["kinetic_energy"]), abs(yq["kinetic_energy"]))}
        scale["acceleration"] = scale["torque"] / self.slaved_inertia
        err = 0.0
        for name in self._names:
            base = name.split(".", 1)[1] if name.startswith("stage[") else name
            kind = _KINDS.get(base) or _HEAD_KINDS.get(base)
            if kind is None:
                continue
            diff = abs(yd[name] - yq[name])
            if not diff > 0.0:          # equal, or NaN: the efficiency where no power flows
                continue
            if kind == "carrier":
                k = int(name[6:name.index("]")]) - 1
                s = abs(self.zeta[k]) * omega_scale
            elif kind == "ratio" and base == "carrier_speed_ratio":
                k = int(name[6:name.index("]")]) - 1
                s = abs(self.zeta[k])
            else:
                s = scale[kind]
            err = max(err, diff / s if s > 0.0 else math.inf)
        return err

    # ---- stepper factory (steppers.make_stepper calls it) ----------------------------------
    def stepper_factory(self, name: str, **options: Any) -> "SwitchingStepper":
        """A :class:`SwitchingStepper` whose dynamic steps are taken by stepper ``name``."""
        return SwitchingStepper(self, name, **options)


class SwitchingStepper(Stepper):
    """Steps an :class:`AdaptiveModel` with the level its criteria choose (module docstring).

    Parameters
    ----------
    model : AdaptiveModel
    name : str
        Stepper of the dynamic level; ``default``: for each dynamic step, ROS34PW2 with the
        tuned options of :data:`prsm_fmu.steppers.options.TUNED_OPTIONS` where the screw speed
        is zero or heads through zero within the step (at the last step's acceleration); else
        explicit (DP5(4)) where the communication step is at most :data:`EXPLICIT_STEP_PER_TAU`
        times the fastest carrier time constant at the step's start (τ_k = c_k |ω|/|F|), and the
        exponential stepper (exprb32) everywhere else, each at the tolerances scaled by
        :data:`prsm_fmu.steppers.options.TOLERANCE_FACTOR`. Why: the exponential stepper takes
        the fewest rhs calls at the loop scenes' 0.1 ms steps; through a zero-speed crossing,
        where every friction law passes the once-differentiable points of its band and every
        stepper lands on them, ROS34PW2 takes about 60 % of its rhs calls (685 against 1126 in
        the speed reversal's crossing step at tolerance 1e-6, docs/accuracy.md §2, "Work of the
        crossing step"). ``closed_form`` and ``closed_form_explicit`` mean
        ``rosenbrock``.
    **options
        That stepper's options; ``rtol``, ``atol`` and ``max_substeps`` also set the
        quasi-static closed form's fallback integrator (with ``default``, they and
        ``fixed_substeps`` set all three dynamic steppers).
    """

    name = "auto"

    def __init__(self, model: AdaptiveModel, name: str, **options: Any) -> None:
        super().__init__(model)
        if not isinstance(model, AdaptiveModel):
            raise ValueError("SwitchingStepper needs an AdaptiveModel (fidelity = 'auto')")
        fallback = {k: options[k] for k in ("rtol", "atol", "max_substeps") if k in options}
        if name == "default":
            common = dict(fallback)
            tuned = dict(TUNED_OPTIONS["rosenbrock"])
            if "fixed_substeps" in options:          # fixed steps: no step-size tuning
                common["fixed_substeps"] = options["fixed_substeps"]
                tuned = {}
            def scaled(stepper: str) -> dict:
                # the tolerances as tuned_stepper_options scales them
                k = TOLERANCE_FACTOR.get(stepper, 1.0)
                return {key: v * k if key in ("rtol", "atol") else v for key, v in common.items()}

            self.dynamic_steppers = {
                "explicit_adaptive": make_stepper("explicit_adaptive", model.dynamic,
                                                  **scaled("explicit_adaptive")),
                "exponential": make_stepper("exponential", model.dynamic, **scaled("exponential")),
                "rosenbrock": make_stepper("rosenbrock", model.dynamic, **tuned,
                                           **scaled("rosenbrock"))}
        else:
            name = "rosenbrock" if name in ("closed_form", "closed_form_explicit") else name
            self.dynamic_steppers = {name: make_stepper(name, model.dynamic, **options)}
        self.quasi_static_stepper = ClosedForm(model.quasi_static, **fallback)
        self.name = f"auto({name})"
        self.tolerance = model.tolerance
        self.reset()

    # ---- memory ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the start level, no lag, no wait."""
        m = self.model
        self.mode = m.start
        m.mode = m.start
        self.lag = [0.0] * m._n
        self.omega_scale = 0.0
        self.wait = 0
        self.backoff = 1
        self.gain = 1.0
        self.switches = 0
        self.alpha = 0.0
        for st in self.dynamic_steppers.values():
            st.reset()
        self.quasi_static_stepper.reset()

    def get_memory(self) -> tuple:
        """``(mode, lags, largest screw speed, wait, backoff, gain, switches, last screw
        acceleration, the dynamic steppers' memories, quasi-static stepper's memory)``."""
        return (self.mode, tuple(self.lag), self.omega_scale, self.wait, self.backoff,
                self.gain, self.switches, self.alpha,
                tuple(st.get_memory() for st in self.dynamic_steppers.values()),
                self.quasi_static_stepper.get_memory())

    def set_memory(self, m: tuple) -> None:
        """Restore a snapshot of :meth:`get_memory`."""
        try:
            mode, lag, scale, wait, backoff, gain, switches, alpha, dmem, qmem = m
        except (TypeError, ValueError):
            raise ValueError(f"{self.name}: not a memory of this stepper: {m!r}") from None
        if mode not in MODES or len(lag) != self.model._n \
                or len(dmem) != len(self.dynamic_steppers):
            raise ValueError(f"{self.name}: not a memory of this stepper: {m!r}")
        for st, mem in zip(self.dynamic_steppers.values(), dmem):
            st.set_memory(mem)
        self.quasi_static_stepper.set_memory(qmem)
        self.mode = self.model.mode = mode
        self.lag = [float(v) for v in lag]
        self.omega_scale = float(scale)
        self.wait, self.backoff, self.switches = int(wait), int(backoff), int(switches)
        self.gain, self.alpha = float(gain), float(alpha)

    # ---- stepping -----------------------------------------------------------------------------
    def dynamic_for(self, x: list[float], u: tuple, h: float) -> Stepper:
        """The stepper of a dynamic step of h [s] from state x with inputs u (see ``name``)."""
        steppers = self.dynamic_steppers
        if len(steppers) == 1:
            return next(iter(steppers.values()))
        m = self.model
        # the axial force that drives the carriers, with the last step's acceleration
        omega, load = m.screw_speed(x, u), u[1] + m._nut_term * self.alpha
        if omega == 0.0 or omega * (omega + self.alpha * h) < 0.0:
            return steppers["rosenbrock"]               # at or through zero speed
        if load == 0.0:
            return steppers["explicit_adaptive"]       # the carriers are not driven
        tau = min(m.lag_coefficients(omega * load > 0.0)) * abs(omega) / abs(load)
        return steppers["explicit_adaptive" if h <= EXPLICIT_STEP_PER_TAU * tau else "exponential"]

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        x1, stats = self._advance(t, x, u, h)
        self.alpha = (x1[1] - x[1]) / h
        return x1, stats

    def _advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        m = self.model
        w0 = m.screw_speed(x, u)
        scale = max(self.omega_scale, abs(w0))
        if self.mode == "quasi-static":
            i = m._i_carrier
            # the lag at the step's start: the carried estimate plus the stored carriers' offset
            # from the equilibrium of this step's speed (a prescribed speed that jumped)
            d0 = list(self.lag)
            for k, z in enumerate(m.zeta):
                if z != 0.0:
                    d0[k] += x[i + k] / z - w0
            yr, stats = self.quasi_static_stepper.advance(t, m.reduced(x), u, h)
            w1 = yr[1]
            d1 = m.advance_lag(d0, (w1 - w0) / h, 0.5 * (w0 + w1), u[1], h)
            if abs(w1) > scale:
                scale = abs(w1)
            worst = 0.0
            for v in d1:
                if abs(v) > worst:
                    worst = abs(v)
            if MARGIN * worst <= self.tolerance * scale:
                self.lag, self.omega_scale = d1, scale
                return m.expanded(yr, w1), stats
            # the carriers trail too far: this step again with the dynamic level, carriers at
            # the estimated lag
            xd = list(x)
            for k, z in enumerate(m.zeta):
                xd[i + k] = z * (w0 + d0[k])
            dyn = self.dynamic_for(xd, u, h)
            dyn.reset()
            x1, st2 = dyn.advance(t, xd, u, h)
            self.mode = m.mode = "dynamic"
            self.switches += 1
            self.wait, self.backoff = 0, 1
            self.omega_scale = max(scale, abs(m.screw_speed(x1, u)))
            return x1, _sum(stats, st2)
        x1, stats = self.dynamic_for(x, u, h).advance(t, x, u, h)
        scale = max(scale, abs(m.screw_speed(x1, u)))
        self.omega_scale = scale
        if self.wait > 0:
            self.wait -= 1
            return x1, stats
        dev = m.deviation(x1, u, scale)
        if 2.0 * MARGIN * dev * self.gain <= self.tolerance:
            err = m.switch_error(t + h, x1, u, scale)
            if 2.0 * MARGIN * err <= self.tolerance:
                self.mode = m.mode = "quasi-static"
                self.lag = [0.0] * m._n
                self.switches += 1
                self.gain = 1.0
                self.quasi_static_stepper.reset()
            elif dev > 0.0 and err / dev > self.gain:
                # the outputs move more than the carriers: wait until the deviation times
                # this gain is within the limit (it decays exponentially near equilibrium)
                self.gain = err / dev
            else:
                self.wait = self.backoff
                self.backoff = min(2 * self.backoff, MAX_WAIT)
        return x1, stats


def _sum(a: StepStats, b: StepStats) -> StepStats:
    """Work counters of two advances together (the last one's error estimate)."""
    return StepStats(rhs_calls=a.rhs_calls + b.rhs_calls,
                     jacobian_calls=a.jacobian_calls + b.jacobian_calls,
                     lu_decompositions=a.lu_decompositions + b.lu_decompositions,
                     substeps=a.substeps + b.substeps, rejected=a.rejected + b.rejected,
                     error_estimate=b.error_estimate)
