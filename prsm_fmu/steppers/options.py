"""Stepper options tuned for the PRSM models, shared by :func:`prsm_fmu.simulate`, the FMU and
the ``auto`` level's own stepper (which sit above this module and below nothing of it)."""

from __future__ import annotations

__all__ = ["TUNED_OPTIONS", "TOLERANCE_FACTOR", "tuned_stepper_options"]

#: options that make an adaptive stepper cheapest at equal accuracy on this model
#: (benchmarks/step_cost.py: Jacobian reuse within a step while h·‖J‖·|Δx|/|x| ≤ 0.1, and a first
#: internal step of at most 8/‖J‖ after an input change)
TUNED_OPTIONS = {"rosenbrock": {"jacobian_reuse": 0.1, "first_step_stiffness": 8.0}}

#: factor on the tolerances a stepper is given (simulate's rtol, the FMU's tolerance): the
#: exponential stepper's estimate is its embedded order-2 solution's, and ROS34PW2 with the
#: first-step bound above delivers errors ~100x below its rtol; at a tenth of the tolerance the
#: exponential stepper's error equals ROS34PW2's at the full one (benchmarks/step_cost.py:
#: 8.7e-9 against 8.6e-9 on the "moving" scenario at tolerance 1e-6), so a given tolerance
#: means the same accuracy whichever of the two runs
TOLERANCE_FACTOR = {"exponential": 0.1}


def tuned_stepper_options(name: str, rtol: float, atol: float) -> dict:
    """Options of stepper ``name`` at the given tolerances, as simulate and the FMU use them.

    Parameters
    ----------
    name : str
        Stepper name (see :func:`prsm_fmu.steppers.make_stepper`).
    rtol, atol : float
        Relative [-] and absolute [state units] tolerances (ignored by ``rk4``; scaled by
        :data:`TOLERANCE_FACTOR` for the steppers listed there).

    Returns
    -------
    dict
        Keyword arguments for :func:`~prsm_fmu.steppers.make_stepper`.
    """
    if name == "rk4":
        return {}
    k = TOLERANCE_FACTOR.get(name, 1.0)
    return {"rtol": rtol * k, "atol": atol * k, **TUNED_OPTIONS.get(name, {})}
