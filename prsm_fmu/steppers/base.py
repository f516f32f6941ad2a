"""The shared base of the steppers: the model protocol, the work counters, the failure, the
abstract :class:`Stepper` and the argument checks every stepper makes.

States and derivatives are plain Python ``list`` objects of ``float``; every advance returns a
fresh state list and never mutates the caller's, so the caller's state is unchanged when
:class:`StepFailure` is raised.  Times are in seconds [s]; states and derivatives in SI units.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable, Protocol, Sequence

__all__ = ["OdeModel", "StepStats", "StepFailure", "Stepper"]

_INF = math.inf
_SQRT_EPS = math.sqrt(2.220446049250313e-16)


class OdeModel(Protocol):
    """Duck-typed interface of a model that a stepper integrates (for type hints only).

    Attributes
    ----------
    n_states : int
        Number of states.
    state_scale : tuple of float
        Per-state absolute scale in SI units; the absolute tolerance of state ``i`` is
        ``atol * state_scale[i]`` and the finite-difference increment uses it too.

    Optional members (looked up with ``getattr``): ``jacobian(t, x, u)`` returning the
    analytic ``d rhs / d x`` as row-major nested lists; ``error_mask``, a tuple of
    bool per state telling which states take part in error control (default: all);
    ``quadrature_states``, a tuple of the indices of states that no rhs component
    depends on (e.g. accumulated energies), which :class:`Rosenbrock` leaves out of its
    Jacobian and LU (default: none).
    """

    n_states: int
    state_scale: tuple[float, ...]

    def rhs(self, t: float, x: list[float], u: tuple) -> list[float]:
        """Time derivative ``dx/dt`` of the states at time ``t`` [s] with inputs ``u``."""
        ...


@dataclass(slots=True)
class StepStats:
    """Work done by one :meth:`Stepper.advance` call.

    Attributes
    ----------
    rhs_calls : int
        Calls of ``model.rhs``, including those spent on finite-difference Jacobians.
    jacobian_calls : int
        Jacobian evaluations (analytic calls of ``model.jacobian`` or finite-difference
        approximations).
    lu_decompositions : int
        LU decompositions of the iteration matrix.
    substeps : int
        Accepted internal steps.
    rejected : int
        Rejected internal steps (error test failed or non-finite trial values).
    error_estimate : float
        Weighted RMS error norm of the last accepted internal step (1.0 = exactly at
        tolerance); 0.0 for methods without an error estimate (RK4, Radau).
    """

    rhs_calls: int = 0
    jacobian_calls: int = 0
    lu_decompositions: int = 0
    substeps: int = 0
    rejected: int = 0
    error_estimate: float = 0.0


class StepFailure(RuntimeError):
    """An advance could not be completed.

    Raised for non-finite values in a stage or the result, a singular iteration matrix,
    a step size below ``h_min``, more than ``max_substeps`` internal steps, or a failure
    of the reference solver.  The message names the stepper, what failed, the time [s]
    and the internal step size [s].  The caller's state list is left unchanged.
    """


# ----------------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------------


def _check_h(h: Any) -> float:
    try:
        hf = float(h)
    except (TypeError, ValueError):
        hf = math.nan
    if isinstance(h, bool) or not (0.0 < hf < _INF):
        raise ValueError(
            f"h = {h!r} is out of range: the communication step must be a finite number > 0 [s]"
        )
    return hf


def _check_tol(name: str, value: Any, strictly_positive: bool) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value > 0.0 if strictly_positive else value >= 0.0)
    if not ok:
        rng = "> 0" if strictly_positive else ">= 0"
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number {rng}")
    return float(value)


def _check_count(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} = {value!r} is out of range: must be an integer >= {minimum}")
    return value


def _model_size(model: Any) -> int:
    n = getattr(model, "n_states", None)
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"model.n_states = {n!r} is out of range: must be an integer >= 1")
    if not callable(getattr(model, "rhs", None)):
        raise TypeError("model has no callable rhs(t, x, u)")
    return n


def _model_scale(model: Any, n: int) -> tuple[float, ...]:
    scale = getattr(model, "state_scale", None)
    if scale is None or len(scale) != n:
        raise ValueError(
            f"model.state_scale must be a sequence of {n} positive finite floats [SI], got {scale!r}"
        )
    out = tuple(float(s) for s in scale)
    for i, s in enumerate(out):
        if not (0.0 < s < _INF):
            raise ValueError(f"model.state_scale[{i}] = {s!r} is out of range: must be finite and > 0")
    return out


def _model_mask(model: Any, n: int) -> tuple[bool, ...]:
    mask = getattr(model, "error_mask", None)
    if mask is None:
        return (True,) * n
    if len(mask) != n:
        raise ValueError(f"model.error_mask must have {n} entries, got {len(mask)}")
    out = tuple(bool(m) for m in mask)
    if not any(out):
        raise ValueError(
            "model.error_mask excludes every state: at least one state must be error controlled"
        )
    return out


def _model_quadrature(model: Any, n: int) -> tuple[int, ...]:
    """Sorted indices of ``model.quadrature_states`` (``()`` if the model has none)."""
    quad = getattr(model, "quadrature_states", None)
    if quad is None:
        return ()
    try:
        idx = tuple(quad)
    except TypeError:
        raise ValueError(
            f"model.quadrature_states must be a sequence of state indices, got {quad!r}"
        ) from None
    for i in idx:
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n:
            raise ValueError(
                f"model.quadrature_states = {quad!r} is out of range: entries must be integers in [0, {n})"
            )
    if len(set(idx)) != len(idx):
        raise ValueError(f"model.quadrature_states = {quad!r} repeats an index")
    return tuple(sorted(idx))


def _analytic_jacobian(model: Any, jacobian: str) -> bool:
    """Whether a linearly implicit or exponential stepper uses the model's own Jacobian
    (``jacobian`` "analytic", or "auto" and the model has one) or forward differences ("fd")."""
    has_jac = callable(getattr(model, "jacobian", None))
    if jacobian == "auto":
        return has_jac
    if jacobian == "analytic":
        if not has_jac:
            raise ValueError('jacobian = "analytic" but the model has no callable jacobian(t, x, u)')
        return True
    if jacobian == "fd":
        return False
    raise ValueError(f"jacobian = {jacobian!r} is out of range: allowed are 'auto', 'fd', 'analytic'")


def _block_jacobian(stepper: Any, f: Callable, t: float, x: list[float], f0: list[float],
                    u: tuple, stats: "StepStats") -> tuple:
    """Jacobian at (t, x) as ``(J_dd, J_qd)`` for a stepper with ``_analytic``, ``_dyn`` and
    ``_quad``: the rows of the non-quadrature states ``d`` and of the quadrature states ``q``,
    both restricted to the columns ``d`` (the columns ``q`` are zero by declaration).  Without
    quadrature states ``J_dd`` is the full Jacobian and ``J_qd`` is empty.  Forward differences
    re-use ``f0 = f(t, x)`` and cost one rhs call per column ``d`` (increment
    ``sqrt(eps) max(|x_i|, state_scale_i)``)."""
    n = stepper.n_states
    dyn, quad = stepper._dyn, stepper._quad
    stats.jacobian_calls += 1
    if stepper._analytic:
        jac = stepper.model.jacobian(t, x, u)
        if len(jac) != n or any(len(row) != n for row in jac):
            raise ValueError(f"model.jacobian must return {n} rows of {n} entries")
        if not quad:
            return jac, ()
        return ([[jac[i][j] for j in dyn] for i in dyn],
                [[jac[i][j] for j in dyn] for i in quad])
    cols = []
    scale = stepper.state_scale
    for i in dyn:
        xi = x[i]
        xp = list(x)
        xp[i] = xi + _SQRT_EPS * max(abs(xi), scale[i])
        inv = 1.0 / (xp[i] - xi)  # the increment actually represented
        fp = f(t, xp, u)
        stats.rhs_calls += 1
        cols.append([(p - q) * inv for p, q in zip(fp, f0)])
    if not quad:
        return list(zip(*cols)), ()
    return [[c[i] for c in cols] for i in dyn], [[c[i] for c in cols] for i in quad]


def _first_nonfinite(vectors: Sequence[Sequence[float]]) -> int:
    """Index of the first vector holding a non-finite value, -1 if none."""
    for i, v in enumerate(vectors):
        for a in v:
            if not math.isfinite(a):
                return i
    return -1


def _is_finite_sum(v: Sequence[float]) -> bool:
    # A sum is finite iff every term is finite (barring overflow of the sum itself,
    # which only happens for values near 1e308 and is then treated as non-finite).
    s = sum(v)
    return s - s == 0.0


def _bad_text(bad: int) -> str:
    if bad > 0:
        return f"non-finite value (or wrong length) in stage {bad}"
    return "non-finite value in the result"


class Stepper(ABC):
    """Advance one model across one communication step with the inputs held.

    Subclasses implement :meth:`advance`.  Everything that influences the next advance
    besides its arguments (e.g. the step-size proposal of an adaptive method) is the
    stepper's *memory*: :meth:`get_memory` / :meth:`set_memory` capture and restore it
    so that an FMU's get/set state reproduces the next advance bit for bit.

    Attributes
    ----------
    name : str
        Factory name of the stepper (see :func:`make_stepper`).
    model : OdeModel
        The integrated model.
    """

    name: str = "stepper"

    def __init__(self, model: Any) -> None:
        self.model = model
        self.n_states = _model_size(model)

    @abstractmethod
    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        """Integrate from ``t`` to ``t + h`` with inputs ``u`` held.

        Parameters
        ----------
        t : float
            Start time [s].
        x : list of float
            State at ``t`` in SI units; not modified.
        u : tuple
            Inputs, passed unchanged to the model.
        h : float
            Communication step [s], finite and > 0.

        Returns
        -------
        x_new : list of float
            New list holding the state at ``t + h``.
        stats : StepStats
            Work counters of this call.

        Raises
        ------
        ValueError
            If ``h`` is not finite and > 0, or ``x`` has the wrong length.
        StepFailure
            If the step cannot be completed.
        """

    def get_memory(self) -> tuple:
        """Return an immutable snapshot of the stepper's memory (``()`` if stateless)."""
        return ()

    def set_memory(self, m: tuple) -> None:
        """Restore a snapshot returned by :meth:`get_memory` of a stepper of the same kind."""
        if tuple(m) != ():
            raise ValueError(f"{self.name}: memory must be () for this stateless stepper, got {m!r}")

    def reset(self) -> None:
        """Forget the memory (the next advance behaves like the first one)."""

    def _check_args(self, t: float, x: Sequence[float], h: float) -> float:
        h = _check_h(h)
        if not math.isfinite(t):
            raise ValueError(f"t = {t!r} is out of range: must be a finite time [s]")
        if len(x) != self.n_states:
            raise ValueError(f"len(x) = {len(x)} does not match model.n_states = {self.n_states}")
        return h

    def _fail(self, what: str, t: float, hs: float, t0: float, h: float) -> StepFailure:
        return StepFailure(
            f"{self.name}: {what} at t = {t!r} s with internal step {hs!r} s "
            f"(advance from t = {t0!r} s over h = {h!r} s)"
        )

    def __repr__(self) -> str:
        return f"{type(self).__name__}(model={type(self.model).__name__})"
