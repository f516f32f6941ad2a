"""The likely cause of a loop run that stopped: a communication step beyond the coupling's
stability limit.

When a co-simulation stops (a refused step, e.g. the drive's overcurrent trip), the first thing
to rule out is the coupling itself: beyond the largest stable communication step the loop's
explicit coupling amplifies every disturbance until a block refuses.  :func:`step_limit_hint`
compares the run's step with the limit :mod:`system_models.coupling_analysis` predicts for the
scene's coupling order, extrapolation and load spring (stiffness and damping), and names it when
the step is beyond.  The prediction is the linearised loop at the analysis's operating point
(docs/ema.md), so the hint says "likely", not "certain".
"""

from __future__ import annotations

import math

from .load import LoadParams
from .scenes import Scene

__all__ = ["step_limit_hint"]


def step_limit_hint(scene: Scene, step: float, order: str, extrapolation: int) -> str:
    """A sentence naming the predicted stability limit if ``step`` [s] is beyond it, else "".

    Parameters
    ----------
    scene : Scene
        The scene that ran (its load's stiffness and damping; direct topology only, the
        analysis does not model the geared actuator).
    step : float
        The communication step h of the run [s].
    order : {"jacobi", "gauss-seidel"}
        The master's coupling order of the run.
    extrapolation : int
        The input extrapolation order of the run, 0 or 1.
    """
    if scene.topology != "direct":
        return ""
    from .coupling_analysis import predicted_stable_step

    defaults = LoadParams()
    stiffness = float(scene.load.get("stiffness", defaults.stiffness))
    damping = float(scene.load.get("damping", defaults.damping))
    try:
        limit = predicted_stable_step(order, extrapolation, stiffness, damping)
    except ValueError:                  # the linear loop is unstable at any step: no hint
        return ""
    if not step > limit:
        return ""
    suggestion = _round_step(limit / 2.0, scene.t_end - scene.t0)
    return (f"likely cause: the communication step h = {step:g} s is beyond the coupling's "
            f"stability limit {limit:.3g} s that system_models/coupling_analysis.py predicts "
            f"for {order} coupling, extrapolation order {extrapolation} and a load of "
            f"{stiffness:g} N/m, {damping:g} N.s/m (docs/ema.md): run with a smaller --step"
            + (f", e.g. --step {suggestion:g}" if suggestion else ""))


def _round_step(h_max: float, span: float) -> float | None:
    """The largest step of the 1-2-5 series at most ``h_max`` [s] that divides ``span`` [s]
    into whole steps (to 1e-9 relative), or None within six decades."""
    decade = 10.0 ** math.floor(math.log10(h_max))
    for _ in range(6):
        for m in (5.0, 2.0, 1.0):
            h = m * decade
            n = round(span / h)
            if h <= h_max and n >= 1 and abs(n * h - span) <= 1e-9 * span:
                return h
        decade /= 10.0
    return None
