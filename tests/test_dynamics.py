"""Time-domain physics: steady states, energy balance, Li et al.'s (2021) transient, stiffness.

Expected values: the independent root-finding steady state (steady_state.py shares no code
with the force recursion), conservation of energy, the Li et al. (2021) paper's statements with the
tolerances stated at each test, and stability limits computed from the linearised carrier time
constants (not from the steppers' output).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from prsm_fmu import presets, simulate, steady_state
from prsm_fmu.models import make_model
from prsm_fmu.profiles import RampSpeed
from prsm_fmu.steppers import StepFailure, make_stepper

LI2021 = presets.load("li2021_two_stage")
STAGE_KEYS = ["carrier_speed_ratio", "contact_force", "driven_torque"]


def energy_residual(r) -> float:
    """max_t |W_in − W_out − W_f − ΔT| / max_t |W_in| over a run [-]."""
    res = r["input_work"] - r["output_work"] - r["friction_work"] - (r["kinetic_energy"] - r["kinetic_energy"][0])
    return float(np.max(np.abs(res)) / np.max(np.abs(r["input_work"])))


@pytest.fixture(scope="module")
def startup():
    """Li et al. (2021) §3.1: screw speed stepped to 100 rad/s, F_N2 = 5000 N, carriers at rest."""
    return simulate(LI2021, "dynamic", "speed", screw_speed=100.0, load_force=5000.0,
                    t_end=1.5e-3, output_interval=2e-6, stepper="radau",
                    stepper_options={"rtol": 1e-11, "atol": 1e-13})


@pytest.mark.parametrize("omega,load", [(100.0, 5000.0), (-60.0, 3000.0), (40.0, -7000.0)])
def test_dynamic_level_run_to_steady_state_equals_the_root_finder_to_1e_6(omega, load):
    r = simulate(LI2021, "dynamic", "speed", screw_speed=omega, load_force=load, t_end=3e-3,
                 output_interval=1e-4, stepper="radau", stepper_options={"rtol": 1e-11, "atol": 1e-13})
    ss = steady_state(LI2021, screw_speed=omega, load_force=load)
    names = ["screw_torque", "efficiency"] + [f"stage[{k}].{q}" for k in (1, 2) for q in STAGE_KEYS]
    names.append("stage[2].spline_friction")
    for name in names:
        assert r[name][-1] == pytest.approx(ss[name], rel=1e-6), name


@pytest.mark.parametrize("omega,load", [(100.0, 5000.0), (-60.0, 3000.0), (40.0, -7000.0), (0.5, 100.0)])
def test_quasi_static_level_equals_the_root_finder_to_1e_9(omega, load):
    model = make_model(LI2021, "quasi-static", "speed")
    y = model.outputs(0.0, [0.0, omega, 0.0, 0.0, 0.0], (0.0, load))   # speed held
    ss = steady_state(LI2021, screw_speed=omega, load_force=load)
    for name in ["screw_torque", "efficiency", "friction_power", "stage[2].spline_friction"] + [
            f"stage[{k}].{q}" for k in (1, 2) for q in STAGE_KEYS + ["normal_force"]]:
        assert y[name] == pytest.approx(ss[name], rel=1e-9), name


def test_energy_balance_closes_over_the_start_up_transient(startup):
    # speed drive: the screw's kinetic energy at t = 0 is part of T(0); W_in = ∫ M_S1 ω dt
    assert energy_residual(startup) <= 1e-9


@pytest.mark.parametrize("stepper", ["rosenbrock", "exponential"])
def test_energy_balance_closes_over_the_start_up_with_the_stiff_steppers(stepper):
    # the start-up of the fixture with 10 µs communication steps (the carriers' transient
    # spans ~0.1 ms): the work integrals are integrated with the speeds, the balance closes
    r = simulate(LI2021, "dynamic", "speed", screw_speed=100.0, load_force=5000.0,
                 t_end=1.5e-3, output_interval=1e-5, stepper=stepper,
                 stepper_options={"rtol": 1e-9, "atol": 1e-12})
    assert energy_residual(r) <= 1e-9


@pytest.mark.parametrize("fidelity", ["dynamic", "quasi-static"])
def test_energy_balance_closes_on_a_speed_ramp_0_to_100_rad_s_in_1_ms(fidelity):
    # the prescribed acceleration 1e5 rad/s² enters the driven torque as J·α: the input work
    # then pays for the kinetic energy (≈ ½ · 4.2e-4 kg·m² · (100 rad/s)² ≈ 2.1 J) as well as
    # the load and the losses
    r = simulate(LI2021, fidelity, "speed", screw_speed=RampSpeed(0.0, 100.0, 1e-3),
                 load_force=5000.0, t_end=1.5e-3, output_interval=1e-5, stepper="radau",
                 stepper_options={"rtol": 1e-11, "atol": 1e-13})
    assert r["screw_speed"][100] == pytest.approx(100.0, rel=1e-12)
    assert energy_residual(r) <= 1e-9
    # the kinetic energy gained is a large part of the input work: the J·α term is there
    assert r["kinetic_energy"][-1] - r["kinetic_energy"][0] > 0.1 * r["input_work"][-1]


@pytest.mark.parametrize("stepper,opts", [("radau", {"rtol": 1e-11, "atol": 1e-13}),
                                          ("rosenbrock", {"rtol": 1e-9, "atol": 1e-12}),
                                          # a tenth of the rtol: the same accuracy
                                          # (steppers.options.TOLERANCE_FACTOR)
                                          ("exponential", {"rtol": 1e-10, "atol": 1e-13}),
                                          ("explicit_adaptive", {"rtol": 1e-9, "atol": 1e-12})])
def test_energy_balance_closes_over_a_speed_reversal_through_zero(stepper, opts):
    # motor torque drops to 5 N·m under a 5 kN load: the screw stops at ~1.04 ms and the load
    # back-drives it; the carriers' time constants collapse to nanoseconds at zero speed
    r = simulate(LI2021, "dynamic", "torque", screw_torque=5.0, load_force=5000.0,
                 t_end=1.5e-3, output_interval=1e-5, initial_screw_speed=30.0,
                 initial_carrier_ratio=None, stepper=stepper, stepper_options=opts)
    assert r["screw_speed"][0] > 0 > r["screw_speed"][-1]
    assert energy_residual(r) <= 1e-9


def test_torque_driven_start_from_rest_balances_energy():
    r = simulate(LI2021, "dynamic", "torque", screw_torque=25.0, load_force=5000.0,
                 t_end=2e-3, output_interval=1e-5, stepper="rosenbrock",
                 stepper_options={"rtol": 1e-8, "atol": 1e-11})
    assert r["screw_speed"][-1] > 10.0
    assert energy_residual(r) <= 1e-6


# Li et al. (2021) §3.1–3.3's statements: tests/test_li2021_paper.py


# ---- stiffness: stability where explicit methods fail ------------------------------------

RK4_REAL_AXIS_LIMIT = 2.785293563405282   # |hλ| where RK4's stability polynomial reaches 1


def run_fixed(stepper, model, x0, u, h, n):
    """n fixed steps; None if the state stops being finite."""
    x = list(x0)
    for i in range(n):
        x, _ = stepper.advance(i * h, x, u, h)
        if not all(math.isfinite(v) for v in x):
            return None
    return x


def carrier_ratio_error(model, x) -> float:
    """Largest |ω_Pk/ω − ζ*_k| [-] (0 at the carriers' equilibrium)."""
    return max(abs(x[2 + k] / x[1] - s.zeta_geometric) for k, s in enumerate(model.mechanism.stages))


@pytest.fixture(scope="module")
def stiff_point():
    model = make_model(LI2021, "dynamic", "torque")
    u = (LI2021.total_lead / (2 * math.pi) * 5000.0 / 0.806, 5000.0)   # ≈ steady torque
    x0 = model.initial_state(u, screw_speed=100.0, carrier_ratio=None)
    x0[2] *= 0.999                                                      # a small disturbance
    tau = model.fastest_time_constant(x0, u)
    return model, x0, u, tau * RK4_REAL_AXIS_LIMIT


def test_predicted_explicit_limit_is_where_rk4_fails(stiff_point):
    model, x0, u, h_lim = stiff_point
    rk4 = make_stepper("rk4", model)
    stable = run_fixed(rk4, model, x0, u, 0.8 * h_lim, 400)
    assert stable is not None and carrier_ratio_error(model, stable) < 1e-6
    # beyond the limit the linear instability is saturated by the Coulomb law: the carriers
    # stay bounded but lock into a limit cycle far from equilibrium ("bounded but wrong")
    unstable = run_fixed(rk4, model, x0, u, 1.25 * h_lim, 400)
    assert unstable is None or carrier_ratio_error(model, unstable) > 1e-2


def test_implicit_stepper_is_stable_and_right_at_100x_the_explicit_limit(stiff_point):
    model, x0, u, h_lim = stiff_point
    ros = make_stepper("rosenbrock", model, fixed_substeps=1)
    x = run_fixed(ros, model, x0, u, 100 * h_lim, 50)
    assert x is not None
    for k, s in enumerate(model.mechanism.stages):   # settled on the right equilibrium
        assert x[2 + k] / x[1] == pytest.approx(s.zeta_geometric, rel=1e-6)


@pytest.mark.parametrize("stepper", ["rosenbrock", "explicit_adaptive"])
def test_reversal_through_zero_speed_has_no_nan_and_no_chatter(stepper):
    kw = dict(screw_torque=5.0, load_force=5000.0, t_end=1.5e-3, output_interval=5e-6,
              initial_screw_speed=30.0, initial_carrier_ratio=None)
    ref = simulate(LI2021, "dynamic", "torque", stepper="radau",
                   stepper_options={"rtol": 1e-10, "atol": 1e-12}, **kw)
    r = simulate(LI2021, "dynamic", "torque", stepper=stepper,
                 stepper_options={"rtol": 1e-6, "atol": 1e-9}, **kw)
    for name in ["screw_torque", "stage[1].contact_force", "stage[2].contact_force",
                 "stage[2].spline_friction", "stage[1].carrier_speed", "friction_power"]:
        assert np.all(np.isfinite(r[name])), name
        # chatter = spurious oscillation: total variation must not exceed the reference's
        tv, tv_ref = np.sum(np.abs(np.diff(r[name]))), np.sum(np.abs(np.diff(ref[name])))
        assert tv <= tv_ref * 1.01 + 1e-9, name


# ---- states the rigid contact cannot resolve are never silent ------------------------------

def _li2021_with_inertias_in_kg_mm2_times_1e_9():
    """Li et al. (2021) §3.1 with every inertia 1000x too small (kg·mm² taken as 1e-9 kg·m², the
    presets' old error): J_S = 55e-9, 170e-9; J_R = 0.08e-9, 0.48e-9; J_P = 3e-9, 12e-9 kg·m²;
    carrier masses J_P/(r_S + r_R)² = 3e-9/1.69e-4 and 12e-9/4.84e-4 kg."""
    s1, s2 = LI2021.stages
    s1 = s1.__class__(**{**s1.__dict__, "screw_inertia": 55e-9, "roller_inertia": 0.08e-9,
                          "carrier_inertia": 3e-9, "carrier_mass": 3e-9 / 1.69e-4})
    s2 = s2.__class__(**{**s2.__dict__, "screw_inertia": 170e-9, "roller_inertia": 0.48e-9,
                          "carrier_inertia": 12e-9, "carrier_mass": 12e-9 / 4.84e-4})
    return LI2021.with_changes(stages=(s1, s2)).validate()


STUCK = dict(screw_torque=20.0, load_force=500.0, t_end=2e-3, output_interval=1e-5,
             initial_screw_speed=-1.0, initial_carrier_ratio=0.0)


@pytest.mark.parametrize("stepper", ["rosenbrock", "exponential", "radau", "explicit_adaptive",
                                     "rk4"])
def test_a_state_without_rigid_solution_is_refused_with_its_named_cause(stepper):
    # −1 rad/s, carriers at rest, +20 N·m: with the light inertias the slip direction makes
    # stage 1's thread self-locking for forward acceleration, M_S1(α) falls for α > 0 and never
    # reaches 20 N·m: no acceleration exists (Painlevé).  No stepper may return a state.
    with pytest.raises(StepFailure, match=r"effective inertia dM_S1/dα = -[0-9.e-]+ kg·m² is <= 0"):
        simulate(_li2021_with_inertias_in_kg_mm2_times_1e_9(), "dynamic", "torque",
                 stepper=stepper, rtol=1e-6, atol=1e-9, **STUCK)


def test_the_same_start_with_the_seeds_inertias_runs_and_closes_energy():
    r = simulate(LI2021, "dynamic", "torque", stepper="radau", rtol=1e-10, atol=1e-12, **STUCK)
    assert np.all(np.isfinite(r["screw_speed"]))
    # it reverses and accelerates forward: (20 N·m − ~2 N·m load torque) / ~4.3e-4 kg·m²
    # ≈ 4e4 rad/s² at most, so |ω| stays below 1 + 4e4 · 2e-3 = 81 rad/s
    assert 0.0 < r["screw_speed"][-1] < 81.0
    assert energy_residual(r) <= 1e-9
