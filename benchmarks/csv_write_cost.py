"""The results CSV's two writers in this checkout, in one run: the compiled formatter
(``prsm_fmu/native/csv_format.c``, where gcc builds it) against the numpy reference
(``prsm_fmu/csv_format.py``, what runs without gcc).  The older writer is compared in
``benchmarks/command_cost.py --write-only`` (item 3).

The table is the one of ``command_cost.py`` item 3: ``position_step``'s result held 1.5 s
(15 001 rows, every output column; the FMU built and run first, not timed).  Printed:

1. ``write_csv`` end to end in a fresh process (the header, the library's load or the numpy
   tables' set-up, the formatting, the file written): CPU [s] of the call, compiled (the
   default) and numpy (the same process without gcc on its PATH and with an empty temporary
   directory: no library can be built or found, the reference writes), interleaved, median of
   ``--repeat`` each, and their ratio;
2. the formatting alone (``format_columns``, in this process, every column): ns of CPU per
   value, each path, median of ``--repeat``, and their ratio.

Run: ``python benchmarks/csv_write_cost.py [--repeat 5]`` (about a minute).
"""

from __future__ import annotations

import argparse
import importlib.util
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent


def _command_cost():
    spec = importlib.util.spec_from_file_location("_command_cost", ROOT / "command_cost.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="repetitions of each (median counts)")
    args = ap.parse_args()
    cc = _command_cost()
    py = sys.executable
    tree = cc.ROOT
    with tempfile.TemporaryDirectory(prefix="csv_write_cost_") as tmp:
        tmp = Path(tmp)
        work = cc._build_fmus(py, {"new": tree}, tmp)
        long_ = tmp / "result_1.5s.pkl"
        subprocess.run([py, "-c", cc._RESULT, str(work["new"] / "dist" / "PRSM2.fmu"),
                        str(tmp / "short.pkl"), str(long_)], env=cc._env(tree), cwd=cc.NEUTRAL,
                       check=True, capture_output=True)
        no_gcc = tmp / "no-gcc"
        (no_gcc / "bin").mkdir(parents=True)
        (no_gcc / "tmp").mkdir()

        def write(compiled: bool) -> float:
            env = cc._env(tree)
            if not compiled:
                env.update(PATH=str(no_gcc / "bin"), TMPDIR=str(no_gcc / "tmp"))
            out = subprocess.run([py, "-c", cc._WRITE, str(long_),
                                  str(tmp / f"w-{compiled}.csv")], env=env, cwd=cc.NEUTRAL,
                                 capture_output=True, text=True, check=True)
            return float(out.stdout.split()[-1])

        runs = cc._interleaved(args.repeat, {"compiled": lambda: write(True),
                                             "numpy": lambda: write(False)})
        c, n = statistics.median(runs["compiled"]), statistics.median(runs["numpy"])
        same = (tmp / "w-True.csv").read_bytes() == (tmp / "w-False.csv").read_bytes()
        res = pickle.load(open(long_, "rb"))

    from prsm_fmu.csv_format import format_columns
    from system_models.output import ordered_columns

    columns = [res.time] + [res[k] for k in ordered_columns(res, ["prsm.rod_position"])]
    values = len(columns) * res.time.size
    print(f"this checkout, {res.time.size} rows x {len(columns)} columns, median of "
          f"{args.repeat} runs each, this machine, this run\n")
    print(f"1. write_csv end to end (fresh process): compiled {c:.3f} s, numpy {n:.3f} s CPU, "
          f"{n / c:.1f}x; files byte-identical: {same}")
    times: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(args.repeat):
        for compiled in (True, False):
            t = time.process_time()
            for _piece in format_columns(columns, compiled=compiled):
                pass
            times[compiled].append(time.process_time() - t)
    tc, tn = (statistics.median(times[k]) / values * 1e9 for k in (True, False))
    print(f"2. formatting alone: compiled {tc:.0f} ns, numpy {tn:.0f} ns of CPU a value, "
          f"{tn / tc:.1f}x")


if __name__ == "__main__":
    main()
