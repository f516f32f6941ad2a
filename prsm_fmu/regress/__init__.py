"""Regression tests of the built FMU's outputs against stored, reviewed baselines (issue 6).

``prsm-fmu regress`` builds ``PRSM2.fmu`` in a child process, runs each case of
``baselines/tolerances.toml`` (a scene of ``system_models/scenes`` at one fidelity) with fmpy,
compares every stored output with its baseline by a tolerance tube (:mod:`.tube`) and writes an
HTML report with a plot of each output that left its tube; ``--update`` rewrites the baselines
at tight tolerance and ``baselines/REPORT.md``.  See docs/regression.md.

Modules: :mod:`.tube` (the tube, numpy only), :mod:`.core` (cases, CSV, runs, update),
:mod:`.report` (PNG and HTML).  Nothing here is used by the FMU's slave.
"""

from .core import (DEFAULT_DIR, Case, CaseResult, build_fmu, check, check_case,
                   fmu_mismatch, load_cases, read_baselines, simulate_case, update, why_build)
from .tube import Tolerance, TubeResult, compare, tube

__all__ = ["DEFAULT_DIR", "Case", "CaseResult", "build_fmu", "check",
           "check_case", "fmu_mismatch", "why_build",
           "load_cases", "read_baselines", "simulate_case", "update", "Tolerance",
           "TubeResult", "compare", "tube"]
