"""Scenes: what to simulate and what it must show, as data (TOML files).

A scene is a TOML file: the built-in ones are ``system_models/scenes/*.toml``; a user adds one
by writing a file into ``./scenes/`` (the directory the command runs in) or passing its path to
``prsm-ema run --scene``.  TOML because it is readable, takes comments (every number can carry
its reason next to it), has typed numbers and nested tables, and Python 3.11 reads it with
the standard library (``tomllib``).

Layout (every table but ``[controller]`` optional; SI units; see the built-in scenes)::

    description = "one line"
    t_end = 0.25                 # [s]
    step = 1e-4                  # communication step h [s]
    order = "gauss-seidel"       # or "jacobi"
    extrapolation = 1            # 0 or 1
    fidelity = "quasi-static"    # the FMU's fidelity parameter
    outputs = ["prsm.rod_position", ...]   # the outputs that matter (printed, plotted first)

    [controller]                 # mode, reference profile (system_models.signals), design
    mode = "position"            #   keys of ControllerParams.design and field overrides
    reference = { kind = "step", initial = 0.0, final = 0.01, time = 0.01 }
    [motor]                      # MotorParams field overrides
    [load]                       # LoadParams field overrides and external_force (a profile)
    [prsm]                       # mechanism = "PRSM2", parameters = { FMU name = value }
    [initial]                    # screw_speed, rod_position, carriers = "rest"|"equilibrium",
                                 #   steady = true|false
    [retry]                      # max_halvings, tolerance (RetryPolicy)
    topology = "geared"          # optional (default "direct"): which blocks (TOPOLOGIES)
    [gear]                       # geared only: GearParams fields, initial_side
    [[check]]                    # one table per requirement (system_models.analysis.CHECKS)
    kind = "step_response"
    ...
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Scene", "load_scene", "list_scenes", "scene_dirs", "BUILTIN_DIR"]

BUILTIN_DIR = Path(__file__).resolve().parent / "scenes"

#: the PRSM FMU's fidelity parameter values
FIDELITIES = ("kinematic", "quasi-static", "dynamic", "auto")

_TOP = {"description", "t_end", "step", "order", "extrapolation", "fidelity", "outputs",
        "controller", "motor", "load", "prsm", "initial", "retry", "check", "t0", "topology", "gear"}

#: which blocks a scene assembles (docs/ema.md): ``direct`` the PMSM in dq with the digital
#: cascade driving the screw directly and the spring-damper load (system_models.ema);
#: ``geared`` a current-fed motor through a gear reduction, the continuous cascade on the
#: measured motor angle, the load behind an elastic gap contact (system_models.geared)
TOPOLOGIES = ("direct", "geared")


@dataclass
class Scene:
    """A scene read from TOML (module docstring); tables are kept as dicts."""

    name: str
    description: str
    t_end: float
    step: float
    order: str = "gauss-seidel"
    extrapolation: int = 1
    fidelity: str = "quasi-static"
    t0: float = 0.0
    outputs: list[str] = field(default_factory=list)
    controller: dict[str, Any] = field(default_factory=dict)
    motor: dict[str, Any] = field(default_factory=dict)
    load: dict[str, Any] = field(default_factory=dict)
    prsm: dict[str, Any] = field(default_factory=dict)
    initial: dict[str, Any] = field(default_factory=dict)
    retry: dict[str, Any] = field(default_factory=dict)
    checks: list[dict[str, Any]] = field(default_factory=list)
    path: Path | None = None
    topology: str = "direct"
    gear: dict[str, Any] = field(default_factory=dict)


def scene_dirs() -> list[Path]:
    """Where scenes are looked up by name: ``./scenes`` first, then the built-in ones."""
    return [Path.cwd() / "scenes", BUILTIN_DIR]


def _positive(data: dict, key: str, where: str) -> float:
    v = data.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise ValueError(f"{where}: {key} = {v!r} is out of range: must be a number > 0")
    return float(v)


def parse_scene(data: dict[str, Any], name: str, path: Path | None = None) -> Scene:
    """A :class:`Scene` from the parsed TOML; ValueError naming the field on a mistake."""
    where = f"scene {name!r}" + (f" ({path})" if path else "")
    unknown = set(data) - _TOP
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)} (allowed: {sorted(_TOP)})")
    if "controller" not in data:
        raise ValueError(f"{where}: the [controller] table (mode, reference) is missing")
    for key in ("controller", "motor", "load", "prsm", "initial", "retry", "gear"):
        if key in data and not isinstance(data[key], dict):
            raise ValueError(f"{where}: {key} must be a table")
    from .scene_types import check_fields

    check_fields(data, where)
    checks = data.get("check", [])
    if not isinstance(checks, list) or not all(isinstance(c, dict) and "kind" in c for c in checks):
        raise ValueError(f"{where}: every [[check]] must be a table with a 'kind'")
    from .analysis import validate_check

    for i, c in enumerate(checks, start=1):
        validate_check(c, f"{where}: check {i}")
    fid = data.get("fidelity", "quasi-static")
    if fid not in FIDELITIES:
        raise ValueError(f"{where}: fidelity = {fid!r} is not allowed: must be one of "
                         f"{', '.join(FIDELITIES)}")
    topology = data.get("topology", "direct")
    if topology not in TOPOLOGIES:
        raise ValueError(f"{where}: topology = {topology!r} is not allowed: must be one of "
                         f"{', '.join(TOPOLOGIES)}")
    if "gear" in data and topology != "geared":
        raise ValueError(f"{where}: a [gear] table needs topology = \"geared\"")
    outputs = data.get("outputs", [])
    if not isinstance(outputs, list) or not all(isinstance(o, str) for o in outputs):
        raise ValueError(f"{where}: outputs must be a list of 'block.port' names")
    return Scene(name=name, description=str(data.get("description", "")),
                 t_end=_positive(data, "t_end", where), step=_positive(data, "step", where),
                 order=data.get("order", "gauss-seidel"),
                 extrapolation=data.get("extrapolation", 1),
                 fidelity=data.get("fidelity", "quasi-static"),
                 t0=float(data.get("t0", 0.0)), outputs=list(outputs),
                 controller=dict(data["controller"]), motor=dict(data.get("motor", {})),
                 load=dict(data.get("load", {})), prsm=dict(data.get("prsm", {})),
                 initial=dict(data.get("initial", {})), retry=dict(data.get("retry", {})),
                 checks=[dict(c) for c in checks], path=path, topology=topology,
                 gear=dict(data.get("gear", {})))


#: what a scene *name* may contain: no path separator, no leading dot (names resolve only
#: inside the scene folders; anything else must be given as a path to a ``.toml`` file)
_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-")


def is_scene_path(name: str) -> bool:
    """True if ``name`` is given as a path (``./my.toml``, ``/abs/x.toml``, ``dir/x.toml``,
    ``x.toml``), False if it is a scene name looked up in the scene folders only."""
    return name.endswith(".toml") or "/" in name or "\\" in name or Path(name).is_absolute() \
        or name.startswith(".")


def _names() -> str:
    """The known scenes' names, for a refusal's message (every scene file is parsed: only when
    a name or path is refused, not for each scene found)."""
    return ", ".join(n for n, _ in list_scenes())


def _find(name: str) -> Path:
    if is_scene_path(name):
        p = Path(name)
        if p.suffix != ".toml":
            raise ValueError(f"--scene {name!r} is neither a scene name ({_names()}) nor a path to "
                             "a .toml file")
        if not p.is_file():
            raise ValueError(f"--scene {name!r}: scene file does not exist (scene names: "
                             f"{_names()})")
        return p
    if not name or not set(name) <= _NAME_CHARS:
        raise ValueError(f"--scene {name!r} is not a scene name: names are letters, digits, '_' "
                         f"and '-' ({_names()}), or give a path to a .toml file")
    for d in scene_dirs():
        f = d / f"{name}.toml"
        if f.is_file():
            return f
    raise ValueError(f"--scene: unknown scene {name!r}: must be one of {_names()} "
                     "or a path to a .toml file")


def load_scene(name: str) -> Scene:
    """Load a scene by name (``./scenes``, then built-in) or from a ``.toml`` path.

    A name resolves only inside the scene folders (:func:`scene_dirs`); a path is taken only
    when given as one (:func:`is_scene_path`) and must name a ``.toml`` file.

    Raises
    ------
    ValueError
        Unknown scene (the message lists the known ones), a TOML syntax error or a bad field.
    """
    path = _find(name)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"scene file {path}: {exc}") from None
    return parse_scene(data, path.stem, path)


def list_scenes() -> list[tuple[str, str]]:
    """(name, description) of every scene found, local ones first, built-in order otherwise."""
    seen: dict[str, str] = {}
    for d in scene_dirs():
        if not d.is_dir():
            continue
        for f in sorted(d.glob("*.toml")):
            if f.stem in seen:
                continue
            try:
                desc = str(tomllib.loads(f.read_text(encoding="utf-8")).get("description", ""))
            except (tomllib.TOMLDecodeError, OSError) as exc:
                desc = f"(unreadable: {exc})"
            seen[f.stem] = desc
    return list(seen.items())
