"""Exact step where the model offers one, an adaptive explicit pair elsewhere."""

from __future__ import annotations

from typing import Any

from .base import Stepper, StepStats, _is_finite_sum
from .explicit import ExplicitAdaptive

__all__ = ["ClosedForm"]


class ClosedForm(Stepper):
    """Exact step where the model offers one, an adaptive explicit pair elsewhere.

    For models with ``closed_form_advance(t, x, u, h) -> list | None`` (the slaved-carrier
    levels: constant acceleration under held inputs outside the friction band).  Where it
    answers None (zero speed crossed, friction band entered, sign pattern left), the step is
    integrated by :class:`ExplicitAdaptive` with the given options.  A closed-form step counts
    as one rhs call.

    Parameters
    ----------
    model : OdeModel
        Model with ``closed_form_advance``.
    **fallback_options
        Options of the fallback :class:`ExplicitAdaptive` (``rtol``, ``atol``, ``order`` ...).
    """

    name = "closed_form"

    def __init__(self, model: Any, **fallback_options: Any) -> None:
        super().__init__(model)
        if not callable(getattr(model, "closed_form_advance", None)):
            raise ValueError(f"closed_form: model {type(model).__name__} has no closed_form_advance; "
                             "use it with the quasi-static or kinematic level")
        self._exact = model.closed_form_advance
        self.fallback = ExplicitAdaptive(model, **fallback_options)

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        y = self._exact(t, x, u, h)
        if y is not None:
            if not _is_finite_sum(y):
                raise self._fail("non-finite value in the closed-form step", t + h, h, t, h)
            return y, StepStats(rhs_calls=1, substeps=1)
        return self.fallback.advance(t, x, u, h)

    def get_memory(self) -> tuple:
        return self.fallback.get_memory()

    def set_memory(self, m: tuple) -> None:
        self.fallback.set_memory(m)

    def reset(self) -> None:
        self.fallback.reset()
