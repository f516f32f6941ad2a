"""The mechanisms the standard FMUs are built from: one FMU per stage count.

=========  ===============================  ==============================================
FMU        parameters (start values)         source
=========  ===============================  ==============================================
PRSM1      ``friction_single_stage``          the friction-torque article's case study, made standard (preset)
PRSM2      ``li2021_two_stage``             Li et al. (2021) §3.1 (preset)
PRSM3      :func:`three_stage`               Li et al.'s (2021) two stages + a third stage below
=========  ===============================  ==============================================

The third stage of PRSM3 is not from a paper.  It continues Li et al.'s (2021) design rule: five
starts, lead 10 mm, 45° flanks, seven rollers, and radii with r_S = 3 r_R (so that
r_N = r_S + 2 r_R = n_S r_R = 5 r_R, the two conditions ``StageParams.validate`` checks).  The
roller radius 9.5 mm makes screw 3 (r_S = 28.5 mm) enclose nut 2 (r_N = 27.5 mm) the way
screw 2 (16.5 mm) encloses nut 1 (16.25 mm); the spline radius 22.5 mm lies between screw 2
and screw 3 as stage 2's 13 mm lies between screws 1 and 2.  Masses scale with r² and
moments of inertia with r⁴ from stage 2 (same axial lengths; s = 9.5 / 5.5), and the carrier
mass follows Li et al.'s (2021) preset convention m_P = J_P / (r_S + r_R)².
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

from prsm_fmu import presets
from prsm_fmu.params import MechanismParams, StageParams

MM = 1e-3


def _third_stage(stage2: StageParams) -> StageParams:
    r_r = 9.5 * MM
    s = r_r / stage2.roller_radius
    r_s, r_n = 3.0 * r_r, 5.0 * r_r
    j_p = stage2.carrier_inertia * s**4
    return replace(
        stage2,
        screw_radius=r_s, roller_radius=r_r, nut_radius=r_n,
        screw_mass=stage2.screw_mass * s**2, nut_mass=stage2.nut_mass * s**2,
        roller_mass=stage2.roller_mass * s**2, carrier_mass=j_p / (r_s + r_r) ** 2,
        screw_inertia=stage2.screw_inertia * s**4, roller_inertia=stage2.roller_inertia * s**4,
        carrier_inertia=j_p, spline_radius=22.5 * MM,
    )


def three_stage() -> MechanismParams:
    """Li et al.'s (2021) two-stage PRSM with a third stage (module docstring), validated."""
    base = presets.load("li2021_two_stage")
    return replace(
        base, stages=base.stages + (_third_stage(base.stages[1]),),
        name="li2021_three_stage",
        source=f"{base.source}; stage 3 extrapolated by fmu_build.mechanisms (not from a paper)",
    ).validate()


#: FMU name -> (function returning the parameters, preset or definition named in the FMU)
FMUS: dict[str, tuple[Callable[[], MechanismParams], str]] = {
    "PRSM1": (lambda: presets.load("friction_single_stage"), "friction_single_stage"),
    "PRSM2": (lambda: presets.load("li2021_two_stage"), "li2021_two_stage"),
    "PRSM3": (three_stage, "li2021_three_stage"),
}
