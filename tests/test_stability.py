"""Stability boundaries of the explicit steppers on the stiff carriers, and reproducible errors.

Expected values: the largest stable step is predicted from the linearised carrier time constant
at the operating point (``model.fastest_time_constant``) times the real-axis stability limit of
the method's stability polynomial (closed form, no stepping); the classification is against a
Radau reference at rtol 1e-12.  The work-precision errors must not depend on the run (costs
may).  The benchmarks are loaded from benchmarks/ by path; their maps and charts are made by
``python benchmarks/stability_maps.py`` and ``python benchmarks/work_precision.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmark_modules import load_benchmark as _load  # noqa: E402




maps = _load("stability_maps")
wp = _load("work_precision")

#: |hλ| where RK4's stability polynomial 1 + z + z²/2 + z³/6 + z⁴/24 reaches 1 on the negative
#: real axis (the constant of tests/test_dynamics.py)
RK4_REAL_AXIS_LIMIT = 2.785293563405282


# ---- stability polynomials -----------------------------------------------------------------

def test_rk4_stability_polynomial_is_the_taylor_polynomial_and_its_limit_is_2_785():
    coeffs = maps.stability_polynomial(*maps.RK4_TABLEAU)
    assert coeffs == pytest.approx([1, 1, 1 / 2, 1 / 6, 1 / 24], abs=1e-15)
    assert maps.method_limits()["rk4"] == pytest.approx(RK4_REAL_AXIS_LIMIT, abs=1e-12)


@pytest.mark.parametrize("method", ["rk4", "explicit_adaptive"])
def test_real_axis_limit_is_the_end_of_the_stability_interval(method):
    a_rows, b = (maps.RK4_TABLEAU if method == "rk4"
                 else maps.EXPLICIT_TABLEAUS[5][1:3])
    coeffs = maps.stability_polynomial(a_rows, b)
    xstar = maps.method_limits()[method]

    def amp(x):
        return abs(np.polyval(coeffs[::-1], -x))

    assert amp(xstar) == pytest.approx(1.0, abs=1e-9)
    assert all(amp(x) < 1.0 for x in np.linspace(1e-3, xstar * (1 - 1e-6), 2000))
    assert amp(xstar * 1.001) > 1.0
    if method == "explicit_adaptive":   # Dormand–Prince 5(4): order 5 and a 6th-degree term
        assert coeffs[:6] == pytest.approx([1 / math.factorial(k) for k in range(6)], rel=1e-12)
        assert 3.2 < xstar < 3.4


# ---- stiff carriers: both sides of every predicted boundary --------------------------------

POINTS = [("speed", 100.0, 5000.0), ("speed", 3.0, 10000.0),
          ("torque", 100.0, 5000.0), ("torque", 30.0, 2000.0)]


@pytest.fixture(scope="module", params=POINTS, ids=lambda p: f"{p[0]}-{p[1]:g}rad_s-{p[2]:g}N")
def point(request):
    drive, omega, load = request.param
    return maps.operating_point(drive, omega, load)


def test_reference_settles_on_the_carriers_equilibrium_ratio(point):
    # after ≥ 500 carrier time constants the Radau reference sits at ζ* (geometry only),
    # at both ends of the runs' span of lengths
    zeta = [s.zeta_geometric for s in point.model.mechanism.stages]
    assert point.ref_ratios == pytest.approx(zeta, abs=1e-9)
    assert point.ref_check <= 1e-9


@pytest.mark.parametrize("method", ["rk4", "explicit_adaptive"])
def test_explicit_stepper_is_correct_below_and_not_correct_above_the_predicted_limit(point, method):
    # point.tau: model.fastest_time_constant at the undisturbed equilibrium
    h_pred = maps.method_limits()[method] * point.tau
    below, err_below, _ = maps.run_fixed(point, method, 0.8 * h_pred)
    above, err_above, _ = maps.run_fixed(point, method, 1.25 * h_pred)
    assert below == maps.CORRECT, (below, err_below)
    assert err_below <= maps.RATIO_TOL
    # bounded is not right: beyond the limit the run either diverges or settles off ζ*
    assert above in (maps.WRONG, maps.DIVERGED)
    assert above == maps.DIVERGED or err_above > 1e-3


# ---- friction at zero speed: the classification ---------------------------------------------

def test_reversal_rk4_at_one_step_per_communication_step_chatters_and_rosenbrock_passes():
    p = maps.LI2021
    ref = maps.reversal_reference(p, 1e-12)
    assert ref["screw_speed"][0] > 0 > ref["screw_speed"][-1]
    rk4 = maps.classify_reversal(maps.reversal(p, "rk4", "substeps", 1), ref)
    assert rk4["cls"] == maps.WRONG and rk4["reason"] == "chatter"
    ros = maps.classify_reversal(maps.reversal(p, "rosenbrock", "rtol", 1e-4), ref)
    assert ros["cls"] == maps.CORRECT
    assert ros["tv_ratio"] <= maps.CHATTER_MARGIN


# ---- work-precision errors are reproducible ------------------------------------------------

def test_work_precision_errors_are_reproducible_to_1e_12():
    scene = wp.SCENES["startup"]
    grid = (wp.Config("dynamic", "rk4", "substeps", 2),
            wp.Config("dynamic", "explicit_adaptive", "rtol", 1e-6),
            wp.Config("dynamic", "rosenbrock", "rtol", 1e-6),
            wp.Config("quasi-static", "closed_form"),
            wp.Config("kinematic", "rk4", "substeps", 1))
    first = wp.run_scene(scene, grid, verbose=False)
    second = wp.run_scene(scene, grid, verbose=False)
    assert first["reference_difference"] == pytest.approx(second["reference_difference"], abs=1e-12)
    for a, b in zip(first["points"], second["points"]):
        assert a.config == b.config
        assert a.status == b.status == "ok"
        assert a.rhs_calls == b.rhs_calls
        for name in scene.outputs:
            assert abs(a.errors[name] - b.errors[name]) <= 1e-12, (a.config.label, name)
    # and the errors are the physics expected of them: the dynamic level resolves the
    # start-up, the slaved levels miss the carriers' spin-up from rest entirely (ratio 0 → ζ*)
    errs = {p.config: p.error for p in first["points"]}
    assert errs[grid[1]] <= 1e-5
    assert errs[grid[3]] > 0.5 and errs[grid[4]] > 0.5


def test_loop_scene_errors_are_reproducible_to_1e_12():
    """A slice of the position-step loop scene (cut to 15 ms: the step and the acceleration),
    run twice against the same reference run: the same errors to 1e-12, the same rhs counts."""
    run = wp.make_loop_runner("position_step", 0.015)
    outs = wp.loop_outputs("position_step")
    ref = run(wp.Config("dynamic", "rosenbrock", "rtol", 1e-9), time_it=False)
    for cfg in (wp.Config("dynamic", "rosenbrock", "rtol", 1e-5),
                wp.Config("quasi-static", "closed_form")):
        a, b = run(cfg, time_it=False), run(cfg, time_it=False)
        ea, eb = (wp.output_errors(r.outputs, ref.outputs, outs) for r in (a, b))
        assert a.rhs_calls == b.rhs_calls
        for name in outs:
            assert abs(ea[name] - eb[name]) <= 1e-12, (cfg.label, name)
