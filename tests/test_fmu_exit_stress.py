"""Stress: the fmpy console script run 50 times under CPU load exits cleanly every time
(pythonfmu 0.7's exit-time use-after-free, prsm_fmu/fmu_exit.py).

Its own file (marked ``stress``): the longest test of the suite, so pytest-xdist can start it
first, on one worker, while the other runs the rest (tests/conftest.py).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import built_fmus  # noqa: E402


@pytest.fixture(scope="module")
def fmus() -> dict[str, Path]:
    return built_fmus()


@pytest.mark.stress
def test_fmpy_simulate_cli_50_runs_under_cpu_load_all_exit_cleanly(fmus, tmp_path):
    """The command that aborted with ``corrupted double-linked list`` (exit 134), run 50 times
    through fmpy's console script, 2 at a time next to a busy loop that loads a core.
    Whether pythonfmu's exit-time write into freed memory hits a heap list depended on the
    layout (hash seed, argv, what the run allocated): each run gets its own PYTHONHASHSEED.
    The busy loop runs at the lowest priority (nice 19): it loads a core the runs and the
    other tests leave idle, as before, but no longer takes a core from the suite's other
    worker (under pytest-xdist that worker's tests are load enough)."""
    import concurrent.futures
    import time

    script = Path(sys.executable).parent / "fmpy"
    args = [str(script), "simulate", str(fmus["PRSM2"]), "--stop-time", "0.01",
            "--start-values", "fidelity", "3", "screw_torque", "15", "load_force", "1000"]
    busy_loop = "import os\nos.nice(19)\nwhile True: pass"        # lowest priority: docstring
    burners = [subprocess.Popen([sys.executable, "-c", busy_loop])]

    def run(seed: int) -> tuple[int, int, str]:
        env = dict(os.environ, PYTHONHASHSEED=str(seed))
        proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300,
                              cwd=tmp_path)
        return seed, proc.returncode, proc.stderr[-300:]

    start = time.monotonic()
    try:
        with concurrent.futures.ThreadPoolExecutor(2) as pool:
            results = list(pool.map(run, range(50)))
    finally:
        for b in burners:
            b.kill()
            b.wait()
    bad = [r for r in results if r[1] != 0]
    print(f"fmpy simulate CLI runs under load: {len(results)}, failed: {len(bad)}, "
          f"{time.monotonic() - start:.0f} s")
    assert len(results) == 50 and bad == [], bad
