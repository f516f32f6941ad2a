"""``fidelity = "auto"``: the estimate of each level's model error and the choice it makes.

Expected values: the carriers' lag in steady acceleration is the linearised first-order lag
ζ*·α·τ with τ from the linearised carrier dynamics; on each scene, the level ``auto`` picks must
meet the scene's tolerance against a reference run of the dynamic level, and the next cheaper
level must not (docs/accuracy.md §1 error measure, benchmarks/work_precision.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from prsm_fmu import presets, simulate
from prsm_fmu.mechanics import Mechanism
from prsm_fmu.models import FIDELITIES, make_model
from prsm_fmu.models.auto import (MARGIN, carrier_time_constant, carrier_time_constants,
                                  choose_fidelity, choose_for_start, effective_load)
from prsm_fmu.models.auto import steady_efficiency

from benchmark_modules import load_benchmark as _load  # noqa: E402




wp = _load("work_precision")
LI2021 = presets.load("li2021_two_stage")


# ---- the estimate's ingredients ----------------------------------------------------------

@pytest.mark.parametrize("omega, load", [(100.0, 5000.0), (1.0, 10000.0), (-30.0, 2000.0)])
def test_fastest_finite_difference_time_constant_is_the_closed_form_one(omega, load):
    taus = carrier_time_constants(LI2021, omega, load)
    assert min(taus) == pytest.approx(carrier_time_constant(LI2021, omega, load), rel=1e-6)


def test_carrier_time_constant_is_proportional_to_speed_over_load():
    t1 = max(carrier_time_constants(LI2021, 50.0, 2000.0))
    t2 = max(carrier_time_constants(LI2021, 100.0, 1000.0))
    assert t2 == pytest.approx(4.0 * t1, rel=1e-3)


def test_carriers_in_steady_acceleration_trail_equilibrium_by_zeta_alpha_tau():
    """Torque drive, constant motor torque, carriers started at equilibrium: after many τ the
    dynamic level's carriers lag ζ*ω by ζ*·α·τ (linearised first-order lag), τ at the axial
    force that presses the threads: the load plus the last nut's inertia force."""
    torque, load = 25.0, 5000.0
    res = simulate(LI2021, "dynamic", "torque", screw_torque=torque, load_force=load,
                   t_end=2e-3, output_interval=1e-4, initial_screw_speed=100.0,
                   initial_carrier_ratio=None, rtol=1e-10, atol=1e-12)
    mech = Mechanism(LI2021, "dynamic")
    w, a = res["screw_speed"][-1], res["screw_acceleration"][-1]
    assert a > 1e3                                       # a real, steady acceleration
    taus = carrier_time_constants(LI2021, w, effective_load(LI2021, load, a))
    for k, (s, tau) in enumerate(zip(mech.stages, taus), start=1):
        lag = s.zeta_geometric * w - res[f"stage[{k}].carrier_speed"][-1]
        assert lag == pytest.approx(s.zeta_geometric * a * tau, rel=0.03), k


# ---- the choice --------------------------------------------------------------------------

def test_choice_is_the_cheapest_level_within_tolerance():
    op = dict(screw_speed=100.0, load_force=5000.0, acceleration=1000.0, comm_step=1e-4)
    est = choose_fidelity(LI2021, 1.0, **op)
    assert est.errors["dynamic"] == 0.0
    assert est.errors["kinematic"] >= est.errors["quasi-static"] > 0.0
    for tol, level in ((2.0 * MARGIN * est.errors["kinematic"], "kinematic"),
                       (1.01 * MARGIN * est.errors["quasi-static"], "quasi-static"),
                       (0.99 * MARGIN * est.errors["quasi-static"], "dynamic")):
        assert choose_fidelity(LI2021, tol, **op).fidelity == level


def test_kinematic_estimate_is_the_friction_loss():
    qs = make_model(LI2021, "quasi-static", "speed")
    u = (0.0, 1000.0)          # speed drive: 100 rad/s held, 1 kN
    eta = qs.outputs(0.0, qs.initial_state(u, screw_speed=100.0), u)["efficiency"]
    c = choose_fidelity(LI2021, 1e-3, screw_speed=0.0, load_force=0.0)
    assert c.terms["friction_loss"] == pytest.approx(1.0 - eta, rel=1e-12)
    assert 0.1 < c.terms["friction_loss"] < 0.3


def test_make_model_auto_needs_a_tolerance_and_reports_its_choice():
    with pytest.raises(ValueError, match="tolerance"):
        make_model(LI2021, "auto", "torque")
    m = make_model(LI2021, "auto", "speed", tolerance=1e-3, inputs=(0.0, 5000.0),
                   screw_speed=100.0, carrier_ratio=0.0, comm_step=1e-5)
    assert m.fidelity == "auto" and m.start == "dynamic" == m.auto_choice.fidelity
    m = make_model(LI2021, "auto", "torque", tolerance=1e-6)      # at rest, no load
    assert m.start == "quasi-static" == m.auto_choice.fidelity
    # a mechanism without spline friction, a kinematic efficiency equal to its own: the
    # kinematic level's estimate is only the carrier ratio's offset
    one = presets.load("friction_single_stage")
    eta = steady_efficiency(one)
    m = make_model(one, "auto", "torque", tolerance=0.5, efficiency=eta)
    assert m.fidelity == "kinematic" == m.auto_choice.fidelity


def test_kinematic_estimate_covers_its_missing_friction_outputs():
    """The kinematic level has no spline friction: over the FMU's outputs its error is 1 on
    Li et al. (2021) (measured on a steady run against the quasi-static level), and so is its estimate,
    whatever its constant efficiency."""
    u = (0.0, 5000.0)          # speed drive: 100 rad/s held, 5 kN
    y = {}
    for fid, opts in (("kinematic", {"efficiency": 0.8}), ("quasi-static", {})):
        m = make_model(LI2021, fid, "speed", **opts)
        y[fid] = m.outputs(0.0, m.initial_state(u, screw_speed=100.0), u)
    measured = abs(y["kinematic"]["stage[2].spline_friction"]
                   - y["quasi-static"]["stage[2].spline_friction"]) \
        / abs(y["quasi-static"]["stage[2].spline_friction"])
    assert measured == 1.0
    for eff in (1.0, 0.8):
        c = choose_fidelity(LI2021, 1.0, screw_speed=100.0, load_force=5000.0,
                            kinematic_efficiency=eff)
        assert c.errors["kinematic"] >= measured and c.fidelity != "kinematic"


def test_fmu_default_start_selects_the_documented_auto_level():
    """The FMU's start values (at rest, no inputs) make auto pick slave.AUTO_FIDELITY."""
    c = choose_for_start(LI2021, 1e-6, "torque", (0.0, 0.0), carrier_ratio=0.0)
    assert c.fidelity == "quasi-static"


# ---- on the scenes -----------------------------------------------------------------------

def _level_error(scene, ref, config) -> float:
    p = wp.measure(scene, config, ref)
    assert p.status == "ok", p.status
    return p.error


def test_startup_auto_starts_dynamic_meets_1e_6_and_quasi_static_does_not():
    """Carriers at rest under a turning screw: the start needs the dynamic level; ``auto``
    (switching to the quasi-static level once the carriers have settled, tests/test_adaptive.py)
    meets the scene's 1e-6 with its stepper at a tighter tolerance, the quasi-static level
    alone does not."""
    scene = wp.STARTUP
    tol = scene.target_error
    assert scene.auto(tol).fidelity == "dynamic"
    ref = wp.reference(scene, wp.REFERENCE_RTOL)
    auto = wp.Config("auto", "explicit_adaptive", "rtol", tol)
    res = scene.run(auto, time_it=False)
    errors = wp.output_errors(res.outputs, ref.outputs, scene.outputs)
    assert max(errors.values()) <= tol
    assert _level_error(scene, ref, wp.Config("quasi-static", "closed_form")) > tol


LOOP_CASES = [
    # scene, cut to [s], tolerance, the level auto must pick
    ("position_step", 0.06, 1e-4, "dynamic"),
    ("load_step", 0.04, 5e-3, "quasi-static"),
    ("sine_tracking", 0.15, 1e-4, "dynamic"),
    # through zero speed and to the end of the ramp (the carriers' largest lag, at 50 ms); the
    # last sample before zero speed is where ROS34PW2 at rtol 1e-4 misses 1e-4 (8.7e-4,
    # docs/accuracy.md §2), so this case holds auto's default stepper to the scene's 1e-4 there
    ("speed_reversal", 0.06, 1e-4, "dynamic"),
]


@pytest.mark.parametrize("name, t_end, tol, level", LOOP_CASES)
def test_loop_scene_auto_level_meets_tolerance_and_the_next_cheaper_does_not(name, t_end, tol,
                                                                             level):
    """The actuator loop with the PRSM as Python block: the level the estimate along the run
    asks for, ``auto`` (which switches levels along the run) and that level meet the tolerance,
    the next cheaper level does not.  Reference: the dynamic level with ROS34PW2 at rtol 1e-10 (within 1e-9 of Radau at rtol 1e-12 on both scenes: measured by
    benchmarks/work_precision.py; Radau would cost the test 6–19 s per scene)."""
    choice = wp.loop_auto_choice(name, tol, t_end)
    assert choice.fidelity == level
    run = wp.make_loop_runner(name, t_end)
    outs = wp.loop_outputs(name)
    ref = run(wp.Config("dynamic", "rosenbrock", "rtol", 1e-10), time_it=False)

    def err(cfg):
        r = run(cfg, time_it=False)
        return max(wp.output_errors(r.outputs, ref.outputs, outs).values())

    # auto itself (the level of each step chosen along the run) with its default stepper (the
    # FMU's) at the tolerance
    assert err(wp.Config("auto", "default", "rtol", tol)) <= tol
    if level != "dynamic":
        assert err(wp.Config(level, "closed_form")) <= tol
    cheaper = FIDELITIES[FIDELITIES.index(level) - 1]
    e_cheaper = err(wp.Config(cheaper, "closed_form"))
    assert e_cheaper > tol
    # the estimate is within a factor MARGIN of the measured model error of that level
    if cheaper == "quasi-static":
        assert choice.errors[cheaper] == pytest.approx(e_cheaper, rel=1.0 - 1.0 / MARGIN)
    assert math.isfinite(choice.errors["quasi-static"])
    assert np.isfinite(e_cheaper)
