"""Embedded explicit Runge-Kutta pairs with step-size control: Dormand-Prince 5(4) and
Bogacki-Shampine 3(2) (tableaux in :mod:`.tableaux`)."""

from __future__ import annotations

import math
from typing import Any, Callable

from .base import StepStats, _INF, _bad_text, _is_finite_sum
from .control import AdaptiveBase
from .tableaux import _BS_A, _BS_B, _BS_C, _BS_E, _DP_A, _DP_B, _DP_C, _DP_E

__all__ = ["ExplicitAdaptive"]


class ExplicitAdaptive(AdaptiveBase):
    """Embedded explicit Runge-Kutta pair with step-size control (FSAL).

    ``order=5`` (default): Dormand-Prince 5(4), 6 rhs calls per step thanks to FSAL
    (the last stage is the first stage of the next step), propagates the 5th-order
    solution (local extrapolation).  Chosen as default because at the tolerances used
    for reference runs (rtol 1e-6 ... 1e-10) it needs far fewer rhs calls per unit of
    accuracy than low-order pairs, and its stability region is comparatively large
    (real-axis limit ~3.3).  ``order=3``: Bogacki-Shampine 3(2), 3 rhs calls per step
    (FSAL), cheaper for loose tolerances (rtol >= 1e-4) or mildly non-smooth rhs.

    The weighted RMS error norm runs over the states with ``error_mask`` true, with
    weights ``atol * state_scale[i] + rtol * max(|x_i|, |x_new_i|)``.  Elementary
    controller ``h_new = h * min(fac_max, max(fac_min, safety * err**(-1/(q+1))))``
    with ``q`` the embedded order; no growth right after a rejection.  Each advance
    lands exactly on ``t + h`` (the last internal step is shortened, or stretched by at
    most 5 % to avoid a tiny remainder).  The step-size proposal is carried between
    advance calls (memory), and so is the FSAL stage: it is reused only when the next
    advance starts where this one ended with the same state and inputs (the master may
    change either in between; then the first stage is evaluated afresh).  Reused or
    evaluated, it is the same number, so results do not depend on it; the rhs count does.
    Without a proposal (the first advance, after :meth:`reset`) the first internal step
    is chosen as in Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.4 (with one extra
    rhs call): from the norms of the state, its derivative and an estimate of the second
    derivative.

    Non-finite values in a trial step (other than at its start point) reject the
    step and shrink it by ``fac_min``; a non-finite rhs at an accepted point, or a step
    shrunk below ``h_min``, raises :class:`StepFailure`.

    Parameters
    ----------
    model : OdeModel
        Model to integrate; needs ``state_scale`` [SI].
    rtol : float, optional
        Relative tolerance (>= 0).
    atol : float, optional
        Absolute tolerance relative to ``state_scale`` (> 0): the absolute tolerance of
        state ``i`` is ``atol * state_scale[i]`` in its SI unit.
    h_min : float, optional
        Smallest internal step [s] the controller may use.
    max_substeps : int, optional
        Maximum internal steps (accepted + rejected) per advance.
    fixed_substeps : int or None, optional
        If given, take this many equal steps per advance without error control (for
        stability and order studies); the error estimate is still reported.
    order : {5, 3}, optional
        5: Dormand-Prince 5(4); 3: Bogacki-Shampine 3(2).
    safety, fac_min, fac_max : float, optional
        Controller safety factor and limits of the step-size ratio.
    """

    name = "explicit_adaptive"

    def __init__(
        self,
        model: Any,
        rtol: float = 1e-6,
        atol: float = 1e-9,
        h_min: float = 1e-14,
        max_substeps: int = 100000,
        fixed_substeps: int | None = None,
        *,
        order: int = 5,
        safety: float = 0.9,
        fac_min: float = 0.2,
        fac_max: float = 5.0,
    ) -> None:
        super().__init__(model, rtol, atol, h_min, max_substeps, fixed_substeps, safety, fac_min, fac_max)
        if order == 5:
            self._trial = self._trial_dp5
            self._rhs_per_trial = 6
            self._q1 = 5.0
            self.method = "Dormand-Prince 5(4)"
        elif order == 3:
            self._trial = self._trial_bs3
            self._rhs_per_trial = 3
            self._q1 = 3.0
            self.method = "Bogacki-Shampine 3(2)"
        else:
            raise ValueError(
                f"order = {order!r} is out of range: allowed are 5 (Dormand-Prince) and 3 (Bogacki-Shampine)"
            )
        self.order = order
        self._fsal: tuple | None = None

    # --- memory: the step-size proposal and the FSAL stage ------------------------------

    def get_memory(self) -> tuple:
        """Return ``(h_proposal, fsal)``: the proposed next internal step [s] (None before
        the first adaptive advance) and ``(t_end, x_end, u, f(t_end, x_end))`` of the last
        advance (None if there is none to reuse)."""
        return (self._h_prop, self._fsal)

    def set_memory(self, m: tuple) -> None:
        """Restore ``(h_proposal, fsal)`` from :meth:`get_memory` (``(h_proposal,)`` alone is
        accepted: no FSAL stage to reuse)."""
        m = tuple(m)
        if len(m) not in (1, 2):
            raise ValueError(f"{self.name}: memory must be (h_proposal, fsal), got {m!r}")
        fsal = m[1] if len(m) == 2 else None
        if fsal is not None and not (isinstance(fsal, tuple) and len(fsal) == 4
                                     and len(fsal[1]) == self.n_states == len(fsal[3])):
            raise ValueError(f"{self.name}: memory's FSAL stage must be None or "
                             f"(t, x, u, f) with {self.n_states} states, got {fsal!r}")
        super().set_memory(m[:1])
        self._fsal = fsal

    def reset(self) -> None:
        """Forget the step-size proposal and the FSAL stage."""
        super().reset()
        self._fsal = None

    def _first_stage(self, f: Callable, t: float, x: list[float], u: tuple, h: float,
                     stats: StepStats) -> list[float]:
        """f(t, x, u): the last advance's FSAL stage when this one starts where it ended."""
        c = self._fsal
        if c is not None and c[2] == u and abs(t - c[0]) <= 4e-16 * max(abs(t), h) \
                and c[1] == tuple(x):
            return list(c[3])
        try:
            k1 = f(t, x, u)
        except (ArithmeticError, ValueError) as exc:
            raise self._fail(f"rhs raised {exc!r} in stage 1", t, self._h_prop or h, t, h) from exc
        stats.rhs_calls += 1
        return k1

    def _starting_step(self, f: Callable, t: float, x: list[float], k1: list[float], u: tuple,
                       h: float, stats: StepStats) -> float:
        """First internal step [s] without a proposal (Hairer, Norsett & Wanner, II.4)."""
        w, d0, d1 = self._start_norms(x, k1)
        n = self._n_err
        if not d1 > 1e-5:          # practically at rest (or nan, handled by the step itself)
            return h
        h0 = min(h, 0.01 * d0 / d1 if d0 >= 1e-5 else 1e-6)
        try:
            f1 = f(t + h0, [a + h0 * b for a, b in zip(x, k1)], u)
        except (ArithmeticError, ValueError):
            return min(h, h0)
        stats.rhs_calls += 1
        d2 = math.sqrt(sum([((b - a) / wi) ** 2 for a, b, wi in zip(k1, f1, w)]) / n) / h0
        dm = max(d1, d2)
        if not math.isfinite(dm):
            return min(h, h0)
        h1 = (0.01 / dm) ** (1.0 / (self.order + 1)) if dm > 1e-15 else max(1e-6, 1e-3 * h0)
        return min(h, 100.0 * h0, h1)

    # --- trial steps: return (x_new, f(t+hs, x_new), err, bad_stage) ---------------------
    # bad_stage: 0 if all finite, i >= 2 the first stage (1-based; the last stage is the
    # rhs at the new point) with a non-finite value, -1 a non-finite result.

    def _trial_dp5(
        self, f: Callable, t: float, x: list[float], k1: list[float], hs: float, u: tuple
    ) -> tuple:
        (_, c2, c3, c4, c5, _, _) = _DP_C
        (a21,), (a31, a32), (a41, a42, a43), (a51, a52, a53, a54), (a61, a62, a63, a64, a65) = _DP_A[1:6]
        b1, _, b3, b4, b5, b6, _ = _DP_B
        h21 = hs * a21
        k2 = f(t + c2 * hs, [p + h21 * q for p, q in zip(x, k1)], u)
        h31, h32 = hs * a31, hs * a32
        k3 = f(t + c3 * hs, [p + h31 * q + h32 * r for p, q, r in zip(x, k1, k2)], u)
        h41, h42, h43 = hs * a41, hs * a42, hs * a43
        k4 = f(t + c4 * hs, [p + h41 * q + h42 * r + h43 * s for p, q, r, s in zip(x, k1, k2, k3)], u)
        h51, h52, h53, h54 = hs * a51, hs * a52, hs * a53, hs * a54
        k5 = f(
            t + c5 * hs,
            [p + h51 * q + h52 * r + h53 * s + h54 * v for p, q, r, s, v in zip(x, k1, k2, k3, k4)],
            u,
        )
        h61, h62, h63, h64, h65 = hs * a61, hs * a62, hs * a63, hs * a64, hs * a65
        k6 = f(
            t + hs,
            [
                p + h61 * q + h62 * r + h63 * s + h64 * v + h65 * w
                for p, q, r, s, v, w in zip(x, k1, k2, k3, k4, k5)
            ],
            u,
        )
        g1, g3, g4, g5, g6 = hs * b1, hs * b3, hs * b4, hs * b5, hs * b6
        xn = [
            p + g1 * q + g3 * s + g4 * v + g5 * w + g6 * z for p, q, s, v, w, z in zip(x, k1, k3, k4, k5, k6)
        ]
        k7 = f(t + hs, xn, u)
        e1, e3, e4, e5, e6, e7 = (hs * e for e in _DP_E)
        rtol = self.rtol
        sq = sum(
            [
                (
                    (e1 * q + e3 * s + e4 * v + e5 * w + e6 * z + e7 * y)
                    / (at + rtol * max(abs(p), abs(pn)))
                )
                ** 2
                for q, s, v, w, z, y, p, pn, at in zip(k1, k3, k4, k5, k6, k7, x, xn, self._atol_w)
            ]
        )
        err = math.sqrt(sq / self._n_err)
        chk = sum(k2) + sum(k3) + sum(k4) + sum(k5) + sum(k6) + sum(k7) + sum(xn) + err
        if chk - chk != 0.0 or len(xn) != len(x):
            return xn, k7, err, self._locate(len(x), (k2, k3, k4, k5, k6, k7), xn)
        return xn, k7, err, 0

    def _trial_bs3(
        self, f: Callable, t: float, x: list[float], k1: list[float], hs: float, u: tuple
    ) -> tuple:
        (_, c2, c3, _) = _BS_C
        b1, b2, b3, _ = _BS_B
        h21 = hs * _BS_A[1][0]
        k2 = f(t + c2 * hs, [p + h21 * q for p, q in zip(x, k1)], u)
        h32 = hs * _BS_A[2][1]
        k3 = f(t + c3 * hs, [p + h32 * r for p, r in zip(x, k2)], u)
        g1, g2, g3 = hs * b1, hs * b2, hs * b3
        xn = [p + g1 * q + g2 * r + g3 * s for p, q, r, s in zip(x, k1, k2, k3)]
        k4 = f(t + hs, xn, u)
        e1, e2, e3, e4 = (hs * e for e in _BS_E)
        rtol = self.rtol
        sq = sum(
            [
                ((e1 * q + e2 * r + e3 * s + e4 * v) / (at + rtol * max(abs(p), abs(pn)))) ** 2
                for q, r, s, v, p, pn, at in zip(k1, k2, k3, k4, x, xn, self._atol_w)
            ]
        )
        err = math.sqrt(sq / self._n_err)
        chk = sum(k2) + sum(k3) + sum(k4) + sum(xn) + err
        if chk - chk != 0.0 or len(xn) != len(x):
            return xn, k4, err, self._locate(len(x), (k2, k3, k4), xn)
        return xn, k4, err, 0

    @staticmethod
    def _locate(n: int, stages: tuple, xn: list[float]) -> int:
        for i, k in enumerate(stages):
            if len(k) != n or not _is_finite_sum(k):
                return i + 2
        return -1

    # --- driver -----------------------------------------------------------------------

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        f = self.model.rhs
        n_st = self._rhs_per_trial
        trial = self._trial
        stats = StepStats()
        k1 = self._first_stage(f, t, x, u, h, stats)
        if len(k1) != len(x) or not _is_finite_sum(k1):
            raise self._fail(
                "non-finite value (or wrong length) in stage 1 (rhs at the start point)",
                t, self._h_prop or h, t, h,
            )

        if self.fixed_substeps is not None:
            n_sub = self.fixed_substeps
            hs = h / n_sub
            y = x
            err = 0.0
            for i in range(n_sub):
                ti = t + i * hs
                try:
                    y_new, k1, err, bad = trial(f, ti, y, k1, hs, u)
                except (ArithmeticError, ValueError) as exc:
                    raise self._fail(f"rhs raised {exc!r}", ti, hs, t, h) from exc
                stats.rhs_calls += n_st
                if bad:
                    raise self._fail(_bad_text(bad), ti, hs, t, h)
                y = y_new
            stats.substeps = n_sub
            stats.error_estimate = err
            self._fsal = (t + h, tuple(y), u, tuple(k1))
            return y, stats

        hs = self._h_prop
        if hs is None:
            hs = self._starting_step(f, t, x, k1, u, h, stats)
        y, k_end, stats = self._adaptive_loop(trial, f, t, x, k1, u, h, hs, n_st, stats)
        self._fsal = (t + h, tuple(y), u, tuple(k_end))
        return y, stats

    def _adaptive_loop(
        self, trial: Callable, f: Callable, t: float, x: list[float], k1: list[float],
        u: tuple, h: float, hs: float, n_st: int, stats: StepStats,
    ) -> tuple[list[float], list[float], StepStats]:
        """Error-controlled internal steps from ``t`` to ``t + h`` starting with ``hs``;
        returns the state at ``t + h``, the rhs there (the FSAL stage) and the counters."""
        tau = 0.0  # elapsed time within this advance [s]
        y = x
        attempts = 0
        just_rejected = False
        max_sub = self.max_substeps
        h_min = self.h_min
        reason = ""
        landing = self._landing()  # kink landing
        while True:
            rem = h - tau
            # a step cut to end on a kink has exactly the cut size, never stretched to t + h
            last = not (landing and landing.cuts) and hs * 1.05 >= rem
            h_step = rem if last else hs
            attempts += 1
            if attempts > max_sub:
                raise self._fail(
                    f"more than max_substeps = {max_sub} internal steps (accepted + rejected)",
                    t + tau, h_step, t, h,
                )
            ti = t + tau
            try:
                y_new, k_new, err, bad = trial(f, ti, y, k1, h_step, u)
            except (ArithmeticError, ValueError) as exc:
                y_new, k_new, err, bad = None, None, _INF, 0
                reason = f"rhs raised {exc!r}"
                stats.rhs_calls += n_st  # upper bound: the failing call and those before it
            else:
                stats.rhs_calls += n_st
                if bad:
                    err = _INF
                    reason = _bad_text(bad)
                elif not err <= 1.0:
                    reason = f"error norm {err:.3g} > 1"
            h_cut = landing.cut(y, y_new, h_step, stats) if landing and not bad and y_new else None
            if h_cut is not None:  # it would cross a kink: ends on it instead (KinkLanding)
                hs = h_cut
                continue
            if err <= 1.0:
                stats.substeps += 1
                fac = self._factor(err)
                if just_rejected and fac > 1.0:
                    fac = 1.0
                h_new = h_step * fac
                if landing:
                    h_new = landing.accepted(h_new, fac)
                y = y_new
                k1 = k_new
                stats.error_estimate = err
                just_rejected = False
                if last:
                    # keep the untruncated proposal unless the controller asks to shrink
                    if h_new >= h_step:
                        h_new = max(h_new, hs)
                    self._h_prop = h_new
                    return y, k1, stats
                tau += h_step
                hs = h_new
            else:
                stats.rejected += 1
                just_rejected = True
                if landing:
                    landing.rejected()
                hs = h_step * self._factor(err)
                if hs < h_min:
                    raise self._fail(
                        f"step size {hs!r} s below h_min = {h_min!r} s after rejection ({reason})",
                        ti, h_step, t, h,
                    )
