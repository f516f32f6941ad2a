"""A sweep point's CPU outside the physics: this checkout against an older commit, in one run.

The study: ``benchmarks/sweep_scaling.py``'s start-up study (Li et al. (2021) §3.1: PRSM2,
dynamic level, 100 rad/s step, 5000 N, 1 ms at 1 µs communication steps) over ``--points``
points (default 240), on the FMU backend's default door — the native FMU ``PRSM2-native.fmu``
stepped by the compiled master (``prsm_fmu/sweep/native/fmu_track.c``) — run by
:func:`prsm_fmu.sweep.run_study` with ``executor="loop"`` (the points one after the other in one
process, the FMU loaded once), series files written, figures off.

The older code (default: commit 721f72e) is unpacked with ``git archive`` into a temporary
folder, as benchmarks/command_cost.py does, and each tree runs in child processes through
``PYTHONPATH`` with its own native FMU (built from its own sources before any clock starts).
A child runs the study once untimed (imports, the FMU instance, the compiled loop's library)
and then ``--repeat``-independent times on fresh output folders, timed; old and new children
are interleaved (old, new, old, new, ...) so a load that comes and goes on a shared machine
hits both alike, and the median of each tree's runs counts.  Printed, per point, in CPU time
of the child process (``time.process_time``):

* the whole point (``run_study``'s CPU / points), old and new, and old / new;
* its split: the compiled loop (``CompiledLoop.run``), the series file (``save_series``),
  fmpy's ``getReal`` (the t = 0 torque and outputs, in initialization mode) and its other calls
  (``setReal``, ``reset``, ... outside the loop), ``resolve_preset``,
  ``MechanismParams.validate``, ``derive_series`` + ``compute_metrics``, and the rest (the
  runner's and ``run_point``'s own work, the table): each part's own time, without the parts
  it calls (a timer around each; their own cost, about a microsecond a call, lands in the rest);
* the cost outside the loop (the point less its loop), old and new, and old / new.

Run: ``python benchmarks/point_cost.py [--old 721f72e] [--points 240] [--repeat 3]``
(about a minute per repeat).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: the parts of a point, in print order: (label, what is timed)
PARTS = (
    ("compiled loop", "prsm_fmu.sweep.native_track:CompiledLoop.run"),
    ("series file", "prsm_fmu.sweep.points:save_series"),
    ("fmpy getReal", "fmpy.fmi2:FMU2Slave.getReal"),
    ("fmpy other calls", "fmpy.fmi2:FMU2Slave.setReal FMU2Slave.setInteger FMU2Slave.setBoolean "
                         "FMU2Slave.reset FMU2Slave.setupExperiment "
                         "FMU2Slave.enterInitializationMode FMU2Slave.exitInitializationMode "
                         "FMU2Slave.terminate"),
    ("resolve_preset", "prsm_fmu.sweep.points:resolve_preset"),
    ("validate", "prsm_fmu.params:MechanismParams.validate"),
    ("metrics", "prsm_fmu.sweep.points:derive_series compute_metrics"),
)

#: the child: one tree's study, untimed once, then timed on fresh folders; prints JSON
_CHILD = r"""
import importlib, json, os, shutil, sys, time
sys.path.insert(0, os.path.join(sys.argv[1], "benchmarks"))
from sweep_scaling import _study
from prsm_fmu.sweep import load_study, run_study

parts = json.loads(sys.argv[5])
spent = {label: 0.0 for label, _ in parts}
stack = []                          # [label, start, time of the parts it called]


def timed(label, f):
    def wrapper(*a, **k):
        stack.append([label, time.process_time(), 0.0])
        try:
            return f(*a, **k)
        finally:
            lab, t0, inner = stack.pop()
            dt = time.process_time() - t0
            spent[lab] += dt - inner
            if stack:
                stack[-1][2] += dt
    return wrapper


for label, where in parts:
    module, names = where.split(":")
    mod = importlib.import_module(module)
    for name in names.split():
        owner, _, attr = name.rpartition(".")
        target = getattr(mod, owner) if owner else mod
        setattr(target, attr, timed(label, getattr(target, attr)))

work, n = sys.argv[2], int(sys.argv[3])
path = os.path.join(work, "study.toml")
_study(path, n)
study = load_study(path)


def run(out):
    return run_study(study, out, executor="loop", fmu_dir=sys.argv[4], fmu="native",
                     figures=False, progress=None, resume=False)


run(os.path.join(work, "warm"))
shutil.rmtree(os.path.join(work, "warm"))
for k in spent:
    spent[k] = 0.0
c0 = time.process_time()
res = run(os.path.join(work, "timed"))          # a fresh folder
total = time.process_time() - c0
shutil.rmtree(os.path.join(work, "timed"))
points = len(study.points())
print(json.dumps({"points": points, "total": total, "parts": spent}))
"""


def _env(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _old_tree(commit: str, where: Path) -> Path:
    tree = where / f"old-{commit}"
    tree.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def _build_fmu(tree: Path, dest: Path) -> None:
    """The tree's own native PRSM2 FMU into dest (with the tree's fmu_build)."""
    code = ("import sys; from prsm_fmu.sweep import ensure_fmus; "
            "ensure_fmus([2], sys.argv[1], kind='native')")
    subprocess.run([sys.executable, "-c", code, str(dest)], env=_env(tree), cwd=dest.parent,
                   check=True)


def _run(tree: Path, work: Path, points: int, fmu_dir: Path) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(tree), str(work), str(points),
                           str(fmu_dir), json.dumps(PARTS)], env=_env(tree), cwd=work,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"the study failed in {tree}:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", default="721f72e", help="the older commit (default 721f72e)")
    ap.add_argument("--points", type=int, default=240, help="points of the study (× 4 µ_SS)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per tree (median counts)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="prsm_point_cost_") as tmp:
        tmp = Path(tmp)
        trees = {"old": _old_tree(args.old, tmp), "new": ROOT}
        fmus = {}
        for name, tree in trees.items():
            fmus[name] = tmp / f"fmu-{name}"
            fmus[name].mkdir()
            _build_fmu(tree, fmus[name])
        runs: dict[str, list[dict]] = {name: [] for name in trees}
        for r in range(args.repeat):
            for name, tree in trees.items():
                runs[name].append(_run(tree, tmp / f"work-{name}-{r}", args.points, fmus[name]))
        n = runs["new"][0]["points"]
        load = os.getloadavg()[0]
        print(f"start-up study, {n} points, native FMU + compiled master, executor loop; "
              f"old = {args.old}, new = this checkout; median of {args.repeat} runs each, "
              f"interleaved; load average {load:.2f} on {os.cpu_count()} cores")

        def per_point(name: str, key: str | None) -> float:
            vals = [(run["total"] if key is None else run["parts"][key]) / run["points"]
                    for run in runs[name]]
            return 1e3 * statistics.median(vals)

        def outside(name: str) -> float:
            vals = [(run["total"] - run["parts"]["compiled loop"]) / run["points"]
                    for run in runs[name]]
            return 1e3 * statistics.median(vals)

        print(f"  {'CPU per point [ms]':<28}{'old':>9}{'new':>9}{'old/new':>9}")
        rows = [(label, per_point("old", label), per_point("new", label)) for label, _ in PARTS]
        rest = {name: 1e3 * statistics.median((run["total"] - sum(run["parts"].values()))
                                              / run["points"] for run in runs[name])
                for name in trees}
        rows.append(("rest", rest["old"], rest["new"]))
        for label, old, new in rows:
            ratio = f"{old / new:9.2f}" if new > 0 else f"{'-':>9}"
            print(f"  {label:<28}{old:9.3f}{new:9.3f}{ratio}")
        old_t, new_t = per_point("old", None), per_point("new", None)
        print(f"  {'whole point':<28}{old_t:9.3f}{new_t:9.3f}{old_t / new_t:9.2f}")
        old_o, new_o = outside("old"), outside("new")
        print(f"  {'outside the loop':<28}{old_o:9.3f}{new_o:9.3f}{old_o / new_o:9.2f}")
        print(f"  the point over its loop: old {old_t / per_point('old', 'compiled loop'):.2f}x, "
              f"new {new_t / per_point('new', 'compiled loop'):.2f}x")


if __name__ == "__main__":
    main()
