"""Fidelity levels of the PRSM behind one interface (:class:`~prsm_fmu.models.base.Model`)."""

from __future__ import annotations

from ..params import MechanismParams
from .adaptive import AdaptiveModel
from .auto import AutoChoice, choose_fidelity, choose_for_start, estimate_errors
from .base import Model
from .dynamic import DynamicModel
from .kinematic import KinematicModel
from .quasi_static import QuasiStaticModel

FIDELITIES = ("kinematic", "quasi-static", "dynamic")

_CLASSES = {"kinematic": KinematicModel, "quasi-static": QuasiStaticModel, "dynamic": DynamicModel}


def make_model(params: MechanismParams, fidelity: str = "dynamic", drive: str = "torque", **options) -> Model:
    """Build the model of one fidelity level.

    Parameters
    ----------
    params : MechanismParams
        The mechanism.
    fidelity : {"kinematic", "quasi-static", "dynamic", "auto"}
        Level of detail.  ``auto``: the cheapest level whose estimated model error is within
        ``tolerance``, chosen at the start (:func:`prsm_fmu.models.auto.choose_for_start`) and
        along the run between the dynamic and the quasi-static level (:func:`auto_model`,
        prsm_fmu/models/adaptive.py; docs/accuracy.md §4); the returned model's
        ``auto_choice`` says what was chosen at the start and why.
    drive : {"torque", "speed"}
        Drive mode.
    **options
        Level-specific options (``efficiency`` for the kinematic level).  With ``auto`` also:
        ``tolerance`` (required), ``inputs`` (start inputs, default (0, 0)), ``comm_step``,
        ``screw_speed``, ``carrier_ratio``, ``acceleration`` (see ``choose_for_start``).

    Returns
    -------
    Model
    """
    if fidelity == "auto":
        auto_keys = ("inputs", "comm_step", "screw_speed", "carrier_ratio", "acceleration")
        if "tolerance" not in options:
            raise ValueError("fidelity = 'auto' needs tolerance = <accepted error>")
        tol = options.pop("tolerance")
        kw = {k: options.pop(k) for k in auto_keys if k in options}
        inputs = kw.pop("inputs", (0.0, 0.0))
        choice = choose_for_start(params, tol, drive, inputs,
                                  kinematic_efficiency=options.get("efficiency", 1.0), **kw)
        return auto_model(params, drive, choice, **options)
    if fidelity not in _CLASSES:
        raise ValueError(f"fidelity = {fidelity!r} is not allowed: must be one of {FIDELITIES}")
    return _CLASSES[fidelity](params, drive, **options)


def auto_model(params: MechanismParams, drive: str, choice: AutoChoice, **options) -> Model:
    """The model ``fidelity = "auto"`` runs, given the choice at the start of the run.

    The kinematic level when it was chosen (its error, the friction loss, does not change along
    a run); otherwise an :class:`~prsm_fmu.models.adaptive.AdaptiveModel` that starts at the
    chosen level and switches between the dynamic and the quasi-static level along the run.

    Parameters
    ----------
    params : MechanismParams
    drive : {"torque", "speed"}
    choice : AutoChoice
        From :func:`choose_for_start`, with its tolerance.
    **options
        ``efficiency`` for the kinematic level.
    """
    if choice.fidelity == "kinematic":
        model = KinematicModel(params, drive, **options)
    else:
        model = AdaptiveModel(params, drive, tolerance=choice.tolerance, start=choice.fidelity,
                              choice=choice)
    model.auto_choice = choice
    return model


__all__ = ["Model", "AdaptiveModel", "auto_model", "DynamicModel", "QuasiStaticModel",
           "KinematicModel", "make_model", "FIDELITIES", "AutoChoice", "choose_fidelity", "choose_for_start", "estimate_errors"]
