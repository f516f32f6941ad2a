"""Time steppers that advance one model across one communication step with inputs held.

A co-simulation master (an FMU's ``doStep``) calls :meth:`Stepper.advance` once per
communication step (typically 1 ms) with the model inputs ``u`` held constant.  The
steppers here are written for that hot path:

* states and derivatives are plain Python ``list`` objects of ``float``; the inner loops
  use list comprehensions over ``zip`` (for the 2..12 states of a PRSM model, small
  numpy arrays cost about ten times more per operation);
* every call returns a fresh state list; the caller's list ``x`` is never mutated, so
  the caller's state is unchanged when :class:`StepFailure` is raised;
* the work done is counted in a :class:`StepStats` per call.

Provided steppers (see :func:`make_stepper`):

``"rk4"``
    :class:`RK4`, classic fixed-step Runge-Kutta of order 4.
``"explicit_adaptive"``
    :class:`ExplicitAdaptive`, embedded explicit pair with step-size control:
    Dormand-Prince 5(4) (default) or Bogacki-Shampine 3(2).
``"rosenbrock"``
    :class:`Rosenbrock`, linearly implicit L-stable ROS34PW2 (order 3, embedded 2)
    for stiff models (contact stiffness, electrical time constants).
``"radau"``
    :class:`ScipyRadau`, the reference path through :func:`scipy.integrate.solve_ivp`.

Model protocol (duck typed, see :class:`OdeModel`): ``n_states``, ``rhs(t, x, u)``,
``state_scale`` and optionally ``jacobian(t, x, u)``, ``error_mask`` and
``quadrature_states``.  Times are in seconds [s]; states and derivatives are in SI units.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from operator import itemgetter, mul
from typing import Any, Callable, Protocol, Sequence

__all__ = [
    "OdeModel",
    "StepStats",
    "StepFailure",
    "Stepper",
    "RK4",
    "ExplicitAdaptive",
    "Rosenbrock",
    "ScipyRadau",
    "make_stepper",
    "STEPPER_NAMES",
]

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


# ----------------------------------------------------------------------------------
# dense LU with partial pivoting, plain Python, for small systems
# ----------------------------------------------------------------------------------


def _lu_factor(rows_rev: list[list[float]]) -> tuple | None:
    """LU-factorise a square matrix with partial pivoting (Doolittle, ``P A = L U``).

    ``rows_rev`` holds the rows of ``A`` with their columns in *reversed* order; the
    lists are consumed.  Keeping the columns reversed lets each elimination step take
    the current column with ``pop()`` from the end of the active rows, so no slicing
    is needed (plain Python, meant for n <= ~12).

    Returns the packed factors ``(perm, lower, upper_rev, inv_diag)`` for
    :func:`_lu_solve` -- ``perm[k]`` is the row of ``A`` used as pivot row ``k``,
    ``lower[k]`` the ``k`` multipliers of L's row ``k``, ``upper_rev[k]`` U's row ``k``
    right of the diagonal in reversed order, ``inv_diag[k] = 1 / U[k][k]`` -- or
    ``None`` if a pivot is exactly zero (singular matrix).
    """
    tails = rows_rev
    n = len(tails)
    orig = list(range(n))
    mults: list[list[float]] = [[] for _ in range(n)]
    perm: list[int] = []
    lower: list[list[float]] = []
    upper_rev: list[list[float]] = []
    inv_diag: list[float] = []
    for _k in range(n):
        col = [abs(r[-1]) for r in tails]
        amax = max(col)
        if not amax > 0.0:
            return None
        p = col.index(amax)
        prow = tails.pop(p)
        perm.append(orig.pop(p))
        lower.append(mults.pop(p))
        inv_piv = 1.0 / prow.pop()
        inv_diag.append(inv_piv)
        upper_rev.append(prow)
        for j, r in enumerate(tails):
            f = r.pop() * inv_piv
            mults[j].append(f)
            if f != 0.0:
                tails[j] = [a - f * b for a, b in zip(r, prow)]
    return perm, lower, upper_rev, inv_diag


def _lu_solve(lu: tuple, b: Sequence[float]) -> list[float]:
    """Solve ``A y = b`` with the packed factors from :func:`_lu_factor` (new list)."""
    perm, lower, upper_rev, inv_diag = lu
    y: list[float] = []
    for i, li in enumerate(lower):
        y.append(b[perm[i]] - sum(map(mul, li, y)))
    xr: list[float] = []
    for i in range(len(y) - 1, -1, -1):
        xr.append((y[i] - sum(map(mul, upper_rev[i], xr))) * inv_diag[i])
    xr.reverse()
    return xr


# Unrolled factorisation and solution of ``(d I - J) y = b[idx]`` for 1, 2 and 3
# unknowns (partial pivoting as in _lu_factor): the iteration matrices of small models
# (or of the non-quadrature block of larger ones).  The factors are flat tuples that
# carry the indices into ``b`` of the (pivoted) rows, so the solve reads its right-hand
# side straight from a longer vector.  ``None`` signals a zero pivot.


def _lu_small1(j: Sequence[Sequence[float]], d: float, idx: Sequence[int]) -> tuple | None:
    a00 = d - j[0][0]
    if a00 == 0.0:
        return None
    return idx[0], 1.0 / a00


def _solve_small1(fac: tuple, b: Sequence[float]) -> list[float]:
    return [b[fac[0]] * fac[1]]


def _lu_small2(j: Sequence[Sequence[float]], d: float, idx: Sequence[int]) -> tuple | None:
    (j00, j01), (j10, j11) = j
    a00, a01, a10, a11 = d - j00, -j01, -j10, d - j11
    i0, i1 = idx
    if abs(a10) > abs(a00):
        a00, a01, a10, a11, i0, i1 = a10, a11, a00, a01, i1, i0
    if a00 == 0.0:
        return None
    d0 = 1.0 / a00
    l10 = a10 * d0
    a11 -= l10 * a01
    if a11 == 0.0:
        return None
    return i0, i1, l10, a01, d0, 1.0 / a11


def _solve_small2(fac: tuple, b: Sequence[float]) -> list[float]:
    i0, i1, l10, u01, d0, d1 = fac
    y0 = b[i0]
    x1 = (b[i1] - l10 * y0) * d1
    return [(y0 - u01 * x1) * d0, x1]


def _lu_small3(j: Sequence[Sequence[float]], d: float, idx: Sequence[int]) -> tuple | None:
    (j00, j01, j02), (j10, j11, j12), (j20, j21, j22) = j
    a00, a01, a02 = d - j00, -j01, -j02
    a10, a11, a12 = -j10, d - j11, -j12
    a20, a21, a22 = -j20, -j21, d - j22
    i0, i1, i2 = idx
    c0, c1, c2 = abs(a00), abs(a10), abs(a20)
    if c1 > c0 and c1 >= c2:
        a00, a01, a02, a10, a11, a12, i0, i1 = a10, a11, a12, a00, a01, a02, i1, i0
    elif c2 > c0:
        a00, a01, a02, a20, a21, a22, i0, i2 = a20, a21, a22, a00, a01, a02, i2, i0
    if a00 == 0.0:
        return None
    d0 = 1.0 / a00
    l10 = a10 * d0
    l20 = a20 * d0
    a11 -= l10 * a01
    a12 -= l10 * a02
    a21 -= l20 * a01
    a22 -= l20 * a02
    if abs(a21) > abs(a11):
        a11, a12, a21, a22, l10, l20, i1, i2 = a21, a22, a11, a12, l20, l10, i2, i1
    if a11 == 0.0:
        return None
    d1 = 1.0 / a11
    l21 = a21 * d1
    a22 -= l21 * a12
    if a22 == 0.0:
        return None
    return i0, i1, i2, l10, l20, l21, a01, a02, a12, d0, d1, 1.0 / a22


def _solve_small3(fac: tuple, b: Sequence[float]) -> list[float]:
    i0, i1, i2, l10, l20, l21, u01, u02, u12, d0, d1, d2 = fac
    y0 = b[i0]
    y1 = b[i1] - l10 * y0
    x2 = (b[i2] - l20 * y0 - l21 * y1) * d2
    x1 = (y1 - u12 * x2) * d1
    return [(y0 - u01 * x1 - u02 * x2) * d0, x1, x2]


def _getter(idx: Sequence[int]) -> Callable[[Sequence[float]], Sequence[float]]:
    """``v -> (v[i] for i in idx)`` as a sequence, via :func:`operator.itemgetter`."""
    if len(idx) == 1:
        i = idx[0]
        return lambda v: (v[i],)
    return itemgetter(*idx)


_SMALL_LU = {1: (_lu_small1, _solve_small1), 2: (_lu_small2, _solve_small2), 3: (_lu_small3, _solve_small3)}


# ----------------------------------------------------------------------------------
# base class
# ----------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------
# RK4
# ----------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------
# shared machinery of the adaptive steppers
# ----------------------------------------------------------------------------------


class _AdaptiveBase(Stepper):
    """Common tolerance handling, error norm and step-size controller."""

    #: exponent denominator of the controller: err ~ h**(q+1), q = min(order, embedded order)
    _q1: float = 1.0

    def __init__(
        self,
        model: Any,
        rtol: float,
        atol: float,
        h_min: float,
        max_substeps: int,
        fixed_substeps: int | None,
        safety: float,
        fac_min: float,
        fac_max: float,
    ) -> None:
        super().__init__(model)
        n = self.n_states
        self.rtol = _check_tol("rtol", rtol, strictly_positive=False)
        self.atol = _check_tol("atol", atol, strictly_positive=True)
        self.h_min = _check_tol("h_min", h_min, strictly_positive=True)
        self.max_substeps = _check_count("max_substeps", max_substeps, 1)
        self.fixed_substeps = (
            None if fixed_substeps is None else _check_count("fixed_substeps", fixed_substeps, 1)
        )
        if not (0.0 < safety <= 1.0):
            raise ValueError(f"safety = {safety!r} is out of range: must be in (0, 1]")
        if not (0.0 < fac_min < 1.0):
            raise ValueError(f"fac_min = {fac_min!r} is out of range: must be in (0, 1)")
        if not (1.0 < fac_max < _INF):
            raise ValueError(f"fac_max = {fac_max!r} is out of range: must be finite and > 1")
        self.safety = float(safety)
        self.fac_min = float(fac_min)
        self.fac_max = float(fac_max)
        self.state_scale = _model_scale(model, n)
        self.error_mask = _model_mask(model, n)
        # absolute error weights; excluded states get an infinite weight, so they add 0
        # to the norm (while a non-finite error in them still shows up as nan)
        self._atol_w = [self.atol * s if m else _INF for s, m in zip(self.state_scale, self.error_mask)]
        self._n_err = sum(self.error_mask)
        self._h_prop: float | None = None

    # --- memory ---------------------------------------------------------------------

    def get_memory(self) -> tuple:
        """Return ``(h_proposal,)``: the step size [s] proposed for the next internal
        step (``None`` before the first adaptive advance or after :meth:`reset`)."""
        return (self._h_prop,)

    def set_memory(self, m: tuple) -> None:
        """Restore ``(h_proposal,)`` from :meth:`get_memory`."""
        m = tuple(m)
        if len(m) != 1 or not (m[0] is None or (isinstance(m[0], float) and 0.0 < m[0] < _INF)):
            raise ValueError(
                f"{self.name}: memory must be (h_proposal,) with None or a finite float > 0, got {m!r}"
            )
        self._h_prop = m[0]

    def reset(self) -> None:
        """Forget the step-size proposal."""
        self._h_prop = None

    # --- helpers --------------------------------------------------------------------

    def _initial_step(self, x: Sequence[float], f0: Sequence[float], h: float) -> float:
        """Cheap first-step guess [s] without extra rhs calls, after Hairer, Norsett &
        Wanner, Solving ODEs I, Sec. II.4 (first part only): ``0.01 * max(d0, 1) / d1``
        with ``d0``, ``d1`` the weighted RMS norms of ``x`` and ``f(t, x)``, at most ``h``."""
        _, d0, d1 = self._start_norms(x, f0)
        if not d1 > 1e-5:  # practically at rest (or nan, handled by the step itself)
            return h
        return min(h, 0.01 * max(d0, 1.0) / d1)

    def _start_norms(self, x: Sequence[float], f0: Sequence[float]) -> tuple:
        """Error weights at ``x`` and the weighted RMS norms of ``x`` and ``f0`` (Hairer,
        Norsett & Wanner's d0, d1)."""
        rtol = self.rtol
        w = [at + rtol * abs(a) for a, at in zip(x, self._atol_w)]
        d0 = math.sqrt(sum([(a / wi) ** 2 for a, wi in zip(x, w)]) / self._n_err)
        d1 = math.sqrt(sum([(a / wi) ** 2 for a, wi in zip(f0, w)]) / self._n_err)
        return w, d0, d1

    def _factor(self, err: float) -> float:
        """Step-size ratio proposed by the elementary controller for error norm ``err``."""
        if err == 0.0:
            return self.fac_max
        if not err < _INF:
            return self.fac_min
        return min(self.fac_max, max(self.fac_min, self.safety * err ** (-1.0 / self._q1)))


# ----------------------------------------------------------------------------------
# explicit embedded pairs
# ----------------------------------------------------------------------------------

# Dormand & Prince (1980), "A family of embedded Runge-Kutta formulae", J. Comput. Appl.
# Math. 6, 19-26; tableau as in Hairer, Norsett & Wanner, Solving ODEs I, Table II.5.2.
_DP_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0)
_DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),
)
_DP_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0)
_DP_BHAT = (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40)

# Bogacki & Shampine (1989), "A 3(2) pair of Runge-Kutta formulas", Appl. Math. Lett.
# 2(4), 321-325.
_BS_C = (0.0, 1 / 2, 3 / 4, 1.0)
_BS_A = ((), (1 / 2,), (0.0, 3 / 4), (2 / 9, 1 / 3, 4 / 9))
_BS_B = (2 / 9, 1 / 3, 4 / 9, 0.0)
_BS_BHAT = (7 / 24, 1 / 4, 1 / 3, 1 / 8)

# error weights b - b_hat (DP: without the zero entry of stage 2)
_DP_E = tuple(b - bh for i, (b, bh) in enumerate(zip(_DP_B, _DP_BHAT)) if i != 1)
_BS_E = tuple(b - bh for b, bh in zip(_BS_B, _BS_BHAT))

#: explicit tableaus by order: (c, a, b, b_hat) -- exposed for the order tests
EXPLICIT_TABLEAUS = {5: (_DP_C, _DP_A, _DP_B, _DP_BHAT), 3: (_BS_C, _BS_A, _BS_B, _BS_BHAT)}


class ExplicitAdaptive(_AdaptiveBase):
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
        while True:
            rem = h - tau
            last = hs * 1.05 >= rem
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
            if err <= 1.0:
                stats.substeps += 1
                fac = self._factor(err)
                if just_rejected and fac > 1.0:
                    fac = 1.0
                h_new = h_step * fac
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
                hs = h_step * self._factor(err)
                if hs < h_min:
                    raise self._fail(
                        f"step size {hs!r} s below h_min = {h_min!r} s after rejection ({reason})",
                        ti, h_step, t, h,
                    )


def _bad_text(bad: int) -> str:
    if bad > 0:
        return f"non-finite value (or wrong length) in stage {bad}"
    return "non-finite value in the result"


# ----------------------------------------------------------------------------------
# Rosenbrock ROS34PW2
# ----------------------------------------------------------------------------------

# ROS34PW2: J. Rang and L. Angermann, "New Rosenbrock W-methods of order 3 for partial
# differential algebraic equations of index 1", BIT Numer. Math. 45 (2005) 761-787.
# 4 stages, order 3 with an embedded order-2 solution; L-stable (R(inf) = 0), stiffly
# accurate (b = last row of alpha + gamma), embedded solution A-stable; satisfies the
# Prothero-Robinson conditions (less order reduction for stiff forced problems).  The
# coefficients are checked in tests/test_steppers.py against the Rosenbrock order
# conditions (Hairer & Wanner, Solving ODEs II, Table IV.7.1) and by observed order.
# Formulation: k_i from (I - h gamma J) k_i = h f(x + sum_j alpha_ij k_j) + h J sum_j gamma_ij k_j.
ROS_GAMMA = 4.3586652150845900e-01
ROS_ALPHA = (
    (0.0, 0.0, 0.0, 0.0),
    (8.7173304301691801e-01, 0.0, 0.0, 0.0),
    (8.4457060015369423e-01, -1.1299064236484185e-01, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.0),
)
ROS_GAMMA_IJ = (  # strictly lower part; the diagonal is ROS_GAMMA
    (0.0, 0.0, 0.0, 0.0),
    (-8.7173304301691801e-01, 0.0, 0.0, 0.0),
    (-9.0338057013044082e-01, 5.4180672388095326e-02, 0.0, 0.0),
    (2.4212380706095346e-01, -1.2232505839045147e00, 5.4526025533510214e-01, 0.0),
)
ROS_B = (2.4212380706095346e-01, -1.2232505839045147e00, 1.5452602553351020e00, 4.3586652150845900e-01)
ROS_BHAT = (3.7810903145819369e-01, -9.6042292212423178e-02, 0.5, 2.1793326075422950e-01)


def _ros_transformed() -> tuple:
    """Coefficients of the Jacobian-product-free form (Hairer & Wanner II, (IV.7.25)):
    with u_i = sum_j Gamma_ij k_j (Gamma incl. its diagonal),
    (I/(h gamma) - J) u_i = f(x + sum_j a_ij u_j) + sum_j (c_ij / h) u_j,
    x_new = x + sum_i m_i u_i, where a = alpha Gamma^-1, c = diag(1/gamma) - Gamma^-1,
    m = b^T Gamma^-1."""
    s = 4
    g = [
        [ROS_GAMMA_IJ[i][j] if j < i else (ROS_GAMMA if i == j else 0.0) for j in range(s)]
        for i in range(s)
    ]
    ginv = [[0.0] * s for _ in range(s)]
    for j in range(s):  # forward substitution for the columns of the lower-triangular inverse
        for i in range(j, s):
            acc = 1.0 if i == j else 0.0
            for k in range(j, i):
                acc -= g[i][k] * ginv[k][j]
            ginv[i][j] = acc / g[i][i]
    a = [[sum(ROS_ALPHA[i][k] * ginv[k][j] for k in range(s)) for j in range(s)] for i in range(s)]
    c = [[-ginv[i][j] if j < i else 0.0 for j in range(s)] for i in range(s)]
    m = [sum(ROS_B[k] * ginv[k][j] for k in range(s)) for j in range(s)]
    mhat = [sum(ROS_BHAT[k] * ginv[k][j] for k in range(s)) for j in range(s)]
    alpha_sum = [sum(row) for row in ROS_ALPHA]
    return a, c, m, mhat, alpha_sum


_ROS_A, _ROS_C, _ROS_M, _ROS_MHAT, _ROS_ALPHA_SUM = _ros_transformed()
# flat coefficients for the hot loop: a_ij, c_ij (i > j) and the stage times alpha_i
_ROS_TRIAL = (
    tuple(_ROS_A[i][j] for i in range(1, 4) for j in range(i))
    + tuple(_ROS_C[i][j] for i in range(1, 4) for j in range(i))
    + tuple(_ROS_ALPHA_SUM[1:])
)
_ROS_E = tuple(p - q for p, q in zip(_ROS_M, _ROS_MHAT))  # error weights m - m_hat


def _quadrature_weights(c: Sequence[Sequence[float]], gamma: float, m: Sequence[float]) -> tuple:
    """Weights w with ``sum_i m_i u_q,i = h sum_i w_i (f_q(X_i) + J_qd u_d,i)`` for the
    quadrature states q of a Rosenbrock method in the transformed form.

    Their stage equations ``u_q,i / (h gamma) - J_qd u_d,i = f_q(X_i) + sum_j (c_ij / h) u_q,j``
    give ``u_q = gamma (I - gamma C)^-1 g`` with ``g_i = h (f_q(X_i) + J_qd u_d,i)`` (C strictly
    lower triangular), so ``w = gamma m^T (I - gamma C)^-1`` (back substitution)."""
    s = len(m)
    w = [0.0] * s
    for j in range(s - 1, -1, -1):
        w[j] = gamma * (m[j] + sum(w[i] * c[i][j] for i in range(j + 1, s)))
    return tuple(w)


# result and error weights of the quadrature states (see _quadrature_weights)
_ROS_WQ = _quadrature_weights(_ROS_C, ROS_GAMMA, _ROS_M)
_ROS_EQ = _quadrature_weights(_ROS_C, ROS_GAMMA, _ROS_E)


class Rosenbrock(_AdaptiveBase):
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
    (controller exponent 1/3 from the embedded order 2).  The error estimate is the raw
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
    does not force tiny first steps.

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
        has_jac = callable(getattr(model, "jacobian", None))
        if jacobian == "auto":
            self._analytic = has_jac
        elif jacobian == "analytic":
            if not has_jac:
                raise ValueError('jacobian = "analytic" but the model has no callable jacobian(t, x, u)')
            self._analytic = True
        elif jacobian == "fd":
            self._analytic = False
        else:
            raise ValueError(
                f"jacobian = {jacobian!r} is out of range: allowed are 'auto', 'fd', 'analytic'"
            )
        self.jacobian = "analytic" if self._analytic else "fd"
        n = self.n_states
        self._quad = _model_quadrature(model, n)
        self._dyn = tuple(i for i in range(n) if i not in self._quad)
        # position of state i in the concatenation k_d + k_q
        pos = {i: p for p, i in enumerate(self._dyn + self._quad)}
        self._merge = tuple(pos[i] for i in range(n))
        self._small = _SMALL_LU.get(len(self._dyn))
        # gather the parts d and q of a vector, and scatter k_d + k_q back, in one C call each
        self._get_d = _getter(self._dyn) if self._dyn else (lambda v: ())
        self._get_q = _getter(self._quad) if self._quad else (lambda v: ())
        self._get_merged = _getter(self._merge) if self._quad else None
        self._solve_d = _lu_solve if self._small is None else self._small[1]
        self._atol_d = [self._atol_w[i] for i in self._dyn]
        self._atol_q = [self._atol_w[i] for i in self._quad]

    # --- Jacobian and iteration matrix --------------------------------------------------

    def _jac(
        self, f: Callable, t: float, x: list[float], f0: list[float], u: tuple, stats: StepStats
    ) -> tuple:
        """Jacobian at (t, x) as ``(J_dd, J_qd)``: the rows of the non-quadrature states
        ``d`` and of the quadrature states ``q``, both restricted to the columns ``d``
        (the columns ``q`` are zero by declaration).  Without quadrature states ``J_dd``
        is the full Jacobian and ``J_qd`` is empty.  Forward differences re-use
        ``f0 = f(t, x)`` and cost one rhs call per column ``d``."""
        n = self.n_states
        dyn, quad = self._dyn, self._quad
        stats.jacobian_calls += 1
        if self._analytic:
            jac = self.model.jacobian(t, x, u)
            if len(jac) != n or any(len(row) != n for row in jac):
                raise ValueError(f"model.jacobian must return {n} rows of {n} entries")
            if not quad:
                return jac, ()
            return (
                [[jac[i][j] for j in dyn] for i in dyn],
                [[jac[i][j] for j in dyn] for i in quad],
            )
        cols = []
        scale = self.state_scale
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
        return (
            [[c[i] for c in cols] for i in dyn],
            [[c[i] for c in cols] for i in quad],
        )

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
            a = [[-v for v in reversed(row)] for row in jdd]  # columns reversed, see _lu_factor
            last = len(a) - 1
            for i, row in enumerate(a):
                row[last - i] += d
            lu = _lu_factor(a)
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
        self, f: Callable, t: float, x: list[float], f0: list[float], fac: tuple, hs: float, u: tuple
    ) -> tuple:
        """One step of size ``hs`` from ``(t, x)`` with ``f0 = f(t, x)``; returns ``(x_new,
        err, bad)`` (``bad``: 0, or the first stage (2..4) with a non-finite value or the
        wrong length, -1 for a non-finite result).

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
        for p, q, r, s, v, at in zip(xd, u1, u2, u3, u4, self._atol_d):
            pn = p + m1 * q + m2 * r + m3 * s + m4 * v
            sq += ((e1 * q + e2 * r + e3 * s + e4 * v) / (at + rtol * max(abs(p), abs(pn)))) ** 2
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
        if fixed is not None:
            hs = h / fixed
        else:
            hs = self._h_prop
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
                if fixed is None and tau == 0.0:
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
                last = hs * 1.05 >= rem
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
                y_new, err, bad = self._trial(f, ti, y, f0, fac_lu, h_step, u)
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
            if err <= 1.0:
                stats.substeps += 1
                stats.error_estimate = err
                fac = self._factor(err)
                if just_rejected and fac > 1.0:
                    fac = 1.0
                h_new = h_step * fac
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
                    return y, stats
                tau += h_step
                hs = h_new
            else:
                stats.rejected += 1
                just_rejected = True
                hs = h_step * self._factor(err)
                if hs < self.h_min:
                    raise self._fail(
                        f"step size {hs!r} s below h_min = {self.h_min!r} s after rejection ({reason})",
                        ti, h_step, t, h,
                    )


# ----------------------------------------------------------------------------------
# reference: scipy Radau IIA
# ----------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------
# closed form with a numerical fallback
# ----------------------------------------------------------------------------------


class ClosedForm(Stepper):
    """Exact step where the model offers one, an adaptive explicit pair elsewhere.

    For models with ``closed_form_advance(t, x, u, h) -> list | None`` (the slaved-carrier
    levels: constant acceleration under held inputs outside the friction band).  Where it
    answers None (zero speed crossed, friction band entered, sign pattern left), the step is
    integrated by :class:`ExplicitAdaptive` with the given options.  A closed-form step counts
    as one rhs call.

    Parameters
    ----------
    model : OdeModel
        Model with ``closed_form_advance``.
    **fallback_options
        Options of the fallback :class:`ExplicitAdaptive` (``rtol``, ``atol``, ``order`` ...).
    """

    name = "closed_form"

    def __init__(self, model: Any, **fallback_options: Any) -> None:
        super().__init__(model)
        if not callable(getattr(model, "closed_form_advance", None)):
            raise ValueError(f"closed_form: model {type(model).__name__} has no closed_form_advance; "
                             "use it with the quasi-static or kinematic level")
        self._exact = model.closed_form_advance
        self.fallback = ExplicitAdaptive(model, **fallback_options)

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        h = self._check_args(t, x, h)
        y = self._exact(t, x, u, h)
        if y is not None:
            if not _is_finite_sum(y):
                raise self._fail("non-finite value in the closed-form step", t + h, h, t, h)
            return y, StepStats(rhs_calls=1, substeps=1)
        return self.fallback.advance(t, x, u, h)

    def get_memory(self) -> tuple:
        return self.fallback.get_memory()

    def set_memory(self, m: tuple) -> None:
        self.fallback.set_memory(m)

    def reset(self) -> None:
        self.fallback.reset()


# ----------------------------------------------------------------------------------
# factory
# ----------------------------------------------------------------------------------

_STEPPERS: dict[str, type[Stepper]] = {
    "rk4": RK4,
    "explicit_adaptive": ExplicitAdaptive,
    "rosenbrock": Rosenbrock,
    "radau": ScipyRadau,
    "closed_form": ClosedForm,
}

#: names accepted by :func:`make_stepper`
STEPPER_NAMES = tuple(_STEPPERS)


def make_stepper(name: str, model: Any, **options: Any) -> Stepper:
    """Create a stepper by name.

    Parameters
    ----------
    name : {"rk4", "explicit_adaptive", "rosenbrock", "radau", "closed_form"}
        Stepper kind.
    model : OdeModel
        Model to integrate.  A model with a ``stepper_factory(name, **options)`` (the
        ``auto`` fidelity, which switches levels along a run) builds its own stepper, taking
        ``name`` (or ``"default"``: its own choice per step) for its dynamic steps.
    **options
        Keyword arguments of the stepper's constructor (e.g. ``rtol``, ``substeps``).

    Returns
    -------
    Stepper
        The new stepper.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the allowed names).
    """
    factory = getattr(model, "stepper_factory", None)
    if factory is not None and (name == "default" or name in _STEPPERS):
        # a model that switches levels steps itself (models/adaptive.py)
        return factory(name, **options)
    try:
        cls = _STEPPERS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown stepper {name!r}: allowed are {', '.join(STEPPER_NAMES)}") from None
    return cls(model, **options)
