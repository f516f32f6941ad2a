"""Files a run writes: the CSV of every output (units in the header), the plots, a summary.

Units are spelled as in the FMU's modelDescription (:mod:`prsm_fmu.units`).

Plots (matplotlib, PNG, one figure per question a reader asks):

``<scene>_position.png``    rod position against the reference, and the tracking error (in
                            µm, mm or m, whichever keeps the ticks to three digits)
``<scene>_speed.png``       screw speed and the speed reference
``<scene>_motor.png``       motor currents (i_q, i_d, reference, limit), voltage against the
                            inverter's limit, torque
``<scene>_forces.png``      axial contact force per roller of each stage; the total load against
                            N_R × the per-roller force; spline friction
``<scene>_carriers.png``    carrier speed ratios against their equilibrium (when recorded)
``<scene>_efficiency.png``  PRSM efficiency and the actuator's (load power / electrical power),
                            with a gap where no power flows (standstill), not a drop to 0
``<scene>_power.png``       the power bookkeeping integrated over the run (legend beside the
                            axes, off the data)

The figures are built by :func:`figures` (one function per figure, returning the unsaved
Figure) on the shared setup of :mod:`prsm_fmu.figures` and written by :func:`write_plots`.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from prsm_fmu.atomic import atomic_path
from prsm_fmu.figures import legend_outside, subplots
from prsm_fmu.units import (AMPERE, DIMENSIONLESS, JOULE, KILONEWTON, METRE, MICROMETRE,
                            MILLIMETRE, MILLIMETRE_PER_SECOND, MILLISECOND, NEWTON, NEWTON_METRE,
                            RADIAN_PER_SECOND, SECOND, VOLT, label)

from .master import Result

__all__ = ["write_csv", "write_plots", "write_summary", "ordered_columns", "figure_writer", "figures",
           "length_scale", "power_flows", "reference_values", "FigureWorkers", "FIGURES",
           "spare_workers", "default_workers"]


def ordered_columns(res: Result, first: Iterable[str] = ()) -> list[str]:
    """Column order: the scene's outputs that matter first, then every other output."""
    first = [c for c in first if c in res.values]
    return first + [c for c in res.names() if c not in first]


def write_csv(res: Result, path: str | Path, first: Iterable[str] = ()) -> Path:
    """All outputs on the macro grid; header ``time [s],prsm.rod_position [m],...`` (UTF-8).

    Every value reads back as the same double, bit for bit (15 significant digits where they
    suffice, else 17; :mod:`prsm_fmu.csv_format`: compiled where gcc builds it, else numpy,
    the same bytes; the columns formatted as they are, not stacked first; its cost against the
    old writer: ``benchmarks/command_cost.py``, item 3, compiled against numpy:
    ``benchmarks/csv_write_cost.py``)."""
    # imported here: its tables cost ~50 ms, which the figures' processes (that import this
    # module) need not pay
    from prsm_fmu.csv_format import format_columns

    cols = ordered_columns(res, first)
    path = Path(path)
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow(
        [label("time", SECOND)] + [label(c, res.units.get(c) or DIMENSIONLESS) for c in cols])
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.getvalue().encode("utf-8"))
        for block in format_columns([res.time] + [res[c] for c in cols]):
            fh.write(block)
    return path


def write_summary(path: str | Path, summary: dict[str, Any]) -> Path:
    """The run's figures and checks as JSON (NaN written as null)."""
    def clean(o):
        if isinstance(o, float):
            return None if not math.isfinite(o) else o
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, (np.floating, np.integer)):
            return clean(o.item())
        return o
    path = Path(path)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(clean(summary), indent=2, ensure_ascii=False) + "\n",
                             encoding="utf-8")
    return path


def _stages(res: Result) -> int:
    n = 0
    while f"prsm.stage[{n + 1}].contact_force" in res:
        n += 1
    return n


def figure_writer(out_dir: str | Path, scene: str):
    """(save, files): ``save(fig, name)`` writes ``<out_dir>/<scene>_<name>.png``
    (:func:`prsm_fmu.figures.save`) and appends the path to ``files``.  Figures are made with
    :func:`prsm_fmu.figures.subplots` (no pyplot, fixed margins, one draw)."""
    from prsm_fmu.figures import save as save_png

    out = Path(out_dir)
    files: list[Path] = []

    def save(fig, name: str) -> None:
        files.append(save_png(fig, out / f"{scene}_{name}.png"))

    return save, files


def length_scale(max_abs: float) -> tuple[float, str]:
    """(factor, unit) to plot a length [m] whose largest magnitude is ``max_abs`` [m] with tick
    labels of at most three integer digits: µm below 1 mm, mm below 1 m, else m."""
    if max_abs < 1e-3:
        return 1e6, MICROMETRE
    if max_abs < 1.0:
        return 1e3, MILLIMETRE
    return 1.0, METRE


def power_flows(p_in: np.ndarray, p_out: np.ndarray, fraction: float = 1e-3) -> np.ndarray:
    """Where power flows through the mechanism: |P_in| or |P_out| above ``fraction`` of the
    run's peak |P_in| [W].  Elsewhere (standstill) an efficiency is undefined: the plots leave a
    gap there instead of a drop to 0."""
    peak = float(np.nanmax(np.abs(p_in))) if np.size(p_in) else 0.0
    with np.errstate(invalid="ignore"):
        return (np.abs(p_in) > fraction * peak) | (np.abs(p_out) > fraction * peak)


def reference_values(reference, t: np.ndarray) -> np.ndarray:
    """The reference on the time grid: ``reference`` is a profile (callable of t [s]) or
    already its values on ``t``."""
    if callable(reference):
        return np.array([reference(v) for v in t])
    return np.asarray(reference, dtype=float)


def _limit_lines(ax, value, label_text, unit, symmetric=True):
    ax.axhline(value, color="k", lw=0.9, ls=":", label=f"{label_text} ±{value:.4g} {unit}"
               if symmetric else f"{label_text} {value:.4g} {unit}")
    if symmetric:
        ax.axhline(-value, color="k", lw=0.9, ls=":")


def _position_frame():
    fig, (a1, a2) = subplots(2, 1, figsize=(8, 6), sharex=True,
                             gridspec_kw={"height_ratios": [2, 1]})
    a1.set_ylabel(label("rod position", MILLIMETRE))
    a1.grid(True)
    a2.grid(True)
    a2.set_xlabel(label("time", MILLISECOND))
    return fig, (a1, a2)


def position_figure(res: Result, scene: str, reference=None, mode: str = "position",
                    sub: str = "", frame=None):
    """Rod position against the reference and the tracking error (position control), or the
    rod's motion; the error in µm, mm or m so that its ticks read well.  ``frame``: the
    figure's :func:`frame` (made while the run goes), else one is made here."""
    fig, (a1, a2) = frame or _position_frame()
    t = res.time
    tm = 1e3 * t
    x = res["prsm.rod_position"]
    a1.plot(tm, 1e3 * x, label="rod position")
    if mode == "position" and reference is not None:
        r = reference_values(reference, t)
        a1.plot(tm, 1e3 * r, "--", label="position reference")
        err = x - r
        factor, unit = length_scale(float(np.nanmax(np.abs(err))) if err.size else 0.0)
        a2.plot(tm, factor * err, color="C3")
        a2.set_ylabel(label("tracking error", unit))
        title = "rod position tracking"
    else:
        a2.plot(tm, 1e3 * res["prsm.rod_velocity"], color="C2")
        a2.set_ylabel(label("rod velocity", MILLIMETRE_PER_SECOND))
        title = f"rod motion ({mode} control: no position reference)"
    a1.legend()
    a1.set_title(f"{scene}: {title}{sub}", fontsize=10)
    return fig


def _speed_frame():
    fig, ax = subplots(figsize=(8, 4))
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("speed", RADIAN_PER_SECOND))
    ax.grid(True)
    return fig, ax


def speed_figure(res: Result, scene: str, mode: str = "position", sub: str = "", frame=None):
    """Screw speed and the speed reference (``frame``: as :func:`position_figure`'s)."""
    fig, ax = frame or _speed_frame()
    tm = 1e3 * res.time
    ax.plot(tm, res["prsm.screw_speed"], label="screw (motor) speed")
    ax.step(tm, res["controller.speed_ref"], where="post", ls="--",
            label="speed reference" + (" (position loop output)" if mode == "position" else ""))
    ax.legend()
    ax.set_title(f"{scene}: screw (motor) speed{sub}", fontsize=10)
    return fig


def _stacked_frame(*ylabels: tuple[str, str]):
    """Panels stacked on one time axis (8 × 8.5 in), y labelled ``(quantity, unit)``, gridded."""
    fig, axes = subplots(len(ylabels), 1, figsize=(8, 8.5), sharex=True)
    for ax, (quantity, unit) in zip(axes, ylabels):
        ax.set_ylabel(label(quantity, unit))
        ax.grid(True)
    axes[-1].set_xlabel(label("time", MILLISECOND))
    return fig, tuple(axes)


def _motor_frame():
    return _stacked_frame(("current", AMPERE), ("voltage", VOLT), ("torque", NEWTON_METRE))


def motor_figure(res: Result, scene: str, current_limit: float | None = None,
                 voltage_limit: float | None = None, sub: str = "", frame=None):
    """Motor currents, voltage against the inverter's limit, torque (``frame``: as
    :func:`position_figure`'s)."""
    fig, (a1, a2, a3) = frame or _motor_frame()
    tm = 1e3 * res.time
    a1.plot(tm, res["motor.i_q"], label="i_q")
    a1.plot(tm, res["motor.i_d"], label="i_d")
    a1.step(tm, res["controller.i_q_ref"], where="post", ls="--", label="i_q reference")
    if current_limit:
        _limit_lines(a1, current_limit, "current limit", "A")
    a1.legend(fontsize=8, loc="best")
    vmag = np.hypot(res["motor.v_d"], res["motor.v_q"])
    a2.plot(tm, vmag, color="C4", label="phase voltage amplitude √(v_d² + v_q²)")
    if voltage_limit:
        _limit_lines(a2, voltage_limit, "inverter limit V_dc/√3 =", "V", symmetric=False)
        a2.set_ylim(0.0, 1.1 * max(voltage_limit, float(np.max(vmag))))
    a2.legend(fontsize=8, loc="best")
    a3.plot(tm, res["motor.torque"], label="electromagnetic torque")
    a3.plot(tm, res["prsm.stage[1].driven_torque"], "--", label="torque held at the screw (PRSM input)")
    a3.legend(fontsize=8)
    a1.set_title(f"{scene}: motor current, voltage and torque{sub}", fontsize=10)
    return fig


def _forces_frame():
    return _stacked_frame(("per roller", KILONEWTON), ("total", KILONEWTON),
                          ("friction", NEWTON))


def forces_figure(res: Result, scene: str, n_rollers: list[int] | None = None, sub: str = "",
                  frame=None):
    """Axial contact force per roller of each stage, the total load against N_R × the per-roller
    force, spline friction (``frame``: as :func:`position_figure`'s)."""
    n = _stages(res)
    nr = list(n_rollers) if n_rollers else [None] * n
    tm = 1e3 * res.time
    fig, (a1, a2, a3) = frame or _forces_frame()
    for k in range(1, n + 1):
        what = f" ({nr[k - 1]} rollers)" if nr[k - 1] else ""
        a1.plot(tm, 1e-3 * res[f"prsm.stage[{k}].contact_force"],
                label=f"stage {k}: axial contact force per roller{what}")
    a1.legend(fontsize=8)
    a2.plot(tm, 1e-3 * res["load.force"], "k", lw=1.2, label="load force on the rod (total)")
    for k in range(1, n + 1):
        if nr[k - 1]:
            a2.plot(tm, 1e-3 * nr[k - 1] * res[f"prsm.stage[{k}].contact_force"], "--",
                    label=f"stage {k}: {nr[k - 1]} × per-roller force (all its threads)")
    a2.legend(fontsize=8)
    for k in range(2, n + 1):
        a3.plot(tm, res[f"prsm.stage[{k}].spline_friction"], color=f"C{k - 1}",
                label=f"stage {k}: spline friction (screw {k - 1} → {k})")
    if n > 1:
        a3.legend(fontsize=8)
    a1.set_title(f"{scene}: thread forces per roller, and the total load{sub}", fontsize=10)
    return fig


def carriers_figure(res: Result, scene: str, carrier_equilibrium: dict[int, float],
                    sub: str = ""):
    """Carrier speed ratios against their equilibrium; None when none is recorded."""
    n = _stages(res)
    ratios = [k for k in range(1, n + 1) if f"prsm.stage[{k}].carrier_speed_ratio" in res]
    if not (carrier_equilibrium and ratios):
        return None
    tm = 1e3 * res.time
    fig, ax = subplots(figsize=(8, 4))
    for k in ratios:
        ax.plot(tm, res[f"prsm.stage[{k}].carrier_speed_ratio"], color=f"C{k - 1}",
                label=f"stage {k}: carrier speed / screw speed")
        if k in carrier_equilibrium:
            ax.axhline(carrier_equilibrium[k], color=f"C{k - 1}", ls=":", lw=1.0,
                       label=f"stage {k}: equilibrium {carrier_equilibrium[k]:.4f} "
                             "(steady-state solver)")
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("carrier speed ratio", DIMENSIONLESS))
    ax.grid(True)
    ax.legend(fontsize=8)
    ax.set_title(f"{scene}: carrier speed ratios{sub}", fontsize=10)
    return fig


def _efficiency_frame():
    fig, ax = subplots(figsize=(8, 4))
    ax.set_ylim(-0.05, 1.2)
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("efficiency", DIMENSIONLESS))
    ax.grid(True)
    return fig, ax


def efficiency_figure(res: Result, scene: str, sub: str = "", frame=None):
    """PRSM and actuator efficiency; a gap wherever no power flows (:func:`power_flows`) or the
    efficiency is undefined (NaN), not a drop to 0 (``frame``: as :func:`position_figure`'s)."""
    fig, ax = frame or _efficiency_frame()
    tm = 1e3 * res.time
    pel = res["motor.electrical_power"]
    pout = res["prsm.output_power"]
    pin = res["prsm.input_power"] if "prsm.input_power" in res else pel
    eta_prsm = np.where(power_flows(pin, pout), res["prsm.efficiency"], np.nan)
    ax.plot(tm, eta_prsm, label="PRSM (instantaneous)")
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where((pel > 1.0) & (pout >= 0.0), pout / pel, np.nan)
    ax.plot(tm, eta, label="actuator: load power / electrical power")
    ax.legend(title="gaps: standstill (no power flows)", title_fontsize=8, fontsize=8)
    ax.set_title(f"{scene}: efficiency (instantaneous; > 1 while stored energy is released){sub}",
                 fontsize=10)
    return fig


def _power_frame():
    fig, ax = subplots(figsize=(10.5, 4), margins={"right": 2.7})
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("energy", JOULE))
    ax.grid(True)
    return fig, ax


def power_figure(res: Result, scene: str, sub: str = "", frame=None):
    """The power bookkeeping integrated over the run; the legend beside the axes, off the data
    (``frame``: as :func:`position_figure`'s)."""
    fig, ax = frame or _power_frame()
    tm = 1e3 * res.time
    e0 = {k: res[k] - res[k][0] for k in ("motor.magnetic_energy", "prsm.kinetic_energy")}
    ax.plot(tm, res["motor.electrical_energy"], label="electrical input")
    ax.plot(tm, res["motor.copper_energy"], label="copper losses")
    ax.plot(tm, res["prsm.friction_work"], label="PRSM friction")
    ax.plot(tm, res["prsm.output_work"], label="work on the load")
    ax.plot(tm, e0["motor.magnetic_energy"] + e0["prsm.kinetic_energy"], label="Δ stored (kinetic + magnetic)")
    resid = (res["motor.electrical_energy"] - res["motor.copper_energy"] - res["prsm.friction_work"]
             - res["prsm.output_work"] - e0["motor.magnetic_energy"] - e0["prsm.kinetic_energy"])
    ax.plot(tm, resid, "k:", label="residual")
    legend_outside(ax)
    ax.set_title(f"{scene}: power bookkeeping (integrated){sub}", fontsize=10)
    return fig


#: the figures in the order they are written
FIGURES = ("position", "speed", "motor", "forces", "carriers", "efficiency", "power")

#: the order the drawing processes share them out in (``DRAW_ORDER[i::n]`` to process i of n):
#: largest first, alternating, as the 3-panel figures take longest
DRAW_ORDER = ("motor", "forces", "position", "power", "speed", "efficiency", "carriers")

#: each figure's frame: the figure, its axes, axis labels, grid and fixed limits, none of which
#: depends on the run (the carriers' figure, drawn only when they are recorded, has none)
_FRAMES = {"position": _position_frame, "speed": _speed_frame, "motor": _motor_frame,
           "forces": _forces_frame, "efficiency": _efficiency_frame, "power": _power_frame}

#: the figures with a frame, in :data:`DRAW_ORDER`
FRAMED = tuple(n for n in DRAW_ORDER if n in _FRAMES)

#: major ticks made with a frame on each axis: position_step's figures use 8 on the time axis
#: and 5 to 10 on the others; a draw makes any more it needs, and a tick beyond those its axis
#: shows is never drawn
FRAME_TICKS = 8


def frame(name: str) -> tuple:
    """(figure, axes) of the figure ``name`` (one of :data:`FRAMED`) without its data, and
    :data:`FRAME_TICKS` major ticks made on each axis: the part of the figure's making that
    needs no run (~40 % of making and drawing it: its axes, and its ticks at ~1 ms each),
    made by the drawing process while the run goes; the figure's function then adds the data."""
    fig, axes = _FRAMES[name]()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            axis.get_major_ticks(FRAME_TICKS)
            axis.get_minor_ticks(1)
    return fig, axes


def figures(res: Result, scene: str, reference=None, mode: str = "position",
            current_limit: float | None = None, *, description: str = "",
            voltage_limit: float | None = None, n_rollers: list[int] | None = None,
            carrier_equilibrium: dict[int, float] | None = None,
            only: Iterable[str] | None = None,
            frames: dict[str, tuple] | None = None) -> dict[str, Any]:
    """The figures of the module docstring by name (``position``, ``speed``, ...), unsaved;
    parameters as :func:`write_plots` (``reference`` may also be its values on the time grid);
    ``only``: those names only; ``frames``: figure name -> its :func:`frame`, made already
    (each used once: taken out of the dict)."""
    sub = f"\n{description}" if description else ""
    frames = {} if frames is None else frames
    make = {"position": lambda f: position_figure(res, scene, reference, mode, sub, f),
            "speed": lambda f: speed_figure(res, scene, mode, sub, f),
            "motor": lambda f: motor_figure(res, scene, current_limit, voltage_limit, sub, f),
            "forces": lambda f: forces_figure(res, scene, n_rollers, sub, f),
            "carriers": lambda f: carriers_figure(res, scene, carrier_equilibrium or {}, sub),
            "efficiency": lambda f: efficiency_figure(res, scene, sub, f),
            "power": lambda f: power_figure(res, scene, sub, f)}
    wanted = FIGURES if only is None else [n for n in FIGURES if n in set(only)]
    out = {}
    for name in wanted:
        fig = make[name](frames.pop(name, None))
        if fig is not None:
            out[name] = fig
    return out


def _save_figures(res: Result, out_dir: str | Path, scene: str, reference, mode: str,
                  current_limit: float | None, kw: dict[str, Any],
                  only: Iterable[str] | None = None,
                  frames: dict[str, tuple] | None = None) -> list[Path]:
    """Build and save the figures (``only``: those named; ``frames``: as :func:`figures`');
    their paths in :data:`FIGURES` order.  :func:`write_plots` here,
    :meth:`FigureWorkers.write_plots` in each worker."""
    save, files = figure_writer(out_dir, scene)
    for name, fig in figures(res, scene, reference, mode, current_limit, only=only,
                             frames=frames, **kw).items():
        save(fig, name)
    return files


def _draw_some(args: tuple) -> list[Path]:
    """Worker side of :meth:`FigureWorkers.write_plots`: the figures named."""
    names, res, out_dir, scene, reference, mode, current_limit, kw = args
    return _save_figures(res, out_dir, scene, reference, mode, current_limit, kw, only=names)


def _warm() -> None:
    """A drawing worker's start, while the run is still going: matplotlib imported, and one
    small figure drawn (title, labels, ticks, legend, grid) so that the fonts the figures share
    are loaded (a figure drawn after it costs ~5-9 ms less than the first: five runs on the
    shared machine; it costs ~35 ms, so the forked drawer draws it only while it waits for the
    run, :func:`system_models.figure_process._ahead`)."""
    from prsm_fmu.figures import subplots

    fig, ax = subplots(figsize=(2.0, 1.5))
    ax.plot([0.0, 1.0], [0.0, 1.0], label="warm")
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_title("warm", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True)
    fig.canvas.draw()


def spare_workers() -> int:
    """Figure processes worth starting: 2 where a core is idle beside the run
    (:func:`prsm_fmu.workers.idle_cores` at least :data:`prsm_fmu.workers.IDLE_CORE`), else 0:
    drawing in this process then ends sooner (position_step under a load of ~8 on 2 cores:
    5.5-6.2 s wall in-process against 6.0-8.9 s with two processes, three runs each)."""
    from prsm_fmu.workers import IDLE_CORE, idle_cores

    return 2 if idle_cores() >= IDLE_CORE else 0


def default_workers() -> int:
    """Drawing processes for :class:`FigureWorkers` by default: where the drawer is forked
    (:func:`system_models.figure_process.available`), :func:`~system_models.figure_process.
    processes`; elsewhere spawned ones, :func:`spare_workers`."""
    from .figure_process import available, processes

    return processes() if available() else spare_workers()


class FigureWorkers:
    """Processes that draw a run's figures beside the parent (which writes the CSV meanwhile).

    Started before the run (:meth:`start`), they import matplotlib while the co-simulation
    runs; :meth:`write_plots` then splits the figures between them.  Where ``fork`` is safe
    (Linux) one forked process (:mod:`system_models.figure_process`) imports matplotlib and
    forks once more to draw (``workers`` >= 2); elsewhere ``workers`` >= 2 spawned processes
    (by default only where a core is idle, :func:`spare_workers`).  With ``workers`` = 0, or if
    the processes cannot start or fail, the figures are drawn in this process (same files, same
    content).  ``drawer``: a :class:`~system_models.figure_process.ForkedDrawer` started
    already (by the command, first thing), used instead of starting one."""

    def __init__(self, workers: int | None = None, drawer=None) -> None:
        self.n = drawer.split if drawer is not None else (
            workers if workers is not None else default_workers())
        self.pool = None
        self.drawer = drawer

    @property
    def active(self) -> bool:
        """True when processes were started to draw (else :meth:`write_plots` draws here)."""
        return self.pool is not None or self.drawer is not None

    def start(self) -> "FigureWorkers":
        from .figure_process import ForkedDrawer, available

        if self.drawer is not None:
            pass
        elif self.n >= 1 and available():
            self.drawer = ForkedDrawer(self.n).start()
        elif self.n >= 2:
            from prsm_fmu.workers import started_pool

            self.pool = started_pool(self.n, _warm)
        return self

    def write_plots(self, res: Result, out_dir: str | Path, scene: str, reference=None,
                    mode: str = "position", current_limit: float | None = None,
                    **kw: Any) -> list[Path]:
        """As :func:`write_plots` (same files, in the same order)."""
        if not self.active:
            return write_plots(res, out_dir, scene, reference, mode, current_limit, **kw)
        ref = reference_values(reference, res.time) if reference is not None else None
        if self.drawer is not None:
            done = self.drawer.draw(res, out_dir, scene, ref, mode, current_limit, kw)
            if done is None:            # the drawer failed: draw here instead
                return write_plots(res, out_dir, scene, reference, mode, current_limit, **kw)
        else:
            parts = [list(DRAW_ORDER[i::self.n]) for i in range(self.n)]
            try:
                futures = [self.pool.submit(_draw_some, (p, res, out_dir, scene, ref, mode,
                                                         current_limit, kw)) for p in parts]
                done = [f for fut in futures for f in fut.result()]
            except Exception:  # noqa: BLE001 - a broken worker: draw here instead
                return write_plots(res, out_dir, scene, reference, mode, current_limit, **kw)
        by_name = {p.name: p for p in done}
        return [by_name[f"{scene}_{n}.png"] for n in FIGURES if f"{scene}_{n}.png" in by_name]

    def close(self) -> None:
        if self.drawer is not None:
            self.drawer.close()
            self.drawer = None
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None


def write_plots(res: Result, out_dir: str | Path, scene: str, reference=None, mode: str = "position",
                current_limit: float | None = None, *, description: str = "",
                voltage_limit: float | None = None, n_rollers: list[int] | None = None,
                carrier_equilibrium: dict[int, float] | None = None) -> list[Path]:
    """The PNG figures of the module docstring; returns their paths.

    Parameters
    ----------
    res : Result
    out_dir, scene
        Where (``<out_dir>/<scene>_<name>.png``).
    reference : callable, optional
        The controller's reference profile; ``mode`` says what it is (position [m], speed
        [rad/s] or current [A]).
    current_limit, voltage_limit : float, optional
        The drive's current [A] and phase-voltage [V] limits, drawn as labelled lines.
    description : str
        The scene's one-line description (second title line of every figure).
    n_rollers : list of int, optional
        Rollers per stage: the contact-force outputs are per roller; the figure also shows
        N_R × the per-roller force against the load.
    carrier_equilibrium : dict, optional
        Stage -> the carriers' equilibrium speed ratio (the steady-state solver's), drawn on
        ``<scene>_carriers.png``; the figure is written when the ratios are recorded and given.
    """
    return _save_figures(res, out_dir, scene, reference, mode, current_limit,
                         dict(description=description, voltage_limit=voltage_limit,
                              n_rollers=n_rollers, carrier_equilibrium=carrier_equilibrium))
