"""CSV text of doubles (prsm_fmu.csv_format, system_models.output.write_csv): every value written
reads back with Python's ``float()`` as the same double, bit for bit.

The reference is Python's own correctly rounded parser, not the formatter: a value passes only if
``float(text)`` has the same 64 bits as the value written.  Cases: every double class (random bit
patterns: normal, subnormal, NaN, ±inf, ±0), doubles near powers of ten and of two (where the
decimal exponent and the digit count change), round numbers, and a scene's result written by
``write_csv`` and read back with the csv module.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from prsm_fmu.csv_format import format_table, format_values
from system_models.master import Result
from system_models.output import write_csv

#: random cases, seeded
N_BITS = 50_000


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.uint64)


def _read_back(texts: list[str]) -> np.ndarray:
    return np.array([float(t) for t in texts], dtype=np.float64)


def _same_bits(x: np.ndarray, back: np.ndarray) -> bool:
    # NaN payloads need not survive text (a NaN is written "nan"): compare NaN as NaN
    nan = np.isnan(x)
    return bool(np.array_equal(np.isnan(back), nan) and np.array_equal(_bits(x[~nan]),
                                                                      _bits(back[~nan])))


def test_random_bit_patterns_round_trip():
    rng = np.random.default_rng(20261126)
    x = rng.integers(0, 2**64, size=N_BITS, dtype=np.uint64, endpoint=False).view(np.float64)
    texts = format_values(x)
    print(f"{N_BITS} random 64-bit patterns, {int(np.isnan(x).sum())} NaN, "
          f"{int((np.abs(x) < 2.2250738585072014e-308).sum())} subnormal or zero")
    assert _same_bits(x, _read_back(texts))


def test_random_physical_magnitudes_round_trip():
    # what results hold: normal values from 1e-12 to 1e9, both signs
    rng = np.random.default_rng(7)
    n = 100_000
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-12, 9, size=n)
    print(f"{n} random values, magnitudes 1e-12..1e9")
    assert _same_bits(x, _read_back(format_values(x)))


def test_powers_of_ten_and_two_and_their_neighbours_round_trip():
    base = np.concatenate([10.0 ** np.arange(-307, 309), 2.0 ** np.arange(-1074, 1024),
                           [5e-324, 2.2250738585072014e-308, 1.7976931348623157e308]])
    with np.errstate(over="ignore"):
        x = np.concatenate([base, np.nextafter(base, 0.0), np.nextafter(base, np.inf)])
    x = x[np.isfinite(x)]
    x = np.concatenate([x, -x])
    print(f"{x.size} powers of ten and two, their neighbours, both signs")
    assert _same_bits(x, _read_back(format_values(x)))


def test_specials_and_round_numbers_are_written_plainly():
    x = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 0.1, 0.25, 3.0, 1e-5, -1234.5, 1e22])
    texts = format_values(x)
    # round numbers need few digits: the text is the shortest of 15 or 17 digits that is exact
    assert texts[:5] == ["0e+00", "-0e+00", "nan", "inf", "-inf"]
    assert [float(t) for t in texts[5:]] == [0.1, 0.25, 3.0, 1e-5, -1234.5, 1e22]
    assert texts[5:] == ["1e-01", "2.5e-01", "3e+00", "1e-05", "-1.2345e+03", "1e+22"]
    assert np.signbit(float(texts[1]))


def test_table_layout():
    data = np.array([[0.0, 1.5, -2.0], [1e-3, np.nan, 7.0]])
    assert format_table(data) == b"0e+00,1.5e+00,-2e+00\n1e-03,nan,7e+00\n"


def test_write_csv_reads_back_bit_for_bit(tmp_path):
    rng = np.random.default_rng(3)
    n = 3001
    time = np.arange(n) * 5e-5          # the macro grid: k·h
    values = {"prsm.rod_position": np.cumsum(rng.normal(size=n)) * 1e-6,
              "motor.i_q": rng.normal(size=n) * 30.0,
              "prsm.efficiency": np.where(rng.random(n) < 0.1, np.nan, rng.random(n)),
              "load.force": np.zeros(n)}
    units = {"prsm.rod_position": "m", "motor.i_q": "A", "prsm.efficiency": "1",
             "load.force": "N"}
    path = write_csv(Result(time, values, units), tmp_path / "r.csv", first=["motor.i_q"])
    with open(path, encoding="utf-8", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["time [s]", "motor.i_q [A]", "prsm.rod_position [m]",
                       "prsm.efficiency [1]", "load.force [N]"]
    back = np.array([[float(v) for v in r] for r in rows[1:]])
    assert back.shape == (n, 5)
    for j, col in enumerate([time] + [values[k] for k in
                                      ("motor.i_q", "prsm.rod_position", "prsm.efficiency",
                                       "load.force")]):
        assert _same_bits(col, back[:, j])


def test_values_where_the_exponent_gets_a_third_digit_round_trip():
    # the exponent's digits: two up to |e| = 99, three beyond (1e-100, 1e+100); 200 neighbours
    # each side of 1e-99, 2e-99, 9e99, 1e100 and 9.999...e99 (which 15 digits round up to
    # 1e+100), both signs
    edges = np.array([1e-100, 1e-99, 2e-99, 9e99, 9.9999999999999999e99, 1e100])
    x = [edges]
    for direction in (0.0, np.inf):
        y = edges.copy()
        for _ in range(200):
            y = np.nextafter(y, direction)
            x.append(y)
    x = np.concatenate(x)
    x = np.concatenate([x, -x])
    print(f"{x.size} values around the two-digit exponents' ends")
    texts = format_values(x)
    assert _same_bits(x, _read_back(texts))
    # two exponent digits where they suffice, as %e writes them
    assert format_values(np.array([1e-99, 1e99, 1e100])) == ["1e-99", "1e+99", "1e+100"]


def test_longest_texts_at_line_ends_and_block_edges():
    # repr's longest texts, 24 characters: a negative value of 17 significant digits with a
    # three-digit exponent (the smallest normal double, its neighbour, the largest double);
    # they stand first, inside and last in lines, in tables long enough to be cut into blocks
    long_ = {-2.2250738585072014e-308: "-2.2250738585072014e-308",
             -2.2250738585072019e-308: "-2.225073858507202e-308",
             -1.7976931348623157e308: "-1.7976931348623157e+308"}
    assert [len(t) for t in long_.values()] == [24, 23, 24]
    rng = np.random.default_rng(11)
    for cols in (1, 3, 60):
        rows = 20_000 // cols                       # 20 000 values: several blocks of rows
        data = rng.normal(size=(rows, cols)) * 10.0 ** rng.integers(-5, 5, size=(rows, cols))
        values = np.array(list(long_))
        at = rng.random(size=data.shape) < 0.02
        data[at] = rng.choice(values, size=int(at.sum()))
        data[0, 0], data[-1, -1] = values[0], values[2]
        text = format_table(data).decode("ascii")
        lines = text.split("\n")
        assert lines[-1] == "" and len(lines) == rows + 1
        cells = [line.split(",") for line in lines[:-1]]
        assert all(len(c) == cols for c in cells)
        for v, t in long_.items():
            assert all(cells[i][j] == t for i, j in zip(*np.nonzero(data == v)))
        back = np.array([[float(c) for c in line] for line in cells])
        print(f"{cols} columns x {rows} rows, {int(at.sum())} longest texts placed")
        assert _same_bits(data.ravel(), back.ravel())


def test_line_starts_and_ends_with_every_kind_of_value():
    # each kind first, inside and last in a line: the separator before a value and the
    # newline after a line do not depend on its sign or on how it is written
    kinds = [0.0, -0.0, 1.0, -1.0, 1.5, -1.5, np.nan, np.inf, -np.inf, 5e-324, -5e-324,
             1e-300, -1e300, 0.1, -0.30000000000000004]
    texts = ["0e+00", "-0e+00", "1e+00", "-1e+00", "1.5e+00", "-1.5e+00", "nan", "inf",
             "-inf", "5e-324", "-5e-324", "1e-300", "-1e+300", "1e-01",
             "-3.0000000000000004e-01"]
    n = len(kinds)
    for cols in (1, 2, 3):
        data = np.array([[kinds[(r + c) % n] for c in range(cols)] for r in range(n)])
        want = "".join(",".join(texts[(r + c) % n] for c in range(cols)) + "\n"
                       for r in range(n))
        assert format_table(data).decode("ascii") == want


def test_empty_and_malformed_tables():
    assert format_table(np.zeros((0, 4))) == b""
    for bad in (np.zeros((3, 0)), np.zeros(3), np.zeros((2, 2, 2))):
        with pytest.raises(ValueError, match=r"data: a 2-D array of at least one column"):
            format_table(bad)


def test_ties_of_fifteen_digits_round_trip():
    # a 15-digit decimal exactly halfway between two doubles: m = o · 10^p with o odd, 15
    # digits, and o · 5^p odd in [2^53, 2^54), so m = (o · 5^p) · 2^p lies in [2^(53+p),
    # 2^(54+p)) where doubles are 2^(p+1) apart: an odd multiple of 2^p, halfway between the
    # doubles m − 2^p and m + 2^p.  Only p = 2 (o from 2^53/25 = 3.6e14) and p = 3 (o up to
    # 2^54/125 = 1.44e14) leave 15-digit o.  float() of the 15-digit text rounds half to even:
    # it gives back one neighbour only, so each neighbour's text must be the one that reads
    # back
    rng = np.random.default_rng(15)
    x = []
    for p in (2, 3):
        lo = max(-(-2**53 // 5**p), 10**14)
        hi = min(2**54 // 5**p, 10**15)
        o = rng.integers(lo, hi, size=2000) | 1
        mid = (o * 10**p).tolist()                       # exact integers (< 2^63)
        below = np.array([float(m - 2**p) for m in mid])
        above = np.array([float(m + 2**p) for m in mid])
        assert [int(v) for v in below] == [m - 2**p for m in mid]     # doubles, exactly
        assert np.array_equal(np.nextafter(below, np.inf), above)     # neighbours
        x += [below, above]
    x = np.concatenate(x)
    x = np.concatenate([x, -x])
    print(f"{x.size} neighbours of 15-digit ties, both signs")
    assert _same_bits(x, _read_back(format_values(x)))
