"""Tests of prsm_fmu.steppers against closed-form solutions.

Every expected value comes from a closed form (exponentials, harmonic oscillator, a
limit cycle with known radius, stability polynomials) or from the published order
conditions; no test compares a stepper with its own earlier output, except the
memory round trip, which is about bit-for-bit reproducibility.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from prsm_fmu.steppers import (
    ExponentialRosenbrock,
    EXPLICIT_TABLEAUS,
    ROS_ALPHA,
    ROS_B,
    ROS_BHAT,
    ROS_GAMMA,
    ROS_GAMMA_IJ,
    RK4,
    STEPPER_NAMES,
    ExplicitAdaptive,
    Rosenbrock,
    ScipyRadau,
    Stepper,
    StepFailure,
    StepStats,
    _ROS_EQ,
    _ROS_WQ,
    _SMALL_LU,
    _lu_factor,
    _lu_solve,
    make_stepper,
)

RK4_REAL_LIMIT = 2.785  # |h lambda| limit of classic RK4 on the negative real axis


# ----------------------------------------------------------------------------------
# test models
# ----------------------------------------------------------------------------------


class Decay:
    """x' = -lam x + u[0];  x(t) = u/lam + (x0 - u/lam) exp(-lam t)."""

    n_states = 1
    state_scale = (1.0,)

    def __init__(self, lam: float = 2.0) -> None:
        self.lam = lam

    def rhs(self, t, x, u):
        return [-self.lam * x[0] + u[0]]

    def exact(self, t, x0, u):
        xs = u[0] / self.lam
        return xs + (x0 - xs) * math.exp(-self.lam * t)


class DecayJ(Decay):
    def jacobian(self, t, x, u):
        return [[-self.lam]]


class Oscillator:
    """x'' = -w^2 x as [x, v] in m and m/s; period 2 pi / w."""

    n_states = 2

    def __init__(self, freq: float = 50.0, amp: float = 1e-3) -> None:
        self.w = 2.0 * math.pi * freq
        self.state_scale = (amp, amp * self.w)

    def rhs(self, t, x, u):
        return [x[1], -self.w * self.w * x[0]]

    def jacobian(self, t, x, u):
        return [[0.0, 1.0], [-self.w * self.w, 0.0]]

    def exact(self, t, x0):
        c, s = math.cos(self.w * t), math.sin(self.w * t)
        return [x0[0] * c + x0[1] / self.w * s, -x0[0] * self.w * s + x0[1] * c]


class LimitCycle:
    """Nonlinear 2-state system with closed form (radius -> 1, angle = angle0 + t)."""

    n_states = 2
    state_scale = (1.0, 1.0)

    def rhs(self, t, x, u):
        a, b = x
        q = 1.0 - a * a - b * b
        return [-b + a * q, a + b * q]

    @staticmethod
    def exact(t, x0):
        r0 = math.hypot(x0[0], x0[1])
        th = math.atan2(x0[1], x0[0]) + t
        r = 1.0 / math.sqrt(1.0 + (1.0 / r0**2 - 1.0) * math.exp(-2.0 * t))
        return [r * math.cos(th), r * math.sin(th)]


class LimitCycleJ(LimitCycle):
    def jacobian(self, t, x, u):
        a, b = x
        q = 1.0 - a * a - b * b
        return [[q - 2 * a * a, -1 - 2 * a * b], [1 - 2 * a * b, q - 2 * b * b]]


class LimitCycleWrongJ(LimitCycle):
    """Deliberately wrong constant Jacobian (tests the W-method property)."""

    def jacobian(self, t, x, u):
        return [[-1.0, 0.3], [0.0, -2.0]]


class Stiff2:
    """y1' = -y1, y2' = -L (y2 - y1): eigenvalues -1 and -L."""

    n_states = 2
    state_scale = (1.0, 1.0)
    L = 1e6
    A = [[-1.0, 0.0], [1e6, -1e6]]

    def rhs(self, t, x, u):
        return [-x[0], -self.L * (x[1] - x[0])]

    def jacobian(self, t, x, u):
        return [list(r) for r in self.A]

    def exact(self, t, y0):
        a = self.L / (self.L - 1.0)
        b = y0[1] - a * y0[0]
        return [y0[0] * math.exp(-t), a * y0[0] * math.exp(-t) + b * math.exp(-self.L * t)]


class Prothero:
    """x' = -L (x - cos t): stiff, explicitly time dependent."""

    n_states = 1
    state_scale = (1.0,)
    L = 1e6

    def rhs(self, t, x, u):
        return [-self.L * (x[0] - math.cos(t))]

    def exact(self, t, x0):
        L = self.L
        p = (L * L * math.cos(t) + L * math.sin(t)) / (L * L + 1.0)
        return p + (x0 - L * L / (L * L + 1.0)) * math.exp(-L * t)


class NanModel:
    """rhs becomes nan for t > t_bad."""

    n_states = 2
    state_scale = (1.0, 1.0)

    def __init__(self, t_bad: float) -> None:
        self.t_bad = t_bad

    def rhs(self, t, x, u):
        return [math.nan if t > self.t_bad else -x[0], -x[1]]


class Quadrature:
    """x1' = -x1 and an energy-like quadrature x2' = x1**2 with a tiny scale."""

    n_states = 2
    state_scale = (1.0, 1e-9)

    def __init__(self, mask=None) -> None:
        if mask is not None:
            self.error_mask = mask

    def rhs(self, t, x, u):
        return [-x[0], x[0] * x[0] + math.sin(50.0 * t)]


def all_steppers(model_j, model_nojac=None):
    """One stepper of every kind (and variant) for a model."""
    m2 = model_nojac if model_nojac is not None else model_j
    return [
        RK4(model_j, substeps=20),
        ExplicitAdaptive(model_j),
        ExplicitAdaptive(model_j, order=3),
        Rosenbrock(model_j),
        Rosenbrock(m2, jacobian="fd"),
        ExponentialRosenbrock(model_j),
        ExponentialRosenbrock(m2, jacobian="fd"),
        ScipyRadau(model_j),
    ]


def observed_orders(errors):
    return [math.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]


# ----------------------------------------------------------------------------------
# scalar decay
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize("stepper", all_steppers(DecayJ(), Decay()), ids=lambda s: f"{s.name}")
def test_decay_with_input_matches_exponential(stepper):
    m = stepper.model
    x0, u, h = [1.5], (0.8,), 0.5
    x, stats = stepper.advance(0.0, x0, u, h)
    exact = m.exact(h, x0[0], u)
    assert abs(x[0] - exact) <= 1e-5 * abs(exact)
    assert x0 == [1.5]
    assert isinstance(stats, StepStats) and stats.substeps >= 1


def test_rk4_observed_order_is_four():
    m = Decay(lam=1.0)
    errs = []
    for n in (8, 16, 32):
        x, _ = RK4(m, substeps=n).advance(0.0, [1.0], (0.0,), 1.0)
        errs.append(abs(x[0] - m.exact(1.0, 1.0, (0.0,))))
    for p in observed_orders(errs):
        assert abs(p - 4.0) <= 0.3


@pytest.mark.parametrize("cls", [ExplicitAdaptive, Rosenbrock])
def test_adaptive_meets_tolerance_and_converges(cls):
    m = DecayJ(lam=3.0)
    u = (0.5,)
    errors = []
    for rtol in (1e-4, 1e-6, 1e-8):
        s = cls(m, rtol=rtol, atol=1e-14)
        x, t, H = [2.0], 0.0, 0.1
        worst = 0.0
        for i in range(10):  # ten communication steps: the step-size proposal is carried
            x, stats = s.advance(t, x, u, H)
            t = (i + 1) * H
            exact = m.exact(t, 2.0, u)
            worst = max(worst, abs(x[0] - exact) / abs(exact))
            assert stats.error_estimate <= 1.0
        assert worst <= 10.0 * rtol
        errors.append(worst)
    assert errors[0] > errors[1] > errors[2]


@pytest.mark.parametrize(
    "make, order",
    [
        (lambda m, n: ExplicitAdaptive(m, fixed_substeps=n), 5),
        (lambda m, n: ExplicitAdaptive(m, fixed_substeps=n, order=3), 3),
        (lambda m, n: Rosenbrock(m, fixed_substeps=n), 3),
    ],
    ids=["dopri5", "bs3", "ros34pw2"],
)
def test_embedded_pair_observed_order_on_decay(make, order):
    m = DecayJ(lam=1.0)
    errs = []
    for n in (4, 8, 16):
        x, _ = make(m, n).advance(0.0, [1.0], (0.0,), 1.0)
        errs.append(abs(x[0] - m.exact(1.0, 1.0, (0.0,))))
    assert abs(observed_orders(errs)[-1] - order) <= 0.3


# ----------------------------------------------------------------------------------
# order on a nonlinear system (checks the tableaus beyond linear problems)
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make, order, ns",
    [
        (lambda n: RK4(LimitCycle(), substeps=n), 4, (20, 40)),
        (lambda n: ExplicitAdaptive(LimitCycle(), fixed_substeps=n), 5, (40, 80)),
        (lambda n: ExplicitAdaptive(LimitCycle(), fixed_substeps=n, order=3), 3, (40, 80)),
        (lambda n: Rosenbrock(LimitCycleJ(), fixed_substeps=n), 3, (40, 80)),
        (lambda n: Rosenbrock(LimitCycle(), fixed_substeps=n, jacobian="fd"), 3, (40, 80)),
        # W-method: order 3 is kept with a wrong Jacobian, hence also without df/dt
        (lambda n: Rosenbrock(LimitCycleWrongJ(), fixed_substeps=n), 3, (80, 160)),
    ],
    ids=["rk4", "dopri5", "bs3", "ros-analytic", "ros-fd", "ros-wrong-jacobian"],
)
def test_observed_order_nonlinear(make, order, ns):
    x0, T = [0.3, 0.1], 1.0
    ex = LimitCycle.exact(T, x0)
    errs = []
    for n in ns:
        x, _ = make(n).advance(0.0, x0, (), T)
        errs.append(math.hypot(x[0] - ex[0], x[1] - ex[1]))
    assert abs(observed_orders(errs)[0] - order) <= 0.3


@pytest.mark.parametrize(
    "make, local_order",
    [
        (lambda: ExplicitAdaptive(LimitCycle(), fixed_substeps=1), 5),  # embedded order 4
        (lambda: ExplicitAdaptive(LimitCycle(), fixed_substeps=1, order=3), 3),  # embedded 2
        (lambda: Rosenbrock(LimitCycleJ(), fixed_substeps=1), 3),  # embedded 2
    ],
    ids=["dopri5", "bs3", "ros34pw2"],
)
def test_error_estimate_has_local_order_of_embedded_method(make, local_order):
    est = [make().advance(0.0, [0.3, 0.1], (), h)[1].error_estimate for h in (0.05, 0.025)]
    assert abs(math.log2(est[0] / est[1]) - local_order) <= 0.3


@pytest.mark.parametrize("order", [5, 3])
def test_explicit_tableau_conditions(order):
    c, a, b, bh = EXPLICIT_TABLEAUS[order]
    for ci, row in zip(c, a):
        assert abs(sum(row) - ci) <= 1e-15
    p_hat = order - 1
    for k in range(1, order + 1):
        assert abs(sum(bi * ci ** (k - 1) for bi, ci in zip(b, c)) - 1.0 / k) <= 1e-14
    for k in range(1, p_hat + 1):
        assert abs(sum(bi * ci ** (k - 1) for bi, ci in zip(bh, c)) - 1.0 / k) <= 1e-14
    # FSAL: the last stage is evaluated at the new solution
    assert tuple(a[-1]) == tuple(b[: len(a[-1])]) and c[-1] == 1.0


def _ros_matrices():
    s = 4
    alpha = np.array(ROS_ALPHA)
    gam = np.array(ROS_GAMMA_IJ) + ROS_GAMMA * np.eye(s)
    return alpha, gam, np.array(ROS_B), np.array(ROS_BHAT)


def test_rosenbrock_order_conditions():
    """Hairer & Wanner II, Table IV.7.1: order 3 for b, order 2 for b_hat, not more."""
    alpha, gam, b, bh = _ros_matrices()
    g = ROS_GAMMA
    beta = alpha + gam - g * np.eye(4)  # strictly lower alpha_ij + gamma_ij
    a_i = alpha.sum(axis=1)
    beta_i = beta.sum(axis=1)

    def conds(w):
        return [
            w.sum() - 1.0,
            w @ beta_i - (0.5 - g),
            w @ a_i**2 - 1.0 / 3.0,
            w @ beta @ beta_i - (1.0 / 6.0 - g + g * g),
        ]

    assert max(abs(v) for v in conds(b)) <= 1e-14
    assert max(abs(v) for v in conds(bh)[:2]) <= 1e-14
    assert max(abs(v) for v in conds(bh)[2:]) > 1e-3  # embedded is genuinely order 2
    assert abs(b @ a_i**3 - 0.25) > 1e-3  # main is genuinely order 3
    # stiffly accurate: b equals the last row of alpha + gamma
    assert np.allclose(b, (alpha + gam)[-1], rtol=0, atol=1e-15)


def test_rosenbrock_stability_function():
    alpha, gam, b, bh = _ros_matrices()

    def R(z, w):
        return 1.0 + z * (w @ np.linalg.solve(np.eye(4) - z * (alpha + gam), np.ones(4)))

    assert abs(R(-1e12, b)) <= 1e-9  # L-stable: R(-inf) = 0
    ys = np.logspace(-3, 6, 200)
    assert max(abs(R(1j * y, b)) for y in ys) <= 1.0 + 1e-12  # A-stable on the imaginary axis
    assert max(abs(R(1j * y, bh)) for y in ys) <= 1.0 + 1e-12
    assert abs(R(-1e12, bh)) < 1.0
    for z in (-0.1, -1.0, -10.0, -1e3):  # damping on the real axis
        assert abs(R(z, b)) < 1.0


# ----------------------------------------------------------------------------------
# harmonic oscillator
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make, rel",
    [
        (lambda m: RK4(m, substeps=50), 1e-5),
        (lambda m: ExplicitAdaptive(m, rtol=1e-8, atol=1e-10), 1e-6),
        (lambda m: ExplicitAdaptive(m, rtol=1e-8, atol=1e-10, order=3), 1e-6),
        (lambda m: Rosenbrock(m, rtol=1e-8, atol=1e-10), 1e-6),
        (lambda m: Rosenbrock(m, rtol=1e-8, atol=1e-10, jacobian="fd"), 1e-6),
        (lambda m: ScipyRadau(m, rtol=1e-8, atol=1e-10), 1e-6),
    ],
    ids=["rk4", "dopri5", "bs3", "ros", "ros-fd", "radau"],
)
def test_harmonic_oscillator_one_period(make, rel):
    m = Oscillator(freq=50.0, amp=1e-3)
    s = make(m)
    x0 = [1e-3, 0.1]
    x, t, H = list(x0), 0.0, 1e-3  # 20 communication steps of 1 ms = one period
    for i in range(20):
        x, _ = s.advance(t, x, (), H)
        t = (i + 1) * H
        ex = m.exact(t, x0)
        assert abs(x[0] - ex[0]) <= rel * m.state_scale[0] * 10
    ex = m.exact(0.02, x0)
    assert abs(ex[0] - x0[0]) <= 1e-15 and abs(ex[1] - x0[1]) <= 1e-12
    for i in range(2):
        assert abs(x[i] - x0[i]) <= rel * (abs(x0[i]) + m.state_scale[i])


# ----------------------------------------------------------------------------------
# stiffness and stability
# ----------------------------------------------------------------------------------


def _stiff_limit():
    lam = np.linalg.eigvals(np.array(Stiff2.A))
    assert sorted(lam.real) == pytest.approx([-1e6, -1.0])
    return RK4_REAL_LIMIT / max(abs(lam))


@pytest.mark.parametrize("jacobian", ["analytic", "fd"])
def test_rosenbrock_stable_at_100x_explicit_limit(jacobian):
    m = Stiff2()
    h_step = 100.0 * _stiff_limit()
    steps_per_comm = 10
    H = steps_per_comm * h_step
    s = Rosenbrock(m, fixed_substeps=steps_per_comm, jacobian=jacobian)
    y0 = [1.0, 0.0]  # far off the slow manifold y2 = a y1
    x, t = list(y0), 0.0
    for i in range(18):
        x, stats = s.advance(t, x, (), H)
        t = (i + 1) * H
        assert max(abs(v) for v in x) <= 1.01  # bounded
    ex = m.exact(t, y0)
    assert abs(x[0] - ex[0]) <= 1e-9 and abs(x[1] - ex[1]) <= 1e-9
    a = m.L / (m.L - 1.0)
    assert abs(x[1] - a * x[0]) <= 1e-9  # the fast transient is gone
    assert stats.lu_decompositions == steps_per_comm


def test_rosenbrock_converges_to_slow_solution_as_step_shrinks():
    m = Stiff2()
    y0, T = [1.0, 0.0], 0.05
    ex = m.exact(T, y0)
    errs = []
    for mult in (1e4, 1e3, 1e2):
        n = round(T / (mult * _stiff_limit()))
        x, _ = Rosenbrock(m, fixed_substeps=n).advance(0.0, y0, (), T)
        errs.append(max(abs(x[0] - ex[0]), abs(x[1] - ex[1])))
    assert errs[0] > errs[1] > errs[2]
    assert errs[-1] <= 1e-9


@pytest.mark.parametrize("factor, grows", [(1.25, True), (0.8, False)])
def test_rk4_stability_limit(factor, grows):
    m = Stiff2()
    n = 40
    h_step = factor * _stiff_limit()
    x, _ = RK4(m, substeps=n).advance(0.0, [1.0, 0.0], (), n * h_step)
    deviation = abs(x[1] - m.L / (m.L - 1.0) * x[0])  # initially 1
    if grows:
        assert deviation > 1e6
    else:
        assert deviation < 1e-6


def test_rosenbrock_adaptive_on_time_dependent_stiff_problem():
    m = Prothero()
    s = Rosenbrock(m, rtol=1e-6, atol=1e-12)
    x, t, H = [0.0], 0.0, 0.01
    total = 0
    for i in range(50):
        x, stats = s.advance(t, x, (), H)
        t = (i + 1) * H
        total += stats.substeps + stats.rejected
        assert abs(x[0] - m.exact(t, 0.0)) <= 1e-5
    explicit_steps = 0.5 / (RK4_REAL_LIMIT / m.L)
    assert total < explicit_steps / 100


# ----------------------------------------------------------------------------------
# work counters
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 3, 10])
def test_rk4_counts_four_rhs_calls_per_substep(n):
    calls = []

    class Counting(Decay):
        def rhs(self, t, x, u):
            calls.append(t)
            return super().rhs(t, x, u)

    x, stats = RK4(Counting(), substeps=n).advance(0.0, [1.0], (0.0,), 0.1)
    assert stats.rhs_calls == 4 * n == len(calls)
    assert stats.substeps == n
    assert stats.jacobian_calls == stats.lu_decompositions == stats.rejected == 0
    assert stats.error_estimate == 0.0


class CountingCycle(LimitCycleJ):
    def __init__(self):
        self.rhs_calls = 0
        self.jac_calls = 0

    def rhs(self, t, x, u):
        self.rhs_calls += 1
        return super().rhs(t, x, u)

    def jacobian(self, t, x, u):
        self.jac_calls += 1
        return super().jacobian(t, x, u)


@pytest.mark.parametrize("jacobian", ["fd", "analytic"])
def test_rosenbrock_fixed_step_counts(jacobian):
    m = CountingCycle()
    n_sub = 5
    x, st = Rosenbrock(m, fixed_substeps=n_sub, jacobian=jacobian).advance(0.0, [0.3, 0.1], (), 0.1)
    per_step = 4 + (m.n_states if jacobian == "fd" else 0)
    assert st.rhs_calls == n_sub * per_step == m.rhs_calls
    assert st.jacobian_calls == n_sub
    assert m.jac_calls == (n_sub if jacobian == "analytic" else 0)
    assert st.lu_decompositions == n_sub and st.substeps == n_sub


def test_fd_jacobian_matches_analytic():
    m = LimitCycleJ()
    s = Rosenbrock(m, jacobian="fd")
    st = StepStats()
    x = [0.3, 0.1]
    f0 = m.rhs(0.0, x, ())
    jfd, jqd = s._jac(m.rhs, 0.0, x, f0, (), st)
    assert jqd == ()
    jan = m.jacobian(0.0, x, ())
    assert st.jacobian_calls == 1 and st.rhs_calls == m.n_states
    for i in range(2):
        for j in range(2):
            assert abs(jfd[i][j] - jan[i][j]) <= 1e-6


def test_adaptive_counts_are_consistent():
    m = CountingCycle()
    # the first advance: stage 1, one call for the starting step's estimate, then the trials
    x, st = ExplicitAdaptive(m, rtol=1e-8).advance(0.0, [0.3, 0.1], (), 1.0)
    assert st.rhs_calls == 2 + 6 * (st.substeps + st.rejected) == m.rhs_calls
    m = CountingCycle()
    x, st = ExplicitAdaptive(m, rtol=1e-6, order=3).advance(0.0, [0.3, 0.1], (), 1.0)
    assert st.rhs_calls == 2 + 3 * (st.substeps + st.rejected) == m.rhs_calls
    m = CountingCycle()
    x, st = Rosenbrock(m, rtol=1e-6).advance(0.0, [0.3, 0.1], (), 1.0)
    assert st.lu_decompositions == st.substeps + st.rejected
    assert st.jacobian_calls == m.jac_calls <= st.lu_decompositions
    assert st.rhs_calls == m.rhs_calls == st.jacobian_calls + 3 * st.lu_decompositions


def test_fixed_explicit_counts():
    m = CountingCycle()
    x, st = ExplicitAdaptive(m, fixed_substeps=7).advance(0.0, [0.3, 0.1], (), 0.1)
    assert st.rhs_calls == 1 + 6 * 7 == m.rhs_calls and st.substeps == 7 and st.rejected == 0


def test_error_mask_excludes_quadrature_from_error_control():
    with_all = ExplicitAdaptive(Quadrature(), rtol=1e-6, atol=1e-6)
    masked = ExplicitAdaptive(Quadrature(mask=(True, False)), rtol=1e-6, atol=1e-6)
    _, st_all = with_all.advance(0.0, [1.0, 0.0], (), 1.0)
    x, st_masked = masked.advance(0.0, [1.0, 0.0], (), 1.0)
    assert st_masked.substeps + st_masked.rejected < st_all.substeps + st_all.rejected
    assert abs(x[0] - math.exp(-1.0)) <= 1e-5
    with pytest.raises(ValueError, match="error_mask"):
        ExplicitAdaptive(Quadrature(mask=(False, False)))


def test_adaptive_lands_exactly_on_end_time():
    class Clock:
        n_states = 1
        state_scale = (1.0,)

        def rhs(self, t, x, u):
            return [3.0 * t * t]  # x = t**3

    for s in (ExplicitAdaptive(Clock(), rtol=1e-10), Rosenbrock(Clock(), rtol=1e-10)):
        t, x = 0.0, [0.0]
        for i in range(7):
            x, _ = s.advance(t, x, (), 0.3)
            t = (i + 1) * 0.3
        assert x[0] == pytest.approx(t**3, rel=1e-9)


# ----------------------------------------------------------------------------------
# quadrature states (Rosenbrock)
# ----------------------------------------------------------------------------------


class StiffQuad:
    """Stiff nonlinear core (v, w) with two quadratures: an angle theta' = v (state 0)
    and an energy E' = v**2 + w**2 (state 3); neither enters any rhs component."""

    n_states = 4
    state_scale = (1.0, 1.0, 1.0, 1.0)
    L = 1e4

    def __init__(self, declare: bool) -> None:
        if declare:
            self.quadrature_states = (3, 0)  # any order

    def rhs(self, t, x, u):
        _, v, w, _ = x
        return [v, u[0] - v + 0.5 * w - 0.1 * v**3, -self.L * (w - math.sin(v)), v * v + w * w]


class StiffQuadJ(StiffQuad):
    def jacobian(self, t, x, u):
        _, v, w, _ = x
        return [
            [0.0, 1.0, 0.0, 0.0],
            [0.0, -1.0 - 0.3 * v * v, 0.5, 0.0],
            [0.0, self.L * math.cos(v), -self.L, 0.0],
            [0.0, 2.0 * v, 2.0 * w, 0.0],
        ]


def _close(a, b, rel=1e-12):
    return all(abs(p - q) <= rel * (1.0 + abs(q)) for p, q in zip(a, b))


@pytest.mark.parametrize("jacobian", ["fd", "analytic"])
def test_quadrature_declaration_changes_only_round_off(jacobian):
    x0 = [0.3, 0.5, 0.2, 0.0]
    cls = StiffQuadJ if jacobian == "analytic" else StiffQuad
    # fixed steps
    res = []
    for declare in (False, True):
        s = Rosenbrock(cls(declare), fixed_substeps=10, jacobian=jacobian)
        res.append(s.advance(0.0, x0, (1.0,), 0.01))
    (a, sa), (b, sb) = res
    assert _close(b, a)
    n_q = 2
    assert sa.rhs_calls - sb.rhs_calls == (n_q * 10 if jacobian == "fd" else 0)
    # adaptive, memory carried, the input changing from advance to advance
    res = []
    for declare in (False, True):
        s = Rosenbrock(cls(declare), rtol=1e-7, atol=1e-10, jacobian=jacobian)
        x, t, out = list(x0), 0.0, []
        for i in range(5):
            x, st = s.advance(t, x, (1.0 + 0.3 * math.sin(i),), 2e-3)
            t += 2e-3
            out.append((x, st))
        res.append(out)
    for (a, sa), (b, sb) in zip(*res):
        assert _close(b, a)
        assert (sb.substeps, sb.rejected, sb.jacobian_calls) == (sa.substeps, sa.rejected, sa.jacobian_calls)
        extra = n_q * sa.jacobian_calls if jacobian == "fd" else 0
        assert sa.rhs_calls - sb.rhs_calls == extra


def test_quadrature_fd_jacobian_has_only_the_other_columns():
    m = StiffQuad(declare=True)
    s = Rosenbrock(m, jacobian="fd")
    x = [0.3, 0.5, 0.2, 7.0]
    st = StepStats()
    jdd, jqd = s._jac(m.rhs, 0.0, x, m.rhs(0.0, x, (1.0,)), (1.0,), st)
    exact = StiffQuadJ(declare=False).jacobian(0.0, x, (1.0,))
    assert st.rhs_calls == 2 and st.jacobian_calls == 1
    for rows, idx in ((jdd, (1, 2)), (jqd, (0, 3))):
        for row, i in zip(rows, idx):
            assert len(row) == 2
            for v, j in zip(row, (1, 2)):
                assert abs(v - exact[i][j]) <= 1e-6 * (1.0 + abs(exact[i][j]))


class _RandomLinear:
    """x' = J x with a given J (for the linear-algebra checks)."""

    def __init__(self, jac, quad):
        self.n_states = len(jac)
        self.state_scale = (1.0,) * self.n_states
        self.J = jac
        if quad:
            self.quadrature_states = quad

    def rhs(self, t, x, u):
        return [sum(a * b for a, b in zip(row, x)) for row in self.J]

    def jacobian(self, t, x, u):
        return self.J


@pytest.mark.parametrize(
    "n, quad",
    [(1, ()), (2, ()), (3, ()), (5, ()), (3, (1,)), (4, (0, 2)), (6, (0, 4, 5)), (8, (7, 0, 3)), (2, (0, 1))],
)
def test_block_solve_matches_dense_solve(n, quad):
    rng = random.Random(10 * n + len(quad))
    jac = [[0.0 if j in quad else rng.uniform(-1e3, 1e3) for j in range(n)] for i in range(n)]
    s = Rosenbrock(_RandomLinear(jac, quad))
    b = [rng.uniform(-1.0, 1.0) for _ in range(n)]
    for hs in (1e-5, 1e-2, 10.0):
        parts = s._jac(None, 0.0, [0.0] * n, None, (), StepStats())
        k = s._solve(s._lu(parts, hs), b)
        ref = np.linalg.solve(np.eye(n) / (hs * ROS_GAMMA) - np.array(jac), np.array(b))
        assert np.allclose(k, ref, rtol=1e-10, atol=1e-14 * np.abs(ref).max())


@pytest.mark.parametrize("n", [1, 2, 3])
def test_unrolled_lu_matches_numpy_with_pivoting(n):
    lu_small, solve_small = _SMALL_LU[n]
    rng = random.Random(n)
    for trial in range(50):
        d = rng.uniform(0.5, 2.0)
        jac = [[rng.uniform(-3.0, 3.0) for _ in range(n)] for _ in range(n)]
        if trial % 2:
            jac[0][0] = d  # zero in the first pivot position: needs a row exchange
        idx = [5, 2, 0][:n]
        b = [rng.uniform(-1.0, 1.0) for _ in range(6)]
        a = d * np.eye(n) - np.array(jac)
        if n == 1 and trial % 2:
            assert lu_small(jac, d, idx) is None
            continue
        y = solve_small(lu_small(jac, d, idx), b)
        ref = np.linalg.solve(a, np.array([b[i] for i in idx]))
        assert np.allclose(y, ref, rtol=1e-10, atol=1e-12)
    # singular: d I - J = 0, and (for n > 1) the rank-1 matrix -ones
    assert lu_small([[float(i == j) for j in range(n)] for i in range(n)], 1.0, list(range(n))) is None
    if n > 1:
        assert lu_small([[1.0] * n for _ in range(n)], 0.0, list(range(n))) is None


def test_quadrature_linear_system_matches_matrix_exponential():
    """5 coupled stiff states (general LU path) and 2 quadratures, against expm."""
    from scipy.linalg import expm

    rng = random.Random(7)
    nd = 5
    lam = [-1.0, -3.0, -10.0, -1e3, -1e4]
    v = np.array([[rng.uniform(-1.0, 1.0) + 3.0 * (i == j) for j in range(nd)] for i in range(nd)])
    a_dd = v @ np.diag(lam) @ np.linalg.inv(v)
    c = np.array([[1.0, 0.5, 0.0, -0.2, 0.3], [0.0, 0.0, 2.0, 0.0, 1.0]])
    # states: q0, d0, d1, q1, d2, d3, d4
    d_idx, q_idx = [1, 2, 4, 5, 6], [0, 3]
    jac = [[0.0] * 7 for _ in range(7)]
    for r, i in enumerate(d_idx):
        for s_, j in enumerate(d_idx):
            jac[i][j] = a_dd[r, s_]
    for r, i in enumerate(q_idx):
        for s_, j in enumerate(d_idx):
            jac[i][j] = c[r, s_]
    m = _RandomLinear(jac, (0, 3))
    x0 = [0.5, 1.0, -1.0, 2.0, 0.5, 0.3, -0.2]
    T = 0.5
    s = Rosenbrock(m, rtol=1e-8, atol=1e-10)
    x, st = s.advance(0.0, x0, (), T)
    xd0 = np.array([x0[i] for i in d_idx])
    xd = expm(a_dd * T) @ xd0
    xq = np.array([x0[i] for i in q_idx]) + c @ np.linalg.solve(a_dd, xd - xd0)
    exact = [0.0] * 7
    for r, i in enumerate(d_idx):
        exact[i] = xd[r]
    for r, i in enumerate(q_idx):
        exact[i] = xq[r]
    assert max(abs(p - q) for p, q in zip(x, exact)) <= 1e-6
    assert st.jacobian_calls >= 1 and st.rhs_calls == st.jacobian_calls + 3 * (st.substeps + st.rejected)


def test_all_states_quadrature():
    class Clock:
        n_states = 1
        state_scale = (1.0,)
        quadrature_states = (0,)

        def rhs(self, t, x, u):
            return [3.0 * t * t]

    s = Rosenbrock(Clock(), rtol=1e-10)
    x, st = s.advance(0.0, [0.0], (), 0.5)
    assert x[0] == pytest.approx(0.125, rel=1e-9)
    # no Jacobian columns to difference: one rhs call per accepted point plus 3 per trial
    assert st.rhs_calls == st.substeps + 3 * (st.substeps + st.rejected)


@pytest.mark.parametrize("bad", [(4,), (-1,), (1, 1), ("a",), (True,), 3, (1.0,)])
def test_quadrature_states_validation(bad):
    m = StiffQuad(declare=False)
    m.quadrature_states = bad
    with pytest.raises(ValueError, match="quadrature_states"):
        Rosenbrock(m)


def test_malformed_analytic_jacobian_raises_step_failure():
    class Ragged(StiffQuadJ):
        def jacobian(self, t, x, u):
            return [row[:2] for row in super().jacobian(t, x, u)]

    for declare in (False, True):
        x = [0.3, 0.5, 0.2, 0.0]
        with pytest.raises(StepFailure, match="jacobian"):
            Rosenbrock(Ragged(declare)).advance(0.0, x, (1.0,), 1e-3)
        assert x == [0.3, 0.5, 0.2, 0.0]


# ----------------------------------------------------------------------------------
# first step and memory after input changes (Rosenbrock)
# ----------------------------------------------------------------------------------


def test_rosenbrock_first_step_resolves_a_fast_transient():
    """Slightly off the slow manifold of Stiff2: the first-step guess (with x'' = J f)
    starts at the fast time scale; the explicit-method guess alone cost 14 rejections."""
    m = Stiff2()
    y0 = [1.0, m.L / (m.L - 1.0) * (1.0 + 1e-5)]
    x, st = Rosenbrock(m, rtol=1e-6, atol=1e-9).advance(0.0, y0, (), 0.01)
    ex = m.exact(0.01, y0)
    assert max(abs(p - q) for p, q in zip(x, ex)) <= 1e-9
    assert st.rejected <= 5


class FastInput:
    """x' = -L (x - u[0]);  x(t) = u + (x0 - u) exp(-L t)."""

    n_states = 1
    state_scale = (1.0,)
    L = 1e4

    def rhs(self, t, x, u):
        return [-self.L * (x[0] - u[0])]

    def jacobian(self, t, x, u):
        return [[-self.L]]


def test_rosenbrock_memory_is_the_first_step_proposal():
    """Each advance starts with a fast transient (new input); the memory proposes the
    first step's successor, so the next advance starts small instead of cascading
    rejections down from the last step's size (which cost 54 rejections here)."""
    m = FastInput()
    s = Rosenbrock(m, rtol=1e-6, atol=1e-9)
    x, t, H = [1.0], 0.0, 1e-3
    rejected = 0
    for i in range(20):
        u = (1.0 + 0.01 * math.sin(0.7 * i),)
        x0 = x[0]
        x, st = s.advance(t, x, u, H)
        t += H
        rejected += st.rejected
        assert abs(x[0] - (u[0] + (x0 - u[0]) * math.exp(-m.L * H))) <= 1e-6
        if i > 0:  # a transient at the start of the advance: the proposal is far below H
            assert s.get_memory()[0] < H / 5
    assert rejected <= 20


# ----------------------------------------------------------------------------------
# Jacobian reuse and the first-step bound (Rosenbrock)
# ----------------------------------------------------------------------------------


def test_quadrature_weights_are_the_b_weights():
    """Untransformed, the quadrature rows read k_q,i = h f_q(X_i) + h J_qd sum_j
    Gamma_ij k_d,j (the columns q of J are zero), so the weights of the stage values in
    the result are b, and b - b_hat in the error estimate."""
    assert np.allclose(_ROS_WQ, ROS_B, rtol=0, atol=1e-14)
    assert np.allclose(_ROS_EQ, np.array(ROS_B) - np.array(ROS_BHAT), rtol=0, atol=1e-14)


def _advances(stepper, x0, inputs, H):
    x, t, out = list(x0), 0.0, []
    for u in inputs:
        x, st = stepper.advance(t, x, u, H)
        t += H
        out.append((x, st))
    return out


def test_jacobian_reuse_changes_nothing_but_the_count_for_a_constant_jacobian():
    m = Stiff2()
    y0 = [1.0, m.L / (m.L - 1.0) * (1.0 + 1e-5)]  # a fast transient at the start
    ref = _advances(Rosenbrock(m, rtol=1e-6, atol=1e-9), y0, [()] * 5, 2e-3)
    reuse = _advances(Rosenbrock(m, rtol=1e-6, atol=1e-9, jacobian_reuse=1e9), y0, [()] * 5, 2e-3)
    for (a, sa), (b, sb) in zip(ref, reuse):
        assert a == b  # the same Jacobian, so the same steps bit for bit
        assert (sa.substeps, sa.rejected) == (sb.substeps, sb.rejected)
        # one per advance, plus one after a rejection at a point whose Jacobian is older;
        # fewer than a fresh one per step wherever the advance took several steps (the later
        # advances continue the earlier ones with nothing changed: one step each)
        assert sb.jacobian_calls <= 1 + sb.rejected
        if sa.substeps > 1:
            assert sb.jacobian_calls < sa.jacobian_calls
    assert ref[0][1].substeps > 1            # the transient: several steps in the first advance
    ex = m.exact(5 * 2e-3, y0)
    assert max(abs(p - q) for p, q in zip(reuse[-1][0], ex)) <= 1e-8


@pytest.mark.parametrize("jacobian", ["fd", "analytic"])
def test_jacobian_reuse_bound_refreshes_a_drifted_jacobian(jacobian):
    """Stiff nonlinear core with quadratures and an input that changes every advance:
    a vanishing bound refreshes the Jacobian at every new point (as without reuse); a
    moderate one saves Jacobians and keeps the error at the level of the tolerance."""
    cls = StiffQuadJ if jacobian == "analytic" else StiffQuad
    inputs = [(1.0 + 0.3 * math.sin(i),) for i in range(6)]
    x0 = [0.3, 0.5, 0.2, 0.0]
    H = 2e-3

    def run(reuse):
        return _advances(Rosenbrock(cls(True), rtol=1e-6, atol=1e-9, jacobian=jacobian,
                                    jacobian_reuse=reuse), x0, inputs, H)

    plain, tiny, moderate = run(0.0), run(1e-300), run(0.1)
    for (a, sa), (b, sb) in zip(plain, tiny):
        assert a == b and sa == sb
    assert sum(st.jacobian_calls for _, st in moderate) < sum(st.jacobian_calls for _, st in plain)
    radau = ScipyRadau(cls(True), rtol=1e-11, atol=1e-13)
    x = list(x0)
    for i, (u, (xm, _)) in enumerate(zip(inputs, moderate)):
        x, _ = radau.advance(i * H, x, u, H)
        assert max(abs(p - q) / (1.0 + abs(q)) for p, q in zip(xm, x)) <= 1e-5


def test_jacobian_reuse_does_not_trap_the_controller_in_a_friction_band():
    """The PRSM braked through zero speed: in the friction band the carriers' time
    constants collapse to nanoseconds while the states hardly change, so the drift bound
    alone would keep a stale Jacobian through ever smaller steps (2.5x the rhs calls);
    refreshing it after a shrinking step keeps reuse cheaper than none."""
    from prsm_fmu import presets
    from prsm_fmu.models import make_model

    model = make_model(presets.load("li2021_two_stage"), "dynamic", "torque")
    u = (5.0, 5000.0)  # the load back-drives the screw after ~1.04 ms
    x0 = model.initial_state(u, screw_speed=30.0, carrier_ratio=None)
    calls, ends = [], []
    for reuse in (0.0, 0.1):
        s = Rosenbrock(model, rtol=1e-7, atol=1e-10, jacobian_reuse=reuse)
        out = _advances(s, x0, [u] * 150, 1e-5)
        calls.append(sum(st.rhs_calls for _, st in out))
        ends.append(out[-1][0])
    assert ends[0][1] < 0.0 < x0[1]
    assert calls[1] < calls[0]
    assert max(abs(p - q) / (1.0 + abs(q)) for p, q in zip(*ends)) <= 1e-6


def _record_trials(s) -> list:
    """Record (t, h) of every trial step of the Rosenbrock stepper ``s``."""
    trials = []
    trial = s._trial

    def record(f, t, x, f0, fac, hs, u, *rest):
        trials.append((t, hs))
        return trial(f, t, x, f0, fac, hs, u, *rest)

    s._trial = record
    return trials


def test_first_step_bound_caps_the_first_step_of_every_advance():
    """h ||J|| <= first_step_stiffness for each advance's first step (an input change
    starts a fast transient there) unless the memory proposes more than fac_max times
    that; without memory the first step is the bound."""
    m = FastInput()
    c = 2.0
    s = Rosenbrock(m, rtol=1e-6, atol=1e-9, first_step_stiffness=c)
    trials = _record_trials(s)
    x, t, H = [1.0], 0.0, 1e-3
    for i in range(10):
        u = (1.0 + 0.01 * math.sin(0.7 * i),)
        x0 = x[0]
        x, _ = s.advance(t, x, u, H)
        assert abs(x[0] - (u[0] + (x0 - u[0]) * math.exp(-m.L * H))) <= 1e-6
        first = [hs for ti, hs in trials if ti == t]
        assert first and first[0] * m.L <= c * (1.0 + 1e-12)
        if i == 0:
            assert first[0] * m.L == pytest.approx(c, rel=1e-12)
        t += H
    # the bound is tighter than the memory alone would start with
    assert max(hs for ti, hs in trials) * m.L > c
    # ... but cuts the memory's proposal by at most fac_max
    s.set_memory((H,))
    trials.clear()
    s.advance(t, x, (1.0,), H)
    assert trials[0] == (t, H / s.fac_max)


class SlowFast:
    """y1' = −(y1 − u), y2' = −L (y2 − y1): a slow mode (rate 1 1/s) driving a fast one
    (L = 1e4 1/s).  With z = y − u: z1 = z1₀ e^(−t), z2 = z1₀ L/(L − 1) (e^(−t) − e^(−L t))
    + z2₀ e^(−L t)."""

    n_states = 2
    state_scale = (1.0, 1.0)
    L = 1e4

    def rhs(self, t, x, u):
        return [-(x[0] - u[0]), -self.L * (x[1] - x[0])]

    def jacobian(self, t, x, u):
        return [[-1.0, 0.0], [self.L, -self.L]]

    def exact(self, t, x, u):
        z1, z2 = x[0] - u[0], x[1] - u[0]
        e1, e2 = math.exp(-t), math.exp(-self.L * t)
        return [u[0] + z1 * e1, u[0] + z1 * self.L / (self.L - 1.0) * (e1 - e2) + z2 * e2]


def test_an_advance_that_continues_a_quiet_motion_is_not_bounded():
    """Nothing changed since the last advance (its end time, state and inputs) and the fast
    mode is at rest (the motion is the slow mode's: ||J f|| / ||f|| ≈ 1 1/s against
    ||J|| = 2e4 1/s): no first-step bound, the advance starts with the step the last one
    proposed; a change of the input, the state or the time brings the bound back.  Results
    against SlowFast's exact solution within the tolerance."""
    m = SlowFast()
    c = 2.0
    s = Rosenbrock(m, rtol=1e-6, atol=1e-9, first_step_stiffness=c)
    trials = _record_trials(s)
    x, t, H, u = [2.0, 1.5], 0.0, 1e-3, (1.0,)
    x, _ = s.advance(t, x, u, H)          # the fast transient: 10 time constants
    t += H
    substeps, continued = [], []
    for _ in range(6):
        proposed = s.get_memory()[1][3]
        trials.clear()
        x0 = list(x)
        x, st = s.advance(t, x, u, H)
        # continued: the first step is the last advance's proposal, however it compares with
        # the bound (the first advances may still see the fast mode's e^(−10 k) remainder)
        continued.append(trials[0] == (t, min(proposed, H)))
        ex = m.exact(H, x0, u)
        # within the tolerance: rtol |x| + atol ≈ 2e-6
        assert max(abs(a - b) for a, b in zip(x, ex)) <= 2e-6 + 1e-9
        substeps.append(st.substeps)
        t += H
    # bounded, every first step would be c / ||J|| = 2 / 2e4 = 1e-4 s (several steps per
    # advance); continuing, the steps grow until one step is the whole advance
    assert continued[-3:] == [True] * 3 and substeps[-1] == 1
    mem = s.get_memory()
    assert mem[1] is not None and mem[1][0] == t and mem[1][1] == tuple(x)
    # a first-step proposal of H: bounded, the first step is max(c / ||J||, H / fac_max)
    mem = (H, mem[1])
    bounded = max(c / (2.0 * m.L), H / s.fac_max)
    assert bounded * 1.05 < H <= mem[1][3]     # bounded: several steps; continuing: one
    s.set_memory(mem)
    trials.clear()
    s.advance(t, x, u, H)
    assert trials[0] == (t, H)                 # nothing changed: the continuation
    for changed in ((t, x, (1.1,)), (t, [x[0], x[1] + 1e-9], u), (t + H, x, u)):
        s.set_memory(mem)
        trials.clear()
        s.advance(changed[0], changed[1], changed[2], H)
        assert trials[0] == (changed[0], bounded), changed
    s.set_memory(mem)
    with pytest.raises(ValueError, match="continuation"):
        s.set_memory((H, (t, (1.0,), u, H)))              # one state for a two-state model
    with pytest.raises(ValueError, match="continuation"):
        s.set_memory((H, (t, (1.0, float("nan")), u, H)))
    assert s.get_memory() == mem                          # refused: nothing changed


def test_a_continuing_fast_transient_keeps_the_first_step_bound():
    """Continuing with nothing changed but the fast mode still relaxing (FastInput: the motion
    is the fast mode itself, ||J f|| / ||f|| = L = ||J||): the bound stays, as after an input
    change (its errors are what the bound was made for)."""
    m = FastInput()
    c = 2.0
    s = Rosenbrock(m, rtol=1e-6, atol=1e-9, first_step_stiffness=c)
    trials = _record_trials(s)
    x, t, H, u = [1.5], 0.0, 1e-3, (1.0,)
    for _ in range(4):
        trials.clear()
        x0 = x[0]
        x, _ = s.advance(t, x, u, H)
        assert trials[0][1] * m.L <= c * (1.0 + 1e-12)
        assert abs(x[0] - (u[0] + (x0 - u[0]) * math.exp(-m.L * H))) <= 1e-6 + 1e-9
        t += H


# ----------------------------------------------------------------------------------
# memory round trip
# ----------------------------------------------------------------------------------


def _memory_cases():
    cyc, cycj = LimitCycle(), LimitCycleJ()
    return [
        RK4(cyc, substeps=3),
        ExplicitAdaptive(cyc, rtol=1e-7),
        ExplicitAdaptive(cyc, rtol=1e-5, order=3),
        ExplicitAdaptive(cyc, fixed_substeps=4),
        Rosenbrock(cycj, rtol=1e-6),
        Rosenbrock(cyc, rtol=1e-5, jacobian="fd"),
        Rosenbrock(cycj, fixed_substeps=4),
        Rosenbrock(cyc, rtol=1e-6, jacobian="fd", jacobian_reuse=0.1),
        ExponentialRosenbrock(cyc, rtol=1e-6),
        ExponentialRosenbrock(cycj, fixed_substeps=4),
        ScipyRadau(cycj),
    ]


@pytest.mark.parametrize("stepper", _memory_cases(), ids=lambda s: s.name)
def test_memory_round_trip_is_bit_exact(stepper):
    x1, _ = stepper.advance(0.0, [0.3, 0.1], (), 0.37)
    mem = stepper.get_memory()
    assert isinstance(mem, tuple)
    a, sa = stepper.advance(0.37, x1, (), 0.21)
    a2, _ = stepper.advance(0.58, a, (), 0.5)  # move the memory on
    stepper.set_memory(mem)
    b, sb = stepper.advance(0.37, x1, (), 0.21)
    assert a == b  # bit for bit
    assert sa == sb
    stepper.reset()
    stepper.reset()


def test_adaptive_memory_carries_step_proposal():
    s = ExplicitAdaptive(LimitCycle(), rtol=1e-8)
    assert s.get_memory() == (None, None)
    s.advance(0.0, [0.3, 0.1], (), 0.3)
    mem = s.get_memory()
    assert mem[0] is not None and mem[0] > 0.0
    _, st_warm = s.advance(0.3, [0.3, 0.1], (), 0.3)
    s.reset()
    assert s.get_memory() == (None, None)
    with pytest.raises(ValueError):
        s.set_memory((1.0, 2.0))
    with pytest.raises(ValueError):
        s.set_memory((-1.0,))
    with pytest.raises(ValueError):
        RK4(LimitCycle()).set_memory((1.0,))


def test_adaptive_reuses_its_last_stage_only_where_the_next_advance_starts():
    """FSAL across advances: from the state it returned, with the same inputs, the next
    advance saves stage 1 and gives the same numbers as a stepper that evaluates it; from
    another state or with other inputs it evaluates it."""
    m = CountingCycle()
    s = ExplicitAdaptive(m, rtol=1e-8)
    x1, _ = s.advance(0.0, [0.3, 0.1], (), 0.3)
    mem = s.get_memory()
    fresh = ExplicitAdaptive(CountingCycle(), rtol=1e-8)
    fresh.set_memory(mem[:1])                       # the proposal, no stage to reuse
    x2, st = s.advance(0.3, x1, (), 0.3)
    x2f, stf = fresh.advance(0.3, x1, (), 0.3)
    assert x2 == x2f and st.substeps == stf.substeps
    assert st.rhs_calls == stf.rhs_calls - 1 == 6 * (st.substeps + st.rejected)
    s.set_memory(mem)
    _, st = s.advance(0.3, [x1[0] + 1e-9, x1[1]], (), 0.3)      # another state
    assert st.rhs_calls == 1 + 6 * (st.substeps + st.rejected)
    with pytest.raises(ValueError, match="FSAL"):
        s.set_memory((0.1, (0.3, (1.0,), (), (1.0,))))


# ----------------------------------------------------------------------------------
# failures and argument checks
# ----------------------------------------------------------------------------------


def _nan_steppers(t_bad):
    m = NanModel(t_bad)
    return [
        RK4(m, substeps=4),
        ExplicitAdaptive(m),
        ExplicitAdaptive(m, fixed_substeps=4),
        Rosenbrock(m),
        Rosenbrock(m, fixed_substeps=4),
        ExponentialRosenbrock(m),
        ExponentialRosenbrock(m, fixed_substeps=4),
        ScipyRadau(m),
    ]


@pytest.mark.parametrize("t_bad", [-1.0, 0.3])
def test_nan_rhs_raises_step_failure_and_keeps_input(t_bad):
    for s in _nan_steppers(t_bad):
        x = [1.0, 2.0]
        with pytest.raises(StepFailure, match=r"t = .* internal step") as info:
            s.advance(0.0, x, (), 1.0)
        assert x == [1.0, 2.0], s.name
        assert s.name in str(info.value)
        msg = str(info.value)
        assert "non-finite" in msg or "step size" in msg


@pytest.mark.parametrize("bad_h", [0.0, -1e-3, math.nan, math.inf, -math.inf])
def test_invalid_h_raises_value_error(bad_h):
    for s in all_steppers(DecayJ()):
        with pytest.raises(ValueError, match=r"\bh = "):
            s.advance(0.0, [1.0], (0.0,), bad_h)


def test_wrong_state_length_raises():
    with pytest.raises(ValueError, match="n_states"):
        RK4(Decay()).advance(0.0, [1.0, 2.0], (0.0,), 0.1)


def test_max_substeps_raises():
    s = ExplicitAdaptive(Stiff2(), rtol=1e-6, max_substeps=50)
    x = [1.0, 0.0]
    with pytest.raises(StepFailure, match="max_substeps"):
        s.advance(0.0, x, (), 0.01)
    assert x == [1.0, 0.0]


def test_singular_iteration_matrix_raises():
    h = 0.1
    lam = 1.0 / (h * ROS_GAMMA)  # makes I/(h gamma) - J exactly zero

    class Growth:
        n_states = 1
        state_scale = (1.0,)

        def rhs(self, t, x, u):
            return [lam * x[0]]

        def jacobian(self, t, x, u):
            return [[lam]]

    with pytest.raises(StepFailure, match="singular"):
        Rosenbrock(Growth(), fixed_substeps=1).advance(0.0, [1.0], (), h)


def test_constructor_validation():
    with pytest.raises(ValueError, match="substeps"):
        RK4(Decay(), substeps=0)
    with pytest.raises(ValueError, match="rtol"):
        ExplicitAdaptive(Decay(), rtol=-1.0)
    with pytest.raises(ValueError, match="atol"):
        Rosenbrock(Decay(), atol=0.0)
    with pytest.raises(ValueError, match="order"):
        ExplicitAdaptive(Decay(), order=4)
    with pytest.raises(ValueError, match="analytic"):
        Rosenbrock(Decay(), jacobian="analytic")
    with pytest.raises(ValueError, match="jacobian"):
        Rosenbrock(Decay(), jacobian="exact")
    assert Rosenbrock(Decay()).jacobian == "fd"
    assert Rosenbrock(DecayJ()).jacobian == "analytic"
    for name in ("jacobian_reuse", "first_step_stiffness"):
        for bad in (-1.0, math.nan, math.inf, "1"):
            with pytest.raises(ValueError, match=name):
                Rosenbrock(Decay(), **{name: bad})


# ----------------------------------------------------------------------------------
# reference path and factory
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize("model", [DecayJ(), Decay()], ids=["jacobian", "no-jacobian"])
def test_scipy_radau_matches_closed_form(model):
    for rtol in (1e-5, 1e-8):
        s = ScipyRadau(model, rtol=rtol, atol=1e-12)
        x, st = s.advance(0.0, [1.5], (0.8,), 1.0)
        exact = model.exact(1.0, 1.5, (0.8,))
        assert abs(x[0] - exact) <= 10 * rtol * abs(exact)
        assert st.rhs_calls > 0 and st.substeps > 0 and st.lu_decompositions > 0


def test_make_stepper():
    m = DecayJ()
    assert isinstance(make_stepper("rk4", m, substeps=2), RK4)
    assert isinstance(make_stepper("explicit_adaptive", m, rtol=1e-5, order=3), ExplicitAdaptive)
    assert isinstance(make_stepper("rosenbrock", m, jacobian="fd"), Rosenbrock)
    assert isinstance(make_stepper("radau", m), ScipyRadau)
    for name in STEPPER_NAMES:
        if name.startswith("closed_form"):   # need a model with closed_form_advance (test_slaved.py)
            with pytest.raises(ValueError, match="closed_form_advance"):
                make_stepper(name, m)
            continue
        s = make_stepper(name, m)
        assert isinstance(s, Stepper) and s.name == name
    with pytest.raises(ValueError) as info:
        make_stepper("euler", m)
    for name in ("rk4", "explicit_adaptive", "rosenbrock", "radau"):
        assert name in str(info.value)


# ----------------------------------------------------------------------------------
# dense LU
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 2, 5, 12])
def test_lu_solves_random_systems(n):
    rng = random.Random(n)
    a = [[rng.uniform(-1.0, 1.0) for _ in range(n)] for _ in range(n)]
    if n > 1:
        a[0][0] = 0.0  # needs pivoting
    b = [rng.uniform(-1.0, 1.0) for _ in range(n)]
    lu = _lu_factor([list(reversed(row)) for row in a])
    x = _lu_solve(lu, b)
    ref = np.linalg.solve(np.array(a), np.array(b))
    assert np.allclose(x, ref, rtol=1e-10, atol=1e-12)


def test_lu_detects_singular_matrix():
    a = [[1.0, 2.0], [2.0, 4.0]]
    assert _lu_factor([list(reversed(r)) for r in a]) is None
