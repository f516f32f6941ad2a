"""The friction-torque article's friction terms: viscous, Coulomb spin sliding and
differential sliding, at every level, in the steady state and in the energy balance.

Closed forms are written out here from the contact geometry alone (the contact point P and the
normal n of geometry.py, tested on their own in test_geometry.py).  For a single stage at
steady state with the carriers at their equilibrium ratio (ℓ = L_S/2π, c = (r_S + r_R, 0, 0)):

    a = ẑ × P + ℓ ẑ,  b = −ẑ × P + n_S ẑ × (P − c),  ζ* = −(a·b)/(b·b),  σ = a + ζ* b,

the slip is s = ω σ with σ ⟂ b, so σ·a = |σ|², and the slip direction's axial part is
u_z = ℓ/|σ|.  The roller's axial balance gives the normal force of all rollers,

    F_N = (F + N_R µ_1 n_t ℓ ω) / (n_z − µ_2 ℓ/|σ|)

(the viscous force's axial part adds to the load the threads carry), and the friction-torque article's M_f,ss
structure — viscous µ_1 n_R n_t v_sr·∂v_sr/∂θ̇_s, spin µ_2 F_nf (v_sr/|v_sr|)·∂v_sr/∂θ̇_s and
differential µ_3 F_nf, each summed over the N_R n_t contacts — reads at this geometry

    M_visc = N_R µ_1 n_t ω |σ|²,   M_spin = µ_2 F_N |σ|,   M_diff = µ_3 F_N,

and the screw torque is M_S1 = ℓ F + M_visc + M_spin + M_diff.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from prsm_fmu import presets, simulate, steady_state
from prsm_fmu.geometry import contact_geometry
from prsm_fmu.mechanics import Mechanism
from prsm_fmu.models import make_model
from prsm_fmu.profiles import RampSpeed, TableSpeed

TERMS = ("coulomb", "viscous", "differential", "joints")


def friction_article(**changes):
    """The friction-torque article's preset (µ_1 = 0.001 N·s/m, n_t = 10, µ_2 = 0.05, µ_3 = 1e-6 m) with changes."""
    return presets.load("friction_single_stage").with_changes(**changes).validate()


#: the terms made strong enough to be seen next to each other: µ_1 = 580 N·s/m is what the friction-torque article's
#: load table's 0.093 N·m intercept would need (docs/sweeps.md), µ_3 = 0.1 mm
STRONG = {"mu_viscous": 580.0, "mu_differential": 1e-4}


def closed_form(params, omega: float, load: float) -> dict:
    """The friction-torque article's M_f,ss terms at the contact geometry (module docstring), ω > 0, F ≥ 0."""
    st = params.stages[0]
    geo = contact_geometry(st)
    p = np.array(geo.point, dtype=float)
    n = np.array(geo.normal, dtype=float)
    ell = st.screw_lead / (2.0 * math.pi)
    z = np.array([0.0, 0.0, 1.0])
    c = np.array([st.screw_radius + st.roller_radius, 0.0, 0.0])
    a = np.cross(z, p) + ell * z
    b = -np.cross(z, p) + st.screw_starts * np.cross(z, p - c)
    zeta = -float(a @ b) / float(b @ b)
    sigma = a + zeta * b
    v = float(np.linalg.norm(sigma))
    cv = st.n_rollers * params.mu_viscous * st.threads_per_roller       # N_R µ_1 n_t
    f_n = (load + cv * ell * omega) / (n[2] - params.mu_screw_roller * ell / v)
    return {"zeta": zeta, "ell": ell, "normal": f_n,
            "viscous": cv * omega * v * v,
            "coulomb": params.mu_screw_roller * f_n * v,
            "differential": params.mu_differential * f_n}


# ---- each term's steady torque on the screw --------------------------------------------------
@pytest.mark.parametrize("term,changes", [
    ("viscous", {"mu_screw_roller": 0.0, "mu_differential": 0.0, "mu_viscous": 580.0}),
    ("coulomb", {"mu_viscous": 0.0, "mu_differential": 0.0}),
    ("differential", {"mu_screw_roller": 0.0, "mu_viscous": 0.0, "mu_differential": 1e-4}),
])
@pytest.mark.parametrize("level", ["quasi-static", "dynamic", "steady_state"])
def test_each_terms_steady_screw_torque_equals_friction_article_closed_form_to_1e_9(term, changes, level):
    params = friction_article(**changes)
    omega, load = 2.0, 1000.0
    ref = closed_form(params, omega, load)
    if level == "steady_state":
        torque = steady_state(params, omega, load)["screw_torque"]
    else:
        mech = Mechanism(params, "equilibrium" if level == "quasi-static" else "dynamic")
        torque = mech.solve(omega, [ref["zeta"] * omega], load, acceleration=0.0).motor_torque
    # the term alone: screw torque minus the load's ℓF
    assert abs((torque - ref["ell"] * load) - ref[term]) <= 1e-9 * ref[term]


@pytest.mark.parametrize("changes", [{}, STRONG], ids=["friction_article_values", "strong"])
@pytest.mark.parametrize("level", ["quasi-static", "dynamic"])
def test_all_three_terms_together_and_each_terms_power_match_the_closed_form(changes, level):
    """With the three terms on at once (the article's own values, then strong ones), the screw
    torque is ℓF + Σ terms and each term's power output over ω is that term's torque."""
    params = friction_article(**changes)
    omega, load = 1.0, 1000.0
    ref = closed_form(params, omega, load)
    model = make_model(params, level, "speed")
    x = model.initial_state((0.0, load), screw_speed=omega, carrier_ratio=None)
    y = model.outputs(0.0, x, (0.0, load))
    total = ref["viscous"] + ref["coulomb"] + ref["differential"]
    assert abs(y["screw_torque"] - (ref["ell"] * load + total)) <= 1e-9 * total
    assert abs(y["screw_friction_torque"] - total) <= 1e-9 * total
    for term in ("viscous", "coulomb", "differential"):
        assert abs(y[f"friction_power_{term}"] / omega - ref[term]) <= 1e-9 * ref[term], term
    assert y["friction_power_joints"] == 0.0
    ss = steady_state(params, omega, load)
    for term in ("viscous", "coulomb", "differential"):
        assert abs(ss[f"friction_power_{term}"] / omega - ref[term]) <= 1e-9 * ref[term], term
    assert abs(ss["stage[1].normal_force"] * params.stages[0].n_rollers - ref["normal"]) \
        <= 1e-9 * ref["normal"]


@pytest.mark.parametrize("term,changes", [
    ("viscous", {"mu_differential": 0.0, "mu_viscous": 580.0}),
    ("differential", {"mu_viscous": 0.0, "mu_differential": 1e-4}),
])
def test_kinematic_level_carries_each_term_through_its_loss_torque(term, changes):
    """The kinematic level has no thread friction (µ_2 acts only through its efficiency η₀);
    its viscous and differential loss torques are the closed forms with µ_2 = 0."""
    params = friction_article(**changes)
    omega, load = 2.0, 1000.0
    ref = closed_form(params.with_changes(mu_screw_roller=0.0), omega, load)
    model = make_model(params, "kinematic", "speed", efficiency=1.0)
    x = model.initial_state((0.0, load), screw_speed=omega)
    y = model.outputs(0.0, x, (0.0, load))
    assert abs((y["screw_torque"] - ref["ell"] * load) - ref[term]) <= 1e-9 * ref[term]
    assert abs(y[f"friction_power_{term}"] - ref[term] * omega) <= 1e-9 * ref[term] * omega


def test_viscous_term_holds_the_carriers_at_equilibrium_without_load():
    """At zero load Coulomb friction leaves the carriers neutral; the lubricant's force along
    the slip holds them at ζ* = −a·b/b·b (where s ⟂ b): the steady state needs no limit."""
    params = friction_article(**STRONG)
    ref = closed_form(params, 3.0, 0.0)
    ss = steady_state(params, 3.0, 0.0)
    assert abs(ss["stage[1].carrier_speed_ratio"] - ref["zeta"]) <= 1e-12
    # no load: the viscous axial force N_R µ_1 n_t ℓ ω alone loads the flanks, so the Coulomb
    # and differential torques act on it too (closed_form's F_N with F = 0)
    expected = ref["viscous"] + ref["coulomb"] + ref["differential"]
    assert ref["coulomb"] > 0.0 and ref["differential"] > 0.0
    assert abs(ss["screw_torque"] - expected) <= 1e-9 * expected


# ---- energy ------------------------------------------------------------------------------------
def _energy_residual(res) -> float:
    w_in = res["input_work"][-1]
    delta_t = res["kinetic_energy"][-1] - res["kinetic_energy"][0]
    return abs(w_in - res["output_work"][-1] - res["friction_work"][-1] - delta_t) / abs(w_in)


@pytest.mark.parametrize("fidelity", ["dynamic", "quasi-static", "kinematic"])
@pytest.mark.parametrize("run", ["accelerating", "reversal"])
def test_energy_balance_with_all_three_terms_closes_within_1e_9(fidelity, run):
    """W_in = W_out + W_f + ΔT to 1e-9 of W_in on the friction-torque article's ramp 0 → 1 rad/s in 20 ms and on a
    reversal 1 → −1 rad/s through zero slip; every term's power is ≥ 0 at every sample (no
    energy created at the reversal) and the terms sum to the friction power."""
    params = friction_article(**STRONG)
    if run == "accelerating":
        speed = RampSpeed(0.0, 1.0, 0.02)
    else:
        speed = TableSpeed([0.0, 0.005, 0.025], [1.0, 1.0, -1.0])
    res = simulate(params, fidelity, "speed", screw_speed=speed, load_force=1000.0, t_end=0.03,
                   output_interval=5e-4, initial_carrier_ratio=None, rtol=1e-10, atol=1e-12,
                   model_options={"efficiency": 0.9} if fidelity == "kinematic" else None)
    assert _energy_residual(res) <= 1e-9
    total = sum(res[f"friction_power_{t}"] for t in TERMS)
    assert np.allclose(total, res["friction_power"], rtol=1e-12, atol=1e-15)
    for t in TERMS:
        assert np.all(res[f"friction_power_{t}"] >= -1e-15), t
    for t in ("coulomb", "viscous", "differential"):
        assert np.max(res[f"friction_power_{t}"]) > 0.0, t
    if run == "reversal":
        assert res["screw_speed"][-1] == pytest.approx(-1.0, abs=1e-12)


def test_friction_power_through_zero_slip_is_never_negative_at_any_term():
    """Sweep the carrier speed of the dynamic level through the point where the slip vanishes
    (ω_P = −(a·b)/(b·b)·ω only makes s ⟂ b; s = 0 needs ω = 0 and ω_P = 0: sweep both through
    zero) and check every term's power is ≥ 0, including inside the regularisation band."""
    params = friction_article(**STRONG)
    mech = Mechanism(params, "dynamic")
    v_eps = params.slip_velocity_scale
    for omega in np.linspace(-3e-2, 3e-2, 61):
        for wp in np.linspace(-1e-2, 1e-2, 21):
            for load in (-800.0, 0.0, 800.0):
                sol = mech.solve(float(omega), [float(wp)], load, acceleration=5.0, detail=True)
                for t, p in sol.friction_power_terms.items():
                    assert p >= -1e-15 * max(1.0, abs(load) * v_eps), (omega, wp, load, t, p)


# ---- efficiency outputs ------------------------------------------------------------------------
def test_overall_efficiency_is_the_work_ratio_and_instantaneous_efficiency_the_power_ratio():
    """The friction-torque article: η(t) = F p_s θ̇_s / (T_in θ̇_s) and η_overall = ∫P_out dt / ∫P_in dt."""
    params = friction_article()
    res = simulate(params, "dynamic", "speed", screw_speed=RampSpeed(0.0, 1.0, 0.02),
                   load_force=1000.0, t_end=0.04, output_interval=1e-3)
    moving = res["screw_speed"] > 0.0
    ell = params.stages[0].screw_lead / (2.0 * math.pi)
    eta = 1000.0 * ell / res["screw_torque"][moving]                       # F p_s / T_in
    assert np.allclose(res["efficiency"][moving], eta, rtol=1e-12)
    w_out = np.trapezoid(1000.0 * ell * res["screw_speed"], res["time"])  # ω linear in pieces
    assert res["overall_efficiency"][-1] == pytest.approx(w_out / res["input_work"][-1],
                                                          rel=1e-9)


# ---- parameters: validation, FMU table, loop --------------------------------------------------
@pytest.mark.parametrize("name,value", [("mu_viscous", -1e-3), ("mu_viscous", math.inf),
                                        ("mu_differential", -1e-6), ("mu_differential", 2e-3)])
def test_out_of_range_friction_parameter_is_refused_naming_it(name, value):
    with pytest.raises(ValueError, match=name):
        friction_article(**{name: value})


def test_threads_per_roller_below_one_is_refused():
    p = presets.load("friction_single_stage")
    with pytest.raises(ValueError, match=r"stage\[1\]\.threads_per_roller"):
        p.with_stage(1, threads_per_roller=0).validate()


def test_fmu_table_has_the_terms_with_units_and_ranges():
    from prsm_fmu.params import MECHANISM_FIELD_NAMES
    from prsm_fmu.slave import MECHANISM_FIELDS, parameter_defaults, variable_table

    assert tuple(MECHANISM_FIELDS) == MECHANISM_FIELD_NAMES
    rows = {v.name: v for v in variable_table(1)}
    assert (rows["mu_viscous"].unit, rows["mu_viscous"].min) == ("N.s/m", 0.0)
    assert (rows["mu_differential"].unit, rows["mu_differential"].min,
            rows["mu_differential"].max) == ("m", 0.0, 1e-3)
    assert (rows["stage[1].threads_per_roller"].type, rows["stage[1].threads_per_roller"].min) \
        == ("Integer", 1)
    start = parameter_defaults(presets.load("friction_single_stage"))
    # the friction-torque article's table: µ_1 = 0.001 N·s/m, µ_3 = 1e-6 m, 10 thread pitches per roller
    assert (start["mu_viscous"], start["mu_differential"], start["stage[1].threads_per_roller"]) \
        == (0.001, 1e-6, 10)
    # Li et al.'s (2021) mechanism keeps its behaviour: no new term
    start = parameter_defaults(presets.load("li2021_two_stage"))
    assert start["mu_viscous"] == 0.0 and start["mu_differential"] == 0.0


def test_the_loop_carries_the_terms_into_its_prsm_block():
    from system_models.prsm import PRSMConfig, make_prsm_block

    cfg = PRSMConfig("PRSM1", {"mu_viscous": 580.0, "mu_differential": 1e-4,
                               "stage[1].threads_per_roller": 10, "fidelity": "quasi-static"})
    block = make_prsm_block(cfg, "python")
    p = block.model.params
    assert (p.mu_viscous, p.mu_differential, p.stages[0].threads_per_roller) == (580.0, 1e-4, 10)
    # the torque-driven block at 1 rad/s and 1 kN: the motor torque ℓF + the closed-form terms
    # holds the screw at constant speed: |α| J ≤ 1e-9 of the friction torque, with J at least
    # the screw's own ½ m r² = ½ · 1 kg · (10 mm)² = 5e-5 kg·m² (the friction-torque article's screw)
    ref = closed_form(p, 1.0, 1000.0)
    total = ref["viscous"] + ref["coulomb"] + ref["differential"]
    y = block.model.outputs(0.0, [0.0, 1.0, 0.0, 0.0, 0.0],
                            (ref["ell"] * 1000.0 + total, 1000.0))
    assert abs(y["screw_acceleration"]) * 5e-5 <= 1e-9 * total
    assert abs(y["screw_friction_torque"] - total) <= 1e-9 * total
