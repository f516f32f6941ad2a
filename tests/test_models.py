"""Instantaneous physics of the three fidelity levels: power identity, equilibria, closed forms.

Expected values come from conservation of energy (the normal forces are workless, so motor
power − load power − friction power = dT/dt at any state), from the virtual-work law of an ideal
screw, and from the equilibrium definition of the carriers; none is copied from a run.
"""

from __future__ import annotations

import math
import random

import pytest

from prsm_fmu.models import make_model
from prsm_fmu.params import MechanismParams
from prsm_fmu.presets.li2021 import two_stage


def three_stage() -> MechanismParams:
    """Li et al.'s (2021) stages plus a third, larger one, with every friction on (incl. bearings)."""
    p = two_stage()
    s1, s2 = p.stages
    s3 = s2.__class__(**{**s2.__dict__, "screw_radius": 24e-3, "roller_radius": 8e-3,
                          "nut_radius": 40e-3, "screw_lead": 12e-3, "spline_radius": 20e-3,
                          "nut_mass": 25.0, "screw_mass": 1.5})
    stages = (s1.__class__(**{**s1.__dict__, "bearing_radius": 14e-3}),
              s2.__class__(**{**s2.__dict__, "bearing_radius": 22e-3}), s3)
    return p.with_changes(stages=stages, mu_nut_screw=0.02, name="three_stage_test").validate()


MECHANISMS = {"li2021": two_stage, "three_stage": three_stage}


def dT_dt(model, x, dx, u) -> float:
    """Rate of kinetic energy from state and derivative [W] (Eq. 11 differentiated)."""
    mech = model.mechanism
    omega, domega = x[1], dx[1]
    rate = mech.equivalent_inertia() * omega * domega
    if model.n_carrier_states:
        i = model._i_carrier
        for s, wp, dwp in zip(mech.stages, x[i:i + model.n_carrier_states], dx[i:i + model.n_carrier_states]):
            rate += s.j_carrier * wp * dwp
    return rate


@pytest.mark.parametrize("mech", sorted(MECHANISMS))
@pytest.mark.parametrize("fidelity", ["dynamic", "quasi-static", "kinematic"])
@pytest.mark.parametrize("drive", ["torque", "speed"])
def test_power_identity_closes_to_round_off_at_random_states(mech, fidelity, drive):
    params = MECHANISMS[mech]()
    opts = {"efficiency": 0.9} if fidelity == "kinematic" else {}
    model = make_model(params, fidelity, drive, **opts)
    rng = random.Random(1234)
    inconsistent = 0
    for _ in range(200):
        omega = rng.choice([1.0, -1.0]) * 10 ** rng.uniform(-4, 2.5)
        load = rng.uniform(-8000.0, 8000.0)
        wp = [omega * rng.uniform(-0.5, 1.0) for _ in range(model.n_carrier_states)]
        x = [0.0, omega] + wp + [0.0, 0.0, 0.0]
        if drive == "torque":
            u = (rng.uniform(-40.0, 40.0), load)
        else:   # a prescribed acceleration: the driven torque carries J·α
            u = (rng.uniform(-2e4, 2e4), load)
        dx = model.rhs(0.0, x, u)
        sol = model.mechanism.solve(omega, wp, load, torque=u[0], detail=True) if drive == "torque" else None
        if sol is not None and not sol.consistent:
            # rigid Coulomb contact without a solution (Painlevé): only far from the carriers'
            # equilibrium, where the slip direction makes a thread self-locking
            zeta = [s.zeta_geometric for s in model.mechanism.stages]
            assert fidelity == "dynamic"
            assert max(abs(w / omega - z) for w, z in zip(wp, zeta)) > 0.1
            inconsistent += 1
            continue
        p_in, p_out, p_f = dx[-3], dx[-2], dx[-1]
        scale = abs(p_in) + abs(p_out) + abs(p_f) + 1e-12
        assert p_f >= -1e-12 * scale, "friction must dissipate"
        assert abs(p_in - p_out - p_f - dT_dt(model, x, dx, u)) <= 1e-10 * scale


@pytest.mark.parametrize("mech", sorted(MECHANISMS))
@pytest.mark.parametrize("fidelity", ["dynamic", "quasi-static", "kinematic"])
def test_hot_path_rates_equal_the_detailed_solution(mech, fidelity):
    """Mechanism.rates (the rhs's path) and Mechanism.solve with and without detail share
    one recursion: the same acceleration, motor torque, carrier accelerations and friction
    power, also in the friction band and where the sign iteration has to bracket."""
    model = make_model(MECHANISMS[mech](), fidelity, "torque")
    mech_ = model.mechanism
    rng = random.Random(4321)
    for _ in range(200):
        omega = rng.choice([1.0, -1.0]) * 10 ** rng.uniform(-6, 2.5)
        wp = [omega * rng.uniform(-0.5, 1.0) for _ in range(model.n_carrier_states)]
        load, torque = rng.uniform(-8000.0, 8000.0), rng.uniform(-40.0, 40.0)
        for drive in ({"torque": torque}, {"acceleration": rng.uniform(-1e4, 1e4)}):
            alpha, motor, acc, p_fric = mech_.rates(omega, wp, load, **drive)
            for detail in (False, True):
                sol = mech_.solve(omega, wp, load, detail=detail, **drive)
                if not sol.consistent:
                    # no rigid solution: the hot path gives NaN so no stepper integrates on
                    assert all(math.isnan(v) for v in (alpha, motor, p_fric, *acc))
                    continue
                assert (alpha, motor) == (sol.screw_acceleration, sol.motor_torque)
                assert acc == pytest.approx(sol.carrier_accelerations, rel=1e-14, abs=0.0)
                assert p_fric == pytest.approx(sol.friction_power, rel=1e-12, abs=1e-12 * abs(motor * omega))


@pytest.mark.parametrize("mech", sorted(MECHANISMS))
def test_carrier_accelerations_vanish_at_the_equilibrium_ratio(mech):
    params = MECHANISMS[mech]()
    dyn = make_model(params, "dynamic", "speed")
    zeta = [s.zeta_geometric for s in dyn.mechanism.stages]
    for omega, load in [(100.0, 5000.0), (-30.0, 2000.0), (5.0, -3000.0)]:
        x = [0.0, omega] + [z * omega for z in zeta] + [0.0] * 3
        dx = dyn.rhs(0.0, x, (0.0, load))
        for k, z in enumerate(zeta):
            # carrier acceleration relative to what ω·ζ would change in 1 µs
            assert abs(dx[2 + k]) * 1e-6 <= 1e-12 * abs(omega)


def test_equilibrium_ratio_is_independent_of_friction_and_load():
    base = two_stage()
    ref = [s.zeta_geometric for s in make_model(base, "quasi-static").mechanism.stages]
    for mu_sr, mu_ss in [(0.05, 0.1), (0.2, 0.3), (0.0, 0.0)]:
        p = base.with_changes(mu_screw_roller=mu_sr, mu_spline=mu_ss)
        got = [s.zeta_geometric for s in make_model(p, "quasi-static").mechanism.stages]
        assert got == pytest.approx(ref, rel=1e-13)
    assert ref[1] > ref[0]  # Li et al. (2021) §3.1: carrier 2 faster than carrier 1 at steady state
    # both slightly below pure rolling at the pitch circles, r_S/(r_S + r_N) = 0.375
    assert all(0.37 < z < 0.375 for z in ref)


@pytest.mark.parametrize("mech", sorted(MECHANISMS))
def test_quasi_static_equals_dynamic_at_the_carrier_equilibrium(mech):
    params = MECHANISMS[mech]()
    qs = make_model(params, "quasi-static", "speed")
    dyn = make_model(params, "dynamic", "speed")
    zeta = [s.zeta_geometric for s in dyn.mechanism.stages]
    for omega, load in [(100.0, 5000.0), (-40.0, 7000.0), (60.0, -4000.0)]:
        yq = qs.outputs(0.0, [0.0, omega, 0.0, 0.0, 0.0], (0.0, load))
        yd = dyn.outputs(0.0, [0.0, omega] + [z * omega for z in zeta] + [0.0] * 3, (0.0, load))
        for name in yq:
            if name == "kinetic_energy":
                continue  # carriers' energy is counted the same way; checked below
            assert yq[name] == pytest.approx(yd[name], rel=1e-12, abs=1e-12), name
        assert yq["kinetic_energy"] == pytest.approx(yd["kinetic_energy"], rel=1e-12)


def test_kinematic_level_is_an_ideal_screw_with_inertia():
    params = two_stage()
    lead_per_rad = params.total_lead / (2 * math.pi)
    ideal = make_model(params, "kinematic", "torque")
    j_all = ideal.mechanism.equivalent_inertia()
    x = [0.0, 50.0, 0.0, 0.0, 0.0]
    for torque, load in [(10.0, 5000.0), (-3.0, 1000.0), (0.0, -2000.0)]:
        dx = ideal.rhs(0.0, x, (torque, load))
        # virtual work: J α = M − F·ΣL/2π
        assert dx[1] == pytest.approx((torque - load * lead_per_rad) / j_all, rel=1e-12)
    lossy = make_model(params, "kinematic", "speed", efficiency=0.8)
    y = lossy.outputs(0.0, [0.0, 100.0, 0.0, 0.0, 0.0], (0.0, 5000.0))
    assert y["efficiency"] == pytest.approx(0.8, rel=1e-6)
    ratio = [s.zeta_ideal for s in lossy.mechanism.stages]
    st = params.stages
    assert ratio == pytest.approx([s.screw_radius / (s.screw_radius + s.nut_radius) for s in st], rel=1e-12)


def test_frictionless_dynamic_torque_equals_virtual_work_for_any_contact_geometry():
    params = two_stage().with_changes(mu_screw_roller=0.0, mu_spline=0.0)
    model = make_model(params, "dynamic", "speed")
    y = model.outputs(0.0, [0.0, 100.0, 11.0, -7.0, 0.0, 0.0, 0.0], (0.0, 5000.0))
    assert y["screw_torque"] == pytest.approx(5000.0 * params.total_lead / (2 * math.pi), rel=1e-12)
    assert y["efficiency"] == pytest.approx(1.0, rel=1e-12)


def test_negative_load_moves_the_contact_to_the_other_flank():
    model = make_model(two_stage(), "quasi-static", "speed")
    pos = model.outputs(0.0, [0.0, 100.0, 0.0, 0.0, 0.0], (0.0, 5000.0))
    neg = model.outputs(0.0, [0.0, 100.0, 0.0, 0.0, 0.0], (0.0, -5000.0))
    for k in (1, 2):
        assert pos[f"stage[{k}].contact_force"] > 0 > neg[f"stage[{k}].contact_force"]
        assert pos[f"stage[{k}].normal_force"] > 0 and neg[f"stage[{k}].normal_force"] > 0
    # an assisting load: the motor torque is below the ideal value, and negative here
    assert neg["screw_torque"] < 0


def test_forces_are_continuous_through_zero_load_and_zero_speed():
    model = make_model(two_stage(), "dynamic", "speed")
    names = ["screw_torque", "stage[1].contact_force", "stage[2].contact_force",
             "stage[2].spline_friction", "friction_power"]
    for eps in (1e-6, 1e-9):
        a = model.outputs(0.0, [0.0, 80.0, 30.0, 30.0, 0, 0, 0], (0.0, eps))
        b = model.outputs(0.0, [0.0, 80.0, 30.0, 30.0, 0, 0, 0], (0.0, -eps))
        for n in names:
            # each output changes by at most ~|Δload| (forces per roller: Δload/N_R)
            assert abs(a[n] - b[n]) <= 2 * eps + 1e-9, n
    torque = make_model(two_stage(), "dynamic", "torque")
    ys = [torque.outputs(0.0, [0.0, w, 0.3 * w, 0.3 * w, 0, 0, 0], (5.0, 5000.0))
          for w in (-1e-9, 0.0, 1e-9)]
    for n in names + ["screw_acceleration"]:
        vals = [y[n] for y in ys]
        # ω changes by 2e-9 rad/s: a continuous law moves forces by far less than 1e-4 N
        assert max(vals) - min(vals) <= 1e-4 + 1e-6 * max(abs(v) for v in vals), n


def test_unphysical_friction_coefficient_is_rejected_with_its_range():
    with pytest.raises(ValueError, match="mu_screw_roller"):
        make_model(two_stage().with_changes(mu_screw_roller=0.75), "dynamic")
    with pytest.raises(ValueError, match="drive"):
        make_model(two_stage(), "dynamic", "position")
    with pytest.raises(ValueError, match="fidelity"):
        make_model(two_stage(), "multibody")


@pytest.mark.parametrize("mu_ns", [0.0, 0.005])
def test_rigid_contact_solution_exists_near_the_carrier_equilibrium(mu_ns):
    # back-drivable mechanisms only: a thread or bearing that self-locks in back-drive makes the
    # rigid Coulomb problem ill-posed when braking (docs/model.md §3), which the model flags
    params = three_stage().with_changes(mu_nut_screw=mu_ns)
    model = make_model(params, "dynamic", "torque")
    zeta = [s.zeta_geometric for s in model.mechanism.stages]
    rng = random.Random(99)
    for _ in range(300):
        omega = rng.choice([1.0, -1.0]) * 10 ** rng.uniform(-4, 2.5)
        wp = [omega * (z + rng.uniform(-0.05, 0.05)) for z in zeta]
        sol = model.mechanism.solve(omega, wp, rng.uniform(-8000, 8000), torque=rng.uniform(-40, 40))
        assert sol.consistent


def test_sign_iteration_converges_without_bracketing_when_bearing_force_is_negative():
    # Li et al. (2021) has spline friction but no bearing friction: the sign of the bearing force is
    # irrelevant and must not keep a converged iteration from being accepted (regression: the
    # fallback root search ran at every evaluation of a braking heavy load)
    model = make_model(two_stage(), "quasi-static", "torque")
    mech = model.mechanism
    calls = []
    original = mech._bracket
    mech._bracket = lambda *a: calls.append(a) or original(*a)
    # a state where B_1 < 0: screw 2's inertial force m_S2 c_1 α and the nut-2 assembly's
    # m_A2 c_2 α outweigh the 36 N load while the motor drives hard in the direction of motion
    omega, load, torque = -18.42, 36.09, -0.2
    sol = mech.solve(omega, (), load, torque=torque, detail=True)
    assert sol.consistent and not calls
    assert sol.bearing_force[0] < 0     # the case that used to cycle
    # and the acceleration balances the motor torque exactly
    assert model.mechanism.solve(omega, (), load, acceleration=sol.screw_acceleration).motor_torque == pytest.approx(torque, rel=1e-12)
