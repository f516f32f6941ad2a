"""The contact-geometry solver without scipy: the engine's C (prsm_geometry.c, called through
ctypes) and its readable Python reference (prsm_fmu.geometry._newton_contact).

* C and Python compute the same numbers bit for bit, contacts and refusals alike, on seeded
  random stage geometries (the count is printed);
* both find the contact of an independent formulation solved with scipy: the contact is where
  the axial gap between the screw flank and the roller flank over the xy-plane is stationary,
  grad z_screw(x, y) = grad z_roller(x, y), two equations in (x, y) written here from the thread
  surfaces (not the module's five unknowns), solved with scipy.optimize.root;
* no scipy is imported to compute a contact (a fresh interpreter).
"""

from __future__ import annotations

import math
import random
import shutil
import subprocess
import sys

import pytest

from prsm_fmu import geometry
from prsm_fmu.params import StageParams

#: seeded random stage geometries per test
N_CASES = 400
SEED = 20261126


def random_geometry(rng: random.Random, pitch_max: float = 0.6,
                    beta: tuple[float, float] = (0.4, 1.2)
                    ) -> tuple[float, float, float, int, float]:
    """(r_S [m], r_R [m], L_S [m], n_S, β [rad]) inside prsm_fmu.param_ranges' bounds (lengths
    in (0, 1] m, starts 1..1000, β in (0, π/2)) around the papers' designs: r_S log-uniform in
    [1 mm, 0.5 m], r_R from 0.1 to 0.7 r_S, n_S from 1 to 12, the pitch L_S/n_S from 0.05 to
    ``pitch_max`` r_R (the papers': 0.3 to 0.6), β uniform in ``beta`` [rad] (the papers':
    45°).  Steeper threads (pitch near r_R and small β) may have several stationary points of
    the gap, of which the reference below may find another than the pitch point's; with
    pitch_max 1.5 and β from 0.15 rad some have no contact at all."""
    r_s = math.exp(rng.uniform(math.log(1e-3), math.log(0.5)))
    r_r = r_s * rng.uniform(0.1, 0.7)
    n_s = rng.randint(1, 12)
    lead = n_s * r_r * rng.uniform(0.05, pitch_max)
    return r_s, r_r, lead, n_s, rng.uniform(*beta)


def reference_contact(r_s: float, r_r: float, lead: float, n_s: int, beta: float):
    """Contact point (x, y) [m] and unit normal of the stationary axial gap, by scipy.

    Screw flank: z_S = ℓ atan2(y, x) + (ρ − r_S) tan β with ρ = |(x, y)|, ℓ = L_S/2π.
    Roller flank about c = (r_S + r_R, 0): z_R = z_r + q ψ_r + sqrt(R² − ρ_r²) with
    (ρ_r, ψ_r) the polar coordinates of (x, y) − c, q = L_S/(2π n_S), R = r_R / sin β.
    Tangency: ∂z_S/∂x = ∂z_R/∂x and ∂z_S/∂y = ∂z_R/∂y; the screw's upward normal is
    (−∂z_S/∂x, −∂z_S/∂y, 1) normalised.
    """
    from scipy.optimize import root

    a = r_s + r_r
    ell, q = lead / (2 * math.pi), lead / (2 * math.pi * n_s)
    tb, big_r = math.tan(beta), r_r / math.sin(beta)

    def grad_screw(x, y):
        rho2 = x * x + y * y
        rho = math.sqrt(rho2)
        return ell * (-y) / rho2 + tb * x / rho, ell * x / rho2 + tb * y / rho

    def grad_roller(x, y):
        dx = x - a
        rr2 = dx * dx + y * y
        h = math.sqrt(max(big_r * big_r - rr2, 1e-30 * big_r * big_r))   # off the arc: steep
        return q * (-y) / rr2 - dx / h, q * dx / rr2 - y / h

    def eqs(v):
        x, y = r_s * (1 + v[0]), r_s * v[1]
        gs, gr = grad_screw(x, y), grad_roller(x, y)
        return [gs[0] - gr[0], gs[1] - gr[1]]

    sol = root(eqs, [0.0, 0.0], method="hybr", options={"xtol": 1e-15})
    # hybr reports "xtol too small" once at round-off: judged by the slopes' residual instead
    if not max(abs(v) for v in eqs(sol.x)) < 1e-12:
        return None
    x, y = r_s * (1 + sol.x[0]), r_s * sol.x[1]
    gx, gy = grad_screw(x, y)
    norm = math.sqrt(gx * gx + gy * gy + 1.0)
    return (x, y), (-gx / norm, -gy / norm, 1.0 / norm)


def _library():
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc to compile the engine library")
    from fmu_build.native_stepper import contact_solver, native_library
    from prsm_fmu import presets

    return contact_solver(native_library(presets.load("li2021_two_stage")))


def _same(a: tuple, b: tuple) -> bool:
    """Equal as doubles, NaN equal to NaN (both solvers give up the same way)."""
    return len(a) == len(b) and all(x == y or (x != x and y != y) for x, y in zip(a, b))


def test_c_solver_equals_python_reference_bit_for_bit():
    solve = _library()
    rng = random.Random(SEED)
    contacts = 0
    for i in range(N_CASES):
        g = random_geometry(rng, pitch_max=1.5, beta=(0.15, 1.45))
        c, py = solve(*g), geometry._newton_contact(*g)
        assert _same(c, py), f"case {i} {g}: C {c} != Python {py}"
        contacts += c[11] < 1e-12
    print(f"{N_CASES} seeded random geometries (seed {SEED}): C == Python bit for bit, "
          f"{contacts} of them with a contact")
    assert 0 < contacts < N_CASES          # both kinds of case were tried


def test_solvers_find_the_independent_reference_contact():
    solve = _library()
    rng = random.Random(SEED + 1)
    compared, worst = 0, 0.0
    for _ in range(N_CASES):
        g = random_geometry(rng)
        r_s, r_r, lead, n_s, beta = g
        ref = reference_contact(*g)
        stage = StageParams(screw_radius=r_s, roller_radius=r_r, nut_radius=r_s + 2 * r_r,
                            screw_lead=lead, screw_starts=n_s, flank_angle=beta, n_rollers=1,
                            screw_mass=1.0, nut_mass=1.0, roller_mass=1.0, carrier_mass=1.0,
                            screw_inertia=1.0, roller_inertia=1.0, carrier_inertia=1.0)
        try:
            got = geometry.contact_geometry(stage)
        except ValueError:
            continue
        assert ref is not None, f"{g}: the module finds a contact, the reference none"
        for out in (solve(*g), geometry._newton_contact(*g)):
            (x, y), n = ref
            err = max(abs(out[0] - x) / r_s, abs(out[1] - y) / r_s,
                      *(abs(out[3 + i] - n[i]) for i in range(3)))
            assert err <= 1e-12, f"{g}: relative difference {err:.3g}"
            worst = max(worst, err)
        assert got.point[:2] == tuple(solve(*g)[:2])
        compared += 1
    print(f"{compared} contacts of {N_CASES} seeded random geometries (seed {SEED + 1}) equal "
          f"to the scipy reference within {worst:.2g} (relative to r_S; unit normal)")
    assert compared > N_CASES // 3


def test_newton_work_is_bounded_on_hopeless_input():
    """A flank angle far too small for the helix and a degenerate roller: the solver stops
    within its bounds (≤ 50 iterations) and contact_geometry refuses, naming the stage's
    parameters."""
    for g in ((0.01, 0.003, 0.05, 1, 0.01), (0.01, 1e-9, 0.01, 5, 0.7),
              (0.01, 0.003, 1e-12, 5, 1.5707)):
        out = geometry._newton_contact(*g)
        assert len(out) == 13 and 0 <= out[12] <= 50
    stage = StageParams(screw_radius=0.01, roller_radius=0.003, nut_radius=0.016, screw_lead=0.05,
                        screw_starts=1, flank_angle=0.01, n_rollers=1, screw_mass=1.0,
                        nut_mass=1.0, roller_mass=1.0, carrier_mass=1.0, screw_inertia=1.0,
                        roller_inertia=1.0, carrier_inertia=1.0)
    with pytest.raises(ValueError, match=r"stage\[3\]\.screw_lead = 0\.05 m with "
                       r"stage\[3\]\.flank_angle = 0\.01 rad .*screw_starts = 1"):
        geometry.contact_geometry(stage, "stage[3]")


def test_contact_geometry_imports_no_scipy():
    code = ("import sys, math\n"
            "from prsm_fmu import presets\n"
            "from prsm_fmu.geometry import contact_geometry\n"
            "p = presets.load('li2021_two_stage')\n"
            "g = [contact_geometry(st) for st in p.stages]\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
