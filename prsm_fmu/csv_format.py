"""Doubles to CSV text at numpy speed, every value read back bit for bit.

Formatting a double in Python costs ~1 µs (``f"{v:.15g}"``, ``repr``), so a 15 001-row result
with ~50 outputs took ~2 s to write.  Here the digits of all values are made at once with numpy
in double-double arithmetic (a value as the unevaluated sum of two doubles, ~106 bits):

1. each value x with 1e-280 < |x| < 1e280 gets a decimal exponent e = ⌊log₁₀|x|⌋ and p
   significant digits d = round(|x| · 10^k), k = p − 1 − e, p = 15, then 17 for the values 15
   do not settle (a value needing 16 gets 17).  |x| · 10^k is formed exactly as a product of
   two doubles (Dekker's split) plus |x| times the table's low part of 10^k, so its error is
   ~1e-32 relative — far below the digit being rounded;
2. d · 10^(e−p+1) reads back as x exactly when it lies within half a unit in the last place
   (ulp) of x, since ``float()`` rounds correctly: the distance |d − |x|·10^k| (known to
   ~1e-15 of a digit from step 1) must be below 0.9 × half the smaller gap from x to a
   neighbouring double, scaled by 10^k, less a margin of 1e-12 (relative and in digits) that
   covers the computation's own errors, so none of them can pass a wrong text; 17 correctly
   rounded digits always pass but for a value within the margin of a tie (then step 3);
3. the fewer digits that pass are written, ``[-]d.ddde±XX`` without trailing zeros; zeros as
   ``0e+00``/``-0e+00``; what is left (NaN, ±inf, |x| outside step 1's range, anything not passed)
   by ``repr``, exact by definition (the shortest text that reads back as the same double).

The tests read values back with ``float()`` and compare the bits (tests/test_csv_format.py).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

__all__ = ["format_cells", "format_values", "format_table", "WIDTH"]

#: the widest text of a double: ``-d.dddddddddddddddde-XXX`` (and ``repr``'s longest, e.g.
#: ``-2.2250738585072014e-308``, has as many characters)
WIDTH = 24

#: values handled by the vectorised path: |x| · 10^k then stays within float64's range and
#: Dekker's split (which multiplies by 2^27) cannot overflow
_LO, _HI = 1e-280, 1e280
_KMAX = 300
#: values formatted at once by format_table
_BLOCK = 8192


def _pow10_table() -> tuple[np.ndarray, np.ndarray]:
    """10^k = hi + lo for k = −_KMAX.._KMAX: hi the nearest double, lo the nearest double to
    the rest (exact rational arithmetic)."""
    hi = np.empty(2 * _KMAX + 1)
    lo = np.empty(2 * _KMAX + 1)
    for i, k in enumerate(range(-_KMAX, _KMAX + 1)):
        exact = Fraction(10) ** k
        h = float(exact)
        hi[i], lo[i] = h, float(exact - Fraction(h))
    return hi, lo


_P10_HI, _P10_LO = _pow10_table()
#: the four characters of each number 0..9999
_GROUPS = np.frombuffer("".join(f"{i:04d}" for i in range(10000)).encode("ascii"),
                        dtype=np.uint8).reshape(10000, 4)
_DIGITS = np.frombuffer(b"0123456789", dtype=np.uint8)
#: the same four characters as one uint32 each, and two-digit numbers as one uint16 each
_GROUPS32 = _GROUPS.reshape(-1).view(np.uint32).copy()
_PAIRS16 = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode("ascii"),
                         dtype=np.uint16).copy()
_SPLIT = 134217729.0          # 2^27 + 1, Dekker's splitting constant for float64


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = _SPLIT * a
    h = c - (c - a)
    return h, a - h


def _digits(a: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """round(a · 10^k) as int64 and the distance |round − a · 10^k| [digits] (step 1)."""
    hi, lo = _P10_HI[k + _KMAX], _P10_LO[k + _KMAX]
    p = a * hi                                       # a · hi = p + err exactly (Dekker)
    ah, al = _split(a)
    bh, bl = _split(hi)
    err = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    yl = err + a * lo
    yr = np.rint(p)
    f = (p - yr) + yl                                # exact: p − yr is exact for |p| < 2^53,
    c = np.rint(f)                                   # zero above (p is then an integer)
    return yr.astype(np.int64) + c.astype(np.int64), np.abs(f - c)


def _shortest(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For ``x`` with _LO < |x| < _HI: 17 significant digits (int64, trailing digits zero when
    fewer suffice), the decimal exponent, and whether the text passed step 2."""
    a = np.abs(x)
    # half the smaller gap to a neighbouring double (at a power of two the gap below is half
    # the gap above); exact in float64
    half_gap = 0.5 * np.minimum(np.nextafter(a, np.inf) - a, a - np.nextafter(a, 0.0))
    e0 = np.floor(np.log10(a)).astype(np.int64)
    d17 = np.zeros(x.size, dtype=np.int64)
    exp = np.zeros(x.size, dtype=np.int64)
    done = np.zeros(x.size, dtype=bool)
    todo = np.arange(x.size)
    for p in (15, 17):
        ai, e = a[todo], e0[todo]
        d, dist = _digits(ai, p - 1 - e)
        # log10 a unit off near powers of ten, or a rounding up to 10^p: one decade over
        low, high = d < 10 ** (p - 1), d >= 10 ** p
        redo = np.flatnonzero(low | high)
        if redo.size:
            e[redo] += high[redo].astype(np.int64) - low[redo]
            d[redo], dist[redo] = _digits(ai[redo], p - 1 - e[redo])
        # the threshold is known to ~1e-16 relative, the distance to ~1e-15 digits
        limit = half_gap[todo] * _P10_HI[p - 1 - e + _KMAX] * (1.0 - 1e-12) - 1e-12
        ok = ((dist < limit)
              & (d >= 10 ** (p - 1)) & (d < 10 ** p))
        good = todo[ok]
        d17[good] = d[ok] * 10 ** (17 - p)
        exp[good] = e[ok]
        done[good] = True
        todo = todo[~ok]
    return d17, exp, done


def _fill(buf: np.ndarray, keep: np.ndarray, negative: np.ndarray, d17: np.ndarray,
          e: np.ndarray) -> None:
    """Write ``[-]d.ddde±XX`` (17 digits, trailing zeros not kept) into rows of buf/keep."""
    first, rest = np.divmod(d17, 10 ** 16)
    hi, lo = np.divmod(rest, 10 ** 8)
    g = np.empty((d17.size, 4), dtype=np.int64)       # the other 16 digits, four groups of 4
    g[:, 0], g[:, 1] = np.divmod(hi, 10000)
    g[:, 2], g[:, 3] = np.divmod(lo, 10000)
    buf[:, 0] = ord("-")
    keep[:, 0] = negative
    buf[:, 1] = np.take(_DIGITS, first)
    buf[:, 2] = ord(".")
    buf[:, 3:19] = np.take(_GROUPS32, g).view(np.uint8)
    # keep the mantissa's digits up to its last nonzero one, and the point only before a digit
    nz = buf[:, 3:19] != ord("0")
    last = 15 - np.argmax(nz[:, ::-1], axis=1)        # 15 also when all are zero,
    last[(last == 15) & ~nz[:, 15]] = -1              # which this marks
    keep[:, 3:19] = np.arange(16)[None, :] <= last[:, None]
    keep[:, 1] = True
    keep[:, 2] = keep[:, 3]
    buf[:, 19] = ord("e")
    buf[:, 20] = np.where(e < 0, ord("-"), ord("+"))
    ae = np.abs(e)
    h, tu = np.divmod(ae, 100)
    buf[:, 21] = np.take(_DIGITS, h)
    buf[:, 22:24] = np.take(_PAIRS16, tu).view(np.uint8).reshape(-1, 2)
    keep[:, 19:24] = True
    keep[:, 21] = ae >= 100                           # two exponent digits at least, as %e


def format_cells(x: np.ndarray, extra: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Each value of ``x`` (read as float64, flattened in C order) as characters, (n, WIDTH +
    extra) uint8 (``extra`` free columns at the end, not kept), and a mask of those to keep:
    text that ``float()`` reads back to the same double, bit for bit (module docstring)."""
    x = np.ascontiguousarray(x, dtype=np.float64).ravel()
    n = x.size
    buf = np.zeros((n, WIDTH + extra), dtype=np.uint8)
    keep = np.zeros((n, WIDTH + extra), dtype=bool)
    ax = np.abs(x)
    zero = ax == 0.0
    inside = (ax > _LO) & (ax < _HI)
    d17 = np.zeros(n, dtype=np.int64)                 # zeros: 0e+00 (or -0e+00)
    e = np.zeros(n, dtype=np.int64)
    settled = zero.copy()
    if inside.all():                                  # the common case: no gather/scatter
        d17, e, settled = _shortest(x)
    else:
        fin = np.flatnonzero(inside)
        d17[fin], e[fin], settled[fin] = _shortest(x[fin])
    _fill(buf, keep, np.signbit(x), d17, e)
    # NaN, ±inf, |x| outside step 1's range and what step 2 did not settle: repr
    for i in np.flatnonzero(~settled).tolist():
        buf[i] = 0
        keep[i] = False
        text = repr(float(x[i])).encode("ascii")
        buf[i, :len(text)] = np.frombuffer(text, dtype=np.uint8)
        keep[i, :len(text)] = True
    return buf, keep


def format_values(x: np.ndarray) -> list[str]:
    """Each value of ``x`` (read as float64, flattened in C order) as exact text
    (:func:`format_cells`)."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 1)
    return format_table(x).decode("ascii").split("\n")[:-1]


def format_table(data: np.ndarray) -> bytes:
    """Rows of a 2-D array as CSV lines, ASCII (``,`` between values, ``\\n`` after each row),
    every value exact (:func:`format_cells`)."""
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2:
        raise ValueError(f"data: a 2-D array expected, got shape {data.shape}")
    rows, cols = data.shape
    # blocks of ~8000 values: the dozens of temporary arrays then stay in the CPU's cache
    # (whole columns of a long run would stream through memory for every operation)
    step = max(1, _BLOCK // max(cols, 1))
    parts = []
    for r0 in range(0, rows, step):
        block = data[r0:r0 + step]
        n = block.shape[0]
        buf, keep = format_cells(block, extra=1)
        buf = buf.reshape(n, cols, WIDTH + 1)
        keep = keep.reshape(n, cols, WIDTH + 1)
        buf[:, :, WIDTH] = ord(",")
        buf[:, -1, WIDTH] = ord("\n")
        keep[:, :, WIDTH] = True
        parts.append(buf[keep].tobytes())
    return b"".join(parts)
