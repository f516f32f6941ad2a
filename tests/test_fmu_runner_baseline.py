"""The sweep's FMU master gives the results it gave before its direct FMI calls.

``tests/data/fmu_runner_startup_c7f5419.csv`` is the stored result of
:class:`prsm_fmu.sweep.fmu_runner.FmuRunner` at commit c7f5419 (fmpy's calls, the slave's full
state restore) on 100 communication steps of Li et al. (2021) §3.1's start-up (PRSM2, dynamic,
100 rad/s step, 5000 N, µ_SR = 0.05, µ_SS = 0.1, tolerance 1e-8, 1 µs steps); its header
says the trial and right-hand-side counts.  The master now calls the FMU's library directly
(``prsm_fmu/sweep/fmi_calls.py``) and the slave restores its own states on a short path; the
calls and their order are the same, so the same trials are taken: the counts must be equal
and every sample equal to 1e-12 of its column's largest magnitude (on the machine the file was
made on they are equal bit for bit; a compiler elsewhere may differ in the last bits of the
engine's arithmetic, never by a different trial).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import re
from pathlib import Path

import pytest

pytest.importorskip("fmpy")

from prsm_fmu import presets  # noqa: E402
from prsm_fmu.sweep import ensure_fmus  # noqa: E402
from prsm_fmu.sweep.fmu_runner import FmuRunner  # noqa: E402
from prsm_fmu.sweep.points import speed_profile  # noqa: E402
from test_fmu import built_fmus  # noqa: E402

BASELINE = Path(__file__).parent / "data" / "fmu_runner_startup_c7f5419.csv"
#: relative to a column's largest magnitude (module docstring)
RTOL = 1e-12


def _baseline() -> tuple[dict[str, list[float]], int, int]:
    with open(BASELINE, encoding="utf-8") as f:
        lines = f.read().splitlines()
    header = [line for line in lines if line.startswith("#")]
    counts = re.search(r"trials = (\d+), rhs_calls = (\d+)", " ".join(header))
    rows = list(csv.reader(line for line in lines if not line.startswith("#")))
    names = rows[0]
    columns = {n: [float(r[j]) for r in rows[1:]] for j, n in enumerate(names)}
    return columns, int(counts.group(1)), int(counts.group(2))


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory) -> str:
    """PRSM2 as the sweep finds it: taken from the session's shared build (tests/test_fmu.py)."""
    shared = built_fmus()["PRSM2"].parent
    path = ensure_fmus([2], str(tmp_path_factory.mktemp("fmu")), fmu_dir=str(shared),
                       build=False)[2]
    assert Path(path).parent == shared
    return path


def test_runner_reproduces_the_stored_start_up(fmu_path, monkeypatch):
    monkeypatch.delenv("PRSM_FMU_ENGINE", raising=False)       # the FMU's default: the engine
    want, trials, rhs_calls = _baseline()
    params = dataclasses.replace(presets.load("li2021_two_stage"), mu_screw_roller=0.05,
                                 mu_spline=0.1)
    profile, acc0 = speed_profile(100.0, 0.0)
    runner = FmuRunner(os.fspath(fmu_path), tolerance=1e-8)
    try:
        got = runner.run(params, "dynamic", profile.speed, acc0, 5000.0, 1e-4, 1e-6)
    finally:
        runner.close()
    assert (got["trials"], got["rhs_calls"]) == (trials, rhs_calls)
    compared = 0
    for name, column in want.items():
        values = [float(v) for v in got[name]]
        assert len(values) == len(column), name
        scale = max((abs(v) for v in column if math.isfinite(v)), default=0.0)
        for i, (g, w) in enumerate(zip(values, column)):
            if math.isnan(w):
                assert math.isnan(g), (name, i)
            else:
                assert abs(g - w) <= RTOL * scale, (name, i, g, w)
            compared += 1
    print(f"\n{len(want)} columns x {len(want['time'])} samples = {compared} values, "
          f"{trials} trials: as stored")
