"""Tests of prsm_fmu.steady_state: the steady state found by root finding.

Expected values come from physics (virtual work, energy, symmetry), from Li et al. (2021) (§3.1, §3.2)
and from a direct back-substitution of the balances of docs/model.md §3 written out again below,
never from the dynamic model.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from prsm_fmu.geometry import contact_geometry
from prsm_fmu.presets import li2021, assembly_article
from prsm_fmu.steady_state import (
    carrier_equilibrium_ratio,
    default_initial_guess,
    steady_state,
    unknown_names,
)

OMEGA, LOAD = 100.0, 5000.0          # Li et al. (2021) §3.1 operating point


@pytest.fixture(scope="module")

def p000():
    return li2021.two_stage()


@pytest.fixture(scope="module")
def p002():
    return assembly_article.two_stage("high_mu_ns").validate()



def law_factor(v: float, v_eps: float) -> float:
    """docs/model.md §5 written out again: u = s·φ(|s|), Coulomb outside the band v_ε."""
    return 1.0 / v if v >= v_eps else (2.0 - v / v_eps) / v_eps

def c_n(params) -> float:
    return params.total_lead / (2.0 * math.pi)


def three_stage():
    """The multi-stage assembly article plus a third stage (a copy of stage 2) so that two bearings and splines act."""
    p = assembly_article.two_stage("high_mu_ns")
    s2 = dataclasses.replace(p.stages[1], bearing_radius=27.5e-3)
    # spline radius 13 mm as stage 2's: inside the screw's 16.5 mm pitch radius (params.py)
    s3 = dataclasses.replace(p.stages[1], spline_radius=13e-3, bearing_radius=0.0)
    return p.with_changes(stages=(p.stages[0], s2, s3)).validate()


def dissipation(params, r) -> float:
    """Σ contact + spline + bearing friction power computed from the solved forces."""
    w = r["screw_speed"]
    v_eps = params.slip_velocity_scale
    n = params.n_stages
    total = 0.0
    for k, st in enumerate(params.stages, start=1):
        g = contact_geometry(st)
        if r[f"stage[{k}].contact_force"] < 0.0:
            g = g.mirrored()
        a, b = (np.array(v) for v in g.slip_jacobians())
        s = w * a + r[f"stage[{k}].carrier_speed_ratio"] * w * b
        s2 = float(s @ s)
        total += (st.n_rollers * params.mu_screw_roller * r[f"stage[{k}].normal_force"]
                  * s2 * law_factor(math.sqrt(s2), v_eps))
        if k >= 2:
            ell_prev = params.stages[k - 2].screw_lead / (2 * math.pi)
            total += r[f"stage[{k}].spline_friction"] * w * ell_prev
    # bearing forces from the axial balances: B_(k-1) = A_k + h_k - h_(k+1), A_n = F
    axial = r["load_force"]
    for k in range(n, 1, -1):
        h_next = r[f"stage[{k + 1}].spline_friction"] if k < n else 0.0
        axial = axial + r[f"stage[{k}].spline_friction"] - h_next    # = B_(k-1) = A_(k-1)
        r_ns = params.stages[k - 2].bearing_radius
        vb = w * r_ns
        total += params.mu_nut_screw * abs(axial) * vb * vb * law_factor(abs(vb), v_eps)
    return total


# ---- API -------------------------------------------------------------------------------------
def test_keys_and_convergence(p000):
    r = steady_state(p000, OMEGA, LOAD)
    expected = {"screw_speed", "screw_torque", "rod_velocity", "load_force", "efficiency",
                "friction_power", "residual_norm", "screw_friction_torque"}
    expected |= {f"friction_power_{t}" for t in ("coulomb", "viscous", "differential", "joints")}
    for k in (1, 2):
        expected |= {f"stage[{k}].{q}" for q in ("carrier_speed_ratio", "normal_force",
                                                 "contact_force", "driven_torque",
                                                 "spline_friction")}
    assert set(r) == expected
    assert all(isinstance(v, float) for v in r.values())
    assert r["residual_norm"] < 1e-12
    assert r["screw_speed"] == OMEGA and r["load_force"] == LOAD
    assert r["rod_velocity"] == pytest.approx(OMEGA * c_n(p000), rel=1e-15)
    assert r["screw_torque"] == r["stage[1].driven_torque"]
    assert r["stage[1].spline_friction"] == 0.0
    # Li et al. (2021) Eq. 28 in forward drive
    assert r["efficiency"] == pytest.approx(
        LOAD * r["rod_velocity"] / (r["screw_torque"] * OMEGA), rel=1e-14)
    assert len(unknown_names(p000)) == 4 * 2 - 1 == default_initial_guess(p000, LOAD).size


@pytest.mark.parametrize("bad", [0.0, -0.0, math.nan, math.inf, -math.inf, "fast", None])
def test_bad_screw_speed(p000, bad):
    with pytest.raises(ValueError, match="screw_speed"):
        steady_state(p000, bad, LOAD)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "heavy"])
def test_bad_load(p000, bad):
    with pytest.raises(ValueError, match="load_force"):
        steady_state(p000, OMEGA, bad)


def test_bad_guess_and_stage_index(p000):
    with pytest.raises(ValueError, match="initial_guess"):
        steady_state(p000, OMEGA, LOAD, initial_guess=[1.0, 2.0])
    for k in (0, 3, 1.0, True):
        with pytest.raises(ValueError, match="k = "):
            carrier_equilibrium_ratio(p000, k)


# ---- uniqueness ------------------------------------------------------------------------------
@pytest.mark.parametrize("params_name", ["p000", "p002"])
def test_independent_of_initial_guess(params_name, request):
    params = request.getfixturevalue(params_name)
    ref = steady_state(params, OMEGA, LOAD)
    rng = np.random.default_rng(1)
    g0 = default_initial_guess(params, LOAD)
    n = params.n_stages
    for _ in range(6):
        g = g0 * rng.uniform(0.5, 1.5, g0.size)
        g[:n] = g0[:n] + rng.uniform(-0.2, 0.2, n)       # carrier ratios
        r = steady_state(params, OMEGA, LOAD, initial_guess=g)
        for key, v in ref.items():
            if key != "residual_norm":
                assert r[key] == pytest.approx(v, rel=1e-11, abs=1e-9), key


# ---- independent back-substitution of the §3 balances ---------------------------------------
def test_matches_direct_back_substitution(p002):
    """Stage n down to 1: ζ* closed form, F_k from the roller balance, M_Sk from the screw."""
    params, w, load = p002, 80.0, 7000.0
    r = steady_state(params, w, load)
    mu, v_eps = params.mu_screw_roller, params.slip_velocity_scale
    sgn = lambda v: v * law_factor(abs(v), v_eps)          # noqa: E731
    n = params.n_stages
    axial, m_next, h_next = load, 0.0, 0.0
    for k in range(n, 0, -1):
        st = params.stages[k - 1]
        g = contact_geometry(st)
        a, b = (np.array(v) for v in g.slip_jacobians())
        zeta = -(a @ b) / (b @ b)
        s = w * a + zeta * w * b
        u = s * law_factor(math.sqrt(s @ s), v_eps)
        nrm, p = np.array(g.normal), np.array(g.point)
        f_k = axial / (st.n_rollers * (nrm[2] - mu * u[2]))
        force = f_k * nrm - mu * f_k * u
        torque_contact = st.n_rollers * (p[0] * force[1] - p[1] * force[0])
        if k >= 2:
            # M_Sk and B_(k-1) are coupled through h_k(M_Sk) and T_b(B_(k-1)): the signs are
            # known (all positive here), so solve the 2x2 linear system
            ell_prev = params.stages[k - 2].screw_lead / (2 * math.pi)
            cs = params.mu_spline / st.spline_radius * sgn(w * ell_prev)
            r_ns = params.stages[k - 2].bearing_radius
            cb = params.mu_nut_screw * r_ns * sgn(w * r_ns)
            # M = m_next - torque_contact + cb*B ;  B = axial + cs*M - h_next
            mat = np.array([[1.0, -cb], [-cs, 1.0]])
            rhs = np.array([m_next - torque_contact, axial - h_next])
            m_k, b_prev = np.linalg.solve(mat, rhs)
            h_k = cs * m_k
        else:
            m_k = m_next - torque_contact
            h_k, b_prev = 0.0, None
        assert r[f"stage[{k}].carrier_speed_ratio"] == pytest.approx(zeta, rel=1e-12)
        assert r[f"stage[{k}].normal_force"] == pytest.approx(f_k, rel=1e-11)
        assert r[f"stage[{k}].driven_torque"] == pytest.approx(m_k, rel=1e-11)
        assert r[f"stage[{k}].spline_friction"] == pytest.approx(h_k, rel=1e-11, abs=1e-12)
        axial, m_next, h_next = b_prev, m_k, h_k


# ---- virtual work ----------------------------------------------------------------------------
@pytest.mark.parametrize("w,load", [(100.0, 5000.0), (-30.0, 5000.0), (7.0, -2000.0)])
def test_frictionless_virtual_work(p000, w, load):
    p0 = p000.with_changes(mu_screw_roller=0.0, mu_spline=0.0, mu_nut_screw=0.0)
    r = steady_state(p0, w, load)
    assert r["screw_torque"] == pytest.approx(load * c_n(p0), rel=1e-12)
    assert r["efficiency"] == pytest.approx(1.0, rel=1e-12)
    assert abs(r["friction_power"]) < 1e-12 * abs(load * r["rod_velocity"])
    for k in (1, 2):
        assert r[f"stage[{k}].carrier_speed_ratio"] == pytest.approx(
            carrier_equilibrium_ratio(p0, k), rel=1e-12)
        assert r[f"stage[{k}].contact_force"] == pytest.approx(load / 7, rel=1e-12)


# ---- carriers (Li et al. (2021) §3.1, §3.2) ----------------------------------------------------------
def test_carrier_ratio_independent_of_friction_and_load(p000):
    ref = [carrier_equilibrium_ratio(p000, k) for k in (1, 2)]
    cases = [dict(mu_screw_roller=m) for m in (0.02, 0.1, 0.2)]
    cases += [dict(mu_spline=m) for m in (0.0, 0.2, 0.3)]
    for changes in cases:
        for load in (100.0, 5000.0, 20000.0, -5000.0):
            for w in (100.0, -3.0):
                r = steady_state(p000.with_changes(**changes), w, load)
                for k in (1, 2):
                    assert r[f"stage[{k}].carrier_speed_ratio"] == pytest.approx(
                        ref[k - 1], rel=1e-12, abs=0.0)
    assert ref[1] > ref[0]                                   # Li et al. (2021) §3.1
    assert ref[0] < 0.375 and ref[1] < 0.375                # below pure rolling r_S/(r_S+r_N)
    # docs/model.md §4 quotes ζ*_1 = 0.37369, ζ*_2 = 0.37454
    assert ref[0] == pytest.approx(0.37369, abs=1e-5)
    assert ref[1] == pytest.approx(0.37454, abs=1e-5)


def test_carrier_ratio_same_on_both_flanks(p000):
    for st in p000.stages:
        for g in (contact_geometry(st), contact_geometry(st).mirrored()):
            a, b = (np.array(v) for v in g.slip_jacobians())
            assert -(a @ b) / (b @ b) == pytest.approx(
                carrier_equilibrium_ratio(p000, p000.stages.index(st) + 1), rel=1e-13)


# ---- friction trends (Li et al. (2021) §3.1, §3.2) ---------------------------------------------------
def test_efficiency_falls_with_screw_roller_friction(p000):
    etas = [steady_state(p000.with_changes(mu_screw_roller=m), OMEGA, LOAD)["efficiency"]
            for m in (0.0, 0.05, 0.1, 0.15, 0.2)]
    assert 0.95 < etas[0] < 1.0                     # spline friction alone costs little
    assert all(e1 > e2 for e1, e2 in zip(etas, etas[1:]))


def test_spline_friction_changes_efficiency_slightly(p000):
    for mu_sr in (0.1, 0.2):
        e2 = steady_state(p000.with_changes(mu_screw_roller=mu_sr, mu_spline=0.2),
                          OMEGA, LOAD)["efficiency"]
        e3 = steady_state(p000.with_changes(mu_screw_roller=mu_sr, mu_spline=0.3),
                          OMEGA, LOAD)["efficiency"]
        assert e3 < e2
        assert (e2 - e3) / e2 < 0.01


def test_stage_ordering_and_positive_dissipation(p000):
    r = steady_state(p000, OMEGA, LOAD)
    assert r["stage[1].driven_torque"] > r["stage[2].driven_torque"] > 0.0
    assert r["stage[1].contact_force"] > r["stage[2].contact_force"] > 0.0
    assert r["stage[2].spline_friction"] > 0.0
    for w in (300.0, 100.0, 1.0, 0.01, -0.01, -100.0):
        for load in (5000.0, -5000.0, 10.0):
            assert steady_state(p000, w, load)["friction_power"] >= 0.0


def test_efficiency_independent_of_load_and_forces_linear(p000):
    """No preload: every force and torque is proportional to the load (same sign)."""
    r1 = steady_state(p000, OMEGA, 1000.0)
    r5 = steady_state(p000, OMEGA, 5000.0)
    assert r5["efficiency"] == pytest.approx(r1["efficiency"], rel=1e-12)
    for k in (1, 2):
        for q in ("normal_force", "driven_torque", "spline_friction"):
            assert r5[f"stage[{k}].{q}"] == pytest.approx(5 * r1[f"stage[{k}].{q}"],
                                                          rel=1e-12, abs=1e-12)


# ---- energy ----------------------------------------------------------------------------------
@pytest.mark.parametrize("w,load", [(100.0, 5000.0), (100.0, -5000.0), (-100.0, 5000.0),
                                    (2.0, 3000.0), (0.01, 5000.0), (-0.003, -700.0)])
@pytest.mark.parametrize("params_name", ["p000", "p002", "three"])
def test_energy_balance(params_name, w, load, request):
    params = three_stage() if params_name == "three" else request.getfixturevalue(params_name)
    r = steady_state(params, w, load)
    assert r["friction_power"] == pytest.approx(
        r["screw_torque"] * w - load * r["rod_velocity"], rel=1e-15)
    assert r["friction_power"] > 0.0
    assert dissipation(params, r) == pytest.approx(r["friction_power"], rel=1e-9)


def test_three_stage_solution(p002):
    params = three_stage()
    r = steady_state(params, OMEGA, LOAD)
    assert len(unknown_names(params)) == 11
    assert r["residual_norm"] < 1e-12
    torques = [r[f"stage[{k}].driven_torque"] for k in (1, 2, 3)]
    assert torques[0] > torques[1] > torques[2] > 0.0
    assert 0.0 < r["efficiency"] < steady_state(p002, OMEGA, LOAD)["efficiency"] < 1.0


# ---- reversal --------------------------------------------------------------------------------
def test_back_driving(p000):
    """ω < 0 with the load resisting extension: the load drives, friction holds the screw back."""
    fwd = steady_state(p000, OMEGA, LOAD)
    back = steady_state(p000, -OMEGA, LOAD)
    ideal = LOAD * c_n(p000)
    assert 0.0 < back["screw_torque"] < ideal < fwd["screw_torque"]
    # power flows from the load to the motor: efficiency = M_S1 ω / (F v_rod)
    assert back["efficiency"] == pytest.approx(back["screw_torque"] / ideal, rel=1e-14)
    assert back["rod_velocity"] < 0.0


def test_mirror_symmetry(p002):
    """The rotation by π about x maps (ω, F) onto (−ω, −F) with every torque reversed."""
    for w, load in ((100.0, 7000.0), (-5.0, 3000.0)):
        r = steady_state(p002, w, load)
        m = steady_state(p002, -w, -load)
        assert m["screw_torque"] == pytest.approx(-r["screw_torque"], rel=1e-12)
        assert m["efficiency"] == pytest.approx(r["efficiency"], rel=1e-12)
        assert m["friction_power"] == pytest.approx(r["friction_power"], rel=1e-11)
        for k in (1, 2):
            assert m[f"stage[{k}].carrier_speed_ratio"] == pytest.approx(
                r[f"stage[{k}].carrier_speed_ratio"], rel=1e-12)
            assert m[f"stage[{k}].normal_force"] == pytest.approx(
                r[f"stage[{k}].normal_force"], rel=1e-12)
            assert m[f"stage[{k}].contact_force"] == pytest.approx(
                -r[f"stage[{k}].contact_force"], rel=1e-12)
            assert m[f"stage[{k}].spline_friction"] == pytest.approx(
                -r[f"stage[{k}].spline_friction"], rel=1e-12, abs=1e-12)


def test_zero_load_idles(p000):
    """No load, no preload: every force vanishes; the carriers run at their µ → 0 ratio."""
    r = steady_state(p000, OMEGA, 0.0)
    assert r["screw_torque"] == 0.0 and r["friction_power"] == 0.0
    assert math.isnan(r["efficiency"])
    for k in (1, 2):
        assert r[f"stage[{k}].normal_force"] == 0.0
        assert r[f"stage[{k}].carrier_speed_ratio"] == pytest.approx(
            carrier_equilibrium_ratio(p000, k), rel=1e-12)
