"""Test-session plumbing: FMU builds shared by pytest-xdist's workers, the longest tests first.

* :func:`shared_build`: a build (an FMU, a set of FMUs) made once per test session and shared
  by every worker process: the first worker to ask builds it under a file lock, the others wait
  and reuse it.  The session's directory is made by the controlling process and removed at its
  end; without xdist it is the same, with a single process.
* The test files in :data:`FIRST` (tests that need a process without other threads) are run
  first, then those in :data:`LONGEST_FIRST` (the costliest, heaviest first), then any other
  file with a test marked ``stress`` (long by design: many runs, many steps), then the rest in
  collection order: with ``--dist loadfile`` each worker takes the next file when it is
  nearly done with one, so that the short files at the end fill in and both workers finish together
  instead of one running a long file alone at the end.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable

import pytest

_ENV = "PRSM_FMU_TEST_SHARED"


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):          # an xdist worker: the controller made it
        return
    os.environ[_ENV] = tempfile.mkdtemp(prefix="prsm_fmu_tests_")


def pytest_unconfigure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):
        return
    shared = os.environ.pop(_ENV, None)
    if shared:
        shutil.rmtree(shared, ignore_errors=True)


#: test files whose tests need a worker process in which no other Python thread runs (the
#: figure drawer forks only then, system_models.figure_process.available(), and these tests
#: skip otherwise): first, so each runs in a fresh process, before any file that leaves a
#: thread behind (test_sweep.py: the Dask client leaves distributed's offload thread)
FIRST = ("test_plot_layout.py",)

#: the test files that cost most, heaviest first: CPU seconds (the worker's and its child
#: processes') of one run of the whole suite on two workers (docs/testing.md, "Profile of
#: the order and the shared builds"):
#: exit stress 38, co-simulation stability 19, sweep 19, command endings 18, engine 17,
#: actuator loop 13, regression 13, bad inputs 12.5, FMU 11.5, FMU hosts 10, kink landing 8,
#: showcase 7, platform binaries 6, dynamics 6; every other file 6 or less (plot layout, 9,
#: is in FIRST); measured alone (one process, its FMU builds included): the sweep master's
#: compiled loop 12, the native FMU's state restore 8.5.  The co-simulation file follows
#: the stress test: it builds no FMU, so
#: neither worker waits at the start for the FMU build the stress test begins with.
LONGEST_FIRST = (
    "test_fmu_exit_stress.py", "test_cosim_stability.py", "test_sweep.py",
    "test_command_endings.py", "test_engine.py", "test_system_ema.py", "test_regress.py",
    "test_bad_inputs.py", "test_fmu_track.py", "test_fmu.py", "test_fmu_hosts.py",
    "test_native_state_restore.py", "test_kink_landing.py",
    "test_showcase_and_units.py", "test_platform_binaries.py", "test_dynamics.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    stress_files = {item.path.name for item in items if item.get_closest_marker("stress")}
    rank = {name: i for i, name in enumerate(FIRST + LONGEST_FIRST)}

    def file_rank(item: pytest.Item) -> int:
        name = item.path.name
        if name in rank:
            return rank[name]
        return len(rank) if name in stress_files else len(rank) + 1

    items.sort(key=file_rank)              # stable: a file's tests keep their order


def shared_build(name: str, build: Callable[[Path], None]) -> Path:
    """The directory ``build(dir)`` filled once per test session, shared by the worker
    processes (a file lock serialises the first build; a marker file says it completed)."""
    base = os.environ.get(_ENV)
    if not base:                                 # not under this conftest's session
        dest = Path(tempfile.mkdtemp(prefix=f"{name}_"))
        build(dest)
        return dest
    try:
        import fcntl
    except ImportError:                          # no flock (Windows): one build per process
        dest = Path(tempfile.mkdtemp(prefix=f"{name}_", dir=base))
        build(dest)
        return dest
    dest = Path(base) / name
    done = dest / ".complete"
    with open(Path(base) / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not done.exists():
                shutil.rmtree(dest, ignore_errors=True)     # a build that failed half-way
                dest.mkdir()
                build(dest)
                done.touch()
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    return dest
