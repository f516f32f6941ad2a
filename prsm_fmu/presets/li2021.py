"""Li et al. (2021) §3.1: the two-stage PRSM example of the multi-stage rigid-body Lagrange model.

Source: Li et al. (2021) §3.1 (geometry, masses, inertias, spline radius) and §3.2
(friction coefficients).  Converted to SI (``units.py``): mm → m, kg·mm² → kg·m² (× 1e-6).

Assumptions, each because the text does not give the number:

* Friction coefficients of the base case.  §3.1 gives none; §3.2 studies µ_SR ∈ {0.1, 0.2} and
  µ_SS ∈ {0.2, 0.3}.  We take the smallest pair of that study, µ_SR = 0.1 and µ_SS = 0.2, as the
  base case; with it the model reproduces the §3.1 figures (settling times about 0.14 / 0.46 ms,
  efficiency < 0.45 → ≈ 0.80; docs/paper_comparison.md, tests/test_li2021_paper.py).
* Thrust-bearing (nut–screw) friction is ignored in Li et al. (2021) (§2.2), so µ_NS = 0.
* The screw mass of stage 1 does not enter the dynamics (screw 1 does not translate); the value of
  the multi-stage assembly article (0.051 kg) is used so that the preset validates.
* Carrier masses are not given.  A carrier ring whose radius of gyration is the roller orbit
  radius r_S + r_R has m_P = J_P / (r_S + r_R)²; we use that estimate (0.0178 kg and 0.0248 kg).
  They enter only the axial kinetic energy 2 m_P ż_N², which is < 1 % of the nut's.
* "β_S2 = 45 mm" in the text is a typo for 45°.
"""

from __future__ import annotations

import math

from ..params import MechanismParams, StageParams
from .units import MM, KG_MM2


#: the Li et al. (2021) §3.1 operating point (not part of the parameters): screw speed [rad/s], load [N]
SCENARIO = {"screw_speed": 100.0, "load_force": 5000.0, "t_end": 1e-3}


def _stage1() -> StageParams:
    r_s, r_r = 9.75 * MM, 3.25 * MM
    j_p = 3.0 * KG_MM2
    return StageParams(
        screw_radius=r_s, roller_radius=r_r, nut_radius=16.25 * MM,
        screw_lead=10.0 * MM, screw_starts=5, flank_angle=math.radians(45.0), n_rollers=7,
        screw_mass=0.051, nut_mass=2.5, roller_mass=0.017, carrier_mass=j_p / (r_s + r_r) ** 2,
        screw_inertia=55.0 * KG_MM2, roller_inertia=0.08 * KG_MM2, carrier_inertia=j_p,
    )


def _stage2() -> StageParams:
    r_s, r_r = 16.5 * MM, 5.5 * MM
    j_p = 12.0 * KG_MM2
    return StageParams(
        screw_radius=r_s, roller_radius=r_r, nut_radius=27.5 * MM,
        screw_lead=10.0 * MM, screw_starts=5, flank_angle=math.radians(45.0), n_rollers=7,
        screw_mass=0.77, nut_mass=18.0, roller_mass=0.04, carrier_mass=j_p / (r_s + r_r) ** 2,
        screw_inertia=170.0 * KG_MM2, roller_inertia=0.48 * KG_MM2, carrier_inertia=j_p,
        spline_radius=13.0 * MM,
    )


def two_stage() -> MechanismParams:
    """Li et al. (2021) §3.1 two-stage PRSM with the base-case friction stated in the module docstring."""
    return MechanismParams(
        stages=(_stage1(), _stage2()),
        mu_screw_roller=0.1, mu_spline=0.2, mu_nut_screw=0.0,
        name="li2021_two_stage",
        source="Li et al. (2021) §3.1 (friction: §3.2)",
    ).validate()


PRESETS = {"li2021_two_stage": two_stage}
