"""The adaptive steppers end internal steps on the friction law's kinks (docs/accuracy.md,
"Landing on the friction law's kinks"): the secant that finds them, steppers that land exactly on
a law with known solution, a run that chatters around zero speed, and the models' sliding
velocities against the geometry."""

from __future__ import annotations

import math

import pytest

from prsm_fmu import presets
from prsm_fmu.friction import regularised_sign
from prsm_fmu.models import make_model
from prsm_fmu.steppers import StepFailure, make_stepper
from prsm_fmu.steppers.control import kink_fraction

#: the friction band's speed v_ε of the toy problems [m/s]
VE = 1e-4


# ---- the secant ---------------------------------------------------------------------------

def test_kink_fraction_one_component_law_crosses_its_band_edge_first():
    # from +3 v_ε to −3 v_ε: |v| = v_ε at (v_ε − 3 v_ε)/(−6 v_ε) = 1/3, before 0 (1/2) and −v_ε
    # (2/3); |v| is 3 v_ε at both ends, so the resolution bound does not act
    s = kink_fraction([(3 * VE,)], [(-3 * VE,)], [(0.0, VE)], VE)
    assert s == pytest.approx(1.0 / 3.0, rel=1e-12)


def test_kink_fraction_sees_a_slip_vector_that_dips_into_the_band_and_out():
    # s(θ) = (2 − 4θ, 0.5, 0) v_ε: |s| = √4.25 v_ε at both ends, below v_ε where
    # (2 − 4θ)² + 0.25 = 1, first at θ = (2 − √0.75)/4 = 0.283494...: an end-point test misses it
    s = kink_fraction([(2 * VE, 0.5 * VE, 0.0)], [(-2 * VE, 0.5 * VE, 0.0)], [(VE,)], VE)
    assert s == pytest.approx((2.0 - math.sqrt(0.75)) / 4.0, rel=1e-12)


def test_kink_fraction_bounds_the_approach_to_zero_speed():
    # |s| from 10 v_ε to 2 v_ε radially, no kink crossed: the approach may at most halve |s|
    # (10 → 5 v_ε), a change of 5 v_ε out of 8: θ = 5/8
    s = kink_fraction([(10 * VE, 0.0, 0.0)], [(2 * VE, 0.0, 0.0)], [(VE,)], VE)
    assert s == pytest.approx(0.625, rel=1e-12)
    # leaving: from 2 v_ε the speed may at most double (by 2 v_ε): to 6 v_ε is cut at 2/4
    s = kink_fraction([(2 * VE,)], [(6 * VE,)], [(0.0, VE)], VE)
    assert s == pytest.approx(0.5, rel=1e-12)


def test_kink_fraction_leaves_steps_that_start_or_end_on_a_kink():
    # starting on the kink 0 (a secant's landing) towards 0.5 v_ε: nothing ahead, change within
    # v_ε; ending 5e-4 v_ε past v_ε (within the landing band of 1e-3 v_ε) from 1.5 v_ε: landed
    assert kink_fraction([(0.0,)], [(0.5 * VE,)], [(0.0, VE)], VE) is None
    assert kink_fraction([(1.5 * VE,)], [(0.9995 * VE,)], [(0.0, VE)], VE) is None
    # the same end 0.01 v_ε past the kink is a crossing: θ = 0.5/0.51
    s = kink_fraction([(1.5 * VE,)], [(0.99 * VE,)], [(0.0, VE)], VE)
    assert s == pytest.approx(0.5 / 0.51, rel=1e-12)


# ---- steppers on a law with known solution --------------------------------------------------

class _Braked:
    """v' = −A (the input), y' = sgñ(v) of friction.py with v_ε = VE: the regularised Coulomb
    law along a speed that falls at a constant rate through the band.  Inside the band sgñ is
    quadratic in v, so y is a cubic in t between the kinks (v = ±v_ε, 0) and linear outside:
    with steps that end on the kinks, every stepper here (order ≥ 3) is exact up to round-off."""

    n_states = 2
    state_scale = (1e-3, 1e-3)

    def rhs(self, t, x, u):
        return [-u[0], regularised_sign(x[0], VE)]


class _BrakedLanding(_Braked):
    kink_speeds = ((0.0, VE),)

    def sliding_velocities(self, x):
        return [(x[0],)]


def _antiderivative(v: float) -> float:
    """G with G' = sgñ: |v| − v_ε/3 outside the band, v²/v_ε − |v|³/(3 v_ε²) inside (both
    2 v_ε/3 at |v| = v_ε)."""
    a = abs(v)
    return a - VE / 3.0 if a >= VE else v * v / VE - a ** 3 / (3.0 * VE * VE)


def _exact(v0: float, accel_down: float, t: float) -> list[float]:
    """v = v0 − A t and y = ∫ sgñ(v) dt = (G(v0) − G(v))/A (dt = −dv/A)."""
    v = v0 - accel_down * t
    return [v, (_antiderivative(v0) - _antiderivative(v)) / accel_down]


@pytest.mark.parametrize("name", ["rosenbrock", "explicit_adaptive", "exponential", "radau"])
def test_steppers_land_on_the_kinks_and_are_exact_between_them(name):
    # 5 v_ε braked at 1 m/s² over 1 ms: through v_ε, 0, −v_ε to −5 v_ε in one advance
    x0, u, h = [5 * VE, 0.0], (1.0,), 1e-3
    exact = _exact(x0[0], u[0], h)
    y, _ = make_stepper(name, _BrakedLanding(), rtol=1e-6, atol=1e-9).advance(0.0, x0, u, h)
    # y(h) = (G(5 v_ε) − G(−5 v_ε))/A = 0: the friction integral cancels; round-off of the
    # ~50 internal steps on values ≤ 4.7e-4 is below 1e-15
    assert abs(y[0] - exact[0]) < 1e-15 and abs(y[1] - exact[1]) < 1e-15
    # without the model's sliding velocities the same stepper spans the kinks: its error there
    # is the error estimate's blind spot, far above round-off
    y_blind, _ = make_stepper(name, _Braked(), rtol=1e-6, atol=1e-9).advance(0.0, x0, u, h)
    assert abs(y_blind[1] - exact[1]) > 1e-11


@pytest.mark.parametrize("name", ["rosenbrock", "explicit_adaptive", "exponential", "radau"])
def test_chattering_through_zero_speed_keeps_its_step_size(name):
    # the input alternates ±1 m/s² every 0.1 ms: v swings between +v_ε/2 and −v_ε/2 and crosses
    # the kink 0 in the middle of every advance (400 advances); each advance must cost no more
    # than the first few (no step-size collapse), and y follows the exact integral throughout
    model = _BrakedLanding()
    st = make_stepper(name, model, rtol=1e-6, atol=1e-9)
    x, y_exact, h = [0.5 * VE, 0.0], 0.0, 1e-4
    calls, cuts = [], []
    for i in range(400):
        a = 1.0 if i % 2 == 0 else -1.0
        v0 = x[0]
        x, s = st.advance(i * h, x, (a,), h)
        y_exact += (_antiderivative(v0) - _antiderivative(v0 - a * h)) / a
        calls.append(s.rhs_calls)
        cuts.append(s.rejected)
    print(f"{name}: rhs calls per advance: first 4 {calls[:4]}, max of the last 300 "
          f"{max(calls[100:])}; rejected steps per advance {min(cuts)} to {max(cuts)}")
    if name == "radau":
        # radau restarts on every advance: no step size carries over to collapse, and its rhs
        # calls vary with its Newton iterations.  What must hold is that the landing does not
        # chatter within an advance: v is linear in t and crosses only the kink 0 (|v| stays
        # within v_ε/2), once per advance, so at most one cut per advance (none where a step
        # happens to end within the landing band of 0; radau reports only its kink cuts as
        # rejected steps)
        assert max(cuts) <= 1
    else:
        assert max(calls[100:]) <= max(calls[:4])
    assert abs(x[0] - 0.5 * VE) < 1e-15
    # y has no feedback (y' does not depend on y), so the advances' errors add: 400 advances
    # held to the absolute tolerance 1e-9 · 1e-3 = 1e-12 each give at most 4e-10
    assert abs(x[1] - y_exact) < 4e-10


def test_radau_refuses_an_advance_beyond_max_substeps_and_leaves_the_state():
    # braked from 5 v_ε through v_ε, 0 and −v_ε in 1 ms: three kinks, each a cut and a restart,
    # so more than 3 internal steps (accepted + cuts) are needed; with max_substeps = 3 the
    # advance is refused naming the bound, and the caller's state list is unchanged
    x0 = [5 * VE, 0.0]
    st = make_stepper("radau", _BrakedLanding(), rtol=1e-6, atol=1e-9, max_substeps=3)
    with pytest.raises(StepFailure, match=r"more than max_substeps = 3 internal steps"):
        st.advance(0.0, x0, (1.0,), 1e-3)
    assert x0 == [5 * VE, 0.0]
    with pytest.raises(ValueError, match=r"max_substeps = 0 is out of range"):
        make_stepper("radau", _BrakedLanding(), max_substeps=0)


def test_radau_at_reference_tolerance_steps_as_solve_ivp():
    # below rtol 1e-10 (the charts' references at 1e-11 and 1e-12) radau does not land: its
    # result through the three kinks is scipy's solve_ivp(Radau)'s from the same start with the
    # same tolerances (atol 1e-14 × state_scale 1e-3 = 1e-17), bit for bit
    import numpy as np
    from scipy.integrate import solve_ivp

    model = _BrakedLanding()
    x0, u, h = [5 * VE, 0.0], (1.0,), 1e-3
    y, _ = make_stepper("radau", model, rtol=1e-12, atol=1e-14).advance(0.0, x0, u, h)
    sol = solve_ivp(lambda t, z: model.rhs(t, z.tolist(), u), (0.0, h), np.array(x0),
                    method="Radau", rtol=1e-12, atol=np.array([1e-17, 1e-17]))
    assert y == sol.y[:, -1].tolist()
    # at rtol 1e-10 it lands: no longer the same steps
    y10, s10 = make_stepper("radau", model, rtol=1e-10, atol=1e-12).advance(0.0, x0, u, h)
    assert s10.rejected >= 1


# ---- the models' sliding velocities ----------------------------------------------------------

def test_dynamic_level_reports_threads_spline_and_kinks_of_li_et_al():
    params = presets.load("li2021_two_stage")
    model = make_model(params, "dynamic", "torque")
    x = model.initial_state((0.0, 1000.0), screw_speed=100.0, carrier_ratio=None)
    v = model.sliding_velocities(x)
    kinks = model.kink_speeds
    ve = params.slip_velocity_scale
    assert len(v) == len(kinks)
    three = [s for s in v if len(s) == 3]
    one = [s for s in v if len(s) == 1]
    # two stages × two thread flanks, each a slip vector whose only kink is v_ε; the last law:
    # stage 2's spline, sliding at ω ℓ_1 = ω · L_1 / 2π, with kinks 0 and v_ε
    assert len(three) == 4 and all(k == (ve,) for s, k in zip(v, kinks) if len(s) == 3)
    lead_1 = params.stages[0].screw_lead
    assert one[-1][0] == pytest.approx(100.0 * lead_1 / (2.0 * math.pi), rel=1e-14)
    assert kinks[-1] == (0.0, ve)
    # the slip's axial part of each flank is ω times its axial slip per unit ω, which is the
    # axial speed the screw's lead gives the contact point, L_1/2π, up to the flank's sign
    for s in three[:2]:
        assert abs(s[2]) == pytest.approx(100.0 * lead_1 / (2.0 * math.pi), rel=1e-12)


# ---- the dynamic level's default stepper and radau through the speed reversal ----------------

@pytest.mark.parametrize("stepper,reference", [("default", "radau"), ("radau", "rosenbrock")])
def test_stepper_meets_its_tolerance_through_the_speed_reversal(stepper, reference):
    """The actuator loop's speed reversal (system_models/scenes/speed_reversal.toml) cut to
    40 ms, through zero screw speed at 31.2 ms, with the PRSM's dynamic level at tolerance 1e-4
    and 1e-6, against another method at rtol 1e-10 (deterministic: the scene has no random
    input, so one case per tolerance).

    * its default stepper (the FMU's ``fidelity = dynamic``) against Radau restarted each
      communication step (at 1e-10 within 5e-12 of its 1e-12 run on the whole scene,
      docs/figures/wp_speed_reversal.csv).  Before the steppers landed on the friction law's
      kinks this gave 8.8e-4 at tolerance 1e-4 (at 31.2 ms) and 4.0e-6 at 1e-6;
    * the reference stepper ``radau`` (scipy's Radau IIA restarted on every communication step)
      against ROS34PW2 (it and Radau at 1e-10 differ by 2.6e-11 here, far below both
      tolerances).  Before radau landed on the kinks this gave 4.06e-4 at tolerance 1e-4."""
    from benchmark_modules import load_benchmark

    wp = load_benchmark("work_precision")
    run = wp.make_loop_runner("speed_reversal", 0.04)
    outs = wp.loop_outputs("speed_reversal")
    ref = run(wp.Config("dynamic", reference, "rtol", 1e-10), time_it=False)
    for tol in (1e-4, 1e-6):
        res = run(wp.Config("dynamic", stepper, "rtol", tol), time_it=False)
        error = max(wp.output_errors(res.outputs, ref.outputs, outs).values())
        print(f"{stepper} at tolerance {tol:g}: error {error:.3e}, {res.rhs_calls} rhs calls")
        assert error <= tol
