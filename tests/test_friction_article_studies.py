"""The friction-torque article's two studies (its load and acceleration-time tables) run
as studies on the accelerating speed drive, and its trends asserted from their tables.

Both studies have two lines: µ_1 = 0.001 N·s/m (the article's value, whose viscous torque at
1 rad/s is ~1.6e-7 N·m) and µ_1 = 580 N·s/m, what the intercept of the article's own load table
needs (least squares through its four points: 0.0931 N·m + 1.429e-4 N·m/N · F; at 1 rad/s the
viscous torque is N_R n_t µ_1 |σ|² ω = 5 · 10 · µ_1 · 3.2167e-6 m², so µ_1 = 0.0931 / 1.608e-4
≈ 579 N·s/m).  docs/sweeps.md §4 tables both beside the article's.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from prsm_fmu import presets, steady_state
from prsm_fmu.sweep import load_study, run_study

STUDIES = Path(__file__).resolve().parents[1] / "studies"
ARTICLE_MU1, FIT_MU1 = 0.001, 580.0


def run_table(name: str, tmp_path_factory) -> list[dict]:
    """The result table of the shipped study ``name``, run in a plain loop."""
    res = run_study(load_study(STUDIES / f"{name}.toml"), str(tmp_path_factory.mktemp(name)),
                    executor="loop", figures=False, progress=None)
    assert not res.failed
    return res.rows


@pytest.fixture(scope="module")
def load_table(tmp_path_factory):
    return run_table("friction_load", tmp_path_factory)


@pytest.fixture(scope="module")
def accel_table(tmp_path_factory):
    return run_table("friction_accel_time", tmp_path_factory)


def line(rows, mu1, along):
    """The rows of one µ_1 line, sorted along the swept parameter."""
    return sorted((r for r in rows if r["mu_viscous"] == mu1), key=lambda r: r[along])


def strictly(values, rising: bool) -> bool:
    return all((b > a) if rising else (b < a) for a, b in zip(values, values[1:]))


@pytest.mark.parametrize("mu1", [ARTICLE_MU1, FIT_MU1])
def test_peak_friction_torque_rises_with_load(load_table, mu1):
    peaks = [r["screw_friction_torque@max"] for r in line(load_table, mu1, "load_force")]
    assert strictly(peaks, rising=True)


def test_time_to_steady_state_falls_with_load_when_a_speed_dependent_term_acts(load_table):
    """With µ_1 = 580 N·s/m the friction torque grows with the speed until the ramp ends; the
    load-proportional Coulomb and differential parts make that growth a smaller share at larger
    loads, so it enters the 1 % band earlier: the time to steady state falls with load."""
    t_ss = [r["screw_friction_torque@settle"] for r in line(load_table, FIT_MU1, "load_force")]
    assert strictly(t_ss, rising=False)
    # before the end of the 20 ms ramp at every load: the viscous share at the ramp's end,
    # 0.0931 / M_f, exceeds 1 % for every load (M_f ≤ 0.78 N·m)
    assert all(0.015 < t < 0.02 for t in t_ss)


def test_time_to_steady_state_with_the_seeds_own_viscous_coefficient(load_table):
    """With µ_1 = 0.001 N·s/m the only part of M_f that changes along the ramp is the carriers'
    inertial drive through friction, ζ*² J_P α ≈ 0.1104 · 2.1375e-4 kg·m² · 50 rad/s² ≈
    1.2e-3 N·m, independent of the load: more than 1 % of M_f at 500 N (0.068 N·m), less at
    1000 N and above.  So 500 N settles when the ramp ends (20 ms) and the others as soon as the
    slip leaves the regularisation band (~1 ms): a fall with load, but a step, not the article's
    gradual 35 → 18 ms."""
    t_ss = [r["screw_friction_torque@settle"] for r in line(load_table, ARTICLE_MU1, "load_force")]
    assert 0.02 <= t_ss[0] < 0.021
    assert all(t < 0.002 for t in t_ss[1:])


@pytest.mark.parametrize("mu1", [ARTICLE_MU1, FIT_MU1])
def test_friction_torque_at_the_end_is_the_independent_steady_state(load_table, mu1):
    params = presets.load("friction_single_stage").with_changes(mu_viscous=mu1)
    for r in line(load_table, mu1, "load_force"):
        ss = steady_state(params, 1.0, r["load_force"])
        assert r["screw_friction_torque@end"] == pytest.approx(ss["screw_friction_torque"],
                                                               rel=1e-6)


@pytest.mark.parametrize("mu1", [ARTICLE_MU1, FIT_MU1])
def test_max_friction_torque_rises_with_shorter_acceleration_time(accel_table, mu1):
    peaks = [r["screw_friction_torque@max"] for r in line(accel_table, mu1, "accel_time")]
    assert strictly(peaks, rising=False)          # falls as t_a grows


@pytest.mark.parametrize("mu1", [ARTICLE_MU1, FIT_MU1])
def test_min_instantaneous_efficiency_falls_with_shorter_acceleration_time(accel_table, mu1):
    eta_min = [r["efficiency@min"] for r in line(accel_table, mu1, "accel_time")]
    assert strictly(eta_min, rising=True)         # rises as t_a grows


def test_overall_efficiency_higher_for_shorter_ramps_only_without_a_strong_viscous_term(
        accel_table):
    """The friction-torque article: a shorter ramp gives a higher overall efficiency (less time in the transient).
    With the article's µ_1 that holds; with µ_1 = 580 N·s/m the viscous loss grows with the speed,
    a longer ramp runs longer at low speed, and the overall efficiency rises with t_a."""
    seed = [r["efficiency@overall"] for r in line(accel_table, ARTICLE_MU1, "accel_time")]
    fit = [r["efficiency@overall"] for r in line(accel_table, FIT_MU1, "accel_time")]
    assert strictly(seed, rising=False)
    assert strictly(fit, rising=True)


def test_the_paper_lead_study_differs_from_the_load_study_only_in_the_lead():
    """studies/friction_load_lead2mm.toml (docs/sweeps.md §4, "The lead"): the load study's grid
    and scenario on the preset with the paper's 2 mm lead: 4 starts × 0.5 mm pitch = 2 mm,
    lead angle atan(0.002 / (2π × 0.010)) = atan(0.031831) = 1.8232°."""
    import math

    from prsm_fmu.sweep.study import apply_overrides, resolve_preset

    base = load_study(STUDIES / "friction_load.toml")
    lead2 = load_study(STUDIES / "friction_load_lead2mm.toml")
    assert lead2.scenario == base.scenario and lead2.preset == base.preset
    assert [p.values for p in lead2.points()] == [p.values for p in base.points()]
    (stage,) = apply_overrides(resolve_preset(lead2.preset), lead2.parameters).stages
    assert stage.screw_starts == 4
    assert stage.screw_lead == pytest.approx(0.002, rel=1e-12)
    assert math.degrees(math.atan(stage.screw_lead / (2 * math.pi * stage.screw_radius))) \
        == pytest.approx(1.8232, abs=1e-4)
