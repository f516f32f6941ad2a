"""Exponential Rosenbrock method exprb32 with error control, for stiff models whose stiffness sits
in a small block of states (φ-functions of that block in :mod:`.phi`)."""

from __future__ import annotations

import math
from operator import mul
from typing import Any, Callable, Sequence

from .base import StepStats, _INF, _analytic_jacobian, _block_jacobian, _bad_text, _is_finite_sum, _model_quadrature
from .control import AdaptiveBase, _finite_floats
from .linalg import getter
from .phi import prepare

__all__ = ["ExponentialRosenbrock"]


class ExponentialRosenbrock(AdaptiveBase):
    """Exponential Rosenbrock method exprb32 (order 3, embedded order 2) with error control.

    Hochbruck, Ostermann & Schweitzer, SIAM J. Numer. Anal. 47 (2009) 786, Sec. 5: with
    ``J = f'(x_n)`` and ``g(x) = f(x) - f(x_n) - J (x - x_n)`` (the model is autonomous within
    an advance: inputs held),

    ``U = x_n + h φ_1(hJ) f(x_n)``   (exponential Rosenbrock–Euler, order 2),
    ``x_{n+1} = U + 2h φ_3(hJ) (g(U) - g(x_n))``   (order 3; ``g(x_n) = 0``),

    and the difference ``2h φ_3(hJ) g(U)`` is the error estimate (controller exponent 1/3).
    The linear part is integrated exactly: a stiff linear system is solved exactly at any step
    size, and the carriers' fast relaxation of a PRSM model (time constants ~10 µs, far below a
    1 ms communication step) costs no step-size reduction; steps are limited by the
    non-linearity only.  Each internal step costs one rhs at its start, the Jacobian, and one
    rhs at ``U``; a rejected step costs one rhs (the retry re-uses both).

    Jacobian reuse (``jacobian_drift > 0``): a Jacobian is kept for later points while fewer
    than ``jacobian_age`` steps were accepted with it and every state ``d`` and input is within
    ``jacobian_drift`` (relative) of where it was taken; a step rejected with a kept Jacobian
    is retried at the same size with a fresh one.  With ``A != f'(x_n)`` the scheme is an
    exponential W-type step and exprb32's order drops, but the error control still holds:
    ``g(U) = f(U) - f(x_n) - A (U - x_n)`` then contains ``(J - A)(U - x_n) = h (J - A)
    f(x_n) + O(h^2)``; ``U`` misses the exact flow's ``h^2/2 (J - A) f`` and the correction
    ``2h φ_3 g(U)`` adds ``h^2/3 (J - A) f`` of it (``φ_3(0) = 1/6``), so the result keeps
    ``h^2/6 (J - A) f`` while the estimate (the correction itself) reports ``h^2/3 (J - A) f``:
    twice the error the staleness causes (tests/test_exponential.py: problems with known
    solutions stepped with one Jacobian for the whole run meet their tolerance).  The
    default ``jacobian_drift = 0`` takes a fresh Jacobian at every accepted point: measured
    on benchmarks/step_cost.py at rtol 1e-7, a drift of 0.05 raised the error from 8.7e-9 to
    7.3e-8 (the result's error then reaches the estimate's level instead of staying ~10x
    below it) and the stop-and-go scenario's cost from 31 to 40 rhs per 1 ms step, and a
    drift of 1e-3 saved 0.3 rhs per step (the speeds move more than that within a substep).

    Block structure: the states that no rhs component depends on (``quadrature_states``: the
    screw angle and the work integrals) have zero Jacobian columns, so with the other states
    ``d`` (the speeds) ``J = [[A, 0], [B, 0]]`` (rows ``d``, ``q``) and
    ``φ_k(hJ) = [[φ_k(hA), 0], [h B φ_{k+1}(hA), I/k!]]``: only the small block ``A`` (1 + one
    per carrier states) needs φ-functions (:mod:`.phi`, plain Python floats), the
    quadrature states follow from ``φ_2`` and ``φ_4`` of it, and the finite-difference Jacobian
    costs one rhs per state ``d`` (increment ``sqrt(eps) max(|x_i|, state_scale_i)``).  With
    ``jacobian = "analytic"`` (or ``"auto"`` and a model with ``jacobian``) the model's own is
    used.  As in :class:`Rosenbrock`, an exact treatment holds up to round-off only if the
    declaration of ``quadrature_states`` is right.

    Memory (:meth:`get_memory`): the controller's proposal after the first accepted step of
    the last advance (for an advance after an input change, as :class:`Rosenbrock`), and, for
    the next advance that starts where the last one ended with the same state and inputs (a
    continued integration, e.g. constant inputs), the proposal after its last step together
    with that end point: such an advance continues with the step size the controller had
    reached instead of starting over; and the kept Jacobian with the point it was taken at
    (all plain floats, checked by :meth:`set_memory`), so a restored memory repeats the run.  Without memory the first internal step tries the whole
    communication step (a rejection costs one rhs).

    Error control, step landing and failures as in :class:`ExplicitAdaptive`; non-finite
    values or an overflow of ``e^{hλ}`` in a trial step reject it.

    Parameters
    ----------
    model : OdeModel
        Model to integrate; needs ``state_scale`` [SI].
    rtol, atol, h_min, max_substeps, fixed_substeps :
        As in :class:`ExplicitAdaptive` (``h_min`` in seconds).
    jacobian : {"auto", "fd", "analytic"}, optional
        Jacobian source.
    safety, fac_min, fac_max : float, optional
        Controller safety factor and limits of the step-size ratio.
    jacobian_age : int, optional
        Accepted steps after which a kept Jacobian is replaced (with ``jacobian_drift > 0``).
    jacobian_drift : float, optional
        Relative change of the states ``d`` and inputs up to which a Jacobian is kept [-];
        0 (default): a fresh one at every accepted point.
    """

    name = "exponential"
    method = "exprb32"
    _q1 = 3.0

    def __init__(
        self,
        model: Any,
        rtol: float = 1e-6,
        atol: float = 1e-9,
        h_min: float = 1e-14,
        max_substeps: int = 100000,
        fixed_substeps: int | None = None,
        jacobian: str = "auto",
        *,
        safety: float = 0.9,
        fac_min: float = 0.2,
        fac_max: float = 5.0,
        jacobian_age: int = 20,
        jacobian_drift: float = 0.0,
    ) -> None:
        super().__init__(model, rtol, atol, h_min, max_substeps, fixed_substeps, safety, fac_min, fac_max)
        if isinstance(jacobian_age, bool) or not isinstance(jacobian_age, int) or jacobian_age < 1:
            raise ValueError(f"jacobian_age = {jacobian_age!r} is out of range: must be an "
                             "integer >= 1 (accepted steps)")
        if not (0.0 <= jacobian_drift < _INF):
            raise ValueError(f"jacobian_drift = {jacobian_drift!r} is out of range: must be a "
                             "finite number >= 0 (relative change)")
        self.jacobian_age = jacobian_age
        self.jacobian_drift = float(jacobian_drift)
        self._analytic = _analytic_jacobian(model, jacobian)
        self.jacobian = "analytic" if self._analytic else "fd"
        n = self.n_states
        self._quad = _model_quadrature(model, n)
        self._dyn = tuple(i for i in range(n) if i not in self._quad)
        if not self._dyn:
            raise ValueError("model.quadrature_states lists every state: no state left to integrate")
        pos = {i: p for p, i in enumerate(self._dyn + self._quad)}
        self._merge = getter(tuple(pos[i] for i in range(n)))
        self._get_d = getter(self._dyn)
        self._get_q = getter(self._quad) if self._quad else (lambda v: ())
        self._cont: tuple | None = None
        #: the kept Jacobian: (x_J, u_J, age, A flat, B flat) in plain floats, or None
        self._jrec: tuple | None = None
        self._jac_kept: tuple | None = None      # (A, B) as rows, built from _jrec
        self._phi_cache: tuple = (None, 0.0, None)

    # --- memory ---------------------------------------------------------------------------

    def get_memory(self) -> tuple:
        """Return ``(h_proposal, continuation, jacobian)``: the first-step proposal [s] for an
        advance after an input change (None before the first adaptive advance); ``(t_end,
        x_end, u, h_next)`` of the last advance (None if there is none): its end time [s],
        state and inputs, and the proposal [s] after its last step, used by an advance that
        continues it; and the kept Jacobian ``(x_J, u_J, age, A, B)`` (None if there is none):
        the state and inputs it was taken at, the accepted steps [-] made with it, and its
        blocks ``A`` (rows and columns ``d``) and ``B`` (rows ``q``, columns ``d``) flattened
        row by row.  All plain floats in tuples."""
        return (self._h_prop, self._cont, self._jrec)

    def set_memory(self, m: tuple) -> None:
        """Restore ``(h_proposal, continuation, jacobian)`` from :meth:`get_memory` (checked
        first: a refused memory changes nothing)."""
        m = tuple(m)
        if len(m) != 3:
            raise ValueError(f"{self.name}: memory must be (h_proposal, continuation, "
                             f"jacobian), got {m!r}")
        cont, jrec = m[1], m[2]
        floats = _finite_floats
        n = self.n_states
        self._check_continuation(cont)
        nd, nq = len(self._dyn), len(self._quad)
        if jrec is not None:
            ok = isinstance(jrec, tuple) and len(jrec) == 5
            if ok:
                xj, uj, age, a, b = jrec
                ok = (floats(xj, n) and floats(uj, None) and isinstance(age, float)
                      and age >= 0.0 and age == int(age)
                      and floats(a, nd * nd) and floats(b, nd * nq))
            if not ok:
                raise ValueError(f"{self.name}: memory's jacobian must be None or (x_J, u_J, "
                                 f"age, A, B) with {n} finite states, finite inputs, a whole "
                                 f"age >= 0 and {nd * nd} + {nd * nq} finite entries, got "
                                 f"{jrec!r}")
        super().set_memory(m[:1])
        self._cont = cont
        self._set_jrec(jrec)

    def _set_jrec(self, jrec: tuple | None) -> None:
        self._jrec = jrec
        if jrec is None:
            self._jac_kept = None
            return
        nd = len(self._dyn)
        a, b = jrec[3], jrec[4]
        self._jac_kept = ([list(a[i * nd:(i + 1) * nd]) for i in range(nd)],
                          [list(b[i * nd:(i + 1) * nd]) for i in range(len(self._quad))])

    def reset(self) -> None:
        """Forget the step-size proposals and the kept Jacobian."""
        super().reset()
        self._cont = None
        self._set_jrec(None)

    def _fresh_enough(self, x: Sequence[float], u: tuple, age: int, xj: Sequence[float],
                      uj: tuple) -> bool:
        """Whether a Jacobian taken at ``(xj, uj)`` and used for ``age`` accepted steps may
        serve at ``(x, u)``: fewer than ``jacobian_age`` steps, and every state ``d`` and
        every input within ``jacobian_drift`` of it, relative to ``max(|value|, state_scale)``
        (inputs: ``max(|u|, |u_J|)``)."""
        if age >= self.jacobian_age or len(u) != len(uj):
            return False
        tol = self.jacobian_drift
        scale = self.state_scale
        for i in self._dyn:
            a, b = x[i], xj[i]
            if abs(a - b) > tol * max(abs(b), scale[i]):
                return False
        for a, b in zip(u, uj):
            if abs(a - b) > tol * max(abs(a), abs(b)):
                return False
        return True

    # --- Jacobian ---------------------------------------------------------------------------

    def _jac(self, f: Callable, t: float, x: list[float], f0: list[float], u: tuple,
             stats: StepStats) -> tuple:
        """``(A, B)``: the Jacobian's rows ``d`` and ``q`` restricted to the columns ``d`` (the
        columns ``q`` are zero; :func:`.base._block_jacobian`)."""
        return _block_jacobian(self, f, t, x, f0, u, stats)

    # --- one trial step ---------------------------------------------------------------------

    def _trial(self, f: Callable, t: float, x: list[float], f0: list[float], jac: tuple,
               hs: float, u: tuple) -> tuple:
        """One exprb32 step of size ``hs``: ``(x_new, err, bad)`` (``bad``: 0, 2 for a
        non-finite or wrong-length rhs at ``U``, -1 for a non-finite result)."""
        a, b = jac
        n = self.n_states
        get_d, get_q = self._get_d, self._get_q
        try:
            c = self._phi_cache
            if c[0] is a and c[1] == hs:
                ph = c[2]
            else:
                ph = prepare([[hs * v for v in row] for row in a])
                self._phi_cache = (a, hs, ph)
            xd, fd = get_d(x), get_d(f0)
            p1, p2 = ph.apply(fd, (1, 2))
        except (OverflowError, ZeroDivisionError):
            return None, _INF, -1
        ud = [p + hs * q for p, q in zip(xd, p1)]
        dd = [hs * q for q in p1]                   # U_d - x_d
        xq, fq = get_q(x), get_q(f0)
        h2 = hs * hs
        uq = [p + hs * g + h2 * sum(map(mul, row, p2)) for p, g, row in zip(xq, fq, b)]
        xu = list(self._merge(ud + uq))
        fu = f(t + hs, xu, u)
        if len(fu) != n or not _is_finite_sum(fu):
            return None, _INF, 2
        # D = g(U) = f(U) - f(x) - J (U - x)
        ddv = [p - q - sum(map(mul, row, dd)) for p, q, row in zip(get_d(fu), fd, a)]
        dq = [p - q - sum(map(mul, row, dd)) for p, q, row in zip(get_q(fu), fq, b)]
        try:
            p3, p4 = ph.apply(ddv, (3, 4))
        except (OverflowError, ZeroDivisionError):
            return None, _INF, -1
        h2s = 2.0 * hs
        ed = [h2s * v for v in p3]
        eq = [h2s * (v / 6.0 + hs * sum(map(mul, row, p4))) for v, row in zip(dq, b)]
        e = self._merge(ed + eq)
        rtol = self.rtol
        sq = 0.0
        xn = []
        for p, uu, ei, at in zip(x, xu, e, self._atol_w):
            pn = uu + ei
            sq += (ei / (at + rtol * max(abs(p), abs(pn)))) ** 2
            xn.append(pn)
        err = math.sqrt(sq / self._n_err)
        chk = sum(xn) + err
        if chk - chk != 0.0:
            return xn, err, -1
        return xn, err, 0

    # --- driver -----------------------------------------------------------------------------

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        f = self.model.rhs
        stats = StepStats()
        fixed = self.fixed_substeps
        if fixed is not None:
            hs = h / fixed
        else:
            hs = self._continues(t, x, u, h)
            if hs is None:
                hs = self._h_prop if self._h_prop is not None else h
        u = tuple(u)
        tau = 0.0
        y = x
        attempts = 0
        just_rejected = False
        f0 = None
        # the Jacobian in use, where it was taken and the accepted steps made with it; with
        # fixed substeps (no error control) a fresh one at every point
        jac = None
        rec = self._jrec
        if fixed is None and rec is not None:
            jac, xj, uj, age = self._jac_kept, rec[0], rec[1], int(rec[2])
        fresh = False
        h_mem = None
        reason = ""
        i_fixed = 0
        landing = None if fixed is not None else self._landing()  # kink landing
        while True:
            if fixed is not None:
                ti = t + i_fixed * hs
                h_step = hs
                last = i_fixed == fixed - 1
            else:
                ti = t + tau
                rem = h - tau
                # a step cut to end on a kink has exactly the cut size, never stretched to t + h
                last = not (landing and landing.cuts) and hs * 1.05 >= rem
                h_step = rem if last else hs
                attempts += 1
                if attempts > self.max_substeps:
                    raise self._fail(
                        f"more than max_substeps = {self.max_substeps} internal steps (accepted + rejected)",
                        ti, h_step, t, h,
                    )
            try:
                if f0 is None:
                    f0 = f(ti, y, u)
                    stats.rhs_calls += 1
                    if len(f0) != self.n_states or not _is_finite_sum(f0):
                        raise self._fail(
                            "non-finite value (or wrong length) in the rhs at an accepted point",
                            ti, h_step, t, h,
                        )
                if jac is None or not (fresh or self._fresh_enough(y, u, age, xj, uj)):
                    jac = self._jac(f, ti, y, f0, u, stats)
                    xj, uj, age, fresh = tuple(y), u, 0, True
                    if not _is_finite_sum([sum(row) for part in jac for row in part]):
                        raise self._fail("non-finite value in the Jacobian", ti, h_step, t, h)
            except (ArithmeticError, ValueError) as exc:
                raise self._fail(f"rhs or jacobian raised {exc!r}", ti, h_step, t, h) from exc
            try:
                y_new, err, bad = self._trial(f, ti, y, f0, jac, h_step, u)
            except (ArithmeticError, ValueError) as exc:
                if fixed is not None:
                    raise self._fail(f"rhs raised {exc!r}", ti, h_step, t, h) from exc
                y_new, err, bad = None, _INF, 0
                reason = f"rhs raised {exc!r}"
            else:
                if bad:
                    if fixed is not None:
                        raise self._fail(_bad_text(bad) if bad > 0 else
                                         "non-finite value (or overflow) in the result",
                                         ti, h_step, t, h)
                    err = _INF
                    reason = _bad_text(bad)
                elif not err <= 1.0:
                    reason = f"error norm {err:.3g} > 1"
            stats.rhs_calls += 1
            if fixed is not None:
                stats.substeps += 1
                stats.error_estimate = err
                y = y_new
                f0 = jac = None
                if last:
                    return y, stats
                i_fixed += 1
                continue
            h_cut = landing.cut(y, y_new, h_step, stats) if landing and not bad and y_new else None
            if h_cut is not None:  # it would cross a kink: ends on it instead (KinkLanding)
                hs = h_cut
                continue
            if err <= 1.0:
                stats.substeps += 1
                stats.error_estimate = err
                fac = self._factor(err)
                if just_rejected and fac > 1.0:
                    fac = 1.0
                h_new = h_step * fac
                if landing:
                    h_new = landing.accepted(h_new, fac)
                # for a step shortened to land on t + h, the untruncated size unless the
                # controller asks to shrink
                h_next = max(h_new, hs) if last and h_new >= h_step else h_new
                if h_mem is None:
                    h_mem = h_next
                y = y_new
                f0 = None
                age += 1
                fresh = False
                just_rejected = False
                if last:
                    self._h_prop = h_mem
                    self._cont = self._continuation(t + h, y, u, h_next)
                    if rec is None or jac is not self._jac_kept:
                        a, b = jac
                        rec = (xj, tuple(float(v) for v in uj), 0.0,
                               tuple([v for row in a for v in row]),
                               tuple([v for row in b for v in row]))
                        self._jac_kept = jac
                    self._jrec = rec[:2] + (float(age),) + rec[3:]
                    return y, stats
                tau += h_step
                hs = h_new
            elif not fresh:
                # rejected with a Jacobian taken elsewhere: retry the same step with a fresh
                # one (the estimate may have seen the Jacobian's error, not the step's)
                stats.rejected += 1
                jac = None
                hs = h_step
            else:
                stats.rejected += 1
                just_rejected = True
                if landing:
                    landing.rejected()
                hs = h_step * self._factor(err)
                if hs < self.h_min:
                    raise self._fail(
                        f"step size {hs!r} s below h_min = {self.h_min!r} s after rejection ({reason})",
                        ti, h_step, t, h,
                    )
