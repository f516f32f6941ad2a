"""The exponential Rosenbrock stepper (exprb32) and its φ-functions.

Expected values come from closed-form solutions worked out by hand below (linear stiff systems,
which an exponential method integrates exactly, and autonomous non-linear ones with known
solutions), from the φ-functions' defining series, and from the mechanism's equilibrium.
"""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from prsm_fmu import presets
from prsm_fmu.models import make_model
from prsm_fmu.steppers import ExponentialRosenbrock, make_stepper
from prsm_fmu.steppers.phi import phi_scalar, prepare


# ---- φ-functions ----------------------------------------------------------------------------

def _phi_series(z: complex, k: int) -> complex:
    """φ_k(z) by its definition: Σ_m z^m / (m + k)! summed in exact rational arithmetic for
    |z| <= 10 (no rounding in the alternating sum), else (e^z - Σ_{j<k} z^j / j!) / z^k with
    the polynomial exact (z real, far left: e^z is then below the polynomial's last digit)."""
    zr, zi = Fraction(complex(z).real), Fraction(complex(z).imag)
    if abs(z) <= 10.0:
        sr, si = Fraction(0), Fraction(0)
        tr, ti = Fraction(1, math.factorial(k)), Fraction(0)
        for m in range(1, 200):
            sr, si = sr + tr, si + ti
            tr, ti = (tr * zr - ti * zi) / (m + k), (tr * zi + ti * zr) / (m + k)
        return complex(float(sr), float(si)) if zi else float(sr)
    poly = sum(Fraction(zr) ** j / math.factorial(j) for j in range(k))
    return float((Fraction(math.exp(z)) - poly) / zr ** k)


@pytest.mark.parametrize("z", [0.0, 1e-9, -0.3, 0.99, -1.0, -7.5, -400.0, 2.0, complex(-3, 4)])
def test_phi_scalar_equals_its_series(z):
    got = phi_scalar(z, 4)
    for k in range(5):
        ref = _phi_series(z, k)
        assert abs(got[k] - ref) <= 1e-13 * abs(ref), (z, k)


def _phi_matrix_diag(lams, v, k, t):
    """φ_k(t·diag(λ)) v component-wise."""
    return [_phi_series(t * lam, k) * vi for lam, vi in zip(lams, v)]


@pytest.mark.parametrize("lams", [(-3.0,), (-2.0, -500.0), (0.0, -34.0, -69.0),
                                  (-1.7e2, -1.6e5, -8.5e4), (-1.0, -1.0005, -40.0)])
def test_phi_of_a_similar_matrix_equals_the_diagonal_form(lams):
    # Z = S diag(λ) S^-1 with S unit lower triangular (S^-1 by hand: for S = I + L with L
    # strictly lower and nilpotent, S^-1 = I - L + L²), so φ_k(Z) v = S φ_k(diag λ) S^-1 v;
    # the last case has two eigenvalues 5e-4 apart (relative 5e-4 < 1e-2 of ‖Z‖): the
    # augmented-matrix path
    n = len(lams)
    low = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i):
            low[i][j] = 0.5 + 0.25 * (i + j)

    def mat(a, b):
        return [[sum(a[i][m] * b[m][j] for m in range(n)) for j in range(n)] for i in range(n)]

    eye = [[float(i == j) for j in range(n)] for i in range(n)]
    s = [[eye[i][j] + low[i][j] for j in range(n)] for i in range(n)]
    l2 = mat(low, low)
    s_inv = [[eye[i][j] - low[i][j] + l2[i][j] for j in range(n)] for i in range(n)]
    z = mat(mat(s, [[lams[i] if i == j else 0.0 for j in range(n)] for i in range(n)]), s_inv)
    v = [1.0, -2.0, 0.5][:n]
    w = [sum(s_inv[i][j] * v[j] for j in range(n)) for i in range(n)]
    got = prepare(z).apply(v, (1, 2, 3, 4))
    for k, g in zip((1, 2, 3, 4), got):
        d = _phi_matrix_diag(lams, w, k, 1.0)
        ref = [sum(s[i][j] * d[j] for j in range(n)) for i in range(n)]
        scale = max(abs(r) for r in ref)
        assert max(abs(a - b) for a, b in zip(g, ref)) <= 1e-11 * scale, k


# ---- closed-form problems --------------------------------------------------------------------

class StiffLinear:
    """x1' = -1000 x1, x2' = x1 - x2, q' = x2 (q: a quadrature state).

    By hand: x1 = a e^{-1000 t}; x2 = b e^{-t} + a (e^{-t} - e^{-1000 t}) / 999;
    q = q0 + b (1 - e^{-t}) + a/999 [(1 - e^{-t}) - (1 - e^{-1000 t}) / 1000]."""

    n_states = 3
    state_scale = (1.0, 1.0, 1.0)
    quadrature_states = (2,)

    def rhs(self, t, x, u):
        return [-1000.0 * x[0], x[0] - x[1], x[1]]

    @staticmethod
    def exact(t, a, b, q0):
        e1, e2 = math.exp(-t), math.exp(-1000.0 * t)
        return [a * e2, b * e1 + a * (e1 - e2) / 999.0,
                q0 + b * (1.0 - e1) + a / 999.0 * ((1.0 - e1) - (1.0 - e2) / 1000.0)]


@pytest.mark.parametrize("h", [1e-4, 0.01, 1.0])
def test_a_linear_stiff_system_is_integrated_exactly_in_one_step_of_any_size(h):
    # h·1000 = 0.1, 10 and 1000: explicit methods are unstable beyond 2.8 (RK4)
    st = ExponentialRosenbrock(StiffLinear(), fixed_substeps=1)
    x, stats = st.advance(0.0, [1.0, 2.0, 0.5], (), h)
    ref = StiffLinear.exact(h, 1.0, 2.0, 0.5)
    for a, b in zip(x, ref):
        assert abs(a - b) <= 1e-12 * max(1.0, abs(b))
    # g(U) = f(U) - f(x) - J (U - x) vanishes for a linear rhs: the error estimate is round-off
    assert stats.error_estimate < 1e-3


class Forced:
    """y' = -y, x' = -k x + y².  By hand: y = e^{-t}; with x(0) = 1/(k-2), x = e^{-2t}/(k-2)
    (x' = -2 e^{-2t}/(k-2) = (-k + k - 2) e^{-2t}/(k-2))."""

    n_states = 2
    state_scale = (1.0, 1.0)

    def __init__(self, k: float) -> None:
        self.k = k

    def rhs(self, t, x, u):
        return [-x[0], -self.k * x[1] + x[0] * x[0]]

    def jacobian(self, t, x, u):
        return [[-1.0, 0.0], [2.0 * x[0], -self.k]]

    def x0(self):
        return [1.0, 1.0 / (self.k - 2.0)]

    def exact(self, t):
        return [math.exp(-t), math.exp(-2.0 * t) / (self.k - 2.0)]


class Riccati:
    """x' = -x², x(0) = 1: x = 1 / (1 + t)."""

    n_states = 1
    state_scale = (1.0,)

    def rhs(self, t, x, u):
        return [-x[0] * x[0]]

    def x0(self):
        return [1.0]

    @staticmethod
    def exact(t):
        return [1.0 / (1.0 + t)]


def _errors(model, ns=(8, 16, 32, 64), jacobian="auto"):
    """Max error at t = 1 after n fixed steps h = 1/n, for each n."""
    errs = []
    for n in ns:
        st = ExponentialRosenbrock(model, fixed_substeps=n, jacobian=jacobian)
        x, _ = st.advance(0.0, model.x0(), (), 1.0)
        errs.append(max(abs(a - b) for a, b in zip(x, model.exact(1.0))))
    return errs


def _orders(errs):
    return [math.log2(errs[i] / errs[i + 1]) for i in range(len(errs) - 1)]


@pytest.mark.parametrize("model,jacobian", [(Riccati(), "fd"), (Forced(10.0), "analytic"),
                                            (Forced(10.0), "fd")])
def test_observed_order_is_three(model, jacobian):
    # h = 1/8 .. 1/64, h·k <= 1.25: exprb32 is of order 3 (Hochbruck, Ostermann & Schweitzer
    # 2009); the forward-difference Jacobian (relative error ~1e-8) does not show at these errors
    orders = _orders(_errors(model, jacobian=jacobian))
    assert all(2.7 <= p <= 3.5 for p in orders), orders


def test_stiff_part_damps_the_error_below_the_non_stiff_one():
    # k = 1e4: h·k = 156 .. 1250.  The local error's h³ term comes through φ_j(hJ), which decays
    # like 1/(h k) in the stiff direction: the errors stay below the non-stiff problem's at the
    # same step (uniform order-3 bound) and fall at least like h² (h³ · 1/(h k))
    stiff, mild = _errors(Forced(1e4)), _errors(Forced(10.0))
    assert all(e <= m for e, m in zip(stiff, mild))
    assert all(p >= 1.9 for p in _orders(stiff)), _orders(stiff)


def test_adaptive_run_meets_its_tolerance_on_a_stiff_forced_problem():
    m = Forced(1e4)
    for rtol in (1e-5, 1e-8):
        st = ExponentialRosenbrock(m, rtol=rtol, atol=rtol * 1e-3)
        x, t = m.x0(), 0.0
        for _ in range(10):
            x, _ = st.advance(t, x, (), 0.1)
            t += 0.1
        ref = m.exact(1.0)
        assert max(abs(a - b) / abs(b) for a, b in zip(x, ref)) <= 10 * rtol


class FrozenJacobian:
    """A model whose ``jacobian`` always returns the exact one at the initial state: a
    deliberately stale Jacobian at every later point."""

    def __init__(self, model) -> None:
        self.inner = model
        self.n_states, self.state_scale = model.n_states, model.state_scale
        self.rhs, self.x0, self.exact = model.rhs, model.x0, model.exact
        self.frozen = _fd_jacobian(model, model.x0())

    def jacobian(self, t, x, u):
        return self.frozen


def _fd_jacobian(model, x):
    """Central differences (the test's own: step 1e-6, error ~1e-12 for these quadratics)."""
    cols = []
    for j in range(len(x)):
        xp, xm = list(x), list(x)
        xp[j] += 1e-6
        xm[j] -= 1e-6
        cols.append([(a - b) / 2e-6 for a, b in zip(model.rhs(0.0, xp, ()), model.rhs(0.0, xm, ()))])
    return [[cols[j][i] for j in range(len(x))] for i in range(len(x))]


@pytest.mark.parametrize("model,t0", [(Forced(10.0), 0.5), (Forced(1e4), 0.5), (Riccati(), 0.7)])
@pytest.mark.parametrize("h", [0.02, 0.1])
def test_a_stale_jacobians_local_error_stays_below_the_estimate(model, t0, h):
    # one step of size h from the exact state at t0 with the Jacobian of t = 0 (Riccati: A = -2
    # where J = -2/(1.7) = -1.18; Forced: A[1][0] = 2 where 2y = 2e^{-0.5} = 1.21); with
    # rtol = 0, atol = 1 and unit scales the estimate is the RMS of the correction, and the
    # W-type argument (exponential.py's docstring) makes the local error about half of it
    frozen = FrozenJacobian(model)
    st = ExponentialRosenbrock(frozen, rtol=0.0, atol=1.0, jacobian="analytic",
                               fixed_substeps=1)
    x1, stats = st.advance(t0, model.exact(t0), (), h)
    e = [a - b for a, b in zip(x1, model.exact(t0 + h))]
    rms = math.sqrt(sum(v * v for v in e) / len(e))
    assert 0.0 < rms <= stats.error_estimate


@pytest.mark.parametrize("rtol", [1e-5, 1e-8])
def test_kept_jacobian_run_meets_the_tolerance_and_saves_jacobians(rtol):
    # Jacobian reuse on (drift allowance 0.3, age 50): fewer Jacobians than accepted steps,
    # and the tolerance still met (the stale-Jacobian retry and the W-type estimate)
    m = Forced(1e4)
    st = ExponentialRosenbrock(m, rtol=rtol, atol=rtol * 1e-3, jacobian="fd",
                               jacobian_drift=0.3, jacobian_age=50)
    x, t, jacs, steps = m.x0(), 0.0, 0, 0
    for _ in range(10):
        x, stats = st.advance(t, x, (), 0.1)
        t += 0.1
        jacs += stats.jacobian_calls
        steps += stats.substeps
    assert jacs < steps
    ref = m.exact(1.0)
    assert max(abs(a - b) / abs(b) for a, b in zip(x, ref)) <= 10 * rtol


def test_continuing_advance_keeps_its_step_size_and_a_changed_input_does_not():
    # Riccati from x = 1 over 4 steps of 0.05: the second advance continues the first (same
    # state, inputs, time), so it starts at the controller's last proposal
    st = ExponentialRosenbrock(Riccati(), rtol=1e-9, atol=1e-12)
    x1, s1 = st.advance(0.0, [1.0], (), 0.05)
    h_first, cont, jrec = st.get_memory()
    assert cont is not None and cont[0] == 0.05 and cont[1] == tuple(x1)
    x2, s2 = st.advance(0.05, x1, (), 0.05)
    assert s2.rejected == 0 and s2.substeps <= s1.substeps
    st.set_memory((h_first, cont, jrec))
    # another state: no continuation (the first-step proposal is used)
    assert st._continues(0.05, [x1[0] * (1 + 1e-12)], (), 0.05) is None
    assert st._continues(0.05, x1, (1.0,), 0.05) is None
    assert st._continues(0.05, x1, (), 0.05) == cont[3]


@pytest.mark.parametrize("bad", [(1.0,), (1.0, 2.0), (None, None), (None, (0.0, (1.0,), (), -1.0), None),
                                 (None, (0.0, (1.0, 2.0), (), 1.0), None),
                                 (None, (0.0, (math.nan,), (), 1.0), None),
                                 # the kept Jacobian (x_J, u_J, age, A, B): Riccati has one
                                 # state d and no quadrature state, so A has 1 entry, B none
                                 (None, None, ((1.0,), (), 0.0, (1.0, 2.0), ())),
                                 (None, None, ((1.0,), (), 1.5, (-2.0,), ())),
                                 (None, None, ((1.0,), (), 0.0, (math.inf,), ())),
                                 (None, None, ((1.0,), (), 0, (-2.0,), ()))])
def test_bad_memory_is_refused(bad):
    st = ExponentialRosenbrock(Riccati())
    with pytest.raises(ValueError, match="memory"):
        st.set_memory(bad)


# ---- the PRSM's carriers ----------------------------------------------------------------------

LI2021 = presets.load("li2021_two_stage")


def test_stiff_carriers_settle_on_their_equilibrium_at_10_ms_steps():
    # torque drive at the steady torque of 100 rad/s under 5 kN (lead / 2π · F / η with the
    # preset's η ≈ 0.806), carrier 1 disturbed by 0.1 %: the carriers' time constants are ~14 µs
    # and ~30 µs, so a 10 ms step is ~700 of them; one exponential step per communication step
    model = make_model(LI2021, "dynamic", "torque")
    u = (LI2021.total_lead / (2 * math.pi) * 5000.0 / 0.806, 5000.0)
    x = model.initial_state(u, screw_speed=100.0, carrier_ratio=None)
    x[2] *= 0.999
    st = make_stepper("exponential", model, fixed_substeps=1)
    for i in range(20):
        x, _ = st.advance(i * 1e-2, x, u, 1e-2)
        assert all(math.isfinite(v) for v in x)
    for k, s in enumerate(model.mechanism.stages):
        assert x[2 + k] / x[1] == pytest.approx(s.zeta_geometric, rel=1e-6)


# ---- φ-functions of clustered, repeated, zero and large blocks ---------------------------------

def _phi_by_expm(z, v, k):
    """φ_k(Z) v from scipy's expm of the augmented matrix [[Z, v e_1^T], [0, N]] (N the k×k
    nilpotent shift; Al-Mohy & Higham, SIAM J. Sci. Comput. 33 (2011) 488, Thm 2.1): its
    column n + k - 1 holds φ_k(Z) v above — an independent reference (LAPACK Padé)."""
    import numpy as np
    from scipy.linalg import expm

    n = len(z)
    m = np.zeros((n + k, n + k))
    m[:n, :n] = z
    m[:n, n] = v
    for j in range(k - 1):
        m[n + j, n + j + 1] = 1.0
    return list(expm(m)[:n, n + k - 1])


@pytest.mark.parametrize("z", [
    [[0.0, 0.0], [0.0, 0.0]],                                   # zero block
    [[-0.3, 0.2], [0.1, -0.3]],                                 # eigenvalues -0.3 ± 0.14
    [[-0.5, 0.0], [0.0, -0.5]],                                 # repeated
    [[-0.5, 1e-9], [0.0, -0.5]],                                # repeated, defective (Jordan)
    [[1e-3, -2e-3, 1e-4], [5e-4, -1e-3, 2e-4], [3e-4, 1e-4, 2e-4]],   # clustered near 0
    [[-0.4, 0.3, 0.2], [0.1, -0.4, 0.1], [0.2, 0.2, -0.4]],     # norm 0.9, clustered pair
    [[-300.0, 250.0], [250.0, -300.0]],                         # large norm, well separated
    [[-120.0, 0.0, 1.0], [0.0, -120.0, 0.5], [2.0, 0.1, -120.0]],     # large norm, clustered
])
def test_phi_matches_the_augmented_matrix_exponential(z):
    v = [1.0, -2.0, 0.5][:len(z)]
    got = prepare(z).apply(v, (1, 2, 3, 4))
    for k, g in zip((1, 2, 3, 4), got):
        ref = _phi_by_expm(z, v, k)
        scale = max(abs(r) for r in ref)
        assert max(abs(a - b) for a, b in zip(g, ref)) <= 1e-13 * scale, (k, g, ref)


@pytest.mark.parametrize("lam,c", [(-0.25, 0.5), (-40.0, 300.0), (0.0, 1e3)])
def test_phi_of_a_jordan_block_equals_its_closed_form(lam, c):
    # Z = [[λ, c], [0, λ]] = λI + cN with N² = 0: φ_k(Z) = φ_k(λ) I + c φ_k'(λ) N, and
    # φ_k' = φ_k - k φ_{k+1} (differentiate Σ z^m/(m+k)! term by term: the coefficient of z^m
    # is (m+1)/(m+k+1)! on both sides).  φ_k(λ) from the rational series above.
    z = [[lam, c], [0.0, lam]]
    v = [0.7, -1.3]
    got = prepare(z).apply(v, (1, 2, 3, 4))
    for k, g in zip((1, 2, 3, 4), got):
        pk, pk1 = _phi_series(lam, k), _phi_series(lam, k + 1)
        ref = [pk * v[0] + c * (pk - k * pk1) * v[1], pk * v[1]]
        scale = max(abs(r) for r in ref)
        assert max(abs(a - b) for a, b in zip(g, ref)) <= 1e-12 * scale, (k, g, ref)
