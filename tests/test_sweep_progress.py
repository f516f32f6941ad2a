"""The sweep's chunks of points and its progress bar (prsm_fmu.sweep.execute).

The Dask runs themselves (chunks on 1 and 2 workers giving byte-identical tables) are in
tests/test_sweep.py.
"""

from __future__ import annotations

import io
import math

from prsm_fmu.sweep.execute import Progress, chunk_size, eta


def test_chunks_keep_every_worker_busy_and_cover_every_point():
    cases = 0
    for workers in range(1, 5):
        for n in range(1, 201):
            size = chunk_size(n, workers)
            chunks = math.ceil(n / size)
            # at least four chunks per worker when there are enough points, else one per point
            assert size >= 1 and chunks >= min(n, 4 * workers), (n, workers, size)
            cases += 1
    print(f"{cases} (points, workers) cases")
    # 24 points of the start-up study on 2 workers: 8 chunks of 3 (24 // (2 × 4) = 3)
    assert chunk_size(24, 2) == 3


def test_time_left_at_the_rate_so_far():
    # 2 of 10 points in 10 s: 5 s a point, 8 left -> 40 s
    assert eta(10.0, 2, 10) == 40.0
    assert eta(10.0, 0, 10) is None and eta(10.0, 10, 10) is None


def test_progress_bar_shows_done_failed_and_time_left():
    out = io.StringIO()                      # not a terminal: a line every 10 %
    bar = Progress(4, 0, out)
    bar.update(True)
    bar.update(False)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("[") and "0/4 points, 0 failed" in lines[0]
    assert "2/4 points, 1 failed" in lines[-1] and "s left" in lines[-1]
    bar.update(True)
    bar.update(True)
    assert "4/4 points, 1 failed" in out.getvalue().splitlines()[-1]
    assert "left" not in out.getvalue().splitlines()[-1]
