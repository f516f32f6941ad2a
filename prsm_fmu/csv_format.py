"""Doubles to CSV text at numpy speed (or compiled, the same bytes), every value read back bit
for bit.

Formatting a double in Python costs ~0.5 µs (``f"{v:.15g}"``, ``repr``), so a 15 001-row result
with ~60 outputs took ~0.5–1 s to write.  Here the digits of all values are made at once with
numpy in double-double arithmetic (a value as the unevaluated sum of two doubles, ~106 bits):

1. each value x with 2e-99 ≤ |x| < 9e99 (two exponent digits) gets a decimal exponent e = ⌊log₁₀|x|⌋ and its 17
   significant digits d = round(|x| · 10^k), k = 16 − e, with the signed rest
   r = |x| · 10^k − d.  |x| · 10^k is formed exactly as a product of two doubles (Dekker's
   product: |x| cut into its top 27 significant bits and the rest by clearing bits, 10^k into
   halves of 26 bits by Dekker's split) plus |x| times the table's low part of 10^k, so its
   error is ~1e-32 relative — r is known to ~1e-15 of a digit;
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

The characters are laid out as 24 bytes per value, three 8-byte words looked up in tables
(:data:`ROW`): the separator *before* the value (``,``, or ``\n`` ending the previous line),
the sign, the first digit and ``.`` in the first four bytes, then the 16 other digits, then
``e±XX``; the bytes a value does not use (trailing zeros, a ``.`` without digits after it,
the sign's place of a positive value) are NUL, and ``bytes.translate`` drops them: one pass
over a block of lines.

The tests read values back with ``float()`` and compare the bits (tests/test_csv_format.py).

This module is the reference.  Where gcc builds it, the same algorithm compiled
(:mod:`prsm_fmu.csv_compiled`, ``prsm_fmu/native/csv_format.c``, every constant and table
passed from here) writes the same bytes (tests/test_csv_compiled.py: 1.4 million seeded
values that reach every branch, 15-digit near-ties constructed across the margin, tables of
1..70 columns) at ~35 ns of CPU a value against ~100 ns here
(``python benchmarks/csv_write_cost.py``); ``compiled=False`` forces this path, and it runs
by itself where the library cannot be built.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Iterator, Sequence

import numpy as np

__all__ = ["format_values", "format_table", "format_blocks", "format_columns", "ROW"]

#: bytes per value in the working layout (three 8-byte words): 0..1 the separator before the
#: value and ``-`` (a negative value: ``,-``; a positive one: NUL ``,``), 2 the first digit,
#: 3 ``.``, 4..19 the other 16 digits, 20 ``e``, 21 the exponent's sign, 22..23 its two
#: digits.  A text of ``repr`` takes bytes 1..23 after the separator (and its 24th character,
#: if any, is written after the row)
ROW = 24

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


#: tables below are indexed by j = e + _EOFF, e the decimal exponent (10^k with k = 16 − e):
#: j = 0.._EOFF + 136 covers k = −120..120
_EOFF = 104
_NJ = 2 * _KMAX + 1


def _by_exponent(table_by_k: np.ndarray) -> np.ndarray:
    """A table indexed by k + _KMAX re-indexed by j = e + _EOFF (k = 16 − e)."""
    return np.ascontiguousarray(table_by_k[::-1])


_P10_HI_K, _P10_LO_K = _pow10_table()
_SPLIT = 134217729.0          # 2^27 + 1, Dekker's splitting constant for float64


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = _SPLIT * a
    h = c - (c - a)
    return h, a - h


#: 10^(16 − e) by j, a row each (one gather for a value): the nearest double, its Dekker
#: halves (26 bits each), the rest
_P10_ROWS = _by_exponent(np.stack([_P10_HI_K, *_split(_P10_HI_K), _P10_LO_K], axis=1))
#: step 2's margin for the computation's own errors, relative and in digits
_MARGIN = 1e-12
#: 10^(16 − e) less the relative margin of step 2
_P10_SAFE = _by_exponent(_P10_HI_K * (1.0 - _MARGIN))
#: the low half of word 0 by the first digit + 10 · negative + 20 · (no digit after the point):
#: ``\0,d.``, ``,-d.``, ``\0,d\0`` or ``,-d\0``
_HEAD = _table(b"%s%d%s\0\0\0\0" % (b",-" if neg else b"\0,", i, b"\0" if bare else b".")
               for bare in (0, 1) for neg in (0, 1) for i in range(10))


def _group(v: int, last: bool) -> bytes:
    """Four digits of v (0..9999), the trailing zeros as NUL if no digit follows them."""
    text = b"%04d" % v
    return text.rstrip(b"0").ljust(4, b"\0") if last else text


#: four digits of 0..9999, + 10000: with trailing zeros as NUL (no nonzero digit after the
#: group), in the low half of an 8-byte word and in its high half (the 16 digits after the
#: first: the high half of word 0, word 1, the low half of word 2)
_GROUPS = _table(_group(v, last) + b"\0" * 4 for last in (0, 1) for v in range(10000))
_GROUPS_HIGH = _table(b"\0" * 4 + _group(v, last) for last in (0, 1) for v in range(10000))
#: the high half of word 2 by j (e = −99..99): ``e``, the sign, two digits; never used
#: elsewhere
_TAIL = _table(b"\0\0\0\0e%+03d" % (j - _EOFF) if -99 <= j - _EOFF <= 99 else b"\0" * 8
               for j in range(_NJ))
_COMMA, _NEWLINE = ord(","), ord("\n")
_D16, _D17 = 10 ** 16, 10 ** 17
#: 10^(17 − 15): the 15 digits are the 17 rounded to hundreds
_DROP = 100
_EXPONENT_BITS = np.int64(0x7FF0000000000000)
#: a double's 26 low fraction bits cleared: its top 27 significant bits, exact in any product
#: with a 26-bit half of 10^k
_HIGH27 = np.int64(~((1 << 26) - 1))
_LO_BITS = int(np.float64(_LO).view(np.int64))
_SPAN_BITS = np.uint64(int(np.float64(_HI).view(np.int64)) - _LO_BITS)


def _digits(a: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """round(a · 10^k) as int64 and the signed rest a · 10^k − round(...) [digits] (step 1),
    k = 16 − e, j = e + _EOFF."""
    hi, bh, bl, lo = np.take(_P10_ROWS, j, axis=0, mode="clip").T
    p = a * hi                                       # a · hi = p + err exactly (Dekker)
    ah = (a.view(np.int64) & _HIGH27).view(np.float64)
    al = a - ah
    err = ah * bh
    err -= p
    t = ah * bl
    err += t
    np.multiply(al, bh, out=t)
    err += t
    np.multiply(al, bl, out=t)
    err += t
    np.multiply(a, lo, out=t)
    err += t                                         # + a · lo: the rest yl
    # p ≈ a · 10^k ≥ 10^16 > 2^53 for the right e: an integer, y = p + err exactly.  A p
    # below 2^53 (e one too high) gives d < 10^16: out of range, and done again
    c = np.rint(err)
    d = p.astype(np.int64)
    d += c.astype(np.int64)
    err -= c
    return d, err


def _shortest(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For ``a`` with _LO ≤ a < _HI: 17 significant digits (int64, trailing digits zero when
    15 suffice), j = the decimal exponent + _EOFF (intp), and whether the text passed step 2."""
    j = np.log10(a)
    j += _EOFF                                       # > 0: truncation is the floor
    j = j.astype(np.intp)
    d, r = _digits(a, j)
    # log10 a unit off near powers of ten (or by adding _EOFF), or a rounding up to 10^17:
    # one decade over
    redo = np.flatnonzero((d - _D16).view(np.uint64) >= _D17 - _D16)
    if redo.size:
        j[redo] += (d[redo] >= _D17).astype(np.intp) - (d[redo] < _D16)
        d[redo], r[redo] = _digits(a[redo], j[redo])
        # still out of range (log10 two off: not seen) -> repr, through a rest no text passes
        bad = redo[(d[redo] < _D16) | (d[redo] >= _D17)]
        d[bad], r[bad] = _D16, np.inf
    # the threshold is known to ~1e-16 relative, the rest r to ~1e-15 digits; half the smaller
    # gap from a to a neighbouring double: half its ulp 2^(E − 52), a quarter at a power of
    # two (the gap below is half the gap above); exact
    gap = a.view(np.int64) & _EXPONENT_BITS           # 2^E, as a double's bits
    shift = np.add(gap.view(np.float64) == a, 53, dtype=np.int64)   # 54 at a power of two
    shift <<= 52
    gap -= shift
    limit = gap.view(np.float64)
    limit *= np.take(_P10_SAFE, j, mode="clip")
    limit -= _MARGIN
    q = d // _DROP
    rem = (d - _DROP * q).astype(np.float64)
    up = rem + r
    up = up > _DROP / 2                              # the 15 digits rounded to nearest
    dist = up * float(_DROP)
    dist -= rem                                      # exact: small integers
    dist -= r
    ok15 = np.abs(dist, out=dist) < limit
    q += up
    q *= _DROP
    d = np.where(ok15, q, d)                         # the 17 digits written
    carry = np.flatnonzero(d == _D17)                # 15 digits rounded up to 10^15
    d[carry] = _D16
    j[carry] += 1
    settled = np.abs(r, out=r) < limit
    settled |= ok15
    return d, j, settled


def _fill(words: np.ndarray, negative: np.ndarray, d17: np.ndarray, j: np.ndarray) -> None:
    """Write ``,[-]d.ddde±XX`` (17 digits, trailing zeros NUL, |e| ≤ 99, j = e + _EOFF) into
    rows of the (n, 3) 8-byte word array ``words`` (characters, :data:`ROW`)."""
    hi = d17 // 10 ** 8                               # the first 9 digits
    lo = hi * 10 ** 8
    np.subtract(d17, lo, out=lo)                      # the last 8
    first = hi // 10 ** 8
    t = first * 10 ** 8
    hi -= t                                           # digits 2..9
    g0 = np.floor_divide(hi, 10000, out=t)            # in four groups of four
    hi -= g0 * 10000
    g2 = lo // 10000
    lo -= g2 * 10000
    g1, g3 = hi, lo
    # a group's trailing zeros are dropped when every later group is zero: its index + 10000
    bare = g3 == 0
    g2 += np.multiply(bare, 10000, dtype=np.int64)
    bare &= g2 == 10000
    g1 += np.multiply(bare, 10000, dtype=np.int64)
    bare &= g1 == 10000
    g0 += np.multiply(bare, 10000, dtype=np.int64)
    bare &= g0 == 10000                               # no digit after the point
    g3 += 10000
    code = np.multiply(negative, 10, dtype=np.intp)
    code += first
    code += np.multiply(bare, 20, dtype=np.intp)
    np.bitwise_or(np.take(_HEAD, code, mode="clip"), np.take(_GROUPS_HIGH, g0, mode="clip"),
                  out=words[:, 0])
    np.bitwise_or(np.take(_GROUPS, g1, mode="clip"), np.take(_GROUPS_HIGH, g2, mode="clip"),
                  out=words[:, 1])
    np.bitwise_or(np.take(_GROUPS, g3, mode="clip"), np.take(_TAIL, j, mode="clip"),
                  out=words[:, 2])


def _cells_into(x: np.ndarray, words: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Each value of the 1-D float64 ``x`` as :data:`ROW` bytes of characters, ``,`` then text
    that ``float()`` reads back to the same double, bit for bit (module docstring), NUL where
    no character is, in the first ``x.size`` rows of the (≥ x.size, 3) 8-byte word array
    ``words`` (reused by :func:`format_blocks`: no fresh pages for every block).

    Returns its (x.size, ROW) uint8 view and, for a ``repr`` of 24 characters (a negative
    value of 17 digits and a three-digit exponent), (row, its last character)."""
    n = x.size
    words = words[:n]
    a = np.abs(x)
    # _LO ≤ a < _HI, on the bits (NaN's are above +inf's, zero's below _LO's)
    offset = a.view(np.int64) - _LO_BITS
    inside = offset.view(np.uint64) < _SPAN_BITS
    outside = np.flatnonzero(~inside)                 # mostly none, or a few zeros
    a[outside] = 1.0                                  # any value inside: its digits unused
    d17, j, settled = _shortest(a)
    d17[outside] = 0                                  # zeros: 0e+00 (or -0e+00)
    j[outside] = _EOFF
    settled[outside] = x[outside] == 0.0
    _fill(words, np.signbit(x), d17, j)
    chars = words.view(np.uint8)
    # NaN, ±inf, |x| outside step 1's range and what step 2 did not settle: repr, in bytes
    # 1..23 after the separator (the longest repr has 24 characters), padded with NUL
    left = np.flatnonzero(~settled)
    longer: list[tuple[int, int]] = []
    if left.size:
        texts = b"".join(repr(v).encode("ascii").ljust(24, b"\0") for v in x[left].tolist())
        text = np.frombuffer(texts, dtype=np.uint8).reshape(-1, 24)
        chars[left, 0] = _COMMA
        chars[left, 1:] = text[:, :23]
        longer = [(int(left[i]), int(text[i, 23])) for i in np.flatnonzero(text[:, 23])]
    return chars, longer


def format_values(x: np.ndarray, compiled: bool | None = None) -> list[str]:
    """Each value of ``x`` (read as float64, flattened in C order) as text that ``float()``
    reads back to the same double, bit for bit (module docstring); ``compiled``: as for
    :func:`format_blocks`."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 1)
    return format_table(x, compiled).decode("ascii").split("\n")[:-1]


def format_blocks(data: np.ndarray, compiled: bool | None = None) -> Iterator[bytes | bytearray]:
    """Rows of a 2-D array as CSV lines, ASCII (``,`` between values, ``\\n`` after each row),
    every value read back by ``float()`` as the same double, bit for bit (module docstring):
    pieces of text (bytes or bytearray) to be written one after the other.

    ``compiled``: None formats with the compiled formatter (:mod:`prsm_fmu.csv_compiled`, the
    same bytes) where it can be built, else with numpy here; False with numpy; True with the
    compiled formatter (RuntimeError saying why if it cannot be built).

    Raises ValueError (naming ``data``) for an array that is not 2-D or has no column."""
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2 or data.shape[1] == 0:
        raise ValueError(f"data: a 2-D array of at least one column expected, got shape "
                         f"{data.shape}")
    return _lines(list(data.T), data.shape[0], compiled)


def format_columns(columns: Sequence[np.ndarray],
                   compiled: bool | None = None) -> Iterator[bytes | bytearray]:
    """:func:`format_blocks` of the table whose columns are ``columns`` (1-D, as many values
    each, read as float64), without stacking them into one array first.

    Raises ValueError (naming ``columns``) for no column, one not 1-D or lengths that
    differ."""
    cols = [np.asarray(c, dtype=np.float64) for c in columns]
    shapes = {c.shape for c in cols}
    if not cols or len(shapes) != 1 or len(cols[0].shape) != 1:
        raise ValueError(f"columns: at least one column, 1-D and of one length, expected, got "
                         f"shapes {sorted(shapes)}")
    return _lines(cols, cols[0].size, compiled)


def _lines(columns: list[np.ndarray], rows: int,
           compiled: bool | None) -> Iterator[bytes | bytearray]:
    """The CSV lines of the float64 1-D ``columns`` (``rows`` values each): compiled or numpy
    (:func:`format_blocks`)."""
    if compiled is not False:
        from . import csv_compiled

        lib, why = csv_compiled.library(_compiled_constants())
        if lib is not None:
            return csv_compiled.compiled_blocks(lib, columns, rows, _BLOCK, ROW)
        if compiled:
            raise RuntimeError(why)
    return _numpy_lines(columns, rows)


def _compiled_constants() -> dict[str, int | float | np.ndarray]:
    """What the compiled formatter takes from here (:mod:`prsm_fmu.csv_compiled`: ``CSV_<name>``
    in its C): the constants and tables of steps 1–2, one definition each."""
    return {"EOFF": _EOFF, "NJ": _NJ, "ROW": ROW, "LO_BITS": _LO_BITS,
            "SPAN_BITS": int(_SPAN_BITS), "HIGH27": int(_HIGH27),
            "EXPONENT_BITS": int(_EXPONENT_BITS), "D16": _D16, "D17": _D17, "DROP": _DROP,
            "MARGIN": _MARGIN, "P10_ROWS": _P10_ROWS, "P10_SAFE": _P10_SAFE}


def _numpy_lines(columns: list[np.ndarray], rows: int) -> Iterator[bytes | bytearray]:
    """:func:`_lines` with numpy (the reference)."""
    cols = len(columns)
    # blocks of ~8000 values: the temporary arrays then stay in the CPU's cache (whole columns
    # of a long run would stream through memory for every operation)
    step = max(1, _BLOCK // cols)
    # the words' memory is a bytearray: a whole block is translated in place of a copy
    buffer = bytearray(min(rows, step) * cols * ROW)
    words = np.frombuffer(buffer, dtype=_QUAD).reshape(-1, ROW // 8)
    for r0 in range(0, rows, step):
        block = np.column_stack([c[r0:r0 + step] for c in columns])
        chars, longer = _cells_into(block.ravel(), words)
        # a line's first value: its separator (byte 0 or 1) ends the line before
        first = chars.reshape(block.shape[0], cols, ROW)[:, 0, :2]
        first[first == _COMMA] = _NEWLINE
        if r0 == 0:                                   # nothing before the first line
            first[0][first[0] == _NEWLINE] = 0
        done = 0
        for row, last in longer:                      # a repr's 24th character
            yield chars[done:row + 1].tobytes().translate(None, b"\0") + bytes([last])
            done = row + 1
        if done == 0 and chars.size == len(buffer):
            yield buffer.translate(None, b"\0")
        else:
            yield chars[done:].tobytes().translate(None, b"\0")
    if rows:
        yield b"\n"


def format_table(data: np.ndarray, compiled: bool | None = None) -> bytes:
    """:func:`format_blocks` as one bytes object."""
    return b"".join(format_blocks(data, compiled))
