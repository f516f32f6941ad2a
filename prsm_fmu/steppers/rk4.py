"""Classic fixed-step Runge-Kutta method of order 4."""

from __future__ import annotations

from typing import Any

from .base import Stepper, StepStats, _check_count, _first_nonfinite

__all__ = ["RK4"]


class RK4(Stepper):
    """Classic fixed-step Runge-Kutta method of order 4.

    Each advance takes ``substeps`` equal internal steps of size ``h / substeps``
    and costs exactly ``4 * substeps`` rhs calls.  No error estimate, no memory.
    Real-axis stability limit: ``|h lambda| <= 2.785``.

    Parameters
    ----------
    model : OdeModel
        Model to integrate.
    substeps : int, optional
        Equal internal steps per advance (>= 1).
    """

    name = "rk4"

    def __init__(self, model: Any, substeps: int = 1) -> None:
        super().__init__(model)
        self.substeps = _check_count("substeps", substeps, 1)

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        f = self.model.rhs
        n_sub = self.substeps
        hs = h / n_sub
        hh = 0.5 * hs
        h6 = hs / 6.0
        y = x
        ti = t
        for i in range(n_sub):
            ti = t + i * hs
            try:
                k1 = f(ti, y, u)
                k2 = f(ti + hh, [a + hh * b for a, b in zip(y, k1)], u)
                k3 = f(ti + hh, [a + hh * b for a, b in zip(y, k2)], u)
                k4 = f(ti + hs, [a + hs * b for a, b in zip(y, k3)], u)
            except (ArithmeticError, ValueError) as exc:
                raise self._fail(f"rhs raised {exc!r}", ti, hs, t, h) from exc
            y_new = [a + h6 * (b + 2.0 * (c + d) + e) for a, b, c, d, e in zip(y, k1, k2, k3, k4)]
            # Every stage enters the result with a non-zero weight, so a non-finite value
            # in any stage makes the result non-finite: checking the result suffices.
            s = sum(y_new)
            if s - s != 0.0 or len(y_new) != self.n_states:
                if len(y_new) != self.n_states:
                    raise self._fail(
                        f"rhs returned {min(map(len, (k1, k2, k3, k4)))} values instead of {self.n_states}",
                        ti, hs, t, h,
                    )
                bad = _first_nonfinite((k1, k2, k3, k4))
                what = (
                    f"non-finite value in stage {bad + 1}" if bad >= 0 else "non-finite value in the result"
                )
                raise self._fail(what, ti, hs, t, h)
            y = y_new
        return y, StepStats(rhs_calls=4 * n_sub, substeps=n_sub)
