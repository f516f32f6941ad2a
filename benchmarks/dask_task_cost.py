"""Dask's CPU cost of a study's chunk, by how the chunk travels: a list of points in and a
list of results out (the sweep's tasks before :func:`prsm_fmu.sweep.points.pack_chunk`), or
one pickle each way (``pack_chunk``); split into a cost per task and a cost per point.

The points' work is taken out: each task returns results computed beforehand (the first
``--points`` points of the model-backend start-up study of benchmarks/sweep_scaling.py, run
once in this process, their series saved as a worker saves them), so what is measured is
Dask's round trip only: submit, scheduler, the worker receiving the task and sending its
result, this process fetching it (``Future.result``) and releasing it.  The results wait on the
worker packed (scattered once), so each task of either shape unpickles them there once more
than a study's task does (about 10 µs a point, the same for both shapes).  A local cluster of one
worker (:func:`prsm_fmu.sweep.execute.local_cluster`), ``--in-flight`` tasks in flight as the
study keeps them, ``--tasks`` tasks per configuration, chunks of 1 and of ``--points`` points,
the configurations interleaved ``--repeat`` times.  Measured: CPU time of the whole process
tree (this process with its scheduler, the worker and its nanny; /proc, 10 ms ticks per
process, so a configuration's total is read to ~0.25 ms a task at 40 tasks); per task =
the chunk of 1 point, per point = (chunk of N - chunk of 1) / (N - 1), medians of the repeats.

Run: ``python benchmarks/dask_task_cost.py [--points 200] [--tasks 40] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time


def tree_cpu() -> float:
    """CPU time [s] of this process and all its descendants (user + system, /proc)."""
    tick = os.sysconf("SC_CLK_TCK")
    pids = [os.getpid()]
    total = 0.0
    while pids:
        pid = pids.pop()
        try:
            with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick     # utime, stime
            with open(f"/proc/{pid}/task/{pid}/children", encoding="ascii") as fh:
                pids.extend(int(c) for c in fh.read().split())
        except (FileNotFoundError, ProcessLookupError):
            continue
    return total


def replay_list(tasks, results: bytes):
    """The old task's shape: a list of points in, a list of results out."""
    from prsm_fmu.sweep.points import unpack_chunk

    return list(unpack_chunk(results))


def replay_packed(payload: bytes, results: bytes):
    """The new task's shape: one pickle in (unpacked as run_chunk does), one pickle out."""
    from prsm_fmu.sweep.points import pack_chunk, unpack_chunk

    unpack_chunk(payload)
    return pack_chunk(unpack_chunk(results))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=200, help="points of the larger chunk")
    ap.add_argument("--tasks", type=int, default=40, help="tasks per configuration and repeat")
    ap.add_argument("--repeat", type=int, default=5, help="interleaved repeats")
    ap.add_argument("--in-flight", type=int, default=2, help="tasks in flight")
    args = ap.parse_args()

    import sys

    from dask.distributed import Client, as_completed

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from sweep_scaling import _study

    from prsm_fmu.sweep import load_study
    from prsm_fmu.sweep.execute import local_cluster, metric_columns
    from prsm_fmu.sweep.points import PointTask, pack_chunk, run_points, unpack_chunk
    from prsm_fmu.sweep.table import columns

    with tempfile.TemporaryDirectory(prefix="prsm_dask_task_cost_") as tmp:
        path = os.path.join(tmp, "study.toml")
        _study(path, 4 * ((args.points + 3) // 4), "model")
        study = load_study(path)
        header = columns(study.swept, metric_columns(study))
        names = tuple(c for c in header if c not in ("point", "id", "status", "error")
                      and c not in study.swept)
        tasks = [PointTask(p.index, study.point_id(p.values, "model"), dict(p.values),
                           study.point_inputs(p.values, "model"), names)
                 for p in study.points()][:args.points]
        series = os.path.join(tmp, "series")
        os.makedirs(series)
        results = run_points(tasks, None, series)      # the series saved, as a worker does
        assert all(r.status == "ok" for r in results), [r.error for r in results]
        n_big = len(results)
        cluster = local_cluster(1)
        client = Client(cluster)
        # the results wait on the worker (scattered once), packed: both shapes unpack them there
        stored = {n: client.scatter(pack_chunk(results[:n]), broadcast=True) for n in (1, n_big)}
        shapes = {
            "list": lambda n: (replay_list, (list(tasks[:n]), stored[n])),
            "pickle": lambda n: (replay_packed, (tasks[:n], stored[n])),
        }
        cpu: dict[tuple[str, int], list[float]] = {(k, n): [] for k in shapes for n in (1, n_big)}
        try:
            client.submit(replay_list, [], stored[1], pure=False).result()   # connections made
            for _ in range(args.repeat):
                for (name, n), v in cpu.items():
                    fn, (points, done) = shapes[name](n)
                    c0 = tree_cpu()
                    pending = as_completed()
                    sent = 0

                    def submit():
                        # packed here, in the loop, as the study packs each chunk it submits
                        first = pack_chunk(points) if name == "pickle" else points
                        return client.submit(fn, first, done, pure=False)

                    while sent < min(args.in_flight, args.tasks):
                        pending.add(submit())
                        sent += 1
                    for fut in pending:
                        out = fut.result()
                        fut.release()
                        got = unpack_chunk(out) if name == "pickle" else out
                        assert len(got) == n
                        if sent < args.tasks:
                            pending.add(submit())
                            sent += 1
                    v.append((tree_cpu() - c0) / args.tasks)
        finally:
            client.close()
            cluster.close()
    print(f"Dask's CPU per chunk (this process with its scheduler, the worker, its nanny): "
          f"chunks of 1 and {n_big} model points, {args.tasks} tasks x {args.repeat} "
          f"interleaved repeats, {args.in_flight} in flight; load average "
          + ", ".join(f"{v:.2f}" for v in os.getloadavg()))
    med = {k: statistics.median(v) for k, v in cpu.items()}
    for name in shapes:
        per_point = (med[name, n_big] - med[name, 1]) / (n_big - 1)
        print(f"  {name:6s}: {med[name, 1] * 1e3:6.2f} ms per task (chunk of 1), "
              f"{med[name, n_big] * 1e3:6.2f} ms per chunk of {n_big}: "
              f"{per_point * 1e3:6.3f} ms per point (medians; least of a chunk of {n_big}: "
              f"{min(cpu[name, n_big]) * 1e3:.2f} ms)")
    saved = ((med["list", n_big] - med["list", 1]) - (med["pickle", n_big] - med["pickle", 1])) \
        / (n_big - 1)
    print(f"  list - one pickle: {saved * 1e3:+.3f} ms per point")


if __name__ == "__main__":
    main()
