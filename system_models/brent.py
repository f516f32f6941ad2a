"""scipy's Brent root finder without the import of all of scipy.optimize.

:func:`scipy.optimize.brentq` checks its tolerances, wraps the function so that a NaN value
raises, and calls scipy's compiled routine ``scipy.optimize._zeros._brentq``.  Importing it
imports the whole of ``scipy.optimize`` first (linalg, sparse, special, fft...: ~0.6 s of CPU,
half of ``prsm-fmu regress``, whose steady starts need one root each).  :func:`brentq` loads
that compiled module alone (~1 ms) and calls it as scipy does, so the roots are
:func:`scipy.optimize.brentq`'s bit for bit (tests/test_brent.py compares them); where the
module cannot be loaded so (another scipy layout), it calls :func:`scipy.optimize.brentq`.
"""

from __future__ import annotations

import math
import sys
from typing import Any, Callable

__all__ = ["brentq"]

#: scipy's smallest allowed ``rtol`` (4 · machine epsilon)
_RTOL_MIN = 4.0 * 2.220446049250313e-16
#: the compiled module once loaded; False once loading it failed
_zeros: Any = None


def _compiled() -> Any:
    """scipy's compiled ``_zeros`` module (loaded by itself unless scipy.optimize already
    imported it), or None where it cannot be loaded so."""
    global _zeros
    if _zeros is None:
        name = "scipy.optimize._zeros"
        try:
            if name in sys.modules:
                module = sys.modules[name]
            else:
                import importlib.machinery
                import importlib.util
                from pathlib import Path

                scipy = importlib.util.find_spec("scipy")    # the package, not its __init__
                where = Path(next(iter(scipy.submodule_search_locations))) / "optimize"
                path = next(where / f"_zeros{s}" for s in importlib.machinery.EXTENSION_SUFFIXES
                            if (where / f"_zeros{s}").is_file())
                loader = importlib.machinery.ExtensionFileLoader(name, str(path))
                spec = importlib.util.spec_from_file_location(name, path, loader=loader)
                module = importlib.util.module_from_spec(spec)
                loader.exec_module(module)
                # not left registered as a module of a package that was not imported: an
                # import of scipy.optimize later loads its own, as it would have
                sys.modules.pop(name, None)
            _zeros = module if callable(getattr(module, "_brentq", None)) else False
        except (ImportError, OSError, StopIteration, TypeError, AttributeError):
            _zeros = False
    return _zeros or None


def brentq(f: Callable[[float], float], a: float, b: float, xtol: float = 2e-12,
           rtol: float = _RTOL_MIN, maxiter: int = 100) -> float:
    """A root of ``f`` in [``a``, ``b``] (``f(a)`` and ``f(b)`` of opposite signs):
    :func:`scipy.optimize.brentq` with the same arguments, the same root.

    Raises
    ------
    ValueError
        As :func:`scipy.optimize.brentq`: ``f(a)``, ``f(b)`` of one sign, a tolerance out of
        range, or a NaN value of ``f`` (naming ``x``).
    RuntimeError
        If it does not converge in ``maxiter`` iterations.
    """
    zeros = _compiled()
    if zeros is None or not (xtol > 0.0 and rtol >= _RTOL_MIN and maxiter >= 0):
        from scipy.optimize import brentq as scipy_brentq     # its own checks and messages

        return scipy_brentq(f, a, b, xtol=xtol, rtol=rtol, maxiter=maxiter)

    def checked(x: float) -> float:
        fx = f(x)
        if math.isnan(fx):
            raise ValueError(f"The function value at x={x} is NaN; solver cannot continue.")
        return fx

    return zeros._brentq(checked, a, b, xtol, rtol, maxiter, (), False, True)
