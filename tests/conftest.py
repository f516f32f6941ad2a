"""Test-session plumbing: FMU builds shared by pytest-xdist's workers, the longest tests first.

* :func:`shared_build`: a build (an FMU, a set of FMUs) made once per test session and shared
  by every worker process: the first worker to ask builds it under a file lock, the others wait
  and reuse it.  The session's directory is made by the controlling process and removed at its
  end; without xdist it is the same, with a single process.
* Tests marked ``stress`` (long by design: many runs, many steps) are run first, so that with
  ``--dist loadfile`` the worker that takes them is not left running them alone at the end.
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


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=lambda item: 0 if item.get_closest_marker("stress") else 1)   # stable


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
