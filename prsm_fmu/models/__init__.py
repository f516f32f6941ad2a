"""Fidelity levels of the PRSM behind one interface (:class:`~prsm_fmu.models.base.Model`)."""

from __future__ import annotations

from ..params import MechanismParams
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
    fidelity : {"kinematic", "quasi-static", "dynamic"}
        Level of detail.
    drive : {"torque", "speed"}
        Drive mode.
    **options
        Level-specific options (``efficiency`` for the kinematic level).

    Returns
    -------
    Model
    """
    if fidelity not in _CLASSES:
        raise ValueError(f"fidelity = {fidelity!r} is not allowed: must be one of {FIDELITIES}")
    return _CLASSES[fidelity](params, drive, **options)


__all__ = ["Model", "DynamicModel", "QuasiStaticModel", "KinematicModel", "make_model", "FIDELITIES"]
