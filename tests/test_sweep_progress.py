"""The sweep's chunks of points and its progress bar (prsm_fmu.sweep.execute): points done,
failed, time left.

The Dask runs themselves (1 and 2 workers giving byte-identical tables) are in
tests/test_sweep.py.
"""

from __future__ import annotations

import io
import math

from prsm_fmu.sweep.execute import Progress, chunk_size, eta


def test_time_left_at_the_rate_so_far():
    # 2 of 10 points in 10 s: 5 s a point, 8 left -> 40 s
    assert eta(10.0, 2, 10) == 40.0
    assert eta(10.0, 0, 10) is None and eta(10.0, 10, 10) is None


def test_progress_bar_shows_done_failed_and_time_left():
    out = io.StringIO()                      # not a terminal: a line every 10 %
    bar = Progress(4, 0, out)
    bar.update(1)
    bar.update(0, 1)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("[") and "0/4 points, 0 failed" in lines[0]
    assert "2/4 points, 1 failed" in lines[-1] and "s left" in lines[-1]
    bar.update(1)
    bar.update(1)
    assert "4/4 points, 1 failed" in out.getvalue().splitlines()[-1]
    assert "left" not in out.getvalue().splitlines()[-1]


def test_chunks_hold_two_cpu_seconds_and_shrink_to_single_points_at_the_end():
    # the start-up study on the model backend, ~6 ms of CPU a point, 10000 left on 2 workers:
    # 2 s / 6 ms = 333.3 -> 333 points (guided bound 10000 // (2 x 2) = 2500 is larger)
    assert chunk_size(10000, 2, 0.006) == 333
    # 1000 left: the guided bound 1000 // 4 = 250 is smaller than 333
    assert chunk_size(1000, 2, 0.006) == 250
    # on the FMU backend, ~0.12 s of CPU a point: 2 / 0.12 = 16.7 -> 16; 0.6 s: 3.3 -> 3;
    # 2.5 s: 0.8 -> a point of its own
    assert chunk_size(1000, 2, 0.12) == 16
    assert chunk_size(1000, 2, 0.6) == 3
    assert chunk_size(1000, 2, 2.5) == 1
    # towards the end the guided bound, but not below 0.1 s of CPU: at 0.12 s a point the
    # floor is 0.1 / 0.12 = 0.83 -> none, so 20 left on 2 workers -> 20 // 4 = 5, 7 left -> 1
    assert chunk_size(20, 2, 0.12) == 5
    assert chunk_size(7, 2, 0.12) == 1
    # at 6 ms a point the floor is 0.1 / 0.006 = 16.7 -> 16 points: 20 left -> 16 (not
    # 20 // 4 = 5), 7 left -> all 7 (not a tail of single points); at 8 ms: 12.5 -> 12
    assert chunk_size(20, 2, 0.006) == 16
    assert chunk_size(7, 2, 0.006) == 7
    assert chunk_size(30, 2, 0.008) == 12
    # before the first result, or with a time that says nothing: one point
    for seconds in (None, 0.0, -1.0, math.nan):
        assert chunk_size(1000, 2, seconds) == 1
    assert chunk_size(1000, 2, math.inf) == 1


def test_chunks_are_never_empty_nor_beyond_the_guided_bound_but_for_the_floor():
    """Never empty, never more than the points left, and beyond the guided bound (the points
    left / (2 × workers)) only by the floor: then at most 0.1 s of CPU in all."""
    cases = 0
    for workers in range(1, 5):
        for remaining in range(1, 301):
            for seconds in (1e-5, 1e-3, 6e-3, 0.05, 0.3, 3.0):
                size = chunk_size(remaining, workers, seconds)
                assert 1 <= size <= remaining, (remaining, workers, seconds)
                if size > max(1, remaining // (2 * workers)):
                    assert size * seconds <= 0.1 * (1 + 1e-12), (remaining, workers, seconds)
                cases += 1
    print(f"{cases} (points left, workers, seconds per point) cases")
