"""``benchmarks/work_precision.py --replot``: a scene's chart redrawn from its CSV alone, through
the same ``plot()`` (checked on the Figure object, caught when saved; no pixels, no run).

* a CSV in the format of the stored docs/figures/wp_*.csv (no ``reference_difference``
  column): the chart's title is the scene's current one, every ok row is one plotted point,
  the failed row none, and the floor is the documented one;
* a CSV written by ``write_csv`` (which now stores the floor) reads back as written.
"""

from __future__ import annotations

import math
import re

import pytest

from benchmark_modules import load_benchmark

wp = load_benchmark("work_precision")

HEADER = ("scene,fidelity,stepper,knob,value,status,error,cpu_s_per_sim_s,rhs_calls,"
          "rhs_per_sim_s,pareto,cheapest_at_1e-06,err:a,err:b\n")
#: four ok rows (two series of the dynamic level, one slaved point), one failed
ROWS = """\
startup,dynamic,rk4,substeps,1,ok,2.0e-05,2.0e+00,400,4e+05,1,0,2.0e-05,1.0e-06
startup,dynamic,rk4,substeps,2,ok,1.0e-07,4.0e+00,800,8e+05,0,0,1.0e-07,1.0e-08
startup,dynamic,rosenbrock_native,rtol,1e-06,ok,7.0e-07,3.0e-01,1200,1.2e+06,1,1,7.0e-07,1.0e-07
startup,quasi-static,closed_form,,0,ok,1.0e+00,1.5e+00,100,1e+05,0,0,1.0e+00,0.0e+00
startup,dynamic,explicit_adaptive,rtol,1e-03,"failed: step size, too small",nan,nan,0,nan,0,0,nan,nan
"""


@pytest.fixture()
def saved(monkeypatch):
    """Figures saved while active, by file name (not rendered)."""
    from matplotlib.figure import Figure

    figs: dict[str, Figure] = {}

    def spy(self, fname, *args, **kwargs):
        figs[str(fname).rsplit("/", 1)[-1]] = self

    monkeypatch.setattr(Figure, "savefig", spy)
    return figs


def _plotted_points(ax) -> int:
    """The configurations' markers on an axes (the series' small markers; the Pareto rings,
    the star and the lines are other Line2D objects)."""
    markers = set(wp.FIDELITY_MARKER.values())
    return sum(len(line.get_xdata()) for line in ax.get_lines()
               if line.get_marker() in markers and line.get_markersize() == 5)


def test_replot_from_a_stored_format_csv(tmp_path, saved):
    (tmp_path / "wp_startup.csv").write_text(HEADER + ROWS, encoding="utf-8")
    wp.main(["--replot", "--scene", "startup", "--out", str(tmp_path)])
    fig = saved["wp_startup.png"]
    title = fig._suptitle.get_text()
    assert title == wp.SCENES["startup"].title
    assert title.startswith("Li et al. (2021) start-up") and "seed" not in title
    n_ok = sum(1 for row in ROWS.splitlines() if ",ok," in row)
    assert n_ok == 4
    for ax in fig.axes:
        assert _plotted_points(ax) == n_ok
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "ROS34PW2 in C (the engine both FMUs run, rtol)" in labels
    assert not any("native FMU" in lab for lab in labels)
    # the star marks the row flagged cheapest
    right = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert any("cheapest at error ≤ 1e-06: dynamic rosenbrock_native rtol 1e-06" in t for t in right)
    # no floor column: the documented one (docs/accuracy.md §1)
    result = wp.read_csv(tmp_path / "wp_startup.csv")
    assert result["reference_difference"] == wp.LEGACY_REFERENCE_DIFFERENCE["startup"] == 6e-13


def test_write_csv_stores_the_floor_and_reads_back(tmp_path):
    scene = wp.SCENES["startup"]
    pts = [wp.Point(wp.Config("dynamic", "rk4", "substeps", 4), "ok", 3e-8,
                    {o: 3e-8 for o in scene.outputs}, 5.0, 1.6e6, 1600),
           wp.Point(wp.Config("dynamic", "rosenbrock", "rtol", 1e-7), "ok", 4e-7,
                    {o: 4e-7 for o in scene.outputs}, 20.0, 2e6, 2000),
           wp.Point(wp.Config("kinematic", "closed_form"), "failed: non-finite outputs")]
    wp.mark_pareto(pts)
    path = tmp_path / "wp_startup.csv"
    wp.write_csv(scene, {"points": pts, "reference_difference": 6.355809816331899e-13}, path)
    back = wp.read_csv(path)
    assert back["scene"] == "startup" and back["target_error"] == scene.target_error
    assert back["reference_difference"] == pytest.approx(6.355809816331899e-13, rel=1e-6)
    assert back["reference_difference_source"] == "csv"
    assert [p.config for p in back["points"]] == [p.config for p in pts]
    assert [p.pareto for p in back["points"]] == [p.pareto for p in pts]
    assert back["cheapest"].config == pts[0].config
    assert math.isnan(back["points"][2].error)
    assert re.fullmatch(r"failed: .*", back["points"][2].status)


def test_rerun_stepper_replaces_only_that_steppers_rows(tmp_path, saved):
    """``--stepper NAME`` (``rerun_stepper``) on a scene whose runs are made up: output ``a`` is
    [1, 2, 3] for the reference (radau at rtol 1e-12), 3 + 3e-12 at the end for the check (rtol
    1e-11), and 3 + v at the end for radau at rtol v.  Errors are relative to max|y_ref| = 3."""
    import numpy as np

    def run(cfg, time_it=True):
        end = {1e-12: 3.0, 1e-11: 3.0 + 3e-12}.get(cfg.value, 3.0 + cfg.value)
        return wp.RunResult({"a": np.array([1.0, 2.0, end])}, 0.5, 10)

    grid = (wp.Config("dynamic", "radau", "rtol", 1e-4), wp.Config("dynamic", "radau", "rtol", 1e-6))
    scene = wp.Scene("toy", "toy", t_end=1.0, comm_step=0.5, run=run, grid=grid,
                     target_error=1e-4, outputs=("a",))
    csv_path = tmp_path / "wp_toy.csv"
    # stored: radau at 1e-4 missing its target (error 4e-4), a rosenbrock row to keep, floor
    # 1e-12 (the check above differs by 3e-12 / 3 = 1e-12)
    csv_path.write_text(
        "scene,fidelity,stepper,knob,value,status,error,cpu_s_per_sim_s,rhs_calls,rhs_per_sim_s,"
        "pareto,cheapest_at_0.0001,reference_difference,err:a\n"
        "toy,dynamic,radau,rtol,0.0001,ok,4.0e-04,9.0e+00,20,20,0,0,1.0e-12,4.0e-04\n"
        "toy,dynamic,rosenbrock,rtol,0.0001,ok,5.0e-05,2.0e+00,7,7,1,1,1.0e-12,5.0e-05\n")
    result = wp.rerun_stepper(scene, "radau", csv_path, tmp_path / "wp_toy.png")
    back = wp.read_csv(csv_path)
    rows = {(p.config.stepper, p.config.value): p for p in back["points"]}
    assert len(rows) == 3 and len(result["replaced"]) == 2
    # radau at 1e-4: |3 + 1e-4 − 3| / 3 = 3.33e-5; at 1e-6: 3.33e-7; cost 0.5 s per 1 s
    assert math.isclose(rows[("radau", 1e-4)].error, 1e-4 / 3, rel_tol=1e-5)
    assert math.isclose(rows[("radau", 1e-6)].error, 1e-6 / 3, rel_tol=1e-5)
    assert rows[("radau", 1e-4)].cpu_per_s == 0.5
    # the rosenbrock row is kept as stored; the cheapest at 1e-4 is now radau at 1e-6 or 1e-4
    # (0.5 CPU s/s against the kept row's 2.0)
    assert rows[("rosenbrock", 1e-4)].error == 5e-5 and rows[("rosenbrock", 1e-4)].cpu_per_s == 2.0
    assert back["cheapest"].config.stepper == "radau"
    with pytest.raises(ValueError, match="stepper = 'nope' has no configuration"):
        wp.rerun_stepper(scene, "nope", csv_path, tmp_path / "wp_toy.png")
