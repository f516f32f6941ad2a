"""The type and range of every plain field of a scene file, checked before anything is built.

Each mistake is one ``ValueError`` line naming the field, its value and what is allowed; no
value is coerced (``extrapolation = 0.7`` is not 0, ``n_rollers = 4.9`` is not 4, ``"7"`` is not
7).  The tables the blocks read field by field (``[motor]``, ``[load]``, ``[controller]``,
``[gear]``) are checked by their dataclasses; this module covers the rest: the top-level
numbers and names, ``[retry]``, ``[initial]`` and ``[prsm]`` with its ``parameters``, whose names
and types are the FMU's (docs/fmu.md, *Variables*).
"""

from __future__ import annotations

import math
import re
from typing import Any

__all__ = ["check_fields", "SCENE_SET_PARAMETERS"]

#: [retry] fields: name -> (kind, allowed)
_RETRY = {"max_halvings": "an integer >= 0", "tolerance": "a number > 0"}
#: [initial] fields of a direct scene: name -> what is allowed
_INITIAL = {"screw_speed": "a finite number [rad/s]", "rod_position": "a finite number [m]",
            "carriers": "'rest' or 'equilibrium'", "steady": "true or false"}
#: FMU parameters the scene sets itself (from fidelity and [initial]): naming one in
#: [prsm] parameters is an error, not a value silently replaced
SCENE_SET_PARAMETERS = {"fidelity": "the scene's fidelity field (or --fidelity)",
                        "initial_screw_speed": "[initial] screw_speed",
                        "initial_screw_angle": "[initial] rod_position",
                        "initial_carrier_equilibrium": "[initial] carriers"}
#: the FMU's own parameters a scene may set, and their kinds
_SOLVER = {"tolerance": "real", "stepper": "enum", "substeps": "int", "max_substeps": "int",
           "kinematic_efficiency": "real"}
_STAGE_NAME = re.compile(r"stage\[(\d+)\]\.(\w+)\Z")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _bad(where: str, field: str, value: Any, allowed: str) -> ValueError:
    return ValueError(f"{where}: {field} = {value!r} is not allowed: must be {allowed}")


def _top(data: dict, where: str) -> None:
    for key, allowed in (("t0", "a finite number [s]"),):
        if key in data and not (_is_number(data[key]) and math.isfinite(data[key])):
            raise _bad(where, key, data[key], allowed)
    if "extrapolation" in data and not (_is_int(data["extrapolation"])
                                        and data["extrapolation"] in (0, 1)):
        raise _bad(where, "extrapolation", data["extrapolation"], "the integer 0 or 1")
    for key in ("description", "order", "fidelity", "topology"):
        if key in data and not isinstance(data[key], str):
            raise _bad(where, key, data[key], "a string")


def _retry(table: dict, where: str) -> None:
    for key, value in table.items():
        if key not in _RETRY:
            raise ValueError(f"{where}: [retry] unknown field {key!r} (allowed: "
                             f"{', '.join(_RETRY)})")
        ok = (_is_int(value) and value >= 0) if key == "max_halvings" else \
            (_is_number(value) and math.isfinite(value) and value > 0)
        if not ok:
            raise _bad(where, f"retry.{key}", value, _RETRY[key])


def _initial(table: dict, where: str) -> None:
    for key, value in table.items():
        if key not in _INITIAL:
            continue                  # unknown fields: named by the topology's builder
        ok = {"carriers": value in ("rest", "equilibrium") and isinstance(value, str),
              "steady": isinstance(value, bool)}.get(
            key, _is_number(value) and math.isfinite(value))
        if not ok:
            raise _bad(where, f"initial.{key}", value, _INITIAL[key])


def _stage_kinds() -> dict[str, str]:
    from dataclasses import fields

    from prsm_fmu.params import StageParams

    return {f.name: ("int" if f.type in ("int", int) else "real") for f in fields(StageParams)}


def _parameter(name: Any, value: Any, n_stages: int, mechanism: str, where: str) -> None:
    from prsm_fmu.params import MECHANISM_FIELD_NAMES

    field = f"prsm.parameters.{name!r}" if not isinstance(name, str) else \
        f"prsm.parameters.\"{name}\""
    if name in SCENE_SET_PARAMETERS:
        raise ValueError(f"{where}: {field} = {value!r} is not allowed: the scene sets "
                         f"{name} from {SCENE_SET_PARAMETERS[name]}; give it there")
    m = _STAGE_NAME.match(name) if isinstance(name, str) else None
    if m:
        k, f = int(m.group(1)), m.group(2)
        kinds = _stage_kinds()
        if not 1 <= k <= n_stages:
            raise ValueError(f"{where}: {field}: stage {k} is out of range: {mechanism} has "
                             f"stages 1 to {n_stages}")
        if f not in kinds:
            raise ValueError(f"{where}: {field}: no per-stage parameter {f!r} (allowed: "
                             f"{', '.join(kinds)})")
        kind = kinds[f]
    elif name in MECHANISM_FIELD_NAMES:
        kind = "real"
    elif name in _SOLVER:
        kind = _SOLVER[name]
    else:
        raise ValueError(f"{where}: {field} is not a parameter of the PRSM FMU a scene may set "
                         f"(stage[k].<field> with k in 1..{n_stages}, "
                         f"{', '.join(MECHANISM_FIELD_NAMES + tuple(_SOLVER))})")
    ok = {"int": _is_int(value), "enum": isinstance(value, str),
          "real": _is_number(value) and math.isfinite(value)}[kind]
    if not ok:
        allowed = {"int": "an integer (no fraction, no string)", "enum": "the item's name, a string",
                   "real": "a finite number"}[kind]
        raise _bad(where, field, value, allowed)


def _prsm(table: dict, topology: str, where: str) -> None:
    from .prsm import MECHANISMS

    mech = table.get("mechanism", "PRSM1" if topology == "geared" else "PRSM2")
    if not isinstance(mech, str) or mech not in MECHANISMS:
        raise _bad(where, "prsm.mechanism", mech, f"one of {', '.join(MECHANISMS)}")
    if "parameters" not in table:
        return
    params = table["parameters"]
    if not isinstance(params, dict):
        raise _bad(where, "prsm.parameters", params, "a table of FMU parameter names and values")
    n_stages = int(mech[len("PRSM"):])        # PRSM<n>: n stages (prsm.MECHANISMS)
    for name, value in params.items():
        _parameter(name, value, n_stages, mech, where)


def check_fields(data: dict[str, Any], where: str) -> None:
    """Check the plain fields of a parsed scene (module docstring); ValueError naming one.

    Parameters
    ----------
    data : dict
        The parsed TOML (tables already known to be tables).
    where : str
        Prefix of the message (``scene 'name' (path)``).
    """
    _top(data, where)
    _retry(data.get("retry", {}), where)
    _initial(data.get("initial", {}), where)
    _prsm(data.get("prsm", {}), data.get("topology", "direct"), where)
