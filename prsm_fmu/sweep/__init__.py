"""Parameter studies: grids and random samples of FMU (or model) runs, on one machine or a cluster.

::

    from prsm_fmu.sweep import load_study, run_study
    study = load_study("studies/li2021_friction.toml")
    res = run_study(study)                       # local Dask cluster, one worker per core
    res = run_study(study, scheduler="tcp://host:8786")
    res.rows, res.trends, res.figures

Command line: ``prsm-fmu sweep STUDY.toml [--out DIR] [--workers N | --scheduler ADDR]
[--backend fmu|model] [--fmu native|python] [--no-dask] [--fmu-dir DIR] [--rerun-all]``.  docs/sweeps.md describes
the study format, the execution, the table and the shipped studies.

Modules: :mod:`.study` (TOML → points), :mod:`.points` (one point on a worker),
:mod:`.fmu_runner` (the FMU with the screw speed prescribed), :mod:`.metrics` (a run → a row),
:mod:`.table` (CSV), :mod:`.execute` (Dask or loop, resume, report), :mod:`.trends` (the papers'
claims checked on the table), :mod:`.plots` (figures).  Dask is imported only when a study runs
on it (``pip install "prsm-fmu[sweep]"``); the FMU backend needs fmpy and, to build the native
FMU it runs on by default, ziglang (``[fmu]``; pythonfmu for ``--fmu python``).
"""

from __future__ import annotations

from .execute import SweepResult, ensure_fmus, load_series, run_study
from .study import Study, StudyError, apply_overrides, load_study
from .table import numeric_rows, read_table
from .trends import TrendResult, evaluate

__all__ = ["load_study", "run_study", "Study", "StudyError", "SweepResult", "TrendResult",
           "apply_overrides", "ensure_fmus", "evaluate", "load_series", "numeric_rows",
           "read_table"]
