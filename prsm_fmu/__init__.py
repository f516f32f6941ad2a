"""prsm-fmu: dynamics of multi-stage planetary roller screw mechanisms at several fidelity levels.

Entry points (docs/architecture.md §3)::

    from prsm_fmu import presets, simulate, steady_state
    p = presets.load("li2021_two_stage")
    ss = steady_state(p, screw_speed=100.0, load_force=5000.0)
    res = simulate(p, fidelity="dynamic", drive="speed", screw_speed=100.0, load_force=5000.0,
                   t_end=1e-3, output_interval=1e-6)

The physics never imports FMI or fmpy.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

__all__ = ["presets", "simulate", "steady_state", "make_model", "FIDELITIES", "MechanismParams",
           "StageParams"]
__version__ = "0.1.0.dev0"

#: public name -> (module, attribute); imported on first use (PEP 562), so that a command that
#: needs none of the physics (``prsm-ema list``, argument parsing) does not pay for numpy, scipy
#: and every model at start-up
_LAZY = {"presets": (".presets", None), "simulate": (".simulate", "simulate"),
         "steady_state": (".steady_state", "steady_state"), "make_model": (".models", "make_model"),
         "FIDELITIES": (".models", "FIDELITIES"), "MechanismParams": (".params", "MechanismParams"),
         "StageParams": (".params", "StageParams")}


def __getattr__(name: str) -> Any:
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    mod = importlib.import_module(module, __name__)
    value = mod if attr is None else getattr(mod, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """``prsm_fmu.simulate`` and ``prsm_fmu.steady_state`` are functions named as their
    modules: importing the module ``prsm_fmu.simulate`` (from anywhere) makes the import system
    set the package's attribute to the module; this keeps the function there instead, as the
    eager ``from .simulate import simulate`` did."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _LAZY.get(name, (None, None))[1] == name:
            value = getattr(value, name)
        super().__setattr__(name, value)

    def __reduce__(self):
        # pickled by name, as (cloud)pickle does a plain module (e.g. Dask returning it)
        return importlib.import_module, (self.__name__,)


sys.modules[__name__].__class__ = _Package
