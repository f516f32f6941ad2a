"""A point's series file (prsm_fmu.sweep.series_files): the ``.npz`` laid out in memory
(prsm_fmu.sweep.npz_bytes) reads back through ``numpy.load`` exactly as ``numpy.savez``'s file
of the same arrays does, and is written whole or not at all (prsm_fmu.atomic.write_atomic)."""

from __future__ import annotations

import os
import zipfile

import numpy as np
import pytest

from prsm_fmu.atomic import write_atomic
from prsm_fmu.sweep.npz_bytes import npz_chunks
from prsm_fmu.sweep.series_files import load_series, save_series, series_path

#: seeded random sets of arrays tried against numpy.savez
N_CASES = 60

_DTYPES = ("<f8", ">f8", "<f4", "<i8", ">i4", "|u1", "|b1", "<c16")


def _random_array(rng: np.random.Generator) -> np.ndarray:
    dtype = np.dtype(_DTYPES[rng.integers(len(_DTYPES))])
    shape = tuple(int(n) for n in rng.integers(0, 6, size=rng.integers(0, 4)))
    raw = np.asarray(rng.standard_normal(shape) * 10.0 ** rng.integers(-300, 300))
    if dtype.kind == "f" and raw.size:
        # the values a series holds besides ordinary ones: NaN, ±inf, −0.0
        flat = raw.reshape(-1)
        flat[rng.integers(flat.size)] = rng.choice([np.nan, np.inf, -np.inf, -0.0])
    if dtype.kind == "c":
        arr = np.asarray((raw + 1j * np.flip(raw)).astype(dtype))
    else:
        with np.errstate(all="ignore"):
            arr = raw.astype(dtype)
    layout = rng.integers(3)
    if layout == 1 and arr.ndim >= 2:
        arr = np.asfortranarray(arr)          # stored with fortran_order: True
    elif layout == 2 and arr.ndim >= 1 and arr.shape[0] > 1:
        arr = arr[::2]                         # not contiguous: stored in C order
    return arr


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Same dtype, shape and values (NaN equal to NaN, −0.0 told from 0.0)."""
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind in "fc":
        parts = (a.real, b.real), (a.imag, b.imag)
        return all(np.array_equal(x, y, equal_nan=True)
                   and np.array_equal(np.signbit(x), np.signbit(y)) for x, y in parts)
    return bool(np.array_equal(a, b))


def test_the_file_reads_back_as_numpy_savez_file_does(tmp_path):
    """60 seeded random sets of 1-8 arrays (dtypes of both byte orders, 0-3 dimensions, empty
    and 0-d arrays, Fortran-ordered and non-contiguous ones, NaN, ±inf, −0.0): numpy.load gives
    the same names in the same order, dtypes, shapes and values from the file save_series
    writes as from numpy.savez's; every member's CRC-32 checks and is stored uncompressed."""
    rng = np.random.default_rng(20261127)
    laid_out = 0
    for case in range(N_CASES):
        arrays = {f"s{case}_{j}[{j}].x": _random_array(rng)
                  for j in range(int(rng.integers(1, 9)))}
        laid_out += npz_chunks(arrays) is not None
        path = save_series(str(tmp_path), f"p{case}", arrays)
        assert path == series_path(str(tmp_path), f"p{case}")
        ref = tmp_path / f"ref{case}.npz"
        np.savez(ref, **arrays)
        with np.load(path) as new, np.load(ref) as old:
            assert new.files == old.files == list(arrays)
            for name in new.files:
                assert _same(new[name], old[name]), (case, name)
                assert _same(new[name], arrays[name]), (case, name)
        with zipfile.ZipFile(path) as z:
            assert z.testzip() is None
            assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_STORED}
    print(f"{N_CASES} random cases, {laid_out} laid out in memory")
    assert laid_out == N_CASES                # none of them needed numpy.savez
    assert sorted(os.listdir(tmp_path)) == sorted(
        [f"p{c}.npz" for c in range(N_CASES)] + [f"ref{c}.npz" for c in range(N_CASES)])


def test_a_sweep_points_series_round_trip(tmp_path):
    """The start-up study's shape: 24 float64 series of 1001 samples; load_series gives them
    back equal, in order."""
    rng = np.random.default_rng(7)
    series = {f"stage[{k}].signal{i}": rng.standard_normal(1001) for k in (1, 2)
              for i in range(12)}
    assert npz_chunks(series) is not None
    os.mkdir(tmp_path / "series")
    save_series(str(tmp_path / "series"), "abc", series)
    back = load_series(str(tmp_path), "abc")
    assert list(back) == list(series)
    assert all(_same(back[k], series[k]) for k in series)


@pytest.mark.parametrize("arrays", [
    {"obj": np.array([{"a": 1}, None], dtype=object)},      # pickled by numpy.savez
    {"größe": np.arange(3.0)},                               # a name that is not ASCII
    {"listed": [1.0, 2.0]},                                  # not an ndarray
], ids=["object", "non-ascii", "list"])
def test_what_cannot_be_laid_out_goes_through_numpy_savez(tmp_path, arrays):
    assert npz_chunks(arrays) is None
    path = save_series(str(tmp_path), "p", arrays)
    with np.load(path, allow_pickle=True) as z:
        assert z.files == list(arrays)
        for name in z.files:
            expected = np.asarray(arrays[name])
            if expected.dtype.hasobject:
                assert list(z[name]) == list(expected)
            else:
                assert _same(z[name], expected)


def test_write_atomic_leaves_the_old_file_or_none_on_failure(tmp_path):
    """A failure while the content is produced leaves the previous file as it was and no
    temporary file."""
    target = tmp_path / "a.npz"
    write_atomic(target, [b"old"])

    def failing():
        yield b"new"
        raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError, match="interrupted"):
        write_atomic(target, failing())
    assert target.read_bytes() == b"old"
    with pytest.raises(RuntimeError, match="interrupted"):
        write_atomic(tmp_path / "b.npz", failing())
    assert sorted(os.listdir(tmp_path)) == ["a.npz"]
