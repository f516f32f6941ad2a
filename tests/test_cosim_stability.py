"""Co-simulation stability of the actuator loop: the linearised prediction against the real loop.

Expected values: closed forms written here from the physics, independently of
``system_models.coupling_analysis`` — the explicitly coupled mass, spring and damper under a
held force (stable for h < 2 c_d / k with the zero-order hold), the same with the first-order
extrapolated force, the sampled q-axis current loop with the voltage held over the step (Jacobi:
one step later), the line of steady states of a speed-controlled actuator against a spring, the
steady current from the independent root finder of the assembly.  Then, for every scheme, the
real nonlinear loop on each side of the predicted boundary (0.8× and 1.25×), classified against
a reference run by ``benchmarks/cosim_stability.py`` (loaded by path).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmark_modules import load_benchmark
from system_models import coupling_analysis as ca

bench = load_benchmark("cosim_stability")

SCHEMES = [("jacobi", 0), ("jacobi", 1), ("gauss-seidel", 0), ("gauss-seidel", 1)]
#: load stiffness where the motor/controller coupling limits h, and where the spring does
CONTROLLER_REGIME, SPRING_REGIME = 1e6, 1e9


@pytest.fixture(scope="module")
def loops():
    """The linearised loop at the operating point, per stiffness."""
    return {k: ca.linear_loop(ca.build_stability_system(k, 1e-4, "gauss-seidel", 1))
            for k in (CONTROLLER_REGIME, SPRING_REGIME)}


def _contains(eigenvalues, expected, tol):
    """Every expected eigenvalue has a match among ``eigenvalues`` (within ``tol``)."""
    return all(np.min(np.abs(eigenvalues - lam)) <= tol * max(1.0, abs(lam)) for lam in expected)


# ---- the linear model against closed forms --------------------------------------------------

def test_steady_current_of_the_linear_prsm_law_is_the_assemblys_root(loops):
    """i_q0 = K_F F0 / k_t (zero acceleration under α = (M − K_F F)/K_α) against the torque
    the assembly found with its own root finder on the full model (brentq, xtol 1e-14)."""
    system = ca.build_stability_system(CONTROLLER_REGIME, 1e-4, "jacobi", 0)
    lp = loops[CONTROLLER_REGIME]
    assert lp.kt * lp.iq0 == pytest.approx(system.initial["torque"], rel=1e-9)
    # the law is the PRSM's: rod mass = the inertia on the screw reflected, plus what friction
    # under acceleration adds (K_α ≥ J), and K_F ≥ c (efficiency below 1)
    assert lp.K_alpha >= system.inertia and lp.K_F >= lp.c


@pytest.mark.parametrize("order,extrapolation", SCHEMES)
@pytest.mark.parametrize("h", [1e-5, 1e-4, 2.37e-4])
def test_line_of_steady_states_is_a_fixed_line_of_every_macro_step(loops, order, extrapolation, h):
    """Speed mode against a spring: the PI holds ω0 at any compression δ, with k_t i_q = K_F k δ,
    i_q* = i_q, I_q = R i_q, v_d = −p ω0 L i_q (steady dq equations, written here): every such
    state must be mapped onto itself, whatever h and the sample phase."""
    lp = loops[SPRING_REGIME]
    iq = lp.K_F * lp.k / lp.kt                  # per metre of compression
    z = [0.0, iq, 1.0 / lp.c, 0.0, iq, 0.0, lp.R * iq, -lp.p * lp.w0 * lp.L * iq, lp.R * iq]
    if extrapolation:
        z += [0.0, iq, 1.0 / lp.c, 0.0]
    z = np.array(z)
    prod, _ = ca.period_map(lp, h, order, extrapolation)
    assert np.linalg.norm(prod @ z - z) <= 1e-9 * np.linalg.norm(z)


def _mechanics(lp, h, extrapolation):
    """Closed-form step map of the rod mass M under the load force F = k x + c_d v held over
    the step (order 0: F_k; order 1: the mean of the extrapolated line, 1.5 F_k − 0.5 F_(k−1)),
    exact integration: x' = x + h v − h² F̄/(2M), v' = v − h F̄/M.  State (x, v[, x⁻, v⁻])."""
    m, k, c = lp.rod_mass, lp.k, lp.c_d
    w = np.array([k, c]) * (1.5 if extrapolation else 1.0)
    w_prev = -0.5 * np.array([k, c]) if extrapolation else None
    n = 4 if extrapolation else 2
    a = np.zeros((n, n))
    a[0, :2] = [1.0, h]
    a[1, :2] = [0.0, 1.0]
    a[0, :2] -= h * h / (2.0 * m) * w
    a[1, :2] -= h / m * w
    if extrapolation:
        a[0, 2:] = -h * h / (2.0 * m) * w_prev
        a[1, 2:] = -h / m * w_prev
        a[2, 0] = a[3, 1] = 1.0
    return a


@pytest.mark.parametrize("order,extrapolation", SCHEMES)
def test_explicit_spring_coupling_has_the_closed_form_eigenvalues(loops, order, extrapolation):
    """With the motor's torque cut (k_t = 0) the mechanics only feel the load's force: the
    closed-form eigenvalues of the explicitly coupled mass–spring–damper must be among the
    macro-step map's, for both orders (the load is last in Gauss–Seidel)."""
    lp = loops[SPRING_REGIME].with_changes(kt=0.0)
    h = 2.0e-5
    eig = np.linalg.eigvals(ca.macro_step_map(lp, h, (), order, extrapolation))
    expected = np.linalg.eigvals(_mechanics(lp, h, extrapolation))
    expected = expected[np.abs(expected) > 1e-12]          # x⁻, v⁻ can add exact zeros
    assert _contains(eig, expected, 1e-9)


def test_zero_order_hold_spring_coupling_limit_is_2_cd_over_k(loops):
    """Held force F_k = k x_k + c_d v_k on the mass M: det = 1 − c_d h/M + k h²/(2M) < 1 gives
    h < 2 c_d/k (Jury; the other conditions: c_d h/M < 2, k h² > 0).  With k = 1e9, c_d = 1000
    this is 2 µs, far below the controller's own limit, so the predicted boundary is this one."""
    lp = loops[SPRING_REGIME].with_changes(kt=0.0)
    expected = min(2.0 * lp.c_d / lp.k, 2.0 * lp.rod_mass / lp.c_d)
    for order in ("jacobi", "gauss-seidel"):
        h = ca.predicted_boundary(lp, order, 0, h_min=1e-7)
        assert h == pytest.approx(expected, rel=3e-3)


def _current_loop(lp, h, order):
    """Closed-form q-axis current loop at ω0 = 0, mechanics frozen, one sample per step at its
    start: i' = a i + g v with a = exp(−R h/L), g = (1 − a)/R (voltage held); v = −K_p i + I,
    I' = I − T_s K_i i.  Gauss–Seidel applies v over the same step, Jacobi one step later."""
    a = math.exp(-lp.R * h / lp.L)
    g = (1.0 - a) / lp.R
    kp, ti = lp.kp_i, lp.Ts * lp.ki_i
    if order == "gauss-seidel":
        return np.array([[a - g * kp, g], [-ti, 1.0]])
    return np.array([[a, 0.0, g], [-ti, 1.0, 0.0], [-kp, 1.0, 0.0]])


@pytest.mark.parametrize("order", ["jacobi", "gauss-seidel"])
def test_sampled_current_loop_has_the_closed_form_eigenvalues(loops, order):
    lp = loops[CONTROLLER_REGIME].with_changes(w0=0.0, iq0=0.0, K_alpha=math.inf)
    h = lp.Ts
    eig = np.linalg.eigvals(ca.macro_step_map(lp, h, (0.0,), order, 0))
    expected = np.linalg.eigvals(_current_loop(lp, h, order))
    expected = expected[np.abs(expected) > 1e-12]
    assert _contains(eig, expected, 1e-9)


def test_two_regimes_spring_at_high_stiffness_controller_at_low(loops):
    """Zero-order hold: at 1e6 N/m the least stable mode just above the boundary is the motor and
    controller's (mechanical energy share < 0.5) and the boundary lies above the controller's
    sample time; at 1e9 N/m it is the spring's and the boundary is several times shorter."""
    for order in ("jacobi", "gauss-seidel"):
        h_lo = ca.predicted_boundary(loops[CONTROLLER_REGIME], order, 0)
        h_hi = ca.predicted_boundary(loops[SPRING_REGIME], order, 0)
        assert ca.critical_mode(loops[CONTROLLER_REGIME], 1.02 * h_lo, order, 0)[
            "mechanical_share"] < 0.5
        assert ca.critical_mode(loops[SPRING_REGIME], 1.02 * h_hi, order, 0)[
            "mechanical_share"] > 0.5
        assert h_lo > loops[CONTROLLER_REGIME].Ts and h_hi < 0.5 * h_lo


# ---- the real loop on each side of the predicted boundary -----------------------------------

@pytest.fixture(scope="module")
def references():
    return {k: bench.reference(k) for k in (CONTROLLER_REGIME, SPRING_REGIME)}


@pytest.mark.parametrize("stiffness", [CONTROLLER_REGIME, SPRING_REGIME])
@pytest.mark.parametrize("order,extrapolation", SCHEMES)
def test_real_loop_is_correct_below_and_not_correct_above_the_predicted_boundary(
        loops, references, stiffness, order, extrapolation):
    """At 0.8× the predicted largest stable step the real loop returns to the reference's state
    (within 2 % of the disturbance amplitude over the last 10 % of 0.4 s); at 1.25× it is
    bounded-but-wrong or diverged.  Where the disturbance is still visible at the end (the
    lightly damped spring mode), its measured decay per step is the predicted spectral radius."""
    lp = loops[stiffness]
    h_star = ca.predicted_boundary(lp, order, extrapolation)
    below = ca.snap_step(0.8 * h_star, lp.Ts)
    above = ca.snap_step(1.25 * h_star, lp.Ts)
    rho_below = ca.spectral_radius(lp, below, order, extrapolation)
    assert rho_below < 1.0 < ca.spectral_radius(lp, above, order, extrapolation)
    ref = references[stiffness]
    run = bench.judge(stiffness, below, order, extrapolation, ref, t_max=bench.T_END)
    print(f"\nk = {stiffness:g}, {order} {extrapolation}: h* = {h_star * 1e6:.1f} µs; 0.8 h*: "
          f"{run['cls']} (error {run['error']:.2e}, growth {run['growth']:.6f}, ρ {rho_below:.6f})",
          end="")
    assert run["cls"] == bench.CORRECT, run
    if math.isfinite(run["growth"]):
        assert math.log(run["growth"]) == pytest.approx(math.log(rho_below), rel=0.05)
    run = bench.judge(stiffness, above, order, extrapolation, ref, t_max=bench.T_END)
    print(f"; 1.25 h*: {run['cls']} ({run['reason']})", end="")
    assert run["cls"] in (bench.WRONG, bench.DIVERGED), run
