"""Regression cases, baselines on disk (CSV), running the FMU on the scenes and comparing.

A *case* is a scene of ``system_models/scenes`` at one fidelity level.  Its baseline is
``<dir>/<case>.csv``: a header ``time [s],prsm.screw_speed [rad/s],…`` (name and unit) and
one row per communication point, produced by :func:`update` with the FMU's ``tolerance``
parameter at ``baseline_tolerance`` (tight).  ``<dir>/tolerances.toml`` holds, per case, the
scene, the fidelity and the tube (``abs_frac`` × max|y_b| + ``rel``·|y_b|, widened by ``dt``),
with the reason next to each number.  The run compared with a baseline uses the scene's own
settings (the FMU's default tolerance), so the tube must cover the error those settings allow.

The simulation needs :mod:`system_models` and fmpy; nothing here is imported by the FMU's slave.
"""

from __future__ import annotations

import csv
import io
import math
import os
import subprocess
import sys
import tomllib
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..atomic import atomic_path
from ..command import child_failure, deferred_interrupt
from .tube import Tolerance, TubeResult, compare

__all__ = ["ROOT", "DEFAULT_DIR", "OUTPUTS", "Case", "Baseline", "CaseResult", "load_cases",
           "read_csv", "write_csv", "read_baselines", "baseline_columns", "build_fmu",
           "why_build", "scene_loop", "simulate_case", "LOOPS",
           "check_case", "check", "update"]

#: the repository (parent of the prsm_fmu package)
ROOT = Path(__file__).resolve().parents[2]
#: baselines of the repository
DEFAULT_DIR = ROOT / "baselines"

#: outputs stored for every case (those of a scene's ``outputs`` are added); only those the
#: run has are kept (stage 2 outputs exist for PRSM2 and PRSM3)
OUTPUTS = ("prsm.screw_speed", "prsm.rod_position", "prsm.rod_velocity",
           "prsm.stage[1].contact_force", "prsm.stage[2].contact_force",
           "prsm.stage[1].driven_torque", "prsm.stage[2].driven_torque",
           "prsm.stage[2].spline_friction", "prsm.stage[1].carrier_speed_ratio",
           "prsm.stage[2].carrier_speed_ratio", "prsm.efficiency", "prsm.friction_power",
           "prsm.friction_work", "motor.torque", "motor.current", "load.force",
           "controller.reference")

#: who takes a case's macro steps (:func:`scene_loop`): the actuator loop compiled to C
#: (system_models.native_loop, ~4x fewer seconds per step than the Python master) or the
#: Python master
LOOPS = ("native", "python")


@dataclass
class Case:
    """One regression case (a scene at one fidelity) and its tube (module docstring)."""

    name: str
    scene: str
    fidelity: str | None
    abs_frac: float
    rel: float
    dt: float
    outputs: dict[str, dict[str, float]] = field(default_factory=dict)   # per-output overrides
    parameters: dict[str, Any] = field(default_factory=dict)             # FMU start values

    def tolerance(self, output: str, baseline: np.ndarray) -> Tolerance:
        """The tube of ``output``: overrides of ``[case.X.outputs."name"]`` first."""
        o = self.outputs.get(output, {})
        frac = float(o.get("abs_frac", self.abs_frac))
        scale = largest_finite(baseline)
        a = frac * scale if scale > 0.0 else frac
        return Tolerance(abs=a, rel=float(o.get("rel", self.rel)), dt=float(o.get("dt", self.dt)))


@dataclass
class Baseline:
    """A baseline: time [s], outputs by name, units by name."""

    time: np.ndarray
    values: dict[str, np.ndarray]
    units: dict[str, str]


@dataclass
class CaseResult:
    """One case compared: the verdict per output and what the report plots."""

    case: Case
    results: list[TubeResult]
    plots: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    units: dict[str, str]
    error: str = ""

    @property
    def passed(self) -> bool:
        return not self.error and all(r.passed for r in self.results)

    def verdicts(self) -> dict[str, bool]:
        return {r.name: r.passed for r in self.results}


# ---- files ---------------------------------------------------------------------------------
def _source(where) -> tuple[str, Any]:
    """("dir", Path) or ("fmu", ZipFile path) for a baselines location."""
    p = Path(where)
    if p.suffix == ".fmu":
        return "fmu", p
    return "dir", p


def _read_text(where, name: str, first_line: bool = False) -> str:
    """The text of baseline file ``name`` (``first_line``: its first line only, with its
    newline: the header of a CSV, without reading the rows)."""
    kind, p = _source(where)
    if kind == "fmu":
        with zipfile.ZipFile(p) as z:
            try:
                with z.open(f"extra/baselines/{name}") as fh:
                    return (fh.readline() if first_line else fh.read()).decode("utf-8")
            except KeyError:
                raise FileNotFoundError(f"{p}: no extra/baselines/{name} in the FMU") from None
    with open(p / name, encoding="utf-8") as fh:
        return fh.readline() if first_line else fh.read()


def load_config(where=DEFAULT_DIR) -> dict[str, Any]:
    """The parsed ``tolerances.toml`` of a baselines directory or FMU."""
    return tomllib.loads(_read_text(where, "tolerances.toml"))


def load_cases(where=DEFAULT_DIR) -> list[Case]:
    """The cases of ``tolerances.toml``, in file order."""
    cfg = load_config(where)
    cases = []
    for name, c in cfg.get("case", {}).items():
        cases.append(Case(name=name, scene=c["scene"], fidelity=c.get("fidelity"),
                          abs_frac=float(c["abs_frac"]), rel=float(c.get("rel", 0.0)),
                          dt=float(c.get("dt", 0.0)), outputs=dict(c.get("outputs", {})),
                          parameters=dict(c.get("parameters", {}))))
    return cases


def _columns(header: str) -> tuple[list[str], dict[str, str]]:
    """Names and units of a baseline's header line ``name [unit],...``."""
    names, units = [], {}
    for h in next(csv.reader([header])):
        n, _, u = h.partition(" [")
        names.append(n)
        units[n] = u.rstrip("]")
    return names, units


def read_csv(text: str) -> Baseline:
    """Parse a baseline CSV (header ``name [unit]``, first column ``time [s]``); the numbers
    by numpy's parser (correctly rounded, as ``float()``)."""
    header, _, body = text.partition("\n")
    names, units = _columns(header)
    data = np.loadtxt(io.StringIO(body), delimiter=",", dtype=float, ndmin=2)
    return Baseline(data[:, 0], {n: data[:, j] for j, n in enumerate(names) if j > 0}, units)


def baseline_columns(where, case: str) -> list[str] | None:
    """The output names of a case's baseline (its header), None if it has none."""
    try:
        header = _read_text(where, f"{case}.csv", first_line=True).partition("\n")[0]
    except FileNotFoundError:
        return None
    return _columns(header)[0][1:]


def write_csv(path: Path, time: np.ndarray, values: dict[str, np.ndarray],
              units: dict[str, str]) -> None:
    """Write a baseline CSV (12 significant digits: rounding 5e-13, far inside every tube)."""
    names = list(values)
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["time [s]"] + [f"{n} [{units.get(n, '') or '1'}]" for n in names])
        for i, t in enumerate(time):
            w.writerow([f"{float(t):.12g}"] + [f"{float(values[n][i]):.12g}" for n in names])


def read_baselines(where=DEFAULT_DIR, cases: list[Case] | None = None) -> dict[str, Baseline]:
    """Baselines by case name (those whose CSV exists)."""
    out = {}
    for c in cases if cases is not None else load_cases(where):
        try:
            out[c.name] = read_csv(_read_text(where, f"{c.name}.csv"))
        except FileNotFoundError:
            pass
    return out


# ---- does an FMU fit the cases ----------------------------------------------------------------
def _stage_count(names) -> int:
    """Stages k = 1, 2, ... with a ``stage[k].contact_force`` among ``names``."""
    k = 0
    while f"stage[{k + 1}].contact_force" in names:
        k += 1
    return k


def fmu_mismatch(variables: Mapping[str, Any], where=DEFAULT_DIR,
                 cases: list[str] | None = None, outputs: bool = True) -> str:
    """Why an FMU cannot run the cases (one line), or "" if it can.

    Checked before anything runs, against what the cases need: the PRSM's stage count of every
    baseline (its ``prsm.stage[k].*`` columns) must be the FMU's, every ``prsm.NAME`` column
    must be an output ``NAME`` of the FMU, and every parameter a case or its scene sets must be
    a parameter of the FMU.

    Parameters
    ----------
    variables : mapping
        The FMU's variables, name -> :class:`prsm_fmu.fmu_variables.Variable`.
    where : path, optional
        Baselines directory or FMU holding them.
    cases : list of str, optional
        The cases to run; default every case.
    outputs : bool
        Also check the outputs (False for ``--update``, which may add or drop outputs on
        purpose; the stage count and the parameters are checked always).
    """
    from system_models.scenes import load_scene

    n_fmu = _stage_count(variables)
    chosen = [c for c in load_cases(where) if cases is None or c.name in cases]
    for c in chosen:
        columns = baseline_columns(where, c.name)
        if columns is None:
            continue
        prsm = [n.removeprefix("prsm.") for n in columns if n.startswith("prsm.")]
        n_case = _stage_count(prsm)
        if n_case != n_fmu:
            return (f"the FMU is a {n_fmu}-stage PRSM but case {c.name} is a {n_case}-stage "
                    f"one: must be a {n_case}-stage FMU (PRSM{n_case}.fmu)")
        missing = [n for n in prsm if getattr(variables.get(n), "causality", "") != "output"]
        if missing and outputs:
            return (f"the FMU has no output {', '.join(missing)} that case {c.name} compares: "
                    "must be an FMU built from this version (python -m fmu_build)")
        params = {**load_scene(c.scene).prsm.get("parameters", {}), **c.parameters}
        missing = [n for n in params if getattr(variables.get(n), "causality", "")
                   != "parameter"]
        if missing:
            return (f"the FMU has no parameter {', '.join(missing)} that case {c.name} sets: "
                    "must be an FMU built from this version (python -m fmu_build)")
    return ""


# ---- building and simulating ------------------------------------------------------------------
def build_fmu(dest: Path, name: str = "PRSM2") -> Path:
    """Build ``dest/<name>.fmu`` with ``python -m fmu_build`` in a child process.

    Raises
    ------
    RuntimeError
        If the build fails: one line with the child's exit status and its last line of error.
    """
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]]
                                                       if env.get("PYTHONPATH") else []))
    proc = subprocess.run([sys.executable, "-m", "fmu_build", name, "--dest", str(dest)],
                          capture_output=True, text=True, env=env, timeout=600)
    fmu = dest / f"{name}.fmu"
    if proc.returncode != 0 or not fmu.is_file():
        raise RuntimeError(child_failure(f"python -m fmu_build {name}", proc.returncode,
                                         proc.stderr, proc.stdout))
    return fmu


def why_build(fmu: Path) -> str | None:
    """Why ``fmu`` must be (re)built ("missing", or older than a file it is built from:
    :func:`system_models.fmu.fmu_is_stale`), None if it is up to date."""
    from system_models.fmu import fmu_is_stale

    return fmu_is_stale(fmu)


def scene_loop(scene, loop: str = "native") -> str:
    """Who takes the macro steps of ``scene`` (a :class:`system_models.scenes.Scene`):
    ``loop``, except "python" where ``loop`` is "native" and the C loop cannot run the scene
    (:func:`system_models.native_loop.check_native_loop`: not the direct topology, a retry
    policy with a coupling tolerance) or cannot be compiled (no gcc).  Both loops give the same
    outputs bit for bit (tests/test_native_loop.py, tests/test_regress.py)."""
    if loop not in LOOPS:
        raise ValueError(f"loop = {loop!r} is not allowed: must be one of {', '.join(LOOPS)}")
    if loop == "python":
        return loop
    from fmu_build.errors import BuildError
    from system_models.native_loop import check_native_loop, loop_library

    try:
        check_native_loop(scene.topology, "fmu", scene.retry.get("tolerance"))
        loop_library()
    except (ValueError, BuildError, OSError):
        return "python"
    return "native"


def simulate_case(case: Case, fmu: Path, tolerance: float | None = None,
                  parameters: dict[str, Any] | None = None, prsm: str = "fmu", progress=None,
                  loop: str = "native"):
    """Run the case's scene on the FMU (fmpy); returns the master's Result (the scene's checks
    are not evaluated).

    ``tolerance`` sets the FMU's ``tolerance`` parameter (None: the scene's, i.e. the FMU's
    default); ``parameters`` adds FMU start values (e.g. a changed ``mu_screw_roller``);
    ``progress(t, t_end)`` is called between macro steps (every step with the Python master,
    every 2048 with the C loop); ``loop``: who takes the macro steps (:func:`scene_loop`).
    """
    from system_models.run import build_scene_system
    from system_models.scenes import load_scene

    sc = load_scene(case.scene)
    par = {**sc.prsm.get("parameters", {}), **case.parameters, **(parameters or {})}
    if tolerance is not None:
        par["tolerance"] = tolerance
    sc = replace(sc, prsm={**sc.prsm, "parameters": par})
    # the run alone: not the scene's checks (run_scene's), which a case does not use (the
    # start-up's steady-state targets would be solved for nothing)
    system = build_scene_system(sc, prsm=prsm, fmu_path=fmu, fidelity=case.fidelity,
                                loop=scene_loop(sc, loop) if prsm == "fmu" else "python")
    return system.run(progress)


def case_outputs(case: Case, result) -> list[str]:
    """The outputs stored for ``case``: :data:`OUTPUTS` and the scene's, those the run has."""
    from system_models.scenes import load_scene

    names = list(OUTPUTS) + [n for n in load_scene(case.scene).outputs if n not in OUTPUTS]
    return [n for n in names if n in result]


def check_case(case: Case, baseline: Baseline, result) -> CaseResult:
    """Compare a run's Result with the case's baseline, output by output."""
    results, plots = [], {}
    for name, yb in baseline.values.items():
        if name not in result:
            results.append(TubeResult(name, False, math.inf, math.nan, math.nan, math.nan,
                                      math.inf, 0, math.nan, "output missing from the run"))
            continue
        tol = case.tolerance(name, yb)
        r, yi, lo, hi = compare(name, baseline.time, yb, result.time, result[name], tol)
        results.append(r)
        plots[name] = (baseline.time, yb, yi, lo, hi)
    return CaseResult(case, results, plots, baseline.units)


def check(fmu: Path, where=DEFAULT_DIR, cases: list[str] | None = None,
          parameters: dict[str, Any] | None = None,
          loop: str = "native") -> list[CaseResult]:
    """Run every case (or those named) on ``fmu`` and compare with the baselines at ``where``
    (a directory or an FMU with ``extra/baselines``), in this process (:func:`_run_cases`);
    ``loop``: who takes the macro steps (:func:`scene_loop`)."""
    all_cases = load_cases(where)
    chosen = [c for c in all_cases if cases is None or c.name in cases]
    unknown = set(cases or ()) - {c.name for c in all_cases}
    if unknown:
        raise ValueError(f"unknown case(s) {sorted(unknown)}: the cases are "
                         f"{', '.join(c.name for c in all_cases)}")
    bases = read_baselines(where, chosen)
    runnable = [c for c in chosen if c.name in bases]
    runs = dict(zip((c.name for c in runnable),
                    _run_cases(runnable, fmu, parameters, loop)))
    out = []
    for c in chosen:
        if c.name not in bases:
            out.append(CaseResult(c, [], {}, {}, error="no baseline (run prsm-fmu regress "
                                                       "--update)"))
            continue
        res = runs[c.name]
        if isinstance(res, str):                   # a failing run is a failing case
            out.append(CaseResult(c, [], {}, {}, error=f"the run failed: {res}"))
            continue
        out.append(check_case(c, bases[c.name], res))
    return out


def largest_finite(values: np.ndarray) -> float:
    """max |value| over the finite values (0.0 if none): the scale of an output, whose NaN
    samples (the efficiency where no power flows) are undefined, not values to scale by."""
    finite = np.abs(values[np.isfinite(values)])
    return float(np.max(finite)) if finite.size else 0.0


def _run_case(case: Case, fmu: Path, parameters: dict[str, Any] | None, progress=None,
              loop: str = "native"):
    """One case's Result, or the message of its failure (a string), in whatever process."""
    try:
        return simulate_case(case, fmu, parameters=parameters, progress=progress, loop=loop)
    except Exception as exc:  # noqa: BLE001 - a failing run is a failing case
        return str(exc) or type(exc).__name__


def _run_cases(cases: list[Case], fmu: Path, parameters: dict[str, Any] | None,
               loop: str = "native") -> list:
    """The cases' Results (or failure messages), in order, one after the other in this process,
    every case loading the FMU from its copy unpacked once and kept
    (:mod:`system_models.fmu_cache`).

    Not in parallel processes: with the C loop the seven runs take ~0.3 s of CPU, less than a
    spawned process costs (~0.8 s: a Python, numpy and what a run imports); forked helpers
    measured no less wall time on the 2 cores of the development machine under load
    (docs/regression.md, "How the cases run")."""
    # Ctrl-C between two macro steps, never inside the FMU's Python (there it would be the
    # FMU's fatal error, recorded as a failing case, and the next case would run)
    with deferred_interrupt() as interrupted:
        return [_run_case(c, fmu, parameters, lambda t, t_end: interrupted(), loop)
                for c in cases]


def update(fmu: Path, where: Path = DEFAULT_DIR, cases: list[str] | None = None,
           loop: str = "native") -> str:
    """Re-run the cases at ``baseline_tolerance``, write their CSVs and ``REPORT.md``
    (``loop``: :func:`scene_loop`).

    The report says, per case, which outputs moved outside the old baseline's tube (max
    difference, where) and which stayed inside; returns its text.
    """
    from datetime import datetime, timezone

    import prsm_fmu

    where = Path(where)
    cfg = load_config(where)
    tight = float(cfg["baseline_tolerance"])
    all_cases = load_cases(where)
    chosen = [c for c in all_cases if cases is None or c.name in cases]
    old = read_baselines(where, chosen)
    with zipfile.ZipFile(fmu) as z:
        xml = z.read("modelDescription.xml").decode("utf-8")
    tool = xml.split('generationTool="', 1)[1].split('"', 1)[0] if "generationTool" in xml else "?"
    lines = ["# Baseline update report", "",
             f"Written by `prsm-fmu regress --update` on "
             f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, prsm-fmu "
             f"{prsm_fmu.__version__}, FMU `{Path(fmu).name}` ({tool}), FMU parameter "
             f"`tolerance = {tight:g}`.", "",
             "Changes against the previous baselines, measured with each case's tube "
             "(tolerances.toml); |Δ|/max|y| is the largest difference over the run divided by "
             "the output's largest magnitude.", ""]
    with deferred_interrupt() as interrupted:      # as in check()
        runs = {c.name: simulate_case(c, fmu, tolerance=tight,
                                      progress=lambda t, t_end: interrupted(), loop=loop)
                for c in chosen}
    for c in chosen:
        res = runs[c.name]
        names = case_outputs(c, res)
        write_csv(where / f"{c.name}.csv", res.time, {n: res[n] for n in names},
                  {n: res.units.get(n, "") for n in names})
        lines.append(f"## {c.name}")
        lines.append("")
        if c.name not in old:
            lines += [f"New baseline: {len(res.time)} points, {res.time[-1]:g} s, "
                      f"{len(names)} outputs.", ""]
            continue
        cr = check_case(c, old[c.name], res)
        moved = [r for r in cr.results if not r.passed]
        added = [n for n in names if n not in old[c.name].values]
        if not moved and not added:
            worst = max(cr.results, key=lambda r: r.max_abs_diff
                        / (largest_finite(old[c.name].values[r.name]) or 1.0))
            scale = largest_finite(old[c.name].values[worst.name]) or 1.0
            lines += [f"Unchanged within the tube: largest |Δ|/max|y| = "
                      f"{worst.max_abs_diff / scale:.2e} ({worst.name}).", ""]
            continue
        for r in moved:
            scale = largest_finite(old[c.name].values[r.name]) or 1.0
            lines.append(f"- **{r.name}** left the old tube: |Δ|/max|y| = "
                         f"{r.max_abs_diff / scale:.2e}, first at t = {r.first_out:g} s, "
                         f"largest excess {r.excess:.3g} {cr.units.get(r.name, '')} at "
                         f"t = {r.t_worst:g} s ({r.n_out} points){' — ' + r.reason if r.reason else ''}")
        for n in added:
            lines.append(f"- {n}: new output")
        lines.append("")
    lines += ["## Review", "",
              "Reviewed by: (name, date — what was checked and why the changes are intended)", ""]
    text = "\n".join(lines)
    with atomic_path(where / "REPORT.md") as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return text
