"""The friction band of the slaved-carrier levels stepped by the exponential Rosenbrock path of
``closed_form`` (prsm_fmu/steppers/band.py) instead of the explicit Dormand-Prince one.

Expected values come from closed forms worked out here (the φ functions to 60 digits, the
relaxation of an affine rhs), from an independent root solve of the speed-drive balance (the
holding speed), from conservation of energy, and from scipy's Radau at rtol 1e-12 (an
independent integration of the same rhs).
"""

from __future__ import annotations

import math
from decimal import Decimal, getcontext

import pytest
from scipy.optimize import brentq

from prsm_fmu import presets
from prsm_fmu.models import make_model
from prsm_fmu.steppers import ClosedForm, make_stepper
from prsm_fmu.steppers.band import ScalarExponential, phi_functions

LI2021 = presets.load("li2021_two_stage")
FRICTION_ARTICLE = presets.load("friction_single_stage")   # with the viscous term


@pytest.mark.parametrize("z", [1e-9, 1e-3, 0.5, -0.99, 1.0, -1.0, 2.0, -50.0, 30.0, -1e6])
def test_phi_functions_equal_their_definition_evaluated_to_60_digits(z):
    # φ1 = (e^z − 1)/z, φ_(k+1) = (φ_k − 1/k!)/z, in 60-digit decimal arithmetic (no cancellation)
    getcontext().prec = 60
    zd = Decimal(z)
    want = [(zd.exp() - 1) / zd]
    for k in (1, 2, 3):
        want.append((want[-1] - Decimal(1) / math.factorial(k)) / zd)
    for got, w in zip(phi_functions(z), want):
        assert got == pytest.approx(float(w), rel=1e-13, abs=0.0)


class _Affine:
    """w' = a − b w with the quadratures θ' = w and E' = 3 w + 2 (exprb32 is exact for it)."""

    n_states = 3
    state_scale = (1.0, 1.0, 1.0)
    quadrature_states = (0, 2)
    a, b = 40.0, 5000.0

    def rhs(self, t, x, u):
        w = x[1]
        return [w, self.a - self.b * w, 3.0 * w + 2.0]


@pytest.mark.parametrize("h", [1e-4, 1e-2])
def test_affine_rhs_is_stepped_exactly_in_one_internal_step_whatever_its_stiffness(h):
    model = _Affine()
    st = ScalarExponential(model, rtol=1e-6, atol=1e-8)
    x0 = [0.1, 0.5, 0.0]
    y, stats = st.advance(0.0, x0, (), h)
    # w(t) = w* + (w0 − w*) e^(−bt), w* = a/b = 8e-3; ∫w = w* t + (w0 − w*)(1 − e^(−bt))/b
    ws = 40.0 / 5000.0
    decay = math.exp(-5000.0 * h)           # b h = 0.5 and 50 (stiff)
    w = ws + (0.5 - ws) * decay
    integral = ws * h + (0.5 - ws) * (1.0 - decay) / 5000.0
    assert y[1] == pytest.approx(w, rel=1e-12, abs=1e-15)
    assert y[0] == pytest.approx(0.1 + integral, rel=1e-12, abs=1e-15)
    assert y[2] == pytest.approx(3.0 * integral + 2.0 * h, rel=1e-12, abs=1e-15)
    assert (stats.substeps, stats.rhs_calls, stats.rejected) == (1, 3, 0)


def _holding_speed(params, torque: float, load: float) -> float:
    """Screw speed [rad/s] at which the motor torque holds the load at zero acceleration: root
    of the speed-drive balance (its driven torque at α = 0), found by bisection in the band."""
    speed_model = make_model(params, "quasi-static", "speed")

    def excess(w):
        return speed_model.outputs(0.0, [0.0, w, 0.0, 0.0, 0.0], (0.0, load))["screw_torque"] - torque

    # the band of Li et al. (2021) is |ω| < v_ε / (ℓ_1) = 1e-3 m/s / (10 mm / 2π) = 0.0628 rad/s
    return brentq(excess, -0.0628, 0.0628, xtol=1e-15, rtol=1e-15)


def _run(stepper, model, x0, u, h, n):
    x, xs, rhs = list(x0), [list(x0)], 0
    for k in range(n):
        x, st = stepper.advance(k * h, x, u, h)
        xs.append(x)
        rhs += st.rhs_calls
    return xs, rhs / n


def _balance_residual(model, xs, u) -> float:
    """max |W_in − W_out − W_f − ΔE_kin| over the run / max |W_in| (conservation of energy)."""
    e0 = model.kinetic_energy(xs[0], u)
    res = max(abs(x[2] - x[3] - x[4] - (model.kinetic_energy(x, u) - e0)) for x in xs)
    return res / max(abs(x[2]) for x in xs)


# 2 kN on Li et al. (2021) (20 mm per screw turn): 6.37 N·m turns into 2 kN × 3.18 mm/rad without
# friction; at 0.06 rad/s (the band's edge) the screw needs 7.90 N·m forward, 5.16 N·m back-driven
# (speed-drive outputs); these torques hold the load creeping inside the band, back-driven (5.5,
# 6.0: near zero speed, where the friction is stiffest) and forward (7.5)
@pytest.mark.parametrize("torque", [5.5, 6.0, 7.5])
@pytest.mark.parametrize("h,n", [(1e-4, 300), (1e-2, 5)])
def test_holding_speed_is_the_balance_root_and_energy_closes(torque, h, n):
    load = 2000.0
    w_star = _holding_speed(LI2021, torque, load)
    assert 0.0 < abs(w_star) < 0.0628
    model = make_model(LI2021, "quasi-static", "torque")
    u = (torque, load)
    st = ClosedForm(model, rtol=1e-6, atol=1e-8)
    xs, rhs = _run(st, model, [0.0, 0.0, 0.0, 0.0, 0.0], u, h, n)
    # 30 ms from rest: many relaxation times g'(ω*) (the holding friction is stiff)
    assert xs[-1][1] == pytest.approx(w_star, rel=1e-7, abs=1e-12)
    # energy at a tight tolerance: the work integrals close to 1e-9 of the input work
    tight = ClosedForm(model, rtol=1e-11, atol=1e-13)
    xs, _ = _run(tight, model, [0.0, 0.0, 0.0, 0.0, 0.0], u, h, n)
    assert _balance_residual(model, xs, u) <= 1e-9


def _max_error(xs, ref) -> float:
    """max over states of max|x − x_ref| / max|x_ref| (docs/accuracy.md §1)."""
    worst = 0.0
    for i in range(len(ref[0])):
        scale = max(abs(r[i]) for r in ref) or 1.0
        worst = max(worst, max(abs(a[i] - b[i]) for a, b in zip(xs, ref)) / scale)
    return worst


# reversal: 5 N·m against 5 kN (19.7 N·m needed forward) brakes the screw from 30 rad/s to zero in
# ~1 ms (tests/test_slaved.py) and the load then back-drives it through the band; holding: 6 N·m
# against 2 kN from rest (above)
CASES = {
    "reversal": (LI2021, (5.0, 5000.0), 30.0, 2e-3),
    "holding": (LI2021, (6.0, 2000.0), 0.0, 3e-2),
    "viscous reversal": (FRICTION_ARTICLE, (-2.0, 3000.0), 20.0, 4e-3),
}


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("h", [1e-4, 1e-3])
def test_band_path_error_against_radau_is_within_tolerance_and_no_worse_than_dormand_prince(case, h):
    params, u, w0, t_end = CASES[case]
    model = make_model(params, "quasi-static", "torque")
    n = round(t_end / h)
    x0 = [0.0, w0, 0.0, 0.0, 0.0]
    ref, _ = _run(make_stepper("radau", model, rtol=1e-12, atol=1e-14), model, x0, u, h, n)
    assert ref[-1][1] * max(w0, 1.0) <= 0.0 or case == "holding"   # the speed did reverse
    opts = {"rtol": 1e-6, "atol": 1e-8}                           # the FMU's tolerance
    new, rhs_new = _run(ClosedForm(model, **opts), model, x0, u, h, n)
    old, rhs_old = _run(ClosedForm(model, band="explicit", **opts), model, x0, u, h, n)
    err_new, err_old = _max_error(new, ref), _max_error(old, ref)
    assert err_new <= 1e-6
    if params is LI2021:
        # the Coulomb band: the exponential path is also no less accurate than Dormand-Prince;
        # with the viscous term (the friction-torque article) it is order 3 against order 5 on a rhs that is not
        # affine in the work integrals, and its error, within the tolerance, can be the larger
        assert max(err_new, 1e-12) <= max(err_old, 1e-12)
    # and cheaper in rhs calls (a count, not a time)
    assert rhs_new < rhs_old


def test_speed_drive_through_zero_speed_follows_the_prescribed_ramp_exactly():
    model = make_model(LI2021, "quasi-static", "speed")
    # −20 rad/s² from 0.05 rad/s over 5 ms: through the band's breaks and zero, to −0.05 rad/s
    u, h, n = (-20.0, 3000.0), 1e-3, 5
    xs, _ = _run(ClosedForm(model, rtol=1e-6, atol=1e-8), model, [0.0, 0.05, 0.0, 0.0, 0.0], u, h, n)
    ref, _ = _run(make_stepper("radau", model, rtol=1e-12, atol=1e-14), model,
                  [0.0, 0.05, 0.0, 0.0, 0.0], u, h, n)
    t = n * h
    assert xs[-1][1] == pytest.approx(0.05 - 20.0 * t, abs=1e-15)              # −0.05 rad/s
    assert xs[-1][0] == pytest.approx(0.05 * t - 10.0 * t * t, abs=1e-16)      # 0 rad
    # the work integrals (~5e-4 J here) within the run's absolute tolerance, 1e-8 J
    assert max(abs(a - b) for x, r in zip(xs, ref) for a, b in zip(x, r)) <= 1e-8


def test_memory_restores_the_next_advance_bit_for_bit():
    model = make_model(LI2021, "quasi-static", "torque")
    st = ClosedForm(model, rtol=1e-6, atol=1e-8)
    x, _ = st.advance(0.0, [0.0, 0.0, 0.0, 0.0, 0.0], (6.0, 2000.0), 1e-3)
    mem = st.get_memory()
    y1, _ = st.advance(1e-3, x, (6.1, 2000.0), 1e-3)
    st.reset()
    st.set_memory(mem)
    y2, _ = st.advance(1e-3, x, (6.1, 2000.0), 1e-3)
    assert y1 == y2


def test_bad_band_method_and_unsuitable_model_are_refused_with_the_reason():
    model = make_model(LI2021, "quasi-static", "torque")
    with pytest.raises(ValueError, match="band = 'implicit' is not allowed"):
        ClosedForm(model, band="implicit")
    with pytest.raises(ValueError, match="exactly one state that is not a quadrature"):
        ScalarExponential(make_model(LI2021, "dynamic", "torque"))
