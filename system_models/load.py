"""The load: a mass on the rod with a spring and a damper to ground and an external force.

The default numbers describe a flight-control surface (an aileron-sized surface) driven through
a horn of arm r, reflected to the rod (surface rotation δ = x / r for small angles):

=====================  ==========================================  ===========================
quantity               at the hinge                                 at the rod
=====================  ==========================================  ===========================
inertia → mass         J_h = 0.5 kg·m² (surface about its hinge)    m = J_h / r² = 50 kg
aerodynamic stiffness  K_h = 2000 N·m/rad (hinge-moment slope        k = K_h / r² = 2e5 N/m
                       ∂H/∂δ at cruise dynamic pressure)
damping                aerodynamic and structural                   c = 1000 N·s/m (ζ ≈ 0.1 of
                                                                     the loaded actuator mode)
external force         hinge-moment offset, gust (scene profile)    F_ext(t)
=====================  ==========================================  ===========================

with r = 0.1 m.  These are representative round numbers (not one aircraft's data), chosen so
that the surface mode (√(k/m_total) ≈ 40 rad/s with the actuator's own reflected mass of 74 kg)
lies inside the position loop's bandwidth and a 10 mm stroke needs 2 kN.

Coupling (docs/ema.md): the mass is rigidly attached to the rod, so it is *not* integrated
here: the assembly adds it to the PRSM's last nut (``stage[n].nut_mass``), which moves with the
rod; integrating it here and exchanging the rod force would be the classic unstable
co-simulation of two rigidly coupled inertias.  This block supplies the force of the spring,
damper and external profile from the rod's position and velocity at the communication point::

    F = k x + c v + F_ext(t)          positive resists extension (the FMU's load_force)

It is a feedthrough block: the master updates its output after every step from the PRSM's new
position and velocity, and the PRSM holds it over the next step (explicit coupling, stable for
c h / M < 2 and adding numerical negative damping ζ ≈ ω h / 4 to the spring mode; docs/ema.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from .blocks import Port, PythonBlock, StepRefused

__all__ = ["LoadParams", "SpringDamperLoad"]


@dataclass(frozen=True)
class LoadParams:
    """Reflected load at the rod (module docstring), SI units."""

    mass: float = 50.0            #: [kg], added to the PRSM's last nut
    stiffness: float = 2.0e5      #: [N/m]
    damping: float = 1.0e3        #: [N·s/m]
    preload: float = 0.0          #: spring force at x = 0 [N]

    def validate(self) -> "LoadParams":
        """Check every field; ValueError naming the field, its value and the range."""
        for f in ("mass", "stiffness", "damping"):
            v = getattr(self, f)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"load.{f} = {v!r} is out of range: must be a finite number >= 0")
        if not math.isfinite(self.preload):
            raise ValueError(f"load.preload = {self.preload!r} is out of range: must be finite")
        return self

    def force(self, t: float, x: float, v: float, external: Callable[[float], float]) -> float:
        """F = preload + k x + c v + F_ext(t) [N]."""
        return self.preload + self.stiffness * x + self.damping * v + external(t)


class SpringDamperLoad(PythonBlock):
    """Spring, damper and external force on the rod (module docstring).

    Inputs: ``position`` [m], ``velocity`` [m/s] of the rod.  Outputs: ``force`` (the PRSM's
    ``load_force``), its parts, the spring's stored energy and the damper's and the external
    force's power at the communication point.
    """

    inputs = (Port("position", "m", "rod position"), Port("velocity", "m/s", "rod velocity"))
    outputs = (Port("force", "N", "total force on the rod, positive resists extension"),
               Port("spring_force", "N", "preload + k x"),
               Port("damper_force", "N", "c v"),
               Port("external_force", "N", "F_ext(t)"),
               Port("spring_energy", "J", "energy stored in the spring 0.5 k x² + preload x"),
               Port("damper_power", "W", "power dissipated in the damper c v²"),
               Port("external_power", "W", "power absorbed by the external force F_ext v"))
    feedthrough = True
    _state_attrs = ("t",)

    def __init__(self, params: LoadParams, external: Callable[[float], float],
                 name: str = "load", t0: float = 0.0) -> None:
        self.params = params.validate()
        super().__init__(name)
        self.external = external
        self.t = float(t0)

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        self.t = t + h

    def update_outputs(self, t: float) -> None:
        self.t = t

    def get_outputs(self) -> list[float]:
        p = self.params
        x, v = self.u
        fs = p.preload + p.stiffness * x
        fd = p.damping * v
        fe = self.external(self.t)
        return [fs + fd + fe, fs, fd, fe, 0.5 * p.stiffness * x * x + p.preload * x, fd * v, fe * v]
