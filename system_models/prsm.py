"""The PRSM block, two ways: the FMU through fmpy, or the same mechanism as a plain Python model.

Both take the FMU's vocabulary (docs/fmu.md): inputs ``screw_torque`` [N.m] and ``load_force``
[N], held over each step; outputs ``screw_speed``, ``rod_position``, ``stage[k].contact_force``,
… and the step counters ``step_rhs_calls``, ``step_substeps``, ``step_fidelity``; parameters by the FMU's names
(``stage[1].screw_inertia``, ``fidelity``, ``tolerance``, ``initial_screw_speed``, …).

:class:`PythonPRSM` does what the FMU's slave (``prsm_fmu/slave.py``) does with the same
parameters: model, stepper, tolerances and ``auto`` choice come from the same function
(:func:`prsm_fmu.configure.configure`), the outputs are computed from the state at the
communication point and the inputs held over the last step.  So a scene run with either gives the same
numbers (tests/test_system_cosim.py checks 1e-10; in practice they agree bit for bit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from prsm_fmu import presets
from prsm_fmu.configure import ATOL_FACTOR, AUTO_FIDELITY, active_level, configure
from prsm_fmu.models.base import model_speed_bounds
from prsm_fmu.param_ranges import input_violation, state_violation
from prsm_fmu.params import MECHANISM_FIELD_NAMES, MechanismParams, stage_field_names
from prsm_fmu.simulate import DEFAULT_STEPPER
from prsm_fmu.steppers import StepFailure
from prsm_fmu.units import DIMENSIONLESS, NEWTON, NEWTON_METRE, unit_of

from .blocks import Port, PythonBlock, StepRefused

__all__ = ["PRSMConfig", "PythonPRSM", "make_prsm_block", "prsm_output_names", "mechanism_params",
           "MECHANISMS", "DEFAULT_STEPPER", "AUTO_FIDELITY", "ATOL_FACTOR"]

#: FMU name -> preset it is built from (fmu_build.mechanisms; PRSM3 is built by fmu_build)
MECHANISMS = {"PRSM1": "friction_single_stage", "PRSM2": "li2021_two_stage",
              "PRSM3": "li2021_three_stage"}


# the FMU's Real outputs in its order; units from prsm_fmu.units (the FMU's spellings)
_HEAD = ("screw_speed", "screw_angle", "screw_acceleration", "rod_position", "rod_velocity")
_STAGE = ("contact_force", "normal_force", "driven_torque", "spline_friction", "carrier_speed",
          "carrier_speed_ratio")
_TAIL = ("efficiency", "friction_power", "friction_power_coulomb", "friction_power_viscous",
         "friction_power_differential", "friction_power_joints", "screw_friction_torque",
         "input_power", "output_power", "input_work", "output_work", "friction_work",
         "kinetic_energy", "overall_efficiency")
COUNTERS = ("step_rhs_calls", "step_substeps", "step_fidelity")


def prsm_output_names(n_stages: int) -> list[str]:
    """The FMU's Real outputs for ``n_stages`` stages, in its order (prsm_fmu.slave.output_names)."""
    names = list(_HEAD)
    for k in range(1, n_stages + 1):
        names += [f"stage[{k}].{f}" for f in _STAGE]
    return names + list(_TAIL)


def _unit(name: str) -> str:
    return unit_of(name, DIMENSIONLESS)


def mechanism_params(mechanism: str) -> MechanismParams:
    """The parameters an FMU ``PRSM<n>`` starts from (its build's preset)."""
    if mechanism not in MECHANISMS:
        raise ValueError(f"mechanism = {mechanism!r} is not allowed: must be one of "
                         f"{', '.join(MECHANISMS)}")
    if mechanism == "PRSM3":
        from fmu_build.mechanisms import three_stage   # needs pythonfmu (fmu_build's package)

        return three_stage()
    return presets.load(MECHANISMS[mechanism])


@dataclass
class PRSMConfig:
    """One PRSM block's configuration, in the FMU's parameter names.

    Attributes
    ----------
    mechanism : str
        ``PRSM1``, ``PRSM2`` or ``PRSM3`` (the FMU file's name; its preset for Python).
    parameters : dict
        Parameter values by FMU name (``stage[1].screw_inertia``, ``mu_screw_roller``,
        ``fidelity``, ``tolerance``, ``initial_screw_speed``, ``initial_carrier_equilibrium``, …);
        the rest keep the FMU's start values (the preset's).
    initial_inputs : tuple
        ``(screw_torque, load_force)`` at the start (set in initialization mode).
    """

    mechanism: str = "PRSM2"
    parameters: dict[str, Any] = field(default_factory=dict)
    initial_inputs: tuple[float, float] = (0.0, 0.0)

    def params(self) -> MechanismParams:
        """The mechanism with the physical parameter overrides applied, validated."""
        p = mechanism_params(self.mechanism)
        fields = set(stage_field_names())
        mech = set(MECHANISM_FIELD_NAMES)
        for name, value in self.parameters.items():
            if name.startswith("stage["):
                k = int(name[6:name.index("]")])
                f = name[name.index("].") + 2:]
                if f not in fields:
                    raise ValueError(f"{name}: no field {f!r} in StageParams")
                cur = getattr(p.stages[k - 1], f)
                p = p.with_stage(k, **{f: type(cur)(value)})
            elif name in mech:
                p = p.with_changes(**{name: float(value)})
        return p.validate()

    def solver(self) -> dict[str, Any]:
        """The FMU's own parameters with their values (defaults of docs/fmu.md)."""
        s = {"fidelity": "quasi-static", "tolerance": 1e-6, "stepper": "default", "substeps": 0,
             "max_substeps": 100000, "kinematic_efficiency": 1.0, "initial_screw_speed": 0.0,
             "initial_screw_angle": 0.0, "initial_carrier_equilibrium": False}
        for name, value in self.parameters.items():
            if name in s:
                s[name] = type(s[name])(value)
            elif not (name.startswith("stage[") or name in MECHANISM_FIELD_NAMES):
                raise ValueError(f"{name!r} is not a parameter of the PRSM FMU")
        return s

    @property
    def n_stages(self) -> int:
        return mechanism_params(self.mechanism).n_stages


class PythonPRSM(PythonBlock):
    """The PRSM as a plain Python block that behaves like the FMU (module docstring)."""

    interpolates_inputs = False
    _state_attrs = ("x", "u_held", "t", "stats", "memory")

    def __init__(self, config: PRSMConfig, name: str = "prsm", start_time: float = 0.0) -> None:
        p = config.params()
        s = config.solver()
        n = p.n_stages
        self.inputs = (Port("screw_torque", NEWTON_METRE, "motor torque on screw 1"),
                       Port("load_force", NEWTON, "force on the last nut, positive resists "
                                                  "extension"))
        self._names = prsm_output_names(n)
        self.outputs = tuple(Port(o, _unit(o)) for o in self._names) + tuple(
            Port(c, DIMENSIONLESS, discrete=True) for c in COUNTERS)
        super().__init__(name)
        self.u = [float(v) for v in config.initial_inputs]
        self.u_held = tuple(self.u)
        # the FMU's own configuration (validation, auto choice, stepper and options)
        self.model, self.stepper, self.x, _level, _name = configure(p, s, self.u_held)
        self.t = float(start_time)
        self.stats = (0, 0, active_level(self.model))
        self.memory = self.stepper.get_memory()

    def do_step(self, t: float, h: float) -> None:
        u = (self.u[0], self.u[1])
        if not (0.0 < h < math.inf):
            raise StepRefused(self.name, t, h, f"communication step size = {h!r} s is out of "
                              "range: must be a finite number > 0")
        if not (math.isfinite(u[0]) and math.isfinite(u[1])):
            raise StepRefused(self.name, t, h, f"inputs screw_torque = {u[0]!r} N.m, load_force = "
                              f"{u[1]!r} N: every input must be finite")
        why = input_violation(u)                 # the FMU's bounds (docs/fmu.md, Variables)
        if why is not None:
            raise StepRefused(self.name, t, h, why)
        self.stepper.set_memory(self.memory)
        try:
            x, st = self.stepper.advance(t, self.x, u, h)
        except StepFailure as exc:
            self.stepper.set_memory(self.memory)
            raise StepRefused(self.name, t, h, f"integration failed: {exc}") from None
        why = state_violation(x, model_speed_bounds(self.model, len(x)))
        if why is not None:
            self.stepper.set_memory(self.memory)
            raise StepRefused(self.name, t, h, f"the step would end out of the state's bounds: "
                              f"{why}")
        self.x, self.t, self.u_held = x, t + h, u
        self.stats = (st.rhs_calls, st.substeps, active_level(self.model))
        self.memory = self.stepper.get_memory()

    def set_state(self, state) -> None:
        super().set_state(state)
        self.stepper.set_memory(self.memory)     # e.g. the level ``auto`` is at, for the outputs

    def get_outputs(self) -> list[float]:
        y = self.model.outputs(self.t, self.x, self.u_held)
        return [float(y[n]) for n in self._names] + [float(c) for c in self.stats]


def make_prsm_block(config: PRSMConfig, kind: str = "fmu", fmu_path=None, name: str = "prsm",
                    start_time: float = 0.0):
    """The PRSM block of ``config``: ``kind = "fmu"`` (fmpy, FMU at ``fmu_path``) or ``"python"``.

    The FMU block exposes the same ports as :class:`PythonPRSM`, in the same order.
    """
    if kind == "python":
        return PythonPRSM(config, name=name, start_time=start_time)
    if kind != "fmu":
        raise ValueError(f"prsm = {kind!r} is not allowed: must be 'fmu' or 'python'")
    from .fmu import FMUBlock

    config.solver()            # refuse unknown parameter names before loading anything
    n = config.n_stages
    start = dict(config.parameters)
    start["screw_torque"], start["load_force"] = config.initial_inputs
    return FMUBlock(fmu_path or f"dist/{config.mechanism}.fmu", name=name,
                    inputs=["screw_torque", "load_force"],
                    outputs=prsm_output_names(n) + list(COUNTERS), parameters=start,
                    start_time=start_time)
