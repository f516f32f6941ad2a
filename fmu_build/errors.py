"""The build's one error type, in a module of its own so that the light parts of the build
(the platform table, the binary checks, the command line) import it without pythonfmu."""

from __future__ import annotations

__all__ = ["BuildError"]


class BuildError(RuntimeError):
    """The FMU could not be built or its modelDescription is not valid."""
