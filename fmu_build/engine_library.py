"""The engine library for another platform: the C model of a mechanism as a shared library.

:func:`build_engine_library` compiles ``prsm_model.c``, ``prsm_ros.c`` and the flat interface
``prsm_api.c`` (the one :mod:`fmu_build.native_stepper` calls through ctypes), with the
mechanism's ``prsm_constants.h`` (:func:`fmu_build.native.constants_header`), for one platform
of :mod:`fmu_build.platforms` with Zig's C compiler, and reads the library back: it must export
every ``prsm_api_*`` function ``prsm_api.c`` defines and load nothing but the platform's C
runtime (linux64: glibc ≤ 2.17).  A pythonfmu FMU that calls the engine packs one such library
per platform pythonfmu ships a wrapper for (:data:`fmu_build.platforms.PYTHONFMU_PLATFORMS`:
linux64 and win64 with pythonfmu 0.7).
"""

from __future__ import annotations

import re
import shutil
import tempfile
from pathlib import Path

from prsm_fmu.engine import LIBRARY_STEM
from prsm_fmu.params import MechanismParams

from . import native, platforms
from .builder import BuildError
from .native_stepper import LIB_SOURCES, library_sources

__all__ = ["build_engine_library", "engine_exports", "engine_library_name"]

_DEFINITION = re.compile(r"^(?!static\b)[A-Za-z_][\w \t\*]*?\b(prsm_api_\w+)\s*\(", re.M)


def engine_exports() -> tuple[str, ...]:
    """The functions ``prsm_api.c`` defines (not ``static``): what the library must export."""
    text = (native.SOURCE_DIR / "prsm_api.c").read_text(encoding="utf-8")
    return tuple(dict.fromkeys(_DEFINITION.findall(text)))


def engine_library_name(platform: str) -> str:
    """The library's file name on ``platform``: ``prsm_engine.so``, ``.dll`` or ``.dylib``."""
    if platform not in platforms.PLATFORMS:
        raise BuildError(f"platform {platform!r} is not allowed: must be one of "
                         f"{', '.join(platforms.PLATFORMS)}")
    return LIBRARY_STEM + platforms.PLATFORMS[platform].suffix


def build_engine_library(params: MechanismParams, platform: str, dest: str | Path) -> Path:
    """Build the engine library of ``params``' geometry for ``platform`` into ``dest``.

    Parameters
    ----------
    params : MechanismParams
        The mechanism: its contact geometry is built into the library.
    platform : str
        A platform of :data:`fmu_build.platforms.PLATFORMS` (FMI 2.0 folder name: ``linux64``,
        ``win64``, ``darwin64``).
    dest : str or Path
        Directory the library is written to (created), e.g. a pythonfmu FMU's
        ``resources/<platform>``.

    Returns
    -------
    Path
        ``<dest>/prsm_engine<suffix>`` (:func:`engine_library_name`), checked.

    Raises
    ------
    BuildError
        For an unknown platform, ziglang missing, a compiler error, or a library that does
        not export every ``prsm_api_*`` function or loads more than the platform's C runtime.
    """
    out = Path(dest) / engine_library_name(platform)
    params = params.validate()
    with tempfile.TemporaryDirectory(prefix="prsm_engine_") as tmp:
        src = Path(tmp)
        for f, data in library_sources(params).items():
            (src / f).write_bytes(data)
        platforms.compile_for(platform, src, LIB_SOURCES, src / out.name, engine_exports())
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(src / out.name), out)
    return out
