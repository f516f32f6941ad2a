"""The two-stage kinematics article design checks (prsm_fmu.design_checks) and ``prsm-fmu check``.

Expected values: the two-stage kinematics article's formulas evaluated by hand (σ = 4F/(πd²), the hollow-screw area),
closed forms of column buckling (Euler's loads of uniform columns; the characteristic equation
tan(k_t ℓ_t)·tan(k_b ℓ_b) = k_t/k_b of a fixed–free two-step column), the continuity of the
piecewise critical stress, and the presets' geometry.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from prsm_fmu import presets
from prsm_fmu.cli import main
from prsm_fmu.design_checks import (
    END_FACTORS,
    MATERIALS,
    DesignInputs,
    check_design,
    critical_stress,
    default_load,
    format_report,
    stepped_column_load,
)
from prsm_fmu.params import MechanismParams
from prsm_fmu.presets import friction_article
from text_numbers import number_after  # noqa: E402

E = 206e9


def _check(report, name):
    found = [c for c in report.checks if c.name == name]
    assert len(found) == 1, [c.name for c in report.checks]
    return found[0]


@pytest.mark.parametrize("name", ["li2021_two_stage", "kinematics_two_stage", "assembly_two_stage",
                                  "friction_single_stage"])
def test_every_preset_passes_the_geometric_conditions(name):
    p = presets.load(name)
    report = check_design(p, DesignInputs(axial_load=1000.0, extended_length=0.3))
    for k in range(1, p.n_stages + 1):
        assert _check(report, f"stage {k}: geometric meshing").verdict == "pass"
        assert _check(report, f"stage {k}: lead matching").verdict == "pass"
        gear = _check(report, f"stage {k}: gear engagement")
        assert gear.verdict == "not checked"
        assert f"z_ig = {p.stages[k - 1].screw_starts:g} z_R" in gear.values
    assert report.valid


def test_friction_article_published_set_fails_meshing_and_lead_matching_by_name():
    """The paper's own table (r_n0 = 15 mm, one start) is not a standard PRSM."""
    bad = MechanismParams(stages=(friction_article.published_stage(),), name="friction-torque article as published")
    report = check_design(bad, DesignInputs(teeth=(20, 60)))
    assert not report.valid
    msgs = [c.message for c in report.failures]
    assert any("geometric meshing r_N = r_S + 2 r_R is violated (15 mm ≠ 20 mm)" in m
               for m in msgs)
    assert any("lead matching r_N = n_S r_R is violated" in m and "n_S = 1" in m for m in msgs)
    # z_ig / z_R = 3 = r_N / r_R: the gear condition itself holds for these teeth
    assert _check(report, "stage 1: gear engagement").verdict == "pass"
    text = format_report(report)
    assert "verdict: INVALID" in text and "geometric meshing" in text


def test_gear_engagement_needs_the_thread_ratio():
    p = presets.load("li2021_two_stage")              # n_S = 5: z_ig = 5 z_R
    assert check_design(p, DesignInputs(teeth=(18, 90))).valid
    report = check_design(p, DesignInputs(teeth=(18, 89)))
    bad = _check(report, "stage 1: gear engagement")
    assert bad.failed and "z_ig / z_R = r_N / r_R is violated" in bad.message


def test_strength_follows_kinematics_article_formulas():
    p = presets.load("kinematics_two_stage")               # d_01 = 30 mm, d_02 = 42 mm
    inputs = DesignInputs(axial_load=340e3, material=MATERIALS["carbon_steel"],
                          safety_factor=2.0)
    report = check_design(p, inputs)
    s1 = 4 * 340e3 / (math.pi * 0.030 ** 2)
    s2 = 4 * 340e3 / (math.pi * (0.042 ** 2 - 0.030 ** 2))
    allow = 306e6 / 2.0
    c1, c2 = _check(report, "screw 1: strength (solid)"), _check(report, "screw 2: strength (hollow)")
    # printed with 4 significant digits: rounding moves the value by at most 5e-4 of itself
    assert number_after(c1.values, "σ_1 = ", "MPa") == pytest.approx(s1 / 1e6, rel=5e-4)
    assert number_after(c2.values, "σ_2 = ", "MPa") == pytest.approx(s2 / 1e6, rel=5e-4)
    assert c1.failed and c2.failed and s1 > allow and s2 > allow
    assert "screw 2: strength σ_2 = 4 F_a / (π (d_02² − d_01²)) < [σ] is violated" in c2.message
    # below the allowable load of the weaker section both pass
    f_ok = 0.99 * allow * min(math.pi * 0.030 ** 2 / 4, math.pi * (0.042 ** 2 - 0.030 ** 2) / 4)
    report = check_design(p, DesignInputs(axial_load=f_ok))
    assert not _check(report, "screw 1: strength (solid)").failed
    assert not _check(report, "screw 2: strength (hollow)").failed


def test_a_hollow_screw_without_wall_fails_strength():
    p = presets.load("li2021_two_stage").with_stage(2, screw_radius=0.009)
    report = check_design(p, DesignInputs(axial_load=1000.0, extended_length=0.5))
    c = _check(report, "screw 2: strength (hollow)")
    assert c.failed and "no wall" in c.message
    assert _check(report, "column: buckling (stepped section)").failed


def test_critical_stress_is_piecewise_and_continuous_for_consistent_constants():
    m = MATERIALS["Q235"]
    s, regime = critical_stress(30.0, m)
    assert s == m.yield_strength and regime.startswith("yield")
    s, regime = critical_stress(80.0, m)
    assert s == pytest.approx(m.a - m.b * 80.0) and regime.startswith("intermediate")
    s, regime = critical_stress(150.0, m)
    assert s == pytest.approx(math.pi ** 2 * m.elastic_modulus / 150.0 ** 2)
    assert regime.startswith("Euler")
    for m in MATERIALS.values():
        # the table's λ_s makes a − bλ_s the yield stress (within the table's rounding)
        assert m.a - m.b * m.lambda_s == pytest.approx(m.yield_strength, rel=0.01)


@pytest.mark.parametrize("ends", list(END_FACTORS))
def test_uniform_column_has_eulers_load(ends):
    i, total = 2e-8, 0.8
    p = stepped_column_load([i, i, i], [0.2, 0.3, 0.3], E, ends)
    exact = {"pinned-pinned": 1.0, "fixed-free": 2.0, "fixed-pinned": 0.699155,
             "fixed-fixed": 0.5}[ends]
    assert p == pytest.approx(math.pi ** 2 * E * i / (exact * total) ** 2, rel=1e-5)


def test_stepped_fixed_free_column_solves_the_characteristic_equation():
    i_b, i_t, l_b, l_t = 5e-8, 1e-8, 0.3, 0.5      # base (fixed) stiffer than the tip (free)
    p = stepped_column_load([i_b, i_t], [l_b, l_t], E, "fixed-free")

    def char(load):
        kb, kt = math.sqrt(load / (E * i_b)), math.sqrt(load / (E * i_t))
        return math.tan(kt * l_t) * math.tan(kb * l_b) - kt / kb

    lo = math.pi ** 2 * E * i_t / (4 * (l_b + l_t) ** 2)
    grid = np.linspace(lo, 4 * lo, 4000)
    vals = [char(x) for x in grid]
    root = next(brentq(char, a, b) for a, b, fa, fb in zip(grid, grid[1:], vals, vals[1:])
                if fa * fb < 0 and abs(fa) < 50 and abs(fb) < 50)
    assert p == pytest.approx(root, rel=1e-9)
    # stiffer base: stronger than the uniform tip section, weaker than the uniform base
    assert lo < p < math.pi ** 2 * E * i_b / (4 * (l_b + l_t) ** 2)


def test_buckling_verdict_and_longest_stable_length():
    p = presets.load("li2021_two_stage")
    inp = DesignInputs(axial_load=5000.0)
    c = _check(check_design(p, inp), "column: buckling (stepped section)")
    assert c.verdict == "not checked"
    l_max = float(c.values.split("L ≤ ")[1].split(" m")[0])
    # just inside that length it passes, just beyond it fails, naming the condition
    ok = _check(check_design(p, DesignInputs(axial_load=5000.0, extended_length=0.99 * l_max)),
                "column: buckling (stepped section)")
    bad = _check(check_design(p, DesignInputs(axial_load=5000.0, extended_length=1.01 * l_max)),
                 "column: buckling (stepped section)")
    assert ok.verdict == "pass" and bad.failed
    assert "buckling F_a ≤ F_cr / n_st is violated" in bad.message
    # a longer column buckles in the Euler regime, µ_2 < 1 (screw 2's section is stiffer)
    long_ = _check(check_design(p, DesignInputs(axial_load=100.0, extended_length=3.0)),
                   "column: buckling (stepped section)")
    assert "Euler" in long_.values
    mu2 = float(long_.values.split("µ_2 = ")[1].split(",")[0])
    assert 0.5 < mu2 < 1.0


def test_inputs_out_of_range_are_named():
    p = presets.load("li2021_two_stage")
    with pytest.raises(ValueError, match="safety_factor"):
        check_design(p, DesignInputs(safety_factor=0.5))
    with pytest.raises(ValueError, match="ends"):
        check_design(p, DesignInputs(ends="clamped"))
    with pytest.raises(ValueError, match="section_fractions"):
        check_design(p, DesignInputs(section_fractions=(1.0,)))


def test_default_load_comes_from_the_seed_scenario():
    assert default_load("li2021_two_stage") == 5000.0
    assert default_load("assembly_two_stage") == 7000.0
    assert default_load("friction_single_stage") == 5000.0     # the largest of its load table
    assert default_load("kinematics_two_stage") is None


def test_cli_check_valid_and_invalid(capsys):
    assert main(["check", "li2021_two_stage", "--length", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "verdict: VALID" in out and "PASS" in out
    assert number_after(out, "(axial load: ") == 5000.0     # Li et al. (2021) §3.1: 5000 N
    code = main(["check", "li2021_two_stage", "--set", "stage[2].nut_radius=0.03",
                 "--load", "60000", "--length", "0.5"])
    out = capsys.readouterr().out
    assert code == 1
    assert "verdict: INVALID" in out
    assert "stage 2: geometric meshing r_N = r_S + 2 r_R is violated" in out
    assert "stage 2: lead matching r_N = n_S r_R is violated" in out
    assert "screw 1: strength" in out
    assert main(["check", "no_such_preset"]) == 2
    assert main(["check", "li2021_two_stage", "--set", "load_force=3"]) == 2


def test_cli_check_default_run_does_what_its_help_says(capsys):
    """kinematics_two_stage's scenario has no load: the default run says so, and its verdict lists every
    check it did not do with the option that would do it (the help says the same); li2021's
    scenario load (Li et al. (2021) §3.1: 5000 N on nut 2) is used and checks screw 1's strength:
    σ_1 = 4 F / (π d_01²) = 4 · 5000 / (π · 0.0195²) = 16.74 MPa (r_S1 = 9.75 mm, Li et al. (2021))."""
    assert main(["check", "kinematics_two_stage"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    not_checked = [ln for ln in lines if ln.lstrip().startswith("not checked")]
    assert len(not_checked) == 5                  # 2 gear engagements, 2 strengths, buckling
    assert "paper scenario gives no load" in out
    verdict = out[out.index("verdict:"):]
    for name in ("stage 1: gear engagement", "stage 2: gear engagement",
                 "screw 1: strength", "screw 2: strength", "column: buckling"):
        reason = next(ln for ln in verdict.splitlines() if name in ln)
        assert ("--teeth" if "gear" in name else "--load") in reason, reason
    assert main(["check", "--help"]) == 0
    help_text = " ".join(capsys.readouterr().out.split())
    assert "kinematics_two_stage's scenario has none" in help_text and "needs --teeth" in help_text
    assert main(["check", "li2021_two_stage"]) == 0
    out = capsys.readouterr().out
    assert number_after(out, "(axial load: ") == 5000.0 and " N, the largest load" in out
    # σ_1 by hand (docstring): 16.742 MPa; printed with 4 significant digits (rel 5e-4)
    assert number_after(out, "σ_1 = ", "MPa") == pytest.approx(4 * 5000 / (math.pi * 0.0195 ** 2) / 1e6,
                                                        rel=5e-4)


@pytest.mark.parametrize("value, name, allowed", [
    ("stage[1].screw_radius=-1", "stage[1].screw_radius", "in (0, "),
    ("stage[2].nut_mass=0", "stage[2].nut_mass", "in (0, "),
    ("stage[1].flank_angle=1.6", "stage[1].flank_angle", "(0, pi/2)"),
    ("stage[1].screw_starts=0", "stage[1].screw_starts", "an integer in [1, "),
    ("mu_spline=2", "mu_spline", "[0, 1)"),
])
def test_cli_check_set_values_are_validated_like_the_parameters(value, name, allowed, capsys):
    """A --set value out of its parameter's range is refused in one line naming it and the
    range, before any check is printed (a negative radius used to print d = −2000 mm)."""
    assert main(["check", "kinematics_two_stage", "--set", value]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and name in err[0] and allowed in err[0] and "--set" in err[0]
    # a value in range that breaks the meshing is graded, not refused
    assert main(["check", "kinematics_two_stage", "--set", "stage[1].nut_radius=0.03"]) == 1
    assert "geometric meshing r_N = r_S + 2 r_R is violated" in capsys.readouterr().out
