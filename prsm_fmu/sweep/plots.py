"""The figures a designer reads: the papers' panels against time, and steady values against the
swept parameter.

* :func:`plot_time_panels`: one panel per signal (default: carrier speed ratios, axial contact
  forces per roller, efficiency, spline friction, as Li et al. (2021) Figs. 4–5), every run in its own
  colour, stages told apart by line style (a legend entry per stage style).  :func:`prsm_fmu.report.plot_runs` is this function
  with the default panels.
* :func:`plot_steady`: one panel per metric of the table against one swept parameter, one
  line per combination of the other swept parameters.

Figures are built on :mod:`prsm_fmu.figures` (Agg canvas, no display, fixed margins);
:func:`time_panels_figure` and :func:`steady_figure` return them unsaved.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np


from ..units import (DIMENSIONLESS, METRE, METRE_PER_SECOND, MILLISECOND, NEWTON, NEWTON_METRE,
                     NEWTON_SECOND_PER_METRE, RADIAN_PER_SECOND, SECOND, WATT, label, unit_of)

__all__ = ["plot_time_panels", "plot_steady", "time_panels_figure", "steady_figure",
           "metric_label", "PANELS", "DEFAULT_PANELS", "STAGE_STYLES", "label_of", "short_label"]

#: time panels: signal -> (title, y label, per stage?, first stage)
PANELS: dict[str, tuple[str, str, bool, int]] = {
    "carrier_speed_ratio": ("carrier speed ratios ζ_PSk (solid k = 1, dashed k = 2)",
                            label("ζ_PSk", DIMENSIONLESS), True, 1),
    "contact_force": ("axial contact force per roller F_Srzk", label("F_Srzk", NEWTON), True, 1),
    "efficiency": ("efficiency η", label("η", DIMENSIONLESS), False, 0),
    "spline_friction": ("spline friction f_S2 between screws 1 and 2", label("f_S2", NEWTON),
                        True, 2),
    "driven_torque": ("driven torques M_Sk (solid k = 1, dashed k = 2)",
                      label("M_Sk", NEWTON_METRE), True, 1),
    "friction_torque": ("friction torque at the screw M_f = P_f / ω", label("M_f", NEWTON_METRE),
                        False, 0),
    "screw_torque": ("motor torque M_S1", label("M_S1", NEWTON_METRE), False, 0),
    "screw_speed": ("screw speed ω", label("ω", RADIAN_PER_SECOND), False, 0),
    "screw_friction_torque": ("friction torque on the screw M_f (model backend)",
                              label("M_f", NEWTON_METRE), False, 0),
    "friction_power_viscous": ("viscous friction power (model backend)", label("P_f,visc", WATT),
                               False, 0),
}

#: Li et al. (2021) Figs. 4 and 5: (a) ζ_PSk, (b) F_Srzk, (c) η, (d) f_S2
DEFAULT_PANELS = ("carrier_speed_ratio", "contact_force", "efficiency", "spline_friction")

_LABELS = {
    "mu_screw_roller": "µ_SR", "mu_spline": "µ_SS", "mu_nut_screw": "µ_NS",
    "load_force": label("load F", NEWTON), "screw_speed": label("screw speed", RADIAN_PER_SECOND),
    "accel_time": label("acceleration time t_a", SECOND), "n_stages": "stages",
    "slip_velocity_scale": label("v_ε", METRE_PER_SECOND),
    "mu_viscous": label("µ_1", NEWTON_SECOND_PER_METRE), "mu_differential": label("µ_3", METRE),
}


_SHORT = {
    "mu_screw_roller": ("µ_SR", ""), "mu_spline": ("µ_SS", ""), "mu_nut_screw": ("µ_NS", ""),
    "load_force": ("F", " N"), "screw_speed": ("ω", " rad/s"), "accel_time": ("t_a", " s"),
    "n_stages": ("stages", ""), "slip_velocity_scale": ("v_ε", " m/s"), "preset": ("", ""),
    "mu_viscous": ("µ_1", " N·s/m"), "mu_differential": ("µ_3", " m"),
}


def short_label(name: str, value: Any) -> str:
    """A legend entry for one swept value, e.g. ``µ_SR 0.1`` or ``F 500 N``."""
    text = f"{value:g}" if isinstance(value, float) else str(value)
    if name in _SHORT:
        sym, unit = _SHORT[name]
        return f"{sym} {text}{unit}".strip()
    if name.startswith("stage[") and name.endswith("].pitch"):
        return f"p{name[6:name.index(']')]} {text} m"
    return f"{name} {text}"


def label_of(name: str) -> str:
    """A short axis label for a parameter or metric name."""
    if name in _LABELS:
        return _LABELS[name]
    if name.startswith("stage[") and name.endswith("].pitch"):
        return label(f"pitch of screw {name[6:name.index(']')]}", METRE)
    return name


#: line style of stage k (k = 1, 2, ...), cycled
STAGE_STYLES = ("-", "--", ":", "-.")
_STYLE_NAMES = {"-": "solid", "--": "dashed", ":": "dotted", "-.": "dash-dot"}


def plot_time_panels(runs: Sequence[tuple[str, Mapping[str, np.ndarray]]], path: str,
                     panels: Sequence[str] = DEFAULT_PANELS, title: str = "") -> None:
    """Save :func:`time_panels_figure` as PNG at ``path``."""
    from ..figures import save

    save(time_panels_figure(runs, panels, title), path)


def time_panels_figure(runs: Sequence[tuple[str, Mapping[str, np.ndarray]]],
                       panels: Sequence[str] = DEFAULT_PANELS, title: str = ""):
    """One panel per signal against time [ms] for several runs; returns the Figure.

    Each run has its colour; on per-stage panels each stage has its line style, and the legend
    has an entry per stage style (``stage 1 (solid)``, ...) beside the runs' colours.

    Parameters
    ----------
    runs : sequence of (label, series)
        Series with ``time`` [s] and the signals (``stage[k].<signal>`` for per-stage ones).
    path : str
        Output PNG.
    panels : sequence of str
        Keys of :data:`PANELS`, in reading order (two per row).
    title : str
        Figure title.
    """
    import matplotlib
    from matplotlib.lines import Line2D

    from ..figures import subplots

    unknown = [p for p in panels if p not in PANELS]
    if unknown:
        raise ValueError(f"unknown time panels {unknown}: must be among {', '.join(PANELS)}")
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    stage_ls = STAGE_STYLES
    n = len(panels)
    ncols = 1 if n == 1 else 2
    nrows = math.ceil(n / ncols)
    fig, axes = subplots(nrows, ncols, figsize=(10, 3.75 * nrows), sharex=True, squeeze=False,
                         margins={"top": 0.5 + (0.35 if title else 0.0)})
    stages_seen: dict[str, set[int]] = {p: set() for p in panels}
    ax_of = {p: axes[i // ncols, i % ncols] for i, p in enumerate(panels)}
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    stage_panels = [p for p in panels if PANELS[p][2]]
    global_panels = [p for p in panels if not PANELS[p][2]]
    for j, (run_label, res) in enumerate(runs):
        c = colours[j % len(colours)]
        t_ms = np.asarray(res["time"]) * 1e3
        k = 1
        while f"stage[{k}].carrier_speed_ratio" in res or f"stage[{k}].contact_force" in res:
            ls = stage_ls[(k - 1) % len(stage_ls)]
            for p in stage_panels:
                first = PANELS[p][3]
                name = f"stage[{k}].{p}"
                if k >= first and name in res:
                    ax_of[p].plot(t_ms, res[name], ls, color=c,
                                  label=run_label if k == first else None)
                    stages_seen[p].add(k)
            k += 1
        for p in global_panels:
            if p in res:
                ax_of[p].plot(t_ms, res[p], "-", color=c, label=run_label)
    for i, p in enumerate(panels):
        ax = ax_of[p]
        ax.set_title(f"({chr(ord('a') + i)}) {PANELS[p][0]}", fontsize=10)
        ax.set_ylabel(PANELS[p][1])
    for p in panels:
        ax = ax_of[p]
        ax.grid(True, alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        # which line style is which stage: an entry per stage drawn on the panel
        if len(stages_seen[p]) > 1:
            for k in sorted(stages_seen[p]):
                ls = stage_ls[(k - 1) % len(stage_ls)]
                handles.append(Line2D([], [], color="0.3", ls=ls))
                labels.append(f"stage {k} ({_STYLE_NAMES[ls]})")
        if handles:
            ax.legend(handles, labels, fontsize=8, loc="best")
    for i in range(n):
        if i >= n - ncols:
            axes.flat[i].set_xlabel(label("time", MILLISECOND))
    if title:
        fig.suptitle(title)
    return fig


def metric_label(metric: str) -> str:
    """The y label of a metric column, ``quantity [unit]`` (settling times in s; the bare name
    when the unit is unknown)."""
    signal, _, how = metric.rpartition("@")
    if how == "settle":
        return label(metric, SECOND)
    u = unit_of(signal)
    return metric if u == "?" else label(metric, u)


def plot_steady(rows: Sequence[Mapping[str, Any]], x: str, metrics: Sequence[str],
                group_by: Sequence[str], path: str, title: str = "",
                x_values: Sequence[Any] | None = None) -> None:
    """Save :func:`steady_figure` as PNG at ``path``."""
    from ..figures import save

    save(steady_figure(rows, x, metrics, group_by, title, x_values), path)


def steady_figure(rows: Sequence[Mapping[str, Any]], x: str, metrics: Sequence[str],
                  group_by: Sequence[str], title: str = "",
                  x_values: Sequence[Any] | None = None):
    """One panel per metric against the swept parameter ``x``; returns the Figure.

    Parameters
    ----------
    rows : sequence of mapping
        Rows of the table (numbers as floats); rows whose status is not ``ok`` are left out.
    x : str
        Column of the abscissa.
    metrics : sequence of str
        Metric columns, one panel each.
    group_by : sequence of str
        Columns whose combinations make the lines (the other swept parameters).
    title : str
        Figure title.
    x_values : sequence, optional
        Tick labels for a non-numeric ``x`` (in order).
    """
    from ..figures import subplots

    ok = [r for r in rows if r.get("status") == "ok"]
    n = max(len(metrics), 1)
    ncols = 1 if n == 1 else 2
    nrows = math.ceil(n / ncols)
    fig, axes = subplots(nrows, ncols, figsize=(10, 3.6 * nrows), squeeze=False,
                         margins={"top": 0.5 + (0.35 if title else 0.0)}, wspace=0.35)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    groups: dict[tuple, list] = {}
    for r in ok:
        groups.setdefault(tuple(r.get(g) for g in group_by), []).append(r)
    numeric = all(isinstance(r.get(x), float) for r in ok)
    order = list(x_values) if x_values is not None else \
        sorted({r.get(x) for r in ok}, key=str)
    for i, m in enumerate(metrics):
        ax = axes.flat[i]
        for key, rs in groups.items():
            rs = sorted(rs, key=(lambda r: r[x]) if numeric else (lambda r: order.index(r[x])
                                                                    if r[x] in order else 0))
            xs = [r[x] if numeric else order.index(r[x]) for r in rs]
            ys = [r.get(m, math.nan) for r in rs]
            ys = [y if isinstance(y, float) else math.nan for y in ys]
            lab = ", ".join(short_label(g, v) for g, v in zip(group_by, key))
            ax.plot(xs, ys, "o-", label=lab or None)
        if not numeric:
            ax.set_xticks(range(len(order)))
            ax.set_xticklabels([str(o) for o in order], fontsize=8)
        ax.set_title(f"({chr(ord('a') + i)}) {m}", fontsize=10)
        ax.set_xlabel(label_of(x))
        ax.set_ylabel(metric_label(m))
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title)
    return fig
