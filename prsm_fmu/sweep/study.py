"""Studies as data: a TOML file names a preset, a scenario, the swept parameters and the claims.

A study file (``studies/*.toml``; every value SI)::

    [study]
    name = "li2021_friction"               # default output directory: out/sweeps/<name>
    title = "Li et al. (2021) §3.2: friction coefficients"
    source = "Li et al. (2021) §3.2, Fig. 4"
    preset = "li2021_two_stage"            # prsm_fmu.presets key (or li2021_three_stage)
    backend = "fmu"                         # "fmu" (default) or "model" (prsm_fmu.simulate)
    notes = "..."                           # free text, copied into the report

    [scenario]                              # the fixed values of every point
    fidelity = "dynamic"                    # kinematic | quasi-static | dynamic
    screw_speed = 100.0                     # rad/s after the step / at the end of the ramp
    accel_time = 0.0                        # s: 0 = step at t = 0, carriers at rest;
                                            #    > 0 = linear ramp from rest over accel_time
    load_force = 5000.0                     # N on the last nut, positive resists extension
    t_end = 1e-3                            # s
    output_interval = 1e-6                  # s (the FMU's communication step)
    sample_times = [0.75e-3]                # s: extra metric columns <signal>@<t>

    [grid]                                  # Cartesian product, in the order written
    mu_screw_roller = [0.1, 0.2]
    mu_spline = [0.2, 0.3]

    [[zip]]                                 # parameters varied together: one axis
    "stage[1].pitch" = [0.001, 0.002, 0.003]
    "stage[2].pitch" = [0.003, 0.002, 0.001]

    [random]                                # n points drawn with numpy's default_rng(seed)
    n = 16
    seed = 1
    uniform = { mu_screw_roller = [0.05, 0.2] }
    loguniform = { load_force = [500.0, 5000.0] }
    choice = { n_stages = [1, 2] }

    [plots]
    x = "mu_screw_roller"                   # abscissa of the steady-values figure
    time_panels = ["carrier_speed_ratio", "contact_force", "efficiency", "spline_friction"]
    steady = ["efficiency@end", "stage[1].contact_force@end"]

    [[trend]]                               # a claim of the paper, checked on the table
    statement = "efficiency decreases as µ_SR increases"
    metric = "efficiency@end"
    vs = "mu_screw_roller"
    expect = "falls"                        # rises | falls | constant | positive | negative
    tolerance = 0.0                         # rises/falls: smallest step; constant: largest
                                            # spread (the metric's unit)
    relative = false                        # true: tolerance relative to max |metric|
    paper = "0.80 → 0.65"                   # optional: what the paper shows

    [metrics]                               # columns beyond the standard ones
    extra = ["stage[1].driven_torque@min"]  # <signal>@<reduction>, see sweep.metrics

The points are the Cartesian product of the axes: each ``[grid]`` key, each ``[[zip]]`` block
and the ``[random]`` block is one axis.  Swept (and fixed) names:

* mechanism: ``mu_screw_roller``, ``mu_spline``, ``mu_nut_screw``, ``slip_velocity_scale``,
  ``mu_viscous``, ``mu_differential``;
* stage k: ``stage[k].<field>`` for every field of :class:`~prsm_fmu.params.StageParams`, and
  ``stage[k].pitch`` (sets ``screw_lead = screw_starts × pitch``);
* structure: ``preset`` (another preset per point), ``n_stages`` (the first n stages of the
  preset);
* scenario: the keys of ``[scenario]`` above.

Fixed mechanism or stage values may also be given in ``[parameters]``.  Loading checks every
name and the shape of every value; the values themselves are checked when a point runs
(``MechanismParams.validate``), so that an invalid point is recorded with its error and the
others still run.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass, field, fields, replace
from typing import Any, Mapping, Sequence

import numpy as np

from ..params import MECHANISM_FIELD_NAMES, MechanismParams, StageParams

__all__ = ["Study", "Axis", "Point", "Trend", "load_study", "apply_overrides", "resolve_preset",
           "SCENARIO_DEFAULTS", "MECHANISM_NAMES", "BACKENDS", "parameter_kind"]

#: backends: the FMU (speed prescribed by the master) or the model through prsm_fmu.simulate
BACKENDS = ("fmu", "model")

#: mechanism-level parameters a study may set
MECHANISM_NAMES = MECHANISM_FIELD_NAMES

#: scenario keys and their defaults (None: required)
SCENARIO_DEFAULTS: dict[str, Any] = {
    "fidelity": "dynamic",
    "screw_speed": 100.0,
    "accel_time": 0.0,
    "load_force": 0.0,
    "t_end": None,
    "output_interval": None,
    "sample_times": (),
}

_STAGE_RE = re.compile(r"^stage\[(\d+)\]\.([a-z_]+)$")
_STAGE_FIELDS = tuple(f.name for f in fields(StageParams))
_INT_STAGE_FIELDS = ("screw_starts", "n_rollers", "carriers", "threads_per_roller")
_FIDELITIES = ("kinematic", "quasi-static", "dynamic")
_EXPECT = ("rises", "falls", "constant", "positive", "negative")

#: bump when the meaning of a point's inputs changes (old results are then not reused)
POINT_FORMAT = 1


class StudyError(ValueError):
    """A study file is malformed; the message names the file, the key and the problem."""


def parameter_kind(name: str) -> str:
    """``mechanism``, ``stage``, ``structure`` or ``scenario``; raises for an unknown name."""
    if name in MECHANISM_NAMES:
        return "mechanism"
    if name in ("preset", "n_stages"):
        return "structure"
    if name in SCENARIO_DEFAULTS:
        return "scenario"
    m = _STAGE_RE.match(name)
    if m and int(m.group(1)) >= 1 and (m.group(2) in _STAGE_FIELDS or m.group(2) == "pitch"):
        return "stage"
    raise KeyError(name)


def resolve_preset(name: str) -> MechanismParams:
    """A preset by registry key; also ``li2021_three_stage`` (PRSM3's parameters).

    A preset is built and validated once per process and name (every point of a study asks
    for it; its parameters are frozen, so the one object serves them all); a name that fails
    raises each time it is asked for, with the same message.

    Raises
    ------
    ValueError
        If the name is unknown or not a multi-stage PRSM.
    """
    if isinstance(name, str):
        return _preset_of_name(name)
    return _build_preset(name)


@functools.lru_cache(maxsize=64)
def _preset_of_name(name: str) -> MechanismParams:
    return _build_preset(name)


def _build_preset(name: str) -> MechanismParams:
    """:func:`resolve_preset` without its cache."""
    from .. import presets

    try:
        p = presets.load(name)
    except ValueError:
        # the three-stage mechanism lives with the FMU builder
        from fmu_build.mechanisms import FMUS

        for make, source in FMUS.values():
            if source == name:
                return make()
        raise
    if not isinstance(p, MechanismParams):
        raise ValueError(f"preset {name!r} is not a planetary roller screw mechanism the models "
                         "can run: must be one of "
                         + ", ".join(n for n in presets.names()
                                     if isinstance(presets.load(n), MechanismParams)))
    return p


def apply_overrides(params: MechanismParams, values: Mapping[str, Any]) -> MechanismParams:
    """``params`` with mechanism and stage values replaced (no validation).

    ``n_stages`` keeps the first n stages; ``stage[k].pitch`` sets the lead after the other
    stage fields (so that a swept ``screw_starts`` is used).  Scenario and ``preset`` keys are
    ignored.

    Raises
    ------
    ValueError
        For a stage index beyond the mechanism or an n_stages out of range.
    """
    if "n_stages" in values:
        n = values["n_stages"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= params.n_stages:
            raise ValueError(f"n_stages = {n!r} is out of range: must be an integer in "
                             f"[1, {params.n_stages}] (the stages of preset {params.name!r})")
        params = replace(params, stages=params.stages[:n])
    mech = {k: v for k, v in values.items() if k in MECHANISM_NAMES}
    if mech:
        params = params.with_changes(**mech)
    pitches = []
    for name, value in values.items():
        m = _STAGE_RE.match(name)
        if not m:
            continue
        k, f = int(m.group(1)), m.group(2)
        if not 1 <= k <= params.n_stages:
            raise ValueError(f"{name} = {value!r}: stage {k} is out of range: must be in "
                             f"[1, {params.n_stages}] (the stages of the mechanism)")
        if f == "pitch":
            pitches.append((k, value))
        else:
            params = params.with_stage(k, **{f: value})
    for k, pitch in pitches:
        params = params.with_stage(k, screw_lead=params.stages[k - 1].screw_starts * pitch)
    return params


@dataclass(frozen=True)
class Axis:
    """One axis of the point set: its parameter names and the rows of values they take."""

    kind: str                                  # "grid", "zip" or "random"
    names: tuple[str, ...]
    rows: tuple[tuple[Any, ...], ...]


@dataclass(frozen=True)
class Point:
    """One point: its index in the study, its swept values and its identity."""

    index: int
    values: Mapping[str, Any]
    id: str


@dataclass(frozen=True)
class Trend:
    """A claim of a paper about how a metric depends on a swept parameter."""

    statement: str
    metric: str
    vs: str
    expect: str
    tolerance: float = 0.0
    paper: str = ""
    relative: bool = False


@dataclass(frozen=True)
class Study:
    """A parameter study loaded from TOML (module docstring)."""

    name: str
    title: str
    source: str
    preset: str
    backend: str
    scenario: Mapping[str, Any]
    parameters: Mapping[str, Any]
    axes: tuple[Axis, ...]
    metrics: tuple[str, ...] = ()
    plots: Mapping[str, Any] = field(default_factory=dict)
    trends: tuple[Trend, ...] = ()
    notes: str = ""
    path: str = ""

    @property
    def swept(self) -> tuple[str, ...]:
        """Names of the swept parameters, in axis order."""
        return tuple(n for ax in self.axes for n in ax.names)

    def points(self) -> list[Point]:
        """Every point of the study, in a fixed order (the product of the axes)."""
        pts = []
        rows = [ax.rows for ax in self.axes] or [((),)]
        names = self.swept
        for i, combo in enumerate(itertools.product(*rows)):
            flat = tuple(v for row in combo for v in row)
            values = dict(zip(names, flat))
            pts.append(Point(i, values, self.point_id(values)))
        return pts

    def point_inputs(self, values: Mapping[str, Any], backend: str | None = None) -> dict:
        """Everything a point's result depends on (preset, overrides, scenario, backend)."""
        scenario = dict(self.scenario)
        overrides = dict(self.parameters)
        preset = self.preset
        for k, v in values.items():
            kind = parameter_kind(k)
            if kind == "scenario":
                scenario[k] = v
            elif k == "preset":
                preset = v
            else:
                overrides[k] = v
        return {"format": POINT_FORMAT, "preset": preset, "overrides": overrides,
                "scenario": scenario, "backend": backend or self.backend}

    def point_id(self, values: Mapping[str, Any], backend: str | None = None) -> str:
        """A short hash of :meth:`point_inputs`: equal inputs, equal id."""
        text = json.dumps(self.point_inputs(values, backend), sort_keys=True, default=list)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]

    def max_stages(self) -> int:
        """Most stages any point can have (for the table's columns)."""
        presets = [self.preset]
        for ax in self.axes:
            if "preset" in ax.names:
                j = ax.names.index("preset")
                presets += [row[j] for row in ax.rows]
        n = 0
        for p in presets:
            try:
                n = max(n, resolve_preset(p).n_stages)
            except ValueError:
                pass
        return max(n, 1)

    def stage_counts(self) -> set[int]:
        """The stage counts the points can have (to know which FMUs are needed)."""
        counts = set()
        presets = {self.preset}
        n_values = {self.parameters.get("n_stages")} - {None}
        for ax in self.axes:
            if "preset" in ax.names:
                presets |= {row[ax.names.index("preset")] for row in ax.rows}
            if "n_stages" in ax.names:
                n_values |= {row[ax.names.index("n_stages")] for row in ax.rows}
        for p in presets:
            try:
                base = resolve_preset(p).n_stages
            except ValueError:
                continue
            if n_values:
                counts |= {n for n in n_values if isinstance(n, int) and 1 <= n <= base}
            else:
                counts.add(base)
        return counts


# ---------------------------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------------------------
def _check_value(where: str, name: str, value: Any) -> Any:
    """Shape check of one parameter value (type, finiteness); ranges are checked at run time."""
    kind = parameter_kind(name)
    if name == "preset":
        if not isinstance(value, str):
            raise StudyError(f"{where}: preset = {value!r} must be a preset name (string)")
        return value
    if name == "fidelity":
        if value not in _FIDELITIES:
            raise StudyError(f"{where}: fidelity = {value!r} must be one of "
                             f"{', '.join(_FIDELITIES)}")
        return value
    if name == "sample_times":
        if not isinstance(value, (list, tuple)) or not all(
                isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t)
                and t >= 0 for t in value):
            raise StudyError(f"{where}: sample_times = {value!r} must be a list of times >= 0 [s]")
        return tuple(float(t) for t in value)
    m = _STAGE_RE.match(name)
    integer = name == "n_stages" or (m is not None and m.group(2) in _INT_STAGE_FIELDS)
    if integer:
        if isinstance(value, bool) or not isinstance(value, int):
            raise StudyError(f"{where}: {name} = {value!r} must be an integer")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise StudyError(f"{where}: {name} = {value!r} must be a finite number "
                         f"({kind} parameter, SI units)")
    return float(value)


def _check_name(where: str, name: str) -> None:
    try:
        parameter_kind(name)
    except KeyError:
        raise StudyError(
            f"{where}: unknown parameter {name!r}: must be one of {', '.join(MECHANISM_NAMES)}, "
            f"stage[k].<{' | '.join(_STAGE_FIELDS + ('pitch',))}>, preset, n_stages, "
            f"{', '.join(SCENARIO_DEFAULTS)}") from None


def _axes(doc: Mapping[str, Any], where: str) -> list[Axis]:
    axes: list[Axis] = []
    grid = doc.get("grid", {})
    if not isinstance(grid, dict):
        raise StudyError(f"{where}: [grid] must be a table of name = [values]")
    for name, values in grid.items():
        _check_name(f"{where} [grid]", name)
        if not isinstance(values, list) or not values:
            raise StudyError(f"{where} [grid]: {name} must be a non-empty list of values")
        rows = tuple((_check_value(f"{where} [grid]", name, v),) for v in values)
        axes.append(Axis("grid", (name,), rows))
    zips = doc.get("zip", [])
    if not isinstance(zips, list):
        raise StudyError(f"{where}: zip must be an array of tables ([[zip]])")
    for j, block in enumerate(zips, start=1):
        w = f"{where} [[zip]] #{j}"
        if not isinstance(block, dict) or not block:
            raise StudyError(f"{w}: must be a table of name = [values]")
        lengths = set()
        for name, values in block.items():
            _check_name(w, name)
            if not isinstance(values, list) or not values:
                raise StudyError(f"{w}: {name} must be a non-empty list of values")
            lengths.add(len(values))
        if len(lengths) != 1:
            raise StudyError(f"{w}: every list must have the same length (got "
                             f"{', '.join(f'{k}: {len(v)}' for k, v in block.items())})")
        names = tuple(block)
        rows = tuple(tuple(_check_value(w, n, block[n][i]) for n in names)
                     for i in range(lengths.pop()))
        axes.append(Axis("zip", names, rows))
    rnd = doc.get("random")
    if rnd is not None:
        axes.append(_random_axis(rnd, f"{where} [random]"))
    seen: set[str] = set()
    for ax in axes:
        for n in ax.names:
            if n in seen:
                raise StudyError(f"{where}: {n} is swept on two axes")
            seen.add(n)
    return axes


def _random_axis(rnd: Any, where: str) -> Axis:
    if not isinstance(rnd, dict):
        raise StudyError(f"{where}: must be a table")
    n, seed = rnd.get("n"), rnd.get("seed", 0)
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise StudyError(f"{where}: n = {n!r} must be an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise StudyError(f"{where}: seed = {seed!r} must be an integer")
    unknown = set(rnd) - {"n", "seed", "uniform", "loguniform", "choice"}
    if unknown:
        raise StudyError(f"{where}: unknown keys {sorted(unknown)}: allowed n, seed, uniform, "
                         "loguniform, choice")
    rng = np.random.default_rng(seed)
    names: list[str] = []
    columns: list[list[Any]] = []
    for dist in ("uniform", "loguniform", "choice"):
        table = rnd.get(dist, {})
        if not isinstance(table, dict):
            raise StudyError(f"{where}: {dist} must be a table of name = [...]")
        for name, spec in table.items():
            _check_name(f"{where}.{dist}", name)
            if dist == "choice":
                if not isinstance(spec, list) or not spec:
                    raise StudyError(f"{where}.choice: {name} must be a non-empty list")
                opts = [_check_value(f"{where}.choice", name, v) for v in spec]
                col = [opts[int(i)] for i in rng.integers(0, len(opts), size=n)]
            else:
                if not (isinstance(spec, list) and len(spec) == 2):
                    raise StudyError(f"{where}.{dist}: {name} must be [low, high]")
                lo, hi = (_check_value(f"{where}.{dist}", name, v) for v in spec)
                if not lo < hi or (dist == "loguniform" and lo <= 0):
                    raise StudyError(f"{where}.{dist}: {name} = [{lo}, {hi}] needs low < high"
                                     + (" and low > 0" if dist == "loguniform" else ""))
                u = rng.random(n)
                col = list(lo + u * (hi - lo)) if dist == "uniform" else \
                    list(np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))))
                col = [float(v) for v in col]
            names.append(name)
            columns.append(col)
    if not names:
        raise StudyError(f"{where}: give at least one of uniform, loguniform, choice")
    return Axis("random", tuple(names), tuple(zip(*columns)))


def _trends(doc: Mapping[str, Any], where: str, swept: Sequence[str]) -> tuple[Trend, ...]:
    out = []
    for j, t in enumerate(doc.get("trend", []), start=1):
        w = f"{where} [[trend]] #{j}"
        if not isinstance(t, dict):
            raise StudyError(f"{w}: must be a table")
        missing = [k for k in ("statement", "metric", "vs", "expect") if k not in t]
        if missing:
            raise StudyError(f"{w}: missing {', '.join(missing)}")
        if t["expect"] not in _EXPECT:
            raise StudyError(f"{w}: expect = {t['expect']!r} must be one of {', '.join(_EXPECT)}")
        if t["vs"] not in swept:
            raise StudyError(f"{w}: vs = {t['vs']!r} is not a swept parameter "
                             f"({', '.join(swept)})")
        tol = t.get("tolerance", 0.0)
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol >= 0:
            raise StudyError(f"{w}: tolerance = {tol!r} must be a number >= 0")
        rel = t.get("relative", False)
        if not isinstance(rel, bool):
            raise StudyError(f"{w}: relative = {rel!r} must be true or false")
        unknown = set(t) - {"statement", "metric", "vs", "expect", "tolerance", "paper",
                            "relative"}
        if unknown:
            raise StudyError(f"{w}: unknown keys {sorted(unknown)}")
        out.append(Trend(str(t["statement"]), str(t["metric"]), str(t["vs"]), str(t["expect"]),
                         float(tol), str(t.get("paper", "")), rel))
    return tuple(out)


def load_study(path: str | os.PathLike, backend: str | None = None) -> Study:
    """Read and check a study file.

    Parameters
    ----------
    path : path-like
        The TOML file.
    backend : str, optional
        Overrides the file's ``backend``.

    Raises
    ------
    StudyError
        Naming the file, the key and the problem.
    """
    where = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{where}: not valid TOML: {exc}") from None
    allowed = {"study", "scenario", "parameters", "grid", "zip", "random", "plots", "trend",
               "metrics"}
    unknown = set(doc) - allowed
    if unknown:
        raise StudyError(f"{where}: unknown sections {sorted(unknown)}: allowed "
                         f"{', '.join(sorted(allowed))}")
    head = doc.get("study", {})
    for key in ("name", "preset"):
        if not isinstance(head.get(key), str) or not head.get(key):
            raise StudyError(f"{where} [study]: {key} must be a non-empty string")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", head["name"]):
        raise StudyError(f"{where} [study]: name = {head['name']!r} may hold letters, digits, "
                         "'_', '.', '-' only (it names the output directory)")
    try:
        resolve_preset(head["preset"])
    except ValueError as exc:
        raise StudyError(f"{where} [study]: {exc}") from None
    be = backend or head.get("backend", "fmu")
    if be not in BACKENDS:
        raise StudyError(f"{where}: backend = {be!r} must be one of {', '.join(BACKENDS)}")
    scenario = dict(SCENARIO_DEFAULTS)
    for key, value in doc.get("scenario", {}).items():
        if key not in SCENARIO_DEFAULTS:
            raise StudyError(f"{where} [scenario]: unknown key {key!r}: allowed "
                             f"{', '.join(SCENARIO_DEFAULTS)}")
        scenario[key] = _check_value(f"{where} [scenario]", key, value)
    parameters = {}
    for key, value in doc.get("parameters", {}).items():
        _check_name(f"{where} [parameters]", key)
        if parameter_kind(key) == "scenario" or key == "preset":
            raise StudyError(f"{where} [parameters]: {key} belongs in [study] or [scenario]")
        parameters[key] = _check_value(f"{where} [parameters]", key, value)
    axes = _axes(doc, where)
    swept = tuple(n for ax in axes for n in ax.names)
    fixed_scenario = {k for k in swept if parameter_kind(k) == "scenario"}
    for key in ("t_end", "output_interval"):
        if scenario[key] is None and key not in fixed_scenario:
            raise StudyError(f"{where} [scenario]: {key} is required [s]")
    metrics = doc.get("metrics", {}).get("extra", [])
    if not isinstance(metrics, list) or not all(isinstance(m, str) for m in metrics):
        raise StudyError(f"{where} [metrics]: extra must be a list of metric names")
    plots = doc.get("plots", {})
    if not isinstance(plots, dict):
        raise StudyError(f"{where}: [plots] must be a table")
    if "x" in plots and plots["x"] not in swept:
        raise StudyError(f"{where} [plots]: x = {plots['x']!r} is not a swept parameter")
    study = Study(name=head["name"], title=str(head.get("title", head["name"])),
                  source=str(head.get("source", "")), preset=head["preset"], backend=be,
                  scenario=scenario, parameters=parameters, axes=tuple(axes),
                  metrics=tuple(metrics), plots=plots, trends=_trends(doc, where, swept),
                  notes=str(head.get("notes", "")), path=where)
    seen_ids: dict[str, Point] = {}
    for p in study.points():
        if p.id in seen_ids:
            raise StudyError(f"{where}: points {seen_ids[p.id].index} and {p.index} are the same "
                             f"point ({dict(p.values)}): remove the repeated value")
        seen_ids[p.id] = p
    return study
