"""Parameters of a multi-stage planetary roller screw mechanism (PRSM), in SI units.

Conventions (stated here, in docs/architecture.md §4 and in docs/model.md):

* Stage 1 is driven by the motor; stage ``n`` carries the output (the rod).
* Screws, rollers and nuts are right-handed (Li et al. (2021) §2.1).
* A *standard* PRSM stage has a single-start roller whose lead equals the screw pitch
  ``L_S / n_S``, a nut with the screw's number of starts, and radii that satisfy both
  ``r_N = r_S + 2 r_R`` (the rollers fit between screw and nut) and ``r_N = n_S r_R``
  (roller and nut share the helix angle, so the roller rolls on the nut without axial
  drift).  Both are checked by :meth:`StageParams.validate`.
* Every length is in metres, every mass in kilograms, every moment of inertia in
  kg·m², every angle in radians.  Presets convert the papers' mm and kg·mm².
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

from .param_ranges import (MECHANISM_RANGES, SOLVER_RANGES, STAGE_RANGES, bearing_rule, max_rollers,
                           spline_rule)

#: relative tolerance of the geometric consistency checks (radii, leads)
GEOMETRY_RTOL = 1e-6

#: largest differential-sliding coefficient µ_3 [m], largest viscous coefficient µ_1 per engaged
#: thread [N·s/m], most engaged thread turns per roller: their reasons are in the table
#: (prsm_fmu.param_ranges), the one definition of every range
MAX_MU_DIFFERENTIAL = MECHANISM_RANGES["mu_differential"].hi
MAX_MU_VISCOUS = MECHANISM_RANGES["mu_viscous"].hi
MAX_THREADS_PER_ROLLER = STAGE_RANGES["threads_per_roller"].hi
#: the largest screw speed the FMUs accept as a start value [rad/s] (the table's bound of
#: ``initial_screw_speed``: 10^4 rad/s, 95,000 rpm, 20x beyond any PRSM)
MAX_SCREW_SPEED = SOLVER_RANGES["initial_screw_speed"].hi


def _check_positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number > 0")


def _check_int_at_least(name: str, value: Any, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} = {value!r} is out of range: must be an integer >= {minimum}")


@dataclass(frozen=True)
class StageParams:
    """Geometry, masses and inertias of one single-stage PRSM inside a multi-stage mechanism.

    Parameters
    ----------
    screw_radius : float
        Nominal (pitch) radius of the screw, r_S [m].
    roller_radius : float
        Nominal (pitch) radius of a roller, r_R [m].
    nut_radius : float
        Nominal (pitch) radius of the nut, r_N [m].
    screw_lead : float
        Lead of the screw, L_S = n_S · pitch [m].
    screw_starts : int
        Number of thread starts of the screw (and of the nut), n_S [-].
    flank_angle : float
        Flank angle β of the thread, between flank and radial plane [rad], in (0, π/2).
    n_rollers : int
        Number of rollers N_R [-].
    screw_mass, nut_mass, roller_mass, carrier_mass : float
        m_S, m_N, m_R, m_P [kg].  ``carrier_mass`` is per carrier; ``carriers`` carriers per stage.
        ``screw_mass`` of stage 1 does not enter the dynamics (screw 1 does not translate).
    screw_inertia, roller_inertia, carrier_inertia : float
        J_S, J_R, J_P about their own axes [kg·m²]; ``carrier_inertia`` is per carrier.
    spline_radius : float
        Nominal radius r_SS of the spline teeth that drive this screw from the previous one
        [m]; unused for stage 1.
    bearing_radius : float
        Effective friction radius r_NS of the thrust bearing between this stage's nut and the
        next stage's screw [m]; unused for the last stage.
    carriers : int
        Carriers per stage (one at each roller end in Li et al. (2021)), default 2.
    threads_per_roller : int
        Engaged thread turns per roller at the screw–roller mesh, n_t [-] (the
        friction-torque article's "thread pitches per roller"), default 1.  Enters only the
        viscous friction (``MechanismParams.mu_viscous`` acts per engaged thread).
    """

    screw_radius: float
    roller_radius: float
    nut_radius: float
    screw_lead: float
    screw_starts: int
    flank_angle: float
    n_rollers: int
    screw_mass: float
    nut_mass: float
    roller_mass: float
    carrier_mass: float
    screw_inertia: float
    roller_inertia: float
    carrier_inertia: float
    spline_radius: float = 0.0
    bearing_radius: float = 0.0
    carriers: int = 2
    threads_per_roller: int = 1

    # ---- derived quantities -------------------------------------------------------------
    @property
    def pitch(self) -> float:
        """Thread pitch p = L_S / n_S [m], also the roller's lead (single-start roller)."""
        return self.screw_lead / self.screw_starts

    @property
    def roller_lead(self) -> float:
        """Lead of the single-start roller thread [m] (equal to the pitch)."""
        return self.pitch

    @property
    def carrier_orbit_radius(self) -> float:
        """Distance between screw axis and roller axis, r_S + r_R [m]."""
        return self.screw_radius + self.roller_radius

    def validate(self, name: str = "stage", geometry: bool = True) -> "StageParams":
        """Check every field against its physical range.

        Parameters
        ----------
        name : str
            Prefix used in error messages, e.g. ``"stage[2]"``.
        geometry : bool
            Also require the radii to mesh (r_N = r_S + 2 r_R = n_S r_R).  False checks each
            field's own range only, for design checks that grade the meshing conditions
            instead of refusing them (:mod:`prsm_fmu.design_checks`).

        Returns
        -------
        StageParams
            ``self``, so that calls can be chained.

        Raises
        ------
        ValueError
            Naming the field, its value and the allowed range.
        """
        for f, rule in STAGE_RANGES.items():
            hi = (max_rollers(self.screw_radius, self.roller_radius)
                  if f == "n_rollers" and geometry else None)
            rule.check(f"{name}.{f}", getattr(self, f), hi=hi)
        beta = self.flank_angle
        if not (isinstance(beta, (int, float)) and math.isfinite(beta) and 0.0 < beta < math.pi / 2):
            raise ValueError(
                f"{name}.flank_angle = {beta!r} rad is out of range: must be in (0, pi/2) rad, "
                "i.e. (0°, 90°)")
        if not geometry:
            return self
        fit = self.screw_radius + 2.0 * self.roller_radius
        if abs(self.nut_radius - fit) > GEOMETRY_RTOL * fit:
            raise ValueError(
                f"{name}.nut_radius = {self.nut_radius!r} m is inconsistent with "
                f"screw_radius + 2*roller_radius = {fit!r} m: must equal it "
                f"(relative tolerance {GEOMETRY_RTOL:g})")
        engaged = self.screw_starts * self.roller_radius
        if abs(self.nut_radius - engaged) > GEOMETRY_RTOL * engaged:
            raise ValueError(
                f"{name}.nut_radius = {self.nut_radius!r} m is inconsistent with the roller lead: "
                f"a single-start roller of lead pitch = screw_lead/screw_starts stays engaged with "
                f"the nut only if nut_radius = screw_starts*roller_radius = {engaged!r} m "
                f"(relative tolerance {GEOMETRY_RTOL:g})")
        return self


@dataclass(frozen=True)
class MechanismParams:
    """A multi-stage PRSM: its stages (stage 1 first) and its friction coefficients.

    Parameters
    ----------
    stages : tuple of StageParams
        At least one stage; stage 1 is driven, the last stage's nut is the output.
    mu_screw_roller : float
        Coulomb coefficient µ_SR at the screw–roller thread contacts [-], in [0, 1).
    mu_spline : float
        Coulomb coefficient µ_SS between the spline teeth of consecutive screws [-], in [0, 1).
    mu_nut_screw : float
        Coulomb coefficient µ_NS of the thrust bearings between nut k and screw k+1 [-]
        (the multi-stage assembly article), in [0, 1).
    slip_velocity_scale : float
        Velocity v_ε [m/s] below which Coulomb friction is regularised (it becomes viscous
        with coefficient 2µ·F/v_ε), so that the friction force is continuous through zero slip.
    mu_viscous : float
        Lubricant viscous coefficient µ_1 at the screw–roller contacts [N·s/m] per engaged
        thread, in [0, inf): each roller feels µ_1 n_t |s| against its slip s (the
        friction-torque article, F_fs1 = µ_1 n_R n_t v_sr).  0 (default): no viscous term.
    mu_differential : float
        Differential-sliding coefficient µ_3 [m], in [0, 1e-3]: a torque µ_3·F_N on each screw
        against its rotation, F_N the stage's total screw–roller normal force (the friction-torque article,
        M_fs3 = −µ_3 F_nf, µ_3 ~ 1e-6 m).  0 (default): no differential-sliding term.
    name, source : str
        Registry key and citation (paper and section, as docs/references.md) of the data.
    """

    stages: tuple[StageParams, ...]
    mu_screw_roller: float = 0.05
    mu_spline: float = 0.1
    mu_nut_screw: float = 0.0
    slip_velocity_scale: float = 1e-4
    mu_viscous: float = 0.0
    mu_differential: float = 0.0
    name: str = "custom"
    source: str = ""
    notes: str = field(default="", compare=False)

    @property
    def n_stages(self) -> int:
        """Number of stages n_T [-]."""
        return len(self.stages)

    @property
    def total_lead(self) -> float:
        """Output (rod) travel per screw revolution, Σ L_Sk [m]."""
        return sum(s.screw_lead for s in self.stages)

    def validate(self, geometry: bool = True) -> "MechanismParams":
        """Check every stage and every friction parameter.

        Parameters
        ----------
        geometry : bool
            Also require every stage's radii to mesh (see :meth:`StageParams.validate`) and the
            spline radii to lie within their screws' radii.

        Returns
        -------
        MechanismParams
            ``self``.

        Raises
        ------
        ValueError
            Naming the parameter (``stage[k].field`` with k from 1), its value and its range.
        """
        if not isinstance(self.stages, tuple) or len(self.stages) < 1:
            raise ValueError(
                f"stages = {self.stages!r} is out of range: need a tuple of at least 1 StageParams")
        # the coefficients first: the radii's checks below depend on them
        for f, rule in MECHANISM_RANGES.items():
            rule.check(f, getattr(self, f))
        for k, st in enumerate(self.stages, start=1):
            if not isinstance(st, StageParams):
                raise ValueError(f"stage[{k}] = {st!r} is not a StageParams")
            st.validate(f"stage[{k}]", geometry)
            conditional = ([spline_rule(k, st.screw_radius if geometry else None)] if k > 1
                           else []) + ([bearing_rule(k)] if k < len(self.stages) else [])
            for rule in conditional:
                if getattr(self, rule.when) > 0.0:
                    rule.range.check(rule.name, getattr(st, rule.name.split(".", 1)[1]),
                                     lo=rule.lo, hi=rule.hi)
        return self

    def with_changes(self, **changes: Any) -> "MechanismParams":
        """Return a copy with mechanism-level fields replaced (e.g. ``mu_screw_roller=0.1``)."""
        return replace(self, **changes)

    def with_stage(self, k: int, **changes: Any) -> "MechanismParams":
        """Return a copy whose stage ``k`` (1-based) has the given fields replaced."""
        if not 1 <= k <= self.n_stages:
            raise ValueError(f"k = {k!r} is out of range: must be in [1, {self.n_stages}]")
        stages = list(self.stages)
        stages[k - 1] = replace(stages[k - 1], **changes)
        return replace(self, stages=tuple(stages))


#: fields of MechanismParams that are physical parameters (every one an FMU parameter, a sweep
#: name and a loop parameter; the rest are the stages and labels)
MECHANISM_FIELD_NAMES = ("mu_screw_roller", "mu_spline", "mu_nut_screw", "slip_velocity_scale",
                         "mu_viscous", "mu_differential")


def stage_field_names() -> tuple[str, ...]:
    """Names of the per-stage fields, in declaration order (used by the FMU's parameter table)."""
    return tuple(f.name for f in fields(StageParams))
