"""Imports on demand: a command loads only what it uses.

Checked in a fresh interpreter (``sys.modules`` after the command), not by timing: ``prsm-ema
list`` needs no numerics at all, and a command or the FMU that solves no geometry or root must not
pay for ``scipy.optimize`` (~0.8 s of CPU to import on the CI machine) nor for matplotlib.
"""

from __future__ import annotations

import json
import subprocess
import sys


def _modules_after(code: str) -> set[str]:
    """The top-level packages loaded by a fresh interpreter after running ``code``."""
    probe = (code + "\nimport sys, json\n"
             "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=120)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_prsm_ema_list_imports_no_numerics():
    loaded = _modules_after("from system_models.cli import main\n"
                            "import contextlib, io\n"
                            "with contextlib.redirect_stdout(io.StringIO()):\n"
                            "    assert main(['list']) == 0\n")
    assert not loaded & {"numpy", "scipy", "matplotlib", "fmpy", "pythonfmu", "dask"}, loaded


def test_prsm_ema_argument_errors_import_no_numerics():
    # a bad argument is refused before anything heavy is loaded
    loaded = _modules_after("from system_models.cli import main\n"
                            "import contextlib, io\n"
                            "with contextlib.redirect_stderr(io.StringIO()):\n"
                            "    assert main(['run', '--scene', 'position_step', '--retry', '-1']) == 2\n")
    assert not loaded & {"numpy", "scipy", "matplotlib"}, loaded


def test_the_figure_process_module_imports_no_numerics():
    # prsm-ema run forks its figure process first thing, from this module: a small process to
    # copy, whose matplotlib import overlaps the command's own imports
    loaded = _modules_after("import system_models.figure_process\n")
    assert not loaded & {"numpy", "scipy", "matplotlib", "fmpy"}, loaded


def test_the_drawing_processes_do_not_load_the_csv_writer():
    # the figures' processes import system_models.output and draw: the CSV formatter's tables
    # (prsm_fmu.csv_format, built at its import) are the command's own process's business
    probe = ("import sys\nfrom system_models.output import _warm\n_warm()\n"
             "print('prsm_fmu.csv_format' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.split()[-1] == "False"


_NO_SCIPY = ["prsm_fmu", "prsm_fmu.geometry", "prsm_fmu.models", "prsm_fmu.steady_state",
             "prsm_fmu.design_checks", "prsm_fmu.report", "system_models.ema",
             "system_models.coupling_analysis", "system_models.run", "prsm_fmu.cli"]


def test_imports_do_not_load_scipy_or_matplotlib():
    # one interpreter, the modules imported one after another; the first that pulls scipy or
    # matplotlib in is named
    code = ("import importlib, sys\nbad = []\n"
            f"for m in {_NO_SCIPY!r}:\n"
            "    importlib.import_module(m)\n"
            "    if {'scipy', 'matplotlib'} & {k.split('.')[0] for k in sys.modules}:\n"
            "        bad.append(m); break\n"
            "assert not bad, f'{bad[0]} imports scipy or matplotlib'\n")
    _modules_after(code)


def test_solving_still_loads_scipy_on_demand():
    # the on-demand import is really there: the steady state is a root of the balance equations
    loaded = _modules_after("from prsm_fmu import presets, steady_state\n"
                            "ss = steady_state(presets.load('li2021_two_stage'), "
                            "screw_speed=100.0, load_force=5000.0)\n")
    assert "scipy" in loaded


def test_functions_named_as_their_modules_stay_functions():
    # importing the submodule prsm_fmu.steady_state first must not hide the function
    _modules_after("import types\n"
                   "import prsm_fmu.steady_state, prsm_fmu.simulate\n"
                   "from prsm_fmu import simulate, steady_state\n"
                   "assert isinstance(simulate, types.FunctionType), simulate\n"
                   "assert isinstance(steady_state, types.FunctionType), steady_state\n")


def test_the_package_pickles_by_name():
    # Dask (cloudpickle) sends module objects by name; the lazy package must allow it
    import pickle

    import prsm_fmu

    assert pickle.loads(pickle.dumps(prsm_fmu)) is prsm_fmu
