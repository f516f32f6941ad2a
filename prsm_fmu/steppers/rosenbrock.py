"""Linearly implicit L-stable Rosenbrock-W method ROS34PW2 with error control, for stiff
models (coefficients in :mod:`.tableaux`, LU in :mod:`.linalg`)."""

from __future__ import annotations

import math
from operator import mul
from typing import Any, Callable, Sequence

from .base import (StepStats, _INF, _analytic_jacobian, _block_jacobian, _bad_text, _check_tol, _is_finite_sum,
                   _model_quadrature)
from .control import AdaptiveBase, slip_error
from .linalg import SMALL_LU, getter, lu_factor, lu_solve
from .tableaux import _ROS_E, _ROS_EQ, _ROS_M, _ROS_TRIAL, _ROS_WQ, ROS_GAMMA

__all__ = ["Rosenbrock"]


#: a continuing advance counts as quiet (fast modes at rest: no first-step bound) when its
#: motion changes at most this fraction of the fastest rate
QUIET = 0.01


class Rosenbrock(AdaptiveBase):
    """Linearly implicit L-stable Rosenbrock-W method ROS34PW2 with error control.

    For stiff models (contact stiffness, fast electrical or control dynamics): each
    step needs one Jacobian, one LU decomposition of ``I/(h gamma) - J`` and four rhs
    calls, with no Newton iteration.  ROS34PW2 (Rang & Angermann 2005) was chosen over
    ROS3P (not L-stable) and RODASP (6 stages, order 4): it is L-stable and stiffly
    accurate, so stiff components are damped to their quasi-static values even at
    steps far beyond the explicit stability limit; it is a W-method (order 3 is kept
    with an approximate Jacobian, see the tests with a deliberately wrong one), so a
    finite-difference Jacobian costs no accuracy; and order 3 suits the 1e-4 ... 1e-7
    tolerances of a 1 ms co-simulation step.

    Jacobian: ``model.jacobian`` if present and ``jacobian`` is ``"auto"`` or
    ``"analytic"``; otherwise forward differences with increment
    ``sqrt(eps) * max(|x_i|, state_scale_i)`` (one extra rhs call per column, counted
    both as one ``jacobian_calls`` and in ``rhs_calls``).  By default one Jacobian and
    one LU per internal step, re-used by all four stages; a rejected step is retried
    from the same point, so its Jacobian (and rhs value there) is re-used and only the
    LU is redone.  The LU is a dense plain-Python LU with partial pivoting, unrolled for
    up to 3 unknowns (meant for n <= ~12); a singular matrix raises :class:`StepFailure`.

    Jacobian reuse (``jacobian_reuse = delta > 0``, adaptive advances only): the W-method
    keeps its order with any Jacobian; what a stale one spoils is the damping of the
    stiff components, by about ``h ||J - J_old||``.  So the Jacobian of an earlier point
    of the same advance is re-used for a step of size ``h`` while
    ``h ||J_dd||_inf * drift <= delta``, with ``drift`` the largest relative change of a
    state ``d`` since that point (relative to ``max(|x_i|, state_scale_i)``, a proxy for
    the relative change of J); otherwise it is evaluated afresh, and also after a
    rejected step and after a step whose successor the controller shrinks (where the
    relative state change is no proxy, e.g. in a friction band at zero speed, a stale
    Jacobian otherwise traps the controller in ever smaller steps that never trigger the
    bound).  Each advance starts with a fresh one (the inputs may have changed).
    (Re-using it without such a bound was measured and rejected: at steps far beyond the
    fast time constants the damping suffers, and the error estimate, made with the same
    Jacobian, does not see it.)  On the PRSM benchmark (benchmarks/step_cost.py)
    ``delta = 0.1`` leaves the error unchanged and saves two of every five Jacobians;
    ``delta >= 0.5`` does not keep the error.

    Quadrature states: a model may declare ``quadrature_states``, the indices of states
    that no rhs component depends on (accumulated energies, an angle whose rate is a
    state).  Their Jacobian columns are zero, so the finite-difference Jacobian skips
    them (an analytic Jacobian's entries there are ignored), and ``I/(h gamma) - J`` is
    block lower triangular: only the block of the other states ``d`` is factorised, and
    the stages are solved for the states ``d`` alone.  The quadrature states enter the
    result and the error estimate through fixed weights of the stage values
    (:func:`_quadrature_weights`: ``b`` and ``b - b_hat`` of the untransformed method),
    ``x_q,new = x_q + h sum_i b_i (f_q(X_i) + J_qd sum_j Gamma_ij k_d,j)``, and the stage
    points ``X_i`` carry the step's start values in them (no rhs component depends on
    them).  The result is the same as without the declaration up to round-off; a wrong
    declaration makes the Jacobian and the stage points inexact, which the W-method
    tolerates in order but not in stiff damping.

    Time dependence: the inputs are held over the communication step, so the model is
    treated as autonomous within it; the stages are evaluated at their proper times
    ``t + alpha_i h`` but the ``h gamma_i df/dt`` term is omitted.  This is exact for
    models without explicit time dependence; otherwise it amounts to an inexact
    Jacobian of the autonomised system, which the W-method tolerates without loss of
    order.

    Error control, step landing and failures as in :class:`ExplicitAdaptive`
    (controller exponent 1/3 from the embedded order 2), the error norm at least the slip
    error norm of the estimate where the model reports its sliding velocities
    (:func:`.control.slip_error`: the friction forces follow the sliding velocity, which near
    pure rolling is a small difference of the screw's and the carriers' parts, so the states'
    norm alone let the forces miss the tolerance).  The error estimate is the raw
    embedded difference: filtering it through ``(I - h gamma J)^-1`` (as Radau5 does)
    was measured to underestimate the true local error of ROS34PW2 by 2-6x at steps far
    beyond the fast time constants, where ``R(z) ~ -2.6 / z`` decays slowly.

    First step and memory: each advance starts where the master may just have changed
    the inputs, which typically excites the fast modes.  Without memory the first step
    is the guess of Hairer, Norsett & Wanner (Solving ODEs I, Sec. II.4) with the
    second derivative ``J f`` from the Jacobian at hand, which is large exactly when a
    fast mode is out of equilibrium.  The memory (:meth:`get_memory`) is the controller's
    proposal after the *first* accepted step of the last advance (not after its last
    step, which after an input change is far too large for the next advance's start and
    costs a cascade of rejections); with smooth inputs it grows by up to ``fac_max``
    per advance.  ``first_step_stiffness = c > 0`` bounds each advance's first step to
    ``h ||J_dd||_inf <= c`` (and starts there without memory): after a small input change
    the memory may propose a step far beyond the fast time constants, whose error
    estimate then misses much of the transient's error (on the PRSM benchmark the
    errors at the end of such advances were 10x those of advances that started at
    ``h ||J|| ~ 5``, at the same cost).  The bound cuts the memory's proposal by at most
    ``fac_max`` (one controller step), so that a mode made extremely stiff by a friction
    band (nanoseconds at zero speed), whose transients are as short as they are small,
    does not force tiny first steps.  An advance that continues the last one (its end
    time, state and inputs: nothing changed) with the fast modes at rest (:meth:`_quiet`)
    starts instead with the proposal after the last advance's *last* step, unbounded: no
    input change, no transient.  (Keeping the last advance's Jacobian for it as well was
    tried and dropped: across many short advances the reuse bound, scaled by the step,
    never refreshed it, and a stale Jacobian fooled both the quiet test and the error
    estimate — 3x the error on the 1 µs start-up.)

    Parameters
    ----------
    model : OdeModel
        Model to integrate; needs ``state_scale`` [SI].
    rtol, atol, h_min, max_substeps, fixed_substeps :
        As in :class:`ExplicitAdaptive` (``h_min`` in seconds).
    jacobian : {"auto", "fd", "analytic"}, optional
        Jacobian source.
    jacobian_reuse : float, optional
        Bound ``delta >= 0`` on ``h ||J|| * drift`` for re-using a Jacobian within an
        advance [-]; 0 (default): a fresh Jacobian at every accepted point.
    first_step_stiffness : float, optional
        Bound ``c >= 0`` on ``h ||J||`` for the first internal step of each advance [-]
        (at most a factor ``fac_max`` below the memory's proposal); 0 (default): no bound.
    safety, fac_min, fac_max : float, optional
        Controller safety factor and limits of the step-size ratio.
    """

    name = "rosenbrock"
    method = "ROS34PW2"
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
        jacobian_reuse: float = 0.0,
        first_step_stiffness: float = 0.0,
        safety: float = 0.9,
        fac_min: float = 0.2,
        fac_max: float = 5.0,
    ) -> None:
        super().__init__(model, rtol, atol, h_min, max_substeps, fixed_substeps, safety, fac_min, fac_max)
        self.jacobian_reuse = _check_tol("jacobian_reuse", jacobian_reuse, strictly_positive=False)
        self.first_step_stiffness = _check_tol("first_step_stiffness", first_step_stiffness,
                                               strictly_positive=False)
        self._analytic = _analytic_jacobian(model, jacobian)
        self.jacobian = "analytic" if self._analytic else "fd"
        n = self.n_states
        self._quad = _model_quadrature(model, n)
        self._dyn = tuple(i for i in range(n) if i not in self._quad)
        # position of state i in the concatenation k_d + k_q
        pos = {i: p for p, i in enumerate(self._dyn + self._quad)}
        self._merge = tuple(pos[i] for i in range(n))
        self._small = SMALL_LU.get(len(self._dyn))
        # gather the parts d and q of a vector, and scatter k_d + k_q back, in one C call each
        self._get_d = getter(self._dyn) if self._dyn else (lambda v: ())
        self._get_q = getter(self._quad) if self._quad else (lambda v: ())
        self._get_merged = getter(self._merge) if self._quad else None
        self._solve_d = lu_solve if self._small is None else self._small[1]
        self._atol_d = [self._atol_w[i] for i in self._dyn]
        self._atol_q = [self._atol_w[i] for i in self._quad]
        self._cont: tuple | None = None

    # --- memory: the first-step proposal and the continuation -------------------------

    def get_memory(self) -> tuple:
        """Return ``(h_proposal, continuation)``: the first-step proposal [s] for an advance
        after an input change (None before the first adaptive advance), and ``(t_end, x_end,
        u, h_next)`` of the last advance (None if there is none): its end time [s], state and
        inputs and the step [s] proposed after its last step, which an advance that continues
        it (same start, state and inputs: nothing changed) starts with, without the
        first-step bound.  Plain floats in tuples."""
        return (self._h_prop, self._cont)

    def set_memory(self, m: tuple) -> None:
        """Restore ``(h_proposal, continuation)`` from :meth:`get_memory` (``(h_proposal,)``
        alone is accepted: no continuation); checked first, a refused memory changes
        nothing."""
        m = tuple(m)
        if len(m) not in (1, 2):
            raise ValueError(f"{self.name}: memory must be (h_proposal, continuation), got {m!r}")
        cont = m[1] if len(m) == 2 else None
        self._check_continuation(cont)
        super().set_memory(m[:1])
        self._cont = cont

    def reset(self) -> None:
        """Forget the step-size proposal and the continuation."""
        super().reset()
        self._cont = None

    # --- Jacobian and iteration matrix --------------------------------------------------

    def _jac(
        self, f: Callable, t: float, x: list[float], f0: list[float], u: tuple, stats: StepStats
    ) -> tuple:
        """Jacobian at (t, x) as ``(J_dd, J_qd)`` (:func:`.base._block_jacobian`)."""
        return _block_jacobian(self, f, t, x, f0, u, stats)

    def _quiet(self, x: Sequence[float], f0: Sequence[float], jac: tuple,
               jac_norm: float) -> bool:
        """Whether the fast modes are at rest at ``x``: the motion changes at a rate
        ``||J_dd f_d|| / ||f_d||`` (norms weighted by the error weights) at most ``QUIET``
        times the fastest rate ``||J_dd||_inf`` [1/s].  In a fast transient ``J f`` is the
        fast mode's λ f (ratio ~1); on the slow manifold it is a slow mode's."""
        rtol, atol = self.rtol, self._atol_w
        if not jac_norm:          # not computed (neither reuse nor a first-step bound)
            jac_norm = max([sum(map(abs, row)) for row in jac[0]], default=0.0)
        fd = [f0[i] for i in self._dyn]
        num = den = 0.0
        for k, (i, row) in enumerate(zip(self._dyn, jac[0])):
            w = atol[i] + rtol * abs(x[i])
            num = max(num, abs(sum(map(mul, row, fd))) / w)
            den = max(den, abs(fd[k]) / w)
        return num <= QUIET * jac_norm * den

    def _drift(self, y: Sequence[float], y_jac: Sequence[float]) -> float:
        """Largest relative change of a state ``d`` from ``y_jac`` to ``y`` (relative to
        ``max(|y_jac_i|, state_scale_i)``)."""
        scale = self.state_scale
        return max(
            [abs(y[i] - y_jac[i]) / max(abs(y_jac[i]), scale[i]) for i in self._dyn], default=0.0
        )

    def _fresh_jac(
        self, f: Callable, t: float, x: list[float], f0: list[float], u: tuple, stats: StepStats,
        hs: float, t0: float, h: float,
    ) -> tuple:
        """:meth:`_jac` and ``||J_dd||_inf`` [1/s] (largest row sum of magnitudes; 0 when
        neither ``jacobian_reuse`` nor ``first_step_stiffness`` needs it), raising
        :class:`StepFailure` for a non-finite entry."""
        jac = self._jac(f, t, x, f0, u, stats)
        if not _is_finite_sum([sum(row) for part in jac for row in part]):
            raise self._fail("non-finite value in the Jacobian", t, hs, t0, h)
        if not (self.jacobian_reuse or self.first_step_stiffness):
            return jac, 0.0
        return jac, max([sum(map(abs, row)) for row in jac[0]], default=0.0)

    def _lu(self, jac: tuple, hs: float) -> tuple | None:
        """Factors of ``I / (hs gamma) - J`` (``hs`` in s) for :meth:`_solve`, ``None``
        if singular.  With quadrature states the matrix is block lower triangular,
        ``[[I/(hs gamma) - J_dd, 0], [-J_qd, I/(hs gamma)]]``: only the ``d`` block is
        LU-factorised (unrolled for up to 3 unknowns); its factors solve for ``k_d`` from
        ``b_d`` (the right-hand side's part ``d``)."""
        jdd, jqd = jac
        hg = hs * ROS_GAMMA
        d = 1.0 / hg
        small = self._small
        if small is not None:
            lu = small[0](jdd, d, range(len(jdd)))
        else:
            a = [[-v for v in reversed(row)] for row in jdd]  # columns reversed, see lu_factor
            last = len(a) - 1
            for i, row in enumerate(a):
                row[last - i] += d
            lu = lu_factor(a)
        if lu is None:
            return None
        return lu, hg, jqd

    def _solve(self, fac: tuple, b: Sequence[float]) -> list[float]:
        """Solve ``(I / (hs gamma) - J) k = b`` with the factors from :meth:`_lu`:
        ``k_d`` by the LU, then ``k_q = hs gamma (b_q + J_qd k_d)`` by substitution."""
        lu, hg, jqd = fac
        kd = self._solve_d(lu, self._get_d(b))
        if not jqd:
            return kd
        kd += [hg * (v + sum(map(mul, row, kd))) for v, row in zip(self._get_q(b), jqd)]
        return list(self._get_merged(kd))

    # --- one trial step: (x_new, err, bad) --------------------------------------------

    def _trial(
        self, f: Callable, t: float, x: list[float], f0: list[float], fac: tuple, hs: float, u: tuple,
        v0: list | None = None,
    ) -> tuple:
        """One step of size ``hs`` from ``(t, x)`` with ``f0 = f(t, x)``; returns ``(x_new,
        err, bad)`` (``bad``: 0, or the first stage (2..4) with a non-finite value or the
        wrong length, -1 for a non-finite result).

        ``v0``: the model's sliding velocities at ``x`` [m/s] (None: none); then ``err`` is
        also at least the slip error norm of the estimate (:func:`.control.slip_error`).  The
        estimate's quadrature components enter no sliding velocity (no rhs component, so no
        friction force, depends on them): they are 0 in the vector mapped.

        The stages are solved for the states ``d`` only (vectors of their length); the
        quadrature states ``q`` enter the result and the error estimate through the weights
        of :func:`_quadrature_weights`, ``x_q,new = x_q + hs sum_i w_i (f_q(X_i) + J_qd u_d,i)``,
        which equals the full stage recursion.  Since no rhs component depends on them, the
        stage points carry their values at the step's start."""
        a21, a31, a32, a41, a42, a43, c21, c31, c32, c41, c42, c43, t2, t3, t4 = _ROS_TRIAL
        lu, _, jqd = fac
        ih = 1.0 / hs
        n = len(x)
        solve, dyn = self._solve_d, self._dyn
        xd = self._get_d(x)
        u1 = solve(lu, self._get_d(f0))
        xs = list(x)  # stage points: the states d change, the quadrature states q do not
        for i, p, q in zip(dyn, xd, u1):
            xs[i] = p + a21 * q
        f2 = f(t + t2 * hs, xs, u)
        if len(f2) != n:
            return None, _INF, 2
        d1 = c21 * ih
        u2 = solve(lu, [f2[i] + d1 * q for i, q in zip(dyn, u1)])
        xs = list(x)
        for i, p, q, r in zip(dyn, xd, u1, u2):
            xs[i] = p + a31 * q + a32 * r
        f3 = f(t + t3 * hs, xs, u)
        if len(f3) != n:
            return None, _INF, 3
        d1, d2 = c31 * ih, c32 * ih
        u3 = solve(lu, [f3[i] + d1 * q + d2 * r for i, q, r in zip(dyn, u1, u2)])
        xs = list(x)
        for i, p, q, r, v in zip(dyn, xd, u1, u2, u3):
            xs[i] = p + a41 * q + a42 * r + a43 * v
        f4 = f(t + t4 * hs, xs, u)
        if len(f4) != n:
            return None, _INF, 4
        d1, d2, d3 = c41 * ih, c42 * ih, c43 * ih
        u4 = solve(lu, [f4[i] + d1 * q + d2 * r + d3 * v for i, q, r, v in zip(dyn, u1, u2, u3)])
        m1, m2, m3, m4 = _ROS_M
        e1, e2, e3, e4 = _ROS_E
        w1, w2, w3, w4 = _ROS_WQ
        v1, v2, v3, v4 = _ROS_EQ
        rtol = self.rtol
        xn, uw, ue = [], [], []
        sq = 0.0
        ed = []
        for p, q, r, s, v, at in zip(xd, u1, u2, u3, u4, self._atol_d):
            pn = p + m1 * q + m2 * r + m3 * s + m4 * v
            e = e1 * q + e2 * r + e3 * s + e4 * v
            sq += (e / (at + rtol * max(abs(p), abs(pn)))) ** 2
            ed.append(e)
            xn.append(pn)
            uw.append(w1 * q + w2 * r + w3 * s + w4 * v)
            ue.append(v1 * q + v2 * r + v3 * s + v4 * v)
        if self._quad:
            get_q = self._get_q
            xnq = []
            for p, g1, g2, g3, g4, row, at in zip(get_q(x), get_q(f0), get_q(f2), get_q(f3), get_q(f4),
                                                  jqd, self._atol_q):
                pn = p + hs * (w1 * g1 + w2 * g2 + w3 * g3 + w4 * g4 + sum(map(mul, row, uw)))
                eq = hs * (v1 * g1 + v2 * g2 + v3 * g3 + v4 * g4 + sum(map(mul, row, ue)))
                sq += (eq / (at + rtol * max(abs(p), abs(pn)))) ** 2
                xnq.append(pn)
            xn = list(self._get_merged(xn + xnq))
        err = math.sqrt(sq / self._n_err)
        if v0 is not None:
            ef = [0.0] * n
            for i, e in zip(dyn, ed):
                ef[i] = e
            slip = slip_error(self._speeds(ef), v0, rtol, self.atol, self._band)
            if slip > err:
                err = slip
        # every stage enters the result with non-zero weights (m_i, and w_i for the states q),
        # so a non-finite value in any stage makes the result non-finite
        chk = sum(xn) + err
        if chk - chk != 0.0:
            for i, k in enumerate((f2, f3, f4)):
                if not _is_finite_sum(k):
                    return xn, err, i + 2
            return xn, err, -1
        return xn, err, 0

    # --- driver -----------------------------------------------------------------------

    def _initial_step_stiff(
        self, x: Sequence[float], f0: Sequence[float], jac: tuple, h: float
    ) -> float:
        """First-step guess [s] without extra rhs calls: Hairer, Norsett & Wanner, Solving
        ODEs I, Sec. II.4, with the second derivative ``x'' = J f`` taken from the
        Jacobian already at hand (instead of a difference quotient).  ``J f`` is large
        where a fast mode is out of equilibrium (a stiff transient, e.g. after an input
        change), so the guess starts such a transient with a step of its time scale."""
        h0 = self._initial_step(x, f0, h)
        jdd, jqd = jac
        fd = [f0[i] for i in self._dyn]
        jf = [sum(map(mul, row, fd)) for row in jdd]
        jf += [sum(map(mul, row, fd)) for row in jqd]
        jf = [jf[j] for j in self._merge]
        rtol = self.rtol
        w = [at + rtol * abs(a) for a, at in zip(x, self._atol_w)]
        d1 = math.sqrt(sum([(a / wi) ** 2 for a, wi in zip(f0, w)]) / self._n_err)
        d2 = math.sqrt(sum([(a / wi) ** 2 for a, wi in zip(jf, w)]) / self._n_err)
        dm = max(d1, d2)
        if not dm > 1e-15:  # at rest (or nan, handled by the step itself)
            return h0
        return min(h0, (0.01 / dm) ** (1.0 / self._q1))

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        f = self.model.rhs
        stats = StepStats()
        fixed = self.fixed_substeps
        h_cont = None
        if fixed is not None:
            hs = h / fixed
        else:
            # an advance that continues the last one (nothing changed) starts with the step
            # its last step proposed: no input change, so no transient to bound the first
            # step for
            h_cont = self._continues(t, x, u, h)
            hs = self._h_prop if h_cont is None else h_cont
        tau = 0.0
        y = x
        attempts = 0
        just_rejected = False
        f0 = jac = None  # rhs value at the current accepted point, Jacobian in use
        jac_norm = 0.0  # ||J_dd||_inf [1/s]
        y_jac = None  # the state at which the Jacobian was evaluated
        h_mem = None  # proposal for the first step of the next advance
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
            if f0 is None:
                try:
                    f0 = f(ti, y, u)
                    stats.rhs_calls += 1
                    if len(f0) != self.n_states or not _is_finite_sum(f0):
                        raise self._fail(
                            "non-finite value (or wrong length) in stage 1 (rhs at an accepted point)",
                            ti, hs or h, t, h,
                        )
                    if jac is None:
                        jac, jac_norm = self._fresh_jac(f, ti, y, f0, u, stats, hs or h, t, h)
                        y_jac = y
                except (ArithmeticError, ValueError) as exc:
                    raise self._fail(f"rhs or jacobian raised {exc!r}", ti, hs or h, t, h) from exc
                if h_cont is not None and tau == 0.0 and not self._quiet(y, f0, jac, jac_norm):
                    # continuing a fast transient: the first-step bound, as after an input
                    # change (the Jacobian is fresh: taken at this point above)
                    h_cont = None
                    hs = self._h_prop
                if fixed is None and tau == 0.0 and h_cont is None:
                    # first step of the advance, right after the master may have changed
                    # the inputs: at most the bound on h ||J||, if one is set
                    limit = self.first_step_stiffness
                    if limit and jac_norm and hs is None:
                        hs = limit / jac_norm
                    elif limit and jac_norm and hs * jac_norm > limit:
                        hs = max(limit / jac_norm, hs / self.fac_max)
                    elif hs is None:
                        hs = self._initial_step_stiff(y, f0, jac, h)
            if fixed is None:
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
            if y_jac is not y and (
                just_rejected or h_step * jac_norm * self._drift(y, y_jac) > self.jacobian_reuse
            ):
                # the Jacobian of an earlier point of this advance is too stale for this
                # step (or a step with it was just rejected): evaluate it here
                try:
                    jac, jac_norm = self._fresh_jac(f, ti, y, f0, u, stats, h_step, t, h)
                except (ArithmeticError, ValueError) as exc:
                    raise self._fail(f"rhs or jacobian raised {exc!r}", ti, h_step, t, h) from exc
                y_jac = y
            fac_lu = self._lu(jac, h_step)
            stats.lu_decompositions += 1
            if fac_lu is None:
                raise self._fail("singular iteration matrix I/(h gamma) - J", ti, h_step, t, h)
            try:
                y_new, err, bad = self._trial(f, ti, y, f0, fac_lu, h_step, u,
                                              landing.start(y) if landing else None)
            except (ArithmeticError, ValueError) as exc:
                if fixed is not None:
                    raise self._fail(f"rhs raised {exc!r}", ti, h_step, t, h) from exc
                y_new, err, bad = None, _INF, 0
                reason = f"rhs raised {exc!r}"
                stats.rhs_calls += 3  # upper bound
            else:
                stats.rhs_calls += 3
                if bad:
                    if fixed is not None:
                        raise self._fail(_bad_text(bad), ti, h_step, t, h)
                    err = _INF
                    reason = _bad_text(bad)
                elif not err <= 1.0:
                    reason = f"error norm {err:.3g} > 1"
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
                if h_mem is None:
                    # the next advance starts, like this one, right after the master may
                    # have changed the inputs: propose what this advance's first step
                    # proposed (for a first step shortened to land on t + h, the
                    # untruncated size unless the controller asks to shrink)
                    h_mem = max(h_new, hs) if last and h_new >= h_step else h_new
                y = y_new
                f0 = None
                if not self.jacobian_reuse or fac < 1.0:
                    jac = None  # a fresh one at the next point (see the class docstring)
                just_rejected = False
                if last:
                    self._h_prop = h_mem
                    h_next = max(h_new, hs) if h_new >= h_step else h_new
                    self._cont = self._continuation(t + h, y, u, h_next)
                    return y, stats
                tau += h_step
                hs = h_new
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
