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

from . import presets
from .models import FIDELITIES, make_model
from .params import MechanismParams, StageParams
from .simulate import simulate
from .steady_state import steady_state

__all__ = ["presets", "simulate", "steady_state", "make_model", "FIDELITIES", "MechanismParams",
           "StageParams"]
__version__ = "0.1.0.dev0"
