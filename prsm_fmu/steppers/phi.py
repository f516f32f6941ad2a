"""The φ-functions of exponential integrators applied to vectors, for small matrices in plain Python.

``φ_0(z) = e^z`` and ``φ_{k+1}(z) = (φ_k(z) - 1/k!) / z`` (``φ_k(0) = 1/k!``); for a matrix
``Z`` (here ``h A``, a step size times the Jacobian block of the stiff states) ``φ_k(Z) v`` is
what an exponential Rosenbrock step needs (:mod:`.exponential`).

Method (:func:`prepare`): for the 1 to 3 unknowns of a PRSM model's speed block the eigenvalues
``z_i`` of ``Z`` come in closed form (quadratic and cubic formulae, polished by Newton steps on
the characteristic polynomial; ``numpy.linalg.eigvals`` for more unknowns), and ``φ_k(Z) v`` is
the Newton interpolation polynomial of ``φ_k`` at them applied to ``v``,
``φ_k[z_1] v + φ_k[z_1, z_2] (Z - z_1) v + φ_k[z_1, z_2, z_3] (Z - z_2)(Z - z_1) v``, exact for
any matrix with those eigenvalues (Cayley–Hamilton; Higham, Functions of Matrices, SIAM 2008,
Ch. 1.2).  The nodes are taken in Leja order (largest modulus first).  Its rounding error grows
like ``eps (||Z|| / δ)^j`` with ``δ`` the smallest distance between eigenvalues, so when
``δ < CLUSTER * ||Z||`` (nearly repeated eigenvalues, e.g. two identical stages) the
φ-functions come instead from the exponential of the augmented matrix
``[[Z, v e_1^T], [0, N]]`` (``N`` the nilpotent shift; Al-Mohy & Higham, SIAM J. Sci. Comput.
33 (2011) 488, Thm 2.1) by ``scipy.linalg.expm``: exact in any case, about ten times slower.
Complex eigenvalues are handled with complex arithmetic (the results' imaginary parts, rounding
noise, are dropped).  A matrix of small norm, ``||Z||_inf <= TAYLOR_NORM`` (clustered
eigenvalues or not: e.g. a PRSM's speed block in saturated friction, whose eigenvalues all sit
near 0), skips the eigenvalues: ``φ_k(Z) v`` is then summed as its Taylor series
``Σ_m Z^m v / (m + k)!`` in matrix-vector products (about 20 terms at norm 1), so the
augmented-matrix exponential is left only for clustered eigenvalues of a larger matrix.
"""

from __future__ import annotations

import cmath
import math
from operator import mul
from typing import Sequence

__all__ = ["phi_scalar", "prepare", "CLUSTER", "TAYLOR_NORM", "Phi"]

#: relative distance of eigenvalues below which the augmented-matrix exponential is used
CLUSTER = 1e-2

#: ``||Z||_inf`` up to which ``φ_k(Z) v`` is summed as its Taylor series (matrix-vector products)
TAYLOR_NORM = 1.0

_INV_FACT = tuple(1.0 / math.factorial(k) for k in range(50))


def phi_scalar(z: complex | float, kmax: int) -> list:
    """``[φ_0(z), ..., φ_kmax(z)]`` for a real or complex number ``z``.

    Taylor series of ``φ_kmax`` and the recurrence downwards ``φ_k = z φ_{k+1} + 1/k!`` for
    ``|z| < 1`` (no cancellation); ``e^z`` and the recurrence upwards elsewhere.  Raises
    ``OverflowError`` where ``e^z`` overflows.
    """
    out = [0.0] * (kmax + 1)
    if abs(z) < 1.0:
        term = _INV_FACT[kmax]
        s = term
        for m in range(1, 30):
            term *= z / (m + kmax)
            s += term
            if abs(term) <= 1e-17 * abs(s):
                break
        out[kmax] = s
        for k in range(kmax - 1, -1, -1):
            out[k] = z * out[k + 1] + _INV_FACT[k]
        return out
    out[0] = cmath.exp(z) if isinstance(z, complex) else math.exp(z)
    for k in range(kmax):
        out[k + 1] = (out[k] - _INV_FACT[k]) / z
    return out


def _newton_step(coef: Sequence[float], r: complex | float) -> complex | float:
    """One Newton step for a root of the monic polynomial ``z^n + coef[0] z^(n-1) + ...``
    (kept only if it lowers |p|)."""
    p = 1.0
    dp = 0.0
    for c in coef:
        dp = dp * r + p
        p = p * r + c
    if dp == 0.0:
        return r
    r1 = r - p / dp
    q = 1.0
    for c in coef:
        q = q * r1 + c
    return r1 if abs(q) < abs(p) else r


def _quadratic(b: float, c: float) -> list:
    """Roots of ``z^2 + b z + c`` (the larger by the formula, the smaller as c / larger)."""
    disc = 0.25 * b * b - c
    if disc >= 0.0:
        r1 = -0.5 * b - math.copysign(math.sqrt(disc), b)
        return [r1, c / r1] if r1 != 0.0 else [0.0, 0.0]
    s = math.sqrt(-disc)
    return [complex(-0.5 * b, s), complex(-0.5 * b, -s)]


def _cubic(a: float, b: float, c: float) -> list:
    """Roots of ``z^3 + a z^2 + b z + c``: one real root by Cardano's or the trigonometric
    formula, polished; the other two from the deflated quadratic; all polished."""
    p = b - a * a / 3.0
    q = 2.0 * a * a * a / 27.0 - a * b / 3.0 + c
    disc = 0.25 * q * q + p * p * p / 27.0
    if disc > 0.0:
        s = math.sqrt(disc)
        u = -0.5 * q + s if q < 0.0 else -0.5 * q - s      # no cancellation
        u = math.copysign(abs(u) ** (1.0 / 3.0), u)
        t = u - p / (3.0 * u) if u != 0.0 else 0.0
    elif p < 0.0:
        m = 2.0 * math.sqrt(-p / 3.0)
        arg = max(-1.0, min(1.0, 3.0 * q / (p * m)))
        t = m * math.cos(math.acos(arg) / 3.0)            # the largest of three real roots
    else:
        t = 0.0
    coef = (a, b, c)
    r = t - a / 3.0
    for _ in range(2):
        r = _newton_step(coef, r)
    # deflate z^3 + a z^2 + b z + c = (z - r)(z^2 + pp z + qq): the product of the other two
    # roots as -c / r when r is larger than their geometric mean, else as b + pp r
    pp = a + r
    qq = -c / r if r != 0.0 and abs(r) ** 3 >= abs(c) else b + pp * r
    roots = [r] + _quadratic(pp, qq)
    return [roots[0]] + [_newton_step(coef, z) for z in roots[1:]]


def _eigenvalues(z: Sequence[Sequence[float]]) -> list:
    n = len(z)
    if n == 1:
        return [z[0][0]]
    if n == 2:
        (a, b), (c, d) = z
        return _quadratic(-(a + d), a * d - b * c)
    if n == 3:
        (a, b, c), (d, e, f), (g, h, i) = z
        tr = a + e + i
        minors = (a * e - b * d) + (a * i - c * g) + (e * i - f * h)
        det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
        return _cubic(-tr, minors, -det)
    import numpy as np

    return [complex(v) if v.imag else float(v.real) for v in np.linalg.eigvals(np.array(z))]


#: Taylor coefficients 1/(m+4)! of φ_4 for |z| < 1 (enough for double precision)
_PHI4_TAYLOR = tuple(_INV_FACT[m + 4] for m in range(16))[::-1]


def _phi14(z: complex | float) -> tuple:
    """``(φ_1(z), φ_2(z), φ_3(z), φ_4(z))``, as :func:`phi_scalar`, unrolled."""
    if z == 0.0:
        return 1.0, 0.5, _INV_FACT[3], _INV_FACT[4]
    if abs(z) < 1.0:
        s = 0.0
        for c in _PHI4_TAYLOR:
            s = s * z + c
        p3 = z * s + _INV_FACT[3]
        p2 = z * p3 + 0.5
        return z * p2 + 1.0, p2, p3, s
    e = cmath.exp(z) if isinstance(z, complex) else math.exp(z)
    iz = 1.0 / z
    p1 = (e - 1.0) * iz
    p2 = (p1 - 1.0) * iz
    p3 = (p2 - 0.5) * iz
    return p1, p2, p3, (p3 - _INV_FACT[3]) * iz


class Phi:
    """``φ_1 .. φ_4`` of one matrix ``Z``, ready to apply to vectors (made by :func:`prepare`).

    Attributes
    ----------
    nodes : tuple
        The eigenvalues of ``Z`` in Leja order (empty on the Taylor and augmented-matrix paths).
    """

    __slots__ = ("z", "nodes", "coef", "complex_", "_aug", "_taylor")

    def __init__(self, z: list[list[float]]) -> None:
        self.z = z
        n = len(z)
        norm = max([sum(map(abs, row)) for row in z])
        if not math.isfinite(norm):
            raise OverflowError("non-finite matrix entries")
        self._taylor = n > 1 and norm <= TAYLOR_NORM
        self._aug = False
        self.complex_ = False
        self.nodes = self.coef = ()
        if self._taylor:
            return
        ev = _eigenvalues(z)
        # Leja order: largest modulus first, then the farthest from those taken
        ev.sort(key=abs, reverse=True)
        if n == 3 and abs(ev[2] - ev[0]) > abs(ev[1] - ev[0]):
            ev[1], ev[2] = ev[2], ev[1]
        elif n > 3:
            nodes = [ev.pop(0)]
            while ev:
                nodes.append(ev.pop(max(range(len(ev)), key=lambda i: math.prod(
                    [abs(ev[i] - s) for s in nodes]))))
            ev = nodes
        gap = min([abs(ev[i] - ev[j]) for i in range(n) for j in range(i)], default=math.inf)
        if not all(map(cmath.isfinite, ev)):
            raise OverflowError("non-finite eigenvalues")
        self._aug = n > 1 and not gap > CLUSTER * norm
        self.complex_ = any([isinstance(w, complex) for w in ev])
        self.nodes = () if self._aug else tuple(ev)
        self.coef = ()
        if self._aug:
            return
        vals = [_phi14(w) for w in ev]          # vals[i][k - 1] = φ_k(z_i)
        if n == 1:
            self.coef = tuple((v,) for v in vals[0])
            return
        coef = []
        for k in range(4):
            if n == 2:
                f0, f1 = vals[0][k], vals[1][k]
                coef.append((f0, (f0 - f1) / (ev[0] - ev[1])))
            elif n == 3:
                f0, f1, f2 = vals[0][k], vals[1][k], vals[2][k]
                c1 = (f0 - f1) / (ev[0] - ev[1])
                coef.append((f0, c1, (c1 - (f1 - f2) / (ev[1] - ev[2])) / (ev[0] - ev[2])))
            else:
                col = [v[k] for v in vals]
                c = [col[0]]
                for j in range(1, n):
                    col = [(col[i] - col[i + 1]) / (ev[i] - ev[i + j]) for i in range(n - j)]
                    c.append(col[0])
                coef.append(tuple(c))
        self.coef = tuple(coef)

    def apply(self, v: Sequence[float], ks: Sequence[int]) -> list[list[float]]:
        """``[φ_k(Z) v for k in ks]`` for ``k`` in 1..4 (lists of float)."""
        if self._taylor:
            return _taylor(self.z, v, ks)
        if self._aug:
            return _augmented(self.z, v, ks)
        z = self.z
        w = v
        ws = [v]
        for s in self.nodes[:-1]:
            w = [sum(map(mul, row, w)) - s * wi for row, wi in zip(z, w)]
            ws.append(w)
        out = []
        coef = self.coef
        if len(ws) == 3:
            w0, w1, w2 = ws
            for k in ks:
                c0, c1, c2 = coef[k - 1]
                out.append([c0 * a + c1 * b + c2 * c for a, b, c in zip(w0, w1, w2)])
        else:
            for k in ks:
                c = coef[k - 1]
                out.append([sum([cj * wj[i] for cj, wj in zip(c, ws)]) for i in range(len(v))])
        if self.complex_:
            out = [[x.real for x in r] for r in out]
        return out


def prepare(z: list[list[float]]) -> Phi:
    """Prepare ``φ_1 .. φ_4`` of the small square matrix ``z`` (rows of floats).

    Raises ``OverflowError`` where an eigenvalue makes ``e^z`` overflow or ``z`` is not
    finite (an exponential step then rejects the step size).
    """
    return Phi(z)


def _augmented(z: list[list[float]], v: Sequence[float], ks: Sequence[int]) -> list[list[float]]:
    """``φ_k(Z) v`` from ``expm([[Z, v e_1^T], [0, N]])`` (its top-right block holds
    ``φ_1(Z) v .. φ_K(Z) v``; ``φ_0(Z) v`` from ``expm(Z) v``)."""
    import numpy as np
    from scipy.linalg import expm

    n = len(z)
    kmax = max(max(ks), 1)
    m = np.zeros((n + kmax, n + kmax))
    m[:n, :n] = z
    m[:n, n] = v
    for j in range(kmax - 1):
        m[n + j, n + j + 1] = 1.0
    e = expm(m)
    if not np.all(np.isfinite(e)):
        raise OverflowError("matrix exponential overflowed")
    out = []
    for k in ks:
        col = e[:n, :n] @ np.asarray(v, dtype=float) if k == 0 else e[:n, n + k - 1]
        out.append([float(a) for a in col])
    return out


def _taylor(z: list[list[float]], v: Sequence[float], ks: Sequence[int]) -> list[list[float]]:
    """``φ_k(Z) v = Σ_m Z^m v / (m + k)!`` for ``||Z||_inf <= 1``, summed in matrix-vector
    products until a term falls below ``1e-17 ||v|| / (kmax + 1)!`` (all terms have the sign
    pattern of ``Z^m v``, no cancellation beyond that of ``Z^m v`` itself; ``||φ_k(Z)|| >=
    1/k! - Σ_{m>=1} 1/(m+k)! > 0``, so the bound is relative to the result)."""
    kmax = max(ks)
    w = list(v)
    out = [[c * _INV_FACT[k] for c in w] for k in ks]
    tiny = 1e-17 * max(map(abs, w)) * _INV_FACT[kmax + 1]
    for m in range(1, 40):
        w = [sum(map(mul, row, w)) for row in z]
        big = max(map(abs, w))
        for acc, k in zip(out, ks):
            c = _INV_FACT[m + k]
            for i, wi in enumerate(w):
                acc[i] += c * wi
        if big * _INV_FACT[m + 1] <= tiny:
            break
    return out
