"""The two-stage kinematics article: the two-stage PRSM whose kinematics were checked against an ADAMS model.

Source: the two-stage kinematics article — "Theoretical Kinematic Model" (ω_c, ω_R, v_N formulas)
and "Simulation Results and Validation" (leads L_S1 = L_S2 = 20 mm = 5 starts × 4 mm pitch,
800°/s input, ADAMS contact friction µ_s = 0.23 / µ_d = 0.16, theory column: carriers 300°/s,
roller rotation 1500°/s, v_N1 = 44.44 mm/s, v_N2 = 88.88 mm/s).  Converted to SI.

The paper gives no radii, masses or inertias.  Assumptions:

* Radii.  ω_c = ω_s d_0s / (2 (d_0s + d_0R)) = 300°/s at ω_s = 800°/s requires r_S = 3 r_R; a
  standard roller screw with n_S = 5 then has r_N = 5 r_R (= r_S + 2 r_R = n_S r_R), which is
  also what the 1500°/s = (r_N / r_R) · 300°/s roller rotation implies.  We choose
  r_R1 = 5 mm (r_S1 = 15, r_N1 = 25 mm) and, for the larger hollow screw that slides over the
  hexagonal end of screw 1, r_R2 = 7 mm (r_S2 = 21, r_N2 = 35 mm).
* Flank angle 45° (Li et al.'s (2021) value; the two-stage kinematics article gives none).  10 rollers per stage (the ADAMS
  model kept 2 of them), 2 carriers per stage.
* Masses and inertias: steel solids (ρ = 7850 kg/m³) of the sizes in :data:`SOLIDS`: rollers
  are solid cylinders of radius r_R; screw 1 a solid cylinder of radius r_S1; screw 2 a tube
  r_S1 … r_S2 (its bore takes the hexagon of screw 1); nuts tubes r_N … r_N + wall; carriers
  flat rings r_S … r_N.  Axial inertia of a tube: J = m (r_in² + r_out²) / 2.
* Friction: the ADAMS contacts used µ_d = 0.16, taken for the screw–roller contact; the
  screw 1 – screw 2 coupling and the thrust bearings were ideal joints in ADAMS, so
  µ_SS = µ_NS = 0.  The hexagon's mean radius, r_SS2 = 13 mm, is given for completeness.
* The scenario: 800°/s = 40π/9 rad/s for 1 s (:data:`SCENARIO`).  The 340 kN load of the ADAMS
  run was applied to the two-roller model; the text does not say what it corresponds to for ten
  rollers, so the scenario leaves the load out.
"""

from __future__ import annotations

import math

from ..params import MechanismParams, StageParams
from .units import MM

STEEL_DENSITY = 7850.0  # kg/m³

#: the two-stage kinematics article's kinematic check: screw speed [rad/s] and duration [s]
SCENARIO = {"screw_speed": 40.0 * math.pi / 9.0, "t_end": 1.0}

#: sizes of the steel solids behind the masses and inertias [m], per stage
SOLIDS = {
    1: {"roller_length": 40 * MM, "screw_length": 250 * MM, "screw_bore": 0.0,
        "nut_length": 50 * MM, "nut_wall": 10 * MM, "carrier_thickness": 5 * MM},
    2: {"roller_length": 48 * MM, "screw_length": 200 * MM, "screw_bore": 15 * MM,
        "nut_length": 60 * MM, "nut_wall": 12 * MM, "carrier_thickness": 6 * MM},
}


def _steel_tube(r_in: float, r_out: float, length: float) -> tuple[float, float]:
    """Mass [kg] and axial moment of inertia [kg·m²] of a steel tube (r_in = 0: a cylinder)."""
    mass = STEEL_DENSITY * math.pi * (r_out**2 - r_in**2) * length
    return mass, 0.5 * mass * (r_in**2 + r_out**2)


def _stage(k: int, r_r: float, spline_radius: float) -> StageParams:
    r_s, r_n = 3.0 * r_r, 5.0 * r_r
    size = SOLIDS[k]
    m_r, j_r = _steel_tube(0.0, r_r, size["roller_length"])
    m_s, j_s = _steel_tube(size["screw_bore"], r_s, size["screw_length"])
    m_n, _ = _steel_tube(r_n, r_n + size["nut_wall"], size["nut_length"])
    m_p, j_p = _steel_tube(r_s, r_n, size["carrier_thickness"])
    return StageParams(
        screw_radius=r_s, roller_radius=r_r, nut_radius=r_n,
        screw_lead=20.0 * MM, screw_starts=5, flank_angle=math.radians(45.0), n_rollers=10,
        screw_mass=m_s, nut_mass=m_n, roller_mass=m_r, carrier_mass=m_p,
        screw_inertia=j_s, roller_inertia=j_r, carrier_inertia=j_p,
        spline_radius=spline_radius, bearing_radius=0.0, carriers=2,
    )


def two_stage() -> MechanismParams:
    """The two-stage kinematics article's two-stage PRSM with the radii and steel-solid masses stated in the docstring.

    Returns
    -------
    MechanismParams
        SI parameters (validate() is called by the registry).
    """
    return MechanismParams(
        stages=(_stage(1, 5.0 * MM, 0.0), _stage(2, 7.0 * MM, 13.0 * MM)),
        mu_screw_roller=0.16, mu_spline=0.0, mu_nut_screw=0.0,
        name="kinematics_two_stage",
        source="the two-stage kinematics article (Theoretical Kinematic Model; Simulation Results)",
    )


PRESETS = {"kinematics_two_stage": two_stage}
