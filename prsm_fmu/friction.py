"""Friction laws shared by every fidelity level.

All Coulomb laws are regularised the same way so that forces stay continuous through zero
slip (documented in docs/model.md, "Friction"):

    f = -µ |N| · v / sqrt(|v|² + v_ε²)

Above the slip-velocity scale v_ε the force has the Coulomb magnitude µ|N| along −v (relative
error ≤ v_ε²/(2|v|²)); below it the law is viscous with coefficient µ|N|/v_ε.  Stiction is not
modelled.  The dissipated power µ|N| |v|² / sqrt(|v|² + v_ε²) is never negative.
"""

from __future__ import annotations

import math


def regularised_sign(v: float, v_scale: float) -> float:
    """Continuous replacement of sign(v) for a Coulomb law, in (−1, 1).

    Parameters
    ----------
    v : float
        Sliding velocity [m/s] (or [rad/s] when ``v_scale`` is one too).
    v_scale : float
        Velocity scale v_ε below which the law turns viscous, same unit as ``v``.

    Returns
    -------
    float
        v / sqrt(v² + v_ε²).
    """
    return v / math.sqrt(v * v + v_scale * v_scale)


def regularised_direction(vx: float, vy: float, vz: float, v_scale: float) -> tuple[float, float, float, float]:
    """Direction factor of a regularised Coulomb force for a slip velocity vector.

    Parameters
    ----------
    vx, vy, vz : float
        Slip velocity components [m/s].
    v_scale : float
        Slip-velocity scale v_ε [m/s].

    Returns
    -------
    tuple
        (ux, uy, uz, q): u = v / q with q = sqrt(|v|² + v_ε²) [m/s]; the friction force on the
        body whose velocity relative to the other is v is −µ|N|·u.
    """
    q = math.sqrt(vx * vx + vy * vy + vz * vz + v_scale * v_scale)
    return vx / q, vy / q, vz / q, q


def spline_friction_force(mu: float, torque: float, radius: float, sign_of_slip: float) -> float:
    """Axial friction force between the spline teeth of consecutive screws (seed 000 Eq. 12).

    Parameters
    ----------
    mu : float
        Friction coefficient µ_SS [-].
    torque : float
        Torque transmitted by the spline M_Sk [N·m]; the tooth normal force is |M_Sk| / r_SS.
    radius : float
        Nominal spline radius r_SS [m].
    sign_of_slip : float
        Regularised sign of the sliding velocity the force opposes, in [−1, 1].

    Returns
    -------
    float
        Friction force [N] with the sign of the slip it opposes reversed.
    """
    return -mu * abs(torque) / radius * sign_of_slip


def bearing_friction_torque(mu: float, axial_force: float, radius: float, sign_of_speed: float) -> float:
    """Friction torque of the thrust bearing between nut k and screw k+1 (seed 002).

    Parameters
    ----------
    mu : float
        Friction coefficient µ_NS [-].
    axial_force : float
        Axial force carried by the bearing [N].
    radius : float
        Effective friction radius r_NS [m].
    sign_of_speed : float
        Regularised sign of the screw's speed relative to the (non-rotating) nut, in [−1, 1].

    Returns
    -------
    float
        Torque on the screw [N·m], opposing its rotation.
    """
    return -mu * abs(axial_force) * radius * sign_of_speed
