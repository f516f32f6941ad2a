"""``fidelity = "auto"`` along a run: the switching between the dynamic and the quasi-static level
(prsm_fmu/models/adaptive.py).

Expected values: the dynamic level itself (the switching may only drop what the tolerance
allows), the linearised carrier lag d' = −α − d/τ checked against the dynamic level's carriers,
conservation of energy across switches, and bit-for-bit reproduction from a saved memory (what
an FMU state needs).
"""

from __future__ import annotations

import numpy as np
import pytest

from prsm_fmu import presets, simulate
from prsm_fmu.models import AdaptiveModel, make_model
from prsm_fmu.models.auto import MARGIN, carrier_time_constants
from prsm_fmu.steppers import make_stepper

LI2021 = presets.load("li2021_two_stage")
OUTPUTS = ("screw_speed", "screw_acceleration", "stage[1].contact_force", "stage[2].contact_force",
           "stage[1].driven_torque", "stage[2].driven_torque", "stage[2].spline_friction",
           "stage[1].carrier_speed", "stage[2].carrier_speed", "friction_power")


def _error(res: dict, ref: dict) -> float:
    """docs/accuracy.md §1: max over outputs of max_t |y − y_ref| / max_t |y_ref| (absolute where the
    reference is identically 0, e.g. the acceleration of a prescribed speed)."""
    errs = []
    for o in OUTPUTS:
        scale = float(np.max(np.abs(ref[o])))
        errs.append(float(np.max(np.abs(res[o] - ref[o]))) / (scale if scale > 0.0 else 1.0))
    assert all(np.isfinite(errs)), errs
    return max(errs)


def _run(model, stepper: str, u_of_t, x0, h: float, n: int, **opts):
    """Step ``model`` n times; states, modes and rhs calls per step."""
    st = make_stepper(stepper, model, **opts)
    x, xs, modes, rhs = x0, [x0], [], 0
    for i in range(n):
        x, s = st.advance(i * h, x, u_of_t(i * h), h)
        xs.append(x)
        modes.append(getattr(st, "mode", model.fidelity))
        rhs += s.rhs_calls
    return st, xs, modes, rhs


def test_lag_integrated_along_the_run_matches_the_dynamic_carriers():
    """Constant motor torque, carriers started at equilibrium: the lag each carrier builds up
    (d_k = ω_Pk/ζ*_k − ω) as the switching model integrates it from the screw's acceleration,
    speed and load, against the dynamic level's carriers after 2 ms (≈ 60 τ of the slower
    carrier)."""
    torque, load, h = 25.0, 5000.0, 1e-5
    res = simulate(LI2021, "dynamic", "torque", screw_torque=torque, load_force=load,
                   t_end=2e-3, output_interval=h, initial_screw_speed=100.0,
                   initial_carrier_ratio=None, rtol=1e-10, atol=1e-12)
    m = AdaptiveModel(LI2021, "torque", tolerance=1e-3)
    w, a = res["screw_speed"], res["screw_acceleration"]
    d = [0.0, 0.0]
    for i in range(len(w) - 1):
        d = m.advance_lag(d, (w[i + 1] - w[i]) / h, 0.5 * (w[i] + w[i + 1]), load, h)
    assert a[-1] > 1e3
    for k, z in enumerate(m.zeta):
        actual = res[f"stage[{k + 1}].carrier_speed"][-1] / z - w[-1]
        assert actual < 0.0                                   # the carriers trail
        assert d[k] == pytest.approx(actual, rel=0.03), k


def test_startup_switches_once_to_quasi_static_after_the_carriers_settle_and_costs_less():
    """Li et al. (2021) start-up (carriers at rest, ω stepped to 100 rad/s, 5 kN): dynamic while the
    carriers spin up, then quasi-static for good; the outputs stay within the tolerance of
    the dynamic level's own run with the same stepper, for fewer rhs calls."""
    tol, h, n = 1e-6, 1e-5, 100
    kw = dict(screw_speed=100.0, load_force=5000.0, t_end=n * h, output_interval=h,
              initial_carrier_ratio=0.0, stepper="explicit_adaptive", rtol=tol, atol=tol * 1e-3)
    auto = simulate(LI2021, "auto", "speed", **kw)
    dyn = simulate(LI2021, "dynamic", "speed", **kw)
    assert _error(auto, dyn) <= tol / MARGIN
    u = (0.0, 5000.0)          # speed drive: constant prescribed speed, 5 kN
    m = make_model(LI2021, "auto", "speed", tolerance=tol, inputs=u, comm_step=h,
                   screw_speed=100.0, carrier_ratio=0.0)
    st, xs, modes, rhs = _run(m, "explicit_adaptive", lambda t: u,
                              m.initial_state(u, screw_speed=100.0, carrier_ratio=0.0), h, n,
                              rtol=tol,
                              atol=tol * 1e-3)
    first = modes.index("quasi-static")
    assert st.switches == 1 and set(modes[first:]) == {"quasi-static"}
    # it switched only once the carriers had settled to the tolerance (dynamic level's own run)
    z = m.zeta
    for k in (1, 2):
        dev = abs(dyn[f"stage[{k}].carrier_speed"][first + 1] - z[k - 1] * 100.0) / (z[k - 1] * 100.0)
        assert dev <= tol / (2 * MARGIN)
    assert 0.2 * n < first < 0.8 * n
    assert auto["rhs_calls"] < 0.8 * dyn["rhs_calls"]


def test_a_strong_acceleration_switches_back_to_dynamic_and_keeps_the_tolerance():
    """Quasi-static at constant speed, then a torque step that accelerates the screw hard
    against a light load: the carriers' estimated lag exceeds the tolerance, the run goes
    dynamic and stays within the tolerance of the dynamic level; the quasi-static level alone
    does not."""
    tol, h, n, load = 1e-4, 1e-5, 300, 1000.0
    qs = make_model(LI2021, "quasi-static", "torque")
    # the torque that holds 100 rad/s, from the quasi-static level's balance (α = 0)
    t_ss = qs.mechanism.solve(100.0, (), load, acceleration=0.0).motor_torque

    def u_of_t(t):
        return (t_ss + (10.0 if t >= 1e-3 else 0.0), load)

    kw = dict(screw_torque=lambda t: u_of_t(t)[0], load_force=load, t_end=n * h,
              output_interval=h, initial_screw_speed=100.0, initial_carrier_ratio=None)
    ref = simulate(LI2021, "dynamic", "torque", rtol=1e-9, atol=1e-11, **kw)
    m = make_model(LI2021, "auto", "torque", tolerance=tol, inputs=u_of_t(0.0), comm_step=h,
                   screw_speed=100.0, carrier_ratio=None)
    assert m.start == "quasi-static"
    x0 = m.initial_state(u_of_t(0.0), screw_speed=100.0, carrier_ratio=None)
    _, _, modes, _ = _run(m, "rosenbrock", u_of_t, x0, h, n, rtol=tol * 1e-2, atol=tol * 1e-4)
    assert set(modes[:100]) == {"quasi-static"} and "dynamic" in modes[100:]
    # the model error alone: the dynamic steps at a tolerance far below the model's
    auto = simulate(LI2021, "auto", "torque", rtol=tol, atol=tol * 1e-2,
                    stepper_options={"rtol": tol * 1e-2, "atol": tol * 1e-4}, **kw)
    assert _error(auto, ref) <= tol
    assert _error(simulate(LI2021, "quasi-static", "torque", **kw), ref) > tol


def test_energy_balance_closes_across_the_switches():
    """Torque drive from carriers at rest: motor work = load work + friction work + kinetic
    energy gained, through a dynamic → quasi-static switch (the carriers' residual deviation
    at the switch carries energy of the order of its square)."""
    tol = 1e-6
    res = simulate(LI2021, "auto", "torque", screw_torque=25.0, load_force=5000.0, t_end=2e-3,
                   output_interval=1e-5, initial_screw_speed=100.0, initial_carrier_ratio=0.0,
                   rtol=tol, atol=tol * 1e-2)
    w_in, w_out, w_f = res["input_work"], res["output_work"], res["friction_work"]
    ke = res["kinetic_energy"]
    resid = np.abs(w_in - w_out - w_f - (ke - ke[0]))
    assert np.max(resid) <= 1e-6 * np.max(np.abs(w_in))


def _memory_round_trip(stepper_name: str, k: int) -> None:
    u = (0.0, 5000.0)          # speed drive: constant prescribed speed, 5 kN
    m = make_model(LI2021, "auto", "speed", tolerance=1e-6, inputs=u, comm_step=1e-5,
                   screw_speed=100.0, carrier_ratio=0.0)
    st = make_stepper(stepper_name, m, rtol=1e-6, atol=1e-9)
    x = m.initial_state(u, screw_speed=100.0, carrier_ratio=0.0)
    saved = None
    first = []
    for i in range(80):
        if i == k:
            saved = (list(x), st.get_memory())
        x, _ = st.advance(i * 1e-5, x, u, 1e-5)
        if i >= k:
            first.append((list(x), m.outputs((i + 1) * 1e-5, x, u)))
    x, mem = saved
    st.set_memory(mem)
    for j, i in enumerate(range(k, 80)):
        x, _ = st.advance(i * 1e-5, x, u, 1e-5)
        assert x == first[j][0] and m.outputs((i + 1) * 1e-5, x, u) == first[j][1]


@pytest.mark.parametrize("k", [10, 70])       # saved while dynamic, and while quasi-static
def test_a_saved_memory_reproduces_the_run_bit_for_bit(k):
    _memory_round_trip("rosenbrock", k)


def test_a_memory_of_another_stepper_is_refused_with_a_clear_error():
    m = make_model(LI2021, "auto", "torque", tolerance=1e-6)
    st = make_stepper("rosenbrock", m)
    with pytest.raises(ValueError, match="not a memory"):
        st.set_memory((None,))
    with pytest.raises(ValueError, match="not a memory"):
        st.set_memory(("static", (0.0, 0.0), 0.0, 0, 1, 1.0, 0, 0.0, ((None,),), (None,)))


@pytest.mark.parametrize("h, omega, alpha, load, expected", [
    (1e-5, 100.0, 0.0, 5000.0, "explicit_adaptive"),   # h = 0.70 τ_fast (14.3 µs): DP5(4) is stable
    (1e-4, 100.0, 0.0, 5000.0, "exponential"),         # h = 7.0 τ_fast: stiff for any explicit step
    (1e-4, 0.4, -5000.0, 5000.0, "rosenbrock"),        # 0.4 − 5000·1e-4 = −0.1: crosses zero
    (1e-4, 0.6, -5000.0, 5000.0, "exponential"),       # 0.6 − 0.5 = +0.1: stays positive
    (1e-5, 0.0, 0.0, 5000.0, "rosenbrock"),            # standstill: τ → 0
    (1e-3, 100.0, 0.0, 0.0, "explicit_adaptive"),      # no axial force: the carriers are not driven
])
def test_default_dynamic_steps_by_the_carriers_time_constant_and_zero_speed(h, omega, alpha, load,
                                                                           expected):
    """The default stepper of auto's dynamic steps: ROS34PW2 at or through zero screw speed
    (predicted with the last step's acceleration); elsewhere explicit only where the
    communication step is within DP5(4)'s stability interval on the negative real axis, about
    3.3 τ (Hairer & Wanner, Solving ODEs II, §IV.2), for the fastest carrier's linearised τ
    from carrier_time_constants, and the exponential stepper (carriers' linear part exact)
    beyond it."""
    u = (0.0, load)            # speed drive: constant prescribed speed
    m = make_model(LI2021, "auto", "speed", tolerance=1e-6, inputs=u, screw_speed=omega,
                   carrier_ratio=0.0)
    st = make_stepper("default", m, rtol=1e-6, atol=1e-8)
    mem = st.get_memory()      # (mode, lags, scale, wait, backoff, gain, switches, alpha, ...)
    st.set_memory(mem[:7] + (alpha,) + mem[8:])
    x = m.initial_state(u, screw_speed=omega, carrier_ratio=None)
    assert st.dynamic_for(x, u, h).name == expected
    if omega and load and alpha == 0.0:
        tau = min(carrier_time_constants(LI2021, omega, load))
        assert (h <= 3.3 * tau) == (expected == "explicit_adaptive")
