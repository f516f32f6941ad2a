"""Scaling of a parameter study on Dask: speed-up of 2 workers over 1, and the cost of the
Dask path over a plain loop, per point and per study; and the one-engine goal.

Study: Li et al. (2021) §3.1's start-up (PRSM2, dynamic level, 100 rad/s step, 5000 N, 1 ms at
1 µs communication steps = 1000 steps a point), over a grid of µ_SR × µ_SS, on both backends:
the FMU (the speed prescribed by the FMU master on the native FMU, the studies' default;
default 120 × 4 = 480 points, ~10 ms each) and the model (``simulate``, the whole run in one
call into the engine; default 120 × 4 = 480 points, a few ms each), so that Dask's cost per
task and per point shows.  Each backend's study is run at two sizes, N and about N/2 points
(spread over the same µ_SR range), with :func:`prsm_fmu.sweep.run_study` on fresh output
directories, each timed from the call to its return (table, series and report written,
figures off):

* ``loop``: the points one after the other in this process (``executor="loop"``), the FMU
  loaded once and reset between points — the reference;
* ``dask 1``: a ``LocalCluster`` of 1 worker process (1 thread);
* ``dask 2``: a ``LocalCluster`` of 2 worker processes (1 thread each).

The machine's speed drifts: the same single-threaded work (a Python loop of ~20 ms) took from
16.5 to 25.5 ms of its thread's CPU from one second to the next on this idle machine (other machines' jobs on the same host), which
a "best of" over runs minutes apart does not cancel.  So every comparison is made in pairs of
runs next to each other in time, and the medians of the pairs count:

* A, the 1-worker cluster started and warmed (one untimed run of 8 points: imports, the
  engine library, the FMU instance; the loop is warmed the same way), then ``--repeat`` times: loop
  N, dask 1 N, loop N/2, dask 1 N/2 (the idle cluster beside the loop's runs, on the other
  core);
* B, ``--repeat`` times: dask 2 N, dask 1 N, each on a cluster started and warmed (8 points)
  for that run and closed after it: one cluster at a time (an idle cluster beside a timed one
  slowed the 1-worker runs by up to a third in one run of this benchmark: its scheduler shares
  this process).

Starting a cluster (≈ 1 s) and a worker's first point are paid once per study, not timed here.
The studies write into ``/dev/shm`` where it exists (memory): the disk's write-back of ~100 MB
of series a run ran beside the timed runs.
Printed, measured in this run on this machine (with its load average before and after: the
machine is shared):

* speed-up = t(dask 1, N) / t(dask 2, N) of each pair of B, their median (goal ≥ 1.85, floor
  ≥ 1.7 on 2 cores); beside it the same per second of the points' own CPU (each run's wall
  time divided by the sum of its points' ``PointResult.cpu_time``: the drift slows a run's
  points and its wall time alike, so this ratio keeps what parallelism gains and loses and
  drops the drift), and the points' own CPU on 2 workers against 1 (above 1: two workers slow
  each other, which that second figure would hide);
* Dask's cost over the loop, each pair of A giving dask 1 − loop, split by the two sizes: per
  point = the slope, [median(N) − median(N/2)] / (N − N/2), as a fraction of a point's own CPU
  in the loop, and per study = the rest, median(N) − N × the per-point part (the first chunks
  of one point, the last chunk's round trip, publishing the progress); in wall time and CPU
  time (this process, where a local cluster's scheduler and its workers' nannies run, and the
  worker processes: what Dask costs whatever else runs on the machine) as measured, and outside the points: the wall time
  less the sum of the points' own wall time (``PointResult.wall_time``, from the start of a
  point to its end where it ran), the CPU time less the sum of their own CPU: what Dask adds
  around the points, which the drift of the points themselves (a run's ±20 %, ten times the
  2 % to resolve) does not reach.
  The goal (≤ 2 % of a point) is judged on the wall time outside the points;
* a point's own CPU in the worker against in this process, pair by pair (1 when a worker runs
  a point as fast as this process);
* the Dask tasks the points went in (chunks, prsm_fmu.sweep.execute.chunk_size).

Dask's cost per task and per point of a chunk alone (no points run) is
benchmarks/dask_task_cost.py.

The one-engine goal (printed first; alone with ``--goal-only``): a point of the same study on
the engine's doors against the Python path in the same run: each of the first
``GOAL_POINTS`` points in this process (``executor="loop"``), the best of ``--repeat`` runs,
on the ``fmu`` backend's default door (the native FMU, PRSM2-native.fmu), on the Python FMU
(PRSM2.fmu, which runs the engine behind pythonfmu) and on the Python path (the same Python FMU
built with ``--engine python``), and on the ``model`` backend (:func:`prsm_fmu.simulate` with
``engine="native"`` and ``engine="python"``).  Goal: the default door ≥ 50× faster than the
Python path (floor 20×); printed in wall time and in this process's CPU time (the least of the
runs; what the other jobs of a shared machine do not change).

Run: ``python benchmarks/sweep_scaling.py [--points 480] [--model-points 480] [--repeat 3]
[--goal-only]`` (about six minutes).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import textwrap
import time


def _study(path: str, n_points: int, backend: str = "fmu") -> None:
    """The start-up study over about ``n_points`` points (× 4 values of µ_SS): µ_SR from 0.05
    in steps of 0.03 up to 24 points, else spread over 0.05 … 0.5 (inside the geometry's
    self-locking bound 0.7025)."""
    n_ss = 4
    n_sr = max(1, n_points // n_ss)
    if n_sr <= 6:
        mu_sr = [round(0.05 + 0.03 * i, 4) for i in range(n_sr)]
    else:
        mu_sr = [round(0.05 + 0.45 * i / (n_sr - 1), 6) for i in range(n_sr)]
    mu_ss = [round(0.1 + 0.05 * j, 4) for j in range(n_ss)]
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(textwrap.dedent(f"""
            [study]
            name = "scaling"
            preset = "li2021_two_stage"
            backend = "{backend}"
            [scenario]
            fidelity = "dynamic"
            screw_speed = 100.0
            load_force = 5000.0
            t_end = 1e-3
            output_interval = 1e-6
            [grid]
            mu_screw_roller = {mu_sr}
            mu_spline = {mu_ss}
            """))


#: points of the study timed for the one-engine goal
GOAL_POINTS = 4


def engine_goal(fmu_dir: str, tmp: str, repeat: int) -> None:
    """Print the time per point of the engine's doors against the Python path (docstring)."""
    import subprocess
    import sys

    from prsm_fmu.sweep import load_study, run_study

    ref_dir = os.path.join(tmp, "fmu_python")
    subprocess.run([sys.executable, "-m", "fmu_build", "PRSM2", "--engine", "python", "--dest",
                    ref_dir], check=True, capture_output=True)
    # (backend, door) -> run_study's arguments; the FMU backend's default door first
    doors = {("fmu", "native FMU (default)"): {"fmu_dir": fmu_dir, "fmu": "native"},
             ("fmu", "Python FMU, engine"): {"fmu_dir": fmu_dir, "fmu": "python"},
             ("fmu", "Python FMU, Python"): {"fmu_dir": ref_dir, "fmu": "python"},
             ("model", "engine"): {"engine": "native"},
             ("model", "Python"): {"engine": "python"}}
    per_point: dict[tuple[str, str], float] = {}
    cpu_point: dict[tuple[str, str], float] = {}     # CPU time of this process per point
    sub = os.path.join(tmp, "goal.toml")
    _study(sub, GOAL_POINTS)                    # the first points of the same grid
    for (backend, door), kw in doors.items():
        study = load_study(sub, backend=backend)
        kw = dict(kw)
        engine = kw.pop("engine", None)
        best = best_cpu = float("inf")
        for r in range(repeat):
            out = os.path.join(tmp, f"goal_{backend}_{len(per_point)}_{r}")
            if engine is not None:
                os.environ["PRSM_FMU_ENGINE"] = engine
            t0, c0 = time.perf_counter(), time.process_time()
            res = run_study(study, out, progress=None, figures=False, resume=False,
                            executor="loop", **kw)
            dt = (time.perf_counter() - t0) / len(res.rows)
            dc = (time.process_time() - c0) / len(res.rows)
            os.environ.pop("PRSM_FMU_ENGINE", None)
            assert all(row["status"] == "ok" for row in res.rows), res.failed
            best = min(best, dt)
            best_cpu = min(best_cpu, dc)
        per_point[backend, door] = best
        cpu_point[backend, door] = best_cpu
    ref = ("fmu", "Python FMU, Python")
    python_path = per_point[ref]
    print(f"one engine: s per point of the start-up study (first {GOAL_POINTS} points, best of "
          f"{repeat}, in this process; the Python path: the Python FMU without its engine):")
    for (backend, door), t in per_point.items():
        print(f"  {backend:5s} backend, {door:21s}: {t:8.4f} s   "
              f"({python_path / t:6.1f}x faster than the Python path)")
    default = ("fmu", "native FMU (default)")
    ratio = python_path / per_point[default]
    print(f"  the studies' default door (FMU backend, native FMU) / Python path = {ratio:.1f}x "
          f"(goal >= 50x, floor >= 20x: {_verdict(ratio, 50.0, 20.0)})")
    same = per_point["model", "Python"] / per_point["model", "engine"]
    py_fmu = python_path / per_point["fmu", "Python FMU, engine"]
    print(f"  Python FMU: engine / Python = {py_fmu:.1f}x; model backend: engine / its own "
          f"Python path (engine='python') = {same:.1f}x")
    # CPU time of this process (the other jobs of a shared machine do not count)
    fmu_cpu = cpu_point[ref] / cpu_point[default]
    print(f"  in CPU time per point: default door {cpu_point[default]:.4f} s / Python path "
          f"{cpu_point[ref]:.4f} s = {fmu_cpu:.1f}x ({_verdict(fmu_cpu, 50.0, 20.0)}); Python "
          f"FMU engine {cpu_point[ref] / cpu_point['fmu', 'Python FMU, engine']:.1f}x; model "
          f"backend {cpu_point['model', 'Python'] / cpu_point['model', 'engine']:.1f}x")
    print()


def _verdict(value: float, goal: float, floor: float) -> str:
    return "goal met" if value >= goal else "floor met" if value >= floor else "NOT met"


def _cluster_cpu(client) -> float:
    """CPU time [s] of this process (with a local cluster's scheduler and its workers' nannies,
    which run here) and, given a client, of its worker processes (their own clocks)."""
    total = time.process_time()
    if client is not None:
        total += sum(client.run(time.process_time).values())
    return total


def _median(values) -> float:
    import statistics

    return statistics.median(values)


def _close_quietly(client, cluster) -> None:
    """Close a cluster without its screen of INFO lines (levels restored afterwards)."""
    import logging

    from prsm_fmu.sweep.execute import _quiet_logs

    levels = {name: logging.getLogger(name).level for name in ("distributed", "tornado")}
    _quiet_logs()
    try:
        client.close()
        cluster.close()
    finally:
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)


def scaling(studies: dict[int, object], warm_study, fmu_dir: str, tmp: str, repeat: int,
            label: str) -> None:
    """Time the loop and 1 worker on two point counts, paired, and 1 against 2 workers on the
    larger, paired; print the speed-up, Dask's cost per point (slope) and per study
    (docstring)."""
    from dask.distributed import Client

    from prsm_fmu.sweep import run_study
    from prsm_fmu.sweep.execute import local_cluster

    small, big = sorted(studies)
    # per configuration and size, the runs in order: (wall, CPU of the processes, CPU of the
    # points themselves, their wall time)
    runs: dict[tuple[str, int], list[tuple[float, float, float]]] = {}
    tasks: dict[str, int] = {}

    def timed(name: str, n: int, r: int, **kw) -> None:
        out = os.path.join(tmp, f"{label}_{name.replace(' ', '_')}_{n}_{r}")
        client = kw.get("client")
        c0 = _cluster_cpu(client)
        t0 = time.perf_counter()
        res = run_study(studies[n], out, fmu_dir=fmu_dir, progress=None, figures=False,
                        resume=False, **kw)
        dt = time.perf_counter() - t0
        dc = _cluster_cpu(client) - c0
        assert all(row["status"] == "ok" for row in res.rows), res.failed
        assert len(res.rows) == n
        shutil.rmtree(out)                   # ~0.2 MB of series a point: not kept
        inside = sum(p.cpu_time for p in res.results)
        inside_wall = sum(p.wall_time for p in res.results)
        runs.setdefault((name, n), []).append((dt, dc, inside, inside_wall))
        tasks[name] = res.dask_tasks
        print(f"  {name:7s} {n:4d} points, run {r + 1}: {dt:7.3f} s  ({dt / n * 1e3:6.2f} ms "
              f"per point; CPU {dc / n * 1e3:6.2f} ms per point, of which the points "
              f"{inside / n * 1e3:6.2f} ms)")

    def warm(client=None, **kw) -> None:
        """One untimed run of a few points: imports, engine library, FMU instance."""
        out = os.path.join(tmp, f"{label}_warm")
        run_study(warm_study, out, fmu_dir=fmu_dir, progress=None, figures=False,
                  resume=False, client=client, **kw)
        shutil.rmtree(out)

    def cluster(workers: int):
        """A started, warmed local cluster of ``workers`` (the sweep's own: loopback only)."""
        made = local_cluster(workers)
        client = Client(made)
        warm(client)
        return client, made

    print(f"{label}: {small} and {big} points")
    warm(executor="loop")
    c1, one = cluster(1)
    try:
        # A: the loop against 1 worker, paired in time (the idle cluster beside the loop)
        for r in range(repeat):
            for n in (big, small):
                timed("loop", n, r, executor="loop")
                timed("dask 1", n, r, client=c1)
    finally:
        _close_quietly(c1, one)
    # B: 2 workers against 1, paired in time, one cluster at a time (an idle cluster beside a
    # timed one slowed the 1-worker runs by up to a third here: its scheduler shares this
    # process), each started and warmed before its run
    for r in range(repeat):
        for workers, run in ((2, r), (1, repeat + r)):
            client, made = cluster(workers)
            try:
                timed(f"dask {workers}", big, run, client=client)
            finally:
                _close_quietly(client, made)

    def col(name: str, n: int, k: int, first: int = 0, count: int | None = None) -> list[float]:
        v = [run[k] for run in runs[name, n]]
        return v[first:first + (count if count is not None else len(v))]

    # speed-up: each 2-worker run against the 1-worker run next to it (B)
    t2, c2 = col("dask 2", big, 0), col("dask 2", big, 2)
    t1, c1 = col("dask 1", big, 0, first=repeat), col("dask 1", big, 2, first=repeat)
    ratios = [a / b for a, b in zip(t1, t2)]
    # the same, each run's wall time per second of its points' own CPU: the machine's drift
    # slows a run's points and its wall time alike
    steady = [(a / ca) / (b / cb) for a, ca, b, cb in zip(t1, c1, t2, c2)]
    speedup = _median(ratios)
    print(f"  {big} points, 1 worker against 2, {repeat} pairs: speed-up "
          f"{', '.join(f'{x:.2f}x' for x in ratios)}; median {speedup:.2f}x   (goal >= 1.85, "
          f"floor >= 1.7: {_verdict(speedup, 1.85, 1.7)}); Dask tasks: {tasks['dask 1']} "
          f"(1 worker), {tasks['dask 2']} (2 workers)")
    print(f"    per second of the points' own CPU (drift taken out): "
          f"{', '.join(f'{x:.2f}x' for x in steady)}; median {_median(steady):.2f}x; the points' "
          f"own CPU on 2 workers / on 1: "
          f"{', '.join(f'{b / a:.3f}' for a, b in zip(c1, c2))} (above 1: the two workers slow "
          f"each other)")
    dn = big - small

    def pairs(k: int, n: int) -> list[float]:
        """Dask 1 worker − loop, per pair of A, of run field ``k`` (0 wall, 1 CPU) or, for
        ``k`` = 3 and 4, of the wall time outside the points (less the points' own wall time)
        and the CPU outside them (less their own CPU)."""
        def get(name):
            field, own = {3: (0, 3), 4: (1, 2)}.get(k, (k, None))
            v = col(name, n, field, count=repeat)
            if own is not None:
                v = [x - p for x, p in zip(v, col(name, n, own, count=repeat))]
            return v
        return [d - lp for d, lp in zip(get("dask 1"), get("loop"))]

    loop_point = _median(col("loop", big, 2, count=repeat)) / big   # a point's own CPU
    for what, k in (("wall time", 0), ("CPU time", 1), ("wall time outside the points", 3),
                    ("CPU outside the points", 4)):
        per_point = (_median(pairs(k, big)) - _median(pairs(k, small))) / dn
        fixed = _median(pairs(k, big)) - per_point * big
        share = per_point / loop_point * 100
        verdict = "" if k != 3 else \
            f"   (goal <= 2 %: {'met' if share <= 2.0 else 'NOT met'})"
        print(f"  Dask 1 worker over the loop, {what}: {per_point * 1e3:+.3f} ms per point = "
              f"{share:+.2f} % of a point's {loop_point * 1e3:.2f} ms{verdict}, and "
              f"{fixed:+.3f} s per study (medians of {repeat} pairs)")
    inside = [d / lp for d, lp in zip(col("dask 1", big, 2, count=repeat),
                                       col("loop", big, 2, count=repeat))]
    print(f"  a point's own CPU in the worker / in this process (pairs of {big} points): "
          f"{', '.join(f'{x:.3f}' for x in inside)}")
    print()


def _load() -> str:
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=480, help="FMU backend: about this many "
                    "points (× 4)")
    ap.add_argument("--model-points", type=int, default=480, help="model backend: about this "
                    "many points (× 4)")
    ap.add_argument("--repeat", type=int, default=5, help="pairs per comparison (their medians "
                    "count; the one-engine goal: runs, the best counts)")
    ap.add_argument("--goal-only", action="store_true", help="only the one-engine goal")
    args = ap.parse_args()

    from prsm_fmu.sweep import ensure_fmus, load_study

    # the studies' outputs (~0.2 MB of series a point, ~100 MB a run) in memory where the
    # system has a memory file system: the disk's write-back and discards of them ran beside
    # the timed runs
    shm = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="prsm_sweep_scaling_", dir=shm) as tmp:
        fmu_dir = os.path.join(tmp, "fmu")
        ensure_fmus([2], fmu_dir)
        ensure_fmus([2], fmu_dir, kind="native")
        print(f"start-up study of Li et al. (2021) (dynamic, 1 ms at 1 µs steps), "
              f"{os.cpu_count()} cores, {_load()}")
        if os.getloadavg()[0] > 0.5:
            print("  other jobs share the cores (load average above 0.5 before the run): the "
                  "wall-time figures and the goals are for a quiet machine; the CPU-time "
                  "figures vary by ±15 % or more at a load above the cores")
        engine_goal(fmu_dir, tmp, args.repeat)
        if not args.goal_only:
            for backend, points in (("fmu", args.points), ("model", args.model_points)):
                studies = {}
                for n in (points // 2, points):
                    path = os.path.join(tmp, f"scaling_{backend}_{n}.toml")
                    _study(path, n, backend)
                    study = load_study(path)
                    studies[len(study.points())] = study
                path = os.path.join(tmp, f"scaling_{backend}_warm.toml")
                _study(path, 8, backend)
                scaling(studies, load_study(path), fmu_dir, tmp, args.repeat,
                        f"{backend} backend")
    print(_load())


if __name__ == "__main__":
    main()
