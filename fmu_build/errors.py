"""The build's one error type, in a module of its own so that the light parts of the build
(the platform table, the binary checks, the command line) import it without pythonfmu; defined
with the gcc build-and-cache step (:mod:`prsm_fmu.compiled`), which raises it too."""

from __future__ import annotations

from prsm_fmu.compiled import BuildError

__all__ = ["BuildError"]
