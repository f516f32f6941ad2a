"""The sweep's progress bar (prsm_fmu.sweep.execute): points done, failed, time left.

The Dask runs themselves (1 and 2 workers giving byte-identical tables) are in
tests/test_sweep.py.
"""

from __future__ import annotations

import io

from prsm_fmu.sweep.execute import Progress, eta


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
