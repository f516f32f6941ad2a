"""A point's time series on disk: ``OUT/series/<id>.npz``, one array per series.

Written where the point ran (a worker of a local cluster, or the study's process for the
``loop`` executor and for workers that do not share its file system), so that saving a point
costs the study's own process nothing.  The arrays are stored uncompressed (``numpy.savez``):
zlib finds little to take out of float64 series (the start-up study's 24 series of 1001
samples: 192 kB raw, 114 kB compressed) and compressing them cost more than the point's
simulation (about 20 ms against 4 ms, benchmarks/sweep_scaling.py); ``numpy.load`` reads
either.  The file is the one ``numpy.savez`` writes, laid out in memory
(:func:`~prsm_fmu.sweep.npz_bytes.npz_chunks`) and written with one open, write and rename:
``numpy.savez`` through :mod:`zipfile` cost about a tenth of a point's CPU
(benchmarks/point_cost.py); values it cannot lay out go through ``numpy.savez``.
"""

from __future__ import annotations

import os
from typing import Mapping

import numpy as np

from ..atomic import atomic_path, write_atomic
from .npz_bytes import npz_chunks

__all__ = ["series_path", "save_series", "load_series"]


def series_path(series_dir: str, point_id: str) -> str:
    """The file of point ``point_id``'s series in ``series_dir``."""
    return os.path.join(series_dir, f"{point_id}.npz")


def save_series(series_dir: str, point_id: str, series: Mapping[str, np.ndarray]) -> str:
    """Write a point's series (atomically: a reader never sees half a file); its path."""
    path = series_path(series_dir, point_id)
    chunks = npz_chunks(series)
    if chunks is not None:
        write_atomic(path, chunks)
        return path
    with atomic_path(path) as tmp:
        np.savez(tmp, **series)
    return path


def load_series(out_dir: str, point_id: str) -> dict[str, np.ndarray] | None:
    """The saved series of a point of the study in ``out_dir``, or None."""
    path = series_path(os.path.join(out_dir, "series"), point_id)
    if not os.path.exists(path):
        return None
    with np.load(path) as z:
        return {k: z[k] for k in z.files}
