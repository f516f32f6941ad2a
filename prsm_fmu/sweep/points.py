"""Running one point: the task a worker executes, on the FMU or on the model.

:func:`run_point` never raises for a problem of the point itself: an invalid parameter, a
refused FMU step or a failed integration comes back as a :class:`PointResult` whose
``status`` is ``"error"`` and whose ``error`` is the exception's type and message, so that a
study records it and goes on.

Each worker process keeps the FMUs it has loaded in :data:`_RUNNERS` (one
:class:`~prsm_fmu.sweep.fmu_runner.FmuRunner` per FMU file and thread) and reuses them for every
point it runs, resetting the instance between points: an FMU is extracted and instantiated
once per worker, not once per point.  The FMU reaches a worker either as a path on a shared
file system (local cluster) or as the file's bytes (a remote cluster: the client scatters
them once to every worker); either way it is identified by its SHA-256.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import pickle
import socket
import tempfile
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np

from ..params import MechanismParams
from ..profiles import ConstantSpeed, RampSpeed, SpeedProfile
from .metrics import compute_metrics, derive_series
from .series_files import save_series
from .study import apply_overrides, resolve_preset

__all__ = ["PointTask", "PointResult", "FmuFile", "run_point", "run_points", "run_chunk",
           "pack_chunk", "unpack_chunk", "worker_info", "speed_profile", "point_params"]

#: largest number of output intervals of one point
MAX_STEPS = 10_000_000


@dataclass(frozen=True)
class FmuFile:
    """An FMU as a task refers to it: its SHA-256, a path and (for remote workers) its bytes."""

    sha256: str
    path: str
    data: Any = None          # bytes, or a dask future of them, or None (use the path)


@dataclass(frozen=True)
class PointTask:
    """Everything a worker needs to run one point (picklable, no open resources)."""

    index: int
    id: str
    values: Mapping[str, Any]
    inputs: Mapping[str, Any]          # Study.point_inputs: preset, overrides, scenario, backend
    metrics: tuple[str, ...]
    fmus: Mapping[int, FmuFile] = field(default_factory=dict)   # stage count -> FMU


@dataclass
class PointResult:
    """What a point gives back: its row of the table, its series and how it was run."""

    index: int
    id: str
    values: Mapping[str, Any]
    status: str                        # "ok" or "error"
    error: str = ""
    metrics: dict[str, float] = field(default_factory=dict)
    series: dict[str, np.ndarray] | None = None
    wall_time: float = 0.0
    cpu_time: float = 0.0
    worker: str = ""
    fmu_instances: int = 0             # FMU instances this worker process has made so far
    fmu_points: int = 0                # points this worker's FMU runner has run so far


# ---------------------------------------------------------------------------------------------
# the worker's FMU cache
# ---------------------------------------------------------------------------------------------
_RUNNERS: dict[tuple[int, str], Any] = {}
_FILES: dict[str, str] = {}
_LOCK = threading.Lock()


def _fmu_path(ref: FmuFile) -> str:
    """A local path of the FMU file ``ref`` (written from its bytes if the path is not here)."""
    with _LOCK:
        if ref.sha256 in _FILES:
            return _FILES[ref.sha256]
        path = None
        if ref.path and os.path.isfile(ref.path):
            with open(ref.path, "rb") as fh:
                if hashlib.sha256(fh.read()).hexdigest() == ref.sha256:
                    path = ref.path
        if path is None:
            if ref.data is None:
                raise FileNotFoundError(f"FMU {ref.path!r} (sha256 {ref.sha256[:12]}) is not on "
                                        f"this worker ({socket.gethostname()}) and was not sent")
            data = bytes(ref.data)
            if hashlib.sha256(data).hexdigest() != ref.sha256:
                raise ValueError("the FMU bytes received do not match their SHA-256")
            d = tempfile.mkdtemp(prefix="prsm_sweep_fmu_")
            path = os.path.join(d, os.path.basename(ref.path) or f"{ref.sha256[:12]}.fmu")
            with open(path, "wb") as fh:
                fh.write(data)
        _FILES[ref.sha256] = path
        return path


def _runner(ref: FmuFile, tolerance: float):
    from .fmu_runner import FmuRunner

    key = (threading.get_ident(), ref.sha256)
    r = _RUNNERS.get(key)
    if r is None:
        r = FmuRunner(_fmu_path(ref), tolerance=tolerance)
        _RUNNERS[key] = r
    return r


def worker_info() -> dict[str, Any]:
    """This process's FMU runners: {sha256: (instances made, points run)} (for tests)."""
    return {sha: (r.instances_made, r.points_run) for (_, sha), r in _RUNNERS.items()}


def close_runners() -> None:
    """Free every FMU instance of this process."""
    for r in _RUNNERS.values():
        r.close()
    _RUNNERS.clear()


# ---------------------------------------------------------------------------------------------
# one point
# ---------------------------------------------------------------------------------------------
def speed_profile(screw_speed: float, accel_time: float) -> tuple[SpeedProfile, float]:
    """(the prescribed screw speed ω_ref(t) [rad/s], ω̇_ref(0⁺) [rad/s²]): a step to
    ``screw_speed`` at t = 0, or a linear ramp from rest over ``accel_time`` [s].  The profile
    serves both backends: the model follows it (:func:`prsm_fmu.simulate`), the FMU runner
    reads its ``speed(t)``."""
    w = float(screw_speed)
    if accel_time == 0.0:
        return ConstantSpeed(w), 0.0
    ta = float(accel_time)
    return RampSpeed(0.0, w, ta), w / ta


def _check_scenario(sc: Mapping[str, Any]) -> tuple[float, float, int]:
    t_end, h = sc["t_end"], sc["output_interval"]
    for name, v in (("t_end", t_end), ("output_interval", h)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v!r} is out of range: must be a finite number > 0 [s]")
    n = round(t_end / h)
    if n < 1 or abs(n * h - t_end) > 1e-9 * t_end:
        raise ValueError(f"t_end = {t_end!r} s must be a whole multiple of output_interval = "
                         f"{h!r} s")
    if n > MAX_STEPS:
        raise ValueError(f"output_interval = {h!r} s gives {n} intervals over t_end: at most "
                         f"{MAX_STEPS}")
    ta = sc["accel_time"]
    if not (isinstance(ta, (int, float)) and math.isfinite(ta) and ta >= 0):
        raise ValueError(f"accel_time = {ta!r} is out of range: must be a finite number >= 0 [s]")
    for name in ("screw_speed", "load_force"):
        v = sc[name]
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise ValueError(f"{name} = {v!r} is out of range: must be a finite number")
    if sc["screw_speed"] == 0.0:
        raise ValueError("screw_speed = 0 is out of range: must be non-zero [rad/s]")
    return float(t_end), float(h), n


def simulate_point(params, scenario: Mapping[str, Any], backend: str,
                   fmus: Mapping[int, FmuFile] | None = None,
                   tolerance: float = 1e-8) -> dict[str, np.ndarray]:
    """Run one scenario on the FMU or the model; the raw result (outputs → arrays).

    ``backend = "model"`` calls :func:`prsm_fmu.simulate` with ``drive="speed"`` and the
    prescribed profile (a ramp is followed exactly, with its inertial torque).
    ``backend = "fmu"`` runs the FMU with the speed prescribed by
    :class:`~prsm_fmu.sweep.fmu_runner.FmuRunner` (exact at every communication point; the
    driven torque includes the inertial torque of the ramp).
    """
    t_end, h, _ = _check_scenario(scenario)
    profile, acc0 = speed_profile(scenario["screw_speed"], scenario["accel_time"])
    fidelity = scenario["fidelity"]
    load = float(scenario["load_force"])
    if backend == "model":
        from ..simulate import simulate

        return simulate(params, fidelity=fidelity, drive="speed", screw_speed=profile,
                        load_force=load, t_end=t_end, output_interval=h)
    if backend != "fmu":
        raise ValueError(f"backend = {backend!r} is not allowed: must be 'fmu' or 'model'")
    ref = (fmus or {}).get(params.n_stages)
    if ref is None:
        raise ValueError(f"no FMU for {params.n_stages} stage(s) was given to this task")
    return _runner(ref, tolerance).run(params, fidelity, profile.speed, acc0, load, t_end, h)


def point_params(preset: str, overrides: Mapping[str, Any]) -> MechanismParams:
    """The validated mechanism of a point: ``preset`` with ``overrides`` applied
    (:func:`~prsm_fmu.sweep.study.apply_overrides`), then ``validate()``.

    Points with the same mechanism (a study that sweeps a scenario value, such as the load,
    beside a parameter) share one: the result is kept per process for overrides equal value
    for value *and* type (7 and 7.0, 0.0 and -0.0, True and 1 are different inputs: one may be
    refused where the other is not), in the same order.  An input that fails raises each time,
    with the same message.

    Raises
    ------
    ValueError
        As ``apply_overrides`` and ``validate``: naming the parameter, its value and range.
    """
    key = _exact_key(overrides) if isinstance(preset, str) else None
    if key is None:
        return _validated(preset, overrides)
    return _point_params(preset, key)


def _validated(preset: str, overrides: Mapping[str, Any]) -> MechanismParams:
    return apply_overrides(resolve_preset(preset), overrides).validate()


#: types of the override values that :func:`point_params` keeps results for
_KEYED = (bool, int, float, str)


def _exact_key(overrides: Mapping[str, Any]) -> tuple | None:
    """``overrides`` as a key equal only for the same names, types and values (a float's
    bits by its hex form: -0.0 is not 0.0), or None for a value of another type."""
    key = []
    for name, value in overrides.items():
        if type(value) not in _KEYED:
            return None
        key.append((name, type(value), value.hex() if type(value) is float else None, value))
    return tuple(key)


@functools.lru_cache(maxsize=256)
def _point_params(preset: str, key: tuple) -> MechanismParams:
    return _validated(preset, {name: value for name, _, _, value in key})


def run_point(task: PointTask, blobs: Mapping[str, bytes] | None = None,
              series_dir: str | None = None) -> PointResult:
    """Run one point; never raises for the point's own problems (module docstring).

    ``blobs`` maps an FMU's SHA-256 to its bytes, for workers that do not see its path.  With
    ``series_dir`` (a folder this process can write: the study's own, on a shared file system)
    the point's series is saved there (:func:`~prsm_fmu.sweep.series_files.save_series`) and
    the result carries none; else the result carries it.
    """
    wall0, cpu0 = time.perf_counter(), time.process_time()
    if blobs:
        task = replace(task, fmus={n: replace(ref, data=blobs.get(ref.sha256, ref.data))
                                   for n, ref in task.fmus.items()})
    result = PointResult(task.index, task.id, dict(task.values), "ok",
                         worker=f"{socket.gethostname()}:{os.getpid()}")
    try:
        inputs = task.inputs
        params = point_params(inputs["preset"], inputs["overrides"])
        res = simulate_point(params, inputs["scenario"], inputs["backend"], task.fmus)
        series = derive_series(res, params.n_stages)
        result.metrics = compute_metrics(series, task.metrics, int(res["rhs_calls"]))
        if series_dir is None:
            result.series = series
        else:
            save_series(series_dir, task.id, series)
    except Exception as exc:  # noqa: BLE001 - recorded in the table, the study goes on
        result.status = "error"
        result.error = f"{type(exc).__name__}: {exc}"
        result.metrics = {}
        result.series = None
    result.wall_time = time.perf_counter() - wall0
    result.cpu_time = time.process_time() - cpu0
    stats = [r for (tid, _), r in _RUNNERS.items() if tid == threading.get_ident()]
    result.fmu_instances = sum(r.instances_made for r in stats)
    result.fmu_points = sum(r.points_run for r in stats)
    return result


def run_points(tasks: Sequence[PointTask], blobs: Mapping[str, bytes] | None = None,
               series_dir: str | None = None) -> list[PointResult]:
    """Run a chunk of points one after the other (one Dask task for several points: the
    scheduler's and the round trip's cost per task is shared by them); each as
    :func:`run_point`."""
    return [run_point(t, blobs, series_dir) for t in tasks]


def pack_chunk(items: Sequence[Any]) -> bytes:
    """The points of one Dask task, or their results, as one pickle.

    On its way through Dask a chunk of Python objects is pickled and unpickled more than once
    (in this process, in the scheduler, which unpickles a task to read it and pickles it again
    for the worker, and in the worker), a ``list`` result element by element; as one ``bytes``
    object it is pickled once each way and only copied in between.  Dask's CPU per point of a
    chunk (this process, scheduler, worker and nanny together) went from 0.114 ms (list in,
    list out) to 0.025 ms (benchmarks/dask_task_cost.py, chunks of 1 and 200 model points,
    medians of 5 interleaved repeats; docs/sweeps.md): ~1.4 % of a model point of 6.5 ms.
    Numpy arrays in it (the series a worker that does not share this file system sends back)
    are copied into the pickle.
    """
    return pickle.dumps(tuple(items), protocol=pickle.HIGHEST_PROTOCOL)


def unpack_chunk(payload: bytes) -> tuple:
    """The items :func:`pack_chunk` packed."""
    return pickle.loads(payload)


def run_chunk(payload: bytes, blobs: Mapping[str, bytes] | None = None,
              series_dir: str | None = None) -> bytes:
    """The Dask task: :func:`run_points` on the packed :class:`PointTask` chunk, its
    :class:`PointResult` list packed (:func:`pack_chunk`)."""
    return pack_chunk(run_points(unpack_chunk(payload), blobs, series_dir))
