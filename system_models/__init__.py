"""The electromechanical actuator around the PRSM FMU: motor, controller, load, co-simulation master.

Modules (docs/ema.md):

* :mod:`.blocks` — the small block interface every part implements (FMU or plain Python);
* :mod:`.fmu` — any FMI 2.0 co-simulation FMU as a block through fmpy's ``FMU2Slave``, and
  :func:`~system_models.fmu.ensure_fmu` (builds ``dist/PRSM2.fmu`` in a child process);
* :mod:`.prsm` — the PRSM block: the FMU, or the same mechanism as a plain Python model;
* :mod:`.motor`, :mod:`.controller`, :mod:`.load` — PMSM in dq, cascaded digital controller,
  spring/damper/external-force load, with their parameters and reasons;
* :mod:`.master` — fixed-step Jacobi / Gauss–Seidel master with input extrapolation and
  roll-back/retry;
* :mod:`.ema` — a scene turned into blocks and connections; :mod:`.run` — run and check a scene;
* :mod:`.scenes`, :mod:`.signals` — scenes as TOML data, time profiles;
* :mod:`.analysis`, :mod:`.output`, :mod:`.progress`, :mod:`.cli` — checks and power
  bookkeeping, CSV and plots, progress bar, the ``prsm-ema`` command;
* the ``geared`` topology (:mod:`.geared`, docs/ema.md §10): :mod:`.gear` (losses, backlash,
  compliance), :mod:`.current_motor` (current source behind a bus delay),
  :mod:`.continuous_controller` with :mod:`.filters`, :mod:`.slew` and :mod:`.noise`,
  :mod:`.contact` (gap contact, end stops), :mod:`.plots_geared`;
* :mod:`.scene_check` — a scene checked whole before anything runs.

The physics of the mechanism stays in :mod:`prsm_fmu`; nothing here imports pythonfmu.
"""

import importlib
from typing import Any

__all__ = ["Master", "RetryPolicy", "Result", "CoSimulationError", "run_scene", "SceneRun",
           "load_scene", "list_scenes"]

#: public name -> its module; imported on first use (PEP 562): ``prsm-ema list`` and argument
#: parsing need neither numpy nor the physics
_LAZY = {"Master": ".master", "RetryPolicy": ".master", "Result": ".master",
         "CoSimulationError": ".master", "run_scene": ".run", "SceneRun": ".run",
         "load_scene": ".scenes", "list_scenes": ".scenes"}


def __getattr__(name: str) -> Any:
    try:
        module = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
