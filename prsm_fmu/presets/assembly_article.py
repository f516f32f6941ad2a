"""The multi-stage assembly article: the two-stage PRSM of the rigid-body Newton model with inter-stage friction.

Source: the multi-stage assembly article — the geometry table (radii, leads, starts, 7 rollers), the
"numerical simulations" paragraph (masses, moments of inertia, µ_RS = 0.05, the 100 rad/s step
and the 7000 N load) and the steady-state table (base scenario µ_SS = 0.10, µ_NS = 0.005).
The geometry is that of Li et al. (2021) §3.1, which also gives what the multi-stage assembly article
omits: the flank angle β = 45° and the spline radius r_SS2 = 13 mm.  Converted to SI
(``units.py``): mm → m, kg·mm² → kg·m² (× 1e-6).  The multi-stage assembly article's "helix angles" 9.27° and 5.51° are the lead angles
atan(L_S / (2π r_S)) of the two screws, and its 20° "pressure angle" belongs to the ring-gear
teeth, which these parameters do not describe.

Assumptions, each because the multi-stage assembly article does not give the number:

* Carrier masses: not given (nor in Li et al. (2021)).  As in ``li2021.py``, a carrier ring whose
  radius of gyration is the roller orbit radius r_S + r_R: m_P = J_P / (r_S + r_R)², i.e.
  0.0175 kg and 0.0411 kg.  They enter only the axial kinetic energy of the carriers.
* Carriers per stage: two (Li et al. (2021) Eq. 8, one at each roller end); J_P is per carrier.
* Thrust-bearing friction radius r_NS1 (nut 1 – screw 2): not given.  We take the nut 1 pitch
  radius, 16.25 mm, as the mean radius of a thrust bearing seated on nut 1.  Stage 2 has no
  bearing to a next stage (r_NS2 unused, 0).
* The scenario (not part of the parameters): a step of screw speed to 100 rad/s and a load of
  7000 N on nut 2, see :data:`SCENARIO`; variants raise µ_SS to 0.20 or µ_NS to 0.105.
"""

from __future__ import annotations

import math

from ..params import MechanismParams, StageParams
from .units import MM, KG_MM2


#: the multi-stage assembly article's operating point: screw speed [rad/s], load on nut 2 [N], simulated time [s]
SCENARIO = {"screw_speed": 100.0, "load_force": 7000.0, "t_end": 0.5}

#: the multi-stage assembly article's friction scenarios (µ_SS, µ_NS) of the steady-state table; µ_RS = 0.05 in all
FRICTION_SCENARIOS = {"base": (0.10, 0.005), "high_mu_ss": (0.20, 0.005),
                      "high_mu_ns": (0.10, 0.105)}


def _stage(r_s_mm: float, r_r_mm: float, r_n_mm: float, *, m_s: float, m_n: float, m_r: float,
           j_s: float, j_r: float, j_p: float, r_ss_mm: float, r_ns_mm: float) -> StageParams:
    orbit = (r_s_mm + r_r_mm) * MM
    return StageParams(
        screw_radius=r_s_mm * MM, roller_radius=r_r_mm * MM, nut_radius=r_n_mm * MM,
        screw_lead=10.0 * MM, screw_starts=5, flank_angle=math.radians(45.0), n_rollers=7,
        screw_mass=m_s, nut_mass=m_n, roller_mass=m_r, carrier_mass=j_p * KG_MM2 / orbit**2,
        screw_inertia=j_s * KG_MM2, roller_inertia=j_r * KG_MM2, carrier_inertia=j_p * KG_MM2,
        spline_radius=r_ss_mm * MM, bearing_radius=r_ns_mm * MM, carriers=2,
    )


def two_stage(scenario: str = "base") -> MechanismParams:
    """The multi-stage assembly article's two-stage PRSM with the friction of one of its scenarios.

    Parameters
    ----------
    scenario : str
        A key of :data:`FRICTION_SCENARIOS` (``"base"``, ``"high_mu_ss"``, ``"high_mu_ns"``).

    Returns
    -------
    MechanismParams
        SI parameters (validate() is called by the registry).
    """
    if scenario not in FRICTION_SCENARIOS:
        raise ValueError(f"scenario = {scenario!r} is out of range: must be one of "
                         f"{', '.join(FRICTION_SCENARIOS)}")
    mu_ss, mu_ns = FRICTION_SCENARIOS[scenario]
    stage1 = _stage(9.75, 3.25, 16.25, m_s=0.051, m_n=2.2, m_r=0.014,
                    j_s=51.94, j_r=0.077, j_p=2.95, r_ss_mm=0.0, r_ns_mm=16.25)
    stage2 = _stage(16.5, 5.5, 27.5, m_s=0.761, m_n=20.0, m_r=0.039,
                    j_s=172.3, j_r=0.471, j_p=19.88, r_ss_mm=13.0, r_ns_mm=0.0)
    return MechanismParams(
        stages=(stage1, stage2),
        mu_screw_roller=0.05, mu_spline=mu_ss, mu_nut_screw=mu_ns,
        name="assembly_two_stage" + ("" if scenario == "base" else f"_{scenario}"),
        source="the multi-stage assembly article (tables and simulation paragraph); "
               "Li et al. (2021) §3.1 (flank angle, spline radius)",
    )


PRESETS = {"assembly_two_stage": two_stage}
