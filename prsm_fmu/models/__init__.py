"""Fidelity levels of the PRSM behind one interface (:class:`~prsm_fmu.models.base.Model`)."""

from __future__ import annotations

from ..params import MechanismParams
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
        Level of detail.  ``auto``: the cheapest level whose estimated model error at the start
        of the run is within ``tolerance`` (:func:`prsm_fmu.models.auto.choose_for_start`;
        docs/accuracy.md §4); the returned model's ``auto_choice`` says what and why.
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
        if choice.fidelity != "kinematic":
            options.pop("efficiency", None)
        model = _CLASSES[choice.fidelity](params, drive, **options)
        model.auto_choice = choice
        return model
    if fidelity not in _CLASSES:
        raise ValueError(f"fidelity = {fidelity!r} is not allowed: must be one of {FIDELITIES}")
    return _CLASSES[fidelity](params, drive, **options)


__all__ = ["Model", "DynamicModel", "QuasiStaticModel", "KinematicModel", "make_model", "FIDELITIES",
           "AutoChoice", "choose_fidelity", "choose_for_start", "estimate_errors"]
