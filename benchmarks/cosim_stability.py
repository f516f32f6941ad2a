"""Co-simulation stability map of the actuator loop: the largest stable communication step,
predicted and measured, for Jacobi / Gauss–Seidel and extrapolation orders 0 / 1, across the
load stiffness.

Operating point (``system_models.coupling_analysis.stability_scene``): speed mode at
ω0 = 50 rad/s against a spring k whose anchor moves with the rod's nominal motion (so the steady
state is stationary whatever k), preload 1 kN, damper 1000 N·s/m (the default load), and a 100 N
step of the external force at 2 ms that excites the loop.  The PRSM is the plain Python block at
the quasi-static fidelity (exactly linear outside the friction band), the master takes plain
macro steps (no retry).

For every stiffness k in ``STIFFNESSES`` and scheme (order, extrapolation):

* **Predicted** boundary h*: ``coupling_analysis.predicted_boundary`` — the largest h at which
  the spectral radius of the linearised loop's macro-step map (over the period of the
  controller's sample pattern) is below 1, written from the blocks' physics and the master's
  scheme, not from the blocks' code.  The least stable mode just above h* is labelled by where
  its energy sits: ``spring`` (the load's spring and the rod mass) or ``controller/motor``.
* **Measured**: the real nonlinear loop at h = f·h* for f in ``FACTORS`` (each h rounded to the
  rational multiple of the controller's sample time the analysis represents exactly,
  ``coupling_analysis.snap_step``); then (1) the first change from correct to not correct,
  bisected ``BISECTIONS`` times (geometric mean): the largest *correct* h, the measured boundary;
  (2) the first change from stable to unstable (:func:`unstable`: stopped, a limit reached, or a
  measured growth per step ≥ 1), bisected the same way: the largest *stable* h.  Every run is
  written with its class, its error, the predicted spectral radius at its h and its measured
  growth per step (:func:`measured_growth`), which the analysis predicts.

Classification of a run against the reference (the same loop, Gauss–Seidel with first-order
extrapolation at h = ``H_REF`` = 10 µs, far below every boundary; its own spectral radius is
printed):

* **diverged**: the master stopped (``CoSimulationError``: the motor trips at 1.5× its current
  limit, a non-finite value) or an output is not finite;
* **correct**: over the last ``FINAL_WINDOW`` of the run, every output in ``OUTPUTS`` (screw
  speed, q current, load force) is within ``TOL`` = 2 % of the disturbance response's amplitude
  (the reference's largest deviation from its final value) of the reference's final value.
  Why 2 %: a stable run has forgotten the disturbance by then (at 0.8 h* the slowest mode, the
  spring mode at k = 1e9, has decayed to ≈ 0.5 %), and the point on the line of steady states
  where a stable run settles (speed mode holds the speed at any spring compression, see
  coupling_analysis) differs from the reference's by ≤ 0.6 % of the amplitude (at k = 1e9); an
  unstable run has grown by orders of magnitude.  A run still decaying at ``T_END`` (linear
  range, measured growth < 1) is run again, long enough to settle at its measured rate, at most
  ``T_MAX``, and judged there (:func:`judge`): so a stable but slow run is not called wrong for
  being slow, except within ≈ 2 % of a lightly damped boundary.
* **bounded-but-wrong**: finite to the end but not correct: an unstable loop held in a limit
  cycle by the current or voltage limit, one still growing at the end, one stable but not
  settled within ``T_MAX``, or one settled on a wrong state (the reason is written).

Writes ``docs/figures/cosim_stability.csv`` (every run), ``cosim_stability_boundaries.csv``
(predicted vs measured boundaries) and ``cosim_stability.png``; prints the table, the
measured/predicted ratios and the pointwise agreement of measured and predicted stability.

Run: ``python benchmarks/cosim_stability.py`` (about 5 min on 2 cores; ``--quick``: two
stiffnesses, two bisections, no re-runs, ≈ 25 s; ``--out DIR``).  docs/ema.md §9,
"Co-simulation stability", explains the map.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(ROOT), str(HERE)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import stability_maps  # noqa: E402  (benchmarks/: the classes and their colours)

from system_models import coupling_analysis as ca  # noqa: E402
from system_models.master import CoSimulationError  # noqa: E402

CORRECT, WRONG, DIVERGED = stability_maps.CORRECT, stability_maps.WRONG, stability_maps.DIVERGED
CLASS_COLOUR = stability_maps.CLASS_COLOUR
FIGURES = ROOT / "docs" / "figures"

STIFFNESSES = (1e5, 3e5, 1e6, 3e6, 1e7, 3e7, 1e8, 3e8, 1e9)      # N/m
SCHEMES = (("jacobi", 0), ("jacobi", 1), ("gauss-seidel", 0), ("gauss-seidel", 1))
FACTORS = (0.5, 0.8, 1.0, 1.25, 2.0)        # h / h*_predicted of the classification grid
BISECTIONS = 6
T_END = 0.4                 # run length [s]
T_MAX = 3.2                 # longest run: a run still decaying at T_END is run up to this [s]
H_REF = 1e-5                # reference communication step [s]
REF_SCHEME = ("gauss-seidel", 1)
OUTPUTS = ("prsm.screw_speed", "motor.i_q", "load.force")
FINAL_WINDOW = 0.1          # the last 10 % of the run
TOL = 0.02                  # correct: within 2 % of the disturbance amplitude (docstring)
GROWTH_WINDOWS = ((0.5, 0.75), (0.75, 1.0))   # fractions of the run (measured_growth)
FLOOR = 1e-6                # settled: oscillation below this fraction of the amplitude

SCHEME_LABEL = {s: f"{'Jacobi' if s[0] == 'jacobi' else 'Gauss–Seidel'}, extrapolation {s[1]}"
                for s in SCHEMES}
SCHEME_COLOUR = {SCHEMES[0]: "tab:blue", SCHEMES[1]: "tab:cyan", SCHEMES[2]: "tab:purple",
                 SCHEMES[3]: "tab:pink"}


# ---- runs -----------------------------------------------------------------------------------
def run_loop(stiffness: float, h: float, order: str, extrapolation: int,
             t_end: float = T_END):
    """Run the real loop at the operating point for ≈ ``t_end`` [s] (a whole number of steps).

    Returns ``(result, reason, limited)``: the :class:`~system_models.master.Result` (None if
    the master stopped), the master's message, and whether the loop reached a limit (the speed
    PI's output at the current limit, or the inverter's voltage on its limit circle), i.e. left
    the linear range.
    """
    n = max(1, round(t_end / h))
    system = ca.build_stability_system(stiffness, h, order, extrapolation, t_end=n * h)
    try:
        res = system.run()
    except CoSimulationError as exc:
        return None, f"stopped at t = {exc.time:.4g} s: {exc.reason.split(':')[0]}", True
    i_lim = system.controller.current_limit
    v_lim = system.motor.voltage_limit
    v = np.hypot(res["motor.v_d"], res["motor.v_q"])
    limited = bool(np.max(np.abs(res["controller.i_q_ref"])) >= (1.0 - 1e-9) * i_lim
                   or np.max(v) >= (1.0 - 1e-9) * v_lim)
    return res, "", limited


def reference(stiffness: float, t_end: float = T_END):
    """The reference run (``REF_SCHEME`` at ``H_REF``); raises if it does not complete or
    leaves the linear range."""
    res, reason, limited = run_loop(stiffness, H_REF, *REF_SCHEME, t_end=t_end)
    if res is None or limited:
        raise RuntimeError(f"the reference run at k = {stiffness:g} N/m failed: "
                           f"{reason or 'a limit was reached'}")
    return res


def classify_run(res, reason: str, limited: bool, ref) -> dict:
    """Class, error and measured growth of a run against the reference (module docstring).

    ``error``: max over ``OUTPUTS`` and the final window of |y − y_ref(end)| / amplitude, the
    amplitude being max_t |y_ref − y_ref(end)| (NaN for a run that stopped).  ``growth``:
    :func:`measured_growth` (inf for a run that stopped).  ``limited``: the run reached the
    current or voltage limit.
    """
    if res is None:
        return {"cls": DIVERGED, "error": math.nan, "growth": math.inf, "limited": True,
                "reason": reason}
    err = 0.0
    for name in OUTPUTS:
        y, yr = np.asarray(res[name]), np.asarray(ref[name])
        if not np.all(np.isfinite(y)):
            return {"cls": DIVERGED, "error": math.nan, "growth": math.inf, "limited": True,
                    "reason": f"{name} not finite"}
        final = yr[-1]
        amplitude = float(np.max(np.abs(yr - final)))
        window = res.time >= res.time[-1] * (1.0 - FINAL_WINDOW)
        err = max(err, float(np.max(np.abs(y[window] - final))) / amplitude)
    growth = measured_growth(res, ref)
    out = {"error": err, "growth": growth, "limited": limited}
    if err <= TOL:
        return {"cls": CORRECT, "reason": "", **out}
    if limited:
        why = "grew into the current or voltage limit (limit cycle)"
    elif growth >= 1.0:
        why = "grows"
    elif math.isnan(growth):
        why = "settled on a wrong state"
    else:
        why = f"decaying but not settled by {res.time[-1]:.3g} s"
    return {"cls": WRONG, "reason": why, **out}


def judge(stiffness: float, h: float, order: str, extrapolation: int, ref,
          t_end: float = T_END, t_max: float = T_MAX) -> dict:
    """Run and classify; a run still decaying at ``t_end`` (linear range, measured growth < 1)
    is run again, long enough to settle at its measured decay rate (at most ``t_max``), and
    classified there.

    Returns the :func:`classify_run` dict with ``t_run``, the run's length [s].
    """
    out = classify_run(*run_loop(stiffness, h, order, extrapolation, t_end), ref)
    t_run = max(1, round(t_end / h)) * h
    g = out["growth"]
    if out["cls"] == WRONG and not out["limited"] and 0.0 < g < 1.0 and t_end < t_max:
        sigma = -math.log(g) / h                               # decay rate [1/s]
        t_new = min(t_max, t_run + 1.2 * math.log(out["error"] / (0.5 * TOL)) / sigma
                    / (1.0 - FINAL_WINDOW))
        out = classify_run(*run_loop(stiffness, h, order, extrapolation, t_new), ref)
        t_run = max(1, round(t_new / h)) * h
    out["t_run"] = t_run
    return out


def measured_growth(res, ref) -> float:
    """Growth factor per macro step of what is left of the disturbance at the end of a run.

    The size of the oscillation in a window: Σ over ``OUTPUTS`` of the variance about the
    window's mean of y / A (A: the reference's disturbance amplitude of that output), so a
    constant offset (where a stable run settles on the line of steady states) does not count
    and the outputs' different phases average out a slow oscillation.  With s1, s2 that size in
    the two ``GROWTH_WINDOWS`` (fractions of the run) and n the steps between their centres:
    (s2/s1)^(1/2n).  NaN if both are below ``FLOOR`` (settled to rounding).  The linear analysis
    predicts this number: the spectral radius of the macro-step map
    (:func:`coupling_analysis.spectral_radius`).
    """
    (a1, b1), (a2, b2) = GROWTH_WINDOWS
    t = res.time
    te = t[-1]
    w1, w2 = (t >= a1 * te) & (t <= b1 * te), (t >= a2 * te) & (t <= b2 * te)
    steps = (0.5 * (a2 + b2) - 0.5 * (a1 + b1)) * te / (t[1] - t[0])
    s1 = s2 = 0.0
    for name in OUTPUTS:
        yr = np.asarray(ref[name])
        y = np.asarray(res[name]) / float(np.max(np.abs(yr - yr[-1])))
        s1 += float(np.var(y[w1]))
        s2 += float(np.var(y[w2]))
    if max(s1, s2) <= FLOOR ** 2:
        return math.nan
    return (s2 / s1) ** (0.5 / steps) if s1 > 0.0 else math.inf


def unstable(run: dict) -> bool:
    """Grows: stopped, reached a limit (a stable linear loop never does after a 100 N
    disturbance), or a measured growth ≥ 1."""
    return run["cls"] == DIVERGED or run["limited"] or run["growth"] >= 1.0


def scheme_boundary(stiffness: float, order: str, extrapolation: int, loop: ca.LinearLoop,
                    ref, factors=FACTORS, bisections: int = BISECTIONS, t_end: float = T_END,
                    t_max: float = T_MAX) -> tuple[list[dict], dict]:
    """Predicted and measured boundaries of one scheme at one stiffness; (runs, boundary).

    Measured: the largest correct h (bisection on the class from the first change in the
    scan over ``factors``), and the stability boundary (bisection on :func:`unstable`, from
    the runs made so far).
    """
    h_pred = ca.predicted_boundary(loop, order, extrapolation)
    mode = ca.critical_mode(loop, 1.02 * h_pred, order, extrapolation)
    runs: list[dict] = []
    done: dict[float, dict] = {}

    def run(f: float) -> dict:
        h = ca.snap_step(f * h_pred, loop.Ts)
        if h in done:                   # two factors rounded to the same rational step
            return done[h]
        c0 = time.process_time()
        out = judge(stiffness, h, order, extrapolation, ref, t_end, t_max)
        r = dict(order=order, extrapolation=extrapolation, stiffness=stiffness, h=h,
                 factor=h / h_pred, h_pred=h_pred,
                 rho=ca.spectral_radius(loop, h, order, extrapolation),
                 cpu=time.process_time() - c0, **out)
        runs.append(r)
        done[h] = r
        return r

    def bisect(lo: float, hi: float, good) -> float:
        for _ in range(bisections):
            mid = math.sqrt(lo * hi)
            if good(run(mid)):
                lo = mid
            else:
                hi = mid
        return lo

    scan = {f: run(f)["cls"] for f in factors}
    while scan[min(scan)] != CORRECT and min(scan) > 0.05:        # extend below if needed
        f = min(scan) / 2.0
        scan[f] = run(f)["cls"]
    while all(c == CORRECT for c in scan.values()) and max(scan) < 50.0:  # ... or above
        f = max(scan) * 2.0
        scan[f] = run(f)["cls"]
    facs = sorted(scan)
    first_bad = next((f for f in facs if scan[f] != CORRECT), None)
    if first_bad is None or first_bad == facs[0]:
        measured = math.inf if first_bad is None else math.nan
        monotone = True
    else:
        lo = max(f for f in facs if f < first_bad)
        measured = bisect(lo, first_bad, lambda r: r["cls"] == CORRECT) * h_pred
        monotone = all(scan[f] != CORRECT for f in facs if f > first_bad)
    # stability: the first unstable run above the largest stable one below it
    by_f = sorted(runs, key=lambda r: r["factor"])
    first_unstable = next((r["factor"] for r in by_f if unstable(r)), None)
    stable_below = [r["factor"] for r in by_f
                    if first_unstable is not None and r["factor"] < first_unstable]
    if first_unstable is None or not stable_below:
        h_stable = math.inf if first_unstable is None else math.nan
    else:
        h_stable = bisect(max(stable_below), first_unstable, lambda r: not unstable(r)) * h_pred
    regime = "spring" if mode["mechanical_share"] > 0.5 else "controller/motor"
    bound = dict(order=order, extrapolation=extrapolation, stiffness=stiffness, h_pred=h_pred,
                 h_measured=measured, ratio=measured / h_pred, h_stable=h_stable,
                 ratio_stable=h_stable / h_pred, monotone=monotone, regime=regime,
                 mechanical_share=mode["mechanical_share"],
                 rho_at_0_8=ca.spectral_radius(loop, 0.8 * h_pred, order, extrapolation),
                 rho_at_1_25=ca.spectral_radius(loop, 1.25 * h_pred, order, extrapolation),
                 beyond={c: sum(1 for r in runs if r["h"] > measured and r["cls"] == c)
                         for c in (WRONG, DIVERGED)},
                 agree=agreement(runs))
    return runs, bound


def agreement(runs: list[dict], margin: float = 1e-4) -> tuple[int, int]:
    """(runs whose measured stability is the predicted one, runs compared): predicted
    ρ < 1 ⇔ not :func:`unstable`, leaving out runs with |ρ − 1| < ``margin`` (marginal)."""
    cmp = [r for r in runs if abs(r["rho"] - 1.0) >= margin]
    return sum(1 for r in cmp if (r["rho"] >= 1.0) == unstable(r)), len(cmp)


def cosim_map(stiffnesses=STIFFNESSES, schemes=SCHEMES, factors=FACTORS,
              bisections: int = BISECTIONS, t_end: float = T_END, t_max: float = T_MAX,
              verbose: bool = True) -> dict:
    """Every (stiffness, scheme): runs and boundaries (lists of dicts)."""
    say = print if verbose else (lambda *a, **k: None)
    runs, bounds, refs = [], [], []
    for k in stiffnesses:
        c0 = time.process_time()
        ref = reference(k, t_end)
        loop = ca.linear_loop(ca.build_stability_system(k, H_REF, *REF_SCHEME, t_end=t_end))
        rho_ref = ca.spectral_radius(loop, H_REF, *REF_SCHEME)
        amp = {n: float(np.max(np.abs(ref[n] - ref[n][-1]))) for n in OUTPUTS}
        refs.append(dict(stiffness=k, rho_ref=rho_ref, amplitude=amp))
        say(f"k = {k:8.1e} N/m: reference ({REF_SCHEME[0]}, {REF_SCHEME[1]}, h = {H_REF:g} s) "
            f"ρ = {rho_ref:.6f}; disturbance amplitude ω {amp[OUTPUTS[0]]:.3g} rad/s, "
            f"i_q {amp[OUTPUTS[1]]:.3g} A, F {amp[OUTPUTS[2]]:.3g} N "
            f"[{time.process_time() - c0:.1f} s]")
        for order, ex in schemes:
            c0 = time.process_time()
            rs, b = scheme_boundary(k, order, ex, loop, ref, factors, bisections, t_end, t_max)
            runs += rs
            bounds.append(b)
            say(f"    {SCHEME_LABEL[(order, ex)]:32s} predicted {b['h_pred']:.4e} s "
                f"({b['regime']}); measured: correct up to "
                f"{b['h_measured']:.4e} s ({b['ratio']:.3f}){'' if b['monotone'] else ' (!)'}, "
                f"stable up to {b['h_stable']:.4e} s ({b['ratio_stable']:.3f})  "
                f"[{len(rs)} runs, {time.process_time() - c0:.1f} s]")
    return {"runs": runs, "boundaries": bounds, "references": refs}


def summary(result: dict) -> list[str]:
    """The table of boundaries and the measured/predicted ratios per scheme."""
    lines = [("largest stable communication step [µs]: predicted (ρ = 1) / measured correct / "
              "measured stable; regime of the least stable mode"),
             f"{'k [N/m]':>9s} " + " ".join(f"{SCHEME_LABEL[s]:>37s}" for s in SCHEMES)]
    ks = sorted({b["stiffness"] for b in result["boundaries"]})
    for k in ks:
        cells = []
        for s in SCHEMES:
            b = next((b for b in result["boundaries"] if b["stiffness"] == k
                      and (b["order"], b["extrapolation"]) == s), None)
            cells.append(f"{'':37s}" if b is None else
                         f"{b['h_pred'] * 1e6:8.1f} {b['h_measured'] * 1e6:8.1f} "
                         f"{b['h_stable'] * 1e6:8.1f} {b['regime'][:10]:>10s}")
        lines.append(f"{k:9.1e} " + " ".join(cells))
    for s in SCHEMES:
        bs = [b for b in result["boundaries"] if (b["order"], b["extrapolation"]) == s]
        if bs:
            r = [b["ratio"] for b in bs]
            rs = [b["ratio_stable"] for b in bs]
            wrong = sum(b["beyond"][WRONG] for b in bs)
            div = sum(b["beyond"][DIVERGED] for b in bs)
            lines.append(f"{SCHEME_LABEL[s]}: measured/predicted: correct {min(r):.3f} … "
                         f"{max(r):.3f}, stable {min(rs):.3f} … {max(rs):.3f}; runs beyond the "
                         f"correct boundary: {wrong} bounded-but-wrong, {div} diverged")
    ok, n = agreement(result["runs"])
    lines.append(f"pointwise: {ok} of {n} runs are stable or unstable as their predicted spectral "
                 "radius says (|ρ − 1| ≥ 1e-4)")
    lin = [r for r in result["runs"] if math.isfinite(r["growth"]) and r["error"] <= 1.0
           and not r["limited"] and abs(math.log(r["rho"])) > 1e-4]
    if lin:
        dev = [abs(math.log(r["growth"]) / math.log(r["rho"]) - 1.0) for r in lin]
        lines.append(f"measured growth per step vs predicted ρ, {len(dev)} runs still near the "
                     f"operating point at the end (error ≤ 1, |ln ρ| > 1e-4): "
                     f"|ln(growth)/ln(ρ) − 1| median {np.median(dev):.3f}, "
                     f"90 % below {np.percentile(dev, 90):.3f}")
    return lines


def write_csv(result: dict, out: Path) -> None:
    """cosim_stability.csv (every run) and cosim_stability_boundaries.csv."""
    with open(out / "cosim_stability.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["order", "extrapolation", "stiffness_N_m", "h_s", "h_over_h_pred", "class",
                    "error", "predicted_spectral_radius", "measured_growth_per_step", "reason",
                    "run_length_s", "cpu_s"])
        for r in result["runs"]:
            w.writerow([r["order"], r["extrapolation"], f"{r['stiffness']:g}", f"{r['h']:.6e}",
                        f"{r['factor']:.5f}", r["cls"], f"{r['error']:.3e}", f"{r['rho']:.6f}",
                        f"{r['growth']:.6f}", r["reason"], f"{r['t_run']:.4g}", f"{r['cpu']:.3f}"])
    with open(out / "cosim_stability_boundaries.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["order", "extrapolation", "stiffness_N_m", "h_predicted_s",
                    "h_measured_correct_s", "measured_correct_over_predicted",
                    "h_measured_stable_s", "measured_stable_over_predicted", "monotone", "regime",
                    "critical_mode_mechanical_energy_share",
                    "rho_at_0.8_h_pred", "rho_at_1.25_h_pred", "runs_beyond_bounded_but_wrong",
                    "runs_beyond_diverged", "runs_agreeing_with_prediction", "runs_compared"])
        for b in result["boundaries"]:
            w.writerow([b["order"], b["extrapolation"], f"{b['stiffness']:g}",
                        f"{b['h_pred']:.6e}", f"{b['h_measured']:.6e}", f"{b['ratio']:.4f}",
                        f"{b['h_stable']:.6e}", f"{b['ratio_stable']:.4f}", b["monotone"],
                        b["regime"], f"{b['mechanical_share']:.3f}",
                        f"{b['rho_at_0_8']:.6f}", f"{b['rho_at_1_25']:.6f}", b["beyond"][WRONG],
                        b["beyond"][DIVERGED], *b["agree"]])


def predicted_lines(stiffnesses, schemes=SCHEMES) -> dict:
    """Predicted boundary on a (denser) stiffness grid, per scheme: {scheme: [h*]}."""
    out = {}
    for s in schemes:
        out[s] = [ca.predicted_boundary(ca.linear_loop(ca.build_stability_system(
            k, H_REF, *REF_SCHEME)), *s) for k in stiffnesses]
    return out


def plot(result: dict, lines: dict, k_dense, path: Path) -> None:
    """h vs stiffness per scheme (runs coloured by class, predicted line, measured boundary),
    all predicted lines together, and the measured/predicted ratio."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(16, 9.5))
    panels = {SCHEMES[0]: axes[0, 0], SCHEMES[1]: axes[0, 1], SCHEMES[2]: axes[1, 0],
              SCHEMES[3]: axes[1, 1]}
    for s, ax in panels.items():
        rs = [r for r in result["runs"] if (r["order"], r["extrapolation"]) == s]
        for cls, colour in CLASS_COLOUR.items():
            sel = [r for r in rs if r["cls"] == cls]
            ax.scatter([r["stiffness"] for r in sel], [r["h"] for r in sel], s=14, color=colour,
                       label=cls, zorder=3)
        ax.plot(k_dense, lines[s], "k-", lw=1.2, label="predicted boundary (ρ = 1)")
        bs = [b for b in result["boundaries"] if (b["order"], b["extrapolation"]) == s]
        ax.plot([b["stiffness"] for b in bs], [b["h_measured"] for b in bs], "kx", ms=8, mew=1.5,
                label="measured: largest correct h", zorder=4)
        ax.plot([b["stiffness"] for b in bs], [b["h_stable"] for b in bs], "k+", ms=10, mew=1.2,
                label="measured: largest stable h (growth < 1)", zorder=4)
        ax.set_title(SCHEME_LABEL[s], fontsize=10)
    ax = axes[0, 2]
    for s in SCHEMES:
        ax.plot(k_dense, lines[s], "-", color=SCHEME_COLOUR[s], lw=1.5, label=SCHEME_LABEL[s])
        bs = [b for b in result["boundaries"] if (b["order"], b["extrapolation"]) == s]
        ax.plot([b["stiffness"] for b in bs], [b["h_measured"] for b in bs], "x",
                color=SCHEME_COLOUR[s], ms=7)
    ax.set_title("all schemes: predicted (lines), measured largest correct h (×)", fontsize=10)
    for ax in list(panels.values()) + [axes[0, 2]]:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.axhline(1e-4, color="0.6", lw=0.8, ls="--")
        ax.set_xlabel("load stiffness k [N/m]")
        ax.set_ylabel("communication step h [s]")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7, loc="lower left")
    ax = axes[1, 2]
    for s in SCHEMES:
        bs = sorted((b for b in result["boundaries"] if (b["order"], b["extrapolation"]) == s),
                    key=lambda b: b["stiffness"])
        ax.plot([b["stiffness"] for b in bs], [b["ratio"] for b in bs], "x-",
                color=SCHEME_COLOUR[s], ms=6, label=SCHEME_LABEL[s] + ": correct")
        ax.plot([b["stiffness"] for b in bs], [b["ratio_stable"] for b in bs], "+--",
                color=SCHEME_COLOUR[s], ms=8, lw=0.8, label=SCHEME_LABEL[s] + ": stable")
    ax.axhline(1.0, color="k", lw=0.8)
    for f in (0.8, 1.25):
        ax.axhline(f, color="0.5", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set_ylim(0.7, 1.3)
    ax.set_xlabel("load stiffness k [N/m]")
    ax.set_ylabel("measured / predicted largest stable step")
    ax.set_title("measured / predicted", fontsize=10)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7)
    fig.suptitle("Actuator loop, co-simulation stability: speed mode 50 rad/s against a spring k "
                 "(moving anchor), preload 1 kN, damper 1000 N·s/m, 100 N force step\n"
                 f"correct = within {TOL:.0%} of the disturbance amplitude of the reference "
                 f"(Gauss–Seidel, extrapolation 1, h = {H_REF:g} s) over the last "
                 f"{FINAL_WINDOW:.0%} of the run ({T_END:g} s, up to {T_MAX:g} s if still "
                 "decaying); dashed: the controller's sample time", fontsize=9.5)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    """Run the map, print the table and ratios, write the CSV files and the PNG."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="two stiffnesses, fewer runs per boundary (< 1 min)")
    ap.add_argument("--out", type=Path, default=FIGURES, help="output directory (docs/figures)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    c0 = time.time()
    if args.quick:
        ks, k_dense = (1e6, 1e9), np.geomspace(1e5, 1e9, 9)
        res = cosim_map(ks, factors=(0.8, 1.25), bisections=2, t_max=T_END)
    else:
        k_dense = np.geomspace(1e5, 1e9, 25)
        res = cosim_map()
    for line in summary(res):
        print(line)
    lines = predicted_lines(k_dense)
    write_csv(res, args.out)
    plot(res, lines, k_dense, args.out / "cosim_stability.png")
    print(f"wrote cosim_stability.csv, cosim_stability_boundaries.csv, cosim_stability.png to "
          f"{args.out} [{time.time() - c0:.0f} s]")


if __name__ == "__main__":
    main()
