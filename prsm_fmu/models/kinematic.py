"""Kinematic level: ideal kinematics, all inertias, optional constant efficiency.

Carriers turn at the pure-rolling ratio r_S/(r_S + r_N) (the two-stage kinematics article); no thread friction.  With
``efficiency`` η₀ < 1 a Coulomb torque (1/η₀ − 1)·|F_load|·ΣL/2π opposes the screw's rotation,
so that the steady forward-drive efficiency is η₀ (and back-driving, 2 − 1/η₀).  It is the
cheapest level and the `IdealGearR2T`-like baseline.

The friction-torque article's other two friction terms reach this level through the same loss torque, lumped at
their steady values with the carriers at their equilibrium ratio ζ*_k and frictionless normal
forces (docs/model.md §4): a viscous torque C_v ω with C_v = Σ_k N_Rk µ_1 n_tk |a_k + ζ*_k b_k|²
and a differential-sliding torque C_d |F_load| sgñ(ω ΣL/2π) with C_d = Σ_k µ_3 / |n_z,k|.  With
η₀ = 1 the steady torque is then the quasi-static level's with µ_SR = 0, up to the product
µ_3 µ_1 (the viscous axial force's share of the normal force).
"""

from __future__ import annotations

from ..friction import regularised_sign, viscous_coefficient
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
        c_v = c_d = 0.0
        for st, s in zip(params.stages, self.mechanism.stages):
            fl = s.flanks[0]
            z = s.zeta_geometric
            sx, sy, sz = fl.ax + z * fl.bx, fl.ay + z * fl.by, fl.az
            c_v += viscous_coefficient(params.mu_viscous, st.n_rollers, st.threads_per_roller) \
                * (sx * sx + sy * sy + sz * sz)
            c_d += params.mu_differential / abs(fl.nz)
        #: lumped viscous loss torque per unit screw speed C_v [N·m·s/rad]
        self._viscous_loss = c_v
        #: lumped differential-sliding loss torque per unit load C_d [m]
        self._differential_loss = c_d
        #: whether the loss torque depends on the speed (the closed-form step is then not exact)
        self.viscous = c_v > 0.0
        #: whether a Coulomb-like loss (η₀ or differential sliding) regularised on ω ΣL/2π acts
        self.coulomb_loss = self._loss_factor > 0.0 or c_d > 0.0

    def _extra_loss_terms(self, omega: float, load: float) -> dict[str, float]:
        sg = regularised_sign(omega * self.mechanism.c_out, self.params.slip_velocity_scale)
        return {"coulomb": self._loss_factor * abs(load) * sg * omega,
                "viscous": self._viscous_loss * omega * omega,
                "differential": self._differential_loss * abs(load) * sg * omega}

    def _extra_loss_torque(self, omega: float, load: float) -> float:
        torque = self._viscous_loss * omega
        if self.coulomb_loss:
            v_eps = self.params.slip_velocity_scale
            torque += ((self._loss_factor + self._differential_loss) * abs(load)
                       * regularised_sign(omega * self.mechanism.c_out, v_eps))
        return torque
