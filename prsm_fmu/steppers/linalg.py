"""Small dense linear algebra in plain Python for the linearly implicit steppers.

LU factorisation with partial pivoting and its solve for systems of up to ~12 unknowns (a PRSM
model's iteration matrix), unrolled for 1, 2 and 3 unknowns, and a gather helper; at this size
plain Python floats beat numpy arrays about tenfold per operation.
"""

from __future__ import annotations

from operator import itemgetter, mul
from typing import Callable, Sequence

__all__ = ["lu_factor", "lu_solve", "SMALL_LU", "getter"]

def lu_factor(rows_rev: list[list[float]]) -> tuple | None:
    """LU-factorise a square matrix with partial pivoting (Doolittle, ``P A = L U``).

    ``rows_rev`` holds the rows of ``A`` with their columns in *reversed* order; the
    lists are consumed.  Keeping the columns reversed lets each elimination step take
    the current column with ``pop()`` from the end of the active rows, so no slicing
    is needed (plain Python, meant for n <= ~12).

    Returns the packed factors ``(perm, lower, upper_rev, inv_diag)`` for
    :func:`lu_solve` -- ``perm[k]`` is the row of ``A`` used as pivot row ``k``,
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


def lu_solve(lu: tuple, b: Sequence[float]) -> list[float]:
    """Solve ``A y = b`` with the packed factors from :func:`lu_factor` (new list)."""
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
# unknowns (partial pivoting as in lu_factor): the iteration matrices of small models
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


def getter(idx: Sequence[int]) -> Callable[[Sequence[float]], Sequence[float]]:
    """``v -> (v[i] for i in idx)`` as a sequence, via :func:`operator.itemgetter`."""
    if len(idx) == 1:
        i = idx[0]
        return lambda v: (v[i],)
    return itemgetter(*idx)


SMALL_LU = {1: (_lu_small1, _solve_small1), 2: (_lu_small2, _solve_small2), 3: (_lu_small3, _solve_small3)}
