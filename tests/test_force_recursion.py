"""An independent check of the force recursion of mechanics.py.

Every body's balance of docs/model.md §3 is written out here plainly, from first principles,
as one system in the 4n − 1 unknowns of Li et al. (2021) (after Eq. 26):
per stage the normal force per roller F_k and the carrier acceleration ω̇_Pk, the driven
torques M_Sk and bearing forces B_(k−1) of stages k ≥ 2, and the screw acceleration α (torque
drive) or the motor torque M_S1 (speed drive).  For a fixed state (ω, ω_Pk) the slip velocity
and so the friction direction are known, and once the signs are fixed (which flank carries
each stage, the sign of each M_Sk for the spline friction and of each B_k for the bearing
friction) the system is linear: every sign pattern is solved with scipy and the patterns whose
solution has the signs assumed are the solutions of the rigid Coulomb problem.  Nothing of
mechanics.py is used: only the contact point and normal of geometry.py (tested on their own
in test_geometry.py) and the parameters.

The bodies (forces on the body named; Φ_k = F_k (n − µ u) − µ_1 n_t s is the force one roller
puts on screw k, u the regularised slip direction of docs/model.md §5, s = ω a + ω_P b the slip
of the screw's material point relative to the roller's, a = ẑ × P + ℓ ẑ,
b = −ẑ × P + n_S ẑ × (P − c); the friction-torque article's viscous force µ_1 n_t s per roller (µ_1 per engaged
thread, n_t threads) and differential-sliding torque µ_3 F on the screw per roller, against its
rotation: −µ_3 F sgñ(ω r) with r = |P_xy| the contact radius):

* nut assembly k (nut, rollers, carriers) moving at ż = −c_k ω:  −N_R Φ_z + B_k = −m_A c_k α
* screw k ≥ 2 moving at ż = −c_(k−1) ω:  N_R Φ_z − B_(k−1) + h_k − h_(k+1) = −m_S c_(k−1) α
* screw k, about z:  J_S α = M_k − M_(k+1) + N_R [P × Φ]_z − N_R µ_3 F sgñ(ω r)
  − µ_NS r_NS |B_(k−1)| sgñ(ω)
* carrier k (generalized force of the friction on θ_Pk):  J_P ω̇_P = N_R (−µ F u − µ_1 n_t s)·b
* spline: h_k = µ_SS |M_k| / r_SS sgñ(ω ℓ_(k−1)) opposing screw k's sliding along screw k−1

with J_P = n_c J_carrier + N_R J_R (n_S − 1)² + N_R m_R (r_S + r_R)² from the kinetic energy of
carriers turning at ω_P, rollers orbiting at radius r_S + r_R and spinning at −(n_S − 1) ω_P.
"""

from __future__ import annotations

import itertools
import math
import random

import numpy as np
import pytest
import scipy.linalg

from prsm_fmu import presets
from prsm_fmu.geometry import contact_geometry
from prsm_fmu.mechanics import Mechanism
from prsm_fmu.params import MechanismParams


def _three_stage_with_bearings() -> MechanismParams:
    """Li et al.'s (2021) stages plus a third, with every friction on (thrust bearings included)."""
    p = presets.load("li2021_two_stage")
    s1, s2 = p.stages
    s3 = s2.__class__(**{**s2.__dict__, "screw_radius": 24e-3, "roller_radius": 8e-3,
                          "nut_radius": 40e-3, "screw_lead": 12e-3, "spline_radius": 20e-3,
                          "nut_mass": 25.0, "screw_mass": 1.5, "screw_starts": 5})
    stages = (s1.__class__(**{**s1.__dict__, "bearing_radius": 14e-3}),
              s2.__class__(**{**s2.__dict__, "bearing_radius": 22e-3}), s3)
    return p.with_changes(stages=stages, mu_nut_screw=0.02, name="three_stage_test").validate()


def _three_stage_all_terms() -> MechanismParams:
    """The three-stage mechanism with the friction-torque article's viscous and differential terms as well, strong
    enough (µ_1 = 5 N·s/m per thread, 8 threads, µ_3 = 50 µm) that the viscous axial force
    N_R µ_1 n_t ℓ ω reaches the loads drawn (up to ~2 kN at 300 rad/s) and so decides flanks."""
    p = _three_stage_with_bearings()
    for k in range(1, p.n_stages + 1):
        p = p.with_stage(k, threads_per_roller=8)
    return p.with_changes(mu_viscous=5.0, mu_differential=5e-5).validate()


MECHANISMS = {
    "li2021": lambda: presets.load("li2021_two_stage"),
    "assembly_article": lambda: presets.load("assembly_two_stage"),      # thrust-bearing friction
    "three_stage": _three_stage_with_bearings,
    "three_stage_all_terms": _three_stage_all_terms,           # + viscous, differential
    "friction_article": lambda: presets.load("friction_single_stage"),   # the friction-torque article's own µ_1, µ_3
}


def phi(v: float, v_eps: float) -> float:
    """Regularised Coulomb factor of docs/model.md §5: u = s φ(|s|)."""
    return 1.0 / v if v >= v_eps else (2.0 - v / v_eps) / v_eps


def sgn_reg(v: float, v_eps: float) -> float:
    """Regularised sign v φ(|v|)."""
    return v * phi(abs(v), v_eps)


class PlainStage:
    """What the plain balances need of one stage, per flank."""

    def __init__(self, params: MechanismParams, k: int) -> None:
        st = params.stages[k]
        self.st = st
        self.n_r = st.n_rollers
        self.ell = st.screw_lead / (2 * math.pi)
        self.c = sum(s.screw_lead for s in params.stages[: k + 1]) / (2 * math.pi)
        self.c_prev = sum(s.screw_lead for s in params.stages[:k]) / (2 * math.pi)
        self.m_assembly = st.nut_mass + st.n_rollers * st.roller_mass + st.carriers * st.carrier_mass
        orbit = st.screw_radius + st.roller_radius
        self.j_carrier = (st.carriers * st.carrier_inertia
                          + st.n_rollers * st.roller_inertia * (st.screw_starts - 1) ** 2
                          + st.n_rollers * st.roller_mass * orbit**2)
        geo = contact_geometry(st)
        self.flanks = []
        for g in (geo, geo.mirrored()):
            p = np.array(g.point, dtype=float)
            n = np.array(g.normal, dtype=float)
            c = np.array([orbit, 0.0, 0.0]) * (1.0 if g is geo else 1.0)
            z = np.array([0.0, 0.0, 1.0])
            a = np.cross(z, p) + self.ell * z
            b = -np.cross(z, p) + st.screw_starts * np.cross(z, p - c)
            self.flanks.append((p, n, a, b))


def plain_solutions(params: MechanismParams, omega: float, wp: list[float], load: float, *,
                    torque: float | None = None, acceleration: float | None = None) -> list[dict]:
    """Every solution of the rigid Coulomb problem at this state (see module docstring)."""
    n = params.n_stages
    stages = [PlainStage(params, k) for k in range(n)]
    mu, v_eps = params.mu_screw_roller, params.slip_velocity_scale
    mu1, mu3 = params.mu_viscous, params.mu_differential
    # unknown vector: F_1..F_n, ω̇_P1..ω̇_Pn, M_2..M_n, B_1..B_(n−1), X (α or M_1)
    i_f, i_p, i_m, i_b, i_x = 0, n, 2 * n, 3 * n - 1, 4 * n - 2
    size = 4 * n - 1
    spline = [0.0] + [params.mu_spline / stages[k].st.spline_radius
                      * sgn_reg(omega * stages[k - 1].ell, v_eps) if params.mu_spline else 0.0
                      for k in range(1, n)]
    bearing = [0.0] + [params.mu_nut_screw * params.stages[k - 1].bearing_radius
                       * sgn_reg(omega * params.stages[k - 1].bearing_radius, v_eps)
                       if params.mu_nut_screw else 0.0 for k in range(1, n)]
    found = []
    # a sign that no friction law reads is not a pattern of its own
    sm_choices = [(1.0, -1.0) if spline[k] else (1.0,) for k in range(1, n)]
    sb_choices = [(1.0, -1.0) if bearing[k] else (1.0,) for k in range(1, n)]
    for flanks in itertools.product((0, 1), repeat=n):
        for sm in itertools.product(*sm_choices):
            for sb in itertools.product(*sb_choices):
                A = np.zeros((size, size))
                rhs = np.zeros(size)
                per_unit = []
                row = 0

                def col_m(k):                  # column of M_(k+1) (k 0-based, k ≥ 1)
                    return i_m + k - 1

                def col_b(k):                  # column of B_(k+1) (k 0-based, k ≤ n − 2)
                    return i_b + k
                for k, stg in enumerate(stages):
                    p, nrm, a, b = stg.flanks[flanks[k]]
                    s = omega * a + wp[k] * b
                    u = s * phi(float(np.linalg.norm(s)), v_eps)
                    force = nrm - mu * u                     # Φ per unit F (the F part)
                    visc = -mu1 * stg.st.threads_per_roller * s  # Φ's viscous part, per roller
                    sg = sgn_reg(omega * math.hypot(p[0], p[1]), v_eps)
                    per_unit.append((force, u, s, b, p, nrm, visc, sg))
                # nut assembly k: N_R Φ_z − B_k − m_A c_k α = 0
                for k, stg in enumerate(stages):
                    force = per_unit[k][0]
                    A[row, i_f + k] = stg.n_r * force[2]
                    rhs[row] -= stg.n_r * per_unit[k][6][2]
                    if k < n - 1:
                        A[row, col_b(k)] = -1.0
                    else:
                        rhs[row] += load
                    if torque is not None:
                        A[row, i_x] = -stg.m_assembly * stg.c
                    else:
                        rhs[row] += stg.m_assembly * stg.c * acceleration
                    row += 1
                # screw k ≥ 2 axial: N_R Φ_z − B_(k−1) + h_k − h_(k+1) + m_S c_(k−1) α = 0
                for k in range(1, n):
                    stg = stages[k]
                    A[row, i_f + k] = stg.n_r * per_unit[k][0][2]
                    rhs[row] -= stg.n_r * per_unit[k][6][2]
                    A[row, col_b(k - 1)] = -1.0
                    A[row, col_m(k)] += spline[k] * sm[k - 1]
                    if k + 1 < n:
                        A[row, col_m(k + 1)] -= spline[k + 1] * sm[k]
                    m_s = stg.st.screw_mass * stg.c_prev
                    if torque is not None:
                        A[row, i_x] = m_s
                    else:
                        rhs[row] -= m_s * acceleration
                    row += 1
                # screw k torque: M_k − M_(k+1) + N_R [P × Φ]_z − bearing − J_S α = 0
                for k, stg in enumerate(stages):
                    force, p, visc, sg = per_unit[k][0], per_unit[k][4], per_unit[k][6], per_unit[k][7]
                    A[row, i_f + k] = stg.n_r * (p[0] * force[1] - p[1] * force[0] - mu3 * sg)
                    rhs[row] -= stg.n_r * (p[0] * visc[1] - p[1] * visc[0])
                    if k == 0:
                        if torque is not None:
                            rhs[row] -= torque
                        else:
                            A[row, i_x] = 1.0
                    else:
                        A[row, col_m(k)] = 1.0
                        A[row, col_b(k - 1)] -= bearing[k] * sb[k - 1]
                    if k + 1 < n:
                        A[row, col_m(k + 1)] = -1.0
                    j_s = stg.st.screw_inertia
                    if torque is not None:
                        A[row, i_x] -= j_s
                    else:
                        rhs[row] += j_s * acceleration
                    row += 1
                # carrier k: J_P ω̇_P − N_R F (−µ u·b) = N_R (viscous force)·b
                for k, stg in enumerate(stages):
                    u, b = per_unit[k][1], per_unit[k][3]
                    A[row, i_p + k] = stg.j_carrier
                    A[row, i_f + k] = stg.n_r * mu * float(u @ b)
                    rhs[row] = stg.n_r * float(per_unit[k][6] @ b)
                    row += 1
                assert row == size
                try:
                    z = scipy.linalg.solve(A, rhs)
                except scipy.linalg.LinAlgError:
                    continue
                forces = z[i_f:i_f + n]
                torques = [None] + list(z[i_m:i_m + n - 1])
                bearings = list(z[i_b:i_b + n - 1])
                if any(f < 0.0 for f in forces):
                    continue
                if any(spline[k] and (torques[k] >= 0.0) != (sm[k - 1] > 0) for k in range(1, n)):
                    continue
                if any(bearing[k] and (bearings[k - 1] >= 0.0) != (sb[k - 1] > 0)
                       for k in range(1, n)):
                    continue
                alpha = z[i_x] if torque is not None else acceleration
                motor = torque if torque is not None else z[i_x]
                h = [0.0] + [spline[k] * sm[k - 1] * torques[k] for k in range(1, n)]
                p_fric = 0.0
                for k, stg in enumerate(stages):
                    u, s, visc, sg = per_unit[k][1], per_unit[k][2], per_unit[k][6], per_unit[k][7]
                    p_fric += stg.n_r * mu * forces[k] * float(u @ s)
                    p_fric -= stg.n_r * float(visc @ s)                   # viscous: µ_1 n_t |s|²
                    p_fric += stg.n_r * mu3 * forces[k] * sg * omega      # differential sliding
                    if k > 0:
                        p_fric += h[k] * omega * stages[k - 1].ell
                        p_fric += bearing[k] * abs(bearings[k - 1]) * omega
                found.append({
                    "alpha": alpha, "motor": motor,
                    "carrier_acc": list(z[i_p:i_p + n]),
                    "normal": list(forces),
                    "contact": [forces[k] * per_unit[k][5][2] for k in range(n)],
                    "driven": [motor] + torques[1:],
                    "spline": h,
                    "friction_power": p_fric,
                })
    return found


def _random_state(rng: random.Random, n: int):
    omega = rng.choice([1.0, -1.0]) * 10 ** rng.uniform(-4, 2.5)
    wp = [omega * rng.uniform(-0.5, 1.0) for _ in range(n)]
    load = rng.uniform(-8000.0, 8000.0)
    return omega, wp, load


def _close(a: float, b: float, scale: float) -> bool:
    return abs(a - b) <= 1e-9 * scale


def _assert_equal(sol, ref: dict, scales: dict) -> None:
    assert _close(sol.screw_acceleration, ref["alpha"], scales["alpha"])
    assert _close(sol.motor_torque, ref["motor"], scales["torque"])
    for k in range(len(ref["normal"])):
        assert _close(sol.carrier_accelerations[k], ref["carrier_acc"][k], scales["carrier"]), k
        assert _close(sol.normal_force[k], ref["normal"][k], scales["force"]), k
        assert _close(sol.contact_force[k], ref["contact"][k], scales["force"]), k
        assert _close(sol.driven_torque[k], ref["driven"][k], scales["torque"]), k
        assert _close(sol.spline_friction[k], ref["spline"][k], scales["force"]), k
    assert _close(sol.friction_power, ref["friction_power"], scales["power"])


@pytest.mark.parametrize("name", sorted(MECHANISMS))
@pytest.mark.parametrize("drive", ["speed", "torque"])
def test_recursion_equals_the_plain_balances_at_random_states_to_1e_9(name, drive):
    params = MECHANISMS[name]()
    mech = Mechanism(params, "dynamic")
    rng = random.Random(2024 + len(name) + len(drive))
    flanks_seen = set()
    compared = painleve = 0
    for _ in range(60):
        omega, wp, load = _random_state(rng, params.n_stages)
        if drive == "torque":
            kw = {"torque": rng.uniform(-40.0, 40.0)}
        else:
            kw = {"acceleration": rng.uniform(-2e4, 2e4)}
        sols = plain_solutions(params, omega, wp, load, **kw)
        sol = mech.solve(omega, wp, load, detail=True, **kw)
        # scales: the largest magnitude of each kind in the plain solutions and the inputs
        ref_all = sols or [{"alpha": 0, "motor": 0, "carrier_acc": [0], "normal": [0],
                            "friction_power": 0}]
        scales = {
            "alpha": max(1.0, *(abs(r["alpha"]) for r in ref_all)),
            "torque": max(1.0, *(abs(r["motor"]) for r in ref_all)),
            "carrier": max(1.0, *(abs(a) for r in ref_all for a in r["carrier_acc"])),
            "force": max(1.0, abs(load), *(abs(f) for r in ref_all for f in r["normal"])),
            "power": max(1e-6, *(abs(r["friction_power"]) for r in ref_all)),
        }
        if drive == "speed":
            # a prescribed acceleration: exactly one solution, always
            assert len(sols) == 1
            assert sol.consistent
        if len(sols) != 1:
            # torque drive with no or several solutions (Painlevé): the recursion must say so
            # (none) or return the one of least |α| (docs/model.md §5)
            painleve += 1
            if not sols:
                assert not sol.consistent
            else:
                best = min(sols, key=lambda r: abs(r["alpha"]))
                assert sol.consistent
                _assert_equal(sol, best, scales)
            continue
        assert sol.consistent
        _assert_equal(sol, sols[0], scales)
        flanks_seen.update((k, c > 0) for k, c in enumerate(sols[0]["contact"]))
        compared += 1
    assert compared >= 40
    # both flanks of every stage were exercised
    assert flanks_seen == {(k, side) for k in range(params.n_stages) for side in (True, False)}
