"""The driven part on the rod: an elastic gap contact (pushes only), a mass, end stops.

Laws (pure functions, tested against their closed forms in tests/test_actuator_blocks.py):

* **Gap contact** (:func:`gap_contact_force`), MSL 4.1
  ``Modelica.Mechanics.Translational.Components.ElastoGap`` with n = 1: s = x_L − x_R is the
  distance from the rod's face to the load's, ``gap`` the distance at which they touch.  In
  contact (s < gap) the compression δ = gap − s gives F = k δ + d δ', the damping part limited
  to |d δ'| ≤ k δ so the contact only pushes (never pulls, never sticks); apart (s ≥ gap):
  F = 0.  ``bilateral = true`` makes it a plain spring-damper (MSL ``SpringDamper``: it pulls
  too), as the MSL actuator example's component named ``elastoGap`` is.
* **End stops** (:func:`end_stop_force`): elastic stops at x_min and x_max on the rod, the same
  pushing-only law: F = k_s (x − x_max) + d_s v beyond x_max (resists extension), F =
  k_s (x − x_min) + d_s v below x_min (negative: pushes the rod back out), 0 between.

Sign: a force on the rod is positive when it resists extension (the PRSM FMU's
``load_force``).  The contact pushes the load forward (+x) with F and the rod back with F.

:class:`GapContactLoad` integrates the load mass m_L with the rod's motion as input::

    m_L x_L'' = F_contact − F_ext(t)        (F_ext positive resists extension)

Causality: the rod side (PRSM with the motor's inertia lumped in) is the heavy side, so it
sends motion and receives the force; the light load and the stiff contact are integrated here
(RK4 on substeps ≤ ``max_substep``, the rod's motion interpolated linearly over the step), so
the contact's stiffness never limits the communication step.  The rod feels the contact force
and the end stops, held over the next step (explicit coupling: stable while the rod side's
mass M_r satisfies d h / M_r < 1 and √(k/M_r)·h ≪ 1; the scene check states it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from .blocks import Port, PythonBlock, StepRefused

__all__ = ["ContactParams", "gap_contact_force", "end_stop_force", "GapContactLoad"]


def gap_contact_force(s: float, v: float, stiffness: float, damping: float, gap: float = 0.0,
                      bilateral: bool = False) -> float:
    """Contact force [N] at distance ``s`` [m] (load face − rod face) closing at −``v`` [m/s].

    ``v`` = ds/dt (negative while the gap closes); δ = gap − s is the compression.
    """
    comp = gap - s
    if bilateral:
        return stiffness * comp - damping * v
    if comp <= 0.0:
        return 0.0
    fc = stiffness * comp
    return fc + min(fc, max(-fc, -damping * v))


def end_stop_force(x: float, v: float, x_min: float, x_max: float, stiffness: float,
                   damping: float) -> float:
    """Force of the end stops on the rod [N] (positive resists extension; module docstring)."""
    if x > x_max:
        fc = stiffness * (x - x_max)
        return fc + min(fc, max(-fc, damping * v))
    if x < x_min:
        fc = stiffness * (x - x_min)             # negative
        return fc + max(fc, min(-fc, damping * v))
    return 0.0


@dataclass(frozen=True)
class ContactParams:
    """The driven part and the rod's end stops, SI units (module docstring).

    Attributes
    ----------
    mass : float
        m_L, load mass [kg], > 0.
    stiffness, damping : float
        Contact k [N/m] > 0 and d [N·s/m] >= 0.
    gap : float
        Distance at which the faces touch [m] (0: touching at s = 0).
    bilateral : bool
        True: a spring-damper that also pulls (no gap law).
    stop_min, stop_max : float
        Rod positions of the end stops [m] (±inf: none).
    stop_stiffness, stop_damping : float
        End stops' k_s [N/m] > 0 and d_s [N·s/m] >= 0.
    max_substep : float
        Largest internal step of the load's integration [s], > 0.
    """

    mass: float = 100.0
    stiffness: float = 1e8
    damping: float = 1e5
    gap: float = 0.0
    bilateral: bool = False
    stop_min: float = -math.inf
    stop_max: float = math.inf
    stop_stiffness: float = 1e8
    stop_damping: float = 1e5
    max_substep: float = 2e-5

    def validate(self) -> "ContactParams":
        """Check every field; ValueError naming the field, its value and the range."""
        def bad(f, rng):
            return ValueError(f"load.{f} = {getattr(self, f)!r} is out of range: must be {rng}")

        def num(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool) and not math.isnan(v)

        for f in ("mass", "stiffness", "stop_stiffness", "max_substep"):
            v = getattr(self, f)
            if not (num(v) and math.isfinite(v) and v > 0):
                raise bad(f, "a finite number > 0")
        for f in ("damping", "stop_damping"):
            v = getattr(self, f)
            if not (num(v) and math.isfinite(v) and v >= 0):
                raise bad(f, "a finite number >= 0")
        if not (num(self.gap) and math.isfinite(self.gap)):
            raise bad("gap", "a finite number")
        if not isinstance(self.bilateral, bool):
            raise bad("bilateral", "true or false")
        if not (num(self.stop_min) and num(self.stop_max) and self.stop_min < self.stop_max):
            raise bad("stop_min", f"a number < stop_max = {self.stop_max!r}")
        return self

    def stop_force(self, x: float, v: float) -> float:
        """End-stop force on the rod [N] (:func:`end_stop_force`)."""
        return end_stop_force(x, v, self.stop_min, self.stop_max, self.stop_stiffness,
                              self.stop_damping)


class GapContactLoad(PythonBlock):
    """Load mass behind an elastic gap contact, and the rod's end stops (module docstring).

    Inputs: rod ``position`` [m] and ``velocity`` [m/s].  Outputs: ``force`` on the rod
    (contact + end stops, positive resists extension; the PRSM's ``load_force``),
    ``contact_force``, ``stop_force``, ``external_force``, ``load_position``,
    ``load_velocity``, ``distance`` (s = x_L − x_R).
    """

    inputs = (Port("position", "m", "rod position"), Port("velocity", "m/s", "rod velocity"))
    outputs = (Port("force", "N", "force on the rod: contact + end stops (positive resists extension)"),
               Port("contact_force", "N", "gap contact force (positive pushes the faces apart)"),
               Port("stop_force", "N", "end-stop force on the rod"),
               Port("external_force", "N", "external force on the load (positive resists extension)"),
               Port("load_position", "m", "load position x_L"),
               Port("load_velocity", "m/s", "load velocity"),
               Port("distance", "m", "load face − rod face s = x_L − x_R"))
    interpolates_inputs = True
    feedthrough = True
    _state_attrs = ("x", "t")

    def __init__(self, params: ContactParams, external: Callable[[float], float],
                 name: str = "load", t0: float = 0.0, load_position: float = 0.0,
                 load_velocity: float = 0.0) -> None:
        self.params = params.validate()
        super().__init__(name)
        self.external = external
        self.x = [float(load_position), float(load_velocity)]
        self.t = float(t0)

    def _acc(self, t: float, xl: float, vl: float, xr: float, vr: float) -> float:
        p = self.params
        f = gap_contact_force(xl - xr, vl - vr, p.stiffness, p.damping, p.gap, p.bilateral)
        return (f - self.external(t)) / p.mass

    def do_step(self, t: float, h: float) -> None:
        if not (math.isfinite(h) and h > 0.0):
            raise StepRefused(self.name, t, h, f"step size h = {h!r} s must be a finite number > 0")
        (x0, v0), (dx, dv) = self.u, self.du
        if not all(math.isfinite(a) for a in (x0, v0, dx, dv)):
            raise StepRefused(self.name, t, h, f"non-finite rod motion {self.u}, slopes {self.du}")
        n = max(1, math.ceil(h / self.params.max_substep - 1e-9))
        dt = h / n
        xl, vl = self.x
        f = self._acc
        for j in range(n):
            ta = t + j * dt
            tm, tb = ta + 0.5 * dt, ta + dt
            ra, rm, rb = (j * dt, (j + 0.5) * dt, (j + 1) * dt)
            xa, xm, xb = x0 + dx * ra, x0 + dx * rm, x0 + dx * rb
            va, vm, vb = v0 + dv * ra, v0 + dv * rm, v0 + dv * rb
            k1x, k1v = vl, f(ta, xl, vl, xa, va)
            k2x, k2v = vl + 0.5 * dt * k1v, f(tm, xl + 0.5 * dt * k1x, vl + 0.5 * dt * k1v, xm, vm)
            k3x, k3v = vl + 0.5 * dt * k2v, f(tm, xl + 0.5 * dt * k2x, vl + 0.5 * dt * k2v, xm, vm)
            k4x, k4v = vl + dt * k3v, f(tb, xl + dt * k3x, vl + dt * k3v, xb, vb)
            xl += dt / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
            vl += dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        if not (math.isfinite(xl) and math.isfinite(vl)):
            raise StepRefused(self.name, t, h, f"the load's motion became non-finite ({xl}, {vl})")
        self.x = [xl, vl]
        self.t = t + h

    def update_outputs(self, t: float) -> None:
        self.t = t

    def get_outputs(self) -> list[float]:
        p = self.params
        xr, vr = self.u
        xl, vl = self.x
        fc = gap_contact_force(xl - xr, vl - vr, p.stiffness, p.damping, p.gap, p.bilateral)
        fs = p.stop_force(xr, vr)
        return [fc + fs, fc, fs, self.external(self.t), xl, vl, xl - xr]
