"""Figures of a ``geared`` scene (system_models.geared), one per question a drive engineer asks.

``<scene>_position.png``  rod position against the reference carried to the rod (r c / N), the
                          error; the load's position behind the contact
``<scene>_motor.png``     current command, current after the bus delay (limit when finite),
                          motor torque; the measured angle's noise
``<scene>_gear.png``      the angle over the gear's backlash and compliance against the flanks
                          ±b/2; the loss torque
``<scene>_forces.png``    the contact force on the rod and the external force on the load
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from prsm_fmu.figures import subplots
from prsm_fmu.units import AMPERE, KILONEWTON, MICROMETRE, MILLIMETRE, NEWTON_METRE, SECOND, label

from .master import Result
from .output import figure_writer

__all__ = ["write_geared_plots"]


def write_geared_plots(res: Result, out_dir: str | Path, scene: str, reference=None, *,
                       description: str = "", ratio: float = 1.0, lead_per_radian: float = 1.0,
                       backlash: float = 0.0, current_limit: float = math.inf) -> list[Path]:
    """Write the figures of the module docstring; returns their paths.

    ``reference`` is the motor-angle reference [rad]; ``ratio`` N and ``lead_per_radian`` c
    [m/rad] carry it to the rod (r c / N); ``backlash`` b [rad] and ``current_limit`` [A] are
    drawn as labelled lines.
    """
    save, files = figure_writer(out_dir, scene)
    t = res.time
    sub = f"\n{description}" if description else ""

    k = lead_per_radian / ratio
    fig, (a1, a2) = subplots(2, 1, figsize=(8, 6), sharex=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    x = res["prsm.rod_position"]
    a1.plot(t, 1e3 * x, label="rod position")
    if reference is not None:
        r = np.array([reference(v) for v in t]) * k
        a1.plot(t, 1e3 * r, "--", label=f"motor-angle reference × c/N ({1e6 * k:.4g} µm/rad)")
        a2.plot(t, 1e6 * (x - r), color="C3", label="rod − reference")
    a1.plot(t, 1e3 * (res["load.load_position"] - res["load.load_position"][0] + x[0]), ":",
            color="C2", label="load mass (from its start)")
    a1.set_ylabel(label("position", MILLIMETRE))
    a1.legend(fontsize=8)
    a1.grid(True)
    a2.set_ylabel(label("error", MICROMETRE))
    a2.set_xlabel(label("time", SECOND))
    a2.grid(True)
    a1.set_title(f"{scene}: rod position{sub}", fontsize=10)
    save(fig, "position")

    fig, (a1, a2, a3) = subplots(3, 1, figsize=(8, 8.5), sharex=True)
    a1.plot(t, res["controller.current_command"], lw=0.6, label="current command i*")
    a1.plot(t, res["motor.current"], lw=0.8, label="current after the bus delay")
    if math.isfinite(current_limit):
        a1.axhline(current_limit, color="k", ls=":", lw=0.9, label=f"current limit ±{current_limit:g} A")
        a1.axhline(-current_limit, color="k", ls=":", lw=0.9)
    a1.set_ylabel(label("current", AMPERE))
    a1.legend(fontsize=8)
    a1.grid(True)
    a2.plot(t, res["motor.torque"], lw=0.8, color="C2", label="motor torque")
    a2.set_ylabel(label("torque", NEWTON_METRE))
    a2.legend(fontsize=8)
    a2.grid(True)
    a3.plot(t, 1e3 * (res["controller.measured_angle"] - res["gear.motor_angle"]), lw=0.6,
            color="C4", label="measured − true motor angle (sensor noise)")
    a3.set_ylabel("angle [mrad]")
    a3.set_xlabel(label("time", SECOND))
    a3.legend(fontsize=8)
    a3.grid(True)
    a1.set_title(f"{scene}: motor current, torque and angle sensor{sub}", fontsize=10)
    save(fig, "motor")

    fig, (a1, a2) = subplots(2, 1, figsize=(8, 6), sharex=True)
    a1.plot(t, 1e3 * res["gear.phi_rel"], label="angle over the gear φ_rel (output side)")
    if backlash > 0:
        a1.axhline(0.5e3 * backlash, color="k", ls=":", lw=0.9,
                   label=f"backlash flanks ±b/2 = ±{0.5e3 * backlash:.4g} mrad")
        a1.axhline(-0.5e3 * backlash, color="k", ls=":", lw=0.9)
    a1.set_ylabel("angle [mrad]")
    a1.legend(fontsize=8)
    a1.grid(True)
    a2.plot(t, res["gear.loss_torque"], lw=0.6, color="C1", label="mesh + bearing loss (input side)")
    a2.plot(t, res["gear.output_torque"] / ratio, lw=0.8, color="C0",
            label="mesh torque delivered, per input (τ_out / N)")
    a2.set_ylabel(label("torque", NEWTON_METRE))
    a2.set_xlabel(label("time", SECOND))
    a2.legend(fontsize=8)
    a2.grid(True)
    a1.set_title(f"{scene}: gear backlash, compliance and losses{sub}", fontsize=10)
    save(fig, "gear")

    fig, ax = subplots(figsize=(8, 4))
    ax.plot(t, 1e-3 * res["load.contact_force"], lw=0.8, label="contact force rod ↔ load")
    ax.plot(t, 1e-3 * res["load.external_force"], "k--", lw=0.9,
            label="external force on the load (positive resists extension)")
    if np.any(res["load.stop_force"] != 0.0):
        ax.plot(t, 1e-3 * res["load.stop_force"], label="end stops")
    ax.set_ylabel(label("force", KILONEWTON))
    ax.set_xlabel(label("time", SECOND))
    ax.legend(fontsize=8)
    ax.grid(True)
    ax.set_title(f"{scene}: forces on the rod and the load{sub}", fontsize=10)
    save(fig, "forces")
    return files
