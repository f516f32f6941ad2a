"""The friction-torque article: the single-stage PRSM of the dynamic friction-torque and efficiency study.

Source: the friction-torque article — the parameter table of the case study (radii, pitch,
starts, rollers, thread pitches per roller, friction coefficients µ_1, µ_2, µ_3, masses, flank
angle, contact offset angles) and the kinetic energy (one carrier).  :data:`PUBLISHED` holds
that table in SI units; :func:`published_stage` builds a :class:`StageParams` from it without
validating it.

The published set is not a standard roller screw, and ``StageParams.validate`` rejects it:
with a single-start screw and r_s0 = 2 r_r0, the nut radius r_n0 = 15 mm differs from
r_s0 + 2 r_r0 = 20 mm (the rollers would not fit between screw and nut; 15 mm is the roller
orbit radius r_s0 + r_r0), and a single-start roller of lead p stays engaged with a nut of
radius r_N only if r_N = n_S r_R, i.e. 5 mm for n_S = 1.

The registered preset ``friction_single_stage`` is the nearest standard PRSM: it keeps
r_s0 = 10 mm, r_r0 = 5 mm, the 2 mm pitch, β = 45°, 5 rollers and the masses, and sets n_S = 4
(the starts for which r_S = (n_S − 2) r_R), hence lead 8 mm, and r_N = 20 mm (= r_S + 2 r_R =
n_S r_R).  Its ideal carrier ratio r_S / (r_S + r_N) is 1/3; the roller spin ratio −(n_S − 1) = −3
replaces the paper's G = −(r_n0 − r_r0) / r_r0 = −2.

Assumptions, because the friction-torque article does not give the numbers:

* Moments of inertia: the screw and each roller as solid cylinders of their nominal radius,
  J = m r² / 2; the one carrier as a thin ring at the orbit radius, J = m_c (r_s0 + r_r0)².
* Friction: the friction-torque article's three terms with its values: µ_2 = 0.05 (spin sliding) is the
  screw–roller Coulomb coefficient, µ_1 = 0.001 N·s/m the viscous coefficient per engaged
  thread with n_t = 10 threads per roller, µ_3 = 1e-6 m the differential-sliding coefficient; a
  single stage has no spline and no thrust bearing to a next stage.
"""

from __future__ import annotations

import math

from ..params import MechanismParams, StageParams

#: the friction-torque article's parameter table, SI units (lengths m, masses kg, angles rad, µ_1 N·s/m, µ_3 m)
PUBLISHED = {
    "screw_radius": 0.01,
    "roller_radius": 0.005,
    "nut_radius": 0.015,
    "pitch": 0.002,
    "screw_starts": 1,
    "n_rollers": 5,
    "thread_pitches_per_roller": 10,
    "mu_viscous": 0.001,
    "mu_sliding": 0.05,
    "mu_differential": 1e-6,
    "nut_mass": 0.5,
    "roller_mass": 0.1,
    "carrier_mass": 0.2,
    "screw_mass": 1.0,
    "flank_angle": math.radians(45.0),
    "contact_offset_angles": (math.radians(5.0), math.radians(5.0)),
}

#: the friction-torque article's scenarios: steady check at 1 rad/s and 100 N; ramps 0 → 1 rad/s
SCENARIO = {"screw_speed": 1.0, "load_force": 100.0,
            "ramp_loads": (500.0, 1000.0, 3000.0, 5000.0), "ramp_time": 0.02,
            "ramp_times_at_1000N": (0.01, 0.03, 0.06, 0.09)}


def _stage(nut_radius: float, screw_starts: int) -> StageParams:
    p = PUBLISHED
    r_s, r_r = p["screw_radius"], p["roller_radius"]
    return StageParams(
        screw_radius=r_s, roller_radius=r_r, nut_radius=nut_radius,
        screw_lead=screw_starts * p["pitch"], screw_starts=screw_starts,
        flank_angle=p["flank_angle"], n_rollers=p["n_rollers"],
        screw_mass=p["screw_mass"], nut_mass=p["nut_mass"], roller_mass=p["roller_mass"],
        carrier_mass=p["carrier_mass"],
        screw_inertia=0.5 * p["screw_mass"] * r_s**2,
        roller_inertia=0.5 * p["roller_mass"] * r_r**2,
        carrier_inertia=p["carrier_mass"] * (r_s + r_r) ** 2,
        carriers=1,
        threads_per_roller=p["thread_pitches_per_roller"],
    )


def published_stage() -> StageParams:
    """The friction-torque article's published stage exactly as printed (r_n0 = 15 mm, one start), not validated.

    Returns
    -------
    StageParams
        Fails ``validate()`` on ``nut_radius``; kept to show why the preset differs.
    """
    return _stage(PUBLISHED["nut_radius"], PUBLISHED["screw_starts"])


def single_stage() -> MechanismParams:
    """The nearest standard PRSM to the friction-torque article's set: n_S = 4, lead 8 mm, r_N = 20 mm.

    Returns
    -------
    MechanismParams
        SI parameters (validate() is called by the registry).
    """
    starts = 4
    nut_radius = starts * PUBLISHED["roller_radius"]
    return MechanismParams(
        stages=(_stage(nut_radius, starts),),
        mu_screw_roller=PUBLISHED["mu_sliding"], mu_spline=0.0, mu_nut_screw=0.0,
        mu_viscous=PUBLISHED["mu_viscous"], mu_differential=PUBLISHED["mu_differential"],
        name="friction_single_stage",
        source="the friction-torque article (case-study parameter table), made standard: "
               "n_S = 4, r_N = 20 mm",
    )


PRESETS = {"friction_single_stage": single_stage}
