"""Build the PRSM co-simulation FMUs (``dist/PRSM<n>.fmu``) with pythonfmu.

``python -m fmu_build`` (console script ``prsm-fmu-build``) builds ``dist/PRSM2.fmu``;
``python -m fmu_build PRSM1 PRSM3`` or ``--all`` builds the others, ``--preset NAME --name X``
builds an FMU from any preset of :mod:`prsm_fmu.presets`.  See docs/fmu.md.

Modules: :mod:`.mechanisms` (which parameters each FMU starts from), :mod:`.builder`
(generate the slave module, run pythonfmu, complete and validate), :mod:`.packing` (what the
FMU carries: the runtime modules, the compiled engine, the start values) and
:mod:`.model_description` (what pythonfmu leaves out of modelDescription.xml).
"""

from __future__ import annotations

import importlib

from .mechanisms import FMUS, three_stage

#: name -> submodule, imported on first use (PEP 562): the builder imports pythonfmu, so that
#: ``import fmu_build`` (and ``prsm-fmu-build --help``) works without the ``fmu`` extra and a
#: build without it is refused in one line (:mod:`prsm_fmu.extras`)
_LAZY = {"DEFAULT_EXPERIMENT": ".builder", "BuildError": ".errors", "build_fmu": ".builder",
         "validate": ".builder", "build_native": ".native"}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["build_fmu", "build_native", "build_named", "validate", "BuildError", "FMUS",
           "three_stage", "DEFAULT_EXPERIMENT"]


def build_named(name: str, dest="dist", check: bool = True, start: dict | None = None,
                native: bool = False, engine: bool = True,
                targets: tuple[str, ...] | None = None,
                engine_platforms: tuple[str, ...] | None = None):
    """Build one of the standard FMUs (``PRSM1``, ``PRSM2``, ``PRSM3``) into ``dest``
    (``start``: parameter start values other than the preset's, see ``builder.start_values``).

    ``native``: the native C FMU ``<name>-native.fmu`` (kinematic, quasi-static and dynamic
    levels and auto, :mod:`fmu_build.native`) instead of the Python one; ``targets``: its platforms
    (default: all of :data:`fmu_build.platforms.FMI2_PLATFORMS`).  ``engine``: the Python FMU
    packs the compiled engine (:mod:`fmu_build.packing`; for this platform and
    ``engine_platforms``); False: the Python model only.

    Returns
    -------
    pathlib.Path
        The FMU file.
    """
    try:
        make, source = FMUS[name]
    except KeyError:
        raise ValueError(f"unknown FMU {name!r}: must be one of {', '.join(FMUS)} "
                         "(or use --preset)") from None
    if native:
        from .native import build_native
        if targets is None:
            return build_native(name, make(), source, dest, check, start)
        return build_native(name, make(), source, dest, check, start, targets)
    from .builder import build_fmu
    return build_fmu(name, make(), source, dest, check, start, engine=engine,
                     engine_platforms=engine_platforms)
