"""The PRSM co-simulation slave: the FMU's variable table mapped onto one model, nothing else.

:class:`PRSMSlave` is a pythonfmu ``Fmi2Slave``.  It owns no physics: it builds a
:class:`~prsm_fmu.params.MechanismParams` from its parameters, a model with
:func:`~prsm_fmu.models.make_model` and a stepper with
:func:`~prsm_fmu.steppers.make_stepper`, and maps

* the inputs ``screw_torque`` [N.m] and ``load_force`` [N] onto the model inputs
  ``u = (screw_torque, load_force)`` (torque drive), held over each communication step;
* the model's outputs (DESIGN.md §4 names) onto output variables;
* every physical quantity of the mechanism onto a parameter ``stage[k].<field>``
  (fields of :class:`~prsm_fmu.params.StageParams`) or a friction parameter.

The FMU built for ``n`` stages is a one-line subclass (``class PRSM2(PRSMSlave)``) that
``fmu_build`` generates with the default parameter values of a preset (see docs/fmu.md).

Behaviour a host sees (docs/fmu.md gives the details):

* Parameters are checked in ``exitInitializationMode`` (``MechanismParams.validate`` and
  the FMU's own parameters); an out-of-range value is logged with the ``ValueError``
  message naming it and its range, and initialization fails (fmi2Fatal: pythonfmu turns
  any Python exception into fmi2Fatal).
* ``doStep`` refuses (returns False, i.e. fmi2Discard) a step with non-finite inputs, a
  non-finite or non-positive step size, or an integration that fails
  (:class:`~prsm_fmu.steppers.StepFailure`); the reason is logged and the FMU's state is
  exactly what it was before the call.
* Outputs are computed on demand from the state at the last communication point and the
  inputs held over the last step: a ``doStep`` costs the integration only, the first
  ``fmi2GetReal`` of an output after it costs one ``Model.outputs`` call.  Setting inputs
  does not change the outputs before the next step (no direct feedthrough).
* The FMU state (``fmi2GetFMUstate`` / ``fmi2SerializeFMUstate``) holds the parameters, the
  inputs, the time, the model state vector (with the accumulated energies), the inputs
  held over the last step and the stepper's memory, so that get → step → set → step
  repeats the step bit for bit, also in another instance after (de)serialization.
"""

from __future__ import annotations

import ctypes
import io
import math
import pickle
from dataclasses import dataclass
from typing import Any, Callable

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from . import __version__
from .configure import (ATOL_FACTOR, AUTO_FIDELITY, FIDELITY_CHOICES, STEPPER_CHOICES,
                        LEVEL_CODES, active_level, configure)
from .params import MAX_MU_DIFFERENTIAL, MechanismParams, StageParams, stage_field_names
from .simulate import DEFAULT_STEPPER
from .steppers import StepFailure

#: the FMU's fidelity and stepper choices, what ``auto`` picks at the default start and the
#: absolute-tolerance factor: one definition for the FMU and the loop (prsm_fmu/configure.py)
FMU_FIDELITIES = FIDELITY_CHOICES
FMU_STEPPERS = STEPPER_CHOICES

_INF = math.inf


# -------------------------------------------------------------------------------------------
# the variable table
# -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Var:
    """One row of the FMU's variable table.

    Attributes
    ----------
    name : str
        Structured FMI name, e.g. ``stage[2].contact_force``.
    type : {"Real", "Integer", "Boolean", "String"}
        FMI type.
    causality : {"parameter", "input", "output"}
        FMI causality.
    variability : {"fixed", "continuous", "discrete"}
        FMI variability (always written explicitly).
    unit : str or None
        Unit of a Real (FMI unit syntax: ``N.m``, ``kg.m2``, ``rad/s``; ``1`` = dimensionless).
    description : str
        What it is.
    min, max : float or int or None
        Bounds that physics (or the parameter's validation) imposes.
    """

    name: str
    type: str
    causality: str
    variability: str
    unit: str | None
    description: str
    min: float | int | None = None
    max: float | int | None = None


#: per-stage parameters: field -> (type, unit, description, min, max); every field of
#: StageParams must be here (checked when the table is built)
STAGE_FIELDS: dict[str, tuple] = {
    "screw_radius": ("Real", "m", "nominal (pitch) radius of the screw r_S", 0.0, None),
    "roller_radius": ("Real", "m", "nominal (pitch) radius of a roller r_R", 0.0, None),
    "nut_radius": ("Real", "m", "nominal (pitch) radius of the nut r_N; must equal r_S + 2 r_R "
                   "= screw_starts * r_R", 0.0, None),
    "screw_lead": ("Real", "m", "lead of the screw L_S = screw_starts * pitch", 0.0, None),
    "screw_starts": ("Integer", None, "thread starts of the screw and of the nut n_S", 1, None),
    "flank_angle": ("Real", "rad", "flank angle of the thread beta, in (0, pi/2)", 0.0, math.pi / 2),
    "n_rollers": ("Integer", None, "number of rollers N_R", 1, None),
    "screw_mass": ("Real", "kg", "mass of the screw (stage 1: unused, screw 1 does not translate)",
                   0.0, None),
    "nut_mass": ("Real", "kg", "mass of the nut", 0.0, None),
    "roller_mass": ("Real", "kg", "mass of one roller", 0.0, None),
    "carrier_mass": ("Real", "kg", "mass of one carrier", 0.0, None),
    "screw_inertia": ("Real", "kg.m2", "moment of inertia of the screw about its axis", 0.0, None),
    "roller_inertia": ("Real", "kg.m2", "moment of inertia of one roller about its own axis",
                       0.0, None),
    "carrier_inertia": ("Real", "kg.m2", "moment of inertia of one carrier about the screw axis",
                        0.0, None),
    "spline_radius": ("Real", "m", "radius of the spline teeth that drive this screw from the "
                      "previous one (stage 1: unused; > 0 if mu_spline > 0)", 0.0, None),
    "bearing_radius": ("Real", "m", "friction radius of the thrust bearing between this nut and the "
                       "next screw (last stage: unused; > 0 if mu_nut_screw > 0)", 0.0, None),
    "carriers": ("Integer", None, "carriers per stage", 1, None),
    # seed 003's friction terms (003_e265d1d1167b0d4b.txt): engaged threads per roller
    "threads_per_roller": ("Integer", None, "engaged thread turns per roller n_t (the viscous "
                           "friction acts per engaged thread)", 1, None),
}

#: mechanism-level parameters (fields of MechanismParams)
MECHANISM_FIELDS: dict[str, tuple] = {
    "mu_screw_roller": ("Real", "1", "Coulomb friction coefficient at the screw-roller thread "
                        "contacts, in [0, 1)", 0.0, 1.0),
    "mu_spline": ("Real", "1", "Coulomb friction coefficient between the spline teeth of "
                  "consecutive screws, in [0, 1)", 0.0, 1.0),
    "mu_nut_screw": ("Real", "1", "Coulomb friction coefficient of the thrust bearings between "
                     "nut k and screw k+1, in [0, 1)", 0.0, 1.0),
    "slip_velocity_scale": ("Real", "m/s", "sliding speed below which Coulomb friction is "
                            "regularised (viscous)", 0.0, None),
    # seed 003's friction terms (003_e265d1d1167b0d4b.txt)
    "mu_viscous": ("Real", "N.s/m", "lubricant viscous coefficient at the screw-roller contacts "
                   "per engaged thread (force mu_viscous * threads_per_roller * slip per roller), "
                   ">= 0", 0.0, None),
    "mu_differential": ("Real", "m", "differential-sliding coefficient: torque mu_differential * "
                        "normal force on the screw against its rotation, in [0, 0.001] m",
                        0.0, MAX_MU_DIFFERENTIAL),
}

#: the FMU's own parameters: name -> (type, unit, description, min, max, default)
SOLVER_FIELDS: dict[str, tuple] = {
    "fidelity": ("String", None, "model level: kinematic, quasi-static, dynamic or auto (auto: the "
                 "cheapest level whose estimated model error at the start is within tolerance)", None, None, "quasi-static"),
    "tolerance": ("Real", "1", "relative local error tolerance of the adaptive steppers "
                  "(absolute tolerance: 0.01 * tolerance in rad, rad/s and J)", 0.0, 1.0, 1e-6),
    "stepper": ("String", None, "time stepper inside a communication step: default (closed_form "
                "for kinematic and quasi-static, rosenbrock for dynamic), closed_form, "
                "explicit_adaptive, rosenbrock, rk4 or radau", None, None, "default"),
    "substeps": ("Integer", None, "0: internal steps chosen by the stepper to meet tolerance; "
                 "n >= 1: n equal internal steps per communication step without error control "
                 "(benchmarks; required for rk4)", 0, None, 0),
    "max_substeps": ("Integer", None, "most internal steps (accepted + rejected) per "
                     "communication step of the adaptive steppers; a step that needs more is "
                     "refused", 1, None, 100000),
    "kinematic_efficiency": ("Real", "1", "constant forward efficiency of the kinematic level, "
                             "in (0, 1]", 0.0, 1.0, 1.0),
    "initial_screw_speed": ("Real", "rad/s", "screw speed at the start time", None, None, 0.0),
    "initial_screw_angle": ("Real", "rad", "screw angle at the start time (rod_position = "
                            "screw_angle * total lead / 2 pi)", None, None, 0.0),
    "initial_carrier_equilibrium": ("Boolean", None, "dynamic level: true starts the carriers at "
                                    "their equilibrium speed ratio, false at rest", None, None,
                                    False),
}

#: inputs: name -> (unit, description)
INPUTS: dict[str, tuple] = {
    "screw_torque": ("N.m", "torque applied to screw 1 by the motor, positive extends the rod"),
    "load_force": ("N", "external axial force on the output (last) nut; positive resists "
                   "extension"),
}

#: outputs before the per-stage ones: name -> (unit, description, min)
OUTPUTS_HEAD: dict[str, tuple] = {
    "screw_speed": ("rad/s", "angular speed of screw 1 (input shaft)", None),
    "screw_angle": ("rad", "angle of screw 1 (input shaft)", None),
    "screw_acceleration": ("rad/s2", "angular acceleration of screw 1 at the end of the step",
                           None),
    "rod_position": ("m", "extension of the output rod (last nut) from its start", None),
    "rod_velocity": ("m/s", "extension speed of the output rod", None),
}

#: per-stage outputs: field -> (unit, description, min)
OUTPUTS_STAGE: dict[str, tuple] = {
    "contact_force": ("N", "axial component of the screw-roller contact force", None),
    "normal_force": ("N", "normal screw-roller contact force (all rollers)", None),
    "driven_torque": ("N.m", "torque driving the screw of this stage", None),
    "spline_friction": ("N", "screw-screw spline friction force (0 for stage 1)", None),
    "carrier_speed": ("rad/s", "angular speed of the carriers", None),
    "carrier_speed_ratio": ("1", "carrier speed / screw speed (0 at standstill)", None),
}

#: outputs after the per-stage ones: name -> (unit, description, min)
OUTPUTS_TAIL: dict[str, tuple] = {
    "efficiency": ("1", "instantaneous efficiency: output power / input power when driving, "
                   "input / output power when back-driven, 0 otherwise", None),
    "friction_power": ("W", "power lost to friction", None),
    "input_power": ("W", "power delivered by the motor torque", None),
    "output_power": ("W", "power delivered to the load force", None),
    "input_work": ("J", "work done by the motor torque since the start", None),
    "output_work": ("J", "work done on the load force since the start", None),
    "friction_work": ("J", "energy lost to friction since the start", None),
    "kinetic_energy": ("J", "kinetic energy of all moving parts", 0.0),
}

#: Integer diagnostics of the last step: name -> description
STEP_COUNTERS: dict[str, str] = {
    "step_rhs_calls": "right-hand-side evaluations of the last communication step",
    "step_substeps": "accepted internal steps of the last communication step",
    "step_fidelity": "level the outputs come from: 0 kinematic, 1 quasi-static, 2 dynamic "
                     "(with fidelity = auto, the level of the last communication step)",
}


def output_names(n_stages: int) -> tuple[str, ...]:
    """Names of the FMU's Real outputs for ``n_stages`` stages, in table order."""
    names = list(OUTPUTS_HEAD)
    for k in range(1, n_stages + 1):
        names += [f"stage[{k}].{f}" for f in OUTPUTS_STAGE]
    return tuple(names + list(OUTPUTS_TAIL))


def variable_table(n_stages: int) -> list[Var]:
    """The FMU's variables for ``n_stages`` stages, in value-reference order.

    Raises
    ------
    KeyError
        If a field of StageParams has no row in :data:`STAGE_FIELDS` (the table must describe
        every physical quantity).
    """
    missing = [f for f in stage_field_names() if f not in STAGE_FIELDS]
    if missing:
        raise KeyError(f"StageParams fields without an FMU parameter row: {missing}")
    rows: list[Var] = []
    for name, (unit, desc) in INPUTS.items():
        rows.append(Var(name, "Real", "input", "continuous", unit, desc))
    for name, (unit, desc, lo) in OUTPUTS_HEAD.items():
        rows.append(Var(name, "Real", "output", "continuous", unit, desc, lo))
    for k in range(1, n_stages + 1):
        for f, (unit, desc, lo) in OUTPUTS_STAGE.items():
            rows.append(Var(f"stage[{k}].{f}", "Real", "output", "continuous", unit,
                            f"stage {k}: {desc}", lo))
    for name, (unit, desc, lo) in OUTPUTS_TAIL.items():
        rows.append(Var(name, "Real", "output", "continuous", unit, desc, lo))
    for name, desc in STEP_COUNTERS.items():
        rows.append(Var(name, "Integer", "output", "discrete", None, desc, 0))
    for k in range(1, n_stages + 1):
        for f in stage_field_names():
            typ, unit, desc, lo, hi = STAGE_FIELDS[f]
            rows.append(Var(f"stage[{k}].{f}", typ, "parameter", "fixed", unit,
                            f"stage {k}: {desc}", lo, hi))
    for name, (typ, unit, desc, lo, hi) in MECHANISM_FIELDS.items():
        rows.append(Var(name, typ, "parameter", "fixed", unit, desc, lo, hi))
    for name, (typ, unit, desc, lo, hi, _default) in SOLVER_FIELDS.items():
        rows.append(Var(name, typ, "parameter", "fixed", unit, desc, lo, hi))
    return rows


def parameter_defaults(params: MechanismParams) -> dict[str, Any]:
    """Start values of every parameter of the FMU built from ``params`` (name -> value)."""
    values: dict[str, Any] = {}
    for k, st in enumerate(params.stages, start=1):
        for f in stage_field_names():
            values[f"stage[{k}].{f}"] = getattr(st, f)
    for f in MECHANISM_FIELDS:
        values[f] = getattr(params, f)
    for name, row in SOLVER_FIELDS.items():
        values[name] = row[-1]
    return values


# -------------------------------------------------------------------------------------------
# pythonfmu variables that carry unit, min and max (pythonfmu 0.7 writes neither)
# -------------------------------------------------------------------------------------------


def _fmt(value: Any) -> str:
    """Exact text of a start/min/max value (repr keeps every bit of a float)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _with_attributes(cls: type) -> type:
    class _Var(cls):  # type: ignore[misc, valid-type]
        def __init__(self, name: str, unit=None, vmin=None, vmax=None, **kwargs) -> None:
            super().__init__(name, **kwargs)
            self.unit, self.vmin, self.vmax = unit, vmin, vmax

        def to_xml(self):
            node = super().to_xml()
            typed = node[0]
            if "start" in typed.attrib and self.start is not None:
                typed.set("start", _fmt(self.start))
            for key, value in (("unit", self.unit), ("min", self.vmin), ("max", self.vmax)):
                if value is not None:
                    typed.set(key, _fmt(value))
            return node

    _Var.__name__ = _Var.__qualname__ = f"_{cls.__name__}"
    return _Var


_VAR_CLASSES = {t.__name__: _with_attributes(t) for t in (Real, Integer, Boolean, String)}
_CAUSALITY = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input,
              "output": Fmi2Causality.output}
_VARIABILITY = {"fixed": Fmi2Variability.fixed, "continuous": Fmi2Variability.continuous,
                "discrete": Fmi2Variability.discrete}
_COERCE: dict[str, Callable[[Any], Any]] = {"Real": float, "Integer": int, "Boolean": bool,
                                            "String": str}
_NEUTRAL = {"Real": math.nan, "Integer": 0, "Boolean": False, "String": ""}


# -------------------------------------------------------------------------------------------
# FMU state serialization: a pickle of plain builtins only (no classes can be loaded)
# -------------------------------------------------------------------------------------------

_STATE_TAG = "prsm-fmu-state/1"
_STATE_MAGIC = b"PRSMFMU1"
_INVALID = "invalid PRSM FMU state"


class _BuiltinsOnly(pickle.Unpickler):
    def find_class(self, module: str, name: str):  # noqa: D102 - refuse every global
        raise pickle.UnpicklingError(f"FMU state bytes refer to {module}.{name}: not a PRSM FMU state")


# -------------------------------------------------------------------------------------------
# the slave
# -------------------------------------------------------------------------------------------


class PRSMSlave(Fmi2Slave):
    """Co-simulation slave of an n-stage PRSM (see module docstring).

    Subclasses (generated by ``fmu_build``) set :attr:`defaults` (the parameter start values,
    see :func:`parameter_defaults`), :attr:`preset` and the FMI class attributes
    (``description``, ``default_experiment``).  Without ``defaults`` the slave takes them
    from the preset named by :attr:`preset`.
    """

    #: parameter name -> start value (every parameter of :func:`variable_table`)
    defaults: dict[str, Any] | None = None
    #: registry key of the preset the defaults come from (documentation, fallback defaults)
    preset: str = "seed000_two_stage"
    author = "prsm-fmu"
    version = __version__

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        defaults = self.defaults
        if defaults is None:
            from . import presets

            defaults = parameter_defaults(presets.load(self.preset))
        n = sum(1 for name in defaults if name.endswith(".screw_radius"))
        self.n_stages = n
        self._table = variable_table(n)
        self._par: dict[str, Any] = {}
        self._par_names: list[str] = []
        self._u = [0.0, 0.0]
        self._out_names = output_names(n)
        self._rget: dict[int, Callable[[], float]] = {}
        self._rset: dict[int, Callable[[Any], None]] = {}
        # run-time state (see _get_fmu_state)
        self._phase = "instantiated"        # -> "initialization" -> "stepping"
        self._t = 0.0
        self._x: list[float] | None = None
        self._u_held = (0.0, 0.0)
        self._stats = (0, 0, 0)
        self._model = None
        self._stepper = None
        self._config: tuple = ()
        self._y: list[float] | None = None
        self._preview: tuple = (None, None)
        self._register(defaults)

    # ---- variable registration -----------------------------------------------------------
    def _register(self, defaults: dict[str, Any]) -> None:
        i_out = {name: i for i, name in enumerate(self._out_names)}
        for row in self._table:
            cls = _VAR_CLASSES[row.type]
            if row.causality == "parameter":
                if row.name not in defaults:
                    raise KeyError(f"no start value for parameter {row.name!r}")
                self._par[row.name] = _COERCE[row.type](defaults[row.name])
                self._par_names.append(row.name)
                getter, setter = self._param_access(row.name, _COERCE[row.type])
            elif row.causality == "input":
                getter, setter = self._input_access(0 if row.name == "screw_torque" else 1)
            elif row.type == "Real":
                getter, setter = self._output_access(i_out[row.name]), None
            else:
                getter, setter = self._counter_access(list(STEP_COUNTERS).index(row.name)), None
            var = cls(row.name, unit=row.unit, vmin=row.min, vmax=row.max,
                      causality=_CAUSALITY[row.causality], variability=_VARIABILITY[row.variability],
                      description=row.description, getter=getter, setter=setter)
            self.register_variable(var, nested=False)
            if row.type == "Real":
                self._rget[var.value_reference] = getter
                if setter is not None:
                    self._rset[var.value_reference] = setter

    def _param_access(self, name: str, coerce: Callable[[Any], Any]):
        par = self._par

        def getter():
            return par[name]

        def setter(value):
            if self._phase == "stepping":
                self.log(f"{name} is a fixed parameter: setting it to {value!r} after "
                         f"initialization is not allowed; the value stays {par[name]!r}",
                         Fmi2Status.error)
                return
            par[name] = coerce(value)
            self._y = None

        return getter, setter

    def _input_access(self, i: int):
        u = self._u

        def getter():
            return u[i]

        def setter(value):
            u[i] = float(value)

        return getter, setter

    def _output_access(self, i: int):
        def getter():
            y = self._y
            if y is None:
                y = self._compute_outputs()
            return y[i]

        return getter

    def _counter_access(self, i: int):
        if i == 2:          # step_fidelity: before initialization, the level asked for
            return lambda: (self._stats[2] if self._model is not None else LEVEL_CODES.get(
                AUTO_FIDELITY if self._par["fidelity"] == "auto" else self._par["fidelity"], 0))
        return lambda: self._stats[i]

    # Value access by reference.  The base class raises on a wrong type or a variable without
    # setter, which pythonfmu turns into fmi2Fatal; here a host's mistake is logged instead
    # (the value read is a neutral one, the value written is ignored).  Reals have a fast path.
    def get_real(self, vrs):
        g = self._rget
        try:
            return [g[vr]() for vr in vrs]
        except KeyError:
            return self._get_typed(vrs, "Real")

    def set_real(self, vrs, values):
        s = self._rset
        for vr, value in zip(vrs, values):
            setter = s.get(vr)
            if setter is None:
                self._set_typed([vr], [value], "Real")
            else:
                setter(value)

    def get_integer(self, vrs):
        return self._get_typed(vrs, "Integer")

    def get_boolean(self, vrs):
        return self._get_typed(vrs, "Boolean")

    def get_string(self, vrs):
        return self._get_typed(vrs, "String")

    def set_integer(self, vrs, values):
        self._set_typed(vrs, values, "Integer")

    def set_boolean(self, vrs, values):
        self._set_typed(vrs, values, "Boolean")

    def set_string(self, vrs, values):
        self._set_typed(vrs, values, "String")

    def _variable(self, vr, typ: str, action: str):
        var = self.vars.get(vr)
        if var is None or type(var) is not _VAR_CLASSES[typ]:
            what = "no variable" if var is None else f"{var.name!r}, not of type {typ}"
            self.log(f"fmi2{action}{typ}: value reference {vr} is {what}; ignored",
                     Fmi2Status.error)
            return None
        return var

    def _get_typed(self, vrs, typ: str) -> list:
        out = []
        for vr in vrs:
            var = self._variable(vr, typ, "Get")
            out.append(_NEUTRAL[typ] if var is None else _COERCE[typ](var.getter()))
        return out

    def _set_typed(self, vrs, values, typ: str) -> None:
        for vr, value in zip(vrs, values):
            var = self._variable(vr, typ, "Set")
            if var is None:
                continue
            if var.setter is None:
                self.log(f"fmi2Set{typ}: {var.name!r} is an output and cannot be set; ignored",
                         Fmi2Status.error)
            else:
                var.setter(value)

    # ---- configuration (parameters -> model, stepper, initial state) ----------------------
    def _build(self):
        """Model, stepper and initial state from the current parameter values.

        Raises
        ------
        ValueError
            Naming the parameter, its value and the allowed range.
        """
        par = self._par
        fields = stage_field_names()
        stages = tuple(StageParams(**{f: par[f"stage[{k}].{f}"] for f in fields})
                       for k in range(1, self.n_stages + 1))
        params = MechanismParams(stages=stages, name=f"{type(self).__name__} ({self.preset})",
                                 **{f: par[f] for f in MECHANISM_FIELDS}).validate()
        return configure(params, par, tuple(self._u))

    def _config_key(self) -> tuple:
        return tuple(self._par[n] for n in self._par_names)

    def _compute_outputs(self) -> list[float]:
        """Output values at the last communication point (never raises: NaN and a log)."""
        model, x, u = self._model, self._x, self._u_held
        key = None
        if model is None:  # before exitInitializationMode: outputs of the initial state
            key = (self._config_key(), tuple(self._u), self._t)
            if self._preview[0] == key:
                return self._preview[1]
        try:
            if model is None:
                model, _, x, _, _ = self._build()
                u = tuple(self._u)
            y = model.outputs(self._t, x, u)
            values = [float(y[name]) for name in self._out_names]
        except Exception as exc:  # noqa: BLE001 - an exception here would be fmi2Fatal
            self.log(f"outputs cannot be computed: {exc}", Fmi2Status.error)
            values = [math.nan] * len(self._out_names)
        if key is None:
            self._y = values
        else:
            self._preview = (key, values)
        return values

    # ---- FMI life cycle ----------------------------------------------------------------------
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None) -> None:
        self._t = float(start_time)

    def enter_initialization_mode(self) -> None:
        self._phase = "initialization"

    def exit_initialization_mode(self) -> None:
        try:
            model, stepper, x0, level, name = self._build()
        except Exception as exc:  # noqa: BLE001 - ValueError naming the parameter, or other
            what = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
            self._fail_visibly(f"initialization failed: {what}")
        if self._par["fidelity"] == "auto":
            along = ("; it switches between the dynamic and the quasi-static level along the run"
                     if model.fidelity == "auto" else "")
            self.log(f"fidelity = 'auto' starts with {model.auto_choice.describe()}{along}",
                     Fmi2Status.ok)
        self._model, self._stepper, self._x = model, stepper, x0
        self._u_held = (self._u[0], self._u[1])
        self._config = self._config_key()
        self._stats = (0, 0, active_level(model))
        self._y = None
        self._phase = "stepping"

    def do_step(self, current_time: float, step_size: float) -> bool:
        u = (self._u[0], self._u[1])
        h = step_size
        if self._stepper is None:
            return self._refuse("doStep before a successful exitInitializationMode")
        if not (0.0 < h < _INF):
            return self._refuse(f"communication step size = {h!r} s is out of range: must be a "
                                "finite number > 0")
        if not (math.isfinite(u[0]) and math.isfinite(u[1])):
            return self._refuse(f"inputs screw_torque = {u[0]!r} N.m, load_force = {u[1]!r} N: "
                                "every input must be finite")
        if not math.isfinite(current_time):
            return self._refuse(f"currentCommunicationPoint = {current_time!r} s must be finite")
        stepper = self._stepper
        memory = stepper.get_memory()
        try:
            x, stats = stepper.advance(current_time, self._x, u, h)
        except Exception as exc:  # noqa: BLE001 - StepFailure; anything else would be fmi2Fatal
            stepper.set_memory(memory)
            what = str(exc) if isinstance(exc, StepFailure) else f"{type(exc).__name__}: {exc}"
            return self._refuse(f"integration failed: {what}")
        self._x = x
        self._t = current_time + h
        self._u_held = u
        self._stats = (stats.rhs_calls, stats.substeps, active_level(self._model))
        self._y = None
        return True

    def _fail_visibly(self, message: str) -> None:
        """Log ``message`` as an error and raise it: pythonfmu turns the exception into fmi2Fatal.

        pythonfmu 0.7 releases the instance's references to the slave, its class and its log
        queue twice after a Python exception (once when it reports the exception, again in
        fmi2FreeInstance).  The references taken here pay for the second release, so that
        freeing the failed instance does not free objects still in use.
        """
        self.log(message, Fmi2Status.error)
        for obj in (type(self), self, self.log_queue):
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
        raise ValueError(message)

    def _refuse(self, reason: str) -> bool:
        self.log(f"doStep refused, state unchanged: {reason}", Fmi2Status.discard)
        return False

    # ---- FMU state -------------------------------------------------------------------------
    def _get_fmu_state(self) -> tuple:
        memory = None if self._stepper is None else self._stepper.get_memory()
        x = None if self._x is None else tuple(self._x)
        return (_STATE_TAG, type(self).__name__, self.n_stages, self._config_key(),
                (self._u[0], self._u[1]), self._phase, self._t, x, self._u_held, memory,
                self._stats)

    def _set_fmu_state(self, state: tuple) -> None:
        if isinstance(state, tuple) and len(state) == 2 and state[0] == _INVALID:
            self._fail_visibly(f"fmi2SetFMUstate: {state[1]}")
        try:
            tag, model_name, n, config, u, phase, t, x, u_held, memory, stats = state
        except (TypeError, ValueError):
            self._fail_visibly(f"fmi2SetFMUstate: not a PRSM FMU state: {type(state).__name__}")
        if tag != _STATE_TAG or model_name != type(self).__name__ or n != self.n_stages \
                or len(config) != len(self._par_names):
            self._fail_visibly(
                f"fmi2SetFMUstate: a state of {model_name!r} ({n} stages, format {tag!r}) cannot "
                f"be set in {type(self).__name__!r} ({self.n_stages} stages, format {_STATE_TAG!r})")
        config = tuple(config)
        model = stepper = None
        if phase == "stepping":
            saved = dict(self._par)
            try:
                if self._stepper is not None and config == self._config:
                    model, stepper = self._model, self._stepper
                else:
                    self._par.update(zip(self._par_names, config))
                    model, stepper, _x0, _level, _name = self._build()
                stepper.set_memory(memory)
            except Exception as exc:  # noqa: BLE001 - invalid parameters or memory in the state
                self._par.update(saved)
                self._fail_visibly(f"fmi2SetFMUstate: the state cannot be restored: {exc}")
        self._par.update(zip(self._par_names, config))
        self._model, self._stepper = model, stepper
        self._config = config if stepper is not None else ()
        self._u[0], self._u[1] = u
        self._phase = phase
        self._t = t
        self._x = None if x is None else list(x)
        self._u_held = u_held
        self._stats = stats
        self._y = None

    @staticmethod
    def _fmu_state_to_bytes(state: tuple) -> bytes:
        return _STATE_MAGIC + pickle.dumps(state, protocol=4)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes) -> tuple:
        # Bad bytes give an "invalid" state that fmi2SetFMUstate reports: an exception here
        # would end the instance without a message that names the problem.
        if not data.startswith(_STATE_MAGIC):
            return (_INVALID, "the bytes are not a serialized PRSM FMU state (bad header)")
        try:
            state = _BuiltinsOnly(io.BytesIO(data[len(_STATE_MAGIC):])).load()
        except Exception as exc:  # noqa: BLE001 - any unpickling error
            return (_INVALID, f"the bytes are not a serialized PRSM FMU state ({exc})")
        if not (isinstance(state, tuple) and state and state[0] == _STATE_TAG):
            return (_INVALID, "the bytes are not a serialized PRSM FMU state (bad content)")
        return state


__all__ = ["PRSMSlave", "Var", "variable_table", "parameter_defaults", "output_names",
           "FMU_FIDELITIES", "FMU_STEPPERS", "AUTO_FIDELITY", "DEFAULT_STEPPER", "ATOL_FACTOR"]
