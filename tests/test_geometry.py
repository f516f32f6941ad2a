"""Tests of prsm_fmu.geometry: screw–roller contact of a PRSM stage.

Every expected value is computed here from the thread-surface definitions (written out again
below, independently of the module), from Li et al. (2021) (Eqs. 14 and 25, §3.1) or from the multi-stage assembly article
(helix angles), never from the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from prsm_fmu.geometry import (
    ContactGeometry,
    contact_geometry,
    ideal_axial_normal_fraction,
    lead_angle,
    screw_helix_angle,
)
from prsm_fmu.params import StageParams

MM = 1e-3


def make_stage(r_s_mm: float, r_r_mm: float, r_n_mm: float, lead_mm: float = 10.0,
               beta_deg: float = 45.0, **masses: float) -> StageParams:
    """A stage of Li et al. (2021) §3.1 (masses and inertias: any positive numbers)."""
    kw = dict(screw_mass=0.5, nut_mass=2.5, roller_mass=0.017, carrier_mass=0.1,
              screw_inertia=55e-9, roller_inertia=0.08e-9,
              carrier_inertia=3e-9)
    kw.update(masses)
    return StageParams(screw_radius=r_s_mm * MM, roller_radius=r_r_mm * MM,
                       nut_radius=r_n_mm * MM, screw_lead=lead_mm * MM, screw_starts=5,
                       flank_angle=math.radians(beta_deg), n_rollers=7, **kw)


# Li et al. (2021) §3.1 two-stage example
STAGE1 = make_stage(9.75, 3.25, 16.25, screw_mass=0.5, nut_mass=2.5, roller_mass=0.017,
                    screw_inertia=55e-9, roller_inertia=0.08e-9, carrier_inertia=3e-9)
STAGE2 = make_stage(16.5, 5.5, 27.5, screw_mass=0.77, nut_mass=18.0, roller_mass=0.04,
                    screw_inertia=170e-9, roller_inertia=0.48e-9, carrier_inertia=12e-9)
STAGES = [pytest.param(STAGE1, id="stage1"), pytest.param(STAGE2, id="stage2")]


# ---- independent description of the thread surfaces ----------------------------------------
def _consts(st: StageParams):
    a = st.screw_radius + st.roller_radius
    ell = st.screw_lead / (2 * math.pi)
    q = st.screw_lead / st.screw_starts / (2 * math.pi)
    big_r = st.roller_radius / math.sin(st.flank_angle)
    return a, ell, q, math.tan(st.flank_angle), big_r


def screw_flank_z(st: StageParams, x: float, y: float, sign: float = 1.0) -> float:
    """z of the screw flank above (x, y), branch ψ ∈ (−π, π); sign −1: the other flank."""
    _, ell, _, tb, _ = _consts(st)
    return ell * math.atan2(y, x) + sign * (math.hypot(x, y) - st.screw_radius) * tb


def roller_params(st: StageParams, x: float, y: float) -> tuple[float, float]:
    """(ρ_r, ψ_r) of a carrier-frame point, ψ_r ∈ (0, 2π) (contact near ψ_r = π)."""
    a = _consts(st)[0]
    return math.hypot(x - a, y), math.atan2(y, x - a) % (2 * math.pi)


def roller_flank_z(st: StageParams, x: float, y: float, z_r: float) -> float:
    """z of the roller's upper flank above (x, y) for the roller phase z_r."""
    _, _, q, _, big_r = _consts(st)
    rho_r, psi_r = roller_params(st, x, y)
    return z_r + q * psi_r + math.sqrt(big_r ** 2 - rho_r ** 2)


def screw_tangents(st: StageParams, x: float, y: float) -> list[np.ndarray]:
    _, ell, _, tb, _ = _consts(st)
    rho, psi = math.hypot(x, y), math.atan2(y, x)
    return [np.array([math.cos(psi), math.sin(psi), tb]),
            np.array([-rho * math.sin(psi), rho * math.cos(psi), ell])]


def roller_tangents(st: StageParams, x: float, y: float) -> list[np.ndarray]:
    _, _, q, _, big_r = _consts(st)
    rho_r, psi_r = roller_params(st, x, y)
    h = math.sqrt(big_r ** 2 - rho_r ** 2)
    return [np.array([math.cos(psi_r), math.sin(psi_r), -rho_r / h]),
            np.array([-rho_r * math.sin(psi_r), rho_r * math.cos(psi_r), q])]


def implied_roller_phase(st: StageParams, g: ContactGeometry) -> float:
    """The roller phase z_r that puts the roller's upper flank through the contact point."""
    x, y, z = g.point
    return z - roller_flank_z(st, x, y, 0.0)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


# ---- the contact lies on both surfaces with a common normal ---------------------------------
@pytest.mark.parametrize("st", STAGES)
def test_point_on_both_surfaces(st):
    g = contact_geometry(st)
    x, y, z = g.point
    assert abs(z - screw_flank_z(st, x, y)) < 1e-12
    rho_r, psi_r = roller_params(st, x, y)
    big_r = _consts(st)[4]
    assert rho_r < big_r                       # the point is on the roller's profile arc
    assert abs(psi_r - math.pi) < math.pi / 2  # on the screw-facing side of the roller
    z_r = implied_roller_phase(st, g)
    assert abs(z - roller_flank_z(st, x, y, z_r)) < 1e-12


@pytest.mark.parametrize("st", STAGES)
def test_normal_unit_and_perpendicular_to_both_surfaces(st):
    g = contact_geometry(st)
    n = np.array(g.normal)
    assert abs(np.linalg.norm(n) - 1.0) < 1e-12
    x, y, _ = g.point
    for t in screw_tangents(st, x, y) + roller_tangents(st, x, y):
        assert abs(np.dot(n, unit(t))) < 1e-12
    # orientation: force on the screw from the roller, into the screw tooth (towards +z),
    # which on this flank is also towards the screw axis (−x)
    assert n[2] > 0.0 and n[0] < 0.0


@pytest.mark.parametrize("st", STAGES)
def test_gap_has_a_touching_minimum(st):
    """Axial gap screw flank − roller flank over the xy-plane: zero with zero gradient at the
    contact and non-negative around it (tangency without interference)."""
    g = contact_geometry(st)
    x0, y0, _ = g.point
    z_r = implied_roller_phase(st, g)

    def gap(x, y):
        return screw_flank_z(st, x, y) - roller_flank_z(st, x, y, z_r)

    d = 1e-6  # [m]; central-difference truncation ~ d² / r² ≈ 1e-8
    grad = [(gap(x0 + d, y0) - gap(x0 - d, y0)) / (2 * d),
            (gap(x0, y0 + d) - gap(x0, y0 - d)) / (2 * d)]
    assert max(abs(v) for v in grad) < 1e-7
    span = 0.3 * st.roller_radius
    for dx in np.linspace(-span, span, 13):
        for dy in np.linspace(-span, span, 13):
            assert gap(x0 + dx, y0 + dy) > -1e-15


# ---- kinematics ------------------------------------------------------------------------------
@pytest.mark.parametrize("st", STAGES)
def test_slip_is_tangent_to_contact(st):
    g = contact_geometry(st)
    a, b = (np.array(v) for v in g.slip_jacobians())
    n = np.array(g.normal)
    assert abs(np.dot(n, a)) < 1e-12 * np.linalg.norm(a)
    assert abs(np.dot(n, b)) < 1e-12 * np.linalg.norm(b)


@pytest.mark.parametrize("st", STAGES)
def test_slip_jacobians_reproduce_li2021_eq14(st):
    g = contact_geometry(st)
    x, y, _ = g.point
    a_dist = st.screw_radius + st.roller_radius
    # radii and angles from their definitions
    r_sr, phi_sr = math.hypot(x, y), math.atan2(y, x)
    r_rs = math.hypot(x - a_dist, y)
    phi_rs = math.atan2(y, a_dist - x)  # point − c = r_Rs (−cos φ_Rs, sin φ_Rs)
    assert g.screw_contact_radius == pytest.approx(r_sr, rel=1e-14)
    assert g.screw_offset_angle == pytest.approx(phi_sr, rel=1e-13)
    assert g.roller_contact_radius == pytest.approx(r_rs, rel=1e-13)
    assert g.roller_offset_angle == pytest.approx(phi_rs, rel=1e-13)
    assert g.roller_axis_distance == pytest.approx(a_dist, rel=1e-15)
    assert g.lead_per_radian == pytest.approx(st.screw_lead / (2 * math.pi), rel=1e-15)
    assert g.screw_starts == st.screw_starts
    a, b = (np.array(v) for v in g.slip_jacobians())
    n_s, lead = st.screw_starts, st.screw_lead
    for w_s, w_p in [(100.0, 0.0), (0.0, 7.0), (100.0, 31.4), (-3.0, 2.0)]:
        eq14 = np.array([
            -r_sr * (w_s - w_p) * math.sin(phi_sr) - n_s * w_p * r_rs * math.sin(phi_rs),
            r_sr * (w_s - w_p) * math.cos(phi_sr) - n_s * w_p * r_rs * math.cos(phi_rs),
            w_s * lead / (2 * math.pi)])
        assert np.allclose(w_s * a + w_p * b, eq14, rtol=0, atol=1e-13 * (abs(w_s) + abs(w_p)))


# ---- Li et al. (2021) Eq. 25 -------------------------------------------------------------------------
@pytest.mark.parametrize("st", STAGES)
def test_axial_normal_component_is_eq25_factor(st):
    g = contact_geometry(st)
    r_sr = math.hypot(g.point[0], g.point[1])
    eq25 = 1.0 / math.sqrt(1.0 + math.tan(st.flank_angle) ** 2
                           + (st.screw_lead / (2 * math.pi * r_sr)) ** 2)
    assert abs(g.normal[2] - eq25) < 1e-12
    assert abs(ideal_axial_normal_fraction(st, r_sr) - eq25) < 1e-15


# ---- Li et al. (2021) §3.1 qualitative claim ---------------------------------------------------------
def test_stage2_contact_closer_to_pitch_point():
    """Li et al. (2021) §3.1: screw 2's helix angle is smaller, so its contact point is closer to the
    point of tangency of the pitch circles.

    True in the angular sense (|φ_Sr|, |φ_Rs|) and relative to the stage size
    (|P − pitch point| / r_S).  In metres it is NOT: to first order in ℓ (see
    test_small_lead_limit) |P − pitch point| ≈ r_S |φ_Sr| = ℓ (r_S/n_S + r_R) / (a tanβ),
    which is 0.4 ℓ for BOTH stages (same lead, r_R = r_S/3 in both); the second-order terms
    make stage 2's distance slightly (< 2 %) larger.
    """
    assert screw_helix_angle(STAGE2) < screw_helix_angle(STAGE1)
    g1, g2 = contact_geometry(STAGE1), contact_geometry(STAGE2)
    assert abs(g2.screw_offset_angle) < abs(g1.screw_offset_angle)
    assert abs(g2.roller_offset_angle) < abs(g1.roller_offset_angle)

    def dist(g, st):
        return math.hypot(g.point[0] - st.screw_radius, g.point[1])

    assert dist(g2, STAGE2) / STAGE2.screw_radius < dist(g1, STAGE1) / STAGE1.screw_radius
    first_order = [st.screw_lead / (2 * math.pi)
                   * (st.screw_radius / st.screw_starts + st.roller_radius)
                   / ((st.screw_radius + st.roller_radius) * math.tan(st.flank_angle))
                   for st in (STAGE1, STAGE2)]
    assert first_order[0] == pytest.approx(first_order[1], rel=1e-12)
    assert dist(g2, STAGE2) == pytest.approx(dist(g1, STAGE1), rel=0.02)


# ---- small-lead limit ------------------------------------------------------------------------
@pytest.mark.parametrize("st", STAGES)
def test_small_lead_limit(st):
    """First-order expansion in ℓ = L/(2π), about the pitch point.

    With ψ, δ = ψ_r − π small, equal y of the two surface points gives r_S ψ = −r_R δ, and
    equal y/z ratios of the two normals give −tanβ ψ − ℓ/r_S = −tanβ δ + q/r_R (q = ℓ/n_S).
    Hence φ_Sr = ψ = −ℓ (1/n_S + r_R/r_S) / (a tanβ) + O(ℓ²), φ_Rs = −δ = (r_S/r_R) φ_Sr.
    The x/z ratios and x coordinates are even in (ψ, δ, ℓ), so the radii move only at
    O(ℓ²/r).  With L = 1 µm, ℓ/r_R ≈ 5e-5: we allow a relative error 1e-3 on the angles
    (20× the expected O(ℓ/r)) and 10 ℓ²/r_R ≈ 8e-11 m on the radii.
    """
    lead = 1e-6
    small = StageParams(**{**st.__dict__, "screw_lead": lead})
    g = contact_geometry(small)
    ell = lead / (2 * math.pi)
    r_s, r_r = st.screw_radius, st.roller_radius
    a = r_s + r_r
    phi_sr_1 = -ell * (1 / st.screw_starts + r_r / r_s) / (a * math.tan(st.flank_angle))
    assert abs(g.screw_offset_angle) < 1e-4
    assert g.screw_offset_angle == pytest.approx(phi_sr_1, rel=1e-3)
    assert g.roller_offset_angle == pytest.approx(r_s / r_r * phi_sr_1, rel=1e-3)
    tol = 10 * ell ** 2 / r_r
    assert abs(g.screw_contact_radius - r_s) < tol
    assert abs(g.roller_contact_radius - r_r) < tol


# ---- the other flank -------------------------------------------------------------------------
@pytest.mark.parametrize("st", STAGES)
def test_mirrored_flank(st):
    g = contact_geometry(st)
    m = g.mirrored()
    assert m.mirrored() == g
    assert m.normal[2] < 0.0
    assert m.flank == -g.flank
    x, y, z = m.point
    assert (x, y, z) == (g.point[0], -g.point[1], -g.point[2])
    # lies on the screw's other (upper) flank z = ℓψ − (ρ − r_S) tanβ
    assert abs(z - screw_flank_z(st, x, y, sign=-1.0)) < 1e-12
    assert m.screw_contact_radius == pytest.approx(g.screw_contact_radius, rel=1e-15)
    assert m.screw_offset_angle == pytest.approx(-g.screw_offset_angle, rel=1e-15)
    assert m.roller_contact_radius == pytest.approx(g.roller_contact_radius, rel=1e-15)
    assert m.roller_offset_angle == pytest.approx(-g.roller_offset_angle, rel=1e-15)
    a, b = (np.array(v) for v in m.slip_jacobians())
    n = np.array(m.normal)
    assert abs(np.dot(n, a)) < 1e-12 * np.linalg.norm(a)
    assert abs(np.dot(n, b)) < 1e-12 * np.linalg.norm(b)


# ---- helix angles (the multi-stage assembly article) and helpers -----------------------------------------------------
@pytest.mark.parametrize("st, expected_deg", [(STAGE1, 9.27), (STAGE2, 5.51)],
                         ids=["stage1", "stage2"])
def test_helix_angles_assembly_article(st, expected_deg):
    assert abs(math.degrees(screw_helix_angle(st)) - expected_deg) < 0.005


def test_lead_angle_values():
    assert lead_angle(2 * math.pi, 1.0) == pytest.approx(math.pi / 4, rel=1e-15)
    assert lead_angle(0.01, 0.01 / (2 * math.pi * math.sqrt(3))) == pytest.approx(
        math.pi / 3, rel=1e-14)
    with pytest.raises(ValueError, match="radius"):
        lead_angle(0.01, 0.0)


def test_ideal_axial_normal_fraction_value():
    # β = 45°, tan λ = 1  ->  1/sqrt(3)
    st = make_stage(10.0, 2.5, 15.0, lead_mm=20 * math.pi)
    assert ideal_axial_normal_fraction(st, 10 * MM) == pytest.approx(1 / math.sqrt(3), rel=1e-14)


# ---- caching and rejection -------------------------------------------------------------------
def test_cached():
    assert contact_geometry(STAGE1) is contact_geometry(STAGE1)


@pytest.mark.parametrize("changes", [{"screw_lead": 0.2}, {"flank_angle": 1e-3}],
                         ids=["huge_lead", "tiny_flank_angle"])
def test_no_contact_near_pitch_point_is_rejected(changes):
    bad = StageParams(**{**STAGE1.__dict__, **changes})
    with pytest.raises(ValueError, match=r"stage\.screw_lead.*stage\.flank_angle"):
        contact_geometry(bad)


@pytest.mark.parametrize("field, value", [("screw_radius", -1.0), ("roller_radius", 0.0),
                                          ("screw_lead", float("nan")), ("screw_starts", 0),
                                          ("flank_angle", math.pi / 2)])
def test_out_of_range_fields_are_named(field, value):
    bad = StageParams(**{**STAGE1.__dict__, field: value})
    with pytest.raises(ValueError, match=rf"stage\.{field}"):
        contact_geometry(bad)
