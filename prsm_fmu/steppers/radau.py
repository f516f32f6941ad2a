"""Reference stepper: scipy's Radau IIA (order 5), restarted on every advance and on every
landing on a friction law's kink."""

from __future__ import annotations

from typing import Any

from .base import Stepper, StepStats, _check_count, _check_tol, _is_finite_sum, _model_scale
from .control import KinkLanding, model_kinks

__all__ = ["ScipyRadau"]

#: smallest internal step [s] a landing cuts to (the adaptive steppers' default ``h_min``)
_H_MIN = 1e-14

#: the smallest rtol at which radau lands on the kinks; below it (the references at rtol 1e-11
#: and 1e-12) it steps as ``solve_ivp(method="Radau")``: there its own steps are far shorter
#: than the friction band, and on the speed reversal one landing at rtol 1e-12 (an approach cut
#: at 31.2 ms) moved the stage-2 spline friction at 31.3 ms by 2.9e-11 of its maximum from
#: ROS34PW2 at rtol 1e-12, where the unlanded run is within 1.4e-13 (docs/accuracy.md,
#: "Landing on the friction law's kinks")
LANDING_MIN_RTOL = 1e-10


class _WorkLimit(Exception):
    """Raised inside scipy's Radau to end an advance that exceeds its rhs-call budget."""


class ScipyRadau(Stepper):
    """Reference stepper: scipy's ``Radau`` (the method of ``solve_ivp(method="Radau")``).

    Radau IIA of order 5 (implicit, L-stable), restarted on every advance, so it has no
    memory.  Slow (numpy and solver set-up per call); meant for validating the other
    steppers, not for the 1 ms hot path.  Uses ``model.jacobian`` if present, else
    scipy's own finite differences.

    Kink landing: if the model reports its sliding velocities and kink speeds (the adaptive
    steppers' :class:`~prsm_fmu.steppers.control.KinkLanding`, docs/accuracy.md, "Landing on
    the friction law's kinks"), every accepted internal step is checked by the same secant; a
    step that crosses a kink (or changes a sliding speed faster than the law resolves) is
    retried from its start by a fresh solver (its own first step) whose end is the cut point,
    and the advance goes on from there with a fresh solver at the size the cut shortened.  At
    ``rtol`` below :data:`LANDING_MIN_RTOL` (the references) there is no landing.  The states are the
    solver's step ends (order 5), never its dense output.  Without sliding velocities the
    steps are those of ``solve_ivp(method="Radau")``.

    ``StepStats`` reports the counted rhs calls (including those of scipy's finite
    differences), the Jacobian evaluations and LU decompositions of all solvers, the accepted
    steps and, as rejected, the kink cuts (scipy's own rejections and error estimate are not
    available).

    Parameters
    ----------
    model : OdeModel
        Model to integrate; needs ``state_scale`` [SI].
    rtol : float, optional
        Relative tolerance.
    atol : float, optional
        Absolute tolerance relative to ``state_scale``; per state ``atol * state_scale[i]``.
    max_rhs_calls : int or None, optional
        Most rhs calls of one advance (scipy's Radau has no step limit of its own, so this
        bounds the work of an advance); an advance that needs more fails
        (:class:`StepFailure`).  None: no limit.
    max_substeps : int, optional
        Most internal steps of one advance, accepted steps and kink cuts together (each cut
        restarts the solver); an advance that needs more fails (:class:`StepFailure`).
    """

    name = "radau"

    def __init__(self, model: Any, rtol: float = 1e-6, atol: float = 1e-9,
                 max_rhs_calls: int | None = None, max_substeps: int = 100000) -> None:
        super().__init__(model)
        self.max_rhs_calls = (None if max_rhs_calls is None
                              else _check_count("max_rhs_calls", max_rhs_calls, 1))
        self.max_substeps = _check_count("max_substeps", max_substeps, 1)
        self.rtol = _check_tol("rtol", rtol, strictly_positive=True)
        self.atol = _check_tol("atol", atol, strictly_positive=True)
        self.state_scale = _model_scale(model, self.n_states)
        self._atol_vec = [self.atol * s for s in self.state_scale]
        self._has_jac = callable(getattr(model, "jacobian", None))
        self._speeds, self._kinks, self._band = model_kinks(model)
        if self.rtol < LANDING_MIN_RTOL:
            self._speeds = None
        import numpy as np  # only the reference path needs numpy/scipy
        from scipy.integrate import Radau

        self._np = np
        self._radau = Radau

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        np = self._np
        model = self.model
        calls = [0]
        limit = self.max_rhs_calls

        def fun(tt, yy):
            calls[0] += 1
            if limit is not None and calls[0] > limit:
                raise _WorkLimit(f"more than max_rhs_calls = {limit} rhs calls")
            return model.rhs(float(tt), yy.tolist(), u)

        jac = None
        if self._has_jac:

            def jac(tt, yy):
                return np.asarray(model.jacobian(float(tt), yy.tolist(), u), dtype=float)

        try:
            f0 = model.rhs(t, list(x), u)
        except (ArithmeticError, ValueError) as exc:
            raise self._fail(f"rhs raised {exc!r} at the start point", t, h, t, h) from exc
        if len(f0) != self.n_states or not _is_finite_sum(f0):
            raise self._fail(
                "non-finite value (or wrong length) in the rhs at the start point", t, h, t, h
            )
        stats = StepStats()
        try:
            y = self._steps(fun, jac, t, np.array(x, dtype=float), t + h, h, stats)
        except _WorkLimit as exc:
            raise self._fail(str(exc), t, h, t, h) from None
        except (ArithmeticError, ValueError) as exc:
            raise self._fail(f"Radau raised {exc!r}", t, h, t, h) from exc
        y = y.tolist()
        if not _is_finite_sum(y):
            raise self._fail("non-finite value in the result", t + h, h, t, h)
        stats.rhs_calls = calls[0] + 1
        return y, stats

    def _solver(self, fun: Any, jac: Any, t0: float, y0: Any, t_end: float,
                first: float | None) -> Any:
        """A fresh scipy Radau from ``(t0, y0)`` to ``t_end`` [s], first step ``first`` [s]
        (None: scipy's own choice)."""
        if first is not None:
            first = min(first, t_end - t0)
        return self._radau(fun, t0, y0, t_end, rtol=self.rtol, atol=self._np.array(self._atol_vec),
                           jac=jac, first_step=first)

    def _steps(self, fun: Any, jac: Any, t: float, y: Any, t_end: float, h: float,
               stats: StepStats) -> Any:
        """Step from ``(t, y)`` to ``t_end`` [s], landing on the kinks (class docstring);
        fills ``stats`` but its rhs calls; returns the end state."""
        speeds = self._speeds
        landing = (None if speeds is None else
                   KinkLanding(lambda yy: speeds(yy.tolist()), self._kinks, self._band, _H_MIN))
        solver = self._solver(fun, jac, t, y, t_end, None)
        done = []  # solvers already replaced: their Jacobians and LU decompositions

        def fail(what: str, hs: float) -> Exception:
            return self._fail(what, t, hs, t_end - h, h)

        while True:
            if stats.substeps + stats.rejected >= self.max_substeps:
                raise fail(f"more than max_substeps = {self.max_substeps} internal steps "
                           "(accepted + kink cuts)", solver.h_abs)
            message = solver.step()
            if solver.status == "failed":
                raise fail(f"Radau failed: {message}", solver.h_abs)
            t_new, y_new = solver.t, solver.y
            h_step = t_new - t
            h_cut = landing.cut(y, y_new, h_step, stats) if landing is not None else None
            if h_cut is not None:  # it would cross a kink: retried from t to end on it instead
                done.append(solver)
                solver = self._solver(fun, jac, t, y, t + h_cut, None)
                continue
            stats.substeps += 1
            t, y = t_new, y_new
            if solver.status == "finished":
                if t == t_end:
                    break
                # landed on a kink: on to t_end at the size the cut shortened
                h_next = landing.accepted(solver.h_abs, solver.h_abs / h_step)
                done.append(solver)
                solver = self._solver(fun, jac, t, y, t_end, h_next)
            elif landing is not None:
                landing.accepted(solver.h_abs, solver.h_abs / h_step)
        done.append(solver)
        stats.jacobian_calls = sum(int(s.njev) for s in done)
        stats.lu_decompositions = sum(int(s.nlu) for s in done)
        return y
