"""Exact step where the model offers one; in the friction band an exponential Rosenbrock step."""

from __future__ import annotations

from typing import Any

from .base import Stepper, StepStats, _is_finite_sum
from .explicit import ExplicitAdaptive
from .band import ScalarExponential

__all__ = ["ClosedForm", "ClosedFormExplicit", "BAND_METHODS"]

#: how :class:`ClosedForm` steps where the closed form declines: ``exponential`` (default,
#: :class:`ScalarExponential`) or ``explicit`` (:class:`ExplicitAdaptive`, Dormand-Prince 5(4);
#: the former path, kept for the benchmarks' comparison and as the native C FMU's method)
BAND_METHODS = ("exponential", "explicit")


class ClosedForm(Stepper):
    """Exact step where the model offers one, an exponential Rosenbrock step elsewhere.

    For models with ``closed_form_advance(t, x, u, h) -> list | None`` (the slaved-carrier
    levels: constant acceleration under held inputs outside the friction band).  Where it
    answers None (friction band, zero speed crossed, sign pattern left, viscous term), the step
    is integrated by :class:`ScalarExponential` (exprb32: exact for an affine rhs, three rhs
    calls per internal step, split at the band edges; :mod:`.band` says why), which
    returns to the closed form as soon as it answers for the rest of the step.  A closed-form
    step counts as one rhs call.

    Parameters
    ----------
    model : OdeModel
        Model with ``closed_form_advance``.
    band : {"exponential", "explicit"}
        Method where the closed form declines (:data:`BAND_METHODS`).
    **band_options
        Options of that method (``rtol``, ``atol``, ``max_substeps``, ``fixed_substeps`` ...).
    """

    name = "closed_form"

    def __init__(self, model: Any, band: str = "exponential", **band_options: Any) -> None:
        super().__init__(model)
        if not callable(getattr(model, "closed_form_advance", None)):
            raise ValueError(f"closed_form: model {type(model).__name__} has no closed_form_advance; "
                             "use it with the quasi-static or kinematic level")
        self._exact = model.closed_form_advance
        if band == "exponential":
            self.band: Stepper = ScalarExponential(model, exact=self._exact, **band_options)
        elif band == "explicit":
            self.band = ExplicitAdaptive(model, **band_options)
        else:
            raise ValueError(f"band = {band!r} is not allowed: must be one of {BAND_METHODS}")
        self.band_method = band

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        y = self._exact(t, x, u, h)
        if y is not None:
            if not _is_finite_sum(y):
                raise self._fail("non-finite value in the closed-form step", t + h, h, t, h)
            return y, StepStats(rhs_calls=1, substeps=1)
        return self.band.advance(t, x, u, h)

    def get_memory(self) -> tuple:
        return self.band.get_memory()

    def set_memory(self, m: tuple) -> None:
        self.band.set_memory(m)

    def reset(self) -> None:
        self.band.reset()


class ClosedFormExplicit(ClosedForm):
    """:class:`ClosedForm` with Dormand-Prince 5(4) where the closed form declines.

    The method the native C FMU runs (``python -m fmu_build --native``), so that the Python FMU
    can be set to step exactly as it does (stepper ``closed_form_explicit``).

    Parameters
    ----------
    model : OdeModel
        Model with ``closed_form_advance``.
    **band_options
        Options of :class:`ExplicitAdaptive` (``rtol``, ``atol``, ``max_substeps`` ...).
    """

    name = "closed_form_explicit"

    def __init__(self, model: Any, **band_options: Any) -> None:
        # Dormand-Prince 5(4) landing on the friction law's kinks, as the native C FMU's slaved
        # levels step the band (prsm_model.c, explicit_advance)
        super().__init__(model, band="explicit", **band_options)
