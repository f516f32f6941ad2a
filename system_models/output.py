"""Files a run writes: the CSV of every output (units in the header), the plots, a summary.

Units are spelled as in the FMU's modelDescription (:mod:`prsm_fmu.units`).

Plots (matplotlib, PNG, one figure per question a reader asks):

``<scene>_position.png``    rod position against the reference, and the tracking error
``<scene>_speed.png``       screw speed and the speed reference
``<scene>_motor.png``       motor currents (i_q, i_d, reference, limit), voltage against the
                            inverter's limit, torque
``<scene>_forces.png``      axial contact force per roller of each stage; the total load against
                            N_R × the per-roller force; spline friction
``<scene>_carriers.png``    carrier speed ratios against their equilibrium (when recorded)
``<scene>_efficiency.png``  PRSM efficiency and the actuator's (load power / electrical power)
``<scene>_power.png``       the power bookkeeping integrated over the run
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from prsm_fmu.csv_format import format_table
from prsm_fmu.units import (AMPERE, DIMENSIONLESS, JOULE, KILONEWTON, MICROMETRE, MILLIMETRE,
                            MILLIMETRE_PER_SECOND, MILLISECOND, NEWTON, NEWTON_METRE,
                            RADIAN_PER_SECOND, SECOND, VOLT, label)

from .master import Result

__all__ = ["write_csv", "write_plots", "write_summary", "ordered_columns", "figure_writer"]


def ordered_columns(res: Result, first: Iterable[str] = ()) -> list[str]:
    """Column order: the scene's outputs that matter first, then every other output."""
    first = [c for c in first if c in res.values]
    return first + [c for c in res.names() if c not in first]


def write_csv(res: Result, path: str | Path, first: Iterable[str] = ()) -> Path:
    """All outputs on the macro grid; header ``time [s],prsm.rod_position [m],...`` (UTF-8).

    Every value reads back as the same double, bit for bit (15 significant digits where they
    suffice, else 17; :mod:`prsm_fmu.csv_format`, formatted with numpy: ~0.1 s for a
    15 001-row run)."""
    cols = ordered_columns(res, first)
    path = Path(path)
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow(
        [label("time", SECOND)] + [label(c, res.units.get(c) or DIMENSIONLESS) for c in cols])
    data = np.column_stack([res.time] + [res[c] for c in cols])
    with open(path, "wb") as fh:
        fh.write(header.getvalue().encode("utf-8"))
        fh.write(format_table(data))
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
    path.write_text(json.dumps(clean(summary), indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    return path


def _stages(res: Result) -> int:
    n = 0
    while f"prsm.stage[{n + 1}].contact_force" in res:
        n += 1
    return n


def figure_writer(out_dir: str | Path, scene: str):
    """(pyplot, save, files): ``save(fig, name)`` writes ``<out_dir>/<scene>_<name>.png``
    (tight layout, 110 dpi), closes the figure and appends the path to ``files``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    files: list[Path] = []

    def save(fig, name: str) -> None:
        p = out / f"{scene}_{name}.png"
        fig.tight_layout()
        fig.savefig(p, dpi=110)
        plt.close(fig)
        files.append(p)

    return plt, save, files


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
    plt, save, files = figure_writer(out_dir, scene)
    t = res.time
    tm = 1e3 * t
    sub = f"\n{description}" if description else ""

    def limit_lines(ax, value, label, unit, symmetric=True):
        ax.axhline(value, color="k", lw=0.9, ls=":", label=f"{label} ±{value:.4g} {unit}"
                   if symmetric else f"{label} {value:.4g} {unit}")
        if symmetric:
            ax.axhline(-value, color="k", lw=0.9, ls=":")

    # position: tracking in position mode, otherwise the rod's motion
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    x = res["prsm.rod_position"]
    a1.plot(tm, 1e3 * x, label="rod position")
    if mode == "position" and reference is not None:
        r = np.array([reference(v) for v in t])
        a1.plot(tm, 1e3 * r, "--", label="position reference")
        a2.plot(tm, 1e6 * (x - r), color="C3")
        a2.set_ylabel(label("tracking error", MICROMETRE))
        title = "rod position tracking"
    else:
        a2.plot(tm, 1e3 * res["prsm.rod_velocity"], color="C2")
        a2.set_ylabel(label("rod velocity", MILLIMETRE_PER_SECOND))
        title = f"rod motion ({mode} control: no position reference)"
    a1.set_ylabel(label("rod position", MILLIMETRE))
    a1.legend()
    a1.grid(True)
    a2.grid(True)
    a2.set_xlabel(label("time", MILLISECOND))
    a1.set_title(f"{scene}: {title}{sub}", fontsize=10)
    save(fig, "position")

    # screw speed
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(tm, res["prsm.screw_speed"], label="screw (motor) speed")
    ax.step(tm, res["controller.speed_ref"], where="post", ls="--",
            label="speed reference" + (" (position loop output)" if mode == "position" else ""))
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("speed", RADIAN_PER_SECOND))
    ax.grid(True)
    ax.legend()
    ax.set_title(f"{scene}: screw (motor) speed{sub}", fontsize=10)
    save(fig, "speed")

    # motor: currents, voltage against the inverter's limit, torque
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(8, 8.5), sharex=True)
    a1.plot(tm, res["motor.i_q"], label="i_q")
    a1.plot(tm, res["motor.i_d"], label="i_d")
    a1.step(tm, res["controller.i_q_ref"], where="post", ls="--", label="i_q reference")
    if current_limit:
        limit_lines(a1, current_limit, "current limit", "A")
    a1.set_ylabel(label("current", AMPERE))
    a1.legend(fontsize=8, loc="best")
    a1.grid(True)
    vmag = np.hypot(res["motor.v_d"], res["motor.v_q"])
    a2.plot(tm, vmag, color="C4", label="phase voltage amplitude √(v_d² + v_q²)")
    if voltage_limit:
        limit_lines(a2, voltage_limit, "inverter limit V_dc/√3 =", "V", symmetric=False)
        a2.set_ylim(0.0, 1.1 * max(voltage_limit, float(np.max(vmag))))
    a2.set_ylabel(label("voltage", VOLT))
    a2.legend(fontsize=8, loc="best")
    a2.grid(True)
    a3.plot(tm, res["motor.torque"], label="electromagnetic torque")
    a3.plot(tm, res["prsm.stage[1].driven_torque"], "--", label="torque held at the screw (PRSM input)")
    a3.set_ylabel(label("torque", NEWTON_METRE))
    a3.set_xlabel(label("time", MILLISECOND))
    a3.legend(fontsize=8)
    a3.grid(True)
    a1.set_title(f"{scene}: motor current, voltage and torque{sub}", fontsize=10)
    save(fig, "motor")

    # forces: per roller, apart from the total load
    n = _stages(res)
    nr = list(n_rollers) if n_rollers else [None] * n
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(8, 8.5), sharex=True)
    for k in range(1, n + 1):
        what = f" ({nr[k - 1]} rollers)" if nr[k - 1] else ""
        a1.plot(tm, 1e-3 * res[f"prsm.stage[{k}].contact_force"],
                label=f"stage {k}: axial contact force per roller{what}")
    a1.set_ylabel(label("per roller", KILONEWTON))
    a1.legend(fontsize=8)
    a1.grid(True)
    a2.plot(tm, 1e-3 * res["load.force"], "k", lw=1.2, label="load force on the rod (total)")
    for k in range(1, n + 1):
        if nr[k - 1]:
            a2.plot(tm, 1e-3 * nr[k - 1] * res[f"prsm.stage[{k}].contact_force"], "--",
                    label=f"stage {k}: {nr[k - 1]} × per-roller force (all its threads)")
    a2.set_ylabel(label("total", KILONEWTON))
    a2.legend(fontsize=8)
    a2.grid(True)
    for k in range(2, n + 1):
        a3.plot(tm, res[f"prsm.stage[{k}].spline_friction"], color=f"C{k - 1}",
                label=f"stage {k}: spline friction (screw {k - 1} → {k})")
    a3.set_ylabel(label("friction", NEWTON))
    a3.set_xlabel(label("time", MILLISECOND))
    if n > 1:
        a3.legend(fontsize=8)
    a3.grid(True)
    a1.set_title(f"{scene}: thread forces per roller, and the total load{sub}", fontsize=10)
    save(fig, "forces")

    # carriers: speed ratios against their equilibrium
    ratios = [k for k in range(1, n + 1) if f"prsm.stage[{k}].carrier_speed_ratio" in res]
    if carrier_equilibrium and ratios:
        fig, ax = plt.subplots(figsize=(8, 4))
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
        save(fig, "carriers")

    # efficiency
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(tm, res["prsm.efficiency"], label="PRSM (instantaneous)")
    pel = res["motor.electrical_power"]
    pout = res["prsm.output_power"]
    with np.errstate(divide="ignore", invalid="ignore"):
        eta = np.where((pel > 1.0) & (pout >= 0.0), pout / pel, np.nan)
    ax.plot(tm, eta, label="actuator: load power / electrical power")
    ax.set_ylim(-0.05, 1.2)
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("efficiency", DIMENSIONLESS))
    ax.grid(True)
    ax.legend()
    ax.set_title(f"{scene}: efficiency (instantaneous; > 1 while stored energy is released){sub}",
                 fontsize=10)
    save(fig, "efficiency")

    # power bookkeeping
    fig, ax = plt.subplots(figsize=(8, 4))
    e0 = {k: res[k] - res[k][0] for k in ("motor.magnetic_energy", "prsm.kinetic_energy")}
    ax.plot(tm, res["motor.electrical_energy"], label="electrical input")
    ax.plot(tm, res["motor.copper_energy"], label="copper losses")
    ax.plot(tm, res["prsm.friction_work"], label="PRSM friction")
    ax.plot(tm, res["prsm.output_work"], label="work on the load")
    ax.plot(tm, e0["motor.magnetic_energy"] + e0["prsm.kinetic_energy"], label="Δ stored (kinetic + magnetic)")
    resid = (res["motor.electrical_energy"] - res["motor.copper_energy"] - res["prsm.friction_work"]
             - res["prsm.output_work"] - e0["motor.magnetic_energy"] - e0["prsm.kinetic_energy"])
    ax.plot(tm, resid, "k:", label="residual")
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("energy", JOULE))
    ax.grid(True)
    ax.legend(fontsize=8)
    ax.set_title(f"{scene}: power bookkeeping (integrated){sub}", fontsize=10)
    save(fig, "power")
    return files
