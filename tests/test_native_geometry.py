"""The native FMU's thread geometry is set at initialization: its C solves the contact then.

* a geometry set before ``fmi2ExitInitializationMode`` gives the outputs of the Python
  reference FMU (``--engine python``) with the same geometry, bit for bit over 100 steps;
* the checks that follow from the geometry refuse the same values with the same message in
  both FMUs, evaluated from the geometry set (not the build's): how many rollers fit around a
  screw of other radii, the spline radius's interval of another screw radius, the meshing
  conditions r_N = r_S + 2 r_R = n_S r_R, the flank angle's interval, and a geometry whose
  helix is too steep for its flank (no contact near the pitch point);
* after a refused geometry, fmi2Reset and the preset's geometry initialize and step.
"""

from __future__ import annotations

import math
import struct
import sys
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import Host, built_prsm2_reference  # noqa: E402
from test_native_fmu import built_native  # noqa: E402
from test_param_ranges import _init  # noqa: E402 - reset, set, exitInitializationMode: why refused
from zig_skip import skip_without_ziglang  # noqa: E402

STEPS = 100


@pytest.fixture(scope="module")
def fmus() -> dict[str, Path]:
    """PRSM2 native (linux64, FMI 2.0) and the Python reference FMU (``--engine python``): the
    session's shared builds (tests/test_native_fmu.py, tests/test_fmu.py)."""
    if sys.platform != "linux":
        pytest.skip("the native FMU is built here for Linux only")
    skip_without_ziglang(module_level=False)
    return {"native": built_native()["PRSM2"], "python": built_prsm2_reference()}


def _bits(values: list[float]) -> list[bytes]:
    return [struct.pack("<d", v) for v in values]


# Li et al. (2021) §3.1's PRSM2: stage 1 r_S 9.75, r_R 3.25, r_N 16.25 mm, stage 2 r_S 16.5,
# r_R 5.5, r_N 27.5 mm, 5 starts, 45° flanks
THINNER_STAGE_1 = {  # meshes: r_N = r_S + 2 r_R = 9 + 6 = 15 mm = n_S r_R = 5 × 3 mm
    "stage[1].screw_radius": 0.009, "stage[1].roller_radius": 0.003,
    "stage[1].nut_radius": 0.015, "stage[2].flank_angle": 0.7}
FOUR_STARTS = {  # 4 starts: r_S = 2 r_R = 6.5 mm, r_N = 13 mm = 4 × 3.25 mm
    "stage[1].screw_radius": 0.0065, "stage[1].roller_radius": 0.00325,
    "stage[1].nut_radius": 0.013, "stage[1].screw_starts": 4}


@pytest.mark.parametrize("change", [THINNER_STAGE_1, FOUR_STARTS], ids=["radii", "starts"])
def test_geometry_set_at_initialization_equals_the_python_fmu(fmus, change):
    nat = Host(path=fmus["native"], instance="nat", start={**change, "stage[1].n_rollers": 9})
    ref = Host(path=fmus["python"], instance="ref", start={**change, "stage[1].n_rollers": 9})
    preset = Host(path=fmus["native"], instance="preset", start={"stage[1].n_rollers": 9})
    vr = [nat.vars[n].valueReference for n in ("screw_torque", "load_force")]
    for k in range(STEPS):
        for h in (nat, ref, preset):
            h.fmu.setReal(vr, [20.0 if k < 50 else -20.0, 3000.0])
            assert h.step(k * 1e-3) == 0, h.messages
        assert _bits(nat.get_real(nat.outputs)) == _bits(ref.get_real(ref.outputs)), k
    assert nat.get_real(nat.outputs) != preset.get_real(preset.outputs)
    print(f"{STEPS} steps equal bit for bit with {change}")
    for h in (nat, ref, preset):
        h.free()


# the preset's r_R of stage 1 is the double nearest r_N / n_S = 16.25 mm / 5, which prints
# 0.0032500000000000003 (R_R below); with 4 starts, n_S r_R = 4 × that
R_R = 0.01625 / 5
# max_rollers(r_S, r_R) = int(π / asin(r_R / (r_S + r_R)) + 1e-9):
#   Li's stage 1, r_R / (r_S + r_R) = 3.25 / 13 = 1/4: π / 0.25268 = 12.43 -> 12 rollers;
#   four starts, 3.25 / 9.75 = 1/3: π / 0.33984 = 9.24 -> 9 rollers
# spline radius of stage 2 with r_S = 15 mm (r_R 5, r_N 25 mm): [0.01 × 15, 15] mm = [0.15, 15] mm
STAGE_2_15MM = {"stage[2].screw_radius": 0.015, "stage[2].roller_radius": 0.005,
                "stage[2].nut_radius": 0.025, "mu_spline": 0.1}
REFUSED = [
    pytest.param({**FOUR_STARTS, "stage[1].n_rollers": 10},
                 "stage[1].n_rollers = 10 is out of range: must be an integer in [1, 9] "
                 "(rollers that fit around the screw)", id="rollers-that-fit"),
    pytest.param({**STAGE_2_15MM, "stage[2].spline_radius": 0.0155},
                 "stage[2].spline_radius = 0.0155 m is out of range: must be in [0.00015, "
                 "0.015] m (while mu_spline > 0: from 0.01 x to 1 x the screw radius; the "
                 "internal spline teeth lie in the bore of the screw)", id="spline-radius"),
    pytest.param({"stage[1].nut_radius": 0.0163},
                 "stage[1].nut_radius = 0.0163 m is inconsistent with screw_radius + "
                 "2*roller_radius = 0.01625 m: must equal it (relative tolerance 1e-06)",
                 id="nut-fit"),
    pytest.param({"stage[1].screw_starts": 4},
                 "stage[1].nut_radius = 0.01625 m is inconsistent with the roller lead: a "
                 "single-start roller of lead pitch = screw_lead/screw_starts stays engaged with "
                 f"the nut only if nut_radius = screw_starts*roller_radius = {4 * R_R!r} m "
                 "(relative tolerance 1e-06)", id="nut-engaged"),
    pytest.param({"stage[2].flank_angle": math.pi / 2},
                 "stage[2].flank_angle = 1.5707963267948966 rad is out of range: must be in "
                 "(0, pi/2) rad, i.e. (0°, 90°)", id="flank-angle"),
    pytest.param({"stage[1].flank_angle": 0.05},
                 "stage[1].screw_lead = 0.01 m with stage[1].flank_angle = 0.05 rad "
                 f"(screw_radius = 0.00975 m, roller_radius = {R_R!r} m, screw_starts = 5) "
                 "gives no screw-roller contact near the pitch point", id="no-contact"),
]


@pytest.mark.parametrize("change,message", REFUSED)
def test_geometry_checks_refuse_alike_from_the_geometry_set(fmus, change, message):
    """Each message written here from the rule (numbers worked out above); both FMUs give it,
    and after fmi2Reset start with the preset's geometry."""
    got = {}
    for kind in ("native", "python"):
        h = Host(path=fmus[kind], instance=f"refuse-{kind}", initialize=False)
        got[kind] = _init(h, change)
        assert _init(h, {}) is None, (kind, h.messages[-3:])
        assert h.step(0.0) == 0, (kind, h.messages[-3:])
        h.free()
    assert got["native"] is not None and got["native"].startswith(message), got
    assert got["python"] == got["native"], got
