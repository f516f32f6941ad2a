"""Scaling of a parameter study on Dask: speed-up of 2 workers over 1, and the cost of the
Dask path over a plain loop, per point and per study; and the one-engine goal.

Study: Li et al. (2021) §3.1's start-up (PRSM2, dynamic level, 100 rad/s step, 5000 N, 1 ms at
1 µs communication steps = 1000 steps a point), over a grid of µ_SR × µ_SS, on both backends:
the FMU (the speed prescribed by the FMU master on the native FMU, the studies' default;
default 60 × 4 = 240 points, ~10 ms each) and the model (``simulate``, the whole run in one
call into the engine; default 120 × 4 = 480 points, a few ms each), so that Dask's cost per
task and per point shows.  Each backend's study is run at two sizes, N and about N/2 points
(spread over the same µ_SR range), with
:func:`prsm_fmu.sweep.run_study` on fresh output directories, each timed from the call to its
return (table, series and report written, figures off):

* ``loop``: the points one after the other in this process (``executor="loop"``), the FMU
  loaded once and reset between points — the reference; no cluster exists meanwhile;
* ``dask 1``: a ``LocalCluster`` of 1 worker process (1 thread), both sizes;
* ``dask 2``: a ``LocalCluster`` of 2 worker processes (1 thread each), N points.

Each cluster is started (:func:`prsm_fmu.sweep.execute.local_cluster`) and warmed by one
untimed run of the N/2 points (imports, the engine library, the FMU instance) before its clock
starts, and closed (quietly) before the next is started, so that no idle cluster runs beside a
timed one; the loop is warmed the same way.  Starting a cluster (≈ 1 s) and a worker's first
point are paid once per study, not timed here.  Each configuration is run ``--repeat`` times,
interleaved, and the fastest run of each counts.  Printed, measured in this run on this
machine (with its load average before and after: the machine is shared):

* speed-up = t(dask 1, N) / t(dask 2, N)        (goal ≥ 1.85, floor ≥ 1.7 on 2 cores);
* Dask's cost over the loop split by the two sizes, in wall time and in CPU time (this
  process with its scheduler thread, and the worker processes: what Dask costs whatever else
  runs on the machine): per point = the slope, [(t(dask 1, N) − t(dask 1, N/2)) −
  (t(loop, N) − t(loop, N/2))] / (N − N/2), as a fraction of the loop's slope (goal ≤ 2 %,
  judged on this per-point part); per study = the rest, t(dask 1, N) − t(loop, N) − N × the
  per-point part (the chunks of one point at the start and at the end, the last chunk's
  round trip, publishing the progress; negative values are the noise of the two fits);
* the CPU of the points themselves (the sum of their ``PointResult.cpu_time``, measured
  where they ran) against the rest, loop and 1 worker: whether a point costs more in a worker
  or Dask costs around it;
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

Run: ``python benchmarks/sweep_scaling.py [--points 240] [--model-points 480] [--repeat 2]
[--goal-only]`` (a few minutes).
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


def scaling(studies: dict[int, object], fmu_dir: str, tmp: str, repeat: int,
            label: str) -> None:
    """Time the loop and 1 worker on two point counts and 2 workers on the larger; print the
    speed-up, the overhead per point (slope) and the fixed overhead per study (docstring)."""
    from dask.distributed import Client

    from prsm_fmu.sweep import run_study
    from prsm_fmu.sweep.execute import local_cluster

    small, big = sorted(studies)
    wall: dict[tuple[str, int], float] = {}
    cpu: dict[tuple[str, int], float] = {}
    inside: dict[tuple[str, int], float] = {}     # CPU of the points themselves (PointResult)
    tasks: dict[str, int] = {}

    def workers_cpu(client) -> float:
        return sum(client.run(time.process_time).values()) if client is not None else 0.0

    def timed(name: str, n: int, r: int, **kw) -> None:
        out = os.path.join(tmp, f"{label}_{name.replace(' ', '_')}_{n}_{r}")
        client = kw.get("client")
        c0 = time.process_time() + workers_cpu(client)
        t0 = time.perf_counter()
        res = run_study(studies[n], out, fmu_dir=fmu_dir, progress=None, figures=False,
                        resume=False, **kw)
        dt = time.perf_counter() - t0
        dc = time.process_time() + workers_cpu(client) - c0
        assert all(row["status"] == "ok" for row in res.rows), res.failed
        assert len(res.rows) == n
        shutil.rmtree(out)                   # ~0.2 MB of series a point: not kept
        key = (name, n)
        wall[key] = min(wall.get(key, float("inf")), dt)
        cpu[key] = min(cpu.get(key, float("inf")), dc)
        inside[key] = min(inside.get(key, float("inf")), sum(p.cpu_time for p in res.results))
        tasks[name] = res.dask_tasks
        print(f"  {name:7s} {n:4d} points, run {r + 1}: {dt:7.3f} s  ({dt / n * 1e3:7.2f} ms "
              f"per point; CPU {dc / n * 1e3:7.2f} ms per point, this process and the workers)")

    def warm(**kw) -> None:
        """One untimed run of the first points: imports, engine library, FMU instance."""
        out = os.path.join(tmp, f"{label}_warm")
        run_study(studies[small], out, fmu_dir=fmu_dir, progress=None, figures=False,
                  resume=False, **kw)
        shutil.rmtree(out)

    print(f"{label}: {small} and {big} points")
    warm(executor="loop")
    for r in range(repeat):
        for n in (big, small):
            timed("loop", n, r, executor="loop")
    for workers, counts in ((1, (big, small)), (2, (big,))):
        cluster = local_cluster(workers)     # the sweep's own (loopback only), alone running
        client = Client(cluster)
        try:
            warm(client=client)
            for r in range(repeat):
                for n in counts:
                    timed(f"dask {workers}", n, r, client=client)
        finally:
            _close_quietly(client, cluster)
    t_loop, t1, t2 = wall["loop", big], wall["dask 1", big], wall["dask 2", big]
    speedup = t1 / t2
    print(f"  {big} points: loop {t_loop:.3f} s, dask 1 worker {t1:.3f} s, dask 2 workers "
          f"{t2:.3f} s (best of {repeat}); Dask tasks: {tasks['dask 1']} (1 worker), "
          f"{tasks['dask 2']} (2 workers)")
    print(f"  speed-up of 2 workers over 1: {speedup:.2f}x   (goal >= 1.85, floor >= 1.7: "
          f"{_verdict(speedup, 1.85, 1.7)})")
    dn = big - small

    def split(t: dict[tuple[str, int], float]) -> tuple[float, float, float]:
        """(loop's cost per point, Dask's extra per point, Dask's extra per study) [s]."""
        per_loop = (t["loop", big] - t["loop", small]) / dn
        per_dask = (t["dask 1", big] - t["dask 1", small]) / dn
        extra = per_dask - per_loop
        return per_loop, extra, (t["dask 1", big] - t["loop", big]) - extra * big

    for what, t in (("wall time", wall), ("CPU time", cpu)):
        per_loop, extra, fixed = split(t)
        share = extra / per_loop * 100
        print(f"  Dask 1 worker over the loop, {what}: {extra * 1e3:+.2f} ms per point = "
              f"{share:+.1f} % of the loop's {per_loop * 1e3:.2f} ms   (goal <= 2 %: "
              f"{'met' if share <= 2.0 else 'NOT met'}), and {fixed:+.3f} s per study")
    print(f"  CPU of the points themselves (sum of their cpu_time), {big} points: loop "
          f"{inside['loop', big] / big * 1e3:.2f} ms, dask 1 worker "
          f"{inside['dask 1', big] / big * 1e3:.2f} ms per point; the rest: loop "
          f"{(cpu['loop', big] - inside['loop', big]) / big * 1e3:.2f} ms, dask 1 worker "
          f"{(cpu['dask 1', big] - inside['dask 1', big]) / big * 1e3:.2f} ms per point")
    print()


def _load() -> str:
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=240, help="FMU backend: about this many "
                    "points (× 4)")
    ap.add_argument("--model-points", type=int, default=480, help="model backend: about this "
                    "many points (× 4)")
    ap.add_argument("--repeat", type=int, default=2, help="runs per configuration (best counts)")
    ap.add_argument("--goal-only", action="store_true", help="only the one-engine goal")
    args = ap.parse_args()

    from prsm_fmu.sweep import ensure_fmus, load_study

    with tempfile.TemporaryDirectory(prefix="prsm_sweep_scaling_") as tmp:
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
                scaling(studies, fmu_dir, tmp, args.repeat, f"{backend} backend")
    print(_load())


if __name__ == "__main__":
    main()
