"""Friction laws shared by every fidelity level and by the steady-state solver.

All Coulomb laws are regularised the same way, here and only here, so that forces stay
continuous through zero slip (docs/model.md §5). With v = |s| the slip speed and v_ε the
slip-velocity scale, the friction force on the body whose velocity relative to the other is s is

    f = −µ|N| · s · φ(v),   φ(v) = 1/v for v ≥ v_ε (exact Coulomb),
                            φ(v) = (2 − v/v_ε)/v_ε for v < v_ε,

i.e. the magnitude µ|N|·r(2 − r) with r = v/v_ε inside the band: continuous with a continuous
first derivative at v = v_ε, viscous (coefficient 2µ|N|/v_ε) at v → 0. Outside the band the law
is exactly Coulomb, so a contact whose slip direction is fixed transmits a force independent of
the slip speed (the quasi-static level then has exactly piecewise-constant accelerations).
Stiction is not modelled. The dissipated power µ|N| v² φ(v) is never negative.

Two more terms act at the screw–roller contacts (the friction-torque article):

* viscous (lubricant shear): f = −µ_1 n_t s per roller, µ_1 [N·s/m] per engaged thread and n_t
  engaged threads (:func:`viscous_coefficient`); linear through zero slip, so it needs no
  regularisation, and its power µ_1 n_t |s|² is never negative;
* differential sliding: a torque µ_3 F_N on the screw against its rotation, µ_3 [m], F_N the
  normal force; its sign is sgñ(ω r) with r the contact radius (:func:`regularised_sign`), so its
  power µ_3 F_N ω sgñ(ω r) is never negative either.
"""

from __future__ import annotations

import math


def regularised_factor(speed: float, v_scale: float) -> float:
    """Factor φ(v) of the regularised Coulomb law: the unit-ish direction is u = s·φ(|s|).

    Parameters
    ----------
    speed : float
        Slip speed |s| ≥ 0 [m/s] (or [rad/s] when ``v_scale`` is one too).
    v_scale : float
        Velocity scale v_ε > 0, same unit: the law is exactly Coulomb above it.

    Returns
    -------
    float
        φ [1/(m/s)]: 1/|s| outside the band, (2 − |s|/v_ε)/v_ε inside (finite at |s| = 0).
    """
    if speed >= v_scale:
        return 1.0 / speed
    return (2.0 - speed / v_scale) / v_scale


def regularised_sign(v: float, v_scale: float) -> float:
    """Continuous replacement of sign(v) for a one-dimensional Coulomb law, in [−1, 1].

    Parameters
    ----------
    v : float
        Sliding velocity [m/s] (or [rad/s] when ``v_scale`` is one too).
    v_scale : float
        Velocity scale v_ε below which the law is blended (see module docstring).

    Returns
    -------
    float
        v·φ(|v|): exactly ±1 for |v| ≥ v_ε.
    """
    return v * regularised_factor(abs(v), v_scale)



def viscous_coefficient(mu_viscous: float, n_rollers: int, threads_per_roller: int) -> float:
    """Viscous coefficient of a stage's rollers together, N_R µ_1 n_t [N·s/m].

    The friction-torque article's lubricant term F_fs1 = µ_1 n_R n_t v_sr: each engaged thread contributes µ_1.

    Parameters
    ----------
    mu_viscous : float
        µ_1 [N·s/m] per engaged thread, ≥ 0.
    n_rollers, threads_per_roller : int
        N_R and n_t [-].

    Returns
    -------
    float
        N_R µ_1 n_t [N·s/m]: the force of all rollers is this times the slip velocity.
    """
    return float(mu_viscous) * n_rollers * threads_per_roller
