"""The one definition of every parameter's range, type and message.

Both FMUs refuse the same values with the same words: the Python package checks its
parameters with :meth:`Range.check` (``StageParams.validate``, ``MechanismParams.validate``,
``configure``), and ``fmu_build.native_ranges`` generates the native FMU's C table of the same
rules from :func:`fmu_rules` (``prsm_params_gen.h``), walked by a loop that formats the same
message.  Numbers in messages are written by :func:`fmt` (the shortest ``%.<p>g`` that reads
back to the same double, for p = 1..17), which C's ``printf`` reproduces character for
character.

A rule's bounds are constants, or a function of the stage's geometry (``n_rollers``: how many
rollers fit; ``spline_radius`` while ``mu_spline > 0``: r_S/100 .. r_S; ``FmuRule.derived``
says which), which the native FMU evaluates from the geometry set at initialization, or another
parameter's value
(``substeps`` ≤ ``max_substeps``).  A rule may apply only while another parameter is > 0
(``when``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

__all__ = ["Range", "fmt", "STAGE_RANGES", "MECHANISM_RANGES", "SOLVER_RANGES", "FmuRule",
           "fmu_rules", "max_rollers", "spline_rule", "bearing_rule", "INPUT_BOUNDS",
           "STATE_BOUNDS", "SMALLEST", "MAX_QUOTIENT", "input_violation", "state_violation",
           "SPLINE_RADIUS_MIN_FRACTION", "KINETIC_ENERGY_MAX", "speed_bounds"]

#: the smallest spline radius relative to the screw's pitch radius (Li et al. (2021), eq. 12:
#: the spline friction µ_SS |M| / r_SS grows without bound as r_SS -> 0; below r_S/100 the bore
#: would leave a wall of 99 % of the screw's radius, which no design has)
SPLINE_RADIUS_MIN_FRACTION = 0.01


def fmt(value: Any) -> str:
    """A number as the messages write it: the shortest ``%.<p>g`` (p = 1..17) that reads back
    to the same double; ``nan``, ``inf``, ``-inf``; an int in decimal; anything else its repr."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if math.isnan(value):
        return "nan"
    for p in range(1, 18):
        s = "%.*g" % (p, value)
        if float(s) == value:
            return s
    return "%.17g" % value


@dataclass(frozen=True)
class Range:
    """Allowed values of one parameter.

    Attributes
    ----------
    lo, hi : float
        Bounds (``hi`` None: no upper bound); both finite when given.
    lo_open, hi_open : bool
        Whether the bound itself is excluded.
    integer : bool
        An integer (Python ``int``, not ``bool``) rather than a finite float.
    unit : str
        SI unit written after the value and the interval ("" for none).
    note : str
        Why, written in parentheses after the interval.
    """

    lo: float
    hi: float | None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    unit: str = ""
    note: str = ""

    def ok(self, value: Any, lo: float | None = None, hi: float | None = None) -> bool:
        """Whether ``value`` is allowed (``lo``/``hi`` replace derived bounds)."""
        lo = self.lo if lo is None else lo
        hi = self.hi if hi is None else hi
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if self.integer and not isinstance(value, int):
            return False
        if not math.isfinite(value):
            return False
        if value < lo or (self.lo_open and value == lo):
            return False
        return hi is None or value < hi or (value == hi and not self.hi_open)

    def message(self, name: str, value: Any, lo: float | None = None,
                hi: float | None = None) -> str:
        """The one-line refusal: name, value, interval, unit and note."""
        lo = self.lo if lo is None else lo
        hi = self.hi if hi is None else hi
        unit = f" {self.unit}" if self.unit else ""
        interval = ("(" if self.lo_open else "[") + fmt(lo) + ", " + \
            ("inf)" if hi is None else fmt(hi) + (")" if self.hi_open else "]"))
        kind = "an integer in " if self.integer else "in "
        note = f" ({self.note})" if self.note else ""
        return f"{name} = {fmt(value)}{unit} is out of range: must be {kind}{interval}{unit}{note}"

    def check(self, name: str, value: Any, lo: float | None = None,
              hi: float | None = None) -> None:
        """Raise ValueError with :meth:`message` unless ``value`` is allowed."""
        if not self.ok(value, lo, hi):
            raise ValueError(self.message(name, value, lo, hi))


_SIZE = "no PRSM comes near it; the papers' largest: 27.5 mm, 18 kg, 1.7e-4 kg.m2"


def _length(lo_open: bool = True) -> Range:
    return Range(0.0, 1.0, lo_open=lo_open, unit="m", note=_SIZE)


def _mass() -> Range:
    return Range(0.0, 1e4, lo_open=True, unit="kg", note=_SIZE)


def _inertia() -> Range:
    return Range(0.0, 1e3, lo_open=True, unit="kg.m2", note=_SIZE)


def _friction(what: str) -> Range:
    return Range(0.0, 1.0, hi_open=True, note=f"Coulomb coefficient {what}")


#: per-stage fields (StageParams), checked in this order
STAGE_RANGES: dict[str, Range] = {
    "screw_radius": _length(), "roller_radius": _length(), "nut_radius": _length(),
    "screw_lead": _length(),
    "screw_starts": Range(1, 1000, integer=True, note="thread starts of screw and nut"),
    "n_rollers": Range(1, 1000, integer=True, note="rollers that fit around the screw"),
    "screw_mass": _mass(), "nut_mass": _mass(), "roller_mass": _mass(), "carrier_mass": _mass(),
    "screw_inertia": _inertia(), "roller_inertia": _inertia(), "carrier_inertia": _inertia(),
    "spline_radius": _length(lo_open=False), "bearing_radius": _length(lo_open=False),
    "carriers": Range(1, 2, integer=True, note="a carrier at one or at both ends of the rollers"),
    "threads_per_roller": Range(1, 1000, integer=True,
                                note="a roller at most 1 m long at 1 mm pitch"),
}

#: mechanism-level fields (MechanismParams), checked before the stages (the radii's
#: conditional rules depend on them)
MECHANISM_RANGES: dict[str, Range] = {
    "mu_screw_roller": _friction("at the screw-roller thread contacts"),
    "mu_spline": _friction("between the spline teeth of consecutive screws"),
    "mu_nut_screw": _friction("of the thrust bearings between nut k and screw k+1"),
    "slip_velocity_scale": Range(0.0, 1.0, lo_open=True, unit="m/s",
                                 note="sliding speed below which Coulomb friction is "
                                      "regularised; a slip of 1 m/s is no longer small"),
    "mu_viscous": Range(0.0, 1e5, unit="N.s/m", note="per engaged thread; beyond it a "
                        "lubricant film would carry more than a thread's normal force"),
    "mu_differential": Range(0.0, 1e-3, unit="m", note="a moment arm, ~1e-6 m in the "
                             "friction-torque article; at most a contact half-width"),
}

#: the FMU's own parameters (configure), in this order; substeps' upper bound is max_substeps
SOLVER_RANGES: dict[str, Range] = {
    "tolerance": Range(1e-12, 0.1, note="below 1e-12 the error estimates are rounding noise; "
                       "above 0.1 auto may carry a model error of a tenth"),
    "max_substeps": Range(10, 100_000, integer=True, note="bounds the work of one doStep"),
    "substeps": Range(0, None, integer=True, note="0: adaptive; at most max_substeps"),
    "kinematic_efficiency": Range(0.0, 1.0, lo_open=True),
    "initial_screw_speed": Range(-1e4, 1e4, unit="rad/s",
                                 note="95,000 rpm, 20 times any PRSM's critical speed"),
    "initial_screw_angle": Range(-1e6, 1e6, unit="rad", note="beyond it a step's angle "
                                 "increment loses its digits to the angle's magnitude"),
}


def max_rollers(screw_radius: float, roller_radius: float) -> int:
    """Most rollers of radius r_R around a screw of radius r_S: their axes lie on a circle of
    radius r_S + r_R, and N_R of them fit without overlapping while
    N_R · 2 asin(r_R / (r_S + r_R)) <= 2π."""
    return int(math.pi / math.asin(roller_radius / (screw_radius + roller_radius)) + 1e-9)


@dataclass(frozen=True)
class FmuRule:
    """One concrete rule of an FMU with n stages: qualified name, range, derived bounds and
    the parameter (name) that must be > 0 for the rule to apply (None: always)."""

    name: str
    range: Range
    lo: float | None = None
    hi: float | None = None
    hi_parameter: str | None = None
    when: str | None = None
    #: how ``lo``/``hi`` follow from the stage's geometry, for an FMU whose geometry is set at
    #: initialization (the native FMU evaluates them then): ``"max_rollers"`` (hi =
    #: :func:`max_rollers` of the stage's radii) or ``"spline"`` (from
    #: SPLINE_RADIUS_MIN_FRACTION × to 1 × the stage's screw radius); None: constant bounds
    derived: str | None = None


def spline_rule(k: int, screw_radius: float | None) -> FmuRule:
    """stage[k].spline_radius while mu_spline > 0 (k > 1): from r_S/100 to r_S (Li et al.
    (2021), eq. 12); ``screw_radius`` None: only > 0 (design checks grade the geometry)."""
    if screw_radius is None:
        return FmuRule(f"stage[{k}].spline_radius",
                       Range(0.0, 1.0, lo_open=True, unit="m", note="while mu_spline > 0"),
                       when="mu_spline")
    return FmuRule(f"stage[{k}].spline_radius",
                   Range(0.0, 1.0, unit="m", note="while mu_spline > 0: from 0.01 x to 1 x the "
                         "screw radius; the internal spline teeth lie in the bore of the screw"),
                   lo=SPLINE_RADIUS_MIN_FRACTION * screw_radius, hi=screw_radius,
                   when="mu_spline", derived="spline")


def bearing_rule(k: int) -> FmuRule:
    """stage[k].bearing_radius while mu_nut_screw > 0 (k < n): > 0."""
    return FmuRule(f"stage[{k}].bearing_radius",
                   Range(0.0, 1.0, lo_open=True, unit="m", note="while mu_nut_screw > 0: the "
                         "thrust bearing's friction acts at that radius"), when="mu_nut_screw")


def fmu_rules(stages: tuple, geometry: Callable[[int], tuple[float, float]] | None = None
              ) -> list[FmuRule]:
    """Every rule of an FMU with ``len(stages)`` stages, in the order they are checked.

    Parameters
    ----------
    stages : tuple
        One item per stage (only the count matters unless ``geometry`` is None).
    geometry : callable, optional
        k -> (screw_radius, roller_radius) of stage k (1-based), for the bounds derived from
        the geometry; default: read from ``stages[k-1]`` (StageParams).
    """
    n = len(stages)
    if geometry is None:
        def geometry(k: int) -> tuple[float, float]:
            st = stages[k - 1]
            return st.screw_radius, st.roller_radius
    rules = [FmuRule(name, r) for name, r in MECHANISM_RANGES.items()]
    for k in range(1, n + 1):
        r_s, r_r = geometry(k)
        for f, r in STAGE_RANGES.items():
            rolls = f == "n_rollers"
            rules.append(FmuRule(f"stage[{k}].{f}", r, hi=max_rollers(r_s, r_r) if rolls else None,
                                 derived="max_rollers" if rolls else None))
        if k > 1:
            rules.append(spline_rule(k, r_s))
        if k < n:
            rules.append(bearing_rule(k))
    for name, r in SOLVER_RANGES.items():
        rules.append(FmuRule(name, r, hi_parameter="max_substeps" if name == "substeps" else None))
    return rules


# ---- bounds of the inputs and of the state: every output finite ------------------------------
#: |input| at most: 10^6 N.m on the screw and 10^8 N on the rod are 10^4 times the papers'
#: largest (≈ 40 N.m, 8 kN); a step with a larger input is refused (docs/fmu.md, Errors)
INPUT_BOUNDS: dict[str, tuple[float, str]] = {"screw_torque": (1e6, "N.m"),
                                              "load_force": (1e8, "N")}
#: |state component| at most: the screw angle [rad] (a year at 10^4 rad/s is 3e11 rad; beyond
#: 10^15 rad a step's increment loses its digits), every work integral [J]; the speeds' bounds
#: follow from the parameters (:func:`speed_bounds`)
STATE_BOUNDS: dict[str, tuple[float, str]] = {"angle": (1e15, "rad"), "work": (1e150, "J")}
#: the largest kinetic energy a state may carry [J]: the work integrals' bound, so that the
#: energy balance input_work = output_work + friction_work + Δkinetic_energy stays representable
KINETIC_ENERGY_MAX = STATE_BOUNDS["work"][0]
#: a nonzero input smaller than this in magnitude is refused: ``efficiency`` divides the load's
#: power by the motor's, about F c / T, which stays below 1e300 for |T| >= 1e-150 N.m
SMALLEST = 1e-150
#: largest quotient an output may take: carrier_speed_ratio = carrier speed / screw speed and
#: overall_efficiency = output work / input work; a state that would make either larger (a
#: subnormal screw speed under spinning carriers, a subnormal input work) is refused
MAX_QUOTIENT = 1e300


def input_violation(u: tuple[float, float]) -> str | None:
    """Why the inputs (screw_torque [N.m], load_force [N]) are refused, or None."""
    for (name, (bound, unit)), v in zip(INPUT_BOUNDS.items(), u):
        if not (v == 0.0 or SMALLEST <= abs(v) <= bound):
            return (f"input {name} = {fmt(v)} {unit} is out of range: must be 0 or of magnitude "
                    f"in [{fmt(SMALLEST)}, {fmt(bound)}] {unit}")
    return None


def speed_bounds(inertias: Sequence[float]) -> tuple[float, ...]:
    """|speed| at most [rad/s] of each of the n speed states whose kinetic energy is
    ½ J_i ω_i² (``inertias`` J_i [kg·m²]): sqrt(2 E / (n J_i)), E = :data:`KINETIC_ENERGY_MAX`,
    so that the kinetic energy of any state within them is at most E (inf where J_i <= 0)."""
    n = len(inertias)
    return tuple(math.sqrt(2.0 * KINETIC_ENERGY_MAX / (n * j)) if j > 0.0 else math.inf
                 for j in inertias)


def state_violation(x, speeds: Sequence[float] | None = None) -> str | None:
    """Why the model state x = (angle, speed, [carrier speeds], input, output and friction
    work) is out of :data:`STATE_BOUNDS`, out of the speed bounds ``speeds`` (one per speed
    state, :func:`prsm_fmu.models.base.model_speed_bounds`; None: not checked) or would make a quotient among the
    outputs exceed :data:`MAX_QUOTIENT`, or None."""
    n = len(x)
    for i, v in enumerate(x):
        if 0 < i < n - 3:
            if speeds is None:
                continue
            bound = speeds[i - 1]
            if not abs(v) <= bound:
                return (f"state x[{i}] (speed) = {fmt(v)} rad/s is out of range: must be in "
                        f"[-{fmt(bound)}, {fmt(bound)}] rad/s (kinetic energy at most "
                        f"{fmt(KINETIC_ENERGY_MAX)} J)")
            continue
        kind = "angle" if i == 0 else "work"
        bound, unit = STATE_BOUNDS[kind]
        if not abs(v) <= bound:
            return (f"state x[{i}] ({kind}) = {fmt(v)} {unit} is out of range: must be in "
                    f"[-{fmt(bound)}, {fmt(bound)}] {unit}")
    omega, w_in, w_out = x[1], x[n - 3], x[n - 2]
    for i in range(2, n - 3):
        if omega != 0.0 and abs(x[i]) > MAX_QUOTIENT * abs(omega):
            return (f"state x[{i}] (carrier speed) = {fmt(x[i])} rad/s is out of range for the "
                    f"screw speed {fmt(omega)} rad/s: carrier_speed_ratio must stay within "
                    f"{fmt(MAX_QUOTIENT)}")
    if w_in > 0.0 and abs(w_out) > MAX_QUOTIENT * w_in:
        return (f"state x[{n - 2}] (output work) = {fmt(w_out)} J is out of range for the input "
                f"work {fmt(w_in)} J: overall_efficiency must stay within {fmt(MAX_QUOTIENT)}")
    return None
