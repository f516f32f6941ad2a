"""The optional extras of the package and the one line that names the one to install.

``pip install -e .`` installs the models and the ``prsm-fmu startup``/``steady``/``check``
commands; building and running FMUs needs the ``fmu`` extra (pythonfmu, fmpy) and Dask sweeps
the ``sweep`` extra (dask[distributed]).  A command that needs a missing extra says so in one
line naming the extra (:func:`require` up front, :func:`missing_extra_message` for an import
that fails deeper down), never with a traceback.
"""

from __future__ import annotations

import importlib

__all__ = ["EXTRA_OF", "MissingExtra", "require", "missing_extra_message"]

#: top-level module -> the extra of pyproject.toml that installs it
EXTRA_OF = {"pythonfmu": "fmu", "fmpy": "fmu", "dask": "sweep", "distributed": "sweep"}


def _install_line(module: str, extra: str, purpose: str) -> str:
    return (f"{purpose} needs {module}, which is not installed: install the {extra!r} extra, "
            f"pip install -e \".[{extra}]\" (or pip install \"prsm-fmu[{extra}]\")")


class MissingExtra(ImportError):
    """A module of an optional extra is not installed; the message names the extra."""

    def __init__(self, module: str, purpose: str) -> None:
        self.module = module
        self.extra = EXTRA_OF[module.partition(".")[0]]
        super().__init__(_install_line(module, self.extra, purpose), name=module)


def require(*modules: str, purpose: str) -> None:
    """Import ``modules`` (each of :data:`EXTRA_OF`, possibly dotted) or raise MissingExtra.

    Parameters
    ----------
    *modules : str
        Module names, e.g. ``"fmpy"``, ``"dask.distributed"``.
    purpose : str
        What needs them, the start of the message (e.g. ``"building an FMU"``).

    Raises
    ------
    MissingExtra
        For the first module that cannot be imported.
    """
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            raise MissingExtra(module, purpose) from None


def missing_extra_message(exc: BaseException, purpose: str = "this command") -> str | None:
    """The one line for an import error of an extra's module, or None for any other error.

    Parameters
    ----------
    exc : BaseException
        The error caught.
    purpose : str
        What needed the module (used when ``exc`` does not say it already).
    """
    if isinstance(exc, MissingExtra):
        return str(exc)
    if isinstance(exc, ImportError) and exc.name:
        top = exc.name.partition(".")[0]
        if top in EXTRA_OF:
            return _install_line(exc.name, EXTRA_OF[top], purpose)
    return None
