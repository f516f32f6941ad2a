"""Doubles to CSV text at numpy speed, every value read back bit for bit.

Formatting a double in Python costs ~0.5 µs (``f"{v:.15g}"``, ``repr``), so a 15 001-row result
with ~60 outputs took ~0.5–1 s to write.  Here the digits of all values are made at once with
numpy in double-double arithmetic (a value as the unevaluated sum of two doubles, ~106 bits):

1. each value x with 2e-99 ≤ |x| < 9e99 (two exponent digits) gets a decimal exponent e = ⌊log₁₀|x|⌋ and its 17
   significant digits d = round(|x| · 10^k), k = 16 − e, with the signed rest
   r = |x| · 10^k − d.  |x| · 10^k is formed exactly as a product of two doubles (Dekker's
   split) plus |x| times the table's low part of 10^k, so its error is ~1e-32 relative — r is
   known to ~1e-15 of a digit;
2. a text reads back as x exactly when it lies within half a unit in the last place (ulp) of x,
   since ``float()`` rounds correctly: its distance from |x| · 10^k (in units of the 17th digit)
   must be below half the smaller gap from x to a neighbouring double, scaled by 10^k, less
   a margin of 1e-12 (relative and in digits) that covers the computation's own errors, so
   none of them can pass a wrong text.  Tried: the 15 significant digits (d and r rounded to
   hundreds: distance |100 · d₁₅ − d − r|, an integer of at most 50 less r), else the 17; 17
   correctly rounded digits always pass but for a value within the margin of a tie (then
   step 4).  A value needing 16 gets 17;
3. the fewer digits that pass are written, ``[-]d.ddde±XX`` without trailing zeros; zeros as
   ``0e+00``/``-0e+00``;
4. what is left (NaN, ±inf, |x| outside step 1's range, anything not passed) by ``repr``, exact
   by definition (the shortest text that reads back as the same double).

The characters are laid out as 32 bytes per value, four 8-byte words looked up in tables
(:data:`ROW`), with a mask of the bytes kept; one boolean index then packs every line.

The tests read values back with ``float()`` and compare the bits (tests/test_csv_format.py).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Iterator

import numpy as np

__all__ = ["format_cells", "format_values", "format_table", "format_blocks", "ROW"]

#: bytes per value in the working layout (four 8-byte words): 5 ``-``, 6 the first digit, 7
#: ``.``, 8..23 the other 16 digits, 24 ``e``, 25 the exponent's sign, 26..27 its two digits,
#: 28 the separator; bytes 0..4 and 29..31 are never kept.  A value's kept bytes are then two
#: runs (``[-]d.ddd`` and ``e±XX,``), which numpy's boolean index copies faster than scattered
#: bytes
ROW = 32

#: values handled by the vectorised path: two exponent digits (|e| ≤ 99, also after rounding
#: up a decade, or when log10 is a unit off); |x| · 10^k stays within float64's range and
#: Dekker's split (which multiplies by 2^27) cannot overflow
_LO, _HI = 2e-99, 9e99
_KMAX = 120
#: values formatted at once by format_table
_BLOCK = 8192
_QUAD = np.dtype("<u8")       # little-endian: byte i of a word is at address 8·w + i


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


def _table(rows) -> np.ndarray:
    """Rows of 8 bytes (or lists of 8 ints) as little-endian 8-byte words."""
    return np.frombuffer(b"".join(bytes(r) for r in rows), dtype=_QUAD).copy()


_P10_HI, _P10_LO = _pow10_table()
#: word 0 by the first digit: ``-``, the digit, ``.`` (bytes 5..7)
_HEAD = _table(b"\0\0\0\0\0-%d." % i for i in range(10))
#: four digits of 0..9999 as the low half of an 8-byte word (words 1 and 2: the 16 digits)
_GROUPS = _table(b"%04d\0\0\0\0" % i for i in range(10000))
#: word 3 by the exponent + 99 (−99..99): ``e``, the sign, two digits, ``,``
_TAIL = _table(b"e%+03d,\0\0\0" % i for i in range(-99, 100))
#: the digits kept up to and with a group's last nonzero one, by the group (0..9999) and its
#: place j: 4·j + its digits up to the last nonzero one; 0 for a zero group.  The digits kept
#: after the point are the largest of the four
_LAST = np.array([[0 if v == 0 else 4 * j + len(str(v).zfill(4).rstrip("0"))
                   for v in range(10000)] for j in range(4)], dtype=np.uint8)
#: bytes kept (1) of word 0 by 2 · negative + (any digit after the point); of words 1 and 2 by
#: the number m of digits after the point; of word 3, always ``e±XX,``
_KEEP_HEAD = _table([0, 0, 0, 0, 0, n, 1, p] for n in (0, 1) for p in (0, 1))
_KEEP_DIGITS = [_table([1 if 8 * w + i < m else 0 for i in range(8)] for m in range(17))
                for w in (0, 1)]
_KEEP_TAIL = _table([[1, 1, 1, 1, 1, 0, 0, 0]])[0]
#: byte 4 of word 3: the separator
_NEWLINE = np.uint64(ord("\n") << 32)
_COMMA = np.uint64(ord(",") << 32)
_SPLIT = 134217729.0          # 2^27 + 1, Dekker's splitting constant for float64
_D16, _D17 = 10 ** 16, 10 ** 17
_EXPONENT_BITS = np.int64(0x7FF0000000000000)
_FRACTION_BITS = np.int64(0x000FFFFFFFFFFFFF)


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = _SPLIT * a
    h = c - (c - a)
    return h, a - h


def _digits(a: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """round(a · 10^k) as int64 and the signed rest a · 10^k − round(...) [digits] (step 1)."""
    i = k + _KMAX
    hi = _P10_HI[i]
    p = a * hi                                       # a · hi = p + err exactly (Dekker)
    ah, al = _split(a)
    bh, bl = _P10_SPLIT_HI[i], _P10_SPLIT_LO[i]      # _split(hi), made once
    err = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    yl = err + a * _P10_LO[i]
    yr = np.rint(p)
    f = (p - yr) + yl                                # exact: p − yr is exact for |p| < 2^53,
    c = np.rint(f)                                   # zero above (p is then an integer)
    return yr.astype(np.int64) + c.astype(np.int64), f - c


_P10_SPLIT_HI, _P10_SPLIT_LO = _split(_P10_HI)
#: 10^k less the relative margin (1e-12) of step 2
_P10_SAFE = _P10_HI * (1.0 - 1e-12)


def _half_gap(a: np.ndarray) -> np.ndarray:
    """Half the smaller gap from a (normal, > 0) to a neighbouring double: half its ulp
    2^(E − 52), a quarter at a power of two (the gap below is half the gap above); exact."""
    bits = a.view(np.int64)
    ulp = ((bits & _EXPONENT_BITS) - (52 << 52)).view(np.float64)
    return ulp * np.where(bits & _FRACTION_BITS, 0.5, 0.25)


def _shortest(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For ``x`` with _LO ≤ |x| < _HI: 17 significant digits (int64, trailing digits zero when
    15 suffice), the decimal exponent, and whether the text passed step 2."""
    a = np.abs(x)
    e = np.floor(np.log10(a)).astype(np.int64)
    d, r = _digits(a, 16 - e)
    # log10 a unit off near powers of ten, or a rounding up to 10^17: one decade over
    off = (d >= _D17).astype(np.int64) - (d < _D16)
    redo = np.flatnonzero(off)
    if redo.size:
        e[redo] += off[redo]
        d[redo], r[redo] = _digits(a[redo], 16 - e[redo])
        # still out of range (log10 two off: not seen) -> repr, through a rest no text passes
        bad = redo[(d[redo] < _D16) | (d[redo] >= _D17)]
        d[bad], r[bad] = _D16, np.inf
    # the threshold is known to ~1e-16 relative, the rest r to ~1e-15 digits
    limit = _half_gap(a) * np.take(_P10_SAFE, 16 - e + _KMAX) - 1e-12
    q = d // 100
    rem = d - 100 * q
    up = (rem + r) > 50.0                            # the 15 digits rounded to nearest
    ok15 = np.abs((100 * up - rem) - r) < limit
    d17 = np.where(ok15, 100 * (q + up), d)
    carry = d17 == _D17                              # 15 digits rounded up to 10^15
    d17[carry] = _D16
    e += carry
    return d17, e, ok15 | (np.abs(r) < limit)


def _fill(words: np.ndarray, keep: np.ndarray, negative: np.ndarray, d17: np.ndarray,
          e: np.ndarray) -> None:
    """Write ``[-]d.ddde±XX,`` (17 digits, trailing zeros not kept, |e| ≤ 99) into rows of the
    (n, 4) 8-byte word arrays ``words`` (characters) and ``keep`` (per byte: 1 kept, 0 not)."""
    first = d17 // _D16
    rest = d17 - first * _D16                         # the other 16 digits
    hi = rest // 10 ** 8
    lo = rest - hi * 10 ** 8
    g0 = hi // 10000                                  # in four groups of four
    g1 = hi - g0 * 10000
    g2 = lo // 10000
    g3 = lo - g2 * 10000
    m = np.maximum(np.maximum(np.take(_LAST[0], g0), np.take(_LAST[1], g1)),
                   np.maximum(np.take(_LAST[2], g2), np.take(_LAST[3], g3)))
    words[:, 0] = np.take(_HEAD, first)
    words[:, 1] = np.take(_GROUPS, g0) | (np.take(_GROUPS, g1) << np.uint64(32))
    words[:, 2] = np.take(_GROUPS, g2) | (np.take(_GROUPS, g3) << np.uint64(32))
    words[:, 3] = np.take(_TAIL, e + 99)
    keep[:, 0] = np.take(_KEEP_HEAD, 2 * negative + (m > 0))
    keep[:, 1] = np.take(_KEEP_DIGITS[0], m)
    keep[:, 2] = np.take(_KEEP_DIGITS[1], m)
    keep[:, 3] = _KEEP_TAIL


def format_cells(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each value of ``x`` (read as float64, flattened in C order) as :data:`ROW` bytes of
    characters, (n, ROW) uint8, and a boolean mask of those to keep: text that ``float()``
    reads back to the same double, bit for bit (module docstring), then ``,`` (byte 28)."""
    x = np.ascontiguousarray(x, dtype=np.float64).ravel()
    n = x.size
    words = np.empty((n, ROW // 8), dtype=_QUAD)
    keep = np.empty((n, ROW // 8), dtype=_QUAD)
    ax = np.abs(x)
    inside = (ax >= _LO) & (ax < _HI)
    if inside.all():                                  # the common case: no gather/scatter
        d17, e, settled = _shortest(x)
    else:
        d17 = np.zeros(n, dtype=np.int64)             # zeros: 0e+00 (or -0e+00)
        e = np.zeros(n, dtype=np.int64)
        settled = ax == 0.0
        fin = np.flatnonzero(inside)
        d17[fin], e[fin], settled[fin] = _shortest(x[fin])
    _fill(words, keep, np.signbit(x), d17, e)
    chars, kept = words.view(np.uint8), keep.view(np.uint8).view(bool)
    # NaN, ±inf, |x| outside step 1's range and what step 2 did not settle: repr, in bytes
    # 0..23 (the longest repr has 24 characters), padded with NUL bytes that are not kept
    left = np.flatnonzero(~settled)
    if left.size:
        texts = b"".join(repr(v).encode("ascii").ljust(24, b"\0") for v in x[left].tolist())
        text = np.frombuffer(texts, dtype=np.uint8).reshape(-1, 24)
        chars[left, :24] = text
        kept[left, :24] = text != 0
        kept[left, 24:28] = False
    return chars, kept


def format_values(x: np.ndarray) -> list[str]:
    """Each value of ``x`` (read as float64, flattened in C order) as exact text
    (:func:`format_cells`)."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 1)
    return format_table(x).decode("ascii").split("\n")[:-1]


def format_blocks(data: np.ndarray) -> Iterator[np.ndarray]:
    """Rows of a 2-D array as CSV lines, ASCII (``,`` between values, ``\\n`` after each row),
    every value exact (:func:`format_cells`): uint8 arrays of consecutive lines, to be written
    one after the other (no copy into one bytes object)."""
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2:
        raise ValueError(f"data: a 2-D array expected, got shape {data.shape}")
    rows, cols = data.shape
    # blocks of ~8000 values: the temporary arrays then stay in the CPU's cache (whole columns
    # of a long run would stream through memory for every operation)
    step = max(1, _BLOCK // max(cols, 1))
    for r0 in range(0, rows, step):
        block = data[r0:r0 + step]
        chars, kept = format_cells(block)
        last = chars.view(_QUAD).reshape(block.shape[0], cols, ROW // 8)[:, -1, 3]
        last ^= _COMMA ^ _NEWLINE                     # the last value's separator
        yield chars[kept]


def format_table(data: np.ndarray) -> bytes:
    """:func:`format_blocks` as one bytes object."""
    return b"".join(block.tobytes() for block in format_blocks(data))
