"""Li et al. (2021) §3.1–3.3 at its base case: the paper's statements as tests.

Base case: µ_SR = 0.1, µ_SS = 0.2 (the smallest pair of §3.2; the preset's docstring says why),
screw speed stepped to 100 rad/s at t = 0 with both carriers at rest, F_N2 = 5000 N.

Settling time: the first time after which |ζ − ζ_final| stays within 0.1 % of ζ_final
(ζ_final = ζ at 2 ms, > 20 time constants of the slower carrier).  The paper reads its times
from Fig. 3a ("about 0.14 ms", "after t = 0.46 ms") without stating a band; the carriers
approach equilibrium exponentially, so any band is a choice: over bands from 0.3 % to 0.03 %
the model's times move by about ±13 %.  Tolerance ±20 %: the reading of a figure at an unstated
band.  Efficiency: the paper's "less than 0.45 at the beginning" and "nearly to 0.80", read as
0.80 ± 0.01.
"""

from __future__ import annotations

import numpy as np
import pytest

from prsm_fmu import presets, simulate, steady_state

LI2021 = presets.load("li2021_two_stage")
BAND = 1e-3
RADAU = {"stepper": "radau", "stepper_options": {"rtol": 1e-10, "atol": 1e-12}}


def settling_time(t, y, band=BAND):
    """First time after which |y − y[-1]| stays within band·|y[-1]| [s]."""
    final = y[-1]
    outside = np.nonzero(np.abs(y - final) > band * abs(final))[0]
    return 0.0 if outside.size == 0 else float(t[min(outside[-1] + 1, len(t) - 1)])


def startup(params, t_end=2e-3, h=2e-6, **kw):
    return simulate(params, "dynamic", "speed", screw_speed=100.0, load_force=5000.0,
                    t_end=t_end, output_interval=h, **{**RADAU, **kw})


@pytest.fixture(scope="module")
def base():
    return startup(LI2021)


def test_carriers_settle_within_the_papers_times(base):
    t = base["time"]
    t1 = settling_time(t, base["stage[1].carrier_speed_ratio"])
    t2 = settling_time(t, base["stage[2].carrier_speed_ratio"])
    assert t1 == pytest.approx(0.14e-3, rel=0.20)     # paper: "about 0.14 ms"
    assert t2 == pytest.approx(0.46e-3, rel=0.20)     # paper: "after t = 0.46 ms"
    assert t1 < t2                                     # carrier 2 takes longer (§4)


def test_efficiency_starts_below_045_and_settles_near_080(base):
    eta = base["efficiency"]
    assert eta[0] < 0.45                               # "less than 0.45 at the beginning"
    assert eta[-1] == pytest.approx(0.80, abs=0.01)    # "increases nearly to 0.80"


def test_carrier_two_is_faster_than_carrier_one_at_steady_state(base):
    assert base["stage[2].carrier_speed_ratio"][-1] > base["stage[1].carrier_speed_ratio"][-1]


def test_stage_one_carries_more_torque_and_contact_force_throughout(base):
    assert np.all(base["stage[1].driven_torque"] > base["stage[2].driven_torque"])   # "all the time"
    assert np.all(base["stage[1].contact_force"] > base["stage[2].contact_force"])   # "always"
    # driven torques start above their steady values (Fig. 3b)
    for k in (1, 2):
        m = base[f"stage[{k}].driven_torque"]
        assert m[0] > m[-1]


def test_section_3_2_dynamic_trends():
    """µ_SR 0.1 → 0.2: the carriers' slopes steepen (they settle sooner) and the contact forces'
    rise between t = 0 and 0.75 ms grows; µ_SS does not change F_Srz2 at any time."""
    runs = {(mu_sr, mu_ss): startup(LI2021.with_changes(mu_screw_roller=mu_sr, mu_spline=mu_ss),
                                    t_end=1e-3, h=5e-6)
            for mu_sr, mu_ss in ((0.1, 0.2), (0.2, 0.2), (0.1, 0.3))}
    lo, hi, ss = runs[(0.1, 0.2)], runs[(0.2, 0.2)], runs[(0.1, 0.3)]
    i75 = int(round(0.75e-3 / 5e-6))
    for k in (1, 2):
        z = f"stage[{k}].carrier_speed_ratio"
        assert settling_time(hi["time"], hi[z]) < settling_time(lo["time"], lo[z])
        f = f"stage[{k}].contact_force"
        assert abs(hi[f][i75] - hi[f][0]) > abs(lo[f][i75] - lo[f][0])
    # "the contact force between screw #2 and roller #2 is independent from µ_SS"
    assert np.max(np.abs(ss["stage[2].contact_force"] - lo["stage[2].contact_force"])) <= 1e-9 * 5000


def test_section_3_2_steady_trends():
    def ss(mu_sr, mu_ss):
        return steady_state(LI2021.with_changes(mu_screw_roller=mu_sr, mu_spline=mu_ss), 100.0, 5000.0)
    base = ss(0.1, 0.2)
    grid = [ss(mu_sr, mu_ss) for mu_sr in (0.1, 0.2) for mu_ss in (0.2, 0.3)]
    for k in (1, 2):   # "these friction coefficients have no effect on the rotational velocities"
        key = f"stage[{k}].carrier_speed_ratio"
        assert max(abs(g[key] - base[key]) for g in grid) <= 1e-12
    assert ss(0.2, 0.2)["efficiency"] < base["efficiency"]          # η falls as µ_SR rises
    slight = abs(ss(0.1, 0.3)["efficiency"] - base["efficiency"]) / base["efficiency"]
    assert 0 < slight < 0.01                                         # µ_SS: "slight effect"
    assert ss(0.1, 0.3)["stage[1].contact_force"] > base["stage[1].contact_force"]
    assert ss(0.2, 0.2)["stage[2].contact_force"] > base["stage[2].contact_force"]
    assert ss(0.1, 0.3)["stage[2].spline_friction"] > base["stage[2].spline_friction"]
    assert ss(0.2, 0.2)["stage[2].spline_friction"] > base["stage[2].spline_friction"]


def test_section_3_3_pitch_trends():
    """Pitches p1 + p2 = 4 mm, p1 ∈ {1, 2, 3} mm, five starts each (leads 5·p)."""
    rows = []
    for p1 in (1.0, 2.0, 3.0):
        p2 = 4.0 - p1
        params = (LI2021.with_stage(1, screw_lead=5 * p1 * 1e-3)
                  .with_stage(2, screw_lead=5 * p2 * 1e-3).validate())
        s = steady_state(params, 100.0, 5000.0)
        r = startup(params, t_end=1e-3, h=2e-6)
        rows.append((s, settling_time(r["time"], r["stage[1].carrier_speed_ratio"])))
    f1 = [s["stage[1].contact_force"] for s, _ in rows]
    f2 = [s["stage[2].contact_force"] for s, _ in rows]
    fs = [s["stage[2].spline_friction"] for s, _ in rows]
    z1 = [s["stage[1].carrier_speed_ratio"] for s, _ in rows]
    eta = [s["efficiency"] for s, _ in rows]
    t1 = [t for _, t in rows]
    assert f1[0] > f1[1] > f1[2]        # F_Srz1 decreases as pitch 1 increases
    assert f2[0] > f2[1] > f2[2]        # F_Srz2 increases with pitch 2 (p2 falls along rows)
    assert fs[0] > fs[1] > fs[2]        # f_S2 increases with pitch 2
    assert z1[0] > z1[1] > z1[2]        # a smaller pitch 1 raises the steady ζ_PS1 ...
    assert t1[0] < t1[1] < t1[2]        # ... and makes it settle sooner
    assert max(eta) - min(eta) < 0.02   # "slight influence on the steady-state efficiency"
