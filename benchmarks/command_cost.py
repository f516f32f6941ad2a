"""What a user waits for: the commands' cost, this checkout against an older commit, in one run.

The older code (default: commit 707572e, before the "speed a user feels" work) is unpacked with
``git archive`` into a temporary folder and run through ``PYTHONPATH`` (it comes before the
editable install of this checkout on ``sys.path``); this checkout runs the same way.  Every
measurement runs in a fresh child process; old and new repetitions are interleaved (old, new,
old, new, ...) and the median of each counts, so a load that comes and goes on a shared machine
hits both alike.  Printed, each beside its goal:

1. ``prsm-ema list``: CPU time [s] (user + system of the child), old and new, against
   ``python -c "import numpy"`` — goal ≤ 1× numpy's import [floor ≤ 2×];
2. the README's first command, ``prsm-ema run --scene position_step``: wall time, old / new,
   with the same files written — goal ≥ 3× [≥ 2×].  Each tree's ``dist/PRSM2.fmu`` is built
   before the clock starts (its first run builds it; not timed);
3. writing the results CSV of ``position_step`` held 1.5 s (15 001 rows: the 0.25 s run's
   result repeated to that length, every column a real output): CPU of ``write_csv``, old / new
   — goal ≥ 10× [≥ 5×], each tree's modules imported before the clock (the old writer's came
   with ``system_models.output``; the new one imports ``prsm_fmu.csv_format`` in its first
   call, so that the figures' processes need not: that import is timed apart and the ratio
   with it printed too); the compiled formatter's library is loaded inside the timed call;
4. the figures of that 0.25 s run (``write_plots``, matplotlib imported inside): CPU, old / new;
5. the pythonfmu FMU's start-up to the end of the first ``doStep`` (fmpy, in a fresh process),
   from ``import fmpy`` (imports included) and from ``instantiate`` (the FMU's own start-up:
   its slave's imports, the model's set-up, the engine's load), old FMU / new FMU, and whether
   scipy was imported by then (``--startup-only``: this alone).

``--write-only``: 3. alone (a minute, not several; ``--repeat 7`` steadies it on a loaded
machine).  ``--readme-only``: 2. alone (``--repeat 7``: two minutes on an idle machine).

Not measured here (say so rather than guess): the sweep's scaling (``benchmarks/sweep_scaling.py``)
and ``prsm-fmu regress`` (``--regress`` adds it: wall time, old / new).

Run: ``python benchmarks/command_cost.py [--old 707572e] [--repeat 3] [--regress]
[--startup-only | --write-only | --readme-only]``
(several minutes: the README command runs 2 × repeat times).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _env(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env.pop("PYTHONHASHSEED", None)
    # bytecode kept as an installed package keeps it (pip compiles on install): a shell that
    # sets PYTHONDONTWRITEBYTECODE would make every child recompile both trees' sources
    # (~0.4 s CPU of `prsm-ema run`), which no user pays after the first run
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


#: the children's working directory when none is given: not a source tree (``python -m`` and
#: ``python -c`` put the working directory first on sys.path, before PYTHONPATH)
NEUTRAL = Path(tempfile.gettempdir())


def _child(args: list[str], tree: Path, cwd: Path | None = None) -> tuple[float, float, str]:
    """(CPU [s] of the child, wall [s], stdout) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(args, env=_env(tree), cwd=cwd or NEUTRAL, capture_output=True,
                          text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in ((0, 1) if "run" in args else (0,)):
        raise RuntimeError(f"{' '.join(args)} (PYTHONPATH={tree}) failed:\n{proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, proc.stdout


def _interleaved(repeat: int, runs: dict[str, callable]) -> dict[str, list]:
    out: dict[str, list] = {k: [] for k in runs}
    for _ in range(repeat):
        for k, f in runs.items():
            out[k].append(f())
    return out


def _med(xs) -> float:
    return statistics.median(xs)


def _old_tree(commit: str, where: Path) -> Path:
    tree = where / f"old-{commit}"
    tree.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


_WRITE = """
import pickle, sys, time
from system_models.output import write_csv
res = pickle.load(open(sys.argv[1], 'rb'))
t = time.process_time()
try:    # imported by write_csv itself where system_models.output does not import it
    import prsm_fmu.csv_format
except ImportError:     # a tree without it
    pass
formatter = time.process_time() - t
t = time.process_time()
write_csv(res, sys.argv[2], ["prsm.rod_position"])
print(formatter, time.process_time() - t)
"""

_PLOTS = """
import pickle, sys, time
t = time.process_time()
from system_models.output import write_plots
res = pickle.load(open(sys.argv[1], 'rb'))
write_plots(res, sys.argv[2], "position_step", lambda s: 0.01 if s >= 0.01 else 0.0,
            "position", 40.0, description="rod position step", voltage_limit=300.0,
            n_rollers=[10, 10])
print(time.process_time() - t)
"""

_RESULT = """
import pickle, sys
import numpy as np
from system_models.run import run_scene
from system_models.master import Result
run = run_scene("position_step", prsm="fmu", fmu_path=sys.argv[1])
r = run.result
pickle.dump(r, open(sys.argv[2], "wb"))
# 1.5 s on the same grid: the run's rows repeated (time continued on the grid)
n = 15001
reps = -(-n // r.time.size)
h = float(r.time[1] - r.time[0])
values = {k: np.tile(v, reps)[:n] for k, v in r.values.items()}
pickle.dump(Result(r.time[0] + h * np.arange(n), values, dict(r.units)), open(sys.argv[3], "wb"))
"""

_STARTUP = """
import sys, time
t0 = time.perf_counter()
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
path = sys.argv[1]
md = read_model_description(path)
unzip = extract(path)
s = FMU2Slave(guid=md.guid, unzipDirectory=unzip,
              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="b")
t1 = time.perf_counter()
s.instantiate()
s.setupExperiment(startTime=0.0)
s.enterInitializationMode()
s.exitInitializationMode()
s.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
t2 = time.perf_counter()
print(t2 - t0, t2 - t1, int("scipy" in sys.modules))
"""


def _startup(py: str, trees: dict[str, Path], work: dict[str, Path], repeat: int) -> None:
    """5. the default FMU's start-up in fresh processes, old FMU (its tree) / new FMU: wall
    time from ``import fmpy`` and from instantiate, both to the end of the first doStep, and
    whether scipy was imported by then."""
    def once(k: str) -> list[float]:
        out = _child([py, "-c", _STARTUP, str(work[k] / "dist" / "PRSM2.fmu")], trees[k])[2]
        return [float(v) for v in out.split()[-3:]]

    r = _interleaved(repeat, {k: (lambda k=k: once(k)) for k in trees})
    (o, oi), (w, wi) = ([_med(x[i] for x in r[k]) for i in (0, 1)] for k in ("old", "new"))
    scipy = {k: "yes" if any(x[2] for x in r[k]) else "no" for k in trees}
    print(f"5. pythonfmu FMU start-up, wall: import fmpy .. end of the first doStep: old {o:.2f} s, "
          f"new {w:.2f} s, {o / w:.2f}x; instantiate .. end of the first doStep: old {oi:.3f} s, "
          f"new {wi:.3f} s, {oi / wi:.2f}x; scipy imported: old {scipy['old']}, new "
          f"{scipy['new']}")


def _write_cost(py: str, trees: dict[str, Path], work: dict[str, Path], tmp: Path,
                repeat: int) -> tuple[Path, Path]:
    """3. ``write_csv`` of the 1.5 s result, old / new, CPU; returns the pickled 0.25 s and
    1.5 s results (made with the new tree's FMU)."""
    short, long_ = tmp / "result_0.25s.pkl", tmp / "result_1.5s.pkl"
    subprocess.run([py, "-c", _RESULT, str(work["new"] / "dist" / "PRSM2.fmu"), str(short),
                    str(long_)], env=_env(trees["new"]), cwd=NEUTRAL, check=True,
                   capture_output=True)

    imports: dict[str, list[float]] = {k: [] for k in trees}

    def write(k: str) -> float:
        formatter, cost = map(float, _child([py, "-c", _WRITE, str(long_),
                                             str(tmp / f"w-{k}.csv")], trees[k])[2].split()[-2:])
        imports[k].append(formatter)
        return cost

    r = _interleaved(repeat, {k: (lambda k=k: write(k)) for k in trees})
    o, w = _med(r["old"]), _med(r["new"])
    f = _med(imports["new"])
    rows = sum(1 for _ in open(tmp / "w-new.csv", encoding="utf-8")) - 1
    print(f"3. write_csv, {rows} rows: old {o:.3f} s, new {w:.3f} s CPU, {o / w:.1f}x faster"
          f"   goal >= 10x [>= 5x]; with the import of the new formatter's module, which "
          f"write_csv does on its first call ({f:.3f} s): {o / (w + f):.1f}x")
    return short, long_


def _readme(py: str, trees: dict[str, Path], work: dict[str, Path], repeat: int) -> None:
    """2. the README's first command, wall time, old / new (each run's beside the medians)."""
    def readme(k: str) -> float:
        out = work[k] / "out"
        shutil.rmtree(out, ignore_errors=True)
        return _child([py, "-m", "system_models", "run", "--scene", "position_step",
                       "--out", str(out)], trees[k], cwd=work[k])[1]

    r = _interleaved(repeat, {k: (lambda k=k: readme(k)) for k in trees})
    files = {k: sorted(p.name for p in (work[k] / "out").iterdir()) for k in trees}
    o, w = _med(r["old"]), _med(r["new"])
    runs = "; ".join(f"{k} " + " ".join(f"{x:.2f}" for x in r[k]) for k in trees)
    print(f"2. prsm-ema run --scene position_step, wall: old {o:.2f} s, new {w:.2f} s, "
          f"{o / w:.2f}x faster   goal >= 3x [>= 2x]; same files written: "
          f"{files['old'] == files['new']} ({len(files['new'])} files); runs [s]: {runs}")


def _build_fmus(py: str, trees: dict[str, Path], tmp: Path,
                only: tuple[str, ...] | None = None) -> dict[str, Path]:
    """Each tree's ``dist/PRSM2.fmu`` (the README command's), built before any clock (``only``:
    those trees' alone)."""
    work = {k: tmp / f"run-{k}" for k in trees}
    for k, tree in trees.items():
        if only is not None and k not in only:
            continue
        work[k].mkdir()
        subprocess.run([py, "-m", "fmu_build", "PRSM2", "--dest", str(work[k] / "dist")],
                       env=_env(tree), cwd=work[k], check=True, capture_output=True)
    return work


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="707572e", help="the commit to compare with")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions of each (median counts)")
    ap.add_argument("--regress", action="store_true", help="also time prsm-fmu regress")
    ap.add_argument("--startup-only", action="store_true",
                    help="only 5., the FMU's start-up (a minute, not several)")
    ap.add_argument("--readme-only", action="store_true",
                    help="only 2., the README's first command")
    ap.add_argument("--write-only", action="store_true",
                    help="only 3., writing the results CSV (a minute, not several)")
    args = ap.parse_args()
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="command_cost_") as tmp:
        tmp = Path(tmp)
        trees = {"old": _old_tree(args.old, tmp), "new": ROOT}
        print(f"old: {args.old} (git archive into a temporary folder); new: {ROOT}; "
              f"median of {args.repeat} interleaved runs each, this machine, this run\n")
        if args.startup_only:
            _startup(py, trees, _build_fmus(py, trees, tmp), args.repeat + 2)
            return
        if args.readme_only:
            _readme(py, trees, _build_fmus(py, trees, tmp), args.repeat)
            return
        if args.write_only:
            _write_cost(py, trees, _build_fmus(py, trees, tmp, only=("new",)), tmp,
                        args.repeat)
            return

        # 1. prsm-ema list
        r = _interleaved(args.repeat + 2, {
            "numpy": lambda: _child([py, "-c", "import numpy"], trees["new"])[0],
            "old": lambda: _child([py, "-m", "system_models", "list"], trees["old"])[0],
            "new": lambda: _child([py, "-m", "system_models", "list"], trees["new"])[0]})
        n, o, w = (_med(r[k]) for k in ("numpy", "old", "new"))
        print(f"1. prsm-ema list, CPU: numpy import {n:.3f} s, old {o:.3f} s ({o / n:.2f}x numpy), "
              f"new {w:.3f} s ({w / n:.2f}x numpy)   goal <= 1x [<= 2x]")

        work = _build_fmus(py, trees, tmp)

        _readme(py, trees, work, args.repeat)

        # 3. writing the 1.5 s result; 4. the figures of the 0.25 s run
        short, _ = _write_cost(py, trees, work, tmp, args.repeat)

        def plots(k: str) -> float:
            d = tmp / f"plots-{k}"
            d.mkdir(exist_ok=True)
            return float(_child([py, "-c", _PLOTS, str(short), str(d)], trees[k])[2].split()[-1])

        r = _interleaved(args.repeat, {k: (lambda k=k: plots(k)) for k in trees})
        o, w = _med(r["old"]), _med(r["new"])
        print(f"4. write_plots (7 figures, matplotlib import included): old {o:.2f} s, new {w:.2f} s "
              f"CPU, {o / w:.2f}x faster")

        _startup(py, trees, work, args.repeat + 2)

        if args.regress:
            r = _interleaved(args.repeat, {k: (lambda k=k: _child(
                [py, "-m", "prsm_fmu.cli", "regress", "--out", str(tmp / f"reg-{k}")],
                trees[k], cwd=work[k])[1]) for k in trees})
            o, w = _med(r["old"]), _med(r["new"])
            print(f"6. prsm-fmu regress, wall: old {o:.1f} s, new {w:.1f} s, {o / w:.2f}x   "
                  "goal >= 3x [>= 2x]")
        else:
            print("6. prsm-fmu regress: not measured (--regress)")
        print("   sweep scaling: not measured here (python benchmarks/sweep_scaling.py)")
        print(json.dumps({"note": "ratios from one run; absolute times depend on the load"}))


if __name__ == "__main__":
    main()
