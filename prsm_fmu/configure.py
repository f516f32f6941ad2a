"""Solver parameters -> model, stepper and initial state: one place for the FMU and the loop.

The FMU slave (prsm_fmu/slave.py) and the actuator loop's plain Python PRSM block
(system_models/prsm.py) both build their model here, so that they run exactly the same
configuration (validation, ``auto`` choice, stepper and its options). Needs no pythonfmu.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from .models import FIDELITIES, auto_model, make_model
from .models.auto import choose_for_start
from .params import MechanismParams
from .simulate import DEFAULT_STEPPER, tuned_stepper_options
from .steppers import STEPPER_NAMES, make_stepper

#: fidelity choices; ``auto``: :func:`prsm_fmu.models.auto.choose_for_start`
FIDELITY_CHOICES = FIDELITIES + ("auto",)

#: the level ``fidelity = auto`` starts with at the FMU's default start (screw at rest, no
#: inputs): the quasi-static level.  The start is chosen when the model is built, by
#: :func:`prsm_fmu.models.auto.choose_for_start` from the tolerance and the start's operating
#: point (the communication step is not known then: input jumps are not credited with damping);
#: from then on the level of each step follows the carriers' lag
#: (:mod:`prsm_fmu.models.adaptive`); see docs/accuracy.md §4
AUTO_FIDELITY = "quasi-static"

#: stepper choices: ``default`` is ``closed_form`` for the levels with slaved carriers
#: (quasi-static, kinematic), ``rosenbrock`` for the dynamic level, and for the dynamic steps of
#: ``auto`` explicit or linearly implicit per step (prsm_fmu/models/adaptive.py)
STEPPER_CHOICES = ("default",) + STEPPER_NAMES

#: the FMU's ``step_fidelity`` output: the level the outputs at a communication point come from
LEVEL_CODES = {"kinematic": 0, "quasi-static": 1, "dynamic": 2}


def active_level(model) -> int:
    """:data:`LEVEL_CODES` of the level a model's outputs come from now (for ``auto``, the
    level of its last step, prsm_fmu/models/adaptive.py)."""
    return LEVEL_CODES[getattr(model, "mode", model.fidelity)]


#: absolute tolerance of the adaptive steppers relative to ``tolerance`` (states are in rad,
#: rad/s and J, each with scale 1): atol = ATOL_FACTOR * tolerance
ATOL_FACTOR = 1e-2


def configure(params: MechanismParams, solver: Mapping[str, Any], inputs: tuple[float, float]):
    """Model, stepper and initial state of a torque-driven PRSM from its solver parameters.

    Parameters
    ----------
    params : MechanismParams
        The validated mechanism.
    solver : mapping
        ``fidelity``, ``tolerance`` [-], ``stepper``, ``substeps``, ``max_substeps``,
        ``kinematic_efficiency`` [-], ``initial_screw_speed`` [rad/s], ``initial_screw_angle``
        [rad], ``initial_carrier_equilibrium`` (bool): the FMU's parameters of the same names.
    inputs : tuple
        Motor torque [N·m] and load force [N] at the start.

    Returns
    -------
    tuple
        (model, stepper, x0, level, stepper name).

    Raises
    ------
    ValueError
        Naming the parameter, its value and the allowed range.
    """
    fidelity = solver["fidelity"]
    if fidelity not in FIDELITY_CHOICES:
        raise ValueError(f"fidelity = {fidelity!r} is not allowed: must be one of "
                         f"{', '.join(FIDELITY_CHOICES)}")
    tol = solver["tolerance"]
    if not (math.isfinite(tol) and 0.0 < tol < 1.0):
        raise ValueError(f"tolerance = {tol!r} is out of range: must be in (0, 1)")
    choice = None
    if fidelity == "auto":
        eff0 = solver["kinematic_efficiency"]
        choice = choose_for_start(
            params, tol, "torque", tuple(inputs), screw_speed=solver["initial_screw_speed"],
            carrier_ratio=None if solver["initial_carrier_equilibrium"] else 0.0,
            kinematic_efficiency=eff0 if math.isfinite(eff0) and 0.0 < eff0 <= 1.0 else 1.0)
    # auto: the kinematic level, or the model that switches between dynamic and quasi-static
    level = fidelity if choice is None else ("kinematic" if choice.fidelity == "kinematic"
                                             else "auto")
    substeps = solver["substeps"]
    if substeps < 0:
        raise ValueError(f"substeps = {substeps!r} is out of range: must be an integer >= 0 "
                         "(0: adaptive)")
    max_substeps = solver["max_substeps"]
    if max_substeps < 1:
        raise ValueError(f"max_substeps = {max_substeps!r} is out of range: must be an "
                         "integer >= 1")
    eff = solver["kinematic_efficiency"]
    if not (math.isfinite(eff) and 0.0 < eff <= 1.0):
        raise ValueError(f"kinematic_efficiency = {eff!r} is out of range: must be in (0, 1]")
    for name in ("initial_screw_speed", "initial_screw_angle"):
        if not math.isfinite(solver[name]):
            raise ValueError(f"{name} = {solver[name]!r} is out of range: must be finite")
    name = solver["stepper"]
    if name not in STEPPER_CHOICES:
        raise ValueError(f"stepper = {name!r} is not allowed: must be one of "
                         f"{', '.join(STEPPER_CHOICES)}")
    name = DEFAULT_STEPPER[level] if name == "default" else name
    if name == "closed_form" and level == "dynamic":
        raise ValueError("stepper = 'closed_form' is not allowed with fidelity = 'dynamic': "
                         "the closed form exists only for kinematic and quasi-static")
    opts: dict[str, Any] = {}
    if name == "rk4":
        if substeps < 1:
            raise ValueError("substeps = 0 is out of range for stepper = 'rk4': must be an "
                             "integer >= 1 (rk4 has no error control)")
        opts["substeps"] = substeps
    else:
        opts.update(tuned_stepper_options(name, tol, ATOL_FACTOR * tol) if not substeps
                    else {"rtol": tol, "atol": ATOL_FACTOR * tol})
        if name != "radau":
            opts["max_substeps"] = max_substeps
        if substeps:
            if name == "radau":
                raise ValueError(f"substeps = {substeps!r} is out of range for stepper = "
                                 "'radau': must be 0 (radau has no fixed-step mode)")
            opts["fixed_substeps"] = substeps
    model_opts = {"efficiency": eff} if level == "kinematic" else {}
    model = (make_model(params, level, "torque", **model_opts) if choice is None
             else auto_model(params, "torque", choice, **model_opts))
    stepper = make_stepper(name, model, **opts)
    x0 = model.initial_state(tuple(inputs), screw_speed=solver["initial_screw_speed"],
                             screw_angle=solver["initial_screw_angle"],
                             carrier_ratio=None if solver["initial_carrier_equilibrium"] else 0.0)
    return model, stepper, x0, level, name
