"""Every value of the two-stage kinematics article's and the friction-torque article's presets
against a literal worked out by hand from the paper's dimensions (or, where the paper gives
none, the stated solids) and materials.

Li et al. (2021) §3.1 and the assembly article are checked the same way in tests/test_presets.py;
the recirculating-screw article's table 2 too.  Nothing here reads the preset modules' own
tables: each expected value is a number in this file, with its arithmetic.

Steel ρ = 7850 kg/m³.  A solid cylinder of radius r and length L: m = ρ π r² L, J = m r²/2; a
tube r_i … r_o: m = ρ π (r_o² − r_i²) L, J = m (r_i² + r_o²)/2.  (A factor ½ → 1 in J doubles
every inertia below and fails the test.)
"""

from __future__ import annotations

import math

import pytest

from prsm_fmu import presets

REL = 1e-5          # the literals carry 6 significant digits


def _check(obj, expected: dict) -> None:
    for field, value in expected.items():
        got = getattr(obj, field)
        if isinstance(value, int) and not isinstance(value, bool):
            assert got == value, field
        else:
            assert got == pytest.approx(value, rel=REL, abs=1e-15), field


# ---- the two-stage kinematics article (kinematics_two_stage) ----------------------------------------
# The article gives leads L_S1 = L_S2 = 20 mm = 5 starts × 4 mm pitch, and (through its ADAMS
# theory column, carriers 300°/s at 800°/s, rollers 1500°/s) r_S = 3 r_R and r_N = 5 r_R.  No
# radii, masses or inertias: the preset takes r_R1 = 5 mm, r_R2 = 7 mm and steel solids of
# stated sizes (stage 1: roller 40 mm long, screw 250 mm, nut 50 mm long with a 10 mm wall,
# carrier 5 mm thick; stage 2: roller 48 mm, hollow screw 200 mm with a 15 mm bore, nut 60 mm
# with a 12 mm wall, carrier 6 mm).

def test_two_stage_kinematics_article_stage_1_by_hand():
    s1 = presets.load("kinematics_two_stage").stages[0]
    _check(s1, {
        # r_R1 = 5 mm, r_S1 = 3 × 5 = 15 mm, r_N1 = 5 × 5 = 25 mm
        "roller_radius": 0.005, "screw_radius": 0.015, "nut_radius": 0.025,
        "screw_lead": 0.020, "screw_starts": 5,          # 5 × 4 mm = 20 mm
        "flank_angle": math.pi / 4, "n_rollers": 10, "carriers": 2,
        "spline_radius": 0.0, "bearing_radius": 0.0,
        # roller: m = 7850 π (0.005)² (0.040) = 7850 π × 1e-6 = 0.0246615 kg
        #         J = 0.0246615 × 0.005² / 2 = 0.0246615 × 1.25e-5 = 3.08269e-7 kg·m²
        "roller_mass": 0.0246615, "roller_inertia": 3.08269e-7,
        # screw 1 (solid): m = 7850 π (0.015)² (0.25) = 7850 π × 5.625e-5 = 0.4415625 π
        #         = 1.38721 kg;  J = 1.38721 × 0.015² / 2 = 1.38721 × 1.125e-4 = 1.56061e-4
        "screw_mass": 1.38721, "screw_inertia": 1.56061e-4,
        # nut: m = 7850 π (0.035² − 0.025²)(0.05) = 7850 π × 6e-4 × 0.05 = 0.2355 π = 0.739845 kg
        "nut_mass": 0.739845,
        # carrier ring 15 … 25 mm, 5 mm: m = 7850 π (0.025² − 0.015²)(0.005) = 7850 π × 2e-6
        #         = 0.0157 π = 0.0493230 kg;  J = 0.0493230 × (0.015² + 0.025²)/2
        #         = 0.0493230 × 4.25e-4 = 2.09623e-5 kg·m²
        "carrier_mass": 0.0493230, "carrier_inertia": 2.09623e-5,
    })


def test_two_stage_kinematics_article_stage_2_by_hand():
    s2 = presets.load("kinematics_two_stage").stages[1]
    _check(s2, {
        # r_R2 = 7 mm, r_S2 = 21 mm, r_N2 = 35 mm; the hexagon's mean radius 13 mm
        "roller_radius": 0.007, "screw_radius": 0.021, "nut_radius": 0.035,
        "screw_lead": 0.020, "screw_starts": 5,
        "flank_angle": math.pi / 4, "n_rollers": 10, "carriers": 2,
        "spline_radius": 0.013, "bearing_radius": 0.0,
        # roller: m = 7850 π (0.007)² (0.048) = 7850 π × 2.352e-6 = 0.0184632 π = 0.0580039 kg
        #         J = 0.0580039 × 0.007² / 2 = 0.0580039 × 2.45e-5 = 1.42109e-6 kg·m²
        "roller_mass": 0.0580039, "roller_inertia": 1.42109e-6,
        # screw 2 (tube 15 … 21 mm, 200 mm): m = 7850 π (0.021² − 0.015²)(0.2)
        #         = 7850 π × 2.16e-4 × 0.2 = 0.33912 π = 1.06538 kg
        #         J = 1.06538 × (0.015² + 0.021²)/2 = 1.06538 × 3.33e-4 = 3.54771e-4 kg·m²
        "screw_mass": 1.06538, "screw_inertia": 3.54771e-4,
        # nut 35 … 47 mm, 60 mm: m = 7850 π (0.047² − 0.035²)(0.06) = 7850 π × 9.84e-4 × 0.06
        #         = 0.463464 π = 1.45602 kg
        "nut_mass": 1.45602,
        # carrier ring 21 … 35 mm, 6 mm: m = 7850 π (0.035² − 0.021²)(0.006)
        #         = 7850 π × 7.84e-4 × 0.006 = 0.0369264 π = 0.116008 kg
        #         J = 0.116008 × (0.021² + 0.035²)/2 = 0.116008 × 8.33e-4 = 9.66344e-5 kg·m²
        "carrier_mass": 0.116008, "carrier_inertia": 9.66344e-5,
    })


def test_two_stage_kinematics_article_friction():
    p = presets.load("kinematics_two_stage")
    # ADAMS contact friction µ_d = 0.16 at the screw–roller threads; ideal joints elsewhere
    assert (p.mu_screw_roller, p.mu_spline, p.mu_nut_screw) == (0.16, 0.0, 0.0)
    assert (p.mu_viscous, p.mu_differential) == (0.0, 0.0)


# ---- the friction-torque article (friction_single_stage) -----------------------------------------
# Its case-study table: r_s0 = 0.01 m, r_r0 = 0.005 m, r_n0 = 0.015 m, p = 0.002 m, z_s = 1,
# n_R = 5, n_t = 10, µ_1 = 0.001 N·s/m, µ_2 = 0.05, µ_3 = 1e-6 m, m_N = 0.5 kg, m_R = 0.1 kg,
# m_c = 0.2 kg, m_s = 1.0 kg, β = 45°.  Made standard (preset docstring): n_S = 4 so that
# r_S = (n_S − 2) r_R = 2 × 5 = 10 mm, r_N = n_S r_R = 4 × 5 = 20 mm, lead 4 × 2 mm = 8 mm.
# No inertias in the article: screw and rollers solid cylinders, the carrier a thin ring at the
# orbit radius r_s0 + r_r0 = 15 mm.

def test_friction_torque_article_stage_by_hand():
    (s,) = presets.load("friction_single_stage").stages
    _check(s, {
        "screw_radius": 0.010, "roller_radius": 0.005, "nut_radius": 0.020,
        "screw_lead": 0.008, "screw_starts": 4,          # 4 × 2 mm
        "flank_angle": math.pi / 4, "n_rollers": 5, "carriers": 1,
        "threads_per_roller": 10,
        "screw_mass": 1.0, "nut_mass": 0.5, "roller_mass": 0.1, "carrier_mass": 0.2,
        # screw: J = 1.0 × 0.010² / 2 = 5.0e-5 kg·m²
        "screw_inertia": 5.0e-5,
        # roller: J = 0.1 × 0.005² / 2 = 0.1 × 1.25e-5 = 1.25e-6 kg·m²
        "roller_inertia": 1.25e-6,
        # carrier: J = 0.2 × 0.015² = 0.2 × 2.25e-4 = 4.5e-5 kg·m²
        "carrier_inertia": 4.5e-5,
    })
    assert s.pitch == pytest.approx(0.002, rel=1e-12)


def test_friction_torque_article_friction():
    p = presets.load("friction_single_stage")
    assert p.mu_screw_roller == 0.05            # µ_2, spin sliding
    assert p.mu_viscous == 0.001                # µ_1 [N·s/m] per engaged thread
    assert p.mu_differential == 1e-6            # µ_3 [m]
    assert (p.mu_spline, p.mu_nut_screw) == (0.0, 0.0)     # one stage: no spline, no bearing


# ---- Li et al. (2021) and the assembly article: the values tests/test_presets.py leaves out -------
# (their masses, inertias and radii are checked there; here the rest, each from its paper or the
# preset docstring's stated assumption)

def test_li2021_remaining_values():
    p = presets.load("li2021_two_stage")
    # §3.2's smallest pair as the base case, µ_NS = 0 (§2.2 ignores the thrust bearings)
    assert (p.mu_screw_roller, p.mu_spline, p.mu_nut_screw) == (0.1, 0.2, 0.0)
    s1, s2 = p.stages
    _check(s1, {"screw_mass": 0.051,       # unused (screw 1 does not translate): the assembly
                                           # article's m_S1
                "spline_radius": 0.0, "bearing_radius": 0.0, "carriers": 2,
                "threads_per_roller": 1})
    _check(s2, {"bearing_radius": 0.0, "carriers": 2, "threads_per_roller": 1})


def test_assembly_article_remaining_values():
    p = presets.load("assembly_two_stage")
    s1, s2 = p.stages
    # its geometry table = Li et al. (2021) §3.1's: r_S 9.75 / 16.5 mm, r_R 3.25 / 5.5 mm,
    # r_N 16.25 / 27.5 mm, L_S = 10 mm (5 starts × 2 mm), 7 rollers; β = 45° from Li et al.
    for s, (r_s, r_r, r_n) in ((s1, (0.00975, 0.00325, 0.01625)),
                               (s2, (0.0165, 0.0055, 0.0275))):
        _check(s, {"screw_radius": r_s, "roller_radius": r_r, "nut_radius": r_n,
                   "screw_lead": 0.010, "screw_starts": 5, "n_rollers": 7,
                   "flank_angle": math.pi / 4, "carriers": 2, "threads_per_roller": 1})
    # thrust bearing nut 1 – screw 2 at the nut 1 pitch radius 16.25 mm (assumed); none after 2
    _check(s1, {"bearing_radius": 0.01625, "spline_radius": 0.0})
    _check(s2, {"bearing_radius": 0.0})
