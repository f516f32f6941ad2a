"""Build the native FMU ``<name>-native.fmu``: the kinematic, quasi-static and dynamic levels
and ``auto`` in C.

No Python in the FMU: the physics of :mod:`prsm_fmu.mechanics`, :mod:`prsm_fmu.models.slaved`,
the Dormand-Prince 5(4) fallback and the dynamic level's ROS34PW2 of :mod:`prsm_fmu.steppers`
translated into C (``fmu_build/native/*.c``), operation for operation, so that the outputs equal
the Python FMU's bit for bit (tests/test_native_fmu.py).

What this module does:

1. builds the Python FMU of the same mechanism (:func:`fmu_build.builder.build_fmu`) and reads
   its modelDescription: the native FMU mirrors its variables (names, value references, types,
   units, descriptions, start values, enumerations) generically, so a variable added there
   appears here without a change to this module -- or the build stops naming what the C does
   not know (an output or input), or the parameter is accepted only at its start value zero
   (a parameter, e.g. a new friction term, that the C does not model: setting it refuses
   initialization with a logged fmi2Error rather than being silently ignored);
2. writes the preset's geometry (the C solves the contact from it at initialization,
   ``prsm_geometry.c``), with the Dormand-Prince and ROS34PW2 tableaux of
   :mod:`prsm_fmu.steppers.tableaux`, into ``prsm_constants.h`` as exact (hexadecimal) double
   literals, and the variable table into ``prsm_variables.h``;
3. keeps every parameter's causality ``parameter``, variability ``fixed`` (settable before
   ``exitInitializationMode``), the geometry's (:data:`STRUCTURAL`) included: the C solves the
   contact of the geometry set when it initializes;
4. compiles the sources (``-std=c99 -O2 -fPIC -shared -ffp-contract=off``, libm only) with
   Zig's C compiler for every platform of :mod:`fmu_build.platforms` (``binaries/linux64``
   for glibc 2.17 and later, ``binaries/win64``, ``binaries/darwin64`` universal x86_64 +
   arm64), reads each library back and fails naming a missing ``fmi2`` function, a library
   other than the platform's C runtime or a glibc symbol above 2.17; packs the sources into
   ``sources/`` (listed in ``<SourceFiles>``, with the FMI 2.0 headers fmpy ships) and
   validates the FMU.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import shutil
import subprocess
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from xml.dom.minidom import parseString

import prsm_fmu
from prsm_fmu.atomic import atomic_path
# the gcc build-and-cache step, shared with every compiled part (re-exported here)
from prsm_fmu.compiled import cached_library, compile_library
from prsm_fmu.slave import TIME_MATCH
from prsm_fmu.models.base import STANDSTILL_SPEED
from prsm_fmu.params import MechanismParams
from prsm_fmu.steppers.control import APPROACH, KINK_BAND, MAX_KINK_CUTS
from prsm_fmu.steppers.options import TOLERANCE_FACTOR
from prsm_fmu.models.adaptive import MAX_WAIT as AUTO_MAX_WAIT
from prsm_fmu.models.auto import MARGIN as AUTO_MARGIN, _EFFICIENCY_POINT as AUTO_EFFICIENCY_POINT
from prsm_fmu.steppers.tableaux import (_ROS_E, _ROS_EQ, _ROS_M, _ROS_TRIAL, _ROS_WQ,
                                        EXPLICIT_TABLEAUS, ROS_GAMMA)
from prsm_fmu.steppers.band import _GAUSS
from prsm_fmu.steppers.base import _SQRT_EPS

from . import model_description, platforms
from .builder import BuildError, build_fmu, validate
from .native_ranges import bounds_defines, ranges_header
from .native_stepper import GEOMETRY_REALS

__all__ = ["build_native", "native_name", "NATIVE_LEVELS", "STRUCTURAL",
           "SOURCES", "COMPILE_FLAGS", "FMI2_COMMON", "FMI2_COSIMULATION", "fmi2_functions"]

#: the fidelity levels of the native FMU that the actuator loop's ``--prsm native`` runs; the
#: native FMU runs ``auto`` too (co-simulation: tests/test_native_fmu.py), not yet offered there
NATIVE_LEVELS = ("kinematic", "quasi-static", "dynamic")
#: the C sources (fmu_build/native)
SOURCE_DIR = Path(__file__).resolve().parent / "native"
SOURCES = ("prsm_model.c", "prsm_ros.c", "prsm_band.c", "prsm_geometry.c", "prsm_auto.c",
           "prsm_fmi2_me.c")
HEADERS = ("prsm_model.h", "prsm_ros.h", "prsm_band.h", "prsm_geometry.h", "prsm_quantity.h",
           "prsm_auto.h", "prsm_bounds.h", "prsm_step.h")
#: C included, not compiled alone: the FMI 2.0 interface prsm_fmi2_me.c builds on
INCLUDED = ("prsm_fmi2.c",)
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
#: compiler flags of every binary (no fused multiply-add: the Python model's rounding)
COMPILE_FLAGS = platforms.COMPILE_FLAGS

#: the functions every FMI 2.0 binary exports (FMI 2.0.4 §2.1.2: "common functions")
FMI2_COMMON = ("fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2SetDebugLogging", "fmi2Instantiate",
               "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
               "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset", "fmi2GetReal",
               "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal",
               "fmi2SetInteger", "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate",
               "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize",
               "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
               "fmi2GetDirectionalDerivative")
#: the co-simulation functions (FMI 2.0.4 §4.2)
FMI2_COSIMULATION = ("fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
                     "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus",
                     "fmi2GetIntegerStatus", "fmi2GetBooleanStatus", "fmi2GetStringStatus")
#: the model-exchange functions (FMI 2.0.4 §3.2)
FMI2_MODEL_EXCHANGE = ("fmi2EnterEventMode", "fmi2NewDiscreteStates",
                       "fmi2EnterContinuousTimeMode", "fmi2CompletedIntegratorStep",
                       "fmi2SetTime", "fmi2SetContinuousStates", "fmi2GetDerivatives",
                       "fmi2GetEventIndicators", "fmi2GetContinuousStates",
                       "fmi2GetNominalsOfContinuousStates")


def fmi2_functions(md: bytes) -> tuple[str, ...]:
    """The functions a binary of the FMU with modelDescription ``md`` must export: the common
    ones and those of each interface it declares (``<CoSimulation>``, ``<ModelExchange>``)."""
    root = ET.fromstring(md)
    out = FMI2_COMMON
    if root.find("CoSimulation") is not None:
        out += FMI2_COSIMULATION
    if root.find("ModelExchange") is not None:
        out += FMI2_MODEL_EXCHANGE
    return out

#: per-stage parameters the contact geometry is computed from (the C solves it at initialization;
#: what an engine library packed by an older build baked in, prsm_engine.json)
STRUCTURAL = ("screw_radius", "roller_radius", "nut_radius", "screw_lead", "screw_starts",
              "flank_angle")


#: parameters the C reads: name (per stage: field) -> allowed FMI types
_STAGE_PARAMS = {"screw_mass": "Real", "nut_mass": "Real", "roller_mass": "Real",
                 "carrier_mass": "Real", "screw_inertia": "Real", "roller_inertia": "Real",
                 "carrier_inertia": "Real", "spline_radius": "Real", "bearing_radius": "Real",
                 "n_rollers": "Integer", "carriers": "Integer", "threads_per_roller": "Integer",
                 # the geometry, whose contact prsm_model_init solves (prsm_geometry.c)
                 "screw_radius": "Real", "roller_radius": "Real", "nut_radius": "Real",
                 "screw_lead": "Real", "flank_angle": "Real", "screw_starts": "Integer"}
_SCALAR_PARAMS = {"mu_screw_roller": ("Real",), "mu_spline": ("Real",),
                  "mu_nut_screw": ("Real",), "mu_viscous": ("Real",),
                  "mu_differential": ("Real",), "slip_velocity_scale": ("Real",),
                  "tolerance": ("Real",), "substeps": ("Integer",),
                  "max_substeps": ("Integer",), "kinematic_efficiency": ("Real",),
                  "initial_screw_speed": ("Real",), "initial_screw_angle": ("Real",),
                  "fidelity": ("String", "Enumeration"), "stepper": ("String", "Enumeration"),
                  # the dynamic level's start; no effect at the kinematic and quasi-static levels
                  "initial_carrier_equilibrium": ("Boolean",)}
_INPUTS = {"screw_torque": 0, "load_force": 1}
_OUTPUTS = {"screw_speed": "Q_SCREW_SPEED", "screw_angle": "Q_SCREW_ANGLE",
            "screw_acceleration": "Q_SCREW_ACCELERATION", "screw_torque": "Q_SCREW_TORQUE",
            "rod_position": "Q_ROD_POSITION", "rod_velocity": "Q_ROD_VELOCITY",
            "load_force": "Q_LOAD_FORCE", "efficiency": "Q_EFFICIENCY",
            "friction_power": "Q_FRICTION_POWER", "input_power": "Q_INPUT_POWER",
            "output_power": "Q_OUTPUT_POWER", "input_work": "Q_INPUT_WORK",
            "output_work": "Q_OUTPUT_WORK", "friction_work": "Q_FRICTION_WORK",
            "kinetic_energy": "Q_KINETIC_ENERGY",
            "friction_power_coulomb": "Q_FRICTION_POWER_COULOMB",
            "friction_power_viscous": "Q_FRICTION_POWER_VISCOUS",
            "friction_power_differential": "Q_FRICTION_POWER_DIFFERENTIAL",
            "friction_power_joints": "Q_FRICTION_POWER_JOINTS",
            "screw_friction_torque": "Q_SCREW_FRICTION_TORQUE",
            "overall_efficiency": "Q_OVERALL_EFFICIENCY"}
_STAGE_OUTPUTS = {"contact_force": "Q_CONTACT_FORCE", "normal_force": "Q_NORMAL_FORCE",
                  "driven_torque": "Q_DRIVEN_TORQUE", "spline_friction": "Q_SPLINE_FRICTION",
                  "carrier_speed": "Q_CARRIER_SPEED",
                  "carrier_speed_ratio": "Q_CARRIER_SPEED_RATIO"}


def api_outputs(n_stages: int) -> tuple[tuple[str, str, int], ...]:
    """The engine's outputs (``prsm_api_outputs`` in prsm_api.c), in the order it writes them:
    (FMU output name, quantity code of prsm_quantity.h, stage index from 0), every
    :data:`_OUTPUTS` then every :data:`_STAGE_OUTPUTS` of stage 1, 2, ...  The one definition
    of that order: :func:`constants_header` generates the C's tables from it, and Python reads
    the names back from the library (``prsm_api_output_name``)."""
    rows = [(name, q, 0) for name, q in _OUTPUTS.items()]
    rows += [(f"stage[{k + 1}].{field}", q, k) for k in range(n_stages)
             for field, q in _STAGE_OUTPUTS.items()]
    return tuple(rows)


#: variables the native FMU adds for model exchange (per stage): the carrier states' derivatives
_STAGE_LOCALS = {"carrier_acceleration": "Q_CARRIER_ACCELERATION"}
#: model exchange: (state, its derivative) in the order of the continuous states (prsm_fmi2_me.c);
#: "stage[k]." entries repeat per stage
ME_STATES = (("screw_angle", "screw_speed"), ("screw_speed", "screw_acceleration"),
             ("stage[k].carrier_speed", "stage[k].carrier_acceleration"),
             ("input_work", "input_power"), ("output_work", "output_power"),
             ("friction_work", "friction_power"))
#: event indicators (prsm_fmi2_me.c): zero screw speed, both friction band edges, rigid contact
N_EVENT_INDICATORS = 4
_COUNTERS = {"step_rhs_calls": "C_RHS_CALLS", "step_substeps": "C_SUBSTEPS",
             "step_fidelity": "C_FIDELITY", "contact_status": "C_CONTACT"}
_STAGE_NAME = re.compile(r"^stage\[(\d+)\]\.(\w+)$")
_TYPE_CODE = {"Real": "T_REAL", "Integer": "T_INTEGER", "Boolean": "T_BOOLEAN",
              "String": "T_STRING", "Enumeration": "T_ENUM"}


def native_name(name: str) -> str:
    """The FMI modelIdentifier of the native FMU built as ``name`` (``PRSM2`` -> ``PRSM2_native``)."""
    return f"{name}_native"


def _hex(v: float) -> str:
    """Exact C99 literal of a double."""
    v = float(v)
    if not math.isfinite(v):
        raise BuildError(f"constant {v!r} is not finite")
    return v.hex()


def _c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def constants_header(params: MechanismParams) -> str:
    """``prsm_constants.h``: the built-in geometry of ``params`` (the engine solves the contact
    from it, or from the geometry it is given), the steppers' tableaux and the outputs' order."""
    # the built-in geometry (prsm_api_new's; the FMU's start values): the engine solves the
    # contact from it when a model is made (prsm_geometry.c)
    geometry = ",\n".join("    {" + ", ".join(_hex(getattr(st, f)) for f in GEOMETRY_REALS) + "}"
                           for st in params.stages)
    starts = ", ".join(str(int(st.screw_starts)) for st in params.stages)
    _, a, b, _ = EXPLICIT_TABLEAUS[5]
    rows = ["    {" + ", ".join(_hex(v) for v in (list(a[i]) + [0.0] * 5)[:5]) + "}"
            for i in range(1, 6)]
    b_used = [b[i] for i in (0, 2, 3, 4, 5)]
    bhat = EXPLICIT_TABLEAUS[5][3]
    e = [b[i] - bhat[i] for i in range(7) if i != 1]     # as steppers.tableaux._DP_E
    sep = ",\n"
    rows_c = sep.join(rows)
    api = api_outputs(params.n_stages)
    return f"""/* Generated by fmu_build.native from {params.name} ({params.source}). Do not edit.
 * prsm-fmu {prsm_fmu.__version__}; values are exact (C99 hexadecimal literals). */
#ifndef PRSM_CONSTANTS_H
#define PRSM_CONSTANTS_H

#define PRSM_N_STAGES {params.n_stages}

/* |screw speed| [rad/s] at or below which no power flows (prsm_fmu.models.base.STANDSTILL_SPEED) */
#define PRSM_STANDSTILL_SPEED {_hex(STANDSTILL_SPEED)}

{bounds_defines()}

/* the built-in geometry, per stage: screw_radius, roller_radius, nut_radius, screw_lead [m],
   flank_angle [rad] (fmu_build.native_stepper.GEOMETRY_REALS); and screw_starts */
static const double PRSM_GEOMETRY[PRSM_N_STAGES][5] = {{
{geometry}
}};
static const int PRSM_SCREW_STARTS[PRSM_N_STAGES] = {{{starts}}};

/* Dormand-Prince 5(4) (prsm_fmu.steppers.tableaux): a rows 2..6, b (stages 1, 3..6), b - b_hat */
static const double PRSM_DP_A[5][5] = {{
{rows_c}
}};
static const double PRSM_DP_B[5] = {{{", ".join(_hex(v) for v in b_used)}}};
static const double PRSM_DP_E[6] = {{{", ".join(_hex(v) for v in e)}}};

/* ROS34PW2 in the transformed form (prsm_fmu.steppers.tableaux): gamma; a_ij, c_ij (i > j) and
   the stage times; the result weights m, the error weights m - m_hat and the quadrature states'
   weights of both */
#define PRSM_ROS_GAMMA {_hex(ROS_GAMMA)}
static const double PRSM_ROS_TRIAL[{len(_ROS_TRIAL)}] = {{{", ".join(_hex(v) for v in _ROS_TRIAL)}}};
static const double PRSM_ROS_M[4] = {{{", ".join(_hex(v) for v in _ROS_M)}}};
static const double PRSM_ROS_E[4] = {{{", ".join(_hex(v) for v in _ROS_E)}}};
static const double PRSM_ROS_WQ[4] = {{{", ".join(_hex(v) for v in _ROS_WQ)}}};
static const double PRSM_ROS_EQ[4] = {{{", ".join(_hex(v) for v in _ROS_EQ)}}};

/* the friction band's exponential step (prsm_fmu.steppers.band): sqrt(eps) of the difference
   increment; Gauss-Legendre nodes on [-1, 1] and weights, 5 and 3 points */
#define PRSM_SQRT_EPS {_hex(_SQRT_EPS)}
static const double PRSM_GAUSS5_X[5] = {{{", ".join(_hex(v) for v in _GAUSS[0][0])}}};
static const double PRSM_GAUSS5_W[5] = {{{", ".join(_hex(v) for v in _GAUSS[0][1])}}};
static const double PRSM_GAUSS3_X[3] = {{{", ".join(_hex(v) for v in _GAUSS[1][0])}}};
static const double PRSM_GAUSS3_W[3] = {{{", ".join(_hex(v) for v in _GAUSS[1][1])}}};

/* kink landing (prsm_fmu.steppers.control): the landing band per v_eps, the resolution of the
   friction law, the cuts of one internal step */
#define PRSM_KINK_BAND {_hex(KINK_BAND)}
#define PRSM_APPROACH {_hex(APPROACH)}
#define PRSM_MAX_KINK_CUTS {MAX_KINK_CUTS}

/* ROS34PW2's factor on the FMU's tolerances (prsm_fmu.steppers.options.TOLERANCE_FACTOR) */
#define PRSM_ROS_TOLERANCE_FACTOR {_hex(TOLERANCE_FACTOR.get("rosenbrock", 1.0))}

/* fidelity = auto (prsm_auto.c): the safety factor on the estimated model error
   (prsm_fmu.models.auto.MARGIN) and the longest wait between two confirmations of a
   dynamic -> quasi-static switch [steps] (prsm_fmu.models.adaptive.MAX_WAIT) */
#define PRSM_AUTO_MARGIN {_hex(AUTO_MARGIN)}
#define PRSM_AUTO_MAX_WAIT {AUTO_MAX_WAIT}
/* the operating point of the quasi-static level's steady efficiency: screw speed [rad/s], load
   [N] (prsm_fmu.models.auto._EFFICIENCY_POINT) */
#define PRSM_AUTO_EFFICIENCY_SPEED {_hex(AUTO_EFFICIENCY_POINT[0])}
#define PRSM_AUTO_EFFICIENCY_LOAD {_hex(AUTO_EFFICIENCY_POINT[1])}

/* the engine's outputs (prsm_api.c prsm_api_outputs), in its order (fmu_build.native.api_outputs):
   initializers of their names, quantities (prsm_quantity.h) and stages (from 0) */
#define PRSM_API_N_OUTPUTS {len(api)}
#define PRSM_API_OUTPUT_NAMES {{{", ".join(_c_string(n) for n, _, _ in api)}}}
#define PRSM_API_OUTPUT_Q {{{", ".join(q for _, q, _ in api)}}}
#define PRSM_API_OUTPUT_STAGE {{{", ".join(str(k) for _, _, k in api)}}}

#endif
"""


class _Var:
    def __init__(self, sv: ET.Element, enums: dict) -> None:
        self.name = sv.get("name")
        self.vr = int(sv.get("valueReference"))
        self.causality = sv.get("causality", "local")
        self.variability = sv.get("variability", "continuous")
        typed = model_description._typed(sv)
        self.type = typed.tag
        self.start = typed.get("start")
        self.items = enums.get(typed.get("declaredType")) if self.type == "Enumeration" else None

    def value(self):
        """The start value as a Python value of the variable's type."""
        s = self.start
        if self.type == "Real":
            return float(s) if s is not None else 0.0
        if self.type in ("Integer", "Enumeration"):
            return int(s) if s is not None else 0
        if self.type == "Boolean":
            return s in ("true", "1")
        return s or ""


def _enumerations(root: ET.Element) -> dict:
    out = {}
    for st in root.iterfind("TypeDefinitions/SimpleType"):
        enum = st.find("Enumeration")
        if enum is not None:
            out[st.get("name")] = [(int(i.get("value")), i.get("name")) for i in enum.iterfind("Item")]
    return out


def variables_header(md: bytes, params: MechanismParams, identifier: str, guid: str) -> str:
    """``prsm_variables.h``: the Python FMU's variables as C tables (module docstring, step 1).

    Raises
    ------
    BuildError
        For an input or output the C does not compute, a parameter of an unexpected type, or a
        parameter the C does not model whose start value is not zero.
    """
    root = ET.fromstring(md)
    enums = _enumerations(root)
    variables = [_Var(sv, enums) for sv in root.find("ModelVariables")]
    n = params.n_stages
    pools = {"Real": [], "Integer": [], "Boolean": [], "String": []}   # start values
    out_q, out_stage, counters = [], [], []
    rows, unmodelled = [], []
    index: dict[str, tuple[str, int, _Var]] = {}
    inputs_start = [0.0, 0.0]
    for v in variables:
        m = _STAGE_NAME.match(v.name)
        stage, field = (int(m.group(1)), m.group(2)) if m else (0, "")
        if v.causality == "input":
            if v.name not in _INPUTS or v.type != "Real":
                raise BuildError(f"input {v.name!r} ({v.type}) is not one the native FMU reads")
            i = _INPUTS[v.name]
            inputs_start[i] = v.value()
            rows.append((v, "K_INPUT", i))
        elif v.causality == "output" and v.type == "Real":
            q = _STAGE_OUTPUTS.get(field) if m else _OUTPUTS.get(v.name)
            if q is None or (m and not 1 <= stage <= n):
                raise BuildError(f"output {v.name!r} is not one the native FMU computes: "
                                 "add it to prsm_fmi2.c and fmu_build/native.py")
            rows.append((v, "K_OUTPUT", len(out_q)))
            out_q.append(q)
            out_stage.append(stage - 1 if m else 0)
        elif v.causality == "local" and v.type == "Real" and m and field in _STAGE_LOCALS:
            rows.append((v, "K_OUTPUT", len(out_q)))
            out_q.append(_STAGE_LOCALS[field])
            out_stage.append(stage - 1)
        elif v.causality == "output" and v.name in _COUNTERS and v.type in ("Integer", "Enumeration"):
            rows.append((v, "K_COUNTER", len(counters)))
            counters.append(_COUNTERS[v.name])
        elif v.causality == "parameter":
            key = "Integer" if v.type == "Enumeration" else v.type
            if key not in pools:
                raise BuildError(f"parameter {v.name!r} has type {v.type}, which the native FMU "
                                 "cannot hold")
            rows.append((v, "K_PARAM", len(pools[key])))
            index[v.name] = (key, len(pools[key]), v)
            pools[key].append(v.value())
            known = (_STAGE_PARAMS.get(field) == v.type if m
                     else v.type in _SCALAR_PARAMS.get(v.name, ()))
            if not known:
                if (m and field in _STAGE_PARAMS) or v.name in _SCALAR_PARAMS:
                    raise BuildError(f"parameter {v.name!r} has type {v.type}, not the one the "
                                     "native FMU reads")
                if v.value() not in (0, 0.0, False, ""):
                    raise BuildError(
                        f"parameter {v.name!r} = {v.value()!r} is not modelled by the native FMU "
                        "and not zero in this preset: the native FMU would run without it; "
                        "build the Python FMU instead, or model it in fmu_build/native")
                unmodelled.append((key, len(pools[key]) - 1, v.name))
        else:
            raise BuildError(f"variable {v.name!r} ({v.causality}, {v.type}) is not one the native "
                             "FMU knows")
    missing = [f"stage[{k}].{f}" for k in range(1, n + 1) for f in _STAGE_PARAMS
               if f"stage[{k}].{f}" not in index]
    missing += [p for p in _SCALAR_PARAMS if p not in index]
    if missing:
        raise BuildError(f"the Python FMU has no parameter(s) {missing}: the native FMU needs them")

    def arr(values, ctype, fmt, name, size_macro) -> str:
        body = ", ".join(fmt(v) for v in values) if values else {"double": "0.0", "int": "0",
                                                                 "const char *const": '""'}[ctype]
        decl = ctype if ctype.startswith("const") else f"const {ctype}"
        return f"#define {size_macro} {len(values)}\nstatic {decl} {name}[] = {{{body}}};\n"

    def idx(name: str) -> int:
        return index[name][1]

    lines = [f"/* Generated by fmu_build.native from the modelDescription of the Python FMU "
             f"{identifier.removesuffix('_native')}. Do not edit. */",
             f"#define PRSM_MODEL_IDENTIFIER {_c_string(identifier)}",
             f"#define PRSM_GUID {_c_string(guid)}",
             f"#define PRSM_TIME_MATCH {_hex(TIME_MATCH)}",
             f"#define PRSM_N_EVENT_INDICATORS {N_EVENT_INDICATORS}",
             f"#define PRSM_N_VARS {len(rows)}",
             f"#define PRSM_MAX_VR {max(v.vr for v, _, _ in rows)}",
             "static const prsm_var PRSM_VARS[PRSM_N_VARS] = {"]
    lines += [f"    {{{v.vr}u, {_TYPE_CODE[v.type]}, {kind}, {i}, {_c_string(v.name)}}},"
              for v, kind, i in rows]
    lines.append("};")
    by_vr = [-1] * (max(v.vr for v, _, _ in rows) + 1)
    for i, (v, _, _) in enumerate(rows):
        by_vr[v.vr] = i
    lines.append(f"static const int VR_INDEX[PRSM_MAX_VR + 1] = {{{', '.join(map(str, by_vr))}}};")
    lines.append(f"static const double INPUT_START[2] = {{{_hex(inputs_start[0])}, {_hex(inputs_start[1])}}};")
    lines.append(arr(pools["Real"], "double", _hex, "PAR_REAL_START", "N_PAR_REAL"))
    lines.append(arr(pools["Integer"], "int", str, "PAR_INT_START", "N_PAR_INT"))
    lines.append(arr([int(b) for b in pools["Boolean"]], "int", str, "PAR_BOOL_START", "N_PAR_BOOL"))
    lines.append(arr(pools["String"], "const char *const", _c_string, "PAR_STRING_START",
                     "N_PAR_STRING"))
    lines.append(arr(out_q, "int", str, "OUT_QUANTITY", "N_OUT_REAL"))
    lines.append(f"static const int OUT_STAGE[] = {{{', '.join(map(str, out_stage)) or '0'}}};")
    lines.append(arr(counters, "int", str, "COUNTER_QUANTITY", "N_COUNTERS"))
    for f in _STAGE_PARAMS:
        lines.append(f"static const int P_{f.upper()}[PRSM_N_STAGES] = "
                     f"{{{', '.join(str(idx(f'stage[{k}].{f}')) for k in range(1, n + 1))}}};")
    for p in _SCALAR_PARAMS:
        lines.append(f"#define P_{p.upper()} {idx(p)}")
    for p in ("fidelity", "stepper"):
        v = index[p][2]
        items = v.items or []
        lines.append(f"#define P_{p.upper()}_TYPE {_TYPE_CODE[v.type]}")
        lines.append(f"#define P_{p.upper()}_N_ITEMS {len(items)}")
        body = ", ".join(f"{{{val}, {_c_string(nm)}}}" for val, nm in items) or '{0, ""}'
        lines.append(f"static const prsm_enum_item P_{p.upper()}_ITEMS[] = {{{body}}};")
    lines.append(f"#define N_UNMODELLED {len(unmodelled)}")
    body = ", ".join(f"{{{_TYPE_CODE[t]}, {i}, {_c_string(nm)}}}" for t, i, nm in unmodelled)
    lines.append(f"static const prsm_par_ref UNMODELLED[] = {{{body or '{0, 0, NULL}'}}};")
    return "\n".join(lines) + "\n"


def with_model_exchange_variables(md: bytes, n_stages: int) -> bytes:
    """The Python FMU's modelDescription with the variables model exchange adds: per stage
    ``stage[k].carrier_acceleration`` (local, rad/s2), the derivative of the carrier state."""
    root = ET.fromstring(md)
    variables = root.find("ModelVariables")
    vr = max(int(sv.get("valueReference")) for sv in variables) + 1
    for k in range(1, n_stages + 1):
        sv = ET.SubElement(variables, "ScalarVariable", name=f"stage[{k}].carrier_acceleration",
                           valueReference=str(vr + k - 1),
                           description=f"stage {k}: angular acceleration of the carriers (the "
                           "derivative of the carrier speed; model exchange)",
                           causality="local", variability="continuous", initial="calculated")
        ET.SubElement(sv, "Real", unit="rad/s2")
    return ET.tostring(root, encoding="utf-8")


def _model_exchange(root: ET.Element, identifier: str) -> None:
    """Add ``<ModelExchange>``, the states' derivatives and the event indicators to ``root``."""
    variables = list(root.find("ModelVariables"))
    index = {sv.get("name"): i + 1 for i, sv in enumerate(variables)}
    n = sum(1 for name in index if name.endswith(".carrier_acceleration"))
    pairs = []
    for state, der in ME_STATES:
        ks = range(1, n + 1) if state.startswith("stage[k].") else [None]
        pairs += [(state.replace("[k]", f"[{k}]"), der.replace("[k]", f"[{k}]")) if k else
                  (state, der) for k in ks]
    for state, der in pairs:
        typed = model_description._typed(variables[index[der] - 1])
        typed.set("derivative", str(index[state]))
    root.set("numberOfEventIndicators", str(N_EVENT_INDICATORS))
    me = ET.Element("ModelExchange", modelIdentifier=identifier, needsExecutionTool="false",
                    completedIntegratorStepNotNeeded="true",
                    canBeInstantiatedOnlyOncePerProcess="false",
                    canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true",
                    canSerializeFMUstate="true")
    files = ET.SubElement(me, "SourceFiles")
    for s in SOURCES:
        ET.SubElement(files, "File", name=s)
    root.insert(list(root).index(root.find("CoSimulation")), me)
    structure = root.find("ModelStructure")
    # in model exchange the outputs depend on the states and inputs: no "dependencies" claim
    for u in structure.iterfind("Outputs/Unknown"):
        u.attrib.pop("dependencies", None)
        u.attrib.pop("dependenciesKind", None)
    ders = ET.Element("Derivatives")
    for _, der in pairs:
        ET.SubElement(ders, "Unknown", index=str(index[der]))
    structure.insert(1, ders)
    initial = structure.find("InitialUnknowns")
    listed = {int(u.get("index")) for u in initial}
    for _, der in pairs:
        if index[der] not in listed:
            ET.SubElement(initial, "Unknown", index=str(index[der]))
    initial[:] = sorted(initial, key=lambda u: int(u.get("index")))


def native_model_description(md: bytes, identifier: str, guid: str) -> bytes:
    """The native FMU's modelDescription.xml: the Python FMU's with its own identity and the
    sources listed (module docstring, step 3)."""
    root = ET.fromstring(md)
    for elem in root.iter():
        if elem.text is not None and not elem.text.strip():
            elem.text = None
        if elem.tail is not None and not elem.tail.strip():
            elem.tail = None
    root.set("modelName", identifier)
    root.set("guid", guid)
    root.set("generationTool", f"prsm-fmu fmu_build --native {prsm_fmu.__version__}")
    root.set("description", root.get("description", "") + "; native C FMU: kinematic, "
             "quasi-static and dynamic levels, contact geometry solved at initialization")
    cs = root.find("CoSimulation")
    for key, value in (("modelIdentifier", identifier), ("needsExecutionTool", "false"),
                       ("canHandleVariableCommunicationStepSize", "true"),
                       ("canBeInstantiatedOnlyOncePerProcess", "false"),
                       ("canNotUseMemoryManagementFunctions", "true"),
                       ("canGetAndSetFMUstate", "true"), ("canSerializeFMUstate", "true")):
        cs.set(key, value)
    for old in cs.findall("SourceFiles"):
        cs.remove(old)
    files = ET.SubElement(cs, "SourceFiles")
    for s in SOURCES:
        ET.SubElement(files, "File", name=s)
    _model_exchange(root, identifier)
    return parseString(ET.tostring(root, encoding="utf-8")).toprettyxml(indent="  ", encoding="UTF-8")


def _fmi_headers(header: str = "fmi2Functions.h", version: str = "2.0") -> Path:
    """The folder of fmpy's copy of the FMI ``version`` headers (the one holding ``header``)."""
    try:
        import fmpy
    except ImportError as exc:
        raise BuildError(f"the FMI {version} headers come from fmpy ({exc}): pip install -e \".[fmu]\"") from None
    found = sorted(Path(fmpy.__file__).parent.rglob(header))
    if not found:
        raise BuildError(f"fmpy ships no {header}" + (f" (the FMI {version} headers)"
                                                      if version != "2.0" else ""))
    return found[0].parent


def build_native(name: str, params: MechanismParams, preset: str, dest: str | Path = "dist",
                 check: bool = True, start: dict | None = None,
                 targets: tuple[str, ...] = platforms.FMI2_PLATFORMS) -> Path:
    """Build ``<dest>/<name>-native.fmu`` (module docstring).

    Parameters
    ----------
    name : str
        Name of the Python FMU it mirrors (``PRSM2``); the modelIdentifier is ``<name>_native``.
    params : MechanismParams
        The mechanism (start values and the built-in geometry).
    preset : str
        Name of the parameter source.
    dest : str or Path
        Output directory.
    check : bool
        Validate with fmpy and the project's modelDescription rules.
    start : dict, optional
        Parameter start values other than the preset's (``builder.start_values``: e.g.
        ``fidelity = dynamic`` for hosts that cannot set an Enumeration), the geometry's
        included.
    targets : tuple of str
        The platforms built (keys of :data:`fmu_build.platforms.PLATFORMS`): all by default.

    Returns
    -------
    Path
        The FMU file.

    Raises
    ------
    BuildError
        For what the C cannot build, or a binary unfit for its platform (named).
    """
    params = params.validate()
    unknown = [t for t in targets if t not in platforms.PLATFORMS]
    if unknown or not targets:
        raise BuildError(f"platforms {unknown or targets!r} not allowed: must be one or more of "
                         f"{', '.join(platforms.PLATFORMS)}")
    identifier = native_name(name)
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="prsm_native_") as tmp:
        tmp = Path(tmp)
        py_fmu = build_fmu(name, params, preset, tmp / "python", check=False, start=start)
        with zipfile.ZipFile(py_fmu) as z:
            md = with_model_exchange_variables(z.read("modelDescription.xml"), params.n_stages)
        src = tmp / "sources"
        src.mkdir()
        for f in SOURCES + HEADERS + INCLUDED:
            shutil.copy(SOURCE_DIR / f, src / f)
        headers = _fmi_headers()
        for f in FMI_HEADERS:
            shutil.copy(headers / f, src / f)
        geometry, ranges = constants_header(params), ranges_header(params)
        constants = geometry + ranges
        (src / "prsm_constants.h").write_text(geometry, encoding="utf-8")
        (src / "prsm_params_gen.h").write_text(ranges, encoding="utf-8")
        stable = re.sub(rb'(guid|generationDateAndTime|generationTool)="[^"]*"', b"", md)
        digest = hashlib.sha256(stable + constants.encode()
                                + b"".join((SOURCE_DIR / f).read_bytes()
                                           for f in SOURCES + HEADERS + INCLUDED))
        guid = str(uuid.uuid5(uuid.NAMESPACE_URL, "prsm-fmu-native:" + digest.hexdigest()))
        (src / "prsm_variables.h").write_text(variables_header(md, params, identifier, guid),
                                              encoding="utf-8")
        (src / "README.txt").write_text(SOURCES_README.format(id=identifier, sources=" ".join(SOURCES)), encoding="utf-8")
        native_md = native_model_description(md, identifier, guid)
        libs = {}
        exports = fmi2_functions(native_md)
        for plat in targets:
            rel = f"binaries/{plat}/{identifier}{platforms.PLATFORMS[plat].suffix}"
            libs[rel] = platforms.compile_for(plat, src, SOURCES, tmp / rel, exports)
        fmu = tmp / f"{name}-native.fmu"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", native_md)
            for rel, lib in libs.items():
                z.write(lib, rel)
            for f in sorted(src.iterdir()):
                z.write(f, f"sources/{f.name}")
        if check:
            problems = validate(fmu)
            if problems:
                raise BuildError(f"{fmu.name} is not valid:\n  " + "\n  ".join(problems))
        target = dest / fmu.name
        with atomic_path(target) as part:          # whole or not at all (Ctrl-C, full disk)
            shutil.copyfile(fmu, part)
    return target


SOURCES_README = """Sources of the native FMU {id} (FMI 2.0 co-simulation and model exchange, C99, libm only;
prsm_fmi2_me.c includes prsm_fmi2.c).

The FMU's binaries/ were built from these with Zig's C compiler (linux64 for glibc 2.17 and
later, win64, darwin64 for x86_64 and arm64).  Compile for another platform, e.g.

  Linux    gcc -std=c99 -O2 -fPIC -shared -ffp-contract=off {sources} -o {id}.so -lm
  macOS    clang -std=c99 -O2 -fPIC -shared -ffp-contract=off {sources} -o {id}.dylib
  Windows  cl /O2 /fp:precise /LD {sources} /Fe{id}.dll

and put the library under binaries/<platform>/ (linux64, darwin64, win64).  Keep fused
multiply-add off (-ffp-contract=off; MSVC /fp:precise) and no fast-math: the results then equal
the Python FMU's to round-off.  prsm_constants.h (geometry), prsm_params_gen.h (parameter
ranges) and prsm_variables.h (variables)
were generated from the preset by prsm-fmu's fmu_build.native: rebuild the FMU to change them.
"""
