"""The PRSM co-simulation slave: the FMU's variable table mapped onto one model, nothing else.

:class:`PRSMSlave` is a pythonfmu ``Fmi2Slave``.  It owns no physics: it builds a
:class:`~prsm_fmu.params.MechanismParams` from its parameters, and a model and a stepper with
:func:`~prsm_fmu.configure.configure`: the compiled engine packed in the FMU
(:mod:`prsm_fmu.engine`; its start values and engine library are read from the instance's own
resources) where it runs the configuration, else a Python stepper (logged, with the reason), and
maps

* the inputs ``screw_torque`` [N.m] and ``load_force`` [N] onto the model inputs
  ``u = (screw_torque, load_force)`` (torque drive), held over each communication step;
* the model's outputs (the names of docs/fmu.md, "Variables") onto output variables;
* every physical quantity of the mechanism onto a parameter ``stage[k].<field>``
  (fields of :class:`~prsm_fmu.params.StageParams`) or a friction parameter.

The FMU built for ``n`` stages is a one-line subclass (``class PRSM2(PRSMSlave)``) that
``fmu_build`` generates with the default parameter values of a preset (see docs/fmu.md).

Behaviour a host sees (docs/fmu.md, "Errors", gives the table):

* ``fidelity`` and ``stepper`` are FMI 2.0 Enumerations (``Fidelity``, ``Stepper``): Integers
  to ``fmi2SetInteger``/``fmi2GetInteger``, with item names and descriptions in the
  modelDescription's TypeDefinitions (:data:`prsm_fmu.configure.ENUMERATIONS`).
* No recoverable error leaves the slave as a Python exception: pythonfmu 0.7 turns every one
  into fmi2Fatal (and libcosim or OMSimulator then end the whole process).  Only ``doStep``
  can return another status (False is fmi2Discard), so every refusal ends there:

  - parameters are checked in ``exitInitializationMode``, which returns fmi2OK and logs an
    out-of-range value (the ``ValueError`` naming it, with its stage index and range) as an
    error; every ``doStep`` is then refused (fmi2Discard) with that message, until fmi2Reset;
  - a call the FMU refuses at once (a variable through the wrong type, an output or a fixed
    parameter set, a call out of FMI's order, a state that fails validation) returns fmi2OK,
    logs the refusal as an error naming the call and the variable, changes nothing, and the
    next ``doStep`` is refused naming it (once: a retry goes on);
  - ``doStep`` refuses a wrong communication point, a step size that is not finite and > 0,
    non-finite inputs and a failed integration (:class:`~prsm_fmu.steppers.StepFailure`),
    the state exactly as before the call.
* Outputs are computed on demand from the state at the last communication point and the
  inputs held over the last step: a ``doStep`` costs the integration only, the first
  ``fmi2GetReal`` of an output after it costs one ``Model.outputs`` call.  Setting inputs
  does not change the outputs before the next step (no direct feedthrough).
* The FMU state (``fmi2GetFMUstate`` / ``fmi2SerializeFMUstate``, :mod:`prsm_fmu.fmu_state`)
  holds the parameters, the inputs, the phase, the time, the model state vector (with the
  accumulated energies), the inputs held over the last step and the stepper's memory, so
  that get → step → set → step repeats the step bit for bit, also in another instance after
  (de)serialization; a state is validated whole before anything of it is restored.
* :mod:`prsm_fmu.fmu_exit` makes the process exit safe from pythonfmu 0.7's exit-time
  use-after-free (the intermittent ``corrupted double-linked list`` abort).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from operator import itemgetter
from typing import Any, Callable

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from . import __version__, fmu_exit, fmu_state
from .configure import (ATOL_FACTOR, AUTO_FIDELITY, ENUMERATIONS, FIDELITY_CHOICES,
                        FIDELITY_ITEMS, LEVEL_CODES, MAX_INITIAL_ANGLE, MAX_INITIAL_SPEED,
                        MAX_SUBSTEPS_RANGE, STEPPER_CHOICES, STEPPER_ITEMS, TOLERANCE_RANGE,
                        active_level, configure, fidelity_name)
from .param_ranges import input_violation, state_violation
from .params import (MAX_MU_DIFFERENTIAL, MAX_MU_VISCOUS, MAX_THREADS_PER_ROLLER,
                     MechanismParams, StageParams, stage_field_names)
from .engine import (ENGINE_ENV, fallback_reason, is_engine, library_name,
                     library_solves_geometry, platform_folder)
from .models.base import model_speed_bounds, undefined_allowed
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
    type : {"Real", "Integer", "Boolean", "Enumeration:<declared type>"}
        FMI type; an Enumeration names its type of :data:`ENUMERATIONS` (an Integer to the
        FMI functions: fmi2GetInteger / fmi2SetInteger).
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
    "n_rollers": ("Integer", None, "number of rollers N_R, at most pi / asin(r_R / (r_S + r_R)) "
                  "(they fit around the screw)", 1, None),
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
    "carriers": ("Integer", None, "carriers per stage: 1 or 2 (one at each end of the rollers)", 1, 2),
    # the friction-torque article's friction terms: engaged threads per roller
    "threads_per_roller": ("Integer", None, "engaged thread turns per roller n_t (the viscous "
                           "friction acts per engaged thread), in [1, 1000]", 1,
                           MAX_THREADS_PER_ROLLER),
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
    # the friction-torque article's friction terms
    "mu_viscous": ("Real", "N.s/m", "lubricant viscous coefficient at the screw-roller contacts "
                   "per engaged thread (force mu_viscous * threads_per_roller * slip per roller), "
                   "in [0, 1e5] N.s/m", 0.0, MAX_MU_VISCOUS),
    "mu_differential": ("Real", "m", "differential-sliding coefficient: torque mu_differential * "
                        "normal force on the screw against its rotation, in [0, 0.001] m",
                        0.0, MAX_MU_DIFFERENTIAL),
}

#: the FMU's own parameters: name -> (type, unit, description, min, max, default)
SOLVER_FIELDS: dict[str, tuple] = {
    "fidelity": ("Enumeration:Fidelity", None, "model level: kinematic, quasi-static, dynamic or "
                 "auto (auto: the cheapest level whose estimated model error meets tolerance, "
                 "chosen along the run)", None, None, FIDELITY_ITEMS["quasi-static"][0]),
    "tolerance": ("Real", "1", "relative local error tolerance of the adaptive steppers "
                  "(absolute tolerance: 0.01 * tolerance in rad, rad/s and J)",
                  TOLERANCE_RANGE[0], TOLERANCE_RANGE[1], 1e-6),
    "stepper": ("Enumeration:Stepper", None, "time stepper inside a communication step: default "
                "(closed_form for kinematic and quasi-static, rosenbrock for dynamic), closed_form, "
                "explicit_adaptive, rosenbrock, rk4, radau, exponential or closed_form_explicit", None, None,
                STEPPER_ITEMS["default"][0]),
    "substeps": ("Integer", None, "0: internal steps chosen by the stepper to meet tolerance; "
                 "n >= 1: n equal internal steps per communication step without error control "
                 "(benchmarks; required for rk4); at most max_substeps", 0, MAX_SUBSTEPS_RANGE[1], 0),
    "max_substeps": ("Integer", None, "most internal steps (accepted + rejected) per "
                     "communication step; a step that needs more is refused (bounds the work of "
                     "one doStep)", MAX_SUBSTEPS_RANGE[0], MAX_SUBSTEPS_RANGE[1], 100000),
    "kinematic_efficiency": ("Real", "1", "constant forward efficiency of the kinematic level, "
                             "in (0, 1]", 0.0, 1.0, 1.0),
    "initial_screw_speed": ("Real", "rad/s", "screw speed at the start time",
                            -MAX_INITIAL_SPEED, MAX_INITIAL_SPEED, 0.0),
    "initial_screw_angle": ("Real", "rad", "screw angle at the start time (rod_position = "
                            "screw_angle * total lead / 2 pi)", -MAX_INITIAL_ANGLE,
                            MAX_INITIAL_ANGLE, 0.0),
    "initial_carrier_equilibrium": ("Boolean", None, "dynamic level: true starts the carriers at "
                                    "their equilibrium speed ratio, false at rest", None, None,
                                    False),
}

#: the Enumeration parameters and their declared types
ENUM_PARAMETERS = {name: row[0].split(":", 1)[1] for name, row in SOLVER_FIELDS.items()
                   if row[0].startswith("Enumeration:")}

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
                   "input / output power when back-driven; NaN where no power passes through "
                   "(standstill |screw_speed| <= 8.9e-12 rad/s, or both sides delivering or "
                   "both absorbing power)", None),
    "friction_power": ("W", "power lost to friction", None),
    "friction_power_coulomb": ("W", "part of friction_power lost to Coulomb sliding at the "
                               "screw-roller contacts", None),
    "friction_power_viscous": ("W", "part of friction_power lost to the lubricant's viscous "
                               "force at the screw-roller contacts", None),
    "friction_power_differential": ("W", "part of friction_power lost to differential sliding "
                                    "(rolling resistance) at the screw-roller contacts", None),
    "friction_power_joints": ("W", "part of friction_power lost in the splines and thrust "
                              "bearings between stages", None),
    "screw_friction_torque": ("N.m", "friction torque on the screw: motor torque minus the "
                              "ideal load torque and the inertial torque", None),
    "input_power": ("W", "power delivered by the motor torque", None),
    "output_power": ("W", "power delivered to the load force", None),
    "input_work": ("J", "work done by the motor torque since the start", None),
    "output_work": ("J", "work done on the load force since the start", None),
    "friction_work": ("J", "energy lost to friction since the start", None),
    "kinetic_energy": ("J", "kinetic energy of all moving parts", 0.0),
    "overall_efficiency": ("1", "overall efficiency since the start: output_work / input_work "
                           "(0 before any input work)", None),
}

#: Integer diagnostics of the last step: name -> description
STEP_COUNTERS: dict[str, str] = {
    "step_rhs_calls": "right-hand-side evaluations of the last communication step",
    "step_substeps": "accepted internal steps of the last communication step",
    "step_fidelity": "level the outputs come from (kinematic, quasi-static or dynamic; with "
                     "fidelity = auto, the level of the last communication step)",
    "contact_status": "1 where the rigid contact has no solution at the current state and inputs "
                      "(Painleve: no acceleration balances the torque; a doStep from here is "
                      "refused naming the cause), else 0",
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
        typ = "Enumeration:Fidelity" if name == "step_fidelity" else "Integer"
        rows.append(Var(name, typ, "output", "discrete", None, desc,
                        0 if typ == "Integer" else None))
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


def _with_attributes(cls: type, fmi_type: str | None = None) -> type:
    """pythonfmu variable class ``cls`` that writes unit, min, max and exact start values;
    with ``fmi_type = "Enumeration:<type>"`` an Integer written as that Enumeration."""
    declared = fmi_type.split(":", 1)[1] if fmi_type else None

    class _Var(cls):  # type: ignore[misc, valid-type]
        fmi_name = fmi_type or cls.__name__

        def __init__(self, name: str, unit=None, vmin=None, vmax=None, **kwargs) -> None:
            super().__init__(name, **kwargs)
            self.unit, self.vmin, self.vmax = unit, vmin, vmax

        def to_xml(self):
            node = super().to_xml()
            typed = node[0]
            if declared is not None:
                typed.tag = "Enumeration"
                typed.set("declaredType", declared)
            if "start" in typed.attrib and self.start is not None:
                typed.set("start", _fmt(self.start))
            for key, value in (("unit", self.unit), ("min", self.vmin), ("max", self.vmax)):
                if value is not None:
                    typed.set(key, _fmt(value))
            return node

    _Var.__name__ = _Var.__qualname__ = f"_{(fmi_type or cls.__name__).replace(':', '_')}"
    return _Var


_VAR_CLASSES = {t.__name__: _with_attributes(t) for t in (Real, Integer, Boolean)}
_VAR_CLASSES.update({f"Enumeration:{e}": _with_attributes(Integer, f"Enumeration:{e}")
                     for e in ENUMERATIONS})
#: the FMI access functions' type -> the variable types they reach (an Enumeration is an
#: Integer to fmi2GetInteger/fmi2SetInteger)
_ACCESS = {"Real": ("Real",), "Boolean": ("Boolean",), "String": (),
           "Integer": ("Integer",) + tuple(f"Enumeration:{e}" for e in ENUMERATIONS)}
_CAUSALITY = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input,
              "output": Fmi2Causality.output}
_VARIABILITY = {"fixed": Fmi2Variability.fixed, "continuous": Fmi2Variability.continuous,
                "discrete": Fmi2Variability.discrete}
_COERCE: dict[str, Callable[[Any], Any]] = {"Real": float, "Integer": int, "Boolean": bool,
                                            "String": str}
_NEUTRAL = {"Real": math.nan, "Integer": 0, "Boolean": False, "String": ""}


def _fmi_type(row_type: str) -> str:
    """How the modelDescription names a variable of the table's ``row_type``."""
    return "Enumeration" if row_type.startswith("Enumeration:") else row_type


def _access_type(row_type: str) -> str:
    """The FMI get/set functions' type of a variable of ``row_type`` (Enumeration: Integer)."""
    return "Integer" if row_type.startswith("Enumeration:") else row_type


def type_definitions() -> dict[str, list[tuple[str, int, str]]]:
    """The Enumerations of the FMU's TypeDefinitions: name -> [(item, value, description)]."""
    return {name: [(item, code, desc) for item, (code, desc) in items.items()]
            for name, items in ENUMERATIONS.items()}


# -------------------------------------------------------------------------------------------
# the slave
# -------------------------------------------------------------------------------------------


#: the FMU's parameter start values, read by every instance from its own resources: two builds
#: of one modelIdentifier (e.g. ``--start fidelity=dynamic``) share the slave module in a
#: process (pythonfmu imports it once), never their start values
START_VALUES_FILE = "prsm_start_values.json"
#: what the FMU's build says about its engine library: ``{"geometry": {name: value}}``, the
#: parameters the library's built-in contact geometry was computed from
ENGINE_FILE = "prsm_engine.json"


def read_resource_json(resources: str | None, name: str) -> Any:
    """The JSON file ``name`` of an FMU's resources (None when absent or no resources)."""
    import json
    import os

    if not resources:
        return None
    path = os.path.join(resources, name)
    if not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def packed_engine(resources: str | None) -> tuple[str | None, dict[str, Any], str | None]:
    """The engine library an FMU packs for this platform: (its path, the geometry it was built
    with, None), or (None, {}, why it has none).  A slave outside an FMU (no ``resources``)
    gets (None, {}, None): the engine compiled for its parameters (:mod:`prsm_fmu.engine`)."""
    import os

    if not resources:
        return None, {}, None
    info = read_resource_json(resources, ENGINE_FILE)
    if info is None:
        return None, {}, "this FMU was built without the engine library"
    path = os.path.join(resources, "binaries", platform_folder(), library_name())
    if not os.path.isfile(path):
        return None, {}, f"this FMU has no engine library for platform {platform_folder()}"
    return path, dict(info["geometry"]), None


def _fixed_level(model) -> int | None:
    """The model's level code if it never changes along a run (None: ``auto``'s switching
    model, whose :func:`active_level` is read after every step)."""
    return None if hasattr(model, "mode") else active_level(model)


def _guarded(call: str, failed: Any = None):
    """Decorate an FMI entry point so that no Python exception leaves it.

    pythonfmu 0.7 turns every exception into fmi2Fatal and releases the instance; a defect of
    the slave caught here is logged as an error naming ``call`` and refused at the next doStep
    instead (the method returns ``failed``)."""
    def wrap(method):
        def entry(self, *args):
            try:
                return method(self, *args)
            except Exception as exc:  # noqa: BLE001 - see the docstring
                self._refused_call(f"{call}: internal error {type(exc).__name__}: {exc}")
                return failed(self, *args) if callable(failed) else failed
        entry.__name__, entry.__doc__ = method.__name__, method.__doc__
        return entry
    return wrap


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
    preset: str = "li2021_two_stage"
    author = "prsm-fmu"
    version = __version__

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        defaults = read_resource_json(self.resources, START_VALUES_FILE) or self.defaults
        if defaults is None:
            from . import presets

            defaults = parameter_defaults(presets.load(self.preset))
        #: the engine library packed in this FMU for this platform, the geometry it was built
        #: with, and why it cannot run here (None: it can)
        self._engine_path, self._engine_geometry, self._engine_missing = packed_engine(
            self.resources)
        #: whether the packed library solves the contact of any geometry (None: not yet asked;
        #: asked only when a geometry parameter differs from the library's build)
        self._engine_solves_geometry: bool | None = None
        n = sum(1 for name in defaults if name.endswith(".screw_radius"))
        self.n_stages = n
        self._table = variable_table(n)
        self._par: dict[str, Any] = {}
        self._par_names: list[str] = []
        self._par_types: list[type] = []
        self._u = [0.0, 0.0]
        self._out_names = output_names(n)
        #: the model's output dict -> the FMU's Real outputs in their order
        self._pick_outputs = itemgetter(*self._out_names)
        self._rget: dict[int, Callable[[], float]] = {}
        #: value reference of a Real output -> its position in the outputs (fmi2GetReal's path)
        self._out_index: dict[int, int] = {}
        #: the lists of value references fmi2GetReal read (at most READ_PLANS) and where
        #: their values are (_read_plan)
        self._read_plans: dict[tuple, tuple] = {}
        #: value references of the step counters -> their place in _counters(); what
        #: fmi2GetInteger read last and their places (None: not a step counter)
        self._counter_index: dict[int, int] = {}
        self._last_counters: tuple = (None, [None])
        #: the value references of the inputs screw_torque and load_force
        self._input_vrs: list[int] = []
        #: value reference of an Integer or Enumeration output -> its getter (fmi2GetInteger's)
        self._iget: dict[int, Callable[[], int]] = {}
        self._rset: dict[int, Callable[[Any], None]] = {}
        self._types: dict[int, str] = {}
        # run-time state (see _get_fmu_state)
        self._phase = "instantiated"
        self._t = 0.0
        self._x: list[float] | None = None
        self._u_held = (0.0, 0.0)
        self._stats = (0, 0, 0)
        self._model = None
        self._stepper = None
        self._level: int | None = None          # the model's level code, if it never changes
        #: value reference of an output that is a state -> its index in the state vector
        #: (``screw_speed``, ``screw_angle``: fmi2GetReal of those alone reads the state)
        self._state_outputs: dict[int, int] = {}
        #: the engine's outputs in C (EngineStepper.output_reader), or None: Model.outputs
        self._engine_outputs = None
        #: the engine's one-call step (EngineStepper.step_block: its block, step, state part),
        #: or None: every doStep is the checked one
        self._engine_step: tuple | None = None
        self._config: tuple = ()
        self._init_error: str | None = None
        self._y: list[float] | None = None
        self._preview: tuple = (None, None)
        self._refused: list[str] = []           # refused calls not yet reported by a doStep
        #: the last FMU states this instance made (the objects themselves, immutable tuples),
        #: each with whether its state vector is known within the state's bounds
        self._own_states: deque = deque(maxlen=OWN_STATES)
        self._register(defaults)
        fmu_exit.guard_library(self.resources, type(self).__name__)

    # ---- variable registration -----------------------------------------------------------
    def _register(self, defaults: dict[str, Any]) -> None:
        i_out = {name: i for i, name in enumerate(self._out_names)}
        for row in self._table:
            cls = _VAR_CLASSES[row.type]
            coerce = _COERCE[_access_type(row.type)]
            if row.causality == "parameter":
                if row.name not in defaults:
                    raise KeyError(f"no start value for parameter {row.name!r}")
                self._par[row.name] = coerce(defaults[row.name])
                self._par_names.append(row.name)
                self._par_types.append(coerce)
                getter, setter = self._param_access(row.name, row.type, coerce)
            elif row.causality == "input":
                getter, setter = self._input_access(row.name,
                                                    0 if row.name == "screw_torque" else 1)
            elif row.type == "Real":
                getter, setter = self._output_access(i_out[row.name]), None
            else:
                getter, setter = self._counter_access(list(STEP_COUNTERS).index(row.name)), None
            var = cls(row.name, unit=row.unit, vmin=row.min, vmax=row.max,
                      causality=_CAUSALITY[row.causality], variability=_VARIABILITY[row.variability],
                      description=row.description, getter=getter, setter=setter)
            self.register_variable(var, nested=False)
            self._types[var.value_reference] = row.type
            if row.causality == "output":
                if row.type == "Real":
                    self._out_index[var.value_reference] = i_out[row.name]
                elif row.type in _ACCESS["Integer"]:
                    self._iget[var.value_reference] = getter
                    counter = list(STEP_COUNTERS).index(row.name)
                    if counter < 3:         # rhs calls, substeps, level: _counters()
                        self._counter_index[var.value_reference] = counter
            elif row.causality == "input":
                self._input_vrs.append(var.value_reference)
            if row.type == "Real":
                self._rget[var.value_reference] = getter
                if setter is not None:
                    self._rset[var.value_reference] = setter

    def _param_access(self, name: str, row_type: str, coerce: Callable[[Any], Any]):
        par = self._par
        call = f"fmi2Set{_access_type(row_type)}"

        def getter():
            return par[name]

        def setter(value):
            value = coerce(value)
            if self._phase in ("instantiated", "initialization"):
                par[name] = value
                self._y = None
            elif value != par[name]:
                self._refused_call(
                    f"{call}: {name!r} is a fixed parameter: it cannot change after "
                    f"fmi2ExitInitializationMode (phase {self._phase}); {value!r} refused, the "
                    f"value stays {par[name]!r}")

        return getter, setter

    def _input_access(self, name: str, i: int):
        u = self._u

        def getter():
            return u[i]

        def setter(value):
            if self._phase == "terminated":
                self._refused_call(f"fmi2SetReal: {name!r} cannot be set after fmi2Terminate; "
                                   f"{value!r} refused")
            else:
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
            def level():
                if self._model is not None:
                    return self._counters()[2]
                try:
                    name = fidelity_name(self._par["fidelity"])
                except ValueError:
                    return 0
                return LEVEL_CODES[AUTO_FIDELITY if name == "auto" else name]
            return level
        if i == 3:          # contact_status: at the current state and inputs
            def contact():
                if self._model is None or self._x is None:
                    return 0
                u = (self._u[0], self._u[1])
                if not (math.isfinite(u[0]) and math.isfinite(u[1])):
                    return 0
                return 0 if self._model.contact_diagnosis(list(self._x), u) is None else 1
            return contact
        return lambda: self._counters()[i]

    # Value access by reference.  The base class raises on a wrong type or a variable without
    # setter, which pythonfmu turns into fmi2Fatal; here a host's mistake is refused instead:
    # logged as an error naming the call and the variable, the value read is a neutral one, the
    # value written is ignored, and the next doStep is refused (fmi2Discard) naming it.
    @_guarded("fmi2GetReal", lambda self, vrs: [math.nan] * len(vrs))
    def get_real(self, vrs):
        states = self._state_outputs
        # a host's step loop reads the same few lists of outputs every step (a master that
        # tracks the speed: the speed after each trial, every output after the step): where
        # they are, worked out once per list
        plans = self._read_plans
        key = tuple(vrs)
        last = plans.get(key)
        if last is None or states is not last[3]:
            if len(plans) >= READ_PLANS:
                plans.clear()
            last = plans[key] = self._read_plan(list(vrs), states)
        _, positions, from_state, _ = last
        if positions is None:
            g = self._rget
            try:
                return [g[vr]() for vr in vrs]
            except KeyError:
                return self._get_typed(vrs, "Real")
        y = self._y
        if y is None:
            x = self._x
            if x is not None and from_state is not None:   # only states: no Model.outputs
                return [x[i] for i in from_state]
            y = self._compute_outputs()
        if positions is ALL_OUTPUTS:
            return y[:]
        return [y[k] for k in positions]

    def _read_plan(self, vrs: list, states: dict) -> tuple:
        """What fmi2GetReal of ``vrs`` reads: (vrs, their positions in the outputs (None: not
        only outputs; ALL_OUTPUTS: all of them in order), their indices in the state vector
        where all are states (else None), ``states``)."""
        index = self._out_index
        try:
            positions = [index[vr] for vr in vrs]
        except KeyError:
            return vrs, None, None, states
        from_state = ([states[vr] for vr in vrs] if states and all(vr in states for vr in vrs)
                      else None)
        if positions == list(range(len(self._out_names))):
            positions = ALL_OUTPUTS
        return vrs, positions, from_state, states

    def set_real(self, vrs, values):
        """fmi2SetReal: a host's step loop sets both inputs, in their order, or one of them
        (a master that tracks the speed: the torque of each trial), every step: those are
        written here; any other call goes through :meth:`_set_real`."""
        if self._phase != "terminated":
            inputs = self._input_vrs
            try:
                if vrs == inputs:
                    torque, load = float(values[0]), float(values[1])
                    u = self._u
                    u[0] = torque
                    u[1] = load
                    return
                if len(vrs) == 1 and vrs[0] in inputs:
                    self._u[inputs.index(vrs[0])] = float(values[0])
                    return
            except Exception:  # noqa: BLE001 - _set_real says what is wrong
                pass
        self._set_real(vrs, values)

    @_guarded("fmi2SetReal")
    def _set_real(self, vrs, values):
        s = self._rset
        for vr, value in zip(vrs, values):
            setter = s.get(vr)
            if setter is None:
                self._set_typed([vr], [value], "Real")
            else:
                setter(value)

    def get_integer(self, vrs):
        """fmi2GetInteger: the step counters after a step (what a host's step loop reads) are
        read here; any other call goes through :meth:`_get_integer`."""
        last = self._last_counters
        if vrs != last[0]:
            where = self._counter_index
            last = self._last_counters = (list(vrs), [where.get(vr) for vr in vrs])
        index = last[1]
        if self._model is not None and None not in index:
            counters = self._counters()
            return [int(counters[i]) for i in index]
        return self._get_integer(vrs)

    @_guarded("fmi2GetInteger", lambda self, vrs: [0] * len(vrs))
    def _get_integer(self, vrs):
        g = self._iget
        getters = [g.get(vr) for vr in vrs]
        if None in getters:         # not only outputs: by type, refusing what does not fit
            return self._get_typed(vrs, "Integer")
        return [int(get()) for get in getters]

    @_guarded("fmi2GetBoolean", lambda self, vrs: [False] * len(vrs))
    def get_boolean(self, vrs):
        return self._get_typed(vrs, "Boolean")

    @_guarded("fmi2GetString", lambda self, vrs: [""] * len(vrs))
    def get_string(self, vrs):
        return self._get_typed(vrs, "String")

    @_guarded("fmi2SetInteger")
    def set_integer(self, vrs, values):
        self._set_typed(vrs, values, "Integer")

    @_guarded("fmi2SetBoolean")
    def set_boolean(self, vrs, values):
        self._set_typed(vrs, values, "Boolean")

    @_guarded("fmi2SetString")
    def set_string(self, vrs, values):
        self._set_typed(vrs, values, "String")

    def _variable(self, vr, typ: str, action: str, value: Any = None):
        var = self.vars.get(vr)
        row_type = self._types.get(vr)
        if var is None or row_type not in _ACCESS[typ]:
            what = ("no variable" if var is None else
                    f"{var.name!r}, of type {_fmi_type(row_type)}"
                    + (f" (use fmi2{action}{_access_type(row_type)})" if row_type else ""))
            shown = "" if value is None else f"; value {value!r} not written"
            self._refused_call(f"fmi2{action}{typ}: value reference {vr} is {what}{shown}")
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
            var = self._variable(vr, typ, "Set", value)
            if var is None:
                continue
            if var.setter is None:
                self._refused_call(f"fmi2Set{typ}: {var.name!r} is an output and cannot be set; "
                                   f"{value!r} not written")
            else:
                var.setter(value)

    def _refused_call(self, message: str) -> None:
        """Log a refused call as an error; the next doStep is refused naming it."""
        self.log(message, Fmi2Status.error)
        self._refused.append(message)

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
        built = configure(params, par, tuple(self._u), library_path=self._engine_path,
                          engine_refusal=self._engine_refusal())
        model, _stepper, x0, _level, _name = built
        u0 = (self._u[0], self._u[1])
        # non-finite inputs are refused by doStep, and so is a start where the rigid contact has
        # no solution under the start inputs (the host may still change them): contact_status
        if all(map(math.isfinite, u0)) and model.contact_diagnosis(list(x0), u0) is None:
            bad = [v for v in model.rhs(self._t, list(x0), u0) if not math.isfinite(v)] or [
                name for name, v in model.outputs(self._t, list(x0), u0).items()
                if isinstance(v, float) and not math.isfinite(v)
                and not undefined_allowed(name, v)]
            if bad:
                raise ValueError("the parameters give non-finite values at the start (e.g. "
                                 f"{bad[0]!r}): a mass, inertia or radius is out of any "
                                 "physical proportion to the others")
        return built

    def _engine_refusal(self) -> str | None:
        """Why the packed engine cannot run the current parameters (None: it can)."""
        if self._engine_missing:
            return self._engine_missing
        changed = [name for name, value in self._engine_geometry.items()
                   if self._par.get(name) != value]
        if changed and self._engine_solves_geometry is None:
            self._engine_solves_geometry = library_solves_geometry(self._engine_path)
        if not changed or self._engine_solves_geometry:
            return None
        name = changed[0]
        return (f"{name} = {self._par.get(name)!r} differs from the value the engine library was "
                f"built with ({self._engine_geometry[name]!r}): this library bakes the contact "
                "geometry in (rebuild the FMU: a library of this version solves it)")

    def _states_read_as_outputs(self, model) -> dict[int, int]:
        """Value reference -> state index of the Real outputs that are states of ``model``
        (their output equals the state: Model.outputs; tests/test_engine.py)."""
        names = getattr(model, "state_names", ())
        return {vr: names.index(self._out_names[i]) for vr, i in self._out_index.items()
                if self._out_names[i] in names}

    def _engine_output_reader(self, stepper):
        """The engine's outputs in C for ``stepper`` (EngineStepper.output_reader of the FMU's
        output names), or None: the Python reference or a C that does not compute them all
        (then Model.outputs computes them, for this instance)."""
        reader = getattr(stepper, "output_reader", None) if is_engine(stepper) else None
        return reader(self._out_names) if reader is not None else None

    def _config_key(self) -> tuple:
        return tuple(self._par[n] for n in self._par_names)

    def _compute_outputs(self) -> list[float]:
        """Output values at the last communication point (never raises: NaN and a log)."""
        model, x, u = self._model, self._x, self._u_held
        key = None
        if model is None:  # before exitInitializationMode: outputs of the initial state
            if self._phase == "failed":
                return [math.nan] * len(self._out_names)
            key = (self._config_key(), tuple(self._u), self._t)
            if self._preview[0] == key:
                return self._preview[1]
        try:
            if model is None:
                model, _, x, _, _ = self._build()
                u = tuple(self._u)
                values = [float(v) for v in self._pick_outputs(model.outputs(self._t, x, u))]
            elif self._engine_outputs is not None:
                fast = self._engine_step
                if fast is not None and x is fast[2] and fast[3] is not None:
                    values = fast[3]()    # the state and inputs of the last one-call step
                else:
                    values = self._engine_outputs(self._t, x, u)
            else:
                values = [float(v) for v in self._pick_outputs(model.outputs(self._t, x, u))]
        except Exception as exc:  # noqa: BLE001 - an exception here would be fmi2Fatal
            self.log(f"fmi2GetReal: the outputs cannot be computed (NaN): {exc}",
                     Fmi2Status.error)
            values = [math.nan] * len(self._out_names)
        if key is None:
            self._y = values
        else:
            self._preview = (key, values)
        return values

    # ---- FMI life cycle ------------------------------------------------------------------
    def _out_of_phase(self, call: str, allowed: tuple[str, ...], what: str) -> bool:
        """Refuse ``call`` unless the FMU is in one of the ``allowed`` phases (True: refused)."""
        if self._phase in allowed:
            return False
        self._refused_call(f"{call} is not allowed in phase {self._phase} (only in "
                           f"{' or '.join(allowed)}): {what}")
        return True

    @_guarded("fmi2SetupExperiment")
    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None) -> None:
        if self._out_of_phase("fmi2SetupExperiment", ("instantiated",),
                              f"startTime = {start_time!r} s ignored, the time stays {self._t!r} s"):
            return
        if not math.isfinite(start_time):
            self._refused_call(f"fmi2SetupExperiment: startTime = {start_time!r} s is out of "
                               "range: must be finite; the time stays 0.0 s")
            return
        self._t = float(start_time)

    @_guarded("fmi2EnterInitializationMode")
    def enter_initialization_mode(self) -> None:
        if self._out_of_phase("fmi2EnterInitializationMode", ("instantiated",),
                              "a started FMU cannot be initialized again (call fmi2Reset); "
                              f"the state and the time {self._t!r} s are unchanged"):
            return
        self._phase = "initialization"

    @_guarded("fmi2ExitInitializationMode")
    def exit_initialization_mode(self) -> None:
        if self._out_of_phase("fmi2ExitInitializationMode", ("initialization",),
                              "ignored, the state is unchanged"):
            return
        try:
            model, stepper, x0, level, name = self._build()
        except Exception as exc:  # noqa: BLE001 - ValueError naming the parameter, or other
            what = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
            self._init_error = f"initialization failed: {what}"
            self._phase = "failed"
            self.log(f"fmi2ExitInitializationMode: {self._init_error}; every fmi2DoStep will "
                     "be refused (fmi2Discard) until fmi2Reset", Fmi2Status.error)
            return
        if fidelity_name(self._par["fidelity"]) == "auto":
            along = ("; it switches between the dynamic and the quasi-static level along the run"
                     if model.fidelity == "auto" else "")
            self.log(f"fidelity = 'auto' starts with {model.auto_choice.describe()}{along}",
                     Fmi2Status.ok)
        if not is_engine(stepper):
            why = fallback_reason(stepper) or f"{ENGINE_ENV} = 'python' selects it"
            self.log(f"the Python reference model runs, not the compiled engine: {why}",
                     Fmi2Status.ok)
        self._model, self._stepper, self._x = model, stepper, x0
        self._level = _fixed_level(model)
        self._state_outputs = self._states_read_as_outputs(model)
        # the compiled engine computes the outputs in C (one call), where it computes all
        # of them; else (and with the Python reference) Model.outputs
        self._engine_outputs = self._engine_output_reader(stepper)
        self._u_held = (self._u[0], self._u[1])
        self._config = self._config_key()
        self._stats = (0, 0, active_level(model))
        self._y = None
        self._arm_engine_step()
        self._phase = "stepping"

    def _arm_engine_step(self) -> None:
        """The engine's one-call step for :meth:`do_step` (EngineStepper.step_block), where the
        engine runs a level that never changes; else None (every step the checked one)."""
        stepper = self._stepper
        block = getattr(stepper, "step_block", None) if is_engine(stepper) else None
        self._engine_step = (block(TIME_MATCH, self._out_names)
                             if block is not None and self._level is not None else None)
        if self._engine_step is not None and self._x is not None:
            self._x = list(self._x)       # (do_step copies it into the engine's block)

    def _counters(self) -> tuple[int, int, int]:
        """(rhs calls, accepted substeps, level) of the last step: after the engine's one-call
        step, read from its block."""
        stats = self._stats
        if stats is None:
            io = self._engine_step[0]
            stats = self._stats = (int(io[5]), int(io[6]), self._level)
        return stats

    def do_step(self, current_time: float, step_size: float) -> bool:
        """fmi2DoStep: the engine's one-call step where it runs (:meth:`_arm_engine_step`),
        else, and wherever that step is not taken, :meth:`_checked_step` (which refuses
        naming why, the state unchanged)."""
        fast = self._engine_step
        if fast is not None and self._phase == "stepping" and not self._refused:
            try:
                io, step, x, _ = fast
                # io holds the time and state of the last one-call step; the checked step, a
                # restore and the start leave a list in self._x (and set self._t)
                if self._x is not x:
                    x[:] = self._x
                    io[0] = self._t
                    self._x = x
                u = self._u
                torque, load = u[0], u[1]
                io[1] = current_time
                io[2] = step_size
                io[3] = torque
                io[4] = load
                if not step(io):
                    self._t = current_time + step_size      # = io[0], the same sum in C
                    self._u_held = (torque, load)
                    self._stats = None          # in io until read (_counters)
                    self._y = None
                    return True
            except Exception:  # noqa: BLE001 - the checked step says what is wrong
                pass
        return self._checked_step(current_time, step_size)

    @_guarded("fmi2DoStep", False)
    def _checked_step(self, current_time: float, step_size: float) -> bool:
        """fmi2DoStep with every check in Python, through the stepper's ``advance``."""
        if self._x is not None and self._engine_step is not None and \
                self._x is self._engine_step[2]:
            self._x = self._x[:]          # the C's block changes in place: a list of its own
        u = (self._u[0], self._u[1])
        h = step_size
        phase = self._phase
        if phase != "stepping":
            if phase == "failed":
                return self._refuse(self._init_error or "initialization failed")
            when = ("after fmi2Terminate" if phase == "terminated"
                    else "before fmi2ExitInitializationMode")
            return self._refuse(f"fmi2DoStep is not allowed {when} (phase {phase})")
        if self._refused:
            earlier, self._refused = self._refused, []
            return self._refuse(f"{len(earlier)} earlier call(s) since the last step were "
                                f"refused: {' | '.join(earlier)}")
        t = self._t
        if not abs(current_time - t) <= TIME_MATCH * max(1.0, abs(t)):
            return self._refuse(f"currentCommunicationPoint = {current_time!r} s is not the "
                                f"FMU's time {t!r} s (the end of the last step): a co-simulation "
                                "step starts where the last one ended (use fmi2SetFMUstate to "
                                "go back)")
        if not (0.0 < h < _INF) or not (current_time + h > current_time):
            return self._refuse(f"communication step size = {h!r} s is out of range: must be a "
                                "finite number > 0 that advances the time")
        if not (math.isfinite(u[0]) and math.isfinite(u[1])):
            return self._refuse(f"inputs screw_torque = {u[0]!r} N.m, load_force = {u[1]!r} N: "
                                "every input must be finite")
        why = input_violation(u)
        if why is not None:
            return self._refuse(why)
        stepper = self._stepper
        # a refused step leaves the stepper's memory as it was: the engine takes its last
        # advance back itself (undo_advance: no copy per step), a Python stepper gets a copy
        undo = getattr(stepper, "undo_advance", None)
        if undo is None:
            memory = stepper.get_memory()
            undo = lambda: stepper.set_memory(memory)  # noqa: E731 - only on a refusal
        try:
            x, stats = stepper.advance(current_time, self._x, u, h)
        except Exception as exc:  # noqa: BLE001 - StepFailure; anything else would be fmi2Fatal
            undo()
            cause = self._model.contact_diagnosis(self._x, u)
            if cause is not None:         # contact_status reads 1 here
                return self._refuse(cause)
            what = str(exc) if isinstance(exc, StepFailure) else f"{type(exc).__name__}: {exc}"
            return self._refuse(f"integration failed: {what}")
        if not all(map(math.isfinite, x)):     # (the engine checks its states itself)
            undo()
            cause = self._model.contact_diagnosis(self._x, u)
            return self._refuse(cause or "integration failed: the stepper returned a non-finite "
                                "state")
        why = state_violation(x, model_speed_bounds(self._model, len(x)))
        if why is not None:          # the outputs of that state could overflow: docs/fmu.md
            undo()
            return self._refuse(f"the step would end out of the state's bounds: {why}")
        self._x = x
        self._t = current_time + h
        self._u_held = u
        level = self._level
        self._stats = (stats.rhs_calls, stats.substeps,
                       active_level(self._model) if level is None else level)
        self._y = None
        return True

    @_guarded("fmi2Terminate")
    def terminate(self) -> None:
        if self._out_of_phase("fmi2Terminate", ("stepping", "failed"), "ignored"):
            return
        self._phase = "terminated"

    def _refuse(self, reason: str) -> bool:
        self.log(f"fmi2DoStep refused, state unchanged: {reason}", Fmi2Status.discard)
        return False

    # ---- FMU state -------------------------------------------------------------------------
    @_guarded("fmi2GetFMUstate")
    def _get_fmu_state(self) -> tuple:
        memory = None if self._stepper is None else self._stepper.get_memory()
        x = self._x
        # a state vector the engine's one-call step just ended in: within the state's bounds
        # (prsm_api_step checks them, as _checked_step does: tests/test_slave_step.py)
        checked = x is not None and self._engine_step is not None and x is self._engine_step[2]
        x = None if x is None else tuple(x[:])    # (a ctypes array's slice: 4x faster)
        # while stepping the parameters are fixed: the key made at initialization holds
        config = self._config if self._config and self._phase == "stepping" else \
            self._config_key()
        state = (fmu_state.TAG, type(self).__name__, self.n_stages, config,
                 (self._u[0], self._u[1]), self._phase, self._t, x, self._u_held, memory,
                 self._counters(), self._init_error)
        self._own_states.append((state, checked))
        return state

    @_guarded("fmi2SetFMUstate")
    def _set_fmu_state(self, state: tuple) -> None:
        # a state this instance made (the same immutable object: a master that saves and
        # restores around trial steps) was valid when made: its check is skipped
        checked = None
        for own, x_checked in self._own_states:
            if own is state:
                checked = x_checked
                break
        if checked and self._restore_own(state):
            return
        why = None if checked is not None else fmu_state.check(
            state, type(self).__name__, self.n_stages, tuple(self._par_types))
        if why is None:
            why = self._restore(dict(zip(fmu_state.FIELDS, state)))
        if why is not None:
            self._refused_call(f"fmi2SetFMUstate: the state is refused, nothing restored: {why}")

    def _restore_own(self, state: tuple) -> bool:
        """Restore a state this instance made while stepping, from a state vector within its
        bounds, with the model and stepper it still runs (a master's save → trial step →
        restore): what :meth:`_restore` would do there, without its checks and rebuilding
        (the parameters are the ones held, the memory is the stepper's own).  False (nothing
        changed) where that is not the case: then :meth:`_restore` runs."""
        (_tag, _model, _n, config, inputs, phase, time, x, held, memory, counters,
         init_error) = state
        stepper = self._stepper
        if (stepper is None or phase != "stepping" or config is not self._config
                or self._phase not in fmu_state.RUNNING):
            return False
        stepper.set_memory(memory)
        u = self._u
        u[0], u[1] = inputs
        self._phase = phase
        self._t = time
        self._x = list(x)
        self._u_held = held
        self._stats = counters
        self._init_error = init_error
        self._y = None
        self._refused = []
        return True

    def _restore(self, f: dict) -> str | None:
        """Restore a state that :func:`fmu_state.check` accepted; why not, if it cannot be."""
        config = f["parameters"]
        model = stepper = None
        saved_par = dict(self._par)
        if f["phase"] in fmu_state.RUNNING:
            old_memory = None if self._stepper is None else self._stepper.get_memory()
            try:
                if self._stepper is not None and config == self._config:
                    model, stepper = self._model, self._stepper
                else:
                    self._par.update(zip(self._par_names, config))
                    model, stepper, _x0, _level, _name = self._build()
                if len(f["x"]) != stepper.n_states:
                    raise ValueError(f"x has {len(f['x'])} values, the model "
                                     f"{stepper.n_states} states")
                why = state_violation(f["x"], model_speed_bounds(model, len(f["x"])))
                if why is not None:     # the outputs of such a state could overflow
                    raise ValueError(why)
                stepper.set_memory(f["memory"])
            except Exception as exc:  # noqa: BLE001 - invalid parameters or memory in the state
                self._par.clear()
                self._par.update(saved_par)
                if stepper is self._stepper and old_memory is not None:
                    stepper.set_memory(old_memory)
                return str(exc)
        self._par.update(zip(self._par_names, config))
        if model is not self._model:
            self._level = None if model is None else _fixed_level(model)
            self._state_outputs = {} if model is None else self._states_read_as_outputs(model)
        if stepper is not self._stepper:
            self._engine_outputs = self._engine_output_reader(stepper)
        self._model, self._stepper = model, stepper
        if stepper is None:
            self._engine_step = None
        elif self._engine_step is None or self._engine_step[0].owner is not stepper:
            self._arm_engine_step()
        self._config = config if stepper is not None else ()
        self._u[0], self._u[1] = f["inputs"]
        self._phase = f["phase"]
        self._t = f["time"]
        self._x = None if f["x"] is None else list(f["x"])
        self._u_held = f["inputs_held"]
        self._stats = f["counters"]
        self._init_error = f["init_error"]
        self._y = None
        self._refused = []
        return None

    @staticmethod
    def _fmu_state_to_bytes(state: tuple) -> bytes:
        return fmu_state.to_bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        return fmu_state.from_bytes(data)


#: fmi2GetReal's positions when it reads every Real output in their order (a copy of the list)
ALL_OUTPUTS = object()

#: how many of its latest FMU states an instance recognises as its own (restored unchecked)
OWN_STATES = 8

#: how many lists of value references fmi2GetReal keeps the plan of (then it forgets them all)
READ_PLANS = 8

#: how far a doStep's currentCommunicationPoint may lie from the FMU's time, relative to
#: max(1 s, |time|): hosts that count time in integers (libcosim: ns) or as differences of
#: accumulated sums differ from t + h in the last bits (about 1e-16 relative); 1e-12 is 10^4
#: times that and still far below any step a host could mean (1 ps at t <= 1 s)
TIME_MATCH = 1e-12


__all__ = ["PRSMSlave", "Var", "variable_table", "parameter_defaults", "output_names",
           "type_definitions", "FMU_FIDELITIES", "FMU_STEPPERS", "AUTO_FIDELITY",
           "DEFAULT_STEPPER", "ATOL_FACTOR", "TIME_MATCH"]
