"""Kinematic level: ideal kinematics, all inertias, optional constant efficiency.

Carriers turn at the pure-rolling ratio r_S/(r_S + r_N) (seed 001); no thread friction.  With
``efficiency`` η₀ < 1 a Coulomb torque (1/η₀ − 1)·|F_load|·ΣL/2π opposes the screw's rotation,
so that the steady forward-drive efficiency is η₀ (and back-driving, 2 − 1/η₀).  It is the
cheapest level and the `IdealGearR2T`-like baseline.
"""

from __future__ import annotations

from ..friction import regularised_sign
from ..params import MechanismParams
from .base import Model
from .slaved import SlavedLevel


class KinematicModel(SlavedLevel, Model):
    """Ideal screw with the mechanism's inertias and an optional constant efficiency.

    Parameters
    ----------
    params : MechanismParams
        The mechanism.
    drive : {"torque", "speed"}
        Drive mode.
    efficiency : float
        Constant forward efficiency η₀ in (0, 1] [-]; 1 is lossless.
    """

    fidelity = "kinematic"
    carriers = "ideal"

    def __init__(self, params: MechanismParams, drive: str = "torque", efficiency: float = 1.0) -> None:
        if not (isinstance(efficiency, (int, float)) and 0.0 < efficiency <= 1.0):
            raise ValueError(f"efficiency = {efficiency!r} is out of range: must be in (0, 1]")
        super().__init__(params, drive)
        self.efficiency = float(efficiency)
        self._loss_factor = (1.0 / self.efficiency - 1.0) * self.mechanism.c_out

    def _extra_loss_torque(self, omega: float, load: float) -> float:
        if self._loss_factor == 0.0:
            return 0.0
        v_eps = self.params.slip_velocity_scale
        return self._loss_factor * abs(load) * regularised_sign(omega * self.mechanism.c_out, v_eps)
