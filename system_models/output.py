"""Files a run writes: the CSV of every output (units in the header), the plots, a summary.

Units are spelled as in the FMU's modelDescription (:mod:`prsm_fmu.units`).

Plots (matplotlib, PNG, one figure per question a reader asks):

``<scene>_position.png``    rod position against the reference, and the tracking error
``<scene>_speed.png``       screw speed and the speed reference
``<scene>_motor.png``       motor currents (i_q, i_d, reference, limit) and torque
``<scene>_forces.png``      per-stage axial contact forces, spline friction and the load force
``<scene>_efficiency.png``  PRSM efficiency and the actuator's (load power / electrical power)
``<scene>_power.png``       the power bookkeeping integrated over the run
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from prsm_fmu.units import (AMPERE, DIMENSIONLESS, JOULE, KILONEWTON, MICROMETRE, MILLIMETRE,
                            MILLIMETRE_PER_SECOND, MILLISECOND, NEWTON, NEWTON_METRE,
                            RADIAN_PER_SECOND, SECOND, label)

from .master import Result

__all__ = ["write_csv", "write_plots", "write_summary", "ordered_columns"]


def ordered_columns(res: Result, first: Iterable[str] = ()) -> list[str]:
    """Column order: the scene's outputs that matter first, then every other output."""
    first = [c for c in first if c in res.values]
    return first + [c for c in res.names() if c not in first]


def write_csv(res: Result, path: str | Path, first: Iterable[str] = ()) -> Path:
    """All outputs on the macro grid; header ``time [s],prsm.rod_position [m],...`` (UTF-8).

    Values with 15 significant digits (enough to compare runs to 1e-10 from the file)."""
    cols = ordered_columns(res, first)
    path = Path(path)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow([label("time", SECOND)]
                   + [label(c, res.units.get(c) or DIMENSIONLESS) for c in cols])
        data = np.column_stack([res.time] + [res[c] for c in cols])
        for row in data:
            w.writerow([f"{v:.15g}" for v in row])
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


def write_plots(res: Result, out_dir: str | Path, scene: str, reference=None, mode: str = "position",
                current_limit: float | None = None) -> list[Path]:
    """The PNG figures of the module docstring; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    t = res.time
    tm = 1e3 * t
    files: list[Path] = []

    def save(fig, name):
        p = out / f"{scene}_{name}.png"
        fig.tight_layout()
        fig.savefig(p, dpi=110)
        plt.close(fig)
        files.append(p)

    # position tracking
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    x = res["prsm.rod_position"]
    a1.plot(tm, 1e3 * x, label="rod position")
    if mode == "position" and reference is not None:
        r = np.array([reference(v) for v in t])
        a1.plot(tm, 1e3 * r, "--", label="reference")
        a2.plot(tm, 1e6 * (x - r), color="C3")
        a2.set_ylabel(label("error", MICROMETRE))
    else:
        a2.plot(tm, 1e3 * res["prsm.rod_velocity"], color="C2")
        a2.set_ylabel(label("rod velocity", MILLIMETRE_PER_SECOND))
    a1.set_ylabel(label("rod position", MILLIMETRE))
    a1.legend()
    a1.grid(True)
    a2.grid(True)
    a2.set_xlabel(label("time", MILLISECOND))
    a1.set_title(f"{scene}: position tracking")
    save(fig, "position")

    # screw speed
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(tm, res["prsm.screw_speed"], label="screw speed")
    ax.step(tm, res["controller.speed_ref"], where="post", ls="--", label="speed reference")
    ax.set_xlabel(label("time", MILLISECOND))
    ax.set_ylabel(label("speed", RADIAN_PER_SECOND))
    ax.grid(True)
    ax.legend()
    ax.set_title(f"{scene}: screw (motor) speed")
    save(fig, "speed")

    # motor current and torque
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot(tm, res["motor.i_q"], label="i_q")
    a1.plot(tm, res["motor.i_d"], label="i_d")
    a1.step(tm, res["controller.i_q_ref"], where="post", ls="--", label="i_q reference")
    if current_limit:
        for s in (1, -1):
            a1.axhline(s * current_limit, color="k", lw=0.8, ls=":")
    a1.set_ylabel(label("current", AMPERE))
    a1.legend()
    a1.grid(True)
    a2.plot(tm, res["motor.torque"], label="electromagnetic torque")
    a2.plot(tm, res["prsm.stage[1].driven_torque"], "--", label="torque held at the screw (PRSM input)")
    a2.set_ylabel(label("torque", NEWTON_METRE))
    a2.set_xlabel(label("time", MILLISECOND))
    a2.legend()
    a2.grid(True)
    a1.set_title(f"{scene}: motor current and torque")
    save(fig, "motor")

    # per-stage forces
    n = _stages(res)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for k in range(1, n + 1):
        a1.plot(tm, 1e-3 * res[f"prsm.stage[{k}].contact_force"], label=f"stage {k} contact (axial)")
    a1.plot(tm, 1e-3 * res["load.force"], "k--", lw=0.9, label="load force (input)")
    a1.set_ylabel(label("force", KILONEWTON))
    a1.legend()
    a1.grid(True)
    for k in range(2, n + 1):
        a2.plot(tm, res[f"prsm.stage[{k}].spline_friction"], color=f"C{k - 1}",
                label=f"stage {k} spline friction")
    a2.set_ylabel(label("force", NEWTON))
    a2.set_xlabel(label("time", MILLISECOND))
    a2.legend()
    a2.grid(True)
    a1.set_title(f"{scene}: per-stage forces")
    save(fig, "forces")

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
    ax.set_title(f"{scene}: efficiency (instantaneous; > 1 while stored energy is released)")
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
    ax.set_title(f"{scene}: power bookkeeping (integrated)")
    save(fig, "power")
    return files
