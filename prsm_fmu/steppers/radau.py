"""Reference stepper through :func:`scipy.integrate.solve_ivp` (Radau IIA, order 5)."""

from __future__ import annotations

from typing import Any

from .base import Stepper, StepStats, _check_count, _check_tol, _is_finite_sum, _model_scale

__all__ = ["ScipyRadau"]


class _WorkLimit(Exception):
    """Raised inside scipy's solve_ivp to end an advance that exceeds its rhs-call budget."""


class ScipyRadau(Stepper):
    """Reference stepper: :func:`scipy.integrate.solve_ivp` with ``method="Radau"``.

    Radau IIA of order 5 (implicit, L-stable), restarted on every advance, so it has no
    memory.  Slow (numpy and solver set-up per call); meant for validating the other
    steppers, not for the 1 ms hot path.  Uses ``model.jacobian`` if present, else
    scipy's own finite differences.  ``StepStats`` reports the counted rhs calls
    (including those of scipy's finite differences), scipy's ``njev`` and ``nlu``, the
    accepted steps; rejected steps and the error estimate are not available (0).

    Parameters
    ----------
    model : OdeModel
        Model to integrate; needs ``state_scale`` [SI].
    rtol : float, optional
        Relative tolerance.
    atol : float, optional
        Absolute tolerance relative to ``state_scale``; per state ``atol * state_scale[i]``.
    max_rhs_calls : int or None, optional
        Most rhs calls of one advance (scipy's ``solve_ivp`` has no step limit of its own, so
        this bounds the work of an advance); an advance that needs more fails
        (:class:`StepFailure`).  None: no limit.
    """

    name = "radau"

    def __init__(self, model: Any, rtol: float = 1e-6, atol: float = 1e-9,
                 max_rhs_calls: int | None = None) -> None:
        super().__init__(model)
        self.max_rhs_calls = (None if max_rhs_calls is None
                              else _check_count("max_rhs_calls", max_rhs_calls, 1))
        self.rtol = _check_tol("rtol", rtol, strictly_positive=True)
        self.atol = _check_tol("atol", atol, strictly_positive=True)
        self.state_scale = _model_scale(model, self.n_states)
        self._atol_vec = [self.atol * s for s in self.state_scale]
        self._has_jac = callable(getattr(model, "jacobian", None))
        import numpy as np  # only the reference path needs numpy/scipy
        from scipy.integrate import solve_ivp

        self._np = np
        self._solve_ivp = solve_ivp

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        np = self._np
        solve_ivp = self._solve_ivp
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

        y0 = np.array(x, dtype=float)
        try:
            f0 = model.rhs(t, list(x), u)
        except (ArithmeticError, ValueError) as exc:
            raise self._fail(f"rhs raised {exc!r} at the start point", t, h, t, h) from exc
        if len(f0) != self.n_states or not _is_finite_sum(f0):
            raise self._fail(
                "non-finite value (or wrong length) in the rhs at the start point", t, h, t, h
            )
        try:
            sol = solve_ivp(
                fun, (t, t + h), y0, method="Radau", rtol=self.rtol, atol=np.array(self._atol_vec), jac=jac
            )
        except _WorkLimit as exc:
            raise self._fail(str(exc), t, h, t, h) from None
        except (ArithmeticError, ValueError) as exc:
            raise self._fail(f"solve_ivp raised {exc!r}", t, h, t, h) from exc
        n_steps = max(len(sol.t) - 1, 0)
        last_h = float(sol.t[-1] - sol.t[-2]) if len(sol.t) > 1 else 0.0
        if sol.status != 0:
            raise self._fail(f"solve_ivp(Radau) failed: {sol.message}", float(sol.t[-1]), last_h, t, h)
        y = sol.y[:, -1].tolist()
        if not _is_finite_sum(y):
            raise self._fail("non-finite value in the result", float(sol.t[-1]), last_h, t, h)
        stats = StepStats(
            rhs_calls=calls[0] + 1,
            jacobian_calls=int(sol.njev),
            lu_decompositions=int(sol.nlu),
            substeps=n_steps,
        )
        return y, stats
