"""Parameters of a multi-stage planetary roller screw mechanism (PRSM), in SI units.

Conventions (stated once here, in README.md and in docs/model.md):

* Stage 1 is driven by the motor; stage ``n`` carries the output (the rod).
* Screws, rollers and nuts are right-handed (seed ``000_a07c98907360be8b.txt`` §2.1).
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

#: relative tolerance of the geometric consistency checks (radii, leads)
GEOMETRY_RTOL = 1e-6

#: largest differential-sliding coefficient µ_3 [m]: a moment arm of rolling resistance is at most
#: a contact half-width, well below a millimetre for thread contacts (seed 003: ~1e-6 m)
MAX_MU_DIFFERENTIAL = 1e-3

#: largest viscous coefficient µ_1 per engaged thread [N·s/m]: 1e5 N·s/m puts 1e4 N on one thread
#: at 0.1 m/s of slip, the order of the largest normal force a thread carries; a lubricant film
#: that resists more than that is no film (seed 003: 0.001 N·s/m; its own load table needs ~580)
MAX_MU_VISCOUS = 1e5
#: the largest screw speed the FMUs accept as a start value [rad/s]: 10^4 rad/s (95,000 rpm) is
#: 20x beyond any PRSM (critical speeds of the seeds' screws are a few thousand rpm)
MAX_SCREW_SPEED = 1e4

#: most engaged thread turns per roller [-]: a roller 1 m long (the length bound) at 1 mm pitch
MAX_THREADS_PER_ROLLER = 1000


def _check_positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number > 0")


#: upper bounds of a stage's sizes: no PRSM has a radius or a lead of a metre, a part of ten
#: tonnes or a moment of inertia of 1000 kg.m2 (the seeds' largest: 27.5 mm, 18 kg,
#: 1.7e-4 kg.m2); beyond them the model's numbers lose their meaning before they overflow
MAX_SIZE = {"m": 1.0, "kg": 1e4, "kg.m2": 1e3}
#: unit of each bounded StageParams field
FIELD_UNITS = {"screw_radius": "m", "roller_radius": "m", "nut_radius": "m", "screw_lead": "m",
               "spline_radius": "m", "bearing_radius": "m", "screw_mass": "kg", "nut_mass": "kg",
               "roller_mass": "kg", "carrier_mass": "kg", "screw_inertia": "kg.m2",
               "roller_inertia": "kg.m2", "carrier_inertia": "kg.m2"}


def _check_at_most(name: str, value: float, unit: str) -> None:
    if value > MAX_SIZE[unit]:
        raise ValueError(f"{name} = {value!r} {unit} is out of range: must be at most "
                         f"{MAX_SIZE[unit]:g} {unit}")


def _check_non_negative(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
        raise ValueError(f"{name} = {value!r} is out of range: must be a finite number >= 0")


def _check_friction(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and 0.0 <= value < 1.0):
        raise ValueError(f"{name} = {value!r} is out of range: friction coefficient must be in [0, 1)")


#: the smallest spline radius relative to the screw's pitch radius (see _check_spline_radius)
SPLINE_RADIUS_MIN_FRACTION = 0.01


def _check_spline_radius(k: int, stage: "StageParams") -> None:
    """Bounds of the spline radius r_SSk of stage k > 1 (seed ``000_a07c98907360be8b.txt``, eq. 12).

    The internal spline teeth are cut in the bore of screw #k, so r_SSk lies inside its pitch
    radius r_Sk.  The spline friction f_Sk = µ_SS |M_Sk| / r_SSk grows without bound as
    r_SSk -> 0 (at 1e-30 m no step can succeed); below 1/100 of r_Sk the bore would leave a
    wall of 99 % of the screw's radius, which no design has.
    """
    r, r_s = stage.spline_radius, stage.screw_radius
    lo = SPLINE_RADIUS_MIN_FRACTION * r_s
    if not (isinstance(r, (int, float)) and lo <= r <= r_s):
        raise ValueError(
            f"stage[{k}].spline_radius = {r!r} m is out of range: must be in [{lo!r}, {r_s!r}] m "
            f"while mu_spline > 0 (from {SPLINE_RADIUS_MIN_FRACTION:g} x to 1 x "
            f"stage[{k}].screw_radius: the internal spline teeth lie in the bore of the screw)")


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
        Carriers per stage (one at each roller end in seed 000), default 2.
    threads_per_roller : int
        Engaged thread turns per roller at the screw–roller mesh, n_t [-] (seed
        ``003_e265d1d1167b0d4b.txt``'s "thread pitches per roller"), default 1.  Enters only the
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
        for f in ("screw_radius", "roller_radius", "nut_radius", "screw_lead", "screw_mass",
                  "nut_mass", "roller_mass", "carrier_mass", "screw_inertia",
                  "roller_inertia", "carrier_inertia"):
            _check_positive(f"{name}.{f}", getattr(self, f))
        for f in ("spline_radius", "bearing_radius"):
            _check_non_negative(f"{name}.{f}", getattr(self, f))
        for f, unit in FIELD_UNITS.items():
            _check_at_most(f"{name}.{f}", getattr(self, f), unit)
        _check_int_at_least(f"{name}.screw_starts", self.screw_starts, 1)
        _check_int_at_least(f"{name}.n_rollers", self.n_rollers, 1)
        _check_int_at_least(f"{name}.carriers", self.carriers, 1)
        _check_int_at_least(f"{name}.threads_per_roller", self.threads_per_roller, 1)
        if self.threads_per_roller > MAX_THREADS_PER_ROLLER:
            raise ValueError(f"{name}.threads_per_roller = {self.threads_per_roller!r} is out of "
                             f"range: must be in [1, {MAX_THREADS_PER_ROLLER}] (a roller at most "
                             "1 m long at 1 mm pitch)")
        if self.carriers > 2:
            raise ValueError(f"{name}.carriers = {self.carriers!r} is out of range: must be 1 or 2 "
                             "(a carrier at one or at both ends of the rollers)")
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
        # the rollers' axes lie on a circle of radius r_S + r_R; N_R rollers of radius r_R fit
        # around it without overlapping while N_R * 2 asin(r_R / (r_S + r_R)) <= 2 pi
        most = int(math.pi / math.asin(self.roller_radius / (self.screw_radius + self.roller_radius))
                   + 1e-9)
        if self.n_rollers > most:
            raise ValueError(
                f"{name}.n_rollers = {self.n_rollers!r} is out of range: must be in [1, {most}] "
                f"(rollers of radius {self.roller_radius!r} m fit around the screw without "
                "overlapping only up to that number)")
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
        (seed ``002_dfce4e5c6f831e77.txt``), in [0, 1).
    slip_velocity_scale : float
        Velocity v_ε [m/s] below which Coulomb friction is regularised (it becomes viscous
        with coefficient 2µ·F/v_ε), so that the friction force is continuous through zero slip.
    mu_viscous : float
        Lubricant viscous coefficient µ_1 at the screw–roller contacts [N·s/m] per engaged
        thread, in [0, inf): each roller feels µ_1 n_t |s| against its slip s (seed
        ``003_e265d1d1167b0d4b.txt``, F_fs1 = µ_1 n_R n_t v_sr).  0 (default): no viscous term.
    mu_differential : float
        Differential-sliding coefficient µ_3 [m], in [0, 1e-3]: a torque µ_3·F_N on each screw
        against its rotation, F_N the stage's total screw–roller normal force (seed 003,
        M_fs3 = −µ_3 F_nf, µ_3 ~ 1e-6 m).  0 (default): no differential-sliding term.
    name, source : str
        Registry key and citation (seed file and section) of the data.
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
        _check_friction("mu_screw_roller", self.mu_screw_roller)
        _check_friction("mu_spline", self.mu_spline)
        _check_friction("mu_nut_screw", self.mu_nut_screw)
        _check_positive("slip_velocity_scale", self.slip_velocity_scale)
        # the coefficients first: the radii's checks below depend on them
        _check_friction("mu_screw_roller", self.mu_screw_roller)
        _check_friction("mu_spline", self.mu_spline)
        _check_friction("mu_nut_screw", self.mu_nut_screw)
        _check_positive("slip_velocity_scale", self.slip_velocity_scale)
        mv = self.mu_viscous
        if not (isinstance(mv, (int, float)) and math.isfinite(mv) and 0.0 <= mv <= MAX_MU_VISCOUS):
            raise ValueError(
                f"mu_viscous = {mv!r} N·s/m is out of range: must be in [0, {MAX_MU_VISCOUS:g}] "
                "N·s/m (per engaged thread; beyond it a lubricant film would carry more than a "
                "thread's normal force)")
        m3 = self.mu_differential
        if not (isinstance(m3, (int, float)) and math.isfinite(m3)
                and 0.0 <= m3 <= MAX_MU_DIFFERENTIAL):
            raise ValueError(
                f"mu_differential = {m3!r} m is out of range: must be in [0, "
                f"{MAX_MU_DIFFERENTIAL:g}] m (a moment arm, ~1e-6 m in seed 003; at most a contact "
                "half-width)")
        for k, st in enumerate(self.stages, start=1):
            if not isinstance(st, StageParams):
                raise ValueError(f"stage[{k}] = {st!r} is not a StageParams")
            st.validate(f"stage[{k}]", geometry)
            if k > 1 and self.mu_spline > 0.0:
                if geometry:
                    _check_spline_radius(k, st)
                else:        # its bound relative to the screw radius is geometry (a design check)
                    _check_positive(f"stage[{k}].spline_radius", st.spline_radius)
            if k < len(self.stages) and self.mu_nut_screw > 0.0 and not st.bearing_radius > 0.0:
                raise ValueError(
                    f"stage[{k}].bearing_radius = {st.bearing_radius!r} is out of range: must be "
                    f"a finite number > 0 while mu_nut_screw = {self.mu_nut_screw!r} > 0 (the "
                    "thrust bearing's friction acts at that radius)")
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
