"""Presets: every registered parameter set loads, validates and carries the papers' numbers;
invalid parameters are rejected with a message that names the field and its allowed range."""

from __future__ import annotations

import dataclasses
import importlib
import math
from pathlib import Path

import pytest

from prsm_fmu import presets
from prsm_fmu.kinematics import RecirculatingParams
from prsm_fmu.params import MechanismParams, StageParams
from prsm_fmu.presets import assembly_article, friction_article



def _reference_short_names() -> tuple[str, ...]:
    """The short names of docs/references.md's table (its first column), the names the
    documentation, the code and the presets cite the papers by."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "references.md").read_text("utf-8")
    rows = [line.split("|")[1].strip() for line in text.splitlines() if line.startswith("| ")]
    return tuple(name for name in rows if name and name != "short name")


SHORT_NAMES = _reference_short_names()


def _cites_a_paper(text: str) -> bool:
    return any(name.lower() in text.lower() for name in SHORT_NAMES)


def test_references_table_has_the_five_papers():
    # docs/references.md: Li et al. (2021) and four technical articles
    assert len(SHORT_NAMES) == 5, SHORT_NAMES


# ---- registry -------------------------------------------------------------------------------
def test_registry_lists_one_key_per_source_sorted():
    assert presets.names() == ("assembly_two_stage", "friction_single_stage", "kinematics_two_stage",
                               "li2021_two_stage", "recirculating_screw")


@pytest.mark.parametrize("name", presets.names())
def test_every_preset_loads_validates_and_cites_its_paper(name):
    params = presets.load(name)
    assert isinstance(params, (MechanismParams, RecirculatingParams))
    assert params.validate() is params
    assert params.name == name
    assert _cites_a_paper(params.source), params.source


@pytest.mark.parametrize("module_name", presets.MODULES)
def test_every_preset_module_docstring_cites_its_paper(module_name):
    module = importlib.import_module(f"prsm_fmu.presets.{module_name}")
    assert _cites_a_paper(module.__doc__ or "")
    assert set(module.PRESETS) <= set(presets.names())


def test_unknown_preset_is_a_value_error_listing_the_known_names():
    with pytest.raises(ValueError) as info:
        presets.load("no_such_machine")
    for name in presets.names():
        assert name in str(info.value)


# ---- validation rules, one per case ----------------------------------------------------------
def _bad_stage(k: int, **changes):
    return presets.load("assembly_two_stage").with_stage(k, **changes)


def _bad_mechanism(**changes):
    return presets.load("assembly_two_stage").with_changes(**changes)


POSITIVE_STAGE_FIELDS = ("screw_radius", "roller_radius", "nut_radius", "screw_lead",
                         "screw_mass", "nut_mass", "roller_mass", "carrier_mass",
                         "screw_inertia", "roller_inertia", "carrier_inertia")

CASES = [
    # "(0, ": the open lower end, > 0 (param_ranges' interval notation)
    *[pytest.param(_bad_stage(1, **{f: v}), f"stage[1].{f}", "in (0, ", id=f"{f}={v}")
      for f in POSITIVE_STAGE_FIELDS for v in (0.0, -1e-3)],
    pytest.param(_bad_stage(2, nut_mass=float("nan")), "stage[2].nut_mass", "in (0, ",
                 id="nut_mass=nan"),
    pytest.param(_bad_stage(1, screw_starts=0), "stage[1].screw_starts", "an integer in [1, ",
                 id="starts=0"),
    pytest.param(_bad_stage(1, n_rollers=0), "stage[1].n_rollers", "an integer in [1, ",
                 id="rollers=0"),
    pytest.param(_bad_stage(1, carriers=0), "stage[1].carriers", "an integer in [1, 2]",
                 id="carriers=0"),
    *[pytest.param(_bad_stage(2, flank_angle=v), "stage[2].flank_angle", "(0, pi/2)",
                   id=f"flank={v:.3f}") for v in (0.0, -0.1, math.pi / 2, 2.0)],
    *[pytest.param(_bad_mechanism(**{f: v}), f, "[0, 1)", id=f"{f}={v}")
      for f in ("mu_screw_roller", "mu_spline", "mu_nut_screw") for v in (-0.01, 1.0)],
    pytest.param(_bad_stage(1, nut_radius=17.0e-3), "stage[1].nut_radius",
                 "screw_radius + 2*roller_radius", id="nut_radius_does_not_fit"),
    pytest.param(_bad_stage(2, screw_starts=4, screw_lead=8.0e-3), "stage[2].nut_radius",
                 "screw_starts*roller_radius", id="nut_radius_not_starts_times_roller"),
    # stage 2's screw pitch radius is 16.5 mm: the spline radius must lie in
    # [16.5 mm / 100, 16.5 mm] = [0.000165, 0.0165] m (internal teeth in the screw's bore)
    *[pytest.param(_bad_stage(2, spline_radius=v), "stage[2].spline_radius",
                   "in [0.000165, 0.0165] m", id=f"spline_radius={v}")
      for v in (0.0, 1e-30, 0.000164, 0.0166)],
    # a friction coefficient is reported as itself, not as the radius its check depends on
    pytest.param(_bad_mechanism(mu_nut_screw=math.inf), "mu_nut_screw", "[0, 1)",
                 id="mu_nut_screw=inf"),
    pytest.param(_bad_stage(1, bearing_radius=0.0), "stage[1].bearing_radius", "in (0, ",
                 id="bearing_radius_missing"),
    pytest.param(_bad_mechanism(stages=()), "stages", "at least 1", id="zero_stages"),
]


@pytest.mark.parametrize(("params", "field", "allowed"), CASES)
def test_invalid_parameter_is_rejected_naming_field_and_range(params, field, allowed):
    with pytest.raises(ValueError) as info:
        params.validate()
    message = str(info.value)
    assert message.startswith(field + " = "), message
    assert allowed in message, message


RECIRCULATING_CASES = [
    *[pytest.param({f: v}, f, "> 0", id=f"{f}={v}")
      for f in ("screw_diameter", "nut_diameter", "roller_diameter", "screw_lead")
      for v in (0.0, -1.0)],
    pytest.param({"screw_starts": 0}, "screw_starts", ">= 1", id="starts=0"),
    pytest.param({"n_rollers": 0}, "n_rollers", ">= 1", id="rollers=0"),
    pytest.param({"nut_diameter": 30e-3, "roller_diameter": 1e-3}, "nut_diameter",
                 "> screw_diameter", id="nut_inside_screw"),
    pytest.param({"roller_diameter": 6.63e-3 / 2}, "nut_diameter",
                 "screw_diameter + 2*roller_diameter", id="radius_typed_for_diameter"),
]


@pytest.mark.parametrize(("changes", "field", "allowed"), RECIRCULATING_CASES)
def test_invalid_recirculating_parameter_is_rejected_naming_field_and_range(changes, field,
                                                                            allowed):
    params = dataclasses.replace(presets.load("recirculating_screw"), **changes)
    with pytest.raises(ValueError) as info:
        params.validate()
    assert str(info.value).startswith(field + " = "), str(info.value)
    assert allowed in str(info.value)


# ---- the papers' numbers ---------------------------------------------------------------------
def _assert_stage_values(stage, expected: dict) -> None:
    for field, value in expected.items():
        assert getattr(stage, field) == pytest.approx(value, rel=1e-12), field


def test_li2021_preset_holds_section_3_1_in_si():
    # Li et al. (2021) §3.1.  Lengths: 1 mm = 1e-3 m.  Inertias: 1 kg·mm² =
    # 1 kg × (1e-3 m)² = 1e-6 kg·m², so e.g. J_S1 = 55 kg·mm² = 55e-6 kg·m² = 5.5e-5 kg·m².
    s1, s2 = presets.load("li2021_two_stage").stages
    _assert_stage_values(s1, {
        "screw_radius": 9.75e-3, "roller_radius": 3.25e-3, "nut_radius": 16.25e-3,
        "screw_lead": 10e-3, "screw_starts": 5, "n_rollers": 7,
        "flank_angle": math.pi / 4,                            # β_S1 = 45°
        "roller_mass": 0.017, "nut_mass": 2.5,                 # m_R1, m_N1 [kg]
        "screw_inertia": 55e-6,                                # J_S1 = 55 kg·mm²
        "roller_inertia": 0.08e-6,                             # J_R1 = 0.08 kg·mm² = 8e-8 kg·m²
        "carrier_inertia": 3e-6,                               # J_P1 = 3 kg·mm²
        # not in the text: m_P = J_P / (r_S + r_R)² (preset docstring) = 3e-6 / (13e-3)²
        # = 3e-6 / 1.69e-4 = 0.017751... kg
        "carrier_mass": 3e-6 / 1.69e-4,
    })
    _assert_stage_values(s2, {
        "screw_radius": 16.5e-3, "roller_radius": 5.5e-3, "nut_radius": 27.5e-3,
        "screw_lead": 10e-3, "screw_starts": 5, "n_rollers": 7,
        "flank_angle": math.pi / 4,                            # "β_S2 = 45 mm": 45° (typo)
        "screw_mass": 0.77, "nut_mass": 18.0, "roller_mass": 0.04,
        "screw_inertia": 170e-6,                               # J_S2 = 170 kg·mm² = 1.7e-4 kg·m²
        "roller_inertia": 0.48e-6,                             # J_R2 = 0.48 kg·mm²
        "carrier_inertia": 12e-6,                              # J_P2 = 12 kg·mm² = 1.2e-5 kg·m²
        "spline_radius": 13e-3,                                # r_SS2 = 13 mm
        # m_P2 = 12e-6 / (22e-3)² = 12e-6 / 4.84e-4 = 0.024793... kg
        "carrier_mass": 12e-6 / 4.84e-4,
    })


def test_assembly_article_preset_holds_the_published_masses_and_inertias_in_si():
    # the multi-stage assembly article, "numerical simulations" paragraph; kg·mm² × 1e-6 = kg·m²
    p = presets.load("assembly_two_stage")
    s1, s2 = p.stages
    _assert_stage_values(s1, {
        "roller_mass": 0.014, "screw_mass": 0.051, "nut_mass": 2.2,
        "roller_inertia": 0.077e-6,                            # 0.077 kg·mm² = 7.7e-8 kg·m²
        "screw_inertia": 51.94e-6,                             # 51.94 kg·mm² = 5.194e-5 kg·m²
        "carrier_inertia": 2.95e-6,                            # 2.95 kg·mm²
        "screw_radius": 9.75e-3,
        # m_P1 = 2.95e-6 / (13e-3)² = 2.95e-6 / 1.69e-4 = 0.017456 kg (docstring: 0.0175)
        "carrier_mass": 2.95e-6 / 1.69e-4,
    })
    _assert_stage_values(s2, {
        "roller_mass": 0.039, "screw_mass": 0.761, "nut_mass": 20.0,
        "roller_inertia": 0.471e-6, "screw_inertia": 172.3e-6, "carrier_inertia": 19.88e-6,
        "screw_radius": 16.5e-3, "spline_radius": 13e-3,
        # m_P2 = 19.88e-6 / (22e-3)² = 19.88e-6 / 4.84e-4 = 0.041074 kg (docstring: 0.0411)
        "carrier_mass": 19.88e-6 / 4.84e-4,
    })
    assert (p.mu_screw_roller, p.mu_spline, p.mu_nut_screw) == (0.05, 0.10, 0.005)


def test_preset_docstrings_state_the_carrier_masses_the_presets_hold():
    # the module docstrings quote m_P in kg to 3 significant figures; the fields must agree
    from prsm_fmu.presets import li2021
    for module, name, quoted in ((li2021, "li2021_two_stage", (0.0178, 0.0248)),
                                 (assembly_article, "assembly_two_stage", (0.0175, 0.0411))):
        stages = presets.load(name).stages
        for k, q in enumerate(quoted):
            assert f"{q} kg" in module.__doc__
            assert stages[k].carrier_mass == pytest.approx(q, abs=5e-5), (name, k)


def test_li2021_equivalent_inertia_from_section_3_1_by_hand():
    # Eq. 11's θ̇_S² bracket with the carriers slaved at ζ (ζ ≈ 0.374, tested elsewhere):
    # J_S1 + J_S2                                = 55e-6 + 170e-6              = 2.25e-4
    # c_1 = 10 mm/2π = 1.59155e-3 m/rad: (m_N1 + N_R m_R1 + 2 m_P1) c_1²
    #     = (2.5 + 0.119 + 0.0355) × 2.53303e-6                             = 6.7243e-6
    # c_2 = 20 mm/2π = 3.18310e-3 m/rad: (m_N2 + N_R m_R2 + 2 m_P2) c_2²
    #     = (18 + 0.28 + 0.0496) × 1.01321e-5                               = 1.85719e-4
    # m_S2 c_1² = 0.77 × 2.53303e-6                                         = 1.9504e-6
    # sum (without the carriers' own rotation)                             ≈ 4.1939e-4 kg·m²
    from prsm_fmu.models import make_model
    model = make_model(presets.load("li2021_two_stage"), "dynamic")
    assert model.mechanism.equivalent_inertia() == pytest.approx(4.1939e-4, rel=2e-4)


def test_assembly_article_lead_angles_reproduce_its_printed_helix_angles_within_rounding():
    # the multi-stage assembly article prints 9.27° and 5.51°: atan(L_S / (2π r_S)) to ±0.005° (rounding to 0.01°)
    s1, s2 = presets.load("assembly_two_stage").stages
    for stage, printed in ((s1, 9.27), (s2, 5.51)):
        angle = math.degrees(math.atan(stage.screw_lead / (2 * math.pi * stage.screw_radius)))
        assert abs(angle - printed) <= 0.005


def test_assembly_friction_scenarios_change_only_the_inter_stage_coefficients():
    base = assembly_article.two_stage("base")
    high_ns = assembly_article.two_stage("high_mu_ns").validate()
    assert (high_ns.mu_spline, high_ns.mu_nut_screw) == (0.10, 0.105)
    assert high_ns.stages == base.stages
    with pytest.raises(ValueError, match="scenario"):
        assembly_article.two_stage("nope")


def test_friction_article_published_set_is_rejected_on_nut_radius():
    with pytest.raises(ValueError, match=r"^stage\.nut_radius = 0\.015 m"):
        friction_article.published_stage().validate()


def test_friction_article_preset_is_the_nearest_standard_prsm():
    (stage,) = presets.load("friction_single_stage").stages
    assert stage.screw_radius == friction_article.PUBLISHED["screw_radius"]
    assert stage.roller_radius == friction_article.PUBLISHED["roller_radius"]
    assert stage.pitch == pytest.approx(friction_article.PUBLISHED["pitch"], rel=1e-12)
    assert stage.screw_starts == 4
    assert stage.screw_lead == pytest.approx(8.0e-3, rel=1e-12)
    assert stage.nut_radius == pytest.approx(20.0e-3, rel=1e-12)
    assert stage.screw_radius == pytest.approx((stage.screw_starts - 2) * stage.roller_radius)
    for field in ("screw_mass", "nut_mass", "roller_mass", "carrier_mass"):
        assert getattr(stage, field) == friction_article.PUBLISHED[field]


def test_recirculating_article_preset_holds_table_2_in_si():
    p = presets.load("recirculating_screw")
    assert (p.screw_diameter, p.nut_diameter, p.roller_diameter) == pytest.approx(
        (31.13e-3, 44.14e-3, 6.63e-3), rel=1e-12)
    assert (p.screw_lead, p.screw_starts, p.n_rollers) == (pytest.approx(1.0e-3), 1, 12)
    # the published diameters misfit by 0.25 mm (d_s + 2 d_r = 44.39 mm against 44.14 mm)
    assert p.fit_mismatch == pytest.approx(-0.25e-3, rel=1e-9)
