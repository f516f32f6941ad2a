"""Stepper options tuned for the PRSM models, shared by :func:`prsm_fmu.simulate`, the FMU and
the ``auto`` level's own stepper (which sit above this module and below nothing of it)."""

from __future__ import annotations

__all__ = ["TUNED_OPTIONS", "tuned_stepper_options"]

#: options that make an adaptive stepper cheapest at equal accuracy on this model
#: (benchmarks/step_cost.py: Jacobian reuse within a step while h·‖J‖·|Δx|/|x| ≤ 0.1, and a first
#: internal step of at most 8/‖J‖ after an input change)
TUNED_OPTIONS = {"rosenbrock": {"jacobian_reuse": 0.1, "first_step_stiffness": 8.0}}


def tuned_stepper_options(name: str, rtol: float, atol: float) -> dict:
    """Options of stepper ``name`` at the given tolerances, as simulate and the FMU use them.

    Parameters
    ----------
    name : str
        Stepper name (see :func:`prsm_fmu.steppers.make_stepper`).
    rtol, atol : float
        Relative [-] and absolute [state units] tolerances (ignored by ``rk4``).

    Returns
    -------
    dict
        Keyword arguments for :func:`~prsm_fmu.steppers.make_stepper`.
    """
    if name == "rk4":
        return {}
    return {"rtol": rtol, "atol": atol, **TUNED_OPTIONS.get(name, {})}
