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
from typing import Callable

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


#: the Newton iteration's bounds and finite-difference step (prsm_geometry.c's PRSM_CONTACT_*)
_MAX_ITER = 50
_MAX_HALVINGS = 30
_DU = 1e-7
#: the compiled solver (prsm_api_contact_geometry of a loaded engine library), or None
_compiled: list = []


def use_compiled_solver(solve: Callable[[float, float, float, int, float], tuple] | None) -> None:
    """Let :func:`contact_geometry` call ``solve`` (the engine library's
    ``prsm_api_contact_geometry``, registered by :func:`fmu_build.native_stepper.load_library`)
    instead of :func:`_newton_contact`, its readable reference; None: the reference again.
    Both compute the same numbers bit for bit (tests/test_geometry_solver.py)."""
    _compiled[:] = [solve] if solve is not None else []


class _ContactProblem:
    """The five contact equations of a stage in the scaled unknowns u (0 at the pitch point):
    ρ = r_S (1 + u0), ψ = u1, ρ_r = r_R (1 + u2), ψ_r = π + u3, z_r = z_r0 + r_S u4."""

    def __init__(self, r_s: float, r_r: float, lead: float, n_s: int, beta: float) -> None:
        self.r_s, self.r_r = r_s, r_r
        self.a = r_s + r_r
        self.ell = lead / (2.0 * math.pi)
        self.q = self.ell / n_s              # roller lead per radian, p / (2π)
        self.tan_b = math.tan(beta)
        self.big_r = r_r / math.sin(beta)    # radius of the roller's axial profile arc
        # the roller phase that puts ψ_r = π on z = 0
        self.z_r0 = -self.q * math.pi - self.big_r * math.cos(beta)
        self.floor_h = (1e-9 * self.big_r) * (1e-9 * self.big_r)

    def unknowns(self, u: list[float]) -> list[float]:
        """(ρ [m], ψ [rad], ρ_r [m], ψ_r [rad], z_r [m]) of the scaled unknowns ``u``."""
        return [self.r_s * (1.0 + u[0]), u[1], self.r_r * (1.0 + u[2]), math.pi + u[3],
                self.z_r0 + self.r_s * u[4]]

    def evaluate(self, u: list[float]) -> tuple[list[float], Vector3, Vector3]:
        """The residual (S − Rr)/r_S (3) and the unit normals' x, y difference (2), the screw
        flank's point [m] and its unit normal (z > 0) at ``u``."""
        rho, psi, rho_r, psi_r, z_r = self.unknowns(u)
        cp, sp = math.cos(psi), math.sin(psi)
        cr, sr = math.cos(psi_r), math.sin(psi_r)
        h2 = self.big_r * self.big_r - rho_r * rho_r
        h = math.sqrt(h2 if h2 > self.floor_h else self.floor_h)
        ell, q, tan_b, r_s = self.ell, self.q, self.tan_b, self.r_s
        sx, sy, sz = rho * cp, rho * sp, ell * psi + (rho - r_s) * tan_b
        rx, ry, rz = self.a + rho_r * cr, rho_r * sr, z_r + q * psi_r + h
        # ∂S/∂ρ × ∂S/∂ψ and ∂Rr/∂ρ_r × ∂Rr/∂ψ_r: both point towards +z
        nsx = ell * sp - rho * tan_b * cp
        nsy = -rho * tan_b * sp - ell * cp
        nsz = rho
        nrx = q * sr + rho_r * rho_r * cr / h
        nry = rho_r * rho_r * sr / h - q * cr
        nrz = rho_r
        ns = math.sqrt(nsx * nsx + nsy * nsy + nsz * nsz)
        nr = math.sqrt(nrx * nrx + nry * nry + nrz * nrz)
        # both unit normals have z > 0, so equal x and y components make them equal
        f = [(sx - rx) / r_s, (sy - ry) / r_s, (sz - rz) / r_s,
             nsx / ns - nrx / nr, nsy / ns - nry / nr]
        return f, (sx, sy, sz), (nsx / ns, nsy / ns, nsz / ns)


def _max_abs(f: list[float]) -> float:
    """Largest |f_i|, infinity if one is not finite."""
    m = 0.0
    for v in f:
        if not math.isfinite(v):
            return math.inf
        if abs(v) > m:
            m = abs(v)
    return m


def _solve5(jac: list[list[float]], f: list[float]) -> list[float] | None:
    """d with J d = f (Gaussian elimination with partial pivoting, ``jac`` and ``f``
    overwritten), or None if J is singular."""
    for c in range(5):
        piv = c
        for r in range(c + 1, 5):
            if abs(jac[r][c]) > abs(jac[piv][c]):
                piv = r
        if not abs(jac[piv][c]) > 0.0 or not math.isfinite(jac[piv][c]):
            return None
        if piv != c:
            jac[c], jac[piv] = jac[piv], jac[c]
            f[c], f[piv] = f[piv], f[c]
        for r in range(c + 1, 5):
            factor = jac[r][c] / jac[c][c]
            for j in range(c, 5):
                jac[r][j] = jac[r][j] - factor * jac[c][j]
            f[r] = f[r] - factor * f[c]
    d = [0.0] * 5
    for r in range(4, -1, -1):
        s = f[r]
        for j in range(r + 1, 5):
            s = s - jac[r][j] * d[j]
        d[r] = s / jac[r][r]
    return d


def _newton_contact(r_s: float, r_r: float, lead: float, n_s: int,
                    beta: float) -> tuple[float, ...]:
    """Solve S = Rr and n_S ∥ n_R near the pitch point by damped Newton (the readable reference
    of the engine's ``prsm_contact_solve``, prsm_geometry.c, operation for operation).

    A central-difference Jacobian (step :data:`_DU` in the scaled unknowns), Gaussian
    elimination with partial pivoting, and a line search that halves the step (at most
    :data:`_MAX_HALVINGS` times) until the largest scaled residual decreases; it stops at
    a residual ≤ 1e-16, at the round-off floor (no decrease) or after :data:`_MAX_ITER`
    iterations, so its work is bounded whatever the input.

    Returns
    -------
    tuple of float
        The contact point (x, y, z) [m], the unit normal (x, y, z) (z > 0), the solution
        (ρ, ψ, ρ_r, ψ_r, z_r), the largest scaled residual and the iterations taken: 13 values.
    """
    prob = _ContactProblem(r_s, r_r, lead, n_s, beta)
    u = [0.0] * 5
    f = prob.evaluate(u)[0]
    fn = _max_abs(f)
    it = 0
    while it < _MAX_ITER and fn > 1e-16 and math.isfinite(fn):
        jac = [[0.0] * 5 for _ in range(5)]
        for j in range(5):
            up, um = list(u), list(u)
            up[j] = u[j] + _DU
            um[j] = u[j] - _DU
            fp, fm = prob.evaluate(up)[0], prob.evaluate(um)[0]
            for i in range(5):
                jac[i][j] = (fp[i] - fm[i]) / (2.0 * _DU)
        d = _solve5(jac, list(f))
        if d is None:
            break
        it += 1
        t = 1.0
        for _ in range(_MAX_HALVINGS):
            un = [u[i] - t * d[i] for i in range(5)]
            fnew = prob.evaluate(un)[0]
            nn = _max_abs(fnew)
            if nn < fn:
                u, f, fn = un, fnew, nn
                break
            t = 0.5 * t
        else:
            break               # at the round-off floor, or no descent
    f, point, normal = prob.evaluate(u)
    return (*point, *normal, *prob.unknowns(u), _max_abs(f), float(it))


def _solve_contact(r_s: float, r_r: float, lead: float, n_s: int,
                   beta: float) -> tuple[float, ...]:
    """:func:`_newton_contact`'s 13 values, by the compiled solver when one is registered."""
    if _compiled:
        return _compiled[0](r_s, r_r, lead, n_s, beta)
    return _newton_contact(r_s, r_r, lead, n_s, beta)


@functools.lru_cache(maxsize=256)
def contact_geometry(stage: StageParams, name: str = "stage") -> ContactGeometry:
    """Screw–roller contact point and normal of a stage, on the "+" flank.

    Solves the five equations "the screw flank and the roller flank share a point (3) and a
    normal (2)" for (ρ, ψ, ρ_r, ψ_r, z_r) by damped Newton (:func:`_newton_contact`, or the
    engine's identical C when its library is loaded), starting at the pitch point (ψ = 0,
    ψ_r = π, ρ = r_S, ρ_r = r_R), to round-off accuracy; no scipy.  The result is
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
        sol = _solve_contact(r_s, r_r, lead, n_s, beta)
        big_r = r_r / math.sin(beta)
    except ArithmeticError:      # e.g. a flank angle of 1e-300 rad: no contact to be found
        sol, big_r = (math.nan,) * 11 + (math.inf, 0.0), math.nan
    point, normal = sol[0:3], sol[3:6]
    rho, psi, rho_r, psi_r, res = sol[6], sol[7], sol[8], sol[9], sol[11]
    near = (all(map(math.isfinite, point)) and res < _RESIDUAL_TOL
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
