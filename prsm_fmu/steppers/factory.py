"""Steppers by name: :func:`make_stepper` and the names it accepts."""

from __future__ import annotations

from typing import Any

from .base import Stepper
from .closed_form import ClosedForm, ClosedFormExplicit
from .explicit import ExplicitAdaptive
from .exponential import ExponentialRosenbrock
from .radau import ScipyRadau
from .rk4 import RK4
from .rosenbrock import Rosenbrock

__all__ = ["make_stepper", "STEPPER_NAMES"]

_STEPPERS: dict[str, type[Stepper]] = {
    "rk4": RK4,
    "explicit_adaptive": ExplicitAdaptive,
    "rosenbrock": Rosenbrock,
    "exponential": ExponentialRosenbrock,
    "radau": ScipyRadau,
    "closed_form": ClosedForm,
    "closed_form_explicit": ClosedFormExplicit,
}

#: names accepted by :func:`make_stepper`
STEPPER_NAMES = tuple(_STEPPERS)


def make_stepper(name: str, model: Any, **options: Any) -> Stepper:
    """Create a stepper by name.

    Parameters
    ----------
    name : {"rk4", "explicit_adaptive", "rosenbrock", "exponential", "radau", "closed_form", "closed_form_explicit"}
        Stepper kind.
    model : OdeModel
        Model to integrate.  A model with a ``stepper_factory(name, **options)`` (the
        ``auto`` fidelity, which switches levels along a run) builds its own stepper, taking
        ``name`` (or ``"default"``: its own choice per step) for its dynamic steps.
    **options
        Keyword arguments of the stepper's constructor (e.g. ``rtol``, ``substeps``).

    Returns
    -------
    Stepper
        The new stepper.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the allowed names).
    """
    factory = getattr(model, "stepper_factory", None)
    if factory is not None and (name == "default" or name in _STEPPERS):
        # a model that switches levels steps itself (models/adaptive.py)
        return factory(name, **options)
    try:
        cls = _STEPPERS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown stepper {name!r}: allowed are {', '.join(STEPPER_NAMES)}") from None
    return cls(model, **options)
