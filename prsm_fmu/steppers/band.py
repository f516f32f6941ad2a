"""Exponential Rosenbrock step of a model with one state that the rhs depends on, the others
quadratures: the slaved-carrier levels' friction band at a few rhs calls per step.

What it integrates
------------------
A model whose state is one *free* state w (the screw speed ω [rad/s] of the quasi-static and
kinematic levels) and quadratures q (screw angle and work integrals): under held inputs
``x' = f(x)`` is the autonomous system

    w' = g(w),    q' = p(w),

(``model.quadrature_states`` names the q; exactly one state must be left over).  Inside the
friction band the regularised Coulomb law r(2 − r)µ|N| (friction.py) makes g depend on w
smoothly except where a sliding speed crosses its band edge v_ε or zero: there g is C¹ only
(its second derivative jumps).  The model names these points, ``model.smooth_breaks()`` (values
of w [rad/s]), and steps are split at them.  Near zero speed g is stiff (slope ≈ −2µ|N|/v_ε per
unit inertia, the holding friction), so an explicit method needs many small steps there.

Method
------
exprb32 of Hochbruck & Ostermann (Exponential integrators, Acta Numerica 19 (2010) 209–286,
§2.4): with J the exact Jacobian at the step's start x0,

    U2 = x0 + h φ1(hJ) f(x0),            D2 = f(U2) − f(x0) − J (U2 − x0),
    x1 = U2 + 2h φ3(hJ) D2               (order 3; U2 alone, the exponential Rosenbrock–Euler
                                          step, is order 2, so 2h φ3(hJ) D2 is the error estimate)

with φ1(z) = (e^z − 1)/z, φ_(k+1)(z) = (φ_k(z) − 1/k!)/z.  Why this method:

* exact for an affine rhs (D2 = 0): outside the band with a fixed sign pattern (g constant, p
  linear in |w|) and with the viscous term (g affine), so the step there is exact to round-off
  and always accepted; inside the band the solution relaxes to the holding speed where g = 0
  almost exponentially, which the φ functions follow exactly for any h·|g'| (no stiffness limit,
  no Newton iteration, no linear solve beyond a division);
* three rhs calls per internal step: f(x0), the Jacobian column (one forward difference in w:
  J has only that column, since no rhs component depends on a quadrature state), f(U2); a
  rejected step restarts from the same x0 and costs one call;
* the Jacobian is J = [[λ, 0], [c, 0]] with λ = g'(w0) and c = p'(w0), so J² = λJ and
  φ_k(hJ) has the closed form φ_k(hJ) v = v/k! + h φ_(k+1)(hλ) J v (from the power series),
  i.e. its w-part is φ_k(hλ) v_w and its q-part v_q/k! + h φ_(k+1)(hλ) c v_w: the quadratures
  are integrated by the same order-3 method, with no matrix function.

Assumptions: the inputs are held over the advance (so the system is autonomous: exprb32's order
3 holds for autonomous problems with the exact Jacobian); the forward-difference Jacobian
(increment √eps · max(|w|, smallest positive break)) is exact to ~1e-8 relative, which perturbs
the order-3 terms only; g is smooth between the breaks (at a break, g' is continuous, so a step
that crosses one anyway keeps a local error O(h³) which the estimate sees).

Traversal: where the motion crosses the band fast (braking through zero speed at ~3e4 rad/s²
crosses it in ~2 µs), exprb32's error in w, O(h³ g'' g²), against the absolute tolerance on w
forces tiny time steps.  There g keeps its sign, so time is a function of w and the crossing is
a plain quadrature in w-space over a known interval: dt = dw/g(w), dq = p(w)/g(w) dw from the
step's start to the next break (known exactly: that is where the integrand's smoothness ends),
by Gauss–Legendre with 5 points (exact to degree 9) and the 3-point rule on the shared midpoint
as error estimate (7 rhs calls; the time error δt counts as a speed error g δt).  It is used when
the linearised motion reaches the break within the advance and g stays above half its start
value on the way (no root of g nearby); if the estimate fails, a quarter of the interval and
then a sixteenth is tried, then exprb32 in time.

Step-size control: the weighted RMS norm of the estimate over the error-controlled states (the
weights of :class:`~prsm_fmu.steppers.explicit.ExplicitAdaptive`: ``atol·state_scale +
rtol·max(|x0|, |x1|)``), elementary controller with exponent 1/3, the order-3 solution
propagated.  Breaks: before each internal step, the time the linearised motion
w(τ) = w0 + τ φ1(λτ) g(w0) needs to reach the next break in its direction is known in closed
form (τ = log(1 + λd/g)/λ for a distance d); a step that would cross it further than 0.1 % and
before 95 % of its length is shortened to end there.  An optional ``exact(t, x, u, h)`` (the
model's closed-form step) is tried for the rest of the advance after every internal step, so a
motion that leaves the band finishes at closed-form cost.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from .base import StepStats, _INF, _SQRT_EPS, _is_finite_sum, _model_quadrature
from .control import AdaptiveBase
from .phi import phi_scalar

__all__ = ["ScalarExponential", "phi_functions"]

#: Gauss–Legendre rules on [−1, 1]: 5 points (exact to degree 9) and 3 points (degree 5), which
#: share the midpoint
_G5X1 = math.sqrt(5.0 - 2.0 * math.sqrt(10.0 / 7.0)) / 3.0
_G5X2 = math.sqrt(5.0 + 2.0 * math.sqrt(10.0 / 7.0)) / 3.0
_G5W1 = (322.0 + 13.0 * math.sqrt(70.0)) / 900.0
_G5W2 = (322.0 - 13.0 * math.sqrt(70.0)) / 900.0
_GAUSS = (((-_G5X2, -_G5X1, 0.0, _G5X1, _G5X2), (_G5W2, _G5W1, 128.0 / 225.0, _G5W1, _G5W2)),
          ((-math.sqrt(0.6), 0.0, math.sqrt(0.6)), (5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0)))


def phi_functions(z: float) -> tuple[float, float, float, float]:
    """φ1(z) … φ4(z) of the exponential integrators, accurate for every real z.

    φ_k(z) = Σ_(n≥0) z^n / (n + k)!, i.e. φ1 = (e^z − 1)/z, φ_(k+1) = (φ_k − 1/k!)/z.  Scalar
    case of :func:`prsm_fmu.steppers.phi.phi_scalar` (its series for |z| < 1, the recursion
    from e^z elsewhere).

    Parameters
    ----------
    z : float
        Argument h·λ [-].

    Returns
    -------
    tuple of float
        (φ1, φ2, φ3, φ4) at z.

    Raises
    ------
    OverflowError
        If e^z overflows (z > ~709).
    """
    return tuple(phi_scalar(z, 4)[1:])


class ScalarExponential(AdaptiveBase):
    """Exponential Rosenbrock exprb32 with step-size control for one free state plus quadratures.

    See the module docstring for the method, its assumptions and the break handling.

    Parameters
    ----------
    model : OdeModel
        Model whose ``quadrature_states`` leave exactly one state; optionally
        ``smooth_breaks()`` returning the values of that state [its SI unit] where the rhs is
        only C¹ (steps are split there).
    rtol, atol, h_min, max_substeps, fixed_substeps, safety, fac_min, fac_max
        As for :class:`~prsm_fmu.steppers.explicit.ExplicitAdaptive` (tolerances relative to
        ``state_scale``; step sizes [s]).
    exact : callable, optional
        ``exact(t, x, u, h) -> list | None``: a closed-form step tried for the rest of the
        advance after each internal step (counted as one rhs call when it answers).
    """

    name = "scalar_exponential"
    _q1 = 3.0

    def __init__(
        self,
        model: Any,
        rtol: float = 1e-6,
        atol: float = 1e-9,
        h_min: float = 1e-14,
        max_substeps: int = 100000,
        fixed_substeps: int | None = None,
        *,
        exact: Callable | None = None,
        safety: float = 0.9,
        fac_min: float = 0.2,
        fac_max: float = 5.0,
    ) -> None:
        super().__init__(model, rtol, atol, h_min, max_substeps, fixed_substeps, safety, fac_min,
                         fac_max)
        n = self.n_states
        quad = _model_quadrature(model, n)
        free = [i for i in range(n) if i not in quad]
        if len(free) != 1:
            raise ValueError(f"{self.name}: the model must have exactly one state that is not a "
                             f"quadrature (model.quadrature_states), it has {len(free)}")
        self._i = free[0]
        self._quad = quad
        breaks_fn = getattr(model, "smooth_breaks", None)
        breaks = tuple(float(b) for b in breaks_fn()) if callable(breaks_fn) else ()
        # a break at ±inf (a law whose band is unbounded) is never crossed
        breaks = tuple(b for b in breaks if math.isfinite(b))
        self._breaks = tuple(sorted(set(breaks)))
        positive = [abs(b) for b in self._breaks if b != 0.0]
        #: scale of the free state for the difference increment [its SI unit]
        self._w_scale = min(positive) if positive else self.state_scale[self._i]
        self._exact = exact

    # --- one internal step ----------------------------------------------------------------

    def _linearise(self, t: float, x: list[float], u: tuple, stats: StepStats) -> tuple:
        """f(x) and the Jacobian column d f / d w by a forward difference (2 rhs calls)."""
        f = self.model.rhs
        i = self._i
        f0 = f(t, x, u)
        stats.rhs_calls += 1
        w = x[i]
        step = _SQRT_EPS * max(abs(w), self._w_scale)
        if f0[i] < 0.0:                    # difference towards where the motion goes
            step = -step
        xd = list(x)
        xd[i] = w + step
        step = xd[i] - w                   # the increment actually represented
        fd = f(t, xd, u)
        stats.rhs_calls += 1
        col = [(b - a) / step for a, b in zip(f0, fd)]
        return f0, col

    def _trial(self, t: float, x: list[float], u: tuple, f0: list[float], col: list[float],
               hs: float, stats: StepStats) -> tuple[list[float] | None, float]:
        """exprb32 step of size hs from x: (x1, error norm); (None, inf) if not finite."""
        i = self._i
        lam = col[i]
        g0 = f0[i]
        try:
            p1, p2, p3, p4 = phi_functions(lam * hs)
        except OverflowError:
            return None, _INF
        dw = hs * p1 * g0
        hp2g = hs * p2 * g0
        u2 = [a + hs * (b + hp2g * c) for a, b, c in zip(x, f0, col)]
        u2[i] = x[i] + dw
        try:
            fu = self.model.rhs(t + hs, u2, u)
        except (ArithmeticError, ValueError):
            stats.rhs_calls += 1
            return None, _INF
        stats.rhs_calls += 1
        d_w = fu[i] - g0 - lam * dw
        h2 = 2.0 * hs
        e_w = h2 * p3 * d_w
        hp4d = hs * p4 * d_w
        est = [h2 * ((b - a - c * dw) / 6.0 + hp4d * c) for a, b, c in zip(f0, fu, col)]
        est[i] = e_w
        x1 = [a + e for a, e in zip(u2, est)]
        rtol = self.rtol
        sq = sum([(e / (at + rtol * max(abs(a), abs(b)))) ** 2
                  for e, a, b, at in zip(est, x, x1, self._atol_w)])
        err = math.sqrt(sq / self._n_err)
        if not (_is_finite_sum(x1) and math.isfinite(err)):
            return None, _INF
        return x1, err

    def _break_time(self, w0: float, g0: float, lam: float, hs: float) -> float | None:
        """Time [s] at which the linearised motion reaches the next break, if a step of size
        hs should end there (module docstring), else None."""
        if g0 == 0.0 or not self._breaks:
            return None
        ahead = [b for b in self._breaks if (b > w0 if g0 > 0.0 else b < w0)]
        ahead.sort(key=lambda b: abs(b - w0))
        for b in ahead:
            d = b - w0
            a = lam * d / g0
            if a <= -1.0:                  # the linearised motion stops short of it
                return None
            tau = d / g0 * (math.log1p(a) / a if a != 0.0 else 1.0)
            if tau <= 1e-3 * hs:           # crossed right at the start: no split
                continue
            return tau if tau < 0.95 * hs else None
        return None

    def _traverse(self, t: float, x: list[float], u: tuple, f0: list[float], col: list[float],
                  rem: float, stats: StepStats) -> tuple[float, list[float], float] | None:
        """Cross to the next break in w-space (module docstring, "Traversal"): (time [s], state
        at the break, error norm), or None where it does not apply (exprb32 steps in time)."""
        i = self._i
        w0, g0, lam = x[i], f0[i], col[i]
        if g0 == 0.0:
            return None
        ahead = [b for b in self._breaks if (b > w0 if g0 > 0.0 else b < w0)]
        if not ahead:
            return None
        b = min(ahead, key=lambda v: abs(v - w0))
        d = b - w0
        a = lam * d / g0
        if a < -0.5:                       # g would fall below half its value: near a root
            return None
        if d / g0 * (math.log1p(a) / a if a != 0.0 else 1.0) > 0.95 * rem:
            return None                    # the linearised motion does not get there in time
        f = self.model.rhs
        for _ in range(3):                 # the whole way to the break, then a quarter, ...
            mid, half = w0 + 0.5 * d, 0.5 * d
            rules = []
            seen: dict = {}
            for nodes, weights in _GAUSS:
                time = 0.0
                acc = [0.0] * len(x)
                for xi, wt in zip(nodes, weights):
                    fk = seen.get(xi)
                    if fk is None:
                        xk = list(x)
                        xk[i] = mid + xi * half
                        try:
                            fk = f(t, xk, u)
                        except (ArithmeticError, ValueError):
                            return None
                        stats.rhs_calls += 1
                        if not (fk[i] * g0 > 0.0 and _is_finite_sum(fk)):
                            return None    # a root of g (or no solution) inside: no traversal
                        seen[xi] = fk
                    c = wt * half / fk[i]  # dt = dw / g, dq = p dw / g
                    time += c
                    acc = [s + c * v for s, v in zip(acc, fk)]
                rules.append((time, acc))
            (t5, q5), (t3, q3) = rules
            if not 0.0 < t5 <= rem:
                return None
            y = [a + dq for a, dq in zip(x, q5)]
            y[i] = w0 + d
            # the lower rule's difference; in w a time error δt is a speed error g δt
            est = [p - q for p, q in zip(q5, q3)]
            est[i] = g0 * (t5 - t3)
            rtol = self.rtol
            err = math.sqrt(sum([(e / (at + rtol * max(abs(p), abs(q)))) ** 2
                                 for e, p, q, at in zip(est, x, y, self._atol_w)]) / self._n_err)
            if err <= 1.0:
                if d == b - w0:
                    y[i] = b                   # land on the break exactly
                return t5, y, err
            d *= 0.25
        return None

    # --- driver -------------------------------------------------------------------------

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        stats = StepStats()
        y = list(x)
        if self.fixed_substeps is not None:
            n_sub = self.fixed_substeps
            hs = h / n_sub
            for k in range(n_sub):
                tk = t + k * hs
                f0, col = self._checked_linearise(tk, y, u, stats, t, h, hs)
                y_new, err = self._trial(tk, y, u, f0, col, hs, stats)
                if y_new is None:
                    raise self._fail("non-finite value in the step", tk, hs, t, h)
                y = y_new
                stats.error_estimate = err
            stats.substeps = n_sub
            return y, stats

        hs = self._h_prop if self._h_prop is not None else h
        tau = 0.0
        attempts = 0
        i = self._i
        while True:
            ti = t + tau
            f0, col = self._checked_linearise(ti, y, u, stats, t, h, hs)
            crossed = self._traverse(ti, y, u, f0, col, h - tau, stats)
            if crossed is not None:
                dt, y, stats.error_estimate = crossed
                stats.substeps += 1
                tau += dt
                ye = self._rest_exact(t + tau, y, u, h - tau, hs, stats)
                if ye is not None:
                    return ye, stats
                continue
            just_rejected = False
            while True:
                rem = h - tau
                last = hs * 1.05 >= rem
                h_step = rem if last else hs
                cut = self._break_time(y[i], f0[i], col[i], h_step)
                if cut is not None:
                    h_step, last = cut, False
                attempts += 1
                if attempts > self.max_substeps:
                    raise self._fail(f"more than max_substeps = {self.max_substeps} internal "
                                     "steps (accepted + rejected)", ti, h_step, t, h)
                y_new, err = self._trial(ti, y, u, f0, col, h_step, stats)
                if err <= 1.0:
                    break
                stats.rejected += 1
                just_rejected = True
                hs = h_step * self._factor(err)
                if hs < self.h_min:
                    what = "non-finite value" if y_new is None else f"error norm {err:.3g} > 1"
                    raise self._fail(f"step size {hs!r} s below h_min = {self.h_min!r} s after "
                                     f"rejection ({what})", ti, h_step, t, h)
            stats.substeps += 1
            stats.error_estimate = err
            fac = self._factor(err)
            if just_rejected and fac > 1.0:
                fac = 1.0
            h_new = h_step * fac
            # a step shortened (to land on the end or a break) keeps the longer proposal
            hs = max(h_new, hs) if h_new >= h_step else h_new
            y = y_new
            if last:
                self._h_prop = hs
                return y, stats
            tau += h_step
            ye = self._rest_exact(t + tau, y, u, h - tau, hs, stats)
            if ye is not None:
                return ye, stats

    def _rest_exact(self, t: float, y: list[float], u: tuple, rem: float, hs: float,
                    stats: StepStats) -> list[float] | None:
        """The closed-form step over the rest ``rem`` [s] of the advance, if it answers."""
        if self._exact is None:
            return None
        ye = self._exact(t, y, u, rem)
        if ye is None or not _is_finite_sum(ye):
            return None
        stats.rhs_calls += 1
        stats.substeps += 1
        self._h_prop = hs
        return ye

    def _checked_linearise(self, ti: float, y: list[float], u: tuple, stats: StepStats,
                           t: float, h: float, hs: float) -> tuple:
        try:
            f0, col = self._linearise(ti, y, u, stats)
        except (ArithmeticError, ValueError) as exc:
            raise self._fail(f"rhs raised {exc!r} at the step's start", ti, hs, t, h) from exc
        if len(f0) != len(y) or not (_is_finite_sum(f0) and _is_finite_sum(col)):
            raise self._fail("non-finite value (or wrong length) in the rhs or its Jacobian "
                             "at the step's start", ti, hs, t, h)
        return f0, col
