"""The actuator's parts and the co-simulation master, without the FMU (issue 4).

Expected values come from closed forms: the RL circuit's step response, the dq power identity,
the PI's anti-windup equilibrium, the linear map of an explicitly coupled mass and spring, exact
integrals of ramps, a second-order system's overshoot exp(−πζ/√(1−ζ²)).
"""

from __future__ import annotations

import cmath
import io
import math

import numpy as np
import pytest

from system_models.analysis import direction_changes, step_metrics, zero_crossings, zigzags
from system_models.blocks import Port, PythonBlock, StepRefused
from system_models.controller import PI, CascadeController, ControllerParams
from system_models.load import LoadParams, SpringDamperLoad
from system_models.master import CoSimulationError, Master, RetryPolicy
from system_models.motor import Motor, MotorParams
from system_models.progress import Progress
from system_models.scenes import BUILTIN_DIR, list_scenes, load_scene, parse_scene
from system_models.signals import make_profile
from text_numbers import number_after  # noqa: E402

SCENES = ("position_step", "sine_tracking", "load_step", "speed_reversal", "startup_li2021")


# ---- toy blocks ------------------------------------------------------------------------------
class Clock(PythonBlock):
    """Output y = t (or a staircase if discrete); records the times it is stepped with."""

    inputs = ()
    _state_attrs = ("t", "calls")

    def __init__(self, name="clock", discrete=False, t0=0.0):
        self.outputs = (Port("y", "s", discrete=discrete),)
        super().__init__(name)
        self.t, self.calls = t0, []

    def do_step(self, t, h):
        self.calls.append((t, h))
        self.t = t + h

    def get_outputs(self):
        return [self.t]


class Integrator(PythonBlock):
    """z = ∫ u dt, exact for the linear input the master gives (value + slope·τ)."""

    inputs = (Port("u", "s"),)
    outputs = (Port("z", "s2"),)
    _state_attrs = ("z",)

    def __init__(self, name="int", interpolates=True):
        super().__init__(name)
        self.interpolates_inputs = interpolates
        self.z = 0.0

    def do_step(self, t, h):
        self.z += self.u[0] * h + 0.5 * self.du[0] * h * h

    def get_outputs(self):
        return [self.z]


class Mass(PythonBlock):
    """A mass under a force held over each step, integrated exactly."""

    inputs = (Port("force", "N"),)
    outputs = (Port("x", "m"), Port("v", "m/s"))
    _state_attrs = ("x", "v")

    def __init__(self, m, x0, name="mass"):
        super().__init__(name)
        self.m, self.x, self.v = m, x0, 0.0

    def do_step(self, t, h):
        f = self.u[0]
        self.x += self.v * h + 0.5 * f / self.m * h * h
        self.v += f / self.m * h

    def get_outputs(self):
        return [self.x, self.v]


class Spring(PythonBlock):
    inputs = (Port("x", "m"),)
    outputs = (Port("force", "N"),)
    feedthrough = True

    def __init__(self, k, name="spring"):
        super().__init__(name)
        self.k = k

    def do_step(self, t, h):
        pass

    def get_outputs(self):
        return [-self.k * self.u[0]]


class Picky(PythonBlock):
    """Refuses any step longer than h_max (its state is untouched when it refuses)."""

    inputs = (Port("u", "s"),)
    outputs = (Port("n", "1"),)
    _state_attrs = ("n",)

    def __init__(self, h_max, name="picky"):
        super().__init__(name)
        self.h_max, self.n = h_max, 0

    def do_step(self, t, h):
        if h > self.h_max * (1 + 1e-12):
            raise StepRefused(self.name, t, h, f"h = {h} s is longer than {self.h_max} s")
        self.n += 1

    def get_outputs(self):
        return [float(self.n)]


# ---- master ----------------------------------------------------------------------------------
def test_communication_points_are_t0_plus_k_h_without_drift():
    t0, h, n = 0.3, 1e-3, 1000
    clock = Clock(t0=t0)
    integ = Integrator()
    m = Master([clock, integ], {"int.u": "clock.y"}, h, t0=t0)
    res = m.run(t0 + n * h)
    assert len(res.time) == n + 1
    assert all(res.time[k] == t0 + k * h for k in range(n + 1))
    assert all(t == t0 + k * h and hk == (t0 + (k + 1) * h) - (t0 + k * h)
               for k, (t, hk) in enumerate(clock.calls))
    # a sum of steps would have drifted off the grid
    acc = t0
    for _ in range(n):
        acc += h
    assert acc != t0 + n * h


def test_a_progress_callback_sees_every_communication_point_and_changes_no_value():
    """With a progress callback the master takes one step per call and reports t_k after each
    (k = 1..n, t_k = t0 + k h from the integer k); without one it takes the run's steps in one
    loop: the two runs' results are the same bit for bit."""
    t0, h, n = 0.3, 1e-3, 200
    seen = []
    runs = []
    for progress in (None, lambda t, t_end: seen.append((t, t_end))):
        m = Master([Clock(t0=t0), Integrator()], {"int.u": "clock.y"}, h, t0=t0, extrapolation=1)
        runs.append(m.run(t0 + n * h, progress))
    assert seen == [(t0 + k * h, t0 + n * h) for k in range(1, n + 1)]
    assert np.array_equal(runs[0].time, runs[1].time)
    for name in runs[0].names():
        assert np.array_equal(runs[0][name], runs[1][name])
    # the integrator of the clock's y = t (Gauss-Seidel: the ramp interpolated, integrated
    # exactly) from t0: z = (t² − t0²)/2
    t = runs[0].time
    assert np.allclose(runs[0]["int.z"], 0.5 * (t * t - t0 * t0), rtol=1e-12, atol=1e-15)


def test_an_end_time_that_is_not_a_whole_number_of_steps_is_refused():
    m = Master([Clock(), Integrator()], {"int.u": "clock.y"}, 1e-3)
    with pytest.raises(ValueError, match="whole"):
        m.run(0.0105)


@pytest.mark.parametrize("order,extrapolation,expected", [
    # Gauss-Seidel, the clock stepped first: z = ∫ t dt exactly (order 1 interpolates), or
    # Σ t_(k+1) h (order 0 holds the new value)
    ("gauss-seidel", 1, lambda n, h: 0.5 * (n * h) ** 2),
    ("gauss-seidel", 0, lambda n, h: h * h * n * (n + 1) / 2),
    # Jacobi: order 0 holds t_k: Σ t_k h; order 1 extrapolates the ramp exactly after step 1
    ("jacobi", 0, lambda n, h: h * h * n * (n - 1) / 2),
    ("jacobi", 1, lambda n, h: 0.5 * (n * h) ** 2 - 0.5 * h * h),
])
def test_orders_and_extrapolation_integrate_a_ramp_as_their_closed_forms(order, extrapolation,
                                                                         expected):
    h, n = 0.01, 50
    m = Master([Clock(), Integrator()], {"int.u": "clock.y"}, h, order=order,
               extrapolation=extrapolation)
    z = m.run(n * h)["int.z"]
    assert z[-1] == pytest.approx(expected(n, h), rel=1e-12)


def test_held_inputs_get_the_mean_of_the_extrapolation_and_discrete_ports_are_never_extrapolated():
    h, n = 0.01, 50
    held = Master([Clock(), Integrator(interpolates=False)], {"int.u": "clock.y"}, h,
                  order="jacobi", extrapolation=1).run(n * h)["int.z"]
    assert held[-1] == pytest.approx(0.5 * (n * h) ** 2 - 0.5 * h * h, rel=1e-12)
    stair = Master([Clock(discrete=True), Integrator()], {"int.u": "clock.y"}, h,
                   order="jacobi", extrapolation=1).run(n * h)["int.z"]
    assert stair[-1] == pytest.approx(h * h * n * (n - 1) / 2, rel=1e-12)


class Ramps(PythonBlock):
    """Outputs t, 2t, 3t; can give only some of them (and notes which it was asked for)."""

    inputs = ()
    outputs = (Port("a", "s"), Port("b", "s"), Port("c", "s"))
    _state_attrs = ("t",)

    def __init__(self, name="ramps"):
        super().__init__(name)
        self.t, self.ports, self.calls = 0.0, [0, 1, 2], 0

    def select_outputs(self, ports):
        self.ports = list(ports)
        return True

    def do_step(self, t, h):
        self.t = t + h

    def get_outputs(self):
        self.calls += 1
        return [(k + 1) * self.t for k in self.ports]


def test_blocks_give_only_the_connected_and_recorded_outputs_and_the_values_are_the_same():
    h, n = 0.01, 50
    connections = {"int.u": "ramps.b"}
    # every output recorded: the block is not asked to narrow them
    full_block = Ramps()
    full = Master([full_block, Integrator()], connections, h, extrapolation=1).run(n * h)
    assert full_block.ports == [0, 1, 2]
    # b feeds the integrator, c is recorded, a nobody uses: the block gives b and c only
    block = Ramps()
    part = Master([block, Integrator()], connections, h, extrapolation=1,
                  record=["ramps.c", "int.z", "ramps.b"]).run(n * h)
    assert block.ports == [1, 2]
    assert part.names() == ["ramps.c", "int.z", "ramps.b"]
    for name in part.names():
        assert np.array_equal(part[name], full[name])
    # closed forms on the grid t_k = k h: c = 3 t, b = 2 t, and the integrator's exact
    # integral of the interpolated 2t (Gauss-Seidel, first order) z = t²
    t = h * np.arange(n + 1)
    assert np.allclose(part["ramps.c"], 3 * t, rtol=1e-15, atol=0)
    assert np.allclose(part["ramps.b"], 2 * t, rtol=1e-15, atol=0)
    assert np.allclose(part["int.z"], t * t, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("extrapolation", [0, 1])
def test_explicit_spring_coupling_follows_its_linear_map_and_grows_by_sqrt_1_plus_a_over_2(extrapolation):
    """A mass (exact under a held force) and a spring force F = −k x_k held over each step:
    x' = (1 − a/2) x + h v, v' = v − (a/h) x with a = (ωh)²; for order 0 the eigenvalues have
    |λ|² = det = 1 + a/2: the coupling adds energy, ζ_num = ωh/4 (docs/ema.md)."""
    m, k, h, n = 2.0, 800.0, 2e-3, 400
    w = math.sqrt(k / m)
    a = (w * h) ** 2
    res = Master([Mass(m, 0.01), Spring(k)], {"mass.force": "spring.force", "spring.x": "mass.x"},
                 h, order="gauss-seidel", extrapolation=extrapolation).run(n * h)
    # the same map, iterated independently
    z = np.array([0.01, 0.0])
    zs = [z]
    for j in range(n):
        if extrapolation == 0 or j == 0:
            f = -k * z[0]
        else:       # held value = mean of the linear extrapolation from the last two points
            f = -k * (z[0] + 0.5 * (z[0] - zs[-2][0]))
        z = np.array([z[0] + h * z[1] + 0.5 * f / m * h * h, z[1] + f / m * h])
        zs.append(z)
    zs = np.array(zs)
    assert np.max(np.abs(res["mass.x"] - zs[:, 0])) <= 1e-14
    if extrapolation == 0:
        amat = np.array([[1 - a / 2, h], [-a / h, 1.0]])
        lam = np.abs(np.linalg.eigvals(amat))
        assert lam == pytest.approx([math.sqrt(1 + a / 2)] * 2, rel=1e-12)
        energy = 0.5 * k * zs[:, 0] ** 2 + 0.5 * m * zs[:, 1] ** 2
        periods = n * h * w / (2 * math.pi)
        growth = (energy[-1] / energy[0]) ** (1 / periods)
        # per period: (1 + a/2)^(2π/(ωh)) ≈ exp(π ωh), i.e. negative damping ζ ≈ ωh/4
        assert growth == pytest.approx(math.exp(math.pi * w * h), rel=2e-2)


def test_a_refused_step_raises_naming_time_block_and_reason_and_returns_no_result():
    m = Master([Clock(), Picky(1e-3)], {"picky.u": "clock.y"}, 2e-3)
    with pytest.raises(CoSimulationError) as info:
        m.run(0.01)
    err = info.value
    assert err.time == 0.0 and err.block == "picky" and "longer than" in err.reason
    assert number_after(str(err), "t = ") == 0.0 and "picky" in str(err) and "incomplete" in str(err)
    assert err.partial is not None and err.partial.time[-1] == 0.0


def test_retry_rolls_back_and_splits_the_step_into_equal_substeps_on_the_grid():
    clock = Clock()
    picky = Picky(1e-3)
    m = Master([clock, picky], {"picky.u": "clock.y"}, 4e-3, retry=RetryPolicy(max_halvings=3))
    res = m.run(0.02)
    assert list(res.time) == [k * 4e-3 for k in range(6)]
    # every macro step: refused at 4 ms and 2 ms, taken as 4 substeps of 1 ms
    assert res.stats["retries"] == 10 and res["picky.n"][-1] == 20.0
    assert res.stats["max_substeps_per_step"] == 4
    # the clock was rolled back: the steps it kept are contiguous 1 ms substeps
    kept = clock.calls[-4:]
    assert [t for t, _ in kept] == pytest.approx([0.016, 0.017, 0.018, 0.019], abs=1e-15)
    assert sum(hk for _, hk in kept) == pytest.approx(4e-3, abs=1e-15)


def test_connections_are_checked():
    with pytest.raises(ValueError, match="not connected"):
        Master([Clock(), Integrator()], {}, 1e-3)
    with pytest.raises(ValueError, match="unit"):
        Master([Mass(1.0, 0.0), Clock()], {"mass.force": "clock.y"}, 1e-3)
    with pytest.raises(ValueError, match="no output"):
        Master([Clock(), Integrator()], {"int.u": "clock.nope"}, 1e-3)


# ---- motor -----------------------------------------------------------------------------------
def test_locked_rotor_current_rises_as_v_over_r_times_one_minus_exp():
    p = MotorParams()
    mot = Motor(p)
    v, h = 10.0, 1e-4
    mot.set_inputs([0.0, v, 0.0], [0.0, 0.0, 0.0])
    t = 0.0
    for _ in range(50):
        mot.do_step(t, h)
        t += h
    iq = mot.get_outputs()[1]
    assert iq == pytest.approx(v / p.resistance * (1 - math.exp(-t * p.resistance / p.inductance)),
                               rel=1e-10)


def test_one_default_motor_step_at_locked_rotor_is_the_rl_closed_form_worked_by_hand():
    # R = 0.5 Ω, L = 2e-3 H (MotorParams' defaults, restated): τ = L/R = 4 ms.  From rest, v_q =
    # 10 V held, ω = 0, one step h = 1e-4 s:
    #   i_q(h) = v/R (1 − e^{−h/τ}) = 20 A · (1 − e^{−0.025}) = 20 · 0.024690087971667 A
    #          = 0.49380175943334 A,   i_d = 0
    #   E_el = 1.5 v ∫ i_q dt = 1.5 · 10 · 20 (h − τ (1 − e^{−h/τ}))
    #        = 300 (1e-4 − 4e-3 · 0.024690087971667) J = 300 · 1.23964811333e-6 J
    #        = 3.71894434e-4 J
    #   E_mag = 0.75 L i_q² = 1.5e-3 J/A² · 0.49380175943334² A² = 1.5e-3 · 0.24384017762 J
    #         = 3.65760266e-4 J
    #   E_cu = E_el − E_mag (ω = 0: no air-gap work) = (3.71894434 − 3.65760266)e-4 J
    #        = 6.134168e-6 J
    mot = Motor(MotorParams(resistance=0.5, inductance=2e-3))
    assert mot.integrator == "rk4"                       # the default
    mot.set_inputs([0.0, 10.0, 0.0], [0.0, 0.0, 0.0])
    mot.do_step(0.0, 1e-4)
    y = dict(zip(mot.output_names(), mot.get_outputs()))
    # RK4 on 5 substeps of 20 µs: error ≈ (20 µs / 4 ms)^5 / 120 per substep, ~1e-14 relative
    assert y["i_q"] == pytest.approx(0.49380175943334, rel=1e-11)
    assert y["i_d"] == 0.0
    assert y["electrical_energy"] == pytest.approx(3.71894434e-4, rel=1e-8)
    assert y["magnetic_energy"] == pytest.approx(3.65760266e-4, rel=1e-8)
    assert y["copper_energy"] == pytest.approx(6.134168e-6, rel=1e-6)
    assert y["airgap_energy"] == 0.0


def test_the_default_rk4_step_is_closer_than_the_exponential_one_to_a_tight_reference():
    """The motor ODE written out here under the master's inputs (voltages held, the speed
    linear over the step), integrated by scipy at rtol 1e-13: the reference both integrators
    are measured against (why RK4 stays the default: docs of system_models/motor.py)."""
    from scipy.integrate import solve_ivp

    r, ell, p, psi, kt = 0.5, 2e-3, 4, 0.25, 1.5          # ψ = k_t/(1.5 p) = 1.5/6 Wb
    mp = MotorParams(pole_pairs=p, resistance=r, inductance=ell, torque_constant=kt)
    h, w0, dw, vd, vq = 1e-4, 120.0, 2e4, -15.0, 140.0    # 2e4 rad/s²: the loop's peak

    def f(tau, s):
        w = w0 + dw * tau
        return [(vd - r * s[0] + p * w * ell * s[1]) / ell,
                (vq - r * s[1] - p * w * ell * s[0] - p * w * psi) / ell,
                1.5 * (vd * s[0] + vq * s[1]), 1.5 * r * (s[0] ** 2 + s[1] ** 2), kt * s[1] * w]

    x0 = [0.3, 12.0, 0.0, 0.0, 0.0]
    ref = solve_ivp(f, (0.0, h), x0, method="DOP853", rtol=1e-13, atol=1e-15).y[:, -1]
    errors = {}
    for integrator in ("rk4", "exponential"):
        mot = Motor(mp, integrator=integrator, i_d=x0[0], i_q=x0[1])
        mot.set_inputs([vd, vq, w0], [0.0, 0.0, dw])
        mot.do_step(0.0, h)
        errors[integrator] = abs(complex(mot.x[0] - ref[0], mot.x[1] - ref[1])) / abs(
            complex(ref[0], ref[1]))
    assert errors["rk4"] < 1e-10
    assert errors["exponential"] > 100 * errors["rk4"]


def test_steady_voltages_hold_the_current_and_the_dq_power_identity_closes():
    p = MotorParams()
    w, iq = 120.0, 8.0
    vd, vq = p.steady_voltages(w, iq)
    mot = Motor(p, i_q=iq)
    mot.set_inputs([vd, vq, w])
    for k in range(20):
        mot.do_step(k * 1e-4, 1e-4)
    y = dict(zip(mot.output_names(), mot.get_outputs()))
    assert y["i_q"] == pytest.approx(iq, rel=1e-12) and abs(y["i_d"]) < 1e-12
    # varying speed and voltages: E_el = E_cu + ΔE_mag + W_airgap (RK4 error only)
    mot = Motor(p)
    e_mag0 = mot.get_outputs()[-1]
    for k in range(200):
        w = 50 + 0.5 * k
        mot.set_inputs([5 * math.sin(0.1 * k), w + 8 * math.cos(0.07 * k), w], [0.0, 0.0, 5000.0])
        mot.do_step(k * 1e-4, 1e-4)
    y = dict(zip(mot.output_names(), mot.get_outputs()))
    resid = y["electrical_energy"] - y["copper_energy"] - (y["magnetic_energy"] - e_mag0) - y["airgap_energy"]
    assert abs(resid) <= 1e-9 * y["electrical_energy"]
    assert y["torque"] == pytest.approx(p.torque_constant * y["i_q"])


def test_exponential_motor_step_is_exact_under_held_speed_and_of_second_order_otherwise():
    p = MotorParams()
    tau = p.inductance / p.resistance                    # 2e-3 H / 0.5 Ω = 4 ms
    # locked rotor, one step of 5 ms: i_q = v/R (1 − e^{−t/τ}) exactly, whatever the step
    mot = Motor(p, integrator="exponential")
    v, h = 10.0, 5e-3
    mot.set_inputs([0.0, v, 0.0], [0.0, 0.0, 0.0])
    mot.do_step(0.0, h)
    y = dict(zip(mot.output_names(), mot.get_outputs()))
    assert y["i_q"] == pytest.approx(v / p.resistance * (1 - math.exp(-h / tau)), rel=1e-13)
    # E_el = ∫ 1.5 v i_q dt = 1.5 v (v/R) (h − τ (1 − e^{−h/τ})) at zero speed, and E_cu = E_el − E_mag
    e_el = 1.5 * v * v / p.resistance * (h - tau * (1 - math.exp(-h / tau)))
    assert y["electrical_energy"] == pytest.approx(e_el, rel=1e-12)
    assert y["copper_energy"] == pytest.approx(e_el - y["magnetic_energy"], rel=1e-12)
    # at a held speed ω the current rotates and decays: i(t) = i_∞ + (i_0 − i_∞) e^{−(R/L + j p ω) t}
    w, h = 80.0, 3e-3
    vd, vq = 4.0, 90.0
    mot = Motor(p, integrator="exponential", i_d=1.0, i_q=-2.0)
    mot.set_inputs([vd, vq, w], [0.0, 0.0, 0.0])
    mot.do_step(0.0, h)
    a = complex(p.resistance / p.inductance, p.pole_pairs * w)
    i_inf = complex(vd, vq - p.pole_pairs * w * p.flux_linkage) / (p.inductance * a)
    i_h = i_inf + (complex(1.0, -2.0) - i_inf) * cmath.exp(-a * h)
    y = mot.get_outputs()
    assert abs(complex(y[0], y[1]) - i_h) <= 1e-13 * abs(i_h)
    # a speed that changes over the step: second order in the substep against RK4 at 0.1 µs, and
    # the block's own energy balance E_el = E_cu + ΔE_mag + W_airgap to rounding
    def run(integrator, max_substep):
        m = Motor(p, integrator=integrator, max_substep=max_substep, i_q=3.0)
        e_mag0 = m.get_outputs()[-1]
        for k in range(40):
            w = 50.0 + 2.0 * k                               # slope 2 rad/s per 0.1 ms = 2e4 rad/s²
            m.set_inputs([5 * math.sin(0.1 * k), 2.5 + w + 3 * math.cos(0.07 * k), w],
                         [0.0, 0.0, 2e4])
            m.do_step(k * 1e-4, 1e-4)
        return dict(zip(m.output_names(), m.get_outputs())), e_mag0
    ref, _ = run("rk4", 1e-7)
    errors = []
    for sub in (2e-5, 1e-5):
        y, e_mag0 = run("exponential", sub)
        errors.append(abs(complex(y["i_d"] - ref["i_d"], y["i_q"] - ref["i_q"])))
        resid = y["electrical_energy"] - y["copper_energy"] - (y["magnetic_energy"] - e_mag0) \
            - y["airgap_energy"]
        assert abs(resid) <= 1e-12 * y["electrical_energy"]
    assert 3.5 < errors[0] / errors[1] < 4.5            # halving the substep: error / 4
    with pytest.raises(ValueError, match="integrator"):
        Motor(p, integrator="euler")


def test_the_inverter_limits_the_voltage_and_overcurrent_trips_the_drive():
    p = MotorParams()
    mot = Motor(p)
    mot.set_inputs([0.0, 1000.0, 0.0])
    assert mot.get_outputs()[5] == pytest.approx(p.voltage_limit)
    with pytest.raises(StepRefused, match="overcurrent"):
        for k in range(200):
            mot.do_step(k * 1e-4, 1e-4)
    with pytest.raises(ValueError, match="motor.resistance"):
        MotorParams(resistance=-1.0).validate()


# ---- controller ------------------------------------------------------------------------------
def test_back_calculation_keeps_a_saturated_integrator_at_the_limit():
    """I += T (K_i e + (K_i/K_p)(u_sat − u)): with the output saturated at u_max under a
    constant error e, I converges to u_max (the fixed point), instead of growing as K_i e t."""
    pi = PI(kp=2.0, ki=50.0, ts=1e-3)
    for _ in range(5000):
        pi.update(1.0, -3.0, 3.0)
    assert pi.integral == pytest.approx(3.0, rel=1e-9)
    # after the error reverses the output leaves the limit at the next sample
    assert pi.update(-1.0, -3.0, 3.0) < 3.0


@pytest.mark.parametrize("h", [1e-4, 3e-5, 2.5e-4])
def test_the_controller_samples_at_t0_plus_j_ts_whatever_the_communication_step(h):
    seen = []

    def ref(t):
        seen.append(t)
        return 0.0

    ctrl = CascadeController(ControllerParams(), MotorParams(), 0.02 / (2 * math.pi), ref,
                             mode="speed", t0=0.5)
    seen.clear()
    ctrl.set_inputs([0.0, 0.0, 0.0, 0.0])
    n = round(0.003 / h)
    for k in range(n):
        ctrl.do_step(0.5 + k * h, h)
    ts = 1e-4
    expected = [0.5 + j * ts for j in range(round(n * h / ts + 0.4999999))]
    assert seen == pytest.approx(expected, abs=1e-12)
    assert ctrl.get_outputs()[-1] == len(expected)


# ---- load, signals, scenes, analysis, progress -------------------------------------------------
def test_load_force_is_spring_damper_and_profile_positive_resisting_extension():
    ld = SpringDamperLoad(LoadParams(stiffness=1e5, damping=200.0, preload=10.0), lambda t: 3.0 * t)
    ld.set_inputs([0.002, -0.1])
    ld.update_outputs(2.0)
    y = dict(zip(ld.output_names(), ld.get_outputs()))
    assert y["force"] == pytest.approx(10.0 + 200.0 - 20.0 + 6.0)
    assert y["spring_energy"] == pytest.approx(0.5 * 1e5 * 0.002 ** 2 + 10.0 * 0.002)


def test_profiles():
    step = make_profile({"kind": "step", "initial": 1.0, "final": 3.0, "time": 1.0, "rise": 0.5})
    assert [step(0.9), step(1.25), step(2.0)] == [1.0, 2.0, 3.0]
    sine = make_profile({"kind": "sine", "amplitude": 2.0, "frequency": 0.5, "offset": 1.0})
    assert sine(0.5) == pytest.approx(1.0 + 2.0 * math.sin(0.5 * math.pi))
    pts = make_profile({"kind": "points", "time": [0.0, 1.0, 1.0, 2.0], "value": [0.0, 1.0, 5.0, 5.0]})
    assert [pts(-1.0), pts(0.5), pts(1.0), pts(3.0)] == [0.0, 0.5, 5.0, 5.0]
    with pytest.raises(ValueError, match="profile.kind"):
        make_profile({"kind": "saw"})
    with pytest.raises(ValueError, match="unknown field"):
        make_profile({"kind": "step", "final": 1.0, "time": 0.0, "rsie": 1.0})


def test_every_built_in_scene_loads_and_names_its_checks_and_outputs():
    names = [n for n, _ in list_scenes()]
    for s in SCENES:
        assert s in names
        sc = load_scene(s)
        assert sc.checks and sc.outputs and sc.description
        assert any(c["kind"] == "energy_balance" for c in sc.checks)
    assert (BUILTIN_DIR / "position_step.toml").is_file()


def test_a_user_scene_in_the_working_directory_is_found_and_bad_fields_are_named(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "mine.toml").write_text(
        'description = "my scene"\nt_end = 0.01\nstep = 1e-4\n[controller]\nreference = 0.001\n')
    assert ("mine", "my scene") in list_scenes()
    assert load_scene("mine").t_end == 0.01
    with pytest.raises(ValueError, match="unknown scene 'nope'.*position_step"):
        load_scene("nope")
    with pytest.raises(ValueError, match="t_edn"):
        parse_scene({"t_end": 1.0, "step": 1e-3, "t_edn": 2, "controller": {}}, "x")
    with pytest.raises(ValueError, match="step = -1"):
        parse_scene({"t_end": 1.0, "step": -1, "controller": {}}, "x")
    with pytest.raises(ValueError, match=r"check 1 \(range\): unknown field\(s\) \['mx'\]"):
        parse_scene({"t_end": 1.0, "step": 1e-3, "controller": {},
                     "check": [{"kind": "range", "signal": "motor.current", "mx": 3.0}]}, "x")
    with pytest.raises(ValueError, match="fidelity = 'fast'"):
        parse_scene({"t_end": 1.0, "step": 1e-3, "controller": {}, "fidelity": "fast"}, "x")


def test_overshoot_of_a_second_order_response_is_exp_minus_pi_zeta_over_sqrt():
    zeta, wn = 0.3, 50.0
    t = np.linspace(0.0, 0.5, 50001)
    wd = wn * math.sqrt(1 - zeta ** 2)
    y = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta ** 2) * np.sin(wd * t))
    m = step_metrics(t, y, 0.0, 1.0, 0.0, band=0.02)
    assert m["overshoot"] == pytest.approx(math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2)), rel=1e-6)
    # 2 % settling of the envelope: ≈ −ln(0.02 √(1−ζ²))/(ζ ωn), the last crossing lies below it
    assert 0.5 * 4 / (zeta * wn) < m["settling_time"] <= -math.log(0.02 * math.sqrt(1 - zeta ** 2)) / (zeta * wn)


def test_chatter_and_crossing_counters():
    assert zero_crossings(np.array([1.0, 0.5, 0.0, -0.5, -1.0])) == 1
    assert direction_changes(np.sin(np.linspace(0, 20, 500))) == 6
    assert zigzags(np.array([5.0, 4, 3, 8, 7, 6])) == 0          # one jump: not chatter
    assert zigzags(np.tile([0.0, 1.0], 10)) > 10


def test_progress_bar_appears_only_after_the_delay():
    now = [0.0]
    out = io.StringIO()
    p = Progress(delay=2.0, stream=out, clock=lambda: now[0])
    p(0.1, 1.0)
    now[0] = 1.9
    p(0.5, 1.0)
    assert out.getvalue() == ""
    now[0] = 2.5
    p(0.6, 1.0)
    now[0] = 3.0
    p(1.0, 1.0)
    text = out.getvalue()
    assert "60 %" in text and "100 %" in text and "left" in text
