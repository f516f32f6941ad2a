"""Stability maps: where each explicit stepper stops being stable, predicted and measured.

Two maps, each point classified against a reference as **correct**, **bounded-but-wrong** or
**diverged** (bounded is not right: past its limit RK4 settles into a limit cycle on a wrong
carrier ratio without any warning).

1. Stiff carriers (``carriers``).  At operating points across screw speed (1…300 rad/s) and
   load (1…10 kN), in both drives (speed drive: ω prescribed; torque drive: the steady motor
   torque of the independent root finder, ω a state), the dynamic model starts at the carriers'
   equilibrium with carrier 1 disturbed by −0.1 % and is advanced by ``N_STEPS`` fixed steps h
   of RK4 (``rk4``) and of the Dormand–Prince 5(4) pair at ``fixed_substeps = 1``
   (``explicit_adaptive``).  Prediction: h_pred = x* τ, with τ the fastest linearised carrier
   time constant at the operating point (``model.fastest_time_constant``) and x* the method's
   real-axis stability limit, the smallest x > 0 with |R(−x)| = 1 of its stability polynomial
   R(z) = Σ_k (bᵀA^(k−1)1) z^k, computed here from the Butcher tableau (RK4: 2.785, DP5: 3.307).
   Scan h/h_pred over ``FACTORS``, then bisect the first change from correct to not correct:
   that is the measured limit.  Reference: ``solve_ivp(Radau)`` at rtol 1e-12 from the same
   start over the shortest run; after ≥ 500 τ the carriers sit on their equilibrium ratio,
   which no longer changes, so the reference ratio holds for every run (checked at the
   longest run too).  A run is *diverged* on StepFailure, a non-finite state, or a speed state
   grown beyond 10× its start; *correct* if every carrier ratio ω_Pk/ω is within 1e-6 of the
   reference's; otherwise *bounded-but-wrong*.  The Jacobian's eigenvalues (finite
   differences) are printed beside the prediction: in the torque drive the screw couples to
   the carriers and the fastest eigenvalue is ~1 % faster than the carrier's own time constant.

2. Friction at zero speed (``friction``).  The torque-driven reversal of tests/test_dynamics.py
   (motor torque 5 N·m against 5 kN from 30 rad/s, carriers at equilibrium, 1.5 ms,
   communication step 10 µs): the screw stops at ~1.04 ms and the load back-drives it, and
   the carriers' time constants collapse to nanoseconds as the slip passes the friction band.
   For each regularisation scale v_ε (``slip_velocity_scale``) and each stepper
   configuration: *diverged* on StepFailure or NaN; *bounded-but-wrong* if it chatters (total
   variation of a force output above 1.01× the reference's), stalls (no reversal), or misses
   the reference by more than ``FRICTION_TOL`` (docs/accuracy.md §1 error over the FMU's outputs);
   else *correct*.  Reference: Radau at rtol 1e-12 on the same v_ε (checked at 1e-11).
   The regularisation's own model error, each v_ε's reference against the smallest v_ε's,
   is printed and written too (a large v_ε passes easily and is wrong in another way).

Writes ``docs/figures/stability_carriers{,_boundaries}.csv``, ``stability_carriers.png``,
``stability_friction.csv`` and ``stability_friction.png``.

Run: ``python benchmarks/stability_maps.py`` (about 70 s; ``--part carriers|friction``,
``--quick``, ``--out DIR``).  docs/accuracy.md explains the maps.
"""

from __future__ import annotations

import argparse
import csv
import functools
import importlib.util
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prsm_fmu import presets, simulate, steady_state
from prsm_fmu.models import make_model
from prsm_fmu.steppers import EXPLICIT_TABLEAUS, StepFailure, make_stepper

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
LI2021 = presets.load("li2021_two_stage")

CORRECT, WRONG, DIVERGED = "correct", "bounded-but-wrong", "diverged"
CLASS_COLOUR = {CORRECT: "tab:green", WRONG: "tab:orange", DIVERGED: "tab:red"}


def _load_sibling(name: str):
    """Import benchmarks/<name>.py by path (script or test use alike)."""
    mod_name = f"_prsm_benchmarks_{name}"
    if mod_name in sys.modules:
        return sys.modules[mod_name]
    spec = importlib.util.spec_from_file_location(mod_name, Path(__file__).with_name(f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    spec.loader.exec_module(mod)
    return mod


# ---- stability polynomials -------------------------------------------------------------------

#: classic RK4 (Kutta 1901), the tableau steppers.RK4 implements
RK4_TABLEAU = ((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0)), (1 / 6, 1 / 3, 1 / 3, 1 / 6)


def stability_polynomial(a_rows, b) -> np.ndarray:
    """Coefficients (ascending powers) of R(z) = 1 + Σ_k (bᵀ A^(k−1) 1) z^k of an explicit
    Runge–Kutta method with strictly lower triangular A given by its rows."""
    s = len(b)
    a = np.zeros((s, s))
    for i, row in enumerate(a_rows):
        a[i, :len(row)] = row
    coeffs = [1.0]
    v = np.ones(s)
    for _ in range(s):
        coeffs.append(float(np.dot(b, v)))
        v = a @ v
    return np.array(coeffs)


def real_axis_limit(coeffs: np.ndarray) -> float:
    """Smallest x > 0 with |R(−x)| = 1: the stability interval on the negative real axis is
    [−x, 0].  Roots of R(z) ∓ 1 on the negative real axis, polished by bisection."""
    cands = []
    for target in (1.0, -1.0):
        q = np.array(coeffs, dtype=float)
        q[0] -= target
        for r in np.roots(q[::-1]):
            if abs(r.imag) <= 1e-7 * max(1.0, abs(r)) and r.real < -1e-9:
                cands.append(-r.real)
    x = min(cands)

    def g(v):          # |R(−v)| − 1, < 0 inside the interval
        return abs(np.polyval(coeffs[::-1], -v)) - 1.0

    lo, hi = 0.5 * x, 1.5 * x
    if not (g(lo) < 0.0 < g(hi)):
        return x
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(mid) < 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@functools.cache
def _limits() -> tuple:
    dp5 = EXPLICIT_TABLEAUS[5]
    return (("rk4", real_axis_limit(stability_polynomial(*RK4_TABLEAU))),
            # DP5 propagates the 5th-order solution b (the 7th stage only serves the estimate)
            ("explicit_adaptive", real_axis_limit(stability_polynomial(dp5[1], dp5[2]))))


def method_limits() -> dict[str, float]:
    """Real-axis stability limit x* of each explicit method of the map."""
    return dict(_limits())


METHOD_OPTIONS = {"rk4": {"substeps": 1}, "explicit_adaptive": {"fixed_substeps": 1}}
METHOD_LABEL = {"rk4": "RK4", "explicit_adaptive": "Dormand–Prince 5(4), fixed steps"}


# ---- 1. stiff carriers -----------------------------------------------------------------------

SPEEDS = (1.0, 3.0, 10.0, 30.0, 100.0, 200.0, 300.0)          # rad/s
LOADS = (1000.0, 2000.0, 5000.0, 10000.0)                     # N
DRIVES = ("speed", "torque")
FACTORS = (0.5, 0.8, 0.9, 0.95, 0.98, 1.0, 1.02, 1.05, 1.1, 1.25, 1.5, 2.0, 3.0, 5.0)
N_STEPS = 400
DISTURBANCE = 0.999            # carrier 1 starts at 0.999 of its equilibrium speed
RATIO_TOL = 1e-6               # correct: every carrier ratio within this of the reference's
GROWTH_LIMIT = 10.0            # diverged: a speed state beyond this multiple of its start
BISECTIONS = 10


@dataclass
class OperatingPoint:
    """The model, inputs and disturbed start at one (drive, ω, F), with its time constants."""

    drive: str
    omega: float
    load: float
    model: object
    u: tuple
    x0: list
    tau: float          # model.fastest_time_constant at the (undisturbed) equilibrium [s]
    tau_eig: float      # 1 / largest |eigenvalue| of the finite-difference Jacobian [s]
    ref_ratios: tuple   # reference carrier ratios ω_Pk/ω after the transient [-]
    ref_check: float    # |reference ratio at the shortest − at the longest run| [-]


def speed_indices(model) -> list[int]:
    """Indices of the speed states (screw speed, carrier speeds)."""
    i0 = model.state_names.index("carrier_1_speed")
    return [1] + list(range(i0, i0 + model.n_carrier_states))


def carrier_ratios(model, x, u) -> tuple:
    """ω_Pk / ω of every carrier [-]."""
    omega = x[1]
    i0 = model.state_names.index("carrier_1_speed")
    return tuple(x[i0 + k] / omega for k in range(model.n_carrier_states))


def jacobian_tau(model, x, u) -> float:
    """1 / (largest |eigenvalue|) of the forward-difference Jacobian over the states that the
    derivatives depend on [s]."""
    idx = [i for i in range(model.n_states) if i not in model.quadrature_states]
    f0 = model.rhs(0.0, x, u)
    jac = np.zeros((len(idx), len(idx)))
    for c, j in enumerate(idx):
        xp = list(x)
        d = 1e-7 * max(abs(x[j]), 1.0)
        xp[j] += d
        fp = model.rhs(0.0, xp, u)
        for r, i in enumerate(idx):
            jac[r, c] = (fp[i] - f0[i]) / d
    return 1.0 / float(np.max(np.abs(np.linalg.eigvals(jac))))


def operating_point(drive: str, omega: float, load: float, params=LI2021,
                    horizons: tuple[float, float] | None = None,
                    disturbance: float = DISTURBANCE) -> OperatingPoint:
    """Set up one operating point and its reference (Radau rtol 1e-12 over ``horizons``, the
    shortest and longest run lengths [s]; default from FACTORS and the RK4 limit)."""
    model = make_model(params, "dynamic", drive)
    if drive == "speed":
        u = (0.0, load)          # constant prescribed speed
    else:
        u = (steady_state(params, omega, load)["screw_torque"], load)
    x_eq = model.initial_state(u, screw_speed=omega, carrier_ratio=None)
    tau = model.fastest_time_constant(x_eq, u)
    x0 = list(x_eq)
    x0[model.state_names.index("carrier_1_speed")] *= disturbance
    if horizons is None:
        lims = method_limits().values()
        horizons = (N_STEPS * FACTORS[0] * min(lims) * tau, N_STEPS * FACTORS[-1] * max(lims) * tau)
    ratios = []
    for t_run in horizons:
        ref = make_stepper("radau", model, rtol=1e-12, atol=1e-14)
        x, _ = ref.advance(0.0, x0, u, t_run)
        ratios.append(carrier_ratios(model, x, u))
    check = max(abs(a - b) for a, b in zip(*ratios))
    return OperatingPoint(drive, omega, load, model, u, x0, tau, jacobian_tau(model, x_eq, u),
                          ratios[0], check)


def run_fixed(op: OperatingPoint, method: str, h: float, n_steps: int = N_STEPS) -> tuple:
    """Advance n_steps fixed steps h [s]; (class, carrier-ratio error [-], growth [-])."""
    model, u = op.model, op.u
    st = make_stepper(method, model, **METHOD_OPTIONS[method])
    speeds = speed_indices(model)
    start = max(abs(op.x0[i]) for i in speeds)
    x = op.x0
    growth = 1.0
    try:
        for i in range(n_steps):
            x, _ = st.advance(i * h, x, u, h)
            g = max(abs(x[j]) for j in speeds) / start
            if not math.isfinite(g):
                return DIVERGED, math.nan, math.inf
            growth = max(growth, g)
            if growth > GROWTH_LIMIT:
                return DIVERGED, math.nan, growth
    except StepFailure:
        return DIVERGED, math.nan, math.inf
    err = max(abs(a - b) for a, b in zip(carrier_ratios(model, x, u), op.ref_ratios))
    return (CORRECT if err <= RATIO_TOL else WRONG), err, growth


def measured_limit(op: OperatingPoint, method: str, h_pred: float, scan: dict) -> tuple:
    """(measured limit factor h/h_pred, monotone?) from the scan ``{factor: class}``: the first
    factor that is not correct, bisected against the last correct one below it."""
    facs = sorted(scan)
    first_bad = next((f for f in facs if scan[f] != CORRECT), None)
    if first_bad is None:
        return math.inf, True
    below = [f for f in facs if f < first_bad]
    if not below:
        return first_bad, True
    lo, hi = below[-1], first_bad
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        if run_fixed(op, method, mid * h_pred)[0] == CORRECT:
            lo = mid
        else:
            hi = mid
    monotone = all(scan[f] != CORRECT for f in facs if f > first_bad)
    return lo, monotone


def carrier_map(speeds=SPEEDS, loads=LOADS, drives=DRIVES, factors=FACTORS, verbose=True,
                disturbance: float = DISTURBANCE) -> dict:
    """Scan every (drive, ω, F, method); returns ``runs`` and ``boundaries`` (lists of dicts)."""
    say = print if verbose else (lambda *a, **k: None)
    limits = method_limits()
    say("real-axis stability limits from the stability polynomials: "
        + ", ".join(f"{METHOD_LABEL[m]} x* = {x:.6f}" for m, x in limits.items()))
    runs, bounds = [], []
    total = len(drives) * len(speeds) * len(loads)
    n = 0
    for drive in drives:
        for omega in speeds:
            for load in loads:
                n += 1
                op = operating_point(drive, omega, load, disturbance=disturbance)
                line = (f"[{n:3d}/{total}] {drive:6s} ω {omega:6.1f} rad/s  F {load:7.0f} N  "
                        f"τ {op.tau:.3e} s (eig {op.tau_eig:.3e}); ref check {op.ref_check:.1e}")
                for method, xstar in limits.items():
                    h_pred = xstar * op.tau
                    scan = {}
                    for f in factors:
                        cls, err, growth = run_fixed(op, method, f * h_pred)
                        scan[f] = cls
                        runs.append(dict(drive=drive, omega=omega, load=load, method=method,
                                         tau=op.tau, h_pred=h_pred, factor=f, h=f * h_pred,
                                         cls=cls, ratio_error=err, growth=growth))
                    f_meas, monotone = measured_limit(op, method, h_pred, scan)
                    bounds.append(dict(drive=drive, omega=omega, load=load, method=method,
                                       tau=op.tau, tau_eig=op.tau_eig, xstar=xstar, h_pred=h_pred,
                                       h_pred_eig=xstar * op.tau_eig, h_measured=f_meas * h_pred,
                                       ratio=f_meas, monotone=monotone, ref_check=op.ref_check,
                                       beyond={c: sum(1 for f in factors if f > f_meas and scan[f] == c)
                                               for c in (WRONG, DIVERGED)}))
                    line += f" | {method[:4]} measured/pred {f_meas:.3f}" + ("" if monotone else " (!)")
                say(line)
    return {"runs": runs, "boundaries": bounds, "limits": limits, "disturbance": disturbance}


def carrier_summary(result: dict) -> list[str]:
    """Lines: the measured/predicted ratio per drive and method (min … max)."""
    lines = []
    for drive in DRIVES:
        for method in result["limits"]:
            bs = [b for b in result["boundaries"] if b["drive"] == drive and b["method"] == method]
            if not bs:
                continue
            r = [b["ratio"] for b in bs]
            re = [b["h_measured"] / b["h_pred_eig"] for b in bs]
            wrong = sum(b["beyond"][WRONG] for b in bs)
            div = sum(b["beyond"][DIVERGED] for b in bs)
            lines.append(f"{drive:6s} {METHOD_LABEL[method]:34s} measured/predicted limit "
                         f"{min(r):.3f} … {max(r):.3f} (vs eigenvalue prediction {min(re):.3f} … "
                         f"{max(re):.3f}); beyond the limit: {wrong} bounded-but-wrong, {div} "
                         f"diverged runs; all monotone: {all(b['monotone'] for b in bs)}")
    return lines


def write_carrier_csv(result: dict, out: Path) -> None:
    """stability_carriers.csv (every run) and stability_carriers_boundaries.csv."""
    with open(out / "stability_carriers.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["drive", "screw_speed_rad_s", "load_N", "method", "tau_s", "h_pred_s",
                    "h_over_h_pred", "h_s", "class", "carrier_ratio_error", "growth"])
        for r in result["runs"]:
            w.writerow([r["drive"], f"{r['omega']:g}", f"{r['load']:g}", r["method"],
                        f"{r['tau']:.6e}", f"{r['h_pred']:.6e}", f"{r['factor']:g}",
                        f"{r['h']:.6e}", r["cls"], f"{r['ratio_error']:.3e}", f"{r['growth']:.4g}"])
    with open(out / "stability_carriers_boundaries.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["drive", "screw_speed_rad_s", "load_N", "method", "tau_s", "tau_eig_s",
                    "real_axis_limit", "h_pred_s", "h_pred_eig_s", "h_measured_s",
                    "measured_over_predicted", "monotone", "reference_check"])
        for b in result["boundaries"]:
            w.writerow([b["drive"], f"{b['omega']:g}", f"{b['load']:g}", b["method"],
                        f"{b['tau']:.6e}", f"{b['tau_eig']:.6e}", f"{b['xstar']:.6f}",
                        f"{b['h_pred']:.6e}", f"{b['h_pred_eig']:.6e}", f"{b['h_measured']:.6e}",
                        f"{b['ratio']:.4f}", int(b["monotone"]), f"{b['ref_check']:.1e}"])


def plot_carriers(result: dict, path: Path) -> None:
    """Per drive: the runs of each method over (τ, h) coloured by class, with the predicted
    limit h = x*·τ, and the measured/predicted ratio across screw speed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(result["limits"])
    fig, axes = plt.subplots(len(DRIVES), len(methods) + 1, figsize=(15, 8.5))
    for row, drive in enumerate(DRIVES):
        for col, method in enumerate(methods):
            ax = axes[row, col]
            rs = [r for r in result["runs"] if r["drive"] == drive and r["method"] == method]
            for cls, colour in CLASS_COLOUR.items():
                sel = [r for r in rs if r["cls"] == cls]
                ax.scatter([r["tau"] for r in sel], [r["h"] for r in sel], s=9, color=colour,
                           label=cls)
            taus = np.array(sorted({r["tau"] for r in rs}))
            if taus.size:
                xs = result["limits"][method]
                ax.plot(taus, xs * taus, "k-", lw=1, label=f"predicted h = {xs:.3f} τ")
                bs = [b for b in result["boundaries"] if b["drive"] == drive and b["method"] == method]
                ax.plot([b["tau"] for b in bs], [b["h_measured"] for b in bs], "kx", ms=6,
                        label="measured limit")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("fastest carrier time constant τ at the operating point [s]")
            ax.set_ylabel("fixed step h [s]")
            ax.set_title(f"{drive} drive — {METHOD_LABEL[method]}", fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper left")
        ax = axes[row, -1]
        for method, marker in zip(methods, "os"):
            for load in LOADS:
                bs = sorted((b for b in result["boundaries"] if b["drive"] == drive
                             and b["method"] == method and b["load"] == load), key=lambda b: b["omega"])
                if bs:
                    ax.plot([b["omega"] for b in bs], [b["ratio"] for b in bs], marker + "-",
                            ms=4, lw=0.8, label=f"{METHOD_LABEL[method][:14]}, F = {load / 1e3:g} kN")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_ylim(0.9, 1.05)
        ax.set_xlabel("screw speed ω [rad/s]")
        ax.set_ylabel("measured / predicted largest stable step")
        ax.set_title(f"{drive} drive: measured / predicted", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, ncol=2, loc="lower left")
    fig.suptitle("Stiff carriers: largest stable fixed step, predicted from the linearised carrier "
                 f"time constant vs measured ({N_STEPS} steps from a {(1 - result['disturbance']) * 100:g} % "
                 "disturbance; correct = "
                 f"carrier ratios within {RATIO_TOL:g} of Radau)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- 2. friction at zero speed ---------------------------------------------------------------

V_EPS = (1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)                   # m/s; 1e-4 is the default
REVERSAL = dict(screw_torque=5.0, load_force=5000.0, initial_screw_speed=30.0,
                initial_carrier_ratio=None, t_end=1.5e-3, output_interval=1e-5)
FRICTION_CONFIGS = (
    [("rk4", "substeps", n) for n in (1, 10, 100, 1000)]
    + [("explicit_adaptive", "rtol", r) for r in (1e-3, 1e-4, 1e-6, 1e-8)]
    + [("rosenbrock", "rtol", r) for r in (1e-3, 1e-4, 1e-6, 1e-8)]
    + [("radau", "rtol", 1e-6)])
FORCE_OUTPUTS = ("stage[1].contact_force", "stage[2].contact_force", "stage[1].normal_force",
                 "stage[2].normal_force", "stage[2].driven_torque", "stage[2].spline_friction",
                 "friction_power")
FRICTION_TOL = 1e-3            # correct: §5 error over the FMU's outputs at most this
CHATTER_MARGIN = 1.01          # chatter: total variation above this multiple of the reference's


def _outputs():
    return _load_sibling("step_cost").OUTPUTS


def reversal(params, stepper: str, knob: str, value: float) -> dict:
    """Simulate the reversal; the result dict of :func:`prsm_fmu.simulate`."""
    if knob == "substeps":
        return simulate(params, "dynamic", "torque", stepper=stepper,
                        stepper_options={"substeps": int(value)}, **REVERSAL)
    return simulate(params, "dynamic", "torque", stepper=stepper, rtol=value,
                    atol=value * (1e-2 if value <= 1e-11 else 1e-3), **REVERSAL)


def section5_errors(y: dict, ref: dict, outputs) -> dict[str, float]:
    """docs/accuracy.md §1, per output: max_t |y − y_ref| / max_t |y_ref|."""
    errs = {}
    for name in outputs:
        a, b = np.asarray(y[name]), np.asarray(ref[name])
        scale = float(np.max(np.abs(b))) or 1.0
        errs[name] = float(np.max(np.abs(a - b))) / scale
    return errs


def section5_error(y: dict, ref: dict, outputs) -> float:
    """docs/accuracy.md §1: the largest per-output error."""
    return max(section5_errors(y, ref, outputs).values())


def total_variation(v) -> float:
    """Σ |v_(i+1) − v_i| over the output grid."""
    return float(np.sum(np.abs(np.diff(np.asarray(v, float)))))


def classify_reversal(r: dict | None, ref: dict, failure: str = "") -> dict:
    """Class and measures of one reversal run against its reference."""
    if r is None:
        return dict(cls=DIVERGED, reason=failure or "StepFailure", error=math.nan, tv_ratio=math.nan,
                    final_speed=math.nan)
    outs = _outputs()
    if not all(np.all(np.isfinite(r[n])) for n in set(outs) | set(FORCE_OUTPUTS)):
        return dict(cls=DIVERGED, reason="NaN", error=math.nan, tv_ratio=math.nan,
                    final_speed=math.nan)
    err = section5_error(r, ref, outs)
    tv_ratio = max(total_variation(r[n]) / max(total_variation(ref[n]), 1e-300) for n in FORCE_OUTPUTS)
    chatter = any(total_variation(r[n]) > CHATTER_MARGIN * total_variation(ref[n])
                  + 1e-9 * float(np.max(np.abs(ref[n]))) for n in FORCE_OUTPUTS)
    stall = np.sign(r["screw_speed"][-1]) != np.sign(ref["screw_speed"][-1])
    if stall:
        cls, reason = WRONG, "stall"
    elif chatter:
        cls, reason = WRONG, "chatter"
    elif err > FRICTION_TOL:
        cls, reason = WRONG, "inaccurate"
    else:
        cls, reason = CORRECT, ""
    return dict(cls=cls, reason=reason, error=err, tv_ratio=tv_ratio,
                final_speed=float(r["screw_speed"][-1]))


def reversal_reference(params, rtol: float = 1e-12) -> dict:
    """Radau restarted on every communication step at ``rtol`` (atol rtol·1e-2)."""
    return reversal(params, "radau", "rtol", rtol)


def friction_map(v_eps=V_EPS, configs=FRICTION_CONFIGS, verbose=True) -> dict:
    """Run every (v_ε, configuration); returns ``runs`` and ``regularisation`` (lists of dicts)."""
    say = print if verbose else (lambda *a, **k: None)
    runs, regs = [], []
    refs = {}
    for ve in v_eps:
        p = LI2021.with_changes(slip_velocity_scale=ve)
        c0 = time.process_time()
        ref = reversal_reference(p, 1e-12)
        check = reversal_reference(p, 1e-11)
        refs[ve] = ref
        diff = section5_error(check, ref, _outputs())
        say(f"v_ε = {ve:g} m/s: reference reverses at "
            f"{ref['time'][int(np.argmax(ref['screw_speed'] < 0))] * 1e3:.2f} ms, ends at "
            f"{ref['screw_speed'][-1]:.4f} rad/s; check at rtol 1e-11 differs by {diff:.1e} "
            f"[{time.process_time() - c0:.1f} s]")
        regs.append(dict(v_eps=ve, reference_check=diff))
        for stepper, knob, value in configs:
            c0 = time.process_time()
            try:
                r = reversal(p, stepper, knob, value)
                res = classify_reversal(r, ref)
                rhs = int(r["rhs_calls"])
            except StepFailure as exc:
                res = classify_reversal(None, ref, "StepFailure: " + str(exc)[:80])
                rhs = 0
            cpu = time.process_time() - c0
            runs.append(dict(v_eps=ve, stepper=stepper, knob=knob, value=value, rhs_calls=rhs,
                             cpu=cpu, **res))
            say(f"    {stepper:18s} {knob} {value:<7g} {res['cls']:18s} {res['reason'][:40]:12s} "
                f"error {res['error']:.1e}  TV/TV_ref {res['tv_ratio']:.3f}  rhs {rhs}")
    smallest = refs[min(refs)]
    for reg in regs:
        errs = section5_errors(refs[reg["v_eps"]], smallest, _outputs())
        reg["worst_output"] = max(errs, key=errs.get)
        reg["model_error_vs_smallest"] = errs[reg["worst_output"]]
        reg["screw_speed_error"] = errs["screw_speed"]
        say(f"regularisation v_ε = {reg['v_eps']:g}: model error against v_ε = {min(refs):g}: "
            f"{reg['model_error_vs_smallest']:.1e} (in {reg['worst_output']}; screw speed "
            f"{reg['screw_speed_error']:.1e})")
    return {"runs": runs, "regularisation": regs}


def friction_summary(result: dict) -> list[str]:
    """Lines: per stepper configuration, the v_ε where it is correct."""
    lines = []
    for stepper, knob, value in FRICTION_CONFIGS:
        rs = [r for r in result["runs"] if (r["stepper"], r["knob"], r["value"]) == (stepper, knob, value)]
        if rs:
            lines.append(f"{stepper:18s} {knob} {value:<7g}: " + ", ".join(
                f"{r['v_eps']:g}:{r['cls'][:7]}{'/' + r['reason'][:7] if r['reason'] else ''}" for r in rs))
    return lines


def write_friction_csv(result: dict, path: Path) -> None:
    """stability_friction.csv: one row per run, then the regularisation's model error."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["v_eps_m_s", "stepper", "knob", "value", "class", "reason", "error",
                    "tv_over_tv_ref", "final_screw_speed", "rhs_calls", "cpu_s"])
        for r in result["runs"]:
            w.writerow([f"{r['v_eps']:g}", r["stepper"], r["knob"], f"{r['value']:g}", r["cls"],
                        r["reason"], f"{r['error']:.3e}", f"{r['tv_ratio']:.4f}",
                        f"{r['final_speed']:.6g}", r["rhs_calls"], f"{r['cpu']:.3f}"])
        for g in result["regularisation"]:
            w.writerow([f"{g['v_eps']:g}", "reference", "model error vs smallest v_eps", "", "",
                        f"worst output {g['worst_output']}; screw_speed {g['screw_speed_error']:.3e}",
                        f"{g['model_error_vs_smallest']:.3e}", "", "", "", ""])


def plot_friction(result: dict, path: Path) -> None:
    """Grid of classes: rows = stepper configurations, columns = v_ε; errors written in."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    v_eps = sorted({r["v_eps"] for r in result["runs"]})
    cfgs = []
    for r in result["runs"]:
        key = (r["stepper"], r["knob"], r["value"])
        if key not in cfgs:
            cfgs.append(key)
    fig, ax = plt.subplots(figsize=(12, 0.42 * len(cfgs) + 2.4))
    for i, cfg in enumerate(cfgs):
        for j, ve in enumerate(v_eps):
            r = next((r for r in result["runs"]
                      if (r["stepper"], r["knob"], r["value"]) == cfg and r["v_eps"] == ve), None)
            if r is None:
                continue
            ax.add_patch(plt.Rectangle((j, i), 1, 1, color=CLASS_COLOUR[r["cls"]], alpha=0.75))
            txt = ("diverged\n" + r["reason"].split(":")[0]) if r["cls"] == DIVERGED else f"{r['error']:.0e}"
            if r["reason"] in ("chatter", "stall"):
                txt += f"\n{r['reason']} TV×{r['tv_ratio']:.2f}"
            ax.text(j + 0.5, i + 0.5, txt, ha="center", va="center", fontsize=6.5)
    row = len(cfgs)
    for j, ve in enumerate(v_eps):
        g = next(g for g in result["regularisation"] if g["v_eps"] == ve)
        ax.add_patch(plt.Rectangle((j, row), 1, 1, color="0.85"))
        ax.text(j + 0.5, row + 0.5, f"{g['model_error_vs_smallest']:.0e} ({g['worst_output']})\n"
                f"screw speed {g['screw_speed_error']:.0e}", ha="center", va="center", fontsize=6)
    ax.set_xlim(0, len(v_eps))
    ax.set_ylim(row + 1, 0)
    ax.set_xticks([j + 0.5 for j in range(len(v_eps))])
    ax.set_xticklabels([f"{v:g}" + (" (default)" if v == LI2021.slip_velocity_scale else "")
                        for v in v_eps], fontsize=8)
    ax.set_yticks([i + 0.5 for i in range(row + 1)])
    ax.set_yticklabels([f"{s} {'×' if k == 'substeps' else 'rtol '}{v:g}" for s, k, v in cfgs]
                       + ["regularisation's own error\n(reference vs smallest v_ε)"], fontsize=8)
    ax.set_xlabel("friction regularisation scale v_ε = slip_velocity_scale [m/s]")
    ax.legend(handles=[Patch(color=c, alpha=0.75, label=k) for k, c in CLASS_COLOUR.items()],
              loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title("Reversal through zero speed (torque 5 N·m vs 5 kN from 30 rad/s, 1.5 ms, "
                 "communication step 10 µs):\ncell = §5 error against Radau rtol 1e-12 on the same "
                 f"v_ε; correct: no chatter (TV ≤ {CHATTER_MARGIN}× ref), reverses, error ≤ {FRICTION_TOL:g}",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    """Run the maps, print the findings, write CSV and PNG files."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("carriers", "friction", "all"), default="all")
    ap.add_argument("--quick", action="store_true", help="fewer operating points and v_ε")
    ap.add_argument("--out", type=Path, default=FIGURES, help="output directory (docs/figures)")
    ap.add_argument("--disturbance", type=float, default=1.0 - DISTURBANCE,
                    help="relative disturbance of carrier 1 at the start (default %(default)g)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.part in ("carriers", "all"):
        c0 = time.time()
        print("== stiff carriers")
        kw = dict(speeds=(3.0, 100.0), loads=(1000.0, 10000.0)) if args.quick else {}
        res = carrier_map(disturbance=1.0 - args.disturbance, **kw)
        for line in carrier_summary(res):
            print(line)
        write_carrier_csv(res, args.out)
        plot_carriers(res, args.out / "stability_carriers.png")
        print(f"wrote stability_carriers.csv, stability_carriers_boundaries.csv, "
              f"stability_carriers.png [{time.time() - c0:.0f} s]")
    if args.part in ("friction", "all"):
        c0 = time.time()
        print("== friction at zero speed")
        kw = dict(v_eps=(1e-6, 1e-4, 1e-2)) if args.quick else {}
        res = friction_map(**kw)
        for line in friction_summary(res):
            print(line)
        write_friction_csv(res, args.out / "stability_friction.csv")
        plot_friction(res, args.out / "stability_friction.png")
        print(f"wrote stability_friction.csv, stability_friction.png [{time.time() - c0:.0f} s]")


if __name__ == "__main__":
    main()
