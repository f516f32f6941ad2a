"""Stepper options tuned for the PRSM models, shared by :func:`prsm_fmu.simulate`, the FMU and
the ``auto`` level's own stepper (which sit above this module and below nothing of it)."""

from __future__ import annotations

__all__ = ["TUNED_OPTIONS", "TOLERANCE_FACTOR", "tuned_stepper_options"]

#: options that make an adaptive stepper cheapest at equal accuracy on this model
#: (benchmarks/step_cost.py: Jacobian reuse within a step while h·‖J‖·|Δx|/|x| ≤ 0.1, and a first
#: internal step of at most 8/‖J‖ after an input change)
TUNED_OPTIONS = {"rosenbrock": {"jacobian_reuse": 0.1, "first_step_stiffness": 8.0}}

#: factor on the tolerances a stepper is given (simulate's rtol, the FMU's tolerance), so that
#: the tolerance bounds the *global* error of a run (docs/accuracy.md §1's measure), not only
#: each internal step's estimate.  The exponential stepper's estimate is its embedded order-2
#: solution's: at a tenth of the tolerance its error equals ROS34PW2's at the full one
#: (benchmarks/step_cost.py: 8.7e-9 against 8.6e-9 on the "moving" scenario at tolerance 1e-6).
#: Dormand-Prince 5(4) at the full tolerance, its steps landing on the friction law's kinks,
#: still missed it in the loop scenes' transients, where the local errors of successive steps
#: add up (speed reversal: 2.9e-5 at 1e-5); at a fifth every work-precision point meets it.
#: ROS34PW2 runs at the full tolerance: its error norm includes the sliding velocities'
#: (control.slip_error), whose errors are what the forces follow; at a fifth without that norm
#: it missed at 1e-7 on the load step and the sine tracking (2.04, 2.14), with it at the full
#: tolerance every point of the loop scenes and the start-up meets it (docs/accuracy.md, "The
#: slip error norm")
TOLERANCE_FACTOR = {"exponential": 0.1, "rosenbrock": 1.0, "explicit_adaptive": 0.2}


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
