"""The recirculating-screw article: the recirculating roller screw of the kinematic and ADAMS study.

Source: the recirculating-screw article — Table 2 (12 grooved rollers of pitch diameter 6.63 mm;
right-handed single-start screw and nut of lead 1 mm, pitch diameters 31.13 mm and 44.14 mm) and
the simulation paragraph (4π rad/s counterclockwise for 1 s; loads 5, 10, 15 kN).  Converted to SI.

The three diameters do not fit exactly: d_s + 2 d_r = 44.39 mm against d_n = 44.14 mm, a misfit
of 0.25 mm (0.57 % of d_n), within ``RECIRCULATING_FIT_RTOL``.  The ideal kinematics in
:mod:`prsm_fmu.kinematics` do not need the fit; docs/kinematics.md shows what it does to the
paper's Table 3.

Sign: the paper counts clockwise positive and reports the screw at −12.57 rad/s, the carrier at
−5.19 rad/s (theory) and the nut at +2.00 mm/s; :data:`SCENARIO` therefore holds ω_s = −4π rad/s.
"""

from __future__ import annotations

import math

from ..kinematics import RecirculatingParams
from .units import MM



#: the recirculating-screw article's run: screw speed in the paper's sign [rad/s], duration [s], loads on the nut [N]
SCENARIO = {"screw_speed": -4.0 * math.pi, "t_end": 1.0, "load_forces": (5e3, 10e3, 15e3)}


def recirculating() -> RecirculatingParams:
    """The recirculating-screw article's Table 2 recirculating roller screw.

    Returns
    -------
    RecirculatingParams
        SI parameters (validate() is called by the registry).
    """
    return RecirculatingParams(
        screw_diameter=31.13 * MM, nut_diameter=44.14 * MM, roller_diameter=6.63 * MM,
        screw_lead=1.0 * MM, screw_starts=1, n_rollers=12,
        name="recirculating_screw", source="the recirculating-screw article Table 2",
    )


PRESETS = {"recirculating_screw": recirculating}
