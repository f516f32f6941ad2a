"""Run a study: on a Dask cluster (a local one by default) or in a plain loop; resume; report.

:func:`run_study` turns a :class:`~prsm_fmu.sweep.study.Study` into

``OUT/results.csv``
    the table (:mod:`prsm_fmu.sweep.table`), one row per point in point order;
``OUT/series/<id>.npz``
    each point's time series (for the figures and for later reading);
``OUT/time.png``, ``OUT/steady.png``
    the figures (:mod:`prsm_fmu.sweep.plots`);
``OUT/report.md``
    the study, the paper's claims with the table's verdicts, the failed points, the figures;
``OUT/timing.csv``
    where and how long each point of this run took (not part of the table);
``OUT/fmu/PRSM<n>-native.fmu`` (or ``PRSM<n>.fmu``)
    the FMUs the points ran on, the native FMU by default (:data:`FMU_KINDS`; built with
    ``python -m fmu_build`` in a child process unless ``fmu_dir`` has them);
``OUT/study.txt``
    the name of the study the folder belongs to: a folder that holds another study's results
    is refused (:func:`claim_out_dir`), so one study never overwrites another's table and
    figures.  The command line puts each study in a folder of its own, ``OUT/<study name>/``.

Execution
---------
``executor="dask"`` (default): with ``scheduler=None`` a ``LocalCluster`` of ``workers``
processes (default: the machine's cores) with one thread each is started and closed again
(:func:`local_cluster`: scheduler, workers, nannies and the HTTP/dashboard server all listen on
the loopback interface only, so a local study exposes nothing beyond this machine); only with
``scheduler="tcp://host:port"`` do the points go to another cluster, and the FMU files are sent
to its workers once (``Client.scatter(..., broadcast=True)``), since they may not share this
machine's file system (they need ``prsm_fmu``, numpy, scipy and fmpy installed, pythonfmu for
the Python FMU).
A ready ``client`` may be passed instead.  ``executor="loop"`` runs the points one after the
other in this process (the reference the Dask overhead is measured against).

The points go to the workers in chunks (:func:`chunk_size`), each submitted once
(``retries=0``, ``pure=False``): about :data:`CHUNK_SECONDS` of CPU each at the latest
chunk's CPU time per point (so Dask's cost per task, ~7 ms of CPU, stays near 0.35 % of the
work; a point of more than that is a chunk of its own), packed into one pickle each way
(:func:`~prsm_fmu.sweep.points.pack_chunk`), shrinking towards the end (so the workers
finish together) but not below :data:`MIN_CHUNK_SECONDS` of CPU, :data:`IN_FLIGHT` per worker, the next submitted as
soon as one comes back.  A chunk's results are appended to the table as soon as it is done,
so an interrupted study keeps every finished chunk; where the workers share this file system
they save each point's series themselves (:mod:`~prsm_fmu.sweep.series_files`).  The local
cluster runs quiet (:data:`QUIET_CLUSTER`).  The progress bar shows the points done, failed
and the time left, and so does the page ``/prsm-progress`` of the dashboard's server
(:mod:`~prsm_fmu.sweep.dashboard`); Dask's own dashboard (with bokeh) shows the chunks
(``prsm-points``) done of those submitted.  A rerun with the same output directory skips the
points whose id (a hash of the point's preset, parameters, scenario and backend) is already in
the table with status ``ok`` and whose series file exists; failed points are run again.  A point whose worker dies is
recorded as failed with the scheduler's message.
"""

from __future__ import annotations

import hashlib
import logging
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence, TextIO

import numpy as np

from ..atomic import atomic_path
from ..command import child_failure, deferred_interrupt
from ..extras import require
from .metrics import standard_metrics
from .points import (FmuFile, PointResult, PointTask, pack_chunk, run_chunk, run_point,
                     unpack_chunk)
from .series_files import load_series, save_series
from .study import Study
from .table import (append_rows, columns, markdown_table, numeric_rows, read_table, row_of,
                    write_table)
from .trends import TrendResult, evaluate

__all__ = ["run_study", "claim_out_dir", "STUDY_MARKER", "SweepResult", "ensure_fmus",
           "metric_columns", "load_series", "EXECUTORS", "Progress", "local_cluster", "LOOPBACK",
           "eta", "chunk_size", "CHUNK_SECONDS", "IN_FLIGHT", "FMU_KINDS", "fmu_file_name",
           "default_fmu_kind"]

EXECUTORS = ("dask", "loop")

#: the interface every process of a local cluster listens on (never all interfaces)
LOOPBACK = "127.0.0.1"

#: most runs drawn in one time figure (evenly chosen over the points)
MAX_TIME_RUNS = 12


@dataclass
class SweepResult:
    """What :func:`run_study` did and where it put it."""

    study: Study
    out_dir: str
    table_path: str
    header: list[str]
    rows: list[dict[str, Any]]                     # the table, numbers as floats
    results: list[PointResult] = field(default_factory=list)    # the points run now
    skipped: int = 0                               # points already done before this run
    trends: list[TrendResult] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)
    wall_time: float = 0.0
    backend: str = ""
    fmu: str = ""                                  # the FMU kind of the FMU backend, or ""
    dask_tasks: int = 0                            # Dask tasks (chunks of points) submitted

    @property
    def failed(self) -> list[dict[str, Any]]:
        """Rows of failed points."""
        return [r for r in self.rows if r.get("status") != "ok"]


def metric_columns(study: Study) -> list[str]:
    """The metric columns of a study's table."""
    names = list(standard_metrics(study.max_stages(), study.scenario.get("sample_times", ())))
    for m in study.metrics:
        if m not in names:
            names.append(m)
    return names


def _sha256(path: str) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


#: the FMUs a sweep's FMU backend can run on: the native C FMU (``PRSM<n>-native.fmu``, the
#: compiled engine behind every FMI call) or the Python FMU (``PRSM<n>.fmu``, pythonfmu, the
#: engine behind its Python slave); the same results bit for bit where the Python FMU's engine
#: loads (tests/test_sweep.py)
FMU_KINDS = ("native", "python")


def check_fmu_kind(kind: str) -> None:
    """ValueError naming ``fmu`` unless ``kind`` is one of :data:`FMU_KINDS`."""
    if kind not in FMU_KINDS:
        raise ValueError(f"fmu = {kind!r} is not allowed: must be one of {', '.join(FMU_KINDS)}")


def fmu_file_name(n_stages: int, kind: str) -> str:
    """``PRSM<n>-native.fmu`` or ``PRSM<n>.fmu``: the file of an FMU of ``kind``."""
    check_fmu_kind(kind)
    return f"PRSM{n_stages}{'-native' if kind == 'native' else ''}.fmu"


def default_fmu_kind() -> tuple[str, str | None]:
    """(the FMU kind a sweep runs on by default, why not the native one or None): the native FMU
    where Zig's C compiler (the ``fmu`` extra's ziglang) can build it, else the Python FMU."""
    from fmu_build.platforms import zig_available

    if zig_available():
        return "native", None
    return "python", ("the native FMU needs Zig's C compiler (pip install ziglang, in the "
                      "'fmu' extra): the points run on the Python FMU")


def ensure_fmus(counts: Sequence[int], dest: str, fmu_dir: str | None = None,
                build: bool = True, kind: str = "python") -> dict[int, str]:
    """Paths of the FMUs of ``kind`` for every stage count, building the missing ones.

    An FMU is taken from ``fmu_dir`` if it is there (:func:`fmu_file_name`); otherwise it is
    built into ``dest`` with ``python -m fmu_build PRSM<n> --dest DEST`` in a child process
    (pythonfmu imports the generated slave module while building, docs/fmu.md), with
    ``--native --platform <this platform> --fmi-version 2`` for ``kind = "native"`` (the
    binary of this platform only: a local study's workers share it).

    Raises
    ------
    ValueError
        For a stage count without a standard FMU (1 to 3) or an unknown kind.
    RuntimeError
        If the build fails (one line: the child's exit status and its last line of error).
    """
    paths: dict[int, str] = {}
    missing = []
    for n in sorted(set(counts)):
        if n not in (1, 2, 3):
            raise ValueError(f"no standard FMU has {n} stages (PRSM1 … PRSM3): use the model "
                             "backend")
        name = fmu_file_name(n, kind)
        if fmu_dir and os.path.isfile(os.path.join(fmu_dir, name)):
            paths[n] = os.path.join(fmu_dir, name)
        else:
            missing.append(n)
    if missing:
        if not build:
            raise FileNotFoundError(f"missing FMUs {', '.join(fmu_file_name(n, kind) for n in missing)}")
        os.makedirs(dest, exist_ok=True)
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([root] + ([env["PYTHONPATH"]]
                                                      if env.get("PYTHONPATH") else []))
        cmd = [sys.executable, "-m", "fmu_build", *(f"PRSM{n}" for n in missing), "--dest", dest]
        if kind == "native":
            from ..engine import platform_folder

            cmd += ["--native", "--platform", platform_folder(), "--fmi-version", "2"]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600,
                              check=False)
        if proc.returncode != 0:
            raise RuntimeError(child_failure(f"building the FMUs ({' '.join(cmd[1:])})",
                                             proc.returncode, proc.stderr, proc.stdout))
        for n in missing:
            paths[n] = os.path.join(dest, fmu_file_name(n, kind))
    return paths


class Progress:
    """The study's progress: a text bar on ``stream`` (redrawn in place on a terminal, else
    every 10 %) and, where :attr:`publish` is set, the same line and counts handed to it (the
    Dask dashboard's progress page, :mod:`prsm_fmu.sweep.dashboard`) at most every
    :data:`PUBLISH_SECONDS` and at the end."""

    #: least time between two calls of :attr:`publish` [s]
    PUBLISH_SECONDS = 0.5

    def __init__(self, total: int, skipped: int, stream: TextIO | None, width: int = 30) -> None:
        self.total, self.skipped, self.stream, self.width = total, skipped, stream, width
        self.done = self.failed = 0
        self.t0 = time.perf_counter()
        self.tty = bool(stream is not None and getattr(stream, "isatty", lambda: False)())
        self._last_decile = -1
        self._published = -math.inf
        #: called with the progress state (:meth:`state`), or None
        self.publish: Callable[[dict], None] | None = None
        self._draw(force=True)

    def update(self, ok: int, failed: int = 0) -> None:
        """``ok`` more points done well and ``failed`` more failed; drawn once."""
        self.done += ok + failed
        self.failed += failed
        self._draw()

    def state(self) -> dict[str, Any]:
        """Points ``done``, ``failed``, ``total``, ``skipped``, ``elapsed`` [s], ``left`` [s]
        (None when unknown) and the bar's ``text``."""
        n = self.total
        frac = 1.0 if n == 0 else self.done / n
        filled = round(frac * self.width)
        bar = "#" * filled + "." * (self.width - filled)
        elapsed = time.perf_counter() - self.t0
        left = eta(elapsed, self.done, n)
        text = (f"[{bar}] {self.done}/{n} points, {self.failed} failed"
                f"{f', {self.skipped} already done' if self.skipped else ''}, "
                f"{elapsed:.1f} s{f', ~{left:.0f} s left' if left is not None else ''}")
        return {"done": self.done, "failed": self.failed, "total": n, "skipped": self.skipped,
                "elapsed": elapsed, "left": left, "text": text}

    def _draw(self, force: bool = False) -> None:
        n = self.total
        now = time.perf_counter()
        if self.publish is not None and (force or self.done >= n
                                         or now - self._published >= self.PUBLISH_SECONDS):
            self._published = now
            self.publish(self.state())
        if self.stream is None:
            return
        decile = int((1.0 if n == 0 else self.done / n) * 10)
        if not self.tty and not force and decile == self._last_decile and self.done < n:
            return
        self._last_decile = decile
        text = self.state()["text"]
        if self.tty:
            self.stream.write("\r" + text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.stream is not None and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def eta(elapsed: float, done: int, total: int) -> float | None:
    """Seconds left at the rate so far (None before the first point and once all are done)."""
    if done <= 0 or done >= total:
        return None
    return elapsed / done * (total - done)


def _label(values: dict[str, Any]) -> str:
    from .plots import short_label

    return ", ".join(short_label(k, v) for k, v in values.items())


#: Dask settings of the local cluster that keep its periodic work off the points' CPU (a
#: cluster's own cost grows with its wall time, not with its points): no statistical profiler
#: (it samples the running task's stack every 10 ms), no work stealing (the chunks are handed
#: out as workers free up, IN_FLIGHT each), the event loops' health check every second
#: instead of every 20 ms, the workers' memory check every second instead of every 100 ms,
#: the system monitor (CPU, memory, disk and network counters of each process, read through
#: psutil for the dashboard) every 5 s instead of every 0.5 s, and no active memory manager
#: (it looks for replicas to drop every 2 s; a local study makes none).  The last two took an
#: idle 1-worker cluster from 13-15 ms to 9-10 ms of CPU a second (two runs each, interleaved)
QUIET_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.scheduler.work-stealing": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.scheduler.active-memory-manager.start": False,
}


def local_cluster(workers: int | None = None):
    """A Dask ``LocalCluster`` for a study on this machine, reachable from this machine only.

    ``workers`` processes (default: the cores) with one thread each.  The scheduler, the
    workers, their nannies and the scheduler's HTTP server (dashboard, ``/health``, metrics)
    bind to :data:`LOOPBACK` with ports chosen by the system; a local study never listens on
    another interface (Dask's default dashboard address ``:8787`` is every interface).

    Parameters
    ----------
    workers : int, optional
        Worker processes, >= 1; default ``os.cpu_count()``.

    Returns
    -------
    dask.distributed.LocalCluster
        Started; the caller closes it (``cluster.close()``).
    """
    from dask.distributed import LocalCluster

    n = workers or os.cpu_count() or 1
    # Ctrl-C reaches the whole process group; only this process is to handle it, by closing
    # the cluster (prsm_fmu.command: one line), not every worker with a traceback.  The worker
    # processes start with SIGINT ignored (a Python child keeps an ignored SIGINT through its
    # imports) and their preload ignores it for good; the price: a Ctrl-C while the cluster
    # starts (a few seconds) is not seen.
    on_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if on_main else None
    import dask

    from .dashboard import ROUTE_MODULE

    routes = list(dask.config.get("distributed.scheduler.http.routes", []))
    settings = dict(QUIET_CLUSTER)
    settings["distributed.nanny.pre-spawn-environ"] = _worker_environ()
    # the study's progress page on the dashboard's server (prsm_fmu.sweep.dashboard)
    settings["distributed.scheduler.http.routes"] = \
        routes + [ROUTE_MODULE] * (ROUTE_MODULE not in routes)
    try:
        with dask.config.set(settings):
            return LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                host=LOOPBACK, dashboard_address=f"{LOOPBACK}:0",
                                preload=["prsm_fmu.sweep.worker_setup"])
    finally:
        if on_main:
            signal.signal(signal.SIGINT, previous)


#: environment variable of glibc's malloc that Dask's nanny sets for its workers
#: (``distributed.nanny.pre-spawn-environ``) and a local study's workers go without
MALLOC_TRIM = "MALLOC_TRIM_THRESHOLD_"


def _worker_environ() -> dict[str, Any]:
    """Dask's ``distributed.nanny.pre-spawn-environ`` without :data:`MALLOC_TRIM`.

    Dask sets ``MALLOC_TRIM_THRESHOLD_=65536`` so that a worker hands freed memory back to the
    system at once; setting it also fixes glibc's mmap threshold at 128 kB.  A point's arrays
    are then taken from the system and given back at every point: ~130-195 page faults a
    model point in a worker against none in this process, and 5-13 % more CPU a point, model
    and FMU backends alike (the same chunk run alternately on two 1-worker clusters, with and
    without it, three runs; docs/sweeps.md).  A study's workers hold a few MB at a time: glibc's own
    defaults suit them.  (The nanny also writes its variables into this process's
    ``os.environ`` before it spawns; a value there is inherited by the workers as before.)
    """
    import dask

    env = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    env.pop(MALLOC_TRIM, None)
    return env


def _quiet_logs() -> None:
    """Run here and on each worker before an interrupted study closes its cluster: no shutdown
    logs (Dask's own, and tornado's: a callback that Dask's sync cancels mid-way can log a
    traceback through ``tornado.application``)."""
    for name in ("distributed", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


#: CPU time [s] a Dask task (a chunk of points) aims at: Dask's cost per task (this process
#: with its scheduler, the worker and its nanny: ~7 ms of CPU on a local cluster,
#: benchmarks/dask_task_cost.py) stays near 0.35 % of it (it was 1.4 % at 0.5 s).  CPU, not
#: wall time: on a loaded machine a point's wall time grows with the other jobs while Dask's
#: cost per task does not shrink.  The price of a longer chunk: the progress and the table
#: move a chunk at a time, and a Ctrl-C loses the chunks running (up to this much CPU a worker)
CHUNK_SECONDS = 2.0
#: chunks in flight per worker: while one runs the next waits on the worker, so that no worker
#: idles during a round trip to this process
IN_FLIGHT = 2


#: CPU time [s] below which a chunk is not cut towards the end of a study: the guided bound
#: shrinks chunks to single points, which for points of a few ms makes a tail of tasks that cost
#: Dask more than their points (~7 ms of CPU a task); at least this much keeps Dask's cost
#: under ~7 % of a tail chunk while the workers still finish within about this much of each other
MIN_CHUNK_SECONDS = 0.1


def chunk_size(remaining: int, workers: int, seconds_per_point: float | None) -> int:
    """Points of the next Dask task: about :data:`CHUNK_SECONDS` of CPU at
    ``seconds_per_point`` (the latest chunk's mean: a worker's first point, which loads the FMU
    or the engine, counts once only; None before the first: one point), at most
    ``remaining // (2 workers)`` (guided: the chunks shrink towards the end, so that the
    workers finish together) but not below :data:`MIN_CHUNK_SECONDS` of CPU (the points left
    if fewer), at least 1.

    Parameters
    ----------
    remaining : int
        Points not yet submitted.
    workers : int
        Workers of the cluster, >= 1.
    seconds_per_point : float or None
        Mean CPU time of a point of the latest chunk [s] (PointResult.cpu_time).
    """
    if seconds_per_point is None or not seconds_per_point > 0.0 \
            or not math.isfinite(seconds_per_point):
        return 1
    by_time = int(CHUNK_SECONDS / seconds_per_point)
    floor = min(remaining, int(MIN_CHUNK_SECONDS / seconds_per_point))
    return max(1, floor, min(by_time, remaining // (2 * max(1, workers))))


def _dask_results(tasks: list[PointTask], client, scheduler: str | None, workers: int | None,
                  ship_fmus: bool, series_dir: str,
                  bar: Progress) -> tuple[Callable, Callable, dict]:
    """(iterator over the chunks' results, a list each, as they complete, closer, counts:
    ``{"tasks": submitted}``) for the Dask executor.

    The points go out in chunks (:func:`chunk_size`), :data:`IN_FLIGHT` per worker, the next
    one submitted as soon as one comes back and before its results are handled; a chunk's
    results come back together and are saved at once.  Workers that share this file system
    (``ship_fmus`` false) save each point's series themselves."""
    from dask.distributed import Client, as_completed

    from .dashboard import page_served, publisher

    own_cluster = own_client = None
    if client is None:
        if scheduler:
            client = own_client = Client(scheduler)
        else:
            own_cluster = local_cluster(workers)
            client = own_client = Client(own_cluster)
    blobs = None
    if ship_fmus:
        files = {}
        for t in tasks:
            for ref in t.fmus.values():
                files[ref.sha256] = ref.path
        blobs = {}
        for sha, path in files.items():
            with open(path, "rb") as fh:
                blobs[sha] = client.scatter(fh.read(), broadcast=True)
    bar.publish = publisher(client)               # the dashboard's progress page
    bar.publish(bar.state())
    # asked over HTTP only when there is a stream to name it on (up to 2 s on a remote cluster
    # that does not answer)
    page = page_served(client) if bar.stream is not None else None
    if page:
        bar.stream.write(f"{chr(10) if bar.tty else ''}progress page: {page}\n")
    n_workers = max(1, len(client.scheduler_info().get("workers", {})) or (workers or 1))
    save_dir = None if ship_fmus else series_dir
    futures: dict[Any, list[PointTask]] = {}
    pending = as_completed()
    state: dict[str, Any] = {"next": 0, "seconds_per_point": None, "tasks": 0}

    def submit() -> None:
        k = state["next"]
        size = chunk_size(len(tasks) - k, n_workers, state["seconds_per_point"])
        chunk = tasks[k:k + size]
        state["next"] = k + len(chunk)
        # the dashboard's progress shows these tasks (prsm-points) done of those submitted
        fut = client.submit(run_chunk, pack_chunk(chunk), blobs, save_dir,
                            key=f"prsm-points-{chunk[0].index}-{len(chunk)}-{chunk[0].id}",
                            pure=False, retries=0)
        futures[fut] = chunk
        pending.add(fut)
        state["tasks"] += 1

    def top_up() -> None:
        while state["next"] < len(tasks) and len(futures) < IN_FLIGHT * n_workers:
            submit()

    def results():
        top_up()
        for fut in pending:
            chunk = futures.pop(fut)
            try:
                done = unpack_chunk(fut.result())
            except Exception as exc:  # noqa: BLE001 - the worker died or the task was lost
                done = [PointResult(t.index, t.id, dict(t.values), "error",
                                    f"{type(exc).__name__}: {exc}") for t in chunk]
            fut.release()
            # the points that ran (a refused point ends in microseconds and says nothing)
            timed = [res.cpu_time for res in done if res.cpu_time > 0.0 and res.status == "ok"]
            if timed:
                state["seconds_per_point"] = sum(timed) / len(timed)
            top_up()                       # the workers go on while these are handled
            yield done

    def close(quiet: bool = False):
        if quiet:
            # the points still running are cancelled: their workers and nannies would log
            # it as warnings and errors on stderr
            _quiet_logs()
            if own_cluster is not None:
                try:
                    client.run(_quiet_logs)
                except Exception:  # noqa: BLE001 - a worker already gone: nothing to quieten
                    pass
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()

    return results, close, state


#: file in a study's output folder naming the study it belongs to
STUDY_MARKER = "study.txt"


def claim_out_dir(out_dir: str, study: Study) -> None:
    """Make ``out_dir`` the output folder of ``study``, refusing one that holds another study's.

    The folder's :data:`STUDY_MARKER` names the study that wrote it; a folder without one
    (new, or from before the marker) is claimed by writing it.

    Raises
    ------
    ValueError
        If the folder belongs to a study of another name (nothing is written then).
    """
    marker = os.path.join(out_dir, STUDY_MARKER)
    try:
        with open(marker, encoding="utf-8") as fh:
            owner = fh.readline().strip()
    except FileNotFoundError:
        owner = ""
    if owner and owner != study.name:
        raise ValueError(f"output folder {out_dir} holds the results of study {owner!r}, not "
                         f"{study.name!r}: must be a folder of its own (the command line "
                         "uses OUT/<study name>/)")
    if not owner:
        os.makedirs(out_dir, exist_ok=True)
        with open(marker, "w", encoding="utf-8") as fh:
            fh.write(study.name + "\n")


def run_study(study: Study, out_dir: str | None = None, *, backend: str | None = None,
              executor: str = "dask", scheduler: str | None = None, workers: int | None = None,
              client=None, fmu_dir: str | None = None, resume: bool = True,
              figures: bool = True, progress: TextIO | None = sys.stderr,
              ship_fmus: bool | None = None, fmu: str | None = None) -> SweepResult:
    """Run every point of ``study`` that is not done yet; write the table, figures and report.

    Parameters
    ----------
    study : Study
        From :func:`~prsm_fmu.sweep.study.load_study`.
    out_dir : str, optional
        Output directory; default ``out/sweeps/<study name>``.  A folder holding another
        study's results is refused (:func:`claim_out_dir`).
    backend : {"fmu", "model"}, optional
        Overrides the study's backend.
    executor : {"dask", "loop"}
        See the module docstring.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``).
    workers : int, optional
        Worker processes of the local cluster; default the number of cores.
    client : dask.distributed.Client, optional
        Use this client (and its cluster) instead of making one.
    fmu_dir : str, optional
        Directory holding the FMUs (``PRSM<n>-native.fmu`` or ``PRSM<n>.fmu``, by ``fmu``) to
        use instead of building them.
    resume : bool
        Skip points already in the table with status ok (default); False runs all.
    figures : bool
        Draw the figures.
    progress : text stream or None
        Where the progress bar goes (None: nowhere).
    ship_fmus : bool, optional
        Send the FMU files to the workers (``Client.scatter``) instead of passing their paths;
        default: only with ``scheduler`` (a remote cluster).  Set it for a ``client`` of a
        cluster whose workers do not share this file system.
    fmu : {"native", "python"}, optional
        The FMU the FMU backend runs on (:data:`FMU_KINDS`): default the native FMU where Zig's
        C compiler can build it, else the Python FMU (:func:`default_fmu_kind`; the reason is
        written to ``progress``).  Not part of a point's identity: both give the same results.

    Returns
    -------
    SweepResult
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor = {executor!r} is not allowed: must be one of "
                         f"{', '.join(EXECUTORS)}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise ValueError(f"workers = {workers!r} is out of range: must be an integer >= 1")
    backend = backend or study.backend
    # the extras, before anything is written or built
    if executor == "dask" and client is None:
        require("dask.distributed",
                purpose="running the points on Dask (or in a plain loop: --no-dask)")
    fallback = None
    if backend == "fmu":
        if fmu is None:
            fmu, fallback = default_fmu_kind()
        check_fmu_kind(fmu)                       # before anything is done
        require("fmpy", *(("pythonfmu",) if fmu == "python" else ()),
                purpose="the FMU backend of a sweep (or --backend model)")
        if progress is not None and fallback is not None:
            progress.write(f"note: {fallback}\n")
    t0 = time.perf_counter()
    out_dir = out_dir or os.path.join("out", "sweeps", study.name)
    claim_out_dir(out_dir, study)
    series_dir = os.path.join(out_dir, "series")
    os.makedirs(series_dir, exist_ok=True)
    table_path = os.path.join(out_dir, "results.csv")
    points = study.points()
    ids = [study.point_id(p.values, backend) for p in points]
    header = columns(study.swept, metric_columns(study))

    kept: dict[str, list[str]] = {}
    if resume:
        old_header, old_rows = read_table(table_path)
        current = set(ids)
        if old_header == header:
            for r in old_rows:
                if r.get("id") in current and r.get("status") == "ok" and os.path.exists(
                        os.path.join(series_dir, f"{r['id']}.npz")):
                    kept[r["id"]] = [r[c] for c in header]
    pending = [(p, i) for p, i in zip(points, ids) if i not in kept]
    index_of = {i: p.index for p, i in zip(points, ids)}
    # the table restarts with what is kept (in point order); new rows are appended as they come
    rows_by_id: dict[str, list[str]] = {}
    for pid in sorted(kept, key=index_of.__getitem__):
        row = kept[pid]
        row[0] = str(index_of[pid])
        rows_by_id[pid] = row
    write_table(table_path, header, rows_by_id.values())

    fmus: dict[int, FmuFile] = {}
    if backend == "fmu" and pending:
        paths = ensure_fmus(sorted(study.stage_counts()), os.path.join(out_dir, "fmu"), fmu_dir,
                            kind=fmu)
        fmus = {n: FmuFile(_sha256(p), os.path.abspath(p)) for n, p in paths.items()}
    metric_names = tuple(c for c in header if c not in
                         ("point", "id", "status", "error") and c not in study.swept)
    tasks = [PointTask(p.index, pid, dict(p.values), study.point_inputs(p.values, backend),
                       metric_names, fmus) for p, pid in pending]

    bar = Progress(len(tasks), len(kept), progress)
    counts = {"tasks": 0}
    done: list[PointResult] = []
    timing_rows: list[list[str]] = []

    def handle(chunk: Sequence[PointResult]) -> None:
        """Record the points of a chunk: their series (unless saved where they ran), their
        rows appended to the table in one write, the progress drawn once."""
        rows = []
        for res in chunk:
            if res.status == "ok" and res.series is not None:      # not saved where it ran
                save_series(series_dir, res.id, res.series)
            row = row_of(res, header)
            rows_by_id[res.id] = row
            rows.append(row)
            timing_rows.append([str(res.index), res.id, res.status, res.worker,
                                f"{res.wall_time:.6f}", f"{res.cpu_time:.6f}"])
            res.series = None          # on disk now; keep the memory small
            done.append(res)
        append_rows(table_path, header, rows)
        ok = sum(res.status == "ok" for res in chunk)
        bar.update(ok, len(chunk) - ok)

    if tasks:
        if executor == "loop":
            # Ctrl-C between two points, not inside an FMU's Python (there it would fail the
            # point and the next one would run)
            with deferred_interrupt() as interrupted:
                for t in tasks:
                    interrupted()
                    handle([run_point(t, None, series_dir)])
        else:
            ship = (scheduler is not None and client is None) if ship_fmus is None \
                else bool(ship_fmus)
            results, close, counts = _dask_results(tasks, client, scheduler, workers, ship,
                                                   series_dir, bar)
            # a Ctrl-C inside Dask's sync() makes it cancel a callback on the client's event
            # loop thread, which can log a traceback through tornado.application before this
            # thread reaches close(quiet=True): that logger is quiet while the points run (a
            # point's own failure is reported through its result)
            loop_log = logging.getLogger("tornado.application")
            level = loop_log.level
            loop_log.setLevel(logging.CRITICAL)
            try:
                for chunk in results():
                    handle(chunk)
            except BaseException:           # Ctrl-C or an error: close without the workers'
                close(quiet=True)           # shutdown warnings (one line, prsm_fmu.command)
                raise
            loop_log.setLevel(level)
            close()
    bar.close()

    ordered = [rows_by_id[i] for i in ids if i in rows_by_id]
    point_of = dict(zip(ids, points))
    write_table(table_path, header, ordered)
    write_table(os.path.join(out_dir, "timing.csv"),
                ["point", "id", "status", "worker", "wall_time [s]", "cpu_time [s]"],
                sorted(timing_rows, key=lambda r: int(r[0])))
    rows = numeric_rows(dict(zip(header, r)) for r in ordered)
    for r in rows:
        r.update(point_of[r["id"]].values)     # swept values with their types (str, int)
    result = SweepResult(study, out_dir, table_path, header, rows, done, len(kept),
                         backend=backend, fmu=fmu if backend == "fmu" else "",
                         dask_tasks=counts["tasks"])
    result.trends = evaluate(study, rows)
    if figures:
        result.figures = draw_figures(study, result)
    result.wall_time = time.perf_counter() - t0
    write_report(result)
    return result


def draw_figures(study: Study, result: SweepResult) -> list[str]:
    """``time.png`` (the time panels of up to :data:`MAX_TIME_RUNS` points) and ``steady.png``."""
    from .plots import DEFAULT_PANELS, plot_steady, plot_time_panels

    out = []
    ok = [r for r in result.rows if r.get("status") == "ok"]
    if not ok:
        return out
    swept = list(study.swept)
    pick = ok if len(ok) <= MAX_TIME_RUNS else \
        [ok[int(i)] for i in np.linspace(0, len(ok) - 1, MAX_TIME_RUNS)]
    runs = []
    for r in pick:
        s = load_series(result.out_dir, r["id"])
        if s is not None:
            runs.append((_label({k: r[k] for k in swept}), s))
    panels = tuple(study.plots.get("time_panels", DEFAULT_PANELS))
    if runs:
        path = os.path.join(result.out_dir, "time.png")
        plot_time_panels(runs, path, panels, title=study.title)
        out.append(path)
    if swept:
        x = study.plots.get("x", swept[0])
        axis = next(ax for ax in study.axes if x in ax.names)
        group_by = [n for ax in study.axes if ax is not axis for n in ax.names]
        metrics = list(study.plots.get("steady", [])) or _default_steady(result.header)
        path = os.path.join(result.out_dir, "steady.png")
        x_values = None
        if not all(isinstance(r.get(x), float) for r in ok):
            x_values = list(dict.fromkeys(r.get(x) for r in result.rows))
        plot_steady(result.rows, x, metrics, group_by, path, title=study.title,
                    x_values=x_values)
        out.append(path)
    return out


def _default_steady(header: Sequence[str]) -> list[str]:
    want = ["efficiency@end", "stage[1].contact_force@end", "stage[2].contact_force@end",
            "stage[2].spline_friction@end"]
    return [m for m in want if m in header][:4]


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.6g}"
    return str(v)


def write_report(result: SweepResult) -> str:
    """``OUT/report.md``: the study, its claims and verdicts, the failed points, the figures."""
    st = result.study
    sc = ", ".join(f"{k} = {v}" for k, v in st.scenario.items() if v not in (None, (), []))
    parts = [f"# {st.title}\n",
             f"Study `{st.path or st.name}` (preset `{st.preset}`, backend "
             f"`{result.backend}`{f', the {result.fmu} FMU' if result.fmu else ''}); source: "
             f"{st.source or '—'}.\n",
             f"Scenario: {sc}.\n"]
    if st.parameters:
        parts.append("Fixed parameters: " + ", ".join(f"{k} = {v}" for k, v in
                                                      st.parameters.items()) + ".\n")
    if st.notes:
        parts.append(st.notes.strip() + "\n")
    n_ok = sum(1 for r in result.rows if r.get("status") == "ok")
    parts.append(f"Points: {len(result.rows)} ({n_ok} ok, {len(result.failed)} failed; "
                 f"{result.skipped} taken from an earlier run). Table: `results.csv`.\n")
    key_cols = [c for c in ("efficiency@end", "stage[1].carrier_speed_ratio@end",
                            "stage[2].carrier_speed_ratio@end", "stage[1].contact_force@end",
                            "stage[2].contact_force@end", "stage[2].spline_friction@end",
                            "friction_torque@max", "efficiency@min", "efficiency@overall")
                if c in result.header]
    parts.append(markdown_table(list(st.swept) + ["status"] + key_cols,
                           [[_cell(r.get(c)) for c in list(st.swept) + ["status"] + key_cols]
                            for r in result.rows]) + "\n")
    if result.trends:
        parts.append("## The paper's claims, checked on the table\n")
        parts.append(markdown_table(["claim", "paper", "metric", "along", "table", "verdict"], [
            [t.trend.statement, t.trend.paper or "—", f"`{t.trend.metric}`", t.trend.vs,
             t.observed, t.verdict] for t in result.trends]) + "\n")
    if result.failed:
        parts.append("## Failed points\n")
        parts.append(markdown_table(["point", "parameters", "error"], [
            [int(r["point"]), _label({k: r[k] for k in st.swept}), r.get("error", "")]
            for r in result.failed]) + "\n")
    for f in result.figures:
        parts.append(f"![{os.path.basename(f)}]({os.path.basename(f)})\n")
    path = os.path.join(result.out_dir, "report.md")
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write("\n".join(parts))
    return path
