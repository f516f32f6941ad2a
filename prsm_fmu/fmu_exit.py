"""Work-around for pythonfmu 0.7's native wrapper at process exit on Linux.

Root cause of the intermittent ``corrupted double-linked list`` abort (exit status 134) of
``fmpy simulate PRSM2.fmu ...`` and of crashes of C hosts after ``fmi2FreeInstance``:
pythonfmu's binary keeps its interpreter bookkeeping in a static ``std::shared_ptr<PyState>``
and resets it in ``finalizePythonInterpreter()``, which its ELF destructor
(``__attribute__((destructor)) onLibraryUnload``) calls.  The library is never unloaded before
exit (its ``std::regex`` code has ``STB_GNU_UNIQUE`` symbols, which make glibc ignore
``dlclose``), so at ``exit()`` glibc first runs the ``__cxa_atexit`` destructor of that
``shared_ptr`` (freeing its 128-byte control block) and only then the ELF destructor, whose
``pyState = nullptr`` decrements the use count inside the freed block.  Valgrind shows it as an
"invalid read of size 4 in finalizePythonInterpreter, 8 bytes inside a block of size 128
free'd in __run_exit_handlers".  What the write hits depends on the heap's layout (which
glibc bin holds the freed block: a tcache entry's key, or a small-bin's back pointer), so the
same command aborts for some hash seeds and argv lengths and not for others; CPU load only
shuffles the layout.

The fix, without rebuilding pythonfmu: call the library's exported
``finalizePythonInterpreter()`` once from an :mod:`atexit` handler, i.e. while the
``shared_ptr`` is still alive.  In a Python host (fmpy) the handler runs in ``Py_FinalizeEx``,
before ``exit()``: it resets the pointer (joining pythonfmu's helper thread, which has already
ended there), and the two exit-time destructors that follow find a null pointer and touch no
heap memory.  In a non-Python host, Python's atexit handlers run only when pythonfmu finalizes
its interpreter, from inside the first of those destructors; the handler then nulls the
pointer while its block is still being released, so the second destructor finds it null (not
tested: the C host of the tests leaves with ``_Exit(0)``; docs/fmu.md, "Non-Python hosts").
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
from pathlib import Path

__all__ = ["guard_library", "guarded", "PYTHONFMU_LIBRARY_STEM"]

#: pythonfmu's library in an FMU whose binary is the status wrapper (fmu_build.status_wrapper):
#: ``binaries/linux64/pythonfmu-export.so``, beside the wrapper ``<modelIdentifier>.so``
PYTHONFMU_LIBRARY_STEM = "pythonfmu-export"

_LIBRARIES: dict[str, ctypes.CDLL] = {}
_REGISTERED = False


def _finalize_all() -> None:
    for lib in list(_LIBRARIES.values()):
        try:
            lib.finalizePythonInterpreter()
        except Exception:  # noqa: BLE001 - nothing more to do at exit
            pass


def guard_library(resources: str | None, model_identifier: str) -> str | None:
    """Make the exit of this process safe for the FMU library whose resources are ``resources``.

    Parameters
    ----------
    resources : str or None
        The instance's resource directory (pythonfmu's ``resources`` argument); pythonfmu's
        library is ``../binaries/linux64/pythonfmu-export.so`` from there where the FMU's binary
        is the status wrapper, else ``../binaries/linux64/<model_identifier>.so``.
    model_identifier : str
        The FMU's modelIdentifier (the slave class's name).

    Returns
    -------
    str or None
        The library's path if it is now guarded (Linux, the library loaded, the symbol there);
        None otherwise (nothing to do: another platform, or a library this cannot find).
    """
    global _REGISTERED
    if not sys.platform.startswith("linux") or not resources:
        return None
    folder = Path(resources).parent / "binaries" / "linux64"
    for stem in (PYTHONFMU_LIBRARY_STEM, model_identifier):
        key = str(folder / f"{stem}.so")
        if key in _LIBRARIES:
            return key
        try:   # RTLD_NOLOAD: the library the host has loaded from there, never a new copy
            lib = ctypes.CDLL(key, mode=os.RTLD_NOW | os.RTLD_NOLOAD)
            lib.finalizePythonInterpreter.restype = None
            break
        except (OSError, AttributeError):
            continue
    else:
        return None
    _LIBRARIES[key] = lib
    if not _REGISTERED:
        atexit.register(_finalize_all)
        _REGISTERED = True
    return key


def guarded() -> tuple[str, ...]:
    """Paths of the libraries :func:`guard_library` has guarded in this process."""
    return tuple(_LIBRARIES)
