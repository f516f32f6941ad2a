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
A child runs the study once untimed (imports, the FMU instance, the compiled loop's library),
drops what the code keeps per process from one study to the next (the validated mechanisms and
presets: the timed run pays them as a process's first study does) and runs it again on a fresh
output folder, timed; ``--repeat`` children per tree; old and new children
are interleaved (old, new, old, new, ...) so a load that comes and goes on a shared machine
hits both alike, and of each quantity the least of each tree's runs counts (what the other
jobs of a shared machine can only add to; ``benchmarks/sweep_scaling.py`` takes the fastest run
the same way).  The compiled loop is the same code in both trees: its old / new ratio shows
what the machine's load leaves of the noise.  Printed, per point, in CPU time
of the child process (``time.process_time``):

* the whole point (``run_study``'s CPU / points), old and new, and old / new;
* its split: the compiled loop (``CompiledLoop.run``), the series file (``save_series``),
  the FMI reads of the t = 0 torque and outputs in initialization mode (fmpy's ``getReal``, or
  the runner's ``StepCalls``) and the other FMI calls outside the loop (``setReal``, ``reset``,
  ...), ``resolve_preset``,
  ``MechanismParams.validate``, ``derive_series`` + ``compute_metrics``, and the rest (the
  runner's and ``run_point``'s own work, the table): each part's own time, without the parts
  it calls (a timer around each; their own cost, about a microsecond a call, lands in the rest);
* the cost outside the loop (the point less its loop), old and new, and old / new;
* whether the first timed run of each tree wrote the same results: every cell of
  ``results.csv`` (numbers compared as doubles) and every array of every series file.

Run: ``python benchmarks/point_cost.py [--old 721f72e] [--points 240] [--repeat 3]``
(about a minute per repeat).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

sys.path.insert(0, str(Path(__file__).resolve().parent))
from command_cost import _env, _old_tree  # noqa: E402 - the same trees and environments

#: the parts of a point, in print order: (label, what is timed: "module:Owner.attr ...", several
#: modules separated by ";"; a name a tree does not have is skipped)
PARTS = (
    ("compiled loop", "prsm_fmu.sweep.native_track:CompiledLoop.run"),
    ("series file", "prsm_fmu.sweep.points:save_series"),
    ("FMI reads at t = 0", "fmpy.fmi2:FMU2Slave.getReal;"
                           "prsm_fmu.sweep.fmi_calls:StepCalls.real StepCalls.outputs_into"),
    ("other FMI calls", "fmpy.fmi2:FMU2Slave.setReal FMU2Slave.setInteger FMU2Slave.setBoolean "
                        "FMU2Slave.reset FMU2Slave.setupExperiment "
                        "FMU2Slave.enterInitializationMode FMU2Slave.exitInitializationMode "
                        "FMU2Slave.terminate;prsm_fmu.sweep.fmi_calls:StepCalls.set_torque"),
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
    for place in where.split(";"):
        module, names = place.split(":")
        mod = importlib.import_module(module)
        for name in names.split():
            owner, _, attr = name.rpartition(".")
            target = getattr(mod, owner) if owner else mod
            if hasattr(target, attr):
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
# what a tree keeps per process from one study to the next (the warm run had the same points)
# is dropped: the timed run pays it as a study's first run in a process does
from prsm_fmu.sweep import points as _points, study as _study_module
for owner, name in ((_points, "_point_params"), (_study_module, "_preset_of_name")):
    cached = getattr(owner, name, None)
    if cached is not None:
        cached.cache_clear()
c0 = time.process_time()
res = run(os.path.join(work, "timed"))          # a fresh folder
total = time.process_time() - c0
if sys.argv[6] != "keep":                       # else the parent compares it and removes it
    shutil.rmtree(os.path.join(work, "timed"))
points = len(study.points())
print(json.dumps({"points": points, "total": total, "parts": spent}))
"""


def _build_fmu(tree: Path, dest: Path) -> None:
    """The tree's own native PRSM2 FMU into dest (with the tree's fmu_build)."""
    code = ("import sys; from prsm_fmu.sweep import ensure_fmus; "
            "ensure_fmus([2], sys.argv[1], kind='native')")
    subprocess.run([sys.executable, "-c", code, str(dest)], env=_env(tree), cwd=dest.parent,
                   check=True)


def _run(tree: Path, work: Path, points: int, fmu_dir: Path, keep: bool) -> dict:
    """One child's run of the study; with ``keep`` its output stays in ``work/timed``."""
    work.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(tree), str(work), str(points),
                           str(fmu_dir), json.dumps(PARTS), "keep" if keep else "drop"],
                          env=_env(tree), cwd=work, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"the study failed in {tree}:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _same_number(a: float, b: float) -> bool:
    """Equal as doubles: the same number with the same sign, or both NaN."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


def _same_arrays(a, b) -> bool:
    import numpy as np

    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind != "f":
        return bool(np.array_equal(a, b))
    return bool(np.array_equal(a, b, equal_nan=True)
                and np.array_equal(np.signbit(a), np.signbit(b)))


def compare_outputs(old: Path, new: Path) -> str:
    """Whether two runs' tables (every cell: numbers as doubles, text as text) and series
    files (every array: dtype, shape, values) are the same; one line saying what was
    compared, or raises AssertionError naming the first difference."""
    import numpy as np

    from prsm_fmu.sweep.table import numeric_rows, read_table

    head_o, rows_o = read_table(str(old / "results.csv"))
    head_n, rows_n = read_table(str(new / "results.csv"))
    assert head_o == head_n and len(rows_o) == len(rows_n) > 0, "the tables' shapes differ"
    cells = 0
    for ro, rn in zip(numeric_rows(rows_o), numeric_rows(rows_n)):
        for col in head_o:
            a, b = ro[col], rn[col]
            same = _same_number(a, b) if isinstance(a, float) and isinstance(b, float) else a == b
            assert same, f"results.csv point {ro['point']} column {col}: {a!r} vs {b!r}"
            cells += 1
    files = sorted(p.name for p in (old / "series").iterdir())
    assert files == sorted(p.name for p in (new / "series").iterdir()), "series files differ"
    arrays = 0
    for name in files:
        with np.load(old / "series" / name) as zo, np.load(new / "series" / name) as zn:
            assert zo.files == zn.files, f"series/{name}: members differ"
            for k in zo.files:
                assert _same_arrays(zo[k], zn[k]), f"series/{name}: {k} differs"
                arrays += 1
    return (f"old and new outputs the same: results.csv {len(rows_o)} rows x {len(head_o)} "
            f"columns ({cells} cells, numbers as doubles), {len(files)} series files "
            f"({arrays} arrays, every value)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", default="721f72e", help="the older commit (default 721f72e)")
    ap.add_argument("--points", type=int, default=240, help="points of the study (× 4 µ_SS)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per tree (the least counts)")
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
                runs[name].append(_run(tree, tmp / f"work-{name}-{r}", args.points, fmus[name],
                                       keep=r == 0))
        n = runs["new"][0]["points"]
        load = os.getloadavg()[0]
        print(f"start-up study, {n} points, native FMU + compiled master, executor loop; "
              f"old = {args.old}, new = this checkout; least of {args.repeat} runs each, "
              f"interleaved; load average {load:.2f} on {os.cpu_count()} cores")

        def per_point(name: str, key: str | None) -> float:
            vals = [(run["total"] if key is None else run["parts"][key]) / run["points"]
                    for run in runs[name]]
            return 1e3 * min(vals)

        def outside(name: str) -> float:
            vals = [(run["total"] - run["parts"]["compiled loop"]) / run["points"]
                    for run in runs[name]]
            return 1e3 * min(vals)

        print(f"  {'CPU per point [ms]':<28}{'old':>9}{'new':>9}{'old/new':>9}")
        rows = [(label, per_point("old", label), per_point("new", label)) for label, _ in PARTS]
        rest = {name: 1e3 * min((run["total"] - sum(run["parts"].values())) / run["points"]
                                for run in runs[name])
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
        print("  " + compare_outputs(tmp / "work-old-0" / "timed", tmp / "work-new-0" / "timed"))


if __name__ == "__main__":
    main()
