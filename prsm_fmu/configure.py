"""Solver parameters -> model, stepper and initial state: one place for the FMU and the loop.

The FMU slave (prsm_fmu/slave.py) and the actuator loop's plain Python PRSM block
(system_models/prsm.py) both build their model here, so that they run exactly the same
configuration (validation, ``auto`` choice, stepper and its options). Needs no pythonfmu.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from .engine import ENGINE_METHOD, check_engine, default_engine, engine_stepper
from .geometry import contact_geometry
from .models import FIDELITIES, auto_model, make_model
from .models.auto import choose_for_start
from .param_ranges import SOLVER_RANGES
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
#: ``auto`` explicit, exponential or linearly implicit per step (prsm_fmu/models/adaptive.py)
STEPPER_CHOICES = ("default",) + STEPPER_NAMES

#: the FMU's Enumeration ``Fidelity``: item name -> (value, description).  The values are part
#: of the FMU's interface (hosts and SSP files store them): never renumber an item.
FIDELITY_ITEMS: dict[str, tuple[int, str]] = {
    "kinematic": (0, "ideal kinematics, constant efficiency kinematic_efficiency"),
    "quasi-static": (1, "carriers at their force equilibrium: one mechanical degree of freedom"),
    "dynamic": (2, "Lagrange model with the carriers' degrees of freedom (stiff)"),
    "auto": (3, "the cheapest level whose estimated model error meets tolerance, chosen along "
                "the run"),
}

#: the FMU's Enumeration ``Stepper``: item name -> (value, description) (values fixed as above)
STEPPER_ITEMS: dict[str, tuple[int, str]] = {
    "default": (0, "closed_form for kinematic and quasi-static, rosenbrock for dynamic, a choice "
                   "per step for auto"),
    "closed_form": (1, "exact constant-acceleration step, scalar exponential Rosenbrock in the "
                       "friction band (kinematic and quasi-static only)"),
    "explicit_adaptive": (2, "Dormand-Prince 5(4) with error control"),
    "rosenbrock": (3, "linearly implicit ROS34PW2 with error control (stiff)"),
    "rk4": (4, "classical Runge-Kutta, substeps equal steps, no error control"),
    "radau": (5, "scipy's Radau IIA (reference; slow)"),
    "exponential": (6, "exponential Rosenbrock exprb32 with error control: the stiff speeds "
                       "integrated exactly through their phi-functions (stiff)"),
    "closed_form_explicit": (7, "exact constant-acceleration step, adaptive Dormand-Prince 5(4) in "
                                "the friction band (kinematic and quasi-static only)"),
}

#: Enumeration name -> its items, as the modelDescription's TypeDefinitions declare them
ENUMERATIONS: dict[str, dict[str, tuple[int, str]]] = {"Fidelity": FIDELITY_ITEMS,
                                                         "Stepper": STEPPER_ITEMS}

#: allowed ranges of the solver parameters, checked by :func:`configure`:
#: ``tolerance`` in [1e-12, 0.1]: below 1e-12 the error estimates of the embedded pairs are
#: rounding noise for states of order 1..1e3 in double precision (eps = 2.2e-16), so a step
#: can fail for every step size; above 0.1 the ``auto`` level may carry a 10 % model error.
TOLERANCE_RANGE = (SOLVER_RANGES["tolerance"].lo, SOLVER_RANGES["tolerance"].hi)
#: ``max_substeps`` in [10, 100000]: it bounds the work of one doStep (docs/fmu.md, "Work of
#: one doStep"); fewer than 10 internal steps cannot take the adaptive steppers through their
#: starting step and one rejection; ``substeps`` (fixed steps) must not exceed it either
MAX_SUBSTEPS_RANGE = (SOLVER_RANGES["max_substeps"].lo, SOLVER_RANGES["max_substeps"].hi)
#: |initial_screw_speed| [rad/s] at most: 10^4 rad/s (95,000 rpm) is 20x beyond any PRSM
#: (critical speeds of the papers' screws are a few thousand rpm)
MAX_INITIAL_SPEED = SOLVER_RANGES["initial_screw_speed"].hi
#: |initial_screw_angle| [rad] at most: beyond 10^6 rad a step's angle increment of 1 µrad
#: loses its last digits to the magnitude of the angle (10^6 * 2.2e-16 = 2e-10 rad)
MAX_INITIAL_ANGLE = SOLVER_RANGES["initial_screw_angle"].hi


def _choice(kind: str, items: dict[str, tuple[int, str]], value: Any) -> str:
    """The item name of ``value``: an item name or its Enumeration value (int)."""
    if isinstance(value, str) and value in items:
        return value
    if isinstance(value, int) and not isinstance(value, bool):
        for name, (code, _desc) in items.items():
            if code == value:
                return name
    allowed = ", ".join(f"{code} ({name})" for name, (code, _d) in items.items())
    raise ValueError(f"{kind} = {value!r} is not allowed: must be one of {allowed}")


def fidelity_name(value: Any) -> str:
    """``fidelity`` as its item name, from the name or the FMU's Enumeration value.

    Raises
    ------
    ValueError
        Naming the value and the allowed items with their values.
    """
    return _choice("fidelity", FIDELITY_ITEMS, value)


def stepper_name(value: Any) -> str:
    """``stepper`` as its item name, from the name or the FMU's Enumeration value."""
    return _choice("stepper", STEPPER_ITEMS, value)


#: the FMU's ``step_fidelity`` output: the level the outputs at a communication point come from
LEVEL_CODES = {"kinematic": 0, "quasi-static": 1, "dynamic": 2}


def active_level(model) -> int:
    """:data:`LEVEL_CODES` of the level a model's outputs come from now (for ``auto``, the
    level of its last step, prsm_fmu/models/adaptive.py)."""
    return LEVEL_CODES[getattr(model, "mode", model.fidelity)]


#: absolute tolerance of the adaptive steppers relative to ``tolerance`` (states are in rad,
#: rad/s and J, each with scale 1): atol = ATOL_FACTOR * tolerance
ATOL_FACTOR = 1e-2


#: rhs calls per internal step of scipy's Radau IIA that ``max_substeps`` allows (3 stages,
#: at most 6 simplified-Newton iterations each, plus its finite-difference Jacobian of the
#: 3-8 states): ``radau`` stops after RADAU_RHS_PER_STEP * max_substeps rhs calls
RADAU_RHS_PER_STEP = 30
#: most internal steps of one doStep where the Python reference model steps (not the compiled
#: engine), whatever ``max_substeps`` above it, and most fixed ``substeps`` there; ``radau``
#: (scipy's, always Python) at most PYTHON_MAX_RHS_CALLS rhs calls.  Measured at the limit
#: (``python benchmarks/dostep_work_bound.py``, PRSM3, tolerance 1e-12, 2026-11-26, loaded
#: 2-core machine): the Python steppers take 0.1-0.25 ms per internal step (at most 8 rhs calls
#: of ~40 us) and radau ~57 us per rhs call, so 100 000 steps could take 10-25 s; with these
#: bounds one doStep takes at most ~2.5 s (exponential, 10 000 steps) and ~3.4 s (radau,
#: 60 000 rhs calls): a margin of about 3 below the 10 s a host may allow a doStep
PYTHON_MAX_SUBSTEPS = 10_000
PYTHON_MAX_RHS_CALLS = 60_000



def _python_work_bound(opts: dict[str, Any], substeps: int, why: str | None) -> None:
    """Bound the Python stepper's options ``opts`` (in place) to :data:`PYTHON_MAX_SUBSTEPS`
    internal steps per doStep (``radau``: :data:`PYTHON_MAX_RHS_CALLS` rhs calls).

    Raises
    ------
    ValueError
        If fixed ``substeps`` exceed it: the step would take that many regardless.
    """
    if substeps > PYTHON_MAX_SUBSTEPS:
        where = f"the Python model runs ({why})" if why else "the Python model runs"
        raise ValueError(f"substeps = {substeps} is out of range where {where}: must be an "
                         f"integer in [0, {PYTHON_MAX_SUBSTEPS}] (bounds the work of one doStep "
                         "of the Python model)")
    if "max_substeps" in opts:
        opts["max_substeps"] = min(opts["max_substeps"], PYTHON_MAX_SUBSTEPS)
    if "max_rhs_calls" in opts:
        opts["max_rhs_calls"] = min(opts["max_rhs_calls"], PYTHON_MAX_RHS_CALLS)


def configure(params: MechanismParams, solver: Mapping[str, Any], inputs: tuple[float, float],
              engine: str | None = None, library_path: str | None = None,
              engine_refusal: str | None = None):
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
    engine : {"native", "python"}, optional
        Default: :func:`prsm_fmu.engine.default_engine` (``native`` unless the environment
        variable ``PRSM_FMU_ENGINE`` says otherwise).  ``native``: the compiled engine steps the model wherever it can (:mod:`prsm_fmu.engine`;
        with ``stepper = default`` it runs its method of the level, the Python default, e.g.
        ``closed_form`` at the quasi-static level); elsewhere, and with ``python``,
        the Python stepper (``stepper.engine_fallback`` says why, for ``native``).
    library_path : str, optional
        The engine library to load (an FMU's packed one); default: compiled for ``params``.
    engine_refusal : str, optional
        A reason known beforehand why the engine cannot run (the FMU's geometry check).

    Returns
    -------
    tuple
        (model, stepper, x0, level, stepper name); the name is the Python stepper's, or the
        engine's method when the engine runs (``stepper.name`` is then ``native``).

    Raises
    ------
    ValueError
        Naming the parameter, its value and the allowed range.
    """
    fidelity = fidelity_name(solver["fidelity"])
    engine = default_engine() if engine is None else check_engine(engine)
    tol = solver["tolerance"]
    for name, rule in SOLVER_RANGES.items():    # the one table of ranges (param_ranges)
        rule.check(name, solver[name],
                   hi=solver["max_substeps"] if name == "substeps" else None)
    max_substeps, substeps = solver["max_substeps"], solver["substeps"]
    eff = solver["kinematic_efficiency"]
    for k, stage in enumerate(params.stages, start=1):   # contact exists: errors name the stage
        contact_geometry(stage, f"stage[{k}]")
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
    asked = stepper_name(solver["stepper"])
    name = DEFAULT_STEPPER[level] if asked == "default" else asked
    if name in ("closed_form", "closed_form_explicit") and level == "dynamic":
        raise ValueError(f"stepper = {name!r} is not allowed with fidelity = 'dynamic': "
                         "the closed form exists only for kinematic and quasi-static")
    opts: dict[str, Any] = {}
    if name == "radau":      # its steps cost up to ~30 rhs calls each: bound those too
        opts["max_rhs_calls"] = RADAU_RHS_PER_STEP * max_substeps
    if name == "rk4":
        if substeps < 1:
            raise ValueError("substeps = 0 is out of range for stepper = 'rk4': must be an "
                             "integer >= 1 (rk4 has no error control)")
        opts["substeps"] = substeps
    else:
        opts.update(tuned_stepper_options(name, tol, ATOL_FACTOR * tol) if not substeps
                    else {"rtol": tol, "atol": ATOL_FACTOR * tol})
        opts["max_substeps"] = max_substeps
        if substeps:
            if name == "radau":
                raise ValueError(f"substeps = {substeps!r} is out of range for stepper = "
                                 "'radau': must be 0 (radau has no fixed-step mode)")
            opts["fixed_substeps"] = substeps
    model_opts = {"efficiency": eff} if level == "kinematic" else {}
    model = (make_model(params, level, "torque", **model_opts) if choice is None
             else auto_model(params, "torque", choice, **model_opts))
    stepper = why = None
    if engine == "native":
        stepper, why = engine_stepper(model, level, asked, tol, ATOL_FACTOR * tol, max_substeps,
                                      substeps, library_path, engine_refusal)
        if stepper is not None and asked == "default":
            name = ENGINE_METHOD.get(level, name)     # auto's default is ROS34PW2 there
    if stepper is None:
        _python_work_bound(opts, substeps, why)
        stepper = make_stepper(name, model, **opts)
        if why is not None:
            stepper.engine_fallback = why
    x0 = model.initial_state(tuple(inputs), screw_speed=solver["initial_screw_speed"],
                             screw_angle=solver["initial_screw_angle"],
                             carrier_ratio=None if solver["initial_carrier_equilibrium"] else 0.0)
    return model, stepper, x0, level, name
