"""Time steppers that advance one model across one communication step with inputs held.

A co-simulation master (an FMU's ``doStep``) calls :meth:`Stepper.advance` once per
communication step (typically 1 ms) with the model inputs ``u`` held constant.  The
steppers here are written for that hot path:

* states and derivatives are plain Python ``list`` objects of ``float``; the inner loops
  use list comprehensions over ``zip`` (for the 2..12 states of a PRSM model, small
  numpy arrays cost about ten times more per operation);
* every call returns a fresh state list; the caller's list ``x`` is never mutated, so
  the caller's state is unchanged when :class:`StepFailure` is raised;
* the work done is counted in a :class:`StepStats` per call.

Provided steppers (see :func:`make_stepper`), one module each on the shared base
(:mod:`.base`; the adaptive ones also on :mod:`.control`):

``"rk4"``
    :class:`RK4` (:mod:`.rk4`), classic fixed-step Runge-Kutta of order 4.
``"explicit_adaptive"``
    :class:`ExplicitAdaptive` (:mod:`.explicit`), embedded explicit pair with step-size
    control: Dormand-Prince 5(4) (default) or Bogacki-Shampine 3(2).
``"rosenbrock"``
    :class:`Rosenbrock` (:mod:`.rosenbrock`), linearly implicit L-stable ROS34PW2
    (order 3, embedded 2) for stiff models (contact stiffness, electrical time constants).
``"exponential"``
    :class:`ExponentialRosenbrock` (:mod:`.exponential`), exponential Rosenbrock exprb32
    (order 3, embedded 2): the stiff speed block integrated exactly through its φ-functions
    (:mod:`.phi`); a choice for the dynamic level (its default stays ``rosenbrock``).
``"radau"``
    :class:`ScipyRadau` (:mod:`.radau`), the reference path through
    :func:`scipy.integrate.solve_ivp`.
``"closed_form"``
    :class:`ClosedForm` (:mod:`.closed_form`), the model's exact step where it has one, and
    where it has none (the slaved levels' friction band) :class:`ScalarExponential`
    (:mod:`.band`), an exponential Rosenbrock step for one free state plus quadratures.
``"closed_form_explicit"``
    :class:`ClosedFormExplicit`: the same with Dormand-Prince 5(4) in the band (the native C
    FMU's method).

The methods' coefficients are data in :mod:`.tableaux`; the small dense LU of the linearly
implicit steppers is in :mod:`.linalg`; the options tuned for the PRSM models in
:mod:`.options`.

Model protocol (duck typed, see :class:`OdeModel`): ``n_states``, ``rhs(t, x, u)``,
``state_scale`` and optionally ``jacobian(t, x, u)``, ``error_mask`` and
``quadrature_states``.  Times are in seconds [s]; states and derivatives are in SI units.
"""

from __future__ import annotations

from .base import OdeModel, StepFailure, Stepper, StepStats
from .closed_form import ClosedForm, ClosedFormExplicit
from .explicit import ExplicitAdaptive
from .band import ScalarExponential
from .exponential import ExponentialRosenbrock
from .factory import STEPPER_NAMES, make_stepper
# private names re-exported for the tests that check the LU and the quadrature weights
from .linalg import SMALL_LU as _SMALL_LU
from .linalg import lu_factor as _lu_factor
from .linalg import lu_solve as _lu_solve
from .options import TUNED_OPTIONS, tuned_stepper_options
from .radau import ScipyRadau
from .rk4 import RK4
from .rosenbrock import Rosenbrock
from .tableaux import (_ROS_EQ, _ROS_WQ, EXPLICIT_TABLEAUS, ROS_ALPHA, ROS_B, ROS_BHAT, ROS_GAMMA,
                       ROS_GAMMA_IJ)

__all__ = [
    "OdeModel",
    "StepStats",
    "StepFailure",
    "Stepper",
    "RK4",
    "ExplicitAdaptive",
    "Rosenbrock",
    "ExponentialRosenbrock",
    "ScipyRadau",
    "ClosedForm",
    "ClosedFormExplicit",
    "ScalarExponential",
    "make_stepper",
    "STEPPER_NAMES",
    "EXPLICIT_TABLEAUS",
    "ROS_GAMMA",
    "ROS_ALPHA",
    "ROS_GAMMA_IJ",
    "ROS_B",
    "ROS_BHAT",
    "TUNED_OPTIONS",
    "tuned_stepper_options",
]
