"""One spelling per unit, for every CSV header, plot label and printed table.

The FMU's modelDescription spells units in the FMI 2.0 unit syntax (``N.m``, ``rad/s2``,
``kg.m2``, ``1`` for a dimensionless quantity); the files and figures the tools write use the
same spellings, taken from here, so a column ``driven_torque [N.m]`` means the same in
``startup.csv``, a scene's CSV, a regression baseline and the FMU.  Scaled units of plot axes
(``ms``, ``mm``, ``kN``) are spelled the same way (FMI prefix + unit, no spaces).

:data:`OUTPUT_UNITS` gives the unit of each name of the output vocabulary
(docs/architecture.md §4, "Conventions"); :func:`unit_of` looks up a full name such as ``stage[2].driven_torque``.
"""

from __future__ import annotations

__all__ = ["SECOND", "MILLISECOND", "METRE", "MILLIMETRE", "MICROMETRE", "METRE_PER_SECOND",
           "MILLIMETRE_PER_SECOND", "AMPERE", "VOLT", "RADIAN",
           "RADIAN_PER_SECOND", "RADIAN_PER_SECOND2", "NEWTON", "KILONEWTON", "NEWTON_METRE",
           "WATT", "JOULE", "KILOGRAM", "KILOGRAM_METRE2", "NEWTON_SECOND_PER_METRE", "DIMENSIONLESS", "OUTPUT_UNITS",
           "unit_of", "label"]

SECOND = "s"
MILLISECOND = "ms"
METRE = "m"
MILLIMETRE = "mm"
MICROMETRE = "µm"
METRE_PER_SECOND = "m/s"
MILLIMETRE_PER_SECOND = "mm/s"
AMPERE = "A"
VOLT = "V"
RADIAN = "rad"
RADIAN_PER_SECOND = "rad/s"
RADIAN_PER_SECOND2 = "rad/s2"
NEWTON = "N"
KILONEWTON = "kN"
NEWTON_METRE = "N.m"
WATT = "W"
JOULE = "J"
KILOGRAM = "kg"
KILOGRAM_METRE2 = "kg.m2"
NEWTON_SECOND_PER_METRE = "N.s/m"
#: a dimensionless quantity (a ratio, an efficiency, a friction coefficient)
DIMENSIONLESS = "1"

#: unit of each output name, by full name or by the part after ``stage[k].``
OUTPUT_UNITS: dict[str, str] = {
    "time": SECOND,
    "screw_speed": RADIAN_PER_SECOND, "screw_angle": RADIAN,
    "screw_acceleration": RADIAN_PER_SECOND2, "screw_torque": NEWTON_METRE,
    "rod_position": METRE, "rod_velocity": METRE_PER_SECOND, "load_force": NEWTON,
    "contact_force": NEWTON, "normal_force": NEWTON, "driven_torque": NEWTON_METRE,
    "spline_friction": NEWTON, "carrier_speed": RADIAN_PER_SECOND,
    "carrier_speed_ratio": DIMENSIONLESS, "efficiency": DIMENSIONLESS,
    "friction_power": WATT, "input_power": WATT, "output_power": WATT,
    "input_work": JOULE, "output_work": JOULE, "friction_work": JOULE, "kinetic_energy": JOULE,
    "rod_force": NEWTON, "bearing_force": NEWTON, "residual_norm": DIMENSIONLESS,
    "friction_torque": NEWTON_METRE, "speed_reference": RADIAN_PER_SECOND,
    "friction_power_coulomb": WATT, "friction_power_viscous": WATT,
    "friction_power_differential": WATT, "friction_power_joints": WATT,
    "screw_friction_torque": NEWTON_METRE, "overall_efficiency": DIMENSIONLESS,
}


def unit_of(name: str, default: str = "?") -> str:
    """Unit of an output name, e.g. ``"stage[2].driven_torque"`` → ``"N.m"``.

    Parameters
    ----------
    name : str
        An output name of the vocabulary (``time`` included), optionally ``stage[k].``-prefixed.
    default : str
        Returned for a name that is not in :data:`OUTPUT_UNITS`.

    Returns
    -------
    str
        The unit in FMI syntax (``"1"`` for dimensionless quantities), or ``default``.
    """
    base = name.split(".", 1)[1] if name.startswith("stage[") and "." in name else name
    return OUTPUT_UNITS.get(base, default)


def label(text: str, unit: str) -> str:
    """An axis label or column header ``"text [unit]"`` (the one format every tool uses)."""
    return f"{text} [{unit}]"
