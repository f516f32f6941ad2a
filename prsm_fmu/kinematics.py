"""Ideal (rigid, slip-free) kinematics of roller screws in closed form, in SI units.

What this module is for: the reference motion against which the kinematic, quasi-static and
dynamic models are checked, and the papers' "theory" columns are reproduced.  The derivations
and the comparison with the papers are in ``docs/kinematics.md``.

Two mechanisms:

* the **standard multi-stage PRSM** (Li et al. (2021) §2.1 Eqs. 1–5; the two-stage kinematics
  article, "Theoretical Kinematic Model"), described by
  :class:`prsm_fmu.params.MechanismParams`;
* the **recirculating roller screw** (the recirculating-screw article), whose grooved rollers
  have no helix, described by :class:`RecirculatingParams`.

Conventions (those of Li et al. (2021) and of the whole project): z is the screw axis, threads are
right-handed, angular velocities are signed about +z by the right-hand rule [rad/s].  A nut's
axial velocity ż_N is given in that z convention, so a positive screw speed drives the nuts
towards −z; the *rod* velocity is −ż_N of the last nut, so a positive screw speed extends the rod.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .params import MechanismParams, StageParams, _check_int_at_least, _check_positive

TWO_PI = 2.0 * math.pi

#: largest accepted misfit |d_n − d_s − 2 d_r| of a recirculating screw, relative to d_n.
#: The closed forms below do not need the fit (see docs/kinematics.md); the check only catches
#: gross input errors (a radius typed for a diameter misfits by > 7 %).  The recirculating-screw article's Table 2
#: misfits by 0.25 mm = 0.57 % of d_n.
RECIRCULATING_FIT_RTOL = 0.01


# ---------------------------------------------------------------------------------------------
# standard multi-stage PRSM
# ---------------------------------------------------------------------------------------------
def nut_velocities(params: MechanismParams, screw_speed: float) -> tuple[float, ...]:
    """Axial velocity of every nut, for the ideal motion at a given screw speed.

    Li et al. (2021) Eq. 2: ż_Nk = −θ̇_S / (2π) · Σ_{i≤k} L_Si.  Nut k carries screw k+1 (Eq. 3), and
    all screws turn at θ̇_S (Eq. 1), so the leads add up.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (assumed valid).
    screw_speed : float
        Angular velocity θ̇_S of the screws about +z [rad/s].

    Returns
    -------
    tuple of float
        ż_N1, …, ż_Nn [m/s] in the z convention (negative for positive screw speed).
    """
    factor = -screw_speed / TWO_PI
    out = []
    cumulative_lead = 0.0
    for stage in params.stages:
        cumulative_lead += stage.screw_lead
        out.append(factor * cumulative_lead)
    return tuple(out)


def screw_axial_velocities(params: MechanismParams, screw_speed: float) -> tuple[float, ...]:
    """Axial velocity of every screw, for the ideal motion at a given screw speed.

    Li et al. (2021) Eq. 3: ż_Sk = ż_N(k−1) for k > 1; screw 1 is axially fixed (ż_S1 = 0).

    Parameters
    ----------
    params : MechanismParams
        The mechanism (assumed valid).
    screw_speed : float
        θ̇_S [rad/s].

    Returns
    -------
    tuple of float
        ż_S1, …, ż_Sn [m/s] in the z convention.
    """
    return (0.0,) + nut_velocities(params, screw_speed)[:-1]


def rod_velocity(params: MechanismParams, screw_speed: float) -> float:
    """Extension speed of the rod (the last nut) for a given screw speed.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (assumed valid).
    screw_speed : float
        θ̇_S [rad/s].

    Returns
    -------
    float
        −ż_Nn = θ̇_S Σ L_Si / (2π) [m/s]; positive means extension.
    """
    return screw_speed * params.total_lead / TWO_PI


def rod_displacement(params: MechanismParams, screw_angle: float) -> float:
    """Extension of the rod after the screw has turned through a given angle.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (assumed valid).
    screw_angle : float
        Screw rotation θ_S from the reference position [rad].

    Returns
    -------
    float
        θ_S Σ L_Si / (2π) [m]; positive means extension.
    """
    return screw_angle * params.total_lead / TWO_PI


def ideal_carrier_speed_ratio(stage: StageParams) -> float:
    """Carrier speed per unit screw speed when the rollers roll without slip on both pitch circles.

    Relative to the carrier, pure rolling at the screw–roller pitch point gives
    (θ̇_S − θ̇_P) r_S = −(θ̇_R − θ̇_P) r_R and at the nut–roller pitch point (nut not turning)
    −θ̇_P r_N = (θ̇_R − θ̇_P) r_R; eliminating the roller spin θ̇_R gives
    θ̇_P / θ̇_S = r_S / (r_S + r_N) = r_S / (2 (r_S + r_R)) (the two-stage kinematics article: ω_c = ω_s d_0s / (2 (d_0s + d_0R))).

    Parameters
    ----------
    stage : StageParams
        One stage (the second form holds when r_N = r_S + 2 r_R, which validate() checks).

    Returns
    -------
    float
        θ̇_P / θ̇_S [-].
    """
    return stage.screw_radius / (stage.screw_radius + stage.nut_radius)


def roller_spin_relative_to_carrier_ratio(stage: StageParams) -> float:
    """Roller spin relative to the carrier per unit carrier speed, from rolling on the nut.

    Rolling without slip at the nut–roller pitch point gives (θ̇_R − θ̇_P) r_R = −θ̇_P r_N.
    The two-stage kinematics article's "rotation" ω_R = (d_0s + 2 d_0R) / d_0R · ω_c is the magnitude of this quantity.

    Parameters
    ----------
    stage : StageParams
        One stage.

    Returns
    -------
    float
        (θ̇_R − θ̇_P) / θ̇_P = −r_N / r_R [-].
    """
    return -stage.nut_radius / stage.roller_radius


def roller_absolute_spin_ratio(stage: StageParams) -> float:
    """Absolute roller spin (about the roller's own axis, inertial frame) per unit carrier speed.

    Li et al. (2021) Eq. 5: θ̇_R = −(n_S − 1) θ̇_P.  It equals 1 − r_N / r_R, the value implied by
    :func:`roller_spin_relative_to_carrier_ratio`, exactly when r_N = n_S r_R (the roller then
    rolls on the nut without axial drift), a condition ``StageParams.validate`` enforces.

    Parameters
    ----------
    stage : StageParams
        One stage.

    Returns
    -------
    float
        θ̇_R / θ̇_P = −(n_S − 1) [-].
    """
    return -(stage.screw_starts - 1.0)


@dataclass(frozen=True)
class StageKinematics:
    """Ideal motion of one stage at a given screw speed (every entry SI).

    Attributes
    ----------
    carrier_speed : float
        θ̇_P [rad/s].
    roller_spin_relative : float
        θ̇_R − θ̇_P, roller spin relative to the carrier [rad/s].
    roller_spin : float
        θ̇_R, absolute roller spin about its own axis [rad/s].
    screw_axial_velocity, nut_velocity : float
        ż_S, ż_N in the z convention [m/s].
    """

    carrier_speed: float
    roller_spin_relative: float
    roller_spin: float
    screw_axial_velocity: float
    nut_velocity: float


@dataclass(frozen=True)
class MechanismKinematics:
    """Ideal motion of a whole mechanism at a given screw speed.

    Attributes
    ----------
    screw_speed : float
        θ̇_S [rad/s].
    stages : tuple of StageKinematics
        Stage 1 first.
    rod_velocity : float
        −ż_Nn [m/s], positive = extension.
    """

    screw_speed: float
    stages: tuple[StageKinematics, ...]
    rod_velocity: float


def ideal_kinematics(params: MechanismParams, screw_speed: float) -> MechanismKinematics:
    """Every ideal velocity of a multi-stage PRSM at one screw speed, in one object.

    Parameters
    ----------
    params : MechanismParams
        The mechanism (assumed valid).
    screw_speed : float
        θ̇_S [rad/s].

    Returns
    -------
    MechanismKinematics
        Carrier speeds, roller spins (relative and absolute), screw and nut axial velocities.
    """
    nuts = nut_velocities(params, screw_speed)
    screws = screw_axial_velocities(params, screw_speed)
    stages = []
    for stage, z_s, z_n in zip(params.stages, screws, nuts):
        carrier = ideal_carrier_speed_ratio(stage) * screw_speed
        stages.append(StageKinematics(
            carrier_speed=carrier,
            roller_spin_relative=roller_spin_relative_to_carrier_ratio(stage) * carrier,
            roller_spin=roller_absolute_spin_ratio(stage) * carrier,
            screw_axial_velocity=z_s,
            nut_velocity=z_n,
        ))
    return MechanismKinematics(screw_speed=screw_speed, stages=tuple(stages),
                               rod_velocity=-nuts[-1])


# ---------------------------------------------------------------------------------------------
# recirculating roller screw (the recirculating-screw article)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecirculatingParams:
    """Geometry of a recirculating roller screw: grooved rollers without helix, nut with a
    non-threaded window and a cam ring that resets the rollers (the recirculating-screw article).

    Parameters
    ----------
    screw_diameter, nut_diameter, roller_diameter : float
        Pitch diameters d_s, d_n, d_r [m].
    screw_lead : float
        Lead L of the screw, equal to the nut's (same hand, same starts) [m].
    screw_starts : int
        Thread starts n of screw and nut [-].
    n_rollers : int
        Number of rollers [-].
    name, source : str
        Registry key and citation.
    """

    screw_diameter: float
    nut_diameter: float
    roller_diameter: float
    screw_lead: float
    screw_starts: int
    n_rollers: int
    name: str = "custom"
    source: str = ""

    @property
    def pitch(self) -> float:
        """Thread pitch p = L / n [m], also the spacing of the roller grooves."""
        return self.screw_lead / self.screw_starts

    @property
    def orbit_diameter(self) -> float:
        """Orbit diameter d_c implied by the closed forms, (d_s + d_n) / 2 [m].

        Equal to d_s + d_r and to d_n − d_r when the geometry fits (d_n = d_s + 2 d_r).
        """
        return 0.5 * (self.screw_diameter + self.nut_diameter)

    @property
    def fit_mismatch(self) -> float:
        """Misfit d_n − d_s − 2 d_r of the three pitch diameters [m] (0 for a consistent set)."""
        return self.nut_diameter - self.screw_diameter - 2.0 * self.roller_diameter

    def validate(self) -> "RecirculatingParams":
        """Check every field against its physical range.

        Returns
        -------
        RecirculatingParams
            ``self``.

        Raises
        ------
        ValueError
            Naming the field, its value and the allowed range.
        """
        for f in ("screw_diameter", "nut_diameter", "roller_diameter", "screw_lead"):
            _check_positive(f, getattr(self, f))
        _check_int_at_least("screw_starts", self.screw_starts, 1)
        _check_int_at_least("n_rollers", self.n_rollers, 1)
        if not self.nut_diameter > self.screw_diameter:
            raise ValueError(
                f"nut_diameter = {self.nut_diameter!r} m is out of range: must be > "
                f"screw_diameter = {self.screw_diameter!r} m")
        if abs(self.fit_mismatch) > RECIRCULATING_FIT_RTOL * self.nut_diameter:
            fit = self.screw_diameter + 2.0 * self.roller_diameter
            raise ValueError(
                f"nut_diameter = {self.nut_diameter!r} m is inconsistent with screw_diameter + "
                f"2*roller_diameter = {fit!r} m: must agree within {RECIRCULATING_FIT_RTOL:g} "
                "of nut_diameter")
        return self


def recirculating_carrier_speed(params: RecirculatingParams, screw_speed: float) -> float:
    """Orbital (carrier) speed of the rollers of a recirculating roller screw.

    Pure rolling at both pitch circles, relative to the carrier (Willis):
    (ω_s − ω_c) d_s = −(ω_r − ω_c) d_r and −ω_c d_n = (ω_r − ω_c) d_r, hence
    ω_c = ω_s d_s / (d_s + d_n), i.e. the recirculating-screw article's ω_c = ω_s d_s / (2 d_c) with d_c = (d_s + d_n)/2.

    Parameters
    ----------
    params : RecirculatingParams
        The screw (assumed valid).
    screw_speed : float
        ω_s about +z [rad/s].

    Returns
    -------
    float
        ω_c [rad/s], same sign as ω_s.
    """
    d_s = params.screw_diameter
    return screw_speed * d_s / (d_s + params.nut_diameter)


def recirculating_roller_spin(params: RecirculatingParams, screw_speed: float) -> float:
    """Absolute spin of a roller about its own axis in a recirculating roller screw.

    From rolling on the nut: ω_r = ω_c (1 − d_n / d_r); identical, by construction of ω_c, to
    the recirculating-screw article's ω_r = (d_s/d_r + 1) ω_c − (d_s/d_r) ω_s (rolling on the screw).

    Parameters
    ----------
    params : RecirculatingParams
        The screw (assumed valid).
    screw_speed : float
        ω_s [rad/s].

    Returns
    -------
    float
        ω_r [rad/s], opposite in sign to ω_s.
    """
    return recirculating_carrier_speed(params, screw_speed) * (
        1.0 - params.nut_diameter / params.roller_diameter)


def recirculating_nut_velocity(params: RecirculatingParams, screw_speed: float) -> float:
    """Axial velocity of the nut of a recirculating roller screw.

    The grooved roller follows the screw thread and the nut thread at its azimuth; with equal
    leads of the same hand the carrier angle cancels: ż_n = −ω_s L / (2π), independent of the
    carrier speed (the recirculating-screw article: v_n = n p ω_s / (2π) in magnitude).

    Parameters
    ----------
    params : RecirculatingParams
        The screw (assumed valid).
    screw_speed : float
        ω_s [rad/s].

    Returns
    -------
    float
        ż_n [m/s] in the z convention of Li et al. (2021) (right-handed threads).
    """
    return -screw_speed * params.screw_lead / TWO_PI


def recirculating_nut_displacement(params: RecirculatingParams, screw_angle: float) -> float:
    """Axial displacement of the nut after the screw turned through a given angle.

    Parameters
    ----------
    params : RecirculatingParams
        The screw (assumed valid).
    screw_angle : float
        θ_s [rad].

    Returns
    -------
    float
        z_n − z_n(0) = −θ_s L / (2π) [m].
    """
    return -screw_angle * params.screw_lead / TWO_PI


@dataclass(frozen=True)
class RecirculatingKinematics:
    """Ideal motion of a recirculating roller screw at one screw speed (every entry SI).

    Attributes
    ----------
    screw_speed, carrier_speed, roller_spin : float
        ω_s, ω_c, ω_r (absolute) [rad/s].
    roller_spin_relative : float
        ω_r − ω_c [rad/s].
    nut_velocity : float
        ż_n [m/s].
    roller_drift_velocity : float
        Axial velocity of the rollers relative to the nut, L ω_c / (2π) [m/s]: one lead per
        orbit, which the cam ring takes back in the non-threaded window.
    """

    screw_speed: float
    carrier_speed: float
    roller_spin: float
    roller_spin_relative: float
    nut_velocity: float
    roller_drift_velocity: float


def recirculating_kinematics(params: RecirculatingParams,
                             screw_speed: float) -> RecirculatingKinematics:
    """Every ideal velocity of a recirculating roller screw at one screw speed.

    Parameters
    ----------
    params : RecirculatingParams
        The screw (assumed valid).
    screw_speed : float
        ω_s [rad/s].

    Returns
    -------
    RecirculatingKinematics
    """
    carrier = recirculating_carrier_speed(params, screw_speed)
    spin = recirculating_roller_spin(params, screw_speed)
    return RecirculatingKinematics(
        screw_speed=screw_speed,
        carrier_speed=carrier,
        roller_spin=spin,
        roller_spin_relative=spin - carrier,
        nut_velocity=recirculating_nut_velocity(params, screw_speed),
        roller_drift_velocity=carrier * params.screw_lead / TWO_PI,
    )
