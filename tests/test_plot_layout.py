"""Plot layout: what the figures show, checked on the Figure objects (axis labels, tick ranges,
legend boxes against the axes, the plotted data), not on pixels.

* the tracking error is plotted in a unit whose ticks read well (at most three integer digits);
* the power bookkeeping's legend lies outside the axes, so it covers no data;
* the sweep's steady figures label their y axes ``quantity [unit]``;
* the sweep's time panels say which line style is which stage;
* the loop's efficiency plot shows standstill as a gap (NaN), not a drop to 0.

The figures are caught when saved (``prsm_fmu.figures.save``, which every writer calls, spied
on), so the tests drive the public writers (``write_plots``, ``plot_steady``, ``plot_time_panels``).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from system_models.master import Result
from system_models.output import write_plots
from prsm_fmu.sweep.plots import plot_steady, plot_time_panels

#: an axis unit -> metres per unit (the test's own table)
METRES_PER = {"µm": 1e-6, "mm": 1e-3, "m": 1.0}


@pytest.fixture()
def saved(monkeypatch):
    """Figures saved while active, by the file name they were saved to (not rendered: the
    tests read the Figure objects)."""
    from pathlib import Path

    from prsm_fmu import figures

    figs = {}

    def spy(fig, path, dpi=110):
        figs[Path(path).name] = fig
        return Path(path)

    monkeypatch.setattr(figures, "save", spy)
    return figs


def _step_result(n: int = 601, standstill_from: int = 400) -> Result:
    """A 10 mm position step answered by a first-order rod (τ = 5 ms), held still from sample
    ``standstill_from`` on (no power flows there: the model's efficiency output is 0)."""
    t = np.linspace(0.0, 0.06, n)
    x = 0.01 * (1.0 - np.exp(-t / 5e-3))
    moving = np.arange(n) < standstill_from
    v = np.where(moving, 0.01 / 5e-3 * np.exp(-t / 5e-3), 0.0)
    force = np.full(n, 3000.0)
    p_out = force * v
    p_in = np.where(moving, p_out / 0.8, 0.0)            # 80 % efficient while moving
    eta = np.where(moving, 0.8, 0.0)
    z = np.zeros(n)
    vals = {"prsm.rod_position": x, "prsm.rod_velocity": v, "prsm.screw_speed": v * 1e3,
            "controller.speed_ref": v * 1e3, "motor.i_q": p_in / 10, "motor.i_d": z,
            "controller.i_q_ref": p_in / 10, "motor.v_d": z + 1.0, "motor.v_q": z + 2.0,
            "motor.torque": p_in / 100, "prsm.stage[1].driven_torque": p_in / 100,
            "prsm.stage[1].contact_force": force / 10, "prsm.stage[2].contact_force": force / 10,
            "prsm.stage[2].spline_friction": z + 5.0, "load.force": force,
            "prsm.efficiency": eta, "prsm.input_power": p_in, "prsm.output_power": p_out,
            "motor.electrical_power": p_in * 1.1,
            "motor.magnetic_energy": z, "prsm.kinetic_energy": z,
            "motor.electrical_energy": np.cumsum(p_in * 1.1) * 1e-4,
            "motor.copper_energy": np.cumsum(p_in * 0.1) * 1e-4,
            "prsm.friction_work": np.cumsum(p_in * 0.2) * 1e-4,
            "prsm.output_work": np.cumsum(p_out) * 1e-4}
    return Result(t, vals, {k: "" for k in vals})


def _write(saved, tmp_path, res):
    write_plots(res, tmp_path, "s", lambda t: 0.01, "position", 40.0, voltage_limit=300.0,
                n_rollers=[10, 10])
    return saved


def test_tracking_error_unit_keeps_ticks_to_three_digits(saved, tmp_path):
    res = _step_result()
    fig = _write(saved, tmp_path, res)["s_position.png"]
    ax = fig.get_axes()[1]
    m = re.fullmatch(r"tracking error \[(.+)\]", ax.get_ylabel())
    assert m, ax.get_ylabel()
    lo, hi = ax.get_ylim()
    ticks = [v for v in ax.get_yticks() if lo <= v <= hi]
    # the error runs from -10 mm to 0: in µm the ticks would reach -10000
    assert ticks and max(abs(v) for v in ticks) < 1000, (m.group(1), ticks)
    # the plotted values are the error in the labelled unit
    line = ax.get_lines()[0]
    err_m = np.asarray(line.get_ydata()) * METRES_PER[m.group(1)]
    assert np.allclose(err_m, res["prsm.rod_position"] - 0.01, rtol=1e-12, atol=1e-15)


def test_power_legend_lies_outside_the_axes(saved, tmp_path):
    fig = _write(saved, tmp_path, _step_result())["s_power.png"]
    fig.canvas.draw()
    ax = fig.get_axes()[0]
    leg = ax.get_legend()
    assert leg is not None and len(leg.get_texts()) == 6
    box = leg.get_window_extent()
    axes_box = ax.get_window_extent()
    # no overlap with the axes' area (where every line is drawn)
    overlap_w = min(box.x1, axes_box.x1) - max(box.x0, axes_box.x0)
    overlap_h = min(box.y1, axes_box.y1) - max(box.y0, axes_box.y0)
    assert overlap_w <= 0 or overlap_h <= 0, (box, axes_box)
    # and it is inside the figure (not cut off)
    fig_box = fig.bbox
    assert box.x1 <= fig_box.x1 + 1 and box.y0 >= fig_box.y0 - 1


def test_efficiency_standstill_is_a_gap_not_a_drop(saved, tmp_path):
    res = _step_result(standstill_from=400)
    fig = _write(saved, tmp_path, res)["s_efficiency.png"]
    ax = fig.get_axes()[0]
    prsm = next(ln for ln in ax.get_lines() if ln.get_label().startswith("PRSM"))
    y = np.asarray(prsm.get_ydata(), dtype=float)
    assert np.all(np.isnan(y[400:])), "standstill drawn as values, not a gap"
    # moving: the efficiency as given (0.8), where power flows (from sample 1: v(0) > 0)
    assert np.allclose(y[:300], 0.8)
    # an efficiency the model leaves undefined (NaN) stays a gap
    res.values["prsm.efficiency"] = np.where(np.arange(res.time.size) < 100, np.nan, 0.8)
    saved.clear()
    fig = _write(saved, tmp_path, res)["s_efficiency.png"]
    prsm = next(ln for ln in fig.get_axes()[0].get_lines() if ln.get_label().startswith("PRSM"))
    assert np.all(np.isnan(np.asarray(prsm.get_ydata(), dtype=float)[:100]))


def test_steady_figure_y_labels_name_quantity_and_unit(saved, tmp_path):
    rows = [{"status": "ok", "mu_screw_roller": mu, "load_force": f,
             "stage[1].contact_force@final": 100.0 * mu * f, "efficiency@final": 0.9 - mu,
             "stage[1].carrier_speed_ratio@settle": 0.01 / mu}
            for mu in (0.05, 0.1, 0.15) for f in (1000.0, 2000.0)]
    metrics = ["stage[1].contact_force@final", "efficiency@final",
               "stage[1].carrier_speed_ratio@settle"]
    plot_steady(rows, "mu_screw_roller", metrics, ["load_force"], str(tmp_path / "st.png"))
    fig = saved["st.png"]
    labels = [ax.get_ylabel() for ax in fig.get_axes() if ax.get_visible()]
    assert len(labels) == 3
    for lab, m in zip(labels, metrics):
        mm = re.fullmatch(r"(.+) \[(.+)\]", lab)
        assert mm and mm.group(1).strip(), f"bare unit {lab!r}"
        assert m in mm.group(1)
    assert [re.fullmatch(r".+ \[(.+)\]", x).group(1) for x in labels] == ["N", "1", "s"]


def test_time_panels_legend_tells_the_stage_line_styles(saved, tmp_path):
    t = np.linspace(0.0, 1e-3, 50)
    runs = []
    for j, mu in enumerate((0.05, 0.1)):
        runs.append((f"µ {mu}", {"time": t,
                                 "stage[1].carrier_speed_ratio": 0.4 + 0 * t + j * 0.01,
                                 "stage[2].carrier_speed_ratio": 0.45 + 0 * t + j * 0.01,
                                 "stage[1].contact_force": 100 + t, "stage[2].contact_force": 90 + t,
                                 "efficiency": 0.8 + 0 * t,
                                 "stage[2].spline_friction": 5 + t}))
    plot_time_panels(runs, str(tmp_path / "tp.png"))
    fig = saved["tp.png"]
    ax = fig.get_axes()[0]                          # carrier speed ratios, two stages
    drawn = {}
    for ln in ax.get_lines():
        drawn.setdefault(ln.get_linestyle(), 0)
        drawn[ln.get_linestyle()] += 1
    assert len(drawn) == 2                          # stage 1 and stage 2 styles
    leg = ax.get_legend()
    entries = dict(zip([t.get_text() for t in leg.get_texts()], leg.legend_handles))
    stage_entries = {k: h for k, h in entries.items() if k.startswith("stage ")}
    assert sorted(k.split()[1] for k in stage_entries) == ["1", "2"], list(entries)
    # each stage entry carries the line style its stage is drawn with
    first_of = {}
    for ln in ax.get_lines():
        first_of.setdefault(ln.get_linestyle(), ln)
    styles = sorted(h.get_linestyle() for h in stage_entries.values())
    assert styles == sorted(drawn), (styles, drawn)
    # and the runs keep their entries
    assert {"µ 0.05", "µ 0.1"} <= set(entries)


def _drawn_here_and_there(tmp_path, workers):
    """(files write_plots draws in this process, files ``workers`` draw) of one result."""
    res = _step_result()
    kw = dict(voltage_limit=300.0, n_rollers=[10, 10], description="a step")
    (tmp_path / "here").mkdir()
    (tmp_path / "there").mkdir()
    here = write_plots(res, tmp_path / "here", "s", lambda t: 0.01, "position", 40.0, **kw)
    there = workers.write_plots(res, tmp_path / "there", "s", lambda t: 0.01, "position", 40.0,
                                **kw)
    return here, there


def _same_bytes(here, there):
    assert [p.name for p in there] == [p.name for p in here]
    for a, b in zip(here, there):
        assert a.read_bytes() == b.read_bytes(), a.name


@pytest.mark.parametrize("how", ["forked", "spawned"])
def test_figures_drawn_in_worker_processes_equal_those_drawn_here(tmp_path, monkeypatch, how):
    """prsm-ema run draws its figures in other processes (forked where fork is safe, else
    spawned): the same files, byte for byte (Agg renders deterministically), as drawn in this
    process."""
    from system_models import figure_process
    from system_models.output import FigureWorkers

    if how == "forked" and not figure_process.available():
        pytest.skip("no safe fork on this platform")
    if how == "spawned":
        monkeypatch.setattr(figure_process, "available", lambda: False)
    workers = FigureWorkers(2).start()
    try:
        # really drawn in the other processes
        assert (workers.drawer if how == "forked" else workers.pool) is not None
        here, there = _drawn_here_and_there(tmp_path, workers)
    finally:
        workers.close()
    _same_bytes(here, there)


@pytest.mark.parametrize("mode, reference", [("position", lambda t: 0.01), ("speed", None)])
def test_figures_drawn_on_frames_made_ahead_equal_those_made_at_once(tmp_path, mode, reference):
    """The drawing process makes the figures' frames (axes, labels, grid, fixed limits and 8
    ticks per axis) before the run's result arrives: the figures drawn on them are the files,
    byte for byte, drawn without (position and speed control; the speed figure's y axis needs
    more than 8 ticks, the tracking error's fewer)."""
    from system_models import output

    res = _step_result()
    kw = dict(voltage_limit=300.0, n_rollers=[10, 10], description="a step")
    frames = {name: output.frame(name) for name in output.FRAMED}
    assert set(frames) == set(output.FIGURES) - {"carriers"}
    (tmp_path / "ahead").mkdir()
    (tmp_path / "at_once").mkdir()
    ahead = output._save_figures(res, tmp_path / "ahead", "s", reference, mode, 40.0, kw,
                                 frames=frames)
    assert frames == {}                             # each frame used once
    at_once = write_plots(res, tmp_path / "at_once", "s", reference, mode, 40.0, **kw)
    assert len(at_once) == 6
    _same_bytes(at_once, ahead)


@pytest.mark.parametrize("polls_before_job", [0, 2, 6, 100])
def test_the_drawer_makes_frames_only_until_the_job_arrives(monkeypatch, polls_before_job):
    """figure_process._ahead: frames in DRAW_ORDER while no job has arrived, then the warm-up
    figure; a job waiting stops it at once (0: none made; 2: two; 6: all six, then the job
    arrives before the warm-up; 100: all six and the warm-up)."""
    from system_models import figure_process, output

    class Conn:
        polls = 0

        def poll(self):
            self.polls += 1
            return self.polls > polls_before_job

    warmed = []
    monkeypatch.setattr(output, "_warm", lambda: warmed.append(True))
    made = figure_process._ahead(Conn())
    n = min(polls_before_job, len(output.FRAMED))
    assert list(made) == list(output.FRAMED[:n])
    assert warmed == ([True] if polls_before_job > len(output.FRAMED) else [])


def test_a_drawer_that_dies_leaves_the_figures_to_this_process(tmp_path):
    """The forked drawer killed before it is given the run: write_plots still writes every
    figure (drawn here), byte for byte as write_plots does."""
    import os
    import signal

    from system_models import figure_process
    from system_models.output import FigureWorkers

    if not figure_process.available():
        pytest.skip("no safe fork on this platform")
    workers = FigureWorkers(2).start()
    try:
        os.kill(workers.drawer.process.pid, signal.SIGKILL)
        workers.drawer.process.join()
        here, there = _drawn_here_and_there(tmp_path, workers)
    finally:
        workers.close()
    _same_bytes(here, there)


def test_an_unused_drawer_ends_when_closed():
    """A run that draws nothing (it failed): close() ends the forked drawer at once, even
    while it is still importing matplotlib, and leaves no process behind."""
    from system_models import figure_process

    if not figure_process.available():
        pytest.skip("no safe fork on this platform")
    drawer = figure_process.ForkedDrawer(2).start()
    process = drawer.process
    assert process.is_alive()
    drawer.close()
    assert not process.is_alive() and process.exitcode is not None


def test_geared_figures_show_the_error_against_the_reference_carried_to_the_rod(saved,
                                                                                tmp_path):
    from system_models.plots_geared import write_geared_plots

    n = 201
    t = np.linspace(0.0, 0.02, n)
    theta_ref = 50.0 * t                              # motor-angle reference [rad]
    ratio, lead = 10.0, 0.5e-3                        # gear N, rod per screw radian c [m/rad]
    # the rod 3 µm behind the reference carried to the rod: 50 t · 0.5e-3 / 10 = 2.5e-3 t [m]
    x = 2.5e-3 * t - 3e-6
    z = np.zeros(n)
    vals = {"prsm.rod_position": x, "load.load_position": x, "controller.current_command": z,
            "motor.current": z, "motor.torque": z, "controller.measured_angle": z,
            "gear.motor_angle": z, "gear.phi_rel": z, "gear.loss_torque": z,
            "gear.output_torque": z, "load.contact_force": z, "load.external_force": z,
            "load.stop_force": z}
    files = write_geared_plots(Result(t, vals, {k: "" for k in vals}), tmp_path, "g",
                               lambda s: 50.0 * s, ratio=ratio, lead_per_radian=lead,
                               backlash=1e-3, current_limit=20.0)
    assert [p.name for p in files] == ["g_position.png", "g_motor.png", "g_gear.png",
                                       "g_forces.png"]
    error_axes = saved["g_position.png"].axes[1]
    assert error_axes.get_ylabel() == "error [µm]"
    (line,) = error_axes.get_lines()
    # rod − reference × c/N = −3 µm throughout
    np.testing.assert_allclose(line.get_ydata(), -3.0, atol=1e-9)


def test_figure_processes_only_where_a_core_is_idle(monkeypatch):
    """Where processes are spawned (no safe fork): two drawing processes on an idle 2-core
    machine; none under a load of 8 (the figures are then drawn in the command's process) nor
    on one core."""
    import os

    from system_models import figure_process
    from system_models.output import FigureWorkers

    monkeypatch.setattr(figure_process, "available", lambda: False)
    for cores, load, expected in ((2, 0.2, 2), (2, 0.6, 0), (2, 8.0, 0), (1, 0.0, 0),
                                  (8, 3.0, 2)):
        monkeypatch.setattr(os, "cpu_count", lambda c=cores: c)
        monkeypatch.setattr(os, "getloadavg", lambda lo=load: (lo, lo, lo))
        assert FigureWorkers().n == expected, (cores, load)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    monkeypatch.setattr(os, "getloadavg", lambda: (8.0, 8.0, 8.0))
    workers = FigureWorkers().start()
    assert workers.pool is None and not workers.active          # nothing started
    workers.close()


def test_forked_drawing_processes_busy_machine_or_not(monkeypatch):
    """Where the drawer is forked its processes copy the command's imports (no interpreter
    start to pay back): two on two cores or more, under a load of 8 too; one on one core."""
    import os

    from system_models import figure_process
    from system_models.output import FigureWorkers

    monkeypatch.setattr(figure_process, "available", lambda: True)
    for cores, load, expected in ((2, 0.2, 2), (2, 8.0, 2), (1, 0.0, 1), (8, 3.0, 2)):
        monkeypatch.setattr(os, "cpu_count", lambda c=cores: c)
        monkeypatch.setattr(os, "getloadavg", lambda lo=load: (lo, lo, lo))
        assert FigureWorkers().n == expected, (cores, load)


def test_long_lived_imports_pause_the_collector_and_freeze_what_they_made(monkeypatch):
    import gc

    from system_models.figure_process import long_lived_imports

    frozen = []
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append(gc.isenabled()))
    assert gc.isenabled()
    with long_lived_imports():
        assert not gc.isenabled()
    assert gc.isenabled() and frozen == [False]     # frozen before the collector resumed
    with pytest.raises(KeyError):
        with long_lived_imports():
            raise KeyError("x")
    assert gc.isenabled() and len(frozen) == 2      # after an error too
    gc.disable()
    try:
        with long_lived_imports():
            pass
        assert not gc.isenabled()                   # left paused: it was paused before
    finally:
        gc.enable()
