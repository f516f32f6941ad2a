"""Thread and contact geometry of one planetary roller screw (PRSM) stage.

The screw–roller contact of a PRSM does not lie in the axial plane through the screw and
roller axes: because the two threads have helix angles of opposite slope at the mesh, the
point where a straight-flank screw thread and a convex (circular-arc) roller thread share a
point *and* a normal is offset from the pitch point.  The dynamic model (Li et al.
(2021) Eqs. 14–25) needs that point's radii and angles
(r_Sr, φ_Sr, r_Rs, φ_Rs) and the contact normal; this module computes them from the thread
surfaces (method of Jones & Velinsky 2013, "Contact kinematics in the roller screw
mechanism", and Fu et al. 2017) instead of taking them as typed-in data.

Coordinates and sign conventions (used by the whole project)
-------------------------------------------------------------
*Carrier frame*: z along the screw axis, the screw axis through the origin, the roller axis
parallel to z through c = (a, 0, 0) with a = r_S + r_R.  All threads are right-handed.
p = L_S / n_S is the pitch (= lead of the single-start roller) and ℓ = L_S / (2π) the screw
lead per radian.

* Screw flank (the face of a screw tooth whose outward normal points towards −z)::

      S(ρ, ψ) = (ρ cos ψ, ρ sin ψ, ℓ ψ + (ρ − r_S) tan β)

* Roller flank (the face of a roller tooth whose outward normal points towards +z): a
  helicoid of lead p about the roller axis whose axial profile is a circular arc of radius
  R = r_R / sin β centred on the roller axis::

      Rr(ρ_r, ψ_r) = (a + ρ_r cos ψ_r, ρ_r sin ψ_r, z_r + p ψ_r / (2π) + sqrt(R² − ρ_r²))

  with z_r the roller's (unknown) axial phase.

The contact on this "+" flank is solved near ψ = 0, ψ_r = π, ρ = r_S, ρ_r = r_R.  The other
("−") flank follows by the rotation by π about the x axis, see
:meth:`ContactGeometry.mirrored`.

All quantities are SI: metres, radians, seconds.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .params import StageParams

Vector3 = tuple[float, float, float]

#: largest accepted scaled residual of the contact equations (positions / r_S, unit normals)
_RESIDUAL_TOL = 1e-12


# ---------------------------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------------------------
def lead_angle(lead: float, radius: float) -> float:
    """Helix (lead) angle of a thread at a given radius.

    Used wherever the inclination of a helix against the radial plane is needed, e.g. the
    helix angle λ of a screw thread at its pitch radius or at the contact radius.

    Parameters
    ----------
    lead : float
        Axial advance of the helix per revolution [m].
    radius : float
        Radius at which the angle is evaluated [m], > 0.

    Returns
    -------
    float
        λ = atan(lead / (2π radius)) [rad].
    """
    if not radius > 0.0:
        raise ValueError(f"radius = {radius!r} m is out of range: must be > 0")
    return math.atan(lead / (2.0 * math.pi * radius))


def screw_helix_angle(stage: StageParams) -> float:
    """Helix angle of the screw thread at the nominal (pitch) screw radius.

    Parameters
    ----------
    stage : StageParams
        The stage; uses ``screw_lead`` L_S [m] and ``screw_radius`` r_S [m].

    Returns
    -------
    float
        λ_S = atan(L_S / (2π r_S)) [rad].
    """
    return lead_angle(stage.screw_lead, stage.screw_radius)


def ideal_axial_normal_fraction(stage: StageParams, radius: float) -> float:
    """Axial component of the unit normal of the straight-flank screw thread at a radius.

    This is the factor of Li et al. (2021) Eq. 25 that converts the normal contact force F_Sr into
    its axial component, F_Srz = F_Sr · fraction.  For the straight-flank helicoid used here
    it is exact at every point of the flank at that radius.

    Parameters
    ----------
    stage : StageParams
        The stage; uses ``flank_angle`` β [rad] and ``screw_lead`` L_S [m].
    radius : float
        Radius at which the normal is evaluated, typically r_Sr [m].

    Returns
    -------
    float
        1 / sqrt(1 + tan²β + tan²λ(radius)) [-], with tan λ = L_S / (2π radius).
    """
    tan_l = math.tan(lead_angle(stage.screw_lead, radius))
    tan_b = math.tan(stage.flank_angle)
    return 1.0 / math.sqrt(1.0 + tan_b * tan_b + tan_l * tan_l)


# ---------------------------------------------------------------------------------------------
# result type
# ---------------------------------------------------------------------------------------------
def _polar_quantities(point: Vector3, axis_distance: float) -> tuple[float, float, float, float]:
    """(r_Sr, φ_Sr, r_Rs, φ_Rs) of a point of the carrier frame (see :class:`ContactGeometry`)."""
    x, y = point[0], point[1]
    r_sr = math.hypot(x, y)
    phi_sr = math.atan2(y, x)
    dx, dy = x - axis_distance, y
    r_rs = math.hypot(dx, dy)
    # point − c = r_Rs (−cos φ_Rs, sin φ_Rs)
    phi_rs = math.atan2(dy, -dx)
    return r_sr, phi_sr, r_rs, phi_rs


@dataclass(frozen=True)
class ContactGeometry:
    """Screw–roller contact of one PRSM stage on one thread flank, in the carrier frame.

    Attributes
    ----------
    point : tuple of float
        Contact point (x, y, z) [m].  z is relative to the screw's thread phase; only x and
        y are meaningful to users.
    normal : tuple of float
        Unit contact normal [-], oriented as the force ON THE SCREW exerted by the roller when
        the contact on this flank is compressed (the screw surface's inward normal).  On the
        "+" flank ``normal[2] > 0``, on the "−" flank ``normal[2] < 0``.
    screw_contact_radius : float
        r_Sr = hypot(x, y) [m].
    screw_offset_angle : float
        φ_Sr = atan2(y, x) [rad].
    roller_contact_radius : float
        r_Rs, distance of the point from the roller axis in the xy-plane [m].
    roller_offset_angle : float
        φ_Rs [rad], defined by point − c = r_Rs (−cos φ_Rs, sin φ_Rs), c = (a, 0) (this is
        the convention of Li et al. (2021) Eq. 14).
    roller_axis_distance : float
        a = r_S + r_R [m], the distance between screw and roller axes.
    lead_per_radian : float
        ℓ = L_S / (2π) [m/rad].
    screw_starts : int
        n_S [-].
    flank : int
        +1 for the flank solved by :func:`contact_geometry`, −1 for its mirror image.
    """

    point: Vector3
    normal: Vector3
    screw_contact_radius: float
    screw_offset_angle: float
    roller_contact_radius: float
    roller_offset_angle: float
    roller_axis_distance: float
    lead_per_radian: float
    screw_starts: int
    flank: int = 1

    @classmethod
    def _from_point_normal(cls, point: Vector3, normal: Vector3, axis_distance: float,
                           lead_per_radian: float, screw_starts: int,
                           flank: int) -> "ContactGeometry":
        r_sr, phi_sr, r_rs, phi_rs = _polar_quantities(point, axis_distance)
        return cls(point=tuple(float(v) for v in point),  # type: ignore[arg-type]
                   normal=tuple(float(v) for v in normal),  # type: ignore[arg-type]
                   screw_contact_radius=r_sr, screw_offset_angle=phi_sr,
                   roller_contact_radius=r_rs, roller_offset_angle=phi_rs,
                   roller_axis_distance=float(axis_distance),
                   lead_per_radian=float(lead_per_radian),
                   screw_starts=int(screw_starts), flank=int(flank))

    def mirrored(self) -> "ContactGeometry":
        """Contact on the other thread flank.

        The rotation by π about the x axis, (x, y, z) → (x, −y, −z), maps the screw's and the
        roller's right-handed helicoids onto themselves and swaps their flanks; it is applied
        to the point and the normal, and the radii and angles are recomputed (φ_Sr and φ_Rs
        change sign, the radii are unchanged).

        Returns
        -------
        ContactGeometry
            The mirrored contact; its normal has a negative z component when this one's is
            positive.  ``g.mirrored().mirrored() == g``.
        """
        x, y, z = self.point
        nx, ny, nz = self.normal
        return ContactGeometry._from_point_normal(
            (x, -y, -z), (nx, -ny, -nz), self.roller_axis_distance, self.lead_per_radian,
            self.screw_starts, -self.flank)

    def slip_jacobians(self) -> tuple[Vector3, Vector3]:
        """Partial derivatives of the screw–roller slip velocity at the contact.

        The slip velocity s is the velocity of the screw's material point relative to the
        roller's material point at the contact, expressed in the carrier frame.  It is linear
        in the screw speed ω_S and the carrier speed ω_P [rad/s]: s = ω_S·a + ω_P·b with::

            a = ẑ × P + ℓ ẑ
            b = −ẑ × P + n_S ẑ × (P − c)

        (the roller spins at −n_S ω_P relative to the carrier because it rolls on the nut,
        r_N = n_S r_R).  Written with (r_Sr, φ_Sr, r_Rs, φ_Rs) this is Li et al. (2021) Eq. 14.
        Both vectors are tangent to the contact (``normal · a = normal · b = 0``).

        Returns
        -------
        tuple
            (a, b): a = ∂s/∂ω_S [m/rad], b = ∂s/∂ω_P [m/rad], each an (x, y, z) tuple.
        """
        x, y, _ = self.point
        c = self.roller_axis_distance
        n = self.screw_starts
        a_vec = (-y, x, self.lead_per_radian)
        # ẑ × (P − c) = (−y, x − c, 0)
        b_vec = (y - n * y, -x + n * (x - c), 0.0)
        return (tuple(float(v) for v in a_vec),  # type: ignore[return-value]
                tuple(float(v) for v in b_vec))


# ---------------------------------------------------------------------------------------------
# the contact problem
# ---------------------------------------------------------------------------------------------
def _check_stage(stage: StageParams, name: str = "stage") -> None:
    """Check the fields used by the contact problem (ValueError naming the field)."""
    for f in ("screw_radius", "roller_radius", "screw_lead"):
        v = getattr(stage, f)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
            raise ValueError(f"{name}.{f} = {v!r} m is out of range: must be a finite number > 0")
    n = stage.screw_starts
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"{name}.screw_starts = {n!r} is out of range: must be an integer >= 1")
    beta = stage.flank_angle
    if not (isinstance(beta, (int, float)) and math.isfinite(beta) and 0.0 < beta < math.pi / 2):
        raise ValueError(f"{name}.flank_angle = {beta!r} rad is out of range: must be in (0, pi/2)")


def _solve_contact(r_s: float, r_r: float, lead: float, n_s: int,
                   beta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Solve S = Rr and n_S ∥ n_R near the pitch point.

    Returns the contact point, the unit normal (z > 0), the solution
    (ρ, ψ, ρ_r, ψ_r, z_r) and the largest scaled residual.
    """
    a = r_s + r_r
    ell = lead / (2.0 * math.pi)
    q = ell / n_s                      # roller lead per radian, p / (2π)
    tan_b = math.tan(beta)
    big_r = r_r / math.sin(beta)       # radius of the roller's axial profile arc
    z_r0 = -q * math.pi - big_r * math.cos(beta)   # roller phase that puts ψ_r = π on z = 0

    def unpack(u: np.ndarray) -> tuple[float, float, float, float, float]:
        return (r_s * (1.0 + u[0]), u[1], r_r * (1.0 + u[2]), math.pi + u[3],
                z_r0 + r_s * u[4])

    def surfaces(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        rho, psi, rho_r, psi_r, z_r = unpack(u)
        cp, sp = math.cos(psi), math.sin(psi)
        cr, sr = math.cos(psi_r), math.sin(psi_r)
        h = math.sqrt(max(big_r * big_r - rho_r * rho_r, (1e-9 * big_r) ** 2))
        p_s = np.array([rho * cp, rho * sp, ell * psi + (rho - r_s) * tan_b])
        p_r = np.array([a + rho_r * cr, rho_r * sr, z_r + q * psi_r + h])
        # ∂S/∂ρ × ∂S/∂ψ and ∂Rr/∂ρ_r × ∂Rr/∂ψ_r: both point towards +z
        n_s_vec = np.array([ell * sp - rho * tan_b * cp, -rho * tan_b * sp - ell * cp, rho])
        n_r_vec = np.array([q * sr + rho_r * rho_r * cr / h, rho_r * rho_r * sr / h - q * cr,
                            rho_r])
        return p_s, p_r, n_s_vec / np.linalg.norm(n_s_vec), n_r_vec / np.linalg.norm(n_r_vec)

    def residual(u: np.ndarray) -> np.ndarray:
        p_s, p_r, n_s_hat, n_r_hat = surfaces(u)
        # both unit normals have z > 0, so equal x and y components make them equal
        return np.concatenate(((p_s - p_r) / r_s, (n_s_hat - n_r_hat)[:2]))

    from scipy.optimize import root   # on demand: importing scipy.optimize costs ~0.8 s

    sol = root(residual, np.zeros(5), method="hybr", options={"xtol": 1e-15})
    u = sol.x
    # a few Newton steps with a central-difference Jacobian polish to round-off
    for _ in range(3):
        f0 = residual(u)
        if np.max(np.abs(f0)) < 1e-16 or not np.all(np.isfinite(f0)):
            break
        jac = np.empty((5, 5))
        for j in range(5):
            du = np.zeros(5)
            du[j] = 1e-7
            jac[:, j] = (residual(u + du) - residual(u - du)) / 2e-7
        try:
            step = np.linalg.solve(jac, f0)
        except np.linalg.LinAlgError:
            break
        u_new = u - step
        if np.max(np.abs(residual(u_new))) < np.max(np.abs(f0)):
            u = u_new
        else:
            break
    p_s, _p_r, n_hat, _ = surfaces(u)
    res = float(np.max(np.abs(residual(u)))) if np.all(np.isfinite(u)) else math.inf
    return p_s, n_hat, np.array(unpack(u)), res


@functools.lru_cache(maxsize=256)
def contact_geometry(stage: StageParams, name: str = "stage") -> ContactGeometry:
    """Screw–roller contact point and normal of a stage, on the "+" flank.

    Solves the five equations "the screw flank and the roller flank share a point (3) and a
    normal (2)" for (ρ, ψ, ρ_r, ψ_r, z_r) with :func:`scipy.optimize.root`, starting at the
    pitch point (ψ = 0, ψ_r = π, ρ = r_S, ρ_r = r_R), to round-off accuracy.  The result is
    cached per (hashable, frozen) :class:`~prsm_fmu.params.StageParams`.

    Parameters
    ----------
    stage : StageParams
        Uses ``screw_radius`` r_S [m], ``roller_radius`` r_R [m], ``screw_lead`` L_S [m],
        ``screw_starts`` n_S and ``flank_angle`` β [rad].

    Returns
    -------
    ContactGeometry
        The contact on the flank whose normal (force on the screw) points towards +z; use
        :meth:`ContactGeometry.mirrored` for the other flank.

    Raises
    ------
    ValueError
        If a used field is out of range, or if no contact exists near the pitch point (the
        helix angle is too large for the flank angle: the message names
        ``<name>.screw_lead`` and ``<name>.flank_angle``).
    name : str, optional
        How messages name the stage, e.g. ``"stage[2]"``.
    """
    _check_stage(stage, name)
    r_s, r_r = float(stage.screw_radius), float(stage.roller_radius)
    lead, n_s, beta = float(stage.screw_lead), int(stage.screw_starts), float(stage.flank_angle)
    a = r_s + r_r
    try:
        point, normal, (rho, psi, rho_r, psi_r, _z_r), res = _solve_contact(r_s, r_r, lead, n_s,
                                                                            beta)
        big_r = r_r / math.sin(beta)
    except ArithmeticError:      # e.g. a flank angle of 1e-300 rad: no contact to be found
        point, res, big_r = np.full(3, np.nan), math.inf, math.nan
        rho = psi = rho_r = psi_r = math.nan
    near = (np.all(np.isfinite(point)) and res < _RESIDUAL_TOL
            and 0.0 < rho_r < big_r * (1.0 - 1e-9) and rho > 0.0
            and abs(psi) < math.pi / 2 and abs(psi_r - math.pi) < math.pi / 2
            and math.hypot(point[0] - r_s, point[1]) < r_r)
    if not near:
        raise ValueError(
            f"{name}.screw_lead = {stage.screw_lead!r} m with {name}.flank_angle = "
            f"{stage.flank_angle!r} rad (screw_radius = {stage.screw_radius!r} m, "
            f"roller_radius = {stage.roller_radius!r} m, screw_starts = {stage.screw_starts!r}) "
            "gives no screw-roller contact near the pitch point: the helix angle is too large "
            "for the flank angle (reduce screw_lead or increase flank_angle)")
    return ContactGeometry._from_point_normal(
        tuple(point), tuple(normal), a, lead / (2.0 * math.pi), n_s, 1)  # type: ignore[arg-type]
