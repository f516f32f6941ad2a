"""C compiled with gcc on first use and cached: the one build-and-cache step of every compiled
part (the engine, the sweep's step loop, the EMA loop, the CSV formatter; gcc alone for the
FMU status wrapper where Zig is missing).

Light on purpose (the standard library only, :mod:`subprocess` imported when gcc runs): a
caller that only loads a library already built (e.g. :mod:`prsm_fmu.csv_compiled` when a result
is written) pays no import of the FMU build tools: ~5 ms of CPU to import this module (most of
it :mod:`hashlib`), against 60–80 ms for :mod:`fmu_build.native` in the same process
(after ``system_models.output``'s imports; ~0.2 s after numpy's alone).  :mod:`fmu_build`
re-exports what is here (``fmu_build.native.cached_library``,
``fmu_build.platforms.COMPILE_FLAGS``, ``fmu_build.errors.BuildError``).
"""

from __future__ import annotations

import getpass
import hashlib
import os
import tempfile
from pathlib import Path

__all__ = ["BuildError", "COMPILE_FLAGS", "compile_library", "cached_library", "user_cache_dir"]

#: flags of every target (no fused multiply-add, no fast-math: the Python model's rounding)
COMPILE_FLAGS = ("-std=c99", "-O2", "-fPIC", "-shared", "-ffp-contract=off")


class BuildError(RuntimeError):
    """A C library or an FMU could not be built (gcc missing or failing, an FMU whose
    modelDescription is not valid)."""


def user_cache_dir(kind: str) -> Path:
    """``<system's temporary directory>/prsm-fmu-<kind>-<user>``: a cache of this user's
    (the compiled libraries: ``native``; the unpacked FMUs, :mod:`system_models.fmu_cache`:
    ``unpacked``), created by its user with mode 0700 so that no other user can put a file
    there; not created here."""
    return Path(tempfile.gettempdir()) / f"prsm-fmu-{kind}-{getpass.getuser()}"


def compile_library(src: Path, out: Path, sources: tuple[str, ...],
                    defines: tuple[str, ...] = (), link: tuple[str, ...] = ()) -> None:
    """Compile ``sources`` in ``src`` into the shared library ``out`` with gcc
    (:data:`COMPILE_FLAGS`), with the ``-D`` ``defines`` and the extra linker arguments
    ``link``.

    Raises
    ------
    BuildError
        When gcc is missing or fails.
    """
    import shutil
    import subprocess      # here, not above: loading a library already built needs neither

    gcc = shutil.which("gcc")
    if gcc is None:
        raise BuildError("gcc is needed to build the compiled parts' Linux libraries "
                         "(apt-get install gcc)")
    cmd = [gcc, *COMPILE_FLAGS, "-Wall", f"-I{src}", *(f"-D{d}" for d in defines),
           *(str(src / s) for s in sources), "-o", str(out), *link, "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError(f"gcc failed:\n{proc.stderr}")


def cached_library(prefix: str, files: dict[str, bytes], sources: tuple[str, ...]) -> Path:
    """A shared library compiled from ``files`` (name → contents; ``sources`` are the ones
    compiled, the others are headers), built once and kept under the hash of every file.

    The cache is a directory of the user's own (mode 0700) in the system's temporary
    directory, so no other user can put a library there; the library is moved in whole, so
    a concurrent build finds it complete.

    Raises
    ------
    BuildError
        When gcc is missing or fails.
    """
    digest = hashlib.sha256(b"".join(name.encode() + b"\0" + data + b"\0"
                                     for name, data in sorted(files.items()))).hexdigest()[:20]
    cache = user_cache_dir("native")
    lib = cache / f"{prefix}_{digest}.so"
    if not lib.exists():
        cache.mkdir(mode=0o700, parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix=f"{prefix}_lib_", dir=cache) as tmp:
            src = Path(tmp)
            for name, data in files.items():
                (src / name).write_bytes(data)
            out = src / lib.name
            compile_library(src, out, sources)
            os.replace(out, lib)
    return lib
