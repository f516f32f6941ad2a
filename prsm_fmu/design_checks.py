"""Design checks of a multi-stage PRSM after the two-stage kinematics article's parameter-matching method.

Source: the two-stage kinematics article, "Parameter Matching Design Methodology" and
its table of conditions.  A multi-stage design must satisfy, per stage, the single-stage
matching conditions and, for the mechanism, two added ones:

1. **Geometric meshing** (the pitch circles touch): r_N = r_S + 2 r_R.
2. **Lead matching** (roller and nut threads share their helix angle, so the roller rolls in
   the nut without axial drift): tan λ_R = p / (2π r_R) equals tan λ_N = n_S p / (2π r_N), i.e.
   r_N = n_S r_R (single-start rollers, an n_S-start nut).
3. **Gear engagement**: the spur teeth at the roller ends and the nut's internal ring must turn
   with the thread ratio, z_ig / z_R = r_N / r_R (= n_S); checked when the tooth counts are
   given, otherwise the required ring teeth are reported.
4. **Strength** of the screws under the axial load F_a, [σ] = σ_s / K:
   σ_1 = 4 F_a / (π d_01²) < [σ] (solid screw 1) and, for the hollow screw k ≥ 2 that slides
   over screw k−1, σ_k = 4 F_a / (π (d_0k² − d_0(k−1)²)) < [σ] (the two-stage kinematics article writes k = 2; the
   same holds down the chain).  d_0k = 2 r_Sk are the pitch diameters.  Every screw carries
   the full load (the stages are in series).
5. **Buckling** of the extended column: slenderness λ = µ L / r_min with the critical stress

       σ_cr = σ_s            for λ < λ_s          (yield),
       σ_cr = a − b λ        for λ_s ≤ λ ≤ λ_p    (straight-line formula),
       σ_cr = π² E / λ²      for λ > λ_p          (Euler),

   and, for the stepped section of a multi-stage screw, F_cr = π² E I_1 / (µ_1 µ_2 L)²,
   µ_1 the end-condition factor and µ_2 the stepped-section correction.  Here µ_2 is not
   looked up in a table but computed: the elastic buckling load of the stepped column (one
   section per screw, section 1 = screw 1 at the base, lengths ℓ_k summing to L) is found
   from the exact piecewise solution of E I_k y'''' + P y'' = 0 (:func:`stepped_column_load`),
   and µ_2 = π sqrt(E I_1 / P_cr) / (µ_1 L).  The column then has λ = µ_1 µ_2 L / i_1,
   i_1 = sqrt(I_1 / A_1) = d_01 / 4, and F_cr = σ_cr(λ) A_1, which for λ > λ_p is exactly the
   stepped Euler load.  The design passes if F_a ≤ F_cr / n_st ("F_a ≪ F_cr", n_st the
   stability safety factor).  Without a length the largest stable extended length is
   reported instead.

Material constants (a, b, λ_p, λ_s) are those of the straight-line formula in the usual
mechanics-of-materials tables; the two-stage kinematics article names them without values, so :data:`MATERIALS`,
the safety factors and the end condition are inputs with stated defaults, not the article's data.
SI units throughout (Pa, N, m).
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from .params import GEOMETRY_RTOL, MechanismParams

__all__ = ["Material", "MATERIALS", "DesignInputs", "Check", "DesignReport", "check_design",
           "critical_stress", "stepped_column_load", "END_FACTORS", "default_load",
           "format_report"]


@dataclass(frozen=True)
class Material:
    """Strength and buckling constants of a screw material (SI: Pa)."""

    name: str
    yield_strength: float         # σ_s
    elastic_modulus: float        # E
    a: float                      # straight-line formula σ_cr = a − b λ
    b: float
    lambda_p: float               # proportional-limit slenderness (Euler above)
    lambda_s: float               # yield slenderness (σ_s below)


#: straight-line-formula materials of the usual mechanics-of-materials tables (E = 206 GPa)
MATERIALS: dict[str, Material] = {
    "Q235": Material("Q235 structural steel", 235e6, 206e9, 304e6, 1.12e6, 100.0, 61.6),
    "carbon_steel": Material("high-quality carbon steel", 306e6, 206e9, 461e6, 2.568e6, 100.0,
                             60.0),
    "silicon_steel": Material("silicon steel", 353e6, 206e9, 578e6, 3.744e6, 100.0, 60.0),
}

#: end-condition (effective length) factors µ_1
END_FACTORS = {"pinned-pinned": 1.0, "fixed-free": 2.0, "fixed-pinned": 0.7, "fixed-fixed": 0.5}


@dataclass(frozen=True)
class DesignInputs:
    """What the checks need beyond the mechanism's parameters.

    Parameters
    ----------
    axial_load : float or None
        F_a [N] (compressive for buckling); None: strength and buckling report the allowable
        load only.
    extended_length : float or None
        L [m], the unsupported length of the extended screw column; None: the largest stable
        length is reported.
    material : Material
        Default :data:`MATERIALS` ``["carbon_steel"]``.
    safety_factor : float
        K, [σ] = σ_s / K; default 2.
    stability_factor : float
        n_st, F_a ≤ F_cr / n_st; default 3.
    ends : str
        Key of :data:`END_FACTORS`; default ``pinned-pinned`` (an actuator mounted by clevises
        at both ends).
    section_fractions : sequence of float, optional
        Share of L taken by each screw's section (stage 1 first); default equal shares.
    teeth : (int, int), optional
        (z_R, z_ig): teeth of the roller-end gear and of the ring (all stages).
    """

    axial_load: float | None = None
    extended_length: float | None = None
    material: Material = field(default_factory=lambda: MATERIALS["carbon_steel"])
    safety_factor: float = 2.0
    stability_factor: float = 3.0
    ends: str = "pinned-pinned"
    section_fractions: Sequence[float] | None = None
    teeth: tuple[int, int] | None = None

    def validate(self, n_stages: int) -> "DesignInputs":
        """Check every input; raise ValueError naming it, its value and its range."""
        for name in ("axial_load", "extended_length"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r} is out of range: must be a finite number > 0")
        for name in ("safety_factor", "stability_factor"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 1.0):
                raise ValueError(f"{name} = {v!r} is out of range: must be a number >= 1")
        if self.ends not in END_FACTORS:
            raise ValueError(f"ends = {self.ends!r} is not allowed: must be one of "
                             f"{', '.join(END_FACTORS)}")
        if self.section_fractions is not None:
            f = list(self.section_fractions)
            if len(f) != n_stages or not all(math.isfinite(x) and x > 0 for x in f):
                raise ValueError(f"section_fractions = {f!r} is out of range: must be "
                                 f"{n_stages} positive numbers (one per stage)")
        if self.teeth is not None:
            z = self.teeth
            if len(z) != 2 or not all(isinstance(v, int) and v >= 1 for v in z):
                raise ValueError(f"teeth = {z!r} is out of range: must be two integers "
                                 ">= 1 (z_R, z_ig)")
        m = self.material
        for name in ("yield_strength", "elastic_modulus", "a", "b", "lambda_p", "lambda_s"):
            v = getattr(m, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"material.{name} = {v!r} is out of range: must be > 0")
        if not m.lambda_s < m.lambda_p:
            raise ValueError(f"material.lambda_s = {m.lambda_s!r} must be below "
                             f"lambda_p = {m.lambda_p!r}")
        return self


@dataclass(frozen=True)
class Check:
    """One condition: what it requires, what the design has, and the verdict."""

    name: str
    condition: str
    values: str
    verdict: str            # "pass", "FAIL" or "not checked"
    message: str = ""       # a FAIL names the violated condition and says what it means
    needs: tuple[str, ...] = ()   # "not checked": the DesignInputs fields that would decide it

    @property
    def failed(self) -> bool:
        return self.verdict == "FAIL"


@dataclass(frozen=True)
class DesignReport:
    """Every check of a design."""

    mechanism: str
    inputs: DesignInputs
    checks: tuple[Check, ...]
    notes: tuple[str, ...] = ()

    @property
    def valid(self) -> bool:
        """True if no check fails (checks not done do not fail)."""
        return not any(c.failed for c in self.checks)

    @property
    def failures(self) -> list[Check]:
        return [c for c in self.checks if c.failed]


# ---------------------------------------------------------------------------------------------
# buckling
# ---------------------------------------------------------------------------------------------
def critical_stress(slenderness: float, material: Material) -> tuple[float, str]:
    """σ_cr [Pa] for slenderness λ and the regime's name (the two-stage kinematics article's piecewise formula)."""
    lam = slenderness
    m = material
    if lam < m.lambda_s:
        return m.yield_strength, "yield (λ < λ_s): σ_cr = σ_s"
    if lam <= m.lambda_p:
        return m.a - m.b * lam, "intermediate (λ_s ≤ λ ≤ λ_p): σ_cr = a − bλ"
    return math.pi ** 2 * m.elastic_modulus / lam ** 2, "Euler (λ > λ_p): σ_cr = π²E/λ²"


def _column_matrix(p: float, rel_i: Sequence[float], lengths: Sequence[float],
                   ends: str) -> np.ndarray:
    """Boundary and interface conditions of the stepped column at load p = P L²/(E I_1)."""
    m = len(rel_i)
    a = np.zeros((4 * m, 4 * m))
    ks = [math.sqrt(p / e) for e in rel_i]

    def rows(i: int, s: float) -> dict[str, np.ndarray]:
        """y, y', e·y'', e·y''' + p·y' of segment i at local coordinate s (coefficients)."""
        k, e = ks[i], rel_i[i]
        c, sn = math.cos(k * s), math.sin(k * s)
        y = np.array([1.0, s, c, sn])
        dy = np.array([0.0, 1.0, -k * sn, k * c])
        d2 = np.array([0.0, 0.0, -k * k * c, -k * k * sn])
        d3 = np.array([0.0, 0.0, k ** 3 * sn, -k ** 3 * c])
        return {"y": y, "dy": dy, "M": e * d2, "V": e * d3 + p * dy}

    r = 0
    base, tip = {"pinned-pinned": (("y", "M"), ("y", "M")),
                 "fixed-free": (("y", "dy"), ("M", "V")),
                 "fixed-pinned": (("y", "dy"), ("y", "M")),
                 "fixed-fixed": (("y", "dy"), ("y", "dy"))}[ends]
    start = rows(0, 0.0)
    for q in base:
        a[r, 0:4] = start[q]
        r += 1
    for i in range(m - 1):
        left, right = rows(i, lengths[i]), rows(i + 1, 0.0)
        for q in ("y", "dy", "M", "V"):
            a[r, 4 * i:4 * i + 4] = left[q]
            a[r, 4 * i + 4:4 * i + 8] = -right[q]
            r += 1
    end = rows(m - 1, lengths[m - 1])
    for q in tip:
        a[r, 4 * (m - 1):4 * m] = end[q]
        r += 1
    return a


def stepped_column_load(moments: Sequence[float], lengths: Sequence[float],
                        elastic_modulus: float, ends: str = "pinned-pinned") -> float:
    """Elastic buckling load [N] of a column of piecewise-constant E I.

    Parameters
    ----------
    moments : sequence of float
        Second moments of area I_k [m⁴] of the sections, from the base (x = 0) to the tip.
    lengths : sequence of float
        Lengths ℓ_k [m] of the sections.
    elastic_modulus : float
        E [Pa].
    ends : str
        Key of :data:`END_FACTORS`; for ``fixed-*`` the base (section 1) is the fixed end.

    Returns
    -------
    float
        The smallest P > 0 for which E I_k y'''' + P y'' = 0 (y, y', E I y'' and the shear
        E I y''' + P y' continuous between sections) has a non-zero solution.
    """
    if len(moments) != len(lengths) or not moments:
        raise ValueError("moments and lengths need the same number (>= 1) of sections")
    if not all(v > 0 and math.isfinite(v) for v in list(moments) + list(lengths)):
        raise ValueError("every section moment and length must be a finite number > 0")
    total = float(sum(lengths))
    i1 = float(moments[0])
    rel_i = [float(v) / i1 for v in moments]
    rel_l = [float(v) / total for v in lengths]
    mu = END_FACTORS[ends]
    # the load lies between those of uniform columns of the weakest and the stiffest section
    # (the table's µ_1 are rounded, e.g. 0.7 for 0.6992: a margin of 10 % either side)
    p_lo = math.pi ** 2 * min(rel_i) / mu ** 2 * 0.9
    p_hi = math.pi ** 2 * max(rel_i) / mu ** 2 * 1.1

    def det(p: float) -> float:
        return float(np.linalg.det(_column_matrix(p, rel_i, rel_l, ends)))

    grid = np.linspace(p_lo, p_hi, 401)
    prev_p, prev_d = grid[0], det(grid[0])
    for p in grid[1:]:
        d = det(p)
        if prev_d == 0.0:
            return prev_p * elastic_modulus * i1 / total ** 2
        if d * prev_d < 0.0:
            from scipy.optimize import brentq   # on demand: scipy costs ~0.8 s to import

            root = brentq(det, prev_p, p, xtol=1e-14 * p, rtol=1e-14, maxiter=200)
            return root * elastic_modulus * i1 / total ** 2
        prev_p, prev_d = p, d
    raise RuntimeError("no buckling load found between the weakest and the stiffest "
                       "uniform column (numerical trouble)")


# ---------------------------------------------------------------------------------------------
# the checks
# ---------------------------------------------------------------------------------------------
def _mm(x: float) -> str:
    return f"{x * 1e3:.6g} mm"


def _mpa(x: float) -> str:
    return f"{x / 1e6:.4g} MPa"


def _kn(x: float) -> str:
    return f"{x / 1e3:.4g} kN"


def _sections(params: MechanismParams) -> list[tuple[float, float, str]]:
    """(area A_k [m²], second moment I_k [m⁴], description) of every screw's section."""
    out = []
    for k, st in enumerate(params.stages, start=1):
        d = 2.0 * st.screw_radius
        if k == 1:
            out.append((math.pi * d ** 2 / 4.0, math.pi * d ** 4 / 64.0, f"solid, d_01 = {_mm(d)}"))
        else:
            d_in = 2.0 * params.stages[k - 2].screw_radius
            out.append((math.pi * (d ** 2 - d_in ** 2) / 4.0,
                        math.pi * (d ** 4 - d_in ** 4) / 64.0,
                        f"hollow, d_0{k} = {_mm(d)}, bore d_0{k - 1} = {_mm(d_in)}"))
    return out


def _geometry_checks(params: MechanismParams, inputs: DesignInputs) -> list[Check]:
    checks = []
    for k, st in enumerate(params.stages, start=1):
        fit = st.screw_radius + 2.0 * st.roller_radius
        ok = abs(st.nut_radius - fit) <= GEOMETRY_RTOL * fit
        checks.append(Check(
            f"stage {k}: geometric meshing", "r_N = r_S + 2 r_R",
            f"r_N = {_mm(st.nut_radius)}, r_S + 2 r_R = {_mm(fit)}", "pass" if ok else "FAIL",
            "" if ok else f"stage {k}: geometric meshing r_N = r_S + 2 r_R is violated "
            f"({_mm(st.nut_radius)} ≠ {_mm(fit)}): the rollers "
            f"{'do not fit between' if st.nut_radius < fit else 'do not touch both'} screw and nut"))
        p = st.screw_lead / st.screw_starts
        tan_r = p / (2.0 * math.pi * st.roller_radius)
        tan_n = st.screw_starts * p / (2.0 * math.pi * st.nut_radius)
        ok = abs(tan_r - tan_n) <= GEOMETRY_RTOL * tan_n
        checks.append(Check(
            f"stage {k}: lead matching", "tan λ_R = p/(2π r_R) = tan λ_N = n_S p/(2π r_N), "
            "i.e. r_N = n_S r_R",
            f"λ_R = {math.degrees(math.atan(tan_r)):.4f}°, λ_N = "
            f"{math.degrees(math.atan(tan_n)):.4f}° (r_N / r_R = "
            f"{st.nut_radius / st.roller_radius:.6g}, n_S = {st.screw_starts})",
            "pass" if ok else "FAIL",
            "" if ok else f"stage {k}: lead matching r_N = n_S r_R is violated (r_N / r_R = "
            f"{st.nut_radius / st.roller_radius:.6g}, n_S = {st.screw_starts}): the roller "
            "and nut helix angles differ, so the rollers drift axially in the nut"))
        ratio = st.nut_radius / st.roller_radius
        if inputs.teeth is None:
            checks.append(Check(
                f"stage {k}: gear engagement", "z_ig / z_R = r_N / r_R",
                f"r_N / r_R = {ratio:.6g}: the ring needs z_ig = {ratio:.6g} z_R "
                "(give the tooth counts to check)", "not checked", needs=("teeth",)))
        else:
            z_r, z_ig = inputs.teeth
            ok = abs(z_ig / z_r - ratio) <= GEOMETRY_RTOL * ratio
            checks.append(Check(
                f"stage {k}: gear engagement", "z_ig / z_R = r_N / r_R",
                f"z_ig / z_R = {z_ig}/{z_r} = {z_ig / z_r:.6g}, r_N / r_R = {ratio:.6g}",
                "pass" if ok else "FAIL",
                "" if ok else f"stage {k}: gear engagement z_ig / z_R = r_N / r_R is violated "
                f"({z_ig}/{z_r} ≠ {ratio:.6g}): the gears and the threads impose different "
                "roller spins"))
    return checks


def _strength_checks(params: MechanismParams, inputs: DesignInputs) -> list[Check]:
    allow = inputs.material.yield_strength / inputs.safety_factor
    checks = []
    secs = _sections(params)
    for k, (area, _i, desc) in enumerate(secs, start=1):
        cond = ("σ_1 = 4 F_a / (π d_01²) < [σ]" if k == 1 else
                f"σ_{k} = 4 F_a / (π (d_0{k}² − d_0{k - 1}²)) < [σ]")
        name = f"screw {k}: strength ({'solid' if k == 1 else 'hollow'})"
        if area <= 0.0:
            checks.append(Check(name, cond, desc, "FAIL",
                                f"screw {k}: strength {cond} cannot hold: d_0{k} ≤ d_0{k - 1}, "
                                f"the hollow screw {k} has no wall around screw {k - 1}"))
            continue
        f_allow = allow * area
        if inputs.axial_load is None:
            checks.append(Check(name, cond, f"{desc}; [σ] = σ_s/K = {_mpa(allow)}; allowable "
                                f"F_a < {_kn(f_allow)}", "not checked",
                                needs=("axial_load",)))
            continue
        sigma = inputs.axial_load / area
        ok = sigma < allow
        checks.append(Check(
            name, cond, f"{desc}: σ_{k} = {_mpa(sigma)}, [σ] = σ_s/K = {_mpa(allow)} "
            f"(allowable F_a < {_kn(f_allow)})", "pass" if ok else "FAIL",
            "" if ok else f"screw {k}: strength {cond} is violated: σ_{k} = {_mpa(sigma)} ≥ "
            f"[σ] = {_mpa(allow)} under F_a = {_kn(inputs.axial_load)} (allowable "
            f"{_kn(f_allow)})"))
    return checks


def _buckling(params: MechanismParams, inputs: DesignInputs, length: float):
    """(F_cr [N], λ, σ_cr [Pa], regime, µ_2) of the column extended to ``length``."""
    secs = _sections(params)
    if any(a <= 0 for a, _, _ in secs):
        raise ValueError("a hollow screw has no wall")
    fr = list(inputs.section_fractions or [1.0] * len(secs))
    lengths = [length * f / sum(fr) for f in fr]
    m = inputs.material
    mu1 = END_FACTORS[inputs.ends]
    moments = [i for _, i, _ in secs]
    p_el = stepped_column_load(moments, lengths, m.elastic_modulus, inputs.ends)
    a1, i1 = secs[0][0], moments[0]
    mu2 = math.pi * math.sqrt(m.elastic_modulus * i1 / p_el) / (mu1 * length)
    lam = mu1 * mu2 * length / math.sqrt(i1 / a1)
    sigma, regime = critical_stress(lam, m)
    return sigma * a1, lam, sigma, regime, mu2


def _buckling_check(params: MechanismParams, inputs: DesignInputs) -> Check:
    n_st = inputs.stability_factor
    mu1 = END_FACTORS[inputs.ends]
    cond = f"F_a ≤ F_cr / n_st, F_cr = σ_cr(λ) A_1, λ = µ_1 µ_2 L / i_1 ({inputs.ends}: µ_1 = {mu1:g})"
    name = "column: buckling (stepped section)"
    secs = _sections(params)
    if any(a <= 0 for a, _, _ in secs):
        return Check(name, cond, "a hollow screw has no wall (see strength)", "FAIL",
                     "column: buckling cannot be assessed: a hollow screw has no wall")
    if inputs.extended_length is not None:
        f_cr, lam, sigma, regime, mu2 = _buckling(params, inputs, inputs.extended_length)
        vals = (f"L = {inputs.extended_length:g} m, µ_2 = {mu2:.4f}, λ = {lam:.1f}, {regime}, "
                f"σ_cr = {_mpa(sigma)}, F_cr = {_kn(f_cr)}, F_cr / n_st = {_kn(f_cr / n_st)}")
        if inputs.axial_load is None:
            return Check(name, cond, vals + " (allowable F_a)", "not checked",
                         needs=("axial_load",))
        ok = inputs.axial_load <= f_cr / n_st
        return Check(name, cond, vals + f", F_a = {_kn(inputs.axial_load)}",
                     "pass" if ok else "FAIL",
                     "" if ok else f"column: buckling F_a ≤ F_cr / n_st is violated: F_a = "
                     f"{_kn(inputs.axial_load)} > F_cr / n_st = {_kn(f_cr / n_st)} at L = "
                     f"{inputs.extended_length:g} m (λ = {lam:.1f}, {regime.split(':')[0]})")
    if inputs.axial_load is None:
        return Check(name, cond, "no axial load and no length given", "not checked",
                     needs=("axial_load", "extended_length"))
    # the longest stable extension: F_cr(L) decreases with L
    need = inputs.axial_load * n_st

    def margin(length: float) -> float:
        return _buckling(params, inputs, length)[0] - need

    short = 1e-4
    if margin(short) < 0:
        return Check(name, cond, f"F_a n_st = {_kn(need)} exceeds the squash load σ_s A_1",
                     "FAIL", "column: buckling F_a ≤ F_cr / n_st is violated at any length: "
                     f"F_a · n_st = {_kn(need)} > σ_s A_1 = "
                     f"{_kn(inputs.material.yield_strength * secs[0][0])}")
    long_ = 1.0
    while margin(long_) > 0 and long_ < 1e4:
        long_ *= 2.0
    from scipy.optimize import brentq   # on demand: scipy costs ~0.8 s to import

    l_max = brentq(margin, short, long_, xtol=1e-9)
    return Check(name, cond, f"no length given: stable (F_a ≤ F_cr / n_st) for an extended "
                 f"length L ≤ {l_max:.4g} m", "not checked", needs=("extended_length",))


def check_design(params: MechanismParams, inputs: DesignInputs | None = None) -> DesignReport:
    """Run every check of the module docstring on ``params``.

    Each parameter is validated against its own range first (a negative radius is refused, as
    everywhere), but not the meshing of the radii: an inconsistent design gets verdicts
    rather than an exception.

    Raises
    ------
    ValueError
        For a parameter out of its range or invalid ``inputs`` (naming it and its range).
    """
    params.validate(geometry=False)
    inputs = (inputs or DesignInputs()).validate(params.n_stages)
    checks = _geometry_checks(params, inputs) + _strength_checks(params, inputs)
    checks.append(_buckling_check(params, inputs))
    notes = (f"material: {inputs.material.name} (σ_s = {_mpa(inputs.material.yield_strength)}, "
             f"E = {inputs.material.elastic_modulus / 1e9:g} GPa, a = {_mpa(inputs.material.a)}, "
             f"b = {_mpa(inputs.material.b)}, λ_s = {inputs.material.lambda_s:g}, "
             f"λ_p = {inputs.material.lambda_p:g}); K = {inputs.safety_factor:g}, "
             f"n_st = {inputs.stability_factor:g}; ends {inputs.ends}",)
    return DesignReport(params.name, inputs, tuple(checks), notes)


def default_load(preset: str) -> float | None:
    """The largest axial load of a preset's paper scenario (its module's ``SCENARIO``), if any."""
    from . import presets

    try:
        factory = presets._registry()[preset]
    except KeyError:
        return None
    module = importlib.import_module(factory.__module__)
    sc = getattr(module, "SCENARIO", {}) or {}
    loads = []
    for key in ("load_force", "ramp_loads", "load_forces"):
        v = sc.get(key)
        if isinstance(v, (int, float)):
            loads.append(float(v))
        elif isinstance(v, (list, tuple)):
            loads += [float(x) for x in v]
    return max(loads) if loads else None


#: how :func:`format_report` names a missing input by default (the DesignInputs field)
_INPUT_NAMES = {"axial_load": "axial_load F_a", "extended_length": "extended_length L",
                "teeth": "teeth (z_R, z_ig)"}


def format_report(report: DesignReport, inputs_named: Mapping[str, str] | None = None) -> str:
    """The report as text: one block per check and a final verdict.

    A verdict with checks not done names, for each missing input, the checks it would decide.

    Parameters
    ----------
    report : DesignReport
    inputs_named : mapping, optional
        How to name a missing DesignInputs field (e.g. ``{"axial_load": "--load F_a"}`` for a
        command line); default the field names.
    """
    names = {**_INPUT_NAMES, **(inputs_named or {})}
    inp = report.inputs
    lines = [f"design checks (the two-stage kinematics article): {report.mechanism}",
             f"axial load F_a = {'not given' if inp.axial_load is None else _kn(inp.axial_load)}, "
             f"extended length L = "
             f"{'not given' if inp.extended_length is None else f'{inp.extended_length:g} m'}"]
    lines += list(report.notes)
    lines.append("")
    width = max(len(c.name) for c in report.checks)
    for c in report.checks:
        lines.append(f"{c.verdict.upper() if c.verdict != 'not checked' else 'not checked':>11}"
                     f"  {c.name.ljust(width)}  {c.condition}")
        lines.append(f"{'':>11}  {'':{width}}  {c.values}")
    lines.append("")
    skipped = [c for c in report.checks if c.verdict == "not checked"]
    if report.valid:
        lines.append(f"verdict: VALID — no condition violated: "
                     f"{len(report.checks) - len(skipped)} checks pass"
                     + (f", {len(skipped)} not checked (inputs missing):" if skipped else ""))
        wanted: dict[tuple[str, ...], list[str]] = {}
        for c in skipped:
            wanted.setdefault(c.needs, []).append(c.name)
        for needs, checks in wanted.items():
            what = " and ".join(names.get(n, n) for n in needs) or "more inputs"
            lines.append(f"  - give {what} to check: {', '.join(checks)}")
    else:
        lines.append(f"verdict: INVALID — {len(report.failures)} condition(s) violated:")
        lines += [f"  - {c.message}" for c in report.failures]
    return "\n".join(lines)
