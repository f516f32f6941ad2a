"""The compiled CSV formatter (prsm_fmu/native/csv_format.c through prsm_fmu.csv_compiled) gives
the same bytes as the numpy reference (prsm_fmu.csv_format), and the reference writes where gcc
is missing.

"One engine, one reference": the same tables are written by both paths and compared byte for
byte, on seeded random cases chosen to reach every branch of the algorithm (the module
docstring of prsm_fmu.csv_format): random bit patterns (every class of double), random
decimal-looking values of 1 to 17 significant digits (the 15-digit texts, the 17-digit ones,
the trailing zeros of every length), 15-digit decimals near the middle between two doubles
(where step 2 decides by a hair), exact 15-digit ties, powers of ten and of two and their
neighbours (the decade's first guess and its correction, the 15 digits rounding up to the next
decade), subnormals, ±0, ±inf, NaN with payloads and signs, values around the ends of the
two-digit exponents (2e-99, 9e99), negative 17-digit values with three-digit exponents (repr's
longest texts), and tables of 1..N rows and columns cut at and around the blocks' edges.  How
many values of each kind were compared is printed; each kind must be present (a test that
reaches no case of a branch does not pass).  Every text also reads back with ``float()`` as the
same double (tests/test_csv_format.py checks the reference the same way).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

from fractions import Fraction

import numpy as np
import pytest

from prsm_fmu import csv_format
from prsm_fmu.csv_format import format_blocks, format_columns, format_table

#: random values per kind, seeded (a million values take a few seconds on each path)
N_DECIMAL = 1_000_000
N_NEAR_MIDDLES = 1_000_000
NEAR = 1e-3
N_BITS = 300_000

pytestmark = pytest.mark.skipif(
    __import__("prsm_fmu.csv_compiled", fromlist=["library"]).library(
        csv_format._compiled_constants())[0] is None,
    reason="no compiled formatter here (no gcc): the numpy path alone writes")


def _both(data: np.ndarray) -> tuple[bytes, bytes]:
    return format_table(data, compiled=True), format_table(data, compiled=False)


def _same_bits_read_back(x: np.ndarray, text: bytes) -> bool:
    back = np.array([float(t) for t in text.decode("ascii").split()], dtype=np.float64)
    nan = np.isnan(x)
    return bool(np.array_equal(np.isnan(back), nan)
                and np.array_equal(x[~nan].view(np.uint64), back[~nan].view(np.uint64)))


def _decimals(rng: np.random.Generator, n: int) -> np.ndarray:
    """Doubles nearest to random decimals m · 10^p, m of 1 to 17 digits (uniform count), p
    such that the exponent lies in −110..110, both signs: parsed from their text by float()."""
    digits = rng.integers(1, 18, size=n)
    m = rng.integers(10 ** (digits - 1), 10 ** digits, dtype=np.int64).tolist()
    p = (rng.integers(-110, 110, size=n) - digits).tolist()
    sign = np.where(rng.random(n) < 0.5, "-", "").tolist()
    return np.array([float(f"{s}{v}e{q}") for s, v, q in zip(sign, m, p)])


def _near_middles(rng: np.random.Generator, n: int, window: float) -> tuple[np.ndarray, int]:
    """Doubles nearest to random 15-digit decimals that lie within ``window`` (in units of the
    gap to the neighbouring double on their side) of the middle between two doubles, both
    signs — where step 2 decides between 15 and 17 digits by a hair; a random decimal lands
    there about once in 1 / (2 · window).  Returns them and how many landed."""
    m = rng.integers(10 ** 14, 10 ** 15, size=n, dtype=np.int64)
    p = rng.integers(-60, 60, size=n)
    x = np.array([float(f"{v}e{q}") for v, q in zip(m.tolist(), p.tolist())])
    # pre-selection in 80-bit arithmetic (~1e-19 relative: ~1e-3 of a gap), then exact
    # rational arithmetic on the candidates
    dec = np.longdouble(m) * np.longdouble(10) ** p
    toward = np.nextafter(x, np.where(dec > x, np.inf, -np.inf))
    approx = np.abs((dec - x) / (toward.astype(np.longdouble) - x))
    kept = []
    for i in np.flatnonzero(np.abs(approx - 0.5) < 10 * window).tolist():
        exact = Fraction(int(m[i])) * Fraction(10) ** int(p[i])
        gap = abs(Fraction(float(toward[i])) - Fraction(float(x[i])))
        if abs(abs(exact - Fraction(float(x[i]))) / gap - Fraction(1, 2)) < Fraction(window):
            kept.append(i)
    y = x[kept]
    return np.concatenate([y, -y]), len(kept)


def _constructed_near_ties(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """15-digit decimals D = m · 10^p at a chosen hair from the middle M between two doubles,
    and the doubles on both sides of M; returns the doubles and (D − M) / gap for each.

    By construction: M = odd · 2^(t+p) and gap = 2^(t+p+1) where D lies in [2^(53+t+p),
    2^(54+t+p)), so D − M = j · 2^p exactly when m · 5^p = 2^t · odd + j, i.e.
    m ≡ (2^t + j) · 5^(−p) (mod 2^(t+1)): (D − M) / gap = j / 2^(t+1).  With t = 30..62 and
    |j| up to 10^4 the hair runs from ~1e-19 to ~1e-6 of a gap — across step 2's margin
    (1e-12), which random decimals reach once in ~10^12."""
    xs, hairs = [], []
    for t in range(30, 63):
        for p in range(1, 60):
            lo, hi = 2 ** (53 + t) // 5 ** p + 1, 2 ** (54 + t) // 5 ** p   # m · 5^p in range
            lo, hi = max(lo, 10 ** 14), min(hi, 10 ** 15 - 1)               # 15 digits
            if lo > hi:
                continue
            inverse = pow(5 ** p, -1, 2 ** (t + 1))
            for j in rng.integers(1, 10 ** 4, size=12).tolist():
                for jj in (j, -j):
                    m0 = (2 ** t + jj) * inverse % 2 ** (t + 1)
                    first = m0 + -(-(lo - m0) // 2 ** (t + 1)) * 2 ** (t + 1)
                    for m in range(first, hi + 1, 2 ** (t + 1)):
                        d = m * 10 ** p
                        x = float(d)                  # correctly rounded: D's side of M
                        other = np.nextafter(x, -np.inf if x > d else np.inf)
                        xs += [x, float(other)]
                        hairs += [jj / 2 ** (t + 1)] * 2
                        break                         # one m per (t, p, j)
    x = np.array(xs)
    return np.concatenate([x, -x]), np.concatenate([hairs, hairs])


def _ties(rng: np.random.Generator, n: int) -> np.ndarray:
    """Both neighbours of 15-digit decimals exactly halfway between two doubles (the
    construction of tests/test_csv_format.py: o · 10^p, o odd, o · 5^p in [2^53, 2^54))."""
    out = []
    for p in (2, 3):
        lo, hi = max(-(-2 ** 53 // 5 ** p), 10 ** 14), min(2 ** 54 // 5 ** p, 10 ** 15)
        for o in (rng.integers(lo, hi, size=n) | 1).tolist():
            mid = o * 10 ** p
            out += [float(mid - 2 ** p), float(mid + 2 ** p)]
    x = np.array(out)
    return np.concatenate([x, -x, x * 1e-40, x * 1e40])   # scaled: other decades, not ties


def _neighbours(base: np.ndarray, k: int) -> np.ndarray:
    out = [base]
    up, down = base.copy(), base.copy()
    with np.errstate(over="ignore"):
        for _ in range(k):
            up, down = np.nextafter(up, np.inf), np.nextafter(down, 0.0)
            out += [up, down]
    x = np.concatenate(out)
    x = x[np.isfinite(x)]
    return np.concatenate([x, -x])


def _edges() -> np.ndarray:
    """Powers of ten and two and 3 neighbours each side; 200 each side of the two-digit
    exponents' ends; 15-digit roundings up to the next decade (9.999999999999999e+n)."""
    powers = np.concatenate([10.0 ** np.arange(-320, 309), 2.0 ** np.arange(-1074, 1024)])
    ends = np.array([1e-100, 1e-99, 2e-99, 9e99, 9.9999999999999999e99, 1e100])
    carries = np.array([float(f"9.99999999999999{d}e{e}") for e in range(-99, 100)
                        for d in range(5, 10)])
    return np.concatenate([_neighbours(powers, 3), _neighbours(ends, 200),
                           _neighbours(carries, 2)])


def _specials(rng: np.random.Generator) -> np.ndarray:
    payloads = rng.integers(1, 2 ** 51, size=50, dtype=np.uint64)
    nans = np.concatenate([(np.uint64(0x7FF8000000000000) | payloads),
                           (np.uint64(0xFFF0000000000000) | payloads)]).view(np.float64)
    subnormal = rng.integers(1, 2 ** 52, size=2000, dtype=np.uint64).view(np.float64)
    longest = -np.array([float(f"1.{v:016d}e{e}") for v, e in zip(
        rng.integers(0, 10 ** 16, size=2000, dtype=np.int64).tolist(),
        rng.choice(np.r_[-307:-99, 100:308], size=2000).tolist())])
    return np.concatenate([[0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -5e-324,
                            2.2250738585072014e-308, 1.7976931348623157e308], nans,
                           subnormal, -subnormal, longest])


def _kinds(x: np.ndarray) -> dict[str, int]:
    """How many values of x fall on each branch (the reference's own steps, counted)."""
    a = np.abs(x)
    inside = (a >= csv_format._LO) & (a < csv_format._HI)
    d, _, settled = csv_format._shortest(np.where(inside, a, 1.0))
    d, settled = d[inside], settled[inside]
    texts = [t for t, i in zip(csv_format.format_values(x[inside], compiled=False),
                               inside[inside]) if i]
    digits = np.array([len(t.split("e")[0].lstrip("-").replace(".", "")) for t in texts])
    # 15 digits rounded up to the next decade: the text 1e±XX, 10^XX above the value (the
    # double nearest to 10^XX, below it: e.g. 1e+23)
    carry = np.array([t.lstrip("-")[:2] == "1e" and Fraction(10) ** int(t.split("e")[1]) > v
                      for t, v in zip(texts, a[inside].tolist())], dtype=bool)
    return {"zero": int((x == 0).sum()), "nan": int(np.isnan(x).sum()),
            "inf": int(np.isinf(x).sum()),
            "outside the two-digit exponents (repr)": int((~inside & np.isfinite(x)
                                                           & (x != 0)).sum()),
            "not settled by step 2 (repr)": int((~settled).sum()),
            "15 digits or fewer": int((settled & (d % 100 == 0)).sum()),
            "17 digits": int((settled & (d % 100 != 0)).sum()),
            "1 digit (no point)": int((settled & (digits == 1)).sum()),
            "2..9 digits (last 8 all zeros)": int((settled & (digits >= 2) & (digits <= 9)).sum()),
            "15 digits rounded up to the next decade": int((settled & carry).sum()),
            "negative": int((np.signbit(x) & ~np.isnan(x)).sum())}


def test_compiled_and_numpy_write_the_same_bytes_on_every_kind_of_value():
    rng = np.random.default_rng(20261127)
    bits = rng.integers(0, 2 ** 64, size=N_BITS, dtype=np.uint64, endpoint=False).view(np.float64)
    near, landed = _near_middles(rng, N_NEAR_MIDDLES, NEAR)
    constructed, hairs = _constructed_near_ties(rng)
    parts = {"random bit patterns": bits,
             "decimals of 1..17 digits": _decimals(rng, N_DECIMAL),
             "15-digit decimals near a middle": near,
             "neighbours of 15-digit ties": _ties(rng, 2000),
             "constructed 15-digit near-ties, 1e-19..1e-6 of a gap": constructed,
             "powers, their neighbours, exponent ends": _edges(),
             "specials, subnormals, longest texts": _specials(rng)}
    total = 0
    for name, x in parts.items():
        x = rng.permutation(x)
        kinds = _kinds(x)
        compiled, numpy_ = _both(x.reshape(-1, 1))
        print(f"{name}: {x.size} values, {kinds}")
        assert compiled == numpy_, name
        assert _same_bits_read_back(x, compiled), name
        total += x.size
    print(f"{total} values compared in all; {landed} of {N_NEAR_MIDDLES} random 15-digit "
          f"decimals within {NEAR} of a middle")
    assert landed > 0
    print(f"constructed near-ties: {constructed.size} doubles, hairs from "
          f"{np.abs(hairs).min():.1e} to {np.abs(hairs).max():.1e} of a gap, "
          f"{int((np.abs(hairs) < 1e-11).sum())} below 1e-11")
    every = _kinds(np.concatenate(list(parts.values())))
    # every branch reached but one: 17 correctly rounded digits are off by |r| <= 0.5 unit of
    # the 17th digit, and half the gap to a neighbouring double is at least 0.55 of that unit
    # (relative gap >= 2^-53 at a power of two, times a · 10^k >= 10^16: 1.11, halved), so step
    # 2 settles every 17-digit text of a value inside the range; its "not settled" branch is a
    # guard, the same in both paths, that no double takes
    assert every.pop("not settled by step 2 (repr)") == 0
    assert all(every.values()), every


def test_tables_of_every_shape_and_block_edge():
    # 1..70 columns; rows such that a table ends just before, at and just after a block of
    # rows (csv_format._BLOCK values) and the C's chunks of 256 values; the values mixed as
    # in a result (zeros, NaN, 15- and 17-digit, longest texts)
    rng = np.random.default_rng(11)
    pool = np.concatenate([rng.normal(size=4000) * 10.0 ** rng.integers(-12, 9, size=4000),
                           np.round(rng.normal(size=2000), 3), np.zeros(500), [np.nan] * 50,
                           [-2.2250738585072014e-308, -1.7976931348623157e308, 1e-300]])
    tables = 0
    for cols in list(range(1, 71)):
        step = max(1, csv_format._BLOCK // cols)
        for rows in sorted({1, 2, 3, step - 1, step, step + 1, 2 * step + 1,
                            max(1, 256 // cols), 256 // cols + 1}):
            if rows < 1:
                continue
            data = rng.choice(pool, size=(rows, cols))
            compiled, numpy_ = _both(data)
            assert compiled == numpy_, (rows, cols)
            tables += 1
    print(f"{tables} tables of 1..70 columns compared")
    assert tables > 400


def test_columns_and_strided_arrays_write_as_the_stacked_table():
    rng = np.random.default_rng(5)
    a = rng.normal(size=(3001, 7)) * 1e3
    a[::17, 3] = np.nan
    want = format_table(np.ascontiguousarray(a), compiled=False)
    assert b"".join(format_columns([a[:, c] for c in range(7)], compiled=True)) == want
    assert b"".join(format_columns([a[:, c].copy() for c in range(7)], compiled=False)) == want
    assert format_table(np.asfortranarray(a), compiled=True) == want
    wide = np.zeros((3001, 14))
    wide[:, ::2] = a                                   # every other column: rows 112 bytes apart
    assert format_table(wide[:, ::2], compiled=True) == want
    assert b"".join(format_blocks(a[::-1][::-1], compiled=True)) == want
    # rows read backwards (negative strides) and a broadcast column (stride 0)
    assert format_table(a[::-1], compiled=True) == format_table(a[::-1].copy(), compiled=False)
    same = np.broadcast_to(1.5, a.shape[0])
    assert (b"".join(format_columns([same, a[:, 0]], compiled=True))
            == format_table(np.column_stack([np.full(a.shape[0], 1.5), a[:, 0]]),
                            compiled=False))


def test_columns_of_other_lengths_or_shapes_are_refused():
    with pytest.raises(ValueError, match=r"columns: at least one column, 1-D and of one length"):
        format_columns([np.zeros(3), np.zeros(4)])
    with pytest.raises(ValueError, match=r"columns: at least one column"):
        format_columns([])
    with pytest.raises(ValueError, match=r"columns: .*1-D"):
        format_columns([np.zeros((2, 2))])


def test_without_gcc_the_numpy_path_writes_the_same_text(tmp_path):
    # a process whose PATH has no gcc and whose temporary directory holds no library built
    # before: the compiled formatter cannot be built, the reference writes; asking for the
    # compiled one says why
    empty = tmp_path / "bin"
    empty.mkdir()
    code = textwrap.dedent("""
        import numpy as np, pytest
        from prsm_fmu import csv_compiled, csv_format
        lib, why = csv_compiled.library(csv_format._compiled_constants())
        assert lib is None and "gcc" in why, why
        data = np.array([[0.0, 1.5, -2.0], [1e-3, np.nan, 7.0], [0.1, -np.inf, 5e-324]])
        # by hand: 15 digits where they suffice, %e style, repr for NaN, inf, subnormals
        assert csv_format.format_table(data) == (
            b"0e+00,1.5e+00,-2e+00\\n1e-03,nan,7e+00\\n1e-01,-inf,5e-324\\n")
        with pytest.raises(RuntimeError, match="gcc"):
            csv_format.format_table(data, compiled=True)
        print("numpy path ok")
    """)
    env = dict(os.environ, PATH=str(empty), TMPDIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "numpy path ok" in out.stdout


def test_the_c_source_is_package_data():
    # an installed (non-editable) wheel carries only the package data that pyproject lists:
    # the C source must match one of prsm_fmu's patterns (checked by hand too: a wheel built
    # with pip wheel and installed with pip --target builds and loads the library)
    import fnmatch
    import tomllib
    from pathlib import Path

    import prsm_fmu.csv_compiled as cc

    root = Path(__file__).resolve().parents[1]
    data = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = data["tool"]["setuptools"]["package-data"]["prsm_fmu"]
    source = cc._SOURCE.relative_to(root / "prsm_fmu").as_posix()
    assert source == "native/csv_format.c"
    assert any(fnmatch.fnmatch(source, p) for p in patterns), patterns
