"""The ``prsm-fmu`` command line.

Subcommands::

    prsm-fmu startup [--preset seed000_two_stage] [--fidelity dynamic|auto|...]
                     [--tolerance 1e-8] [--speed 100] [--load 5000] [--t-end 1e-3]
                     [--interval 1e-6] [--out out]
    prsm-fmu steady  [--preset seed000_two_stage] [--speed 100] [--load 5000]
    prsm-fmu presets
    prsm-fmu sweep   STUDY.toml [--out DIR] [--workers N | --scheduler tcp://host:port |
                     --no-dask] [--backend fmu|model] [--fmu-dir DIR] [--rerun-all]
    prsm-fmu check   PRESET [--load N] [--length M] [--material NAME] [--safety-factor K]
                     [--stability-factor N] [--ends ENDS] [--teeth Z_R,Z_IG] [--set NAME=VALUE]
    prsm-fmu regress [--update] [--fmu PRSM2.fmu] [--baselines DIR|FMU] [--case NAME ...]
                     [--set NAME=VALUE] [--out DIR]

``startup`` runs the start-up scenario of seed 000 §3.1 (the screw speed stepped at t = 0 with
the carriers at rest, a constant load on the last nut), prints a table, the carriers' settling
times and the run's cost and energy balance, and writes ``startup.csv`` and ``startup.png``.
``steady`` prints the steady state found by root finding (:func:`prsm_fmu.steady_state`).
``sweep`` runs a parameter study (:mod:`prsm_fmu.sweep`, docs/sweeps.md) and ``check`` the
design checks of seed 001 (:mod:`prsm_fmu.design_checks`).  ``regress`` compares the built
FMU's outputs with the stored baselines (:mod:`prsm_fmu.regress`, docs/regression.md).
All quantities are SI (m, N, N·m, rad/s, s, W, J).

The helpers :func:`settling_time`, :func:`energy_balance_residual`, :func:`write_csv` and
:func:`plot_startup` are shared with :mod:`prsm_fmu.report`.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
from typing import Callable, Mapping, Sequence

import numpy as np

from . import presets as _presets
from .models import FIDELITIES
from .params import MECHANISM_FIELD_NAMES, MechanismParams
from .simulate import simulate
from .steady_state import steady_state
from .steppers import StepFailure

__all__ = ["main", "build_parser", "settling_time", "is_settled", "energy_balance_residual", "unit_of",
           "write_csv", "plot_startup", "startup_table"]

#: relative band of the settling time (1 % of the final value)
SETTLING_BAND = 0.01

#: steppers accepted by ``--stepper`` (see prsm_fmu.steppers)
STEPPERS = ("rk4", "explicit_adaptive", "rosenbrock", "radau")

# unit of each output, by full name or by the part after "stage[k]."
_UNITS = {
    "time": "s", "screw_speed": "rad/s", "screw_angle": "rad", "screw_acceleration": "rad/s^2",
    "screw_torque": "N·m", "rod_position": "m", "rod_velocity": "m/s", "load_force": "N",
    "contact_force": "N", "normal_force": "N", "driven_torque": "N·m", "spline_friction": "N",
    "carrier_speed": "rad/s", "carrier_speed_ratio": "-", "efficiency": "-",
    "friction_power": "W", "input_power": "W", "output_power": "W", "input_work": "J",
    "output_work": "J", "friction_work": "J", "kinetic_energy": "J", "rod_force": "N",
    "bearing_force": "N", "residual_norm": "-",
    "friction_power_coulomb": "W", "friction_power_viscous": "W",
    "friction_power_differential": "W", "friction_power_joints": "W",
    "screw_friction_torque": "N·m",
    "overall_efficiency": "-",
}


# ---------------------------------------------------------------------------------------------
# analysis helpers (also used by prsm_fmu.report)
# ---------------------------------------------------------------------------------------------
def unit_of(name: str) -> str:
    """SI unit of an output name, e.g. ``"stage[2].driven_torque"`` → ``"N·m"``.

    Parameters
    ----------
    name : str
        Output name of the vocabulary in README.md "Conventions" (``time`` included).

    Returns
    -------
    str
        The unit, ``"-"`` for dimensionless quantities, ``"?"`` if the name is not known.
    """
    base = name.split(".", 1)[1] if name.startswith("stage[") and "." in name else name
    return _UNITS.get(base, "?")


def settling_time(time: Sequence[float], value: Sequence[float],
                  band: float = SETTLING_BAND) -> float:
    """First time after which a signal stays within ``band`` of its final value.

    The final value is the last sample, ζ_f.  The settling time is the first t_s such that
    |ζ(t) − ζ_f| ≤ band·|ζ_f| for every sample t ≥ t_s; between the last sample outside the
    band and the next one it is interpolated linearly, so it is not quantised to the output
    grid.

    Parameters
    ----------
    time : sequence of float
        Sample times [s], increasing.
    value : sequence of float
        The signal at those times (e.g. a carrier speed ratio [-]).
    band : float
        Relative half-width of the band [-], default 0.01 (1 %).

    Returns
    -------
    float
        Settling time [s]; ``time[0]`` if the signal starts inside the band; NaN if the final
        value is 0 or not finite (the relative band is undefined).
    """
    t = np.asarray(time, dtype=float)
    z = np.asarray(value, dtype=float)
    z_f = z[-1]
    tol = band * abs(z_f)
    if not math.isfinite(z_f) or tol == 0.0:
        return math.nan
    excess = np.abs(z - z_f) - tol
    outside = np.nonzero(excess > 0.0)[0]
    if outside.size == 0:
        return float(t[0])
    i = int(outside[-1])          # < len - 1, because the last sample is inside the band
    e0, e1 = excess[i], excess[i + 1]
    frac = e0 / (e0 - e1) if e0 != e1 else 1.0
    return float(t[i] + frac * (t[i + 1] - t[i]))


def is_settled(time: Sequence[float], value: Sequence[float],
               band: float = SETTLING_BAND) -> bool:
    """Whether a signal has reached its final value within the run.

    True if it varies by at most a tenth of the settling band (0.1·band·|final value|) over
    the last 20 % of the run, so that the final sample is a fair stand-in for the steady value
    that :func:`settling_time` measures against.

    Parameters
    ----------
    time, value : sequence of float
        Sample times [s] and the signal, as for :func:`settling_time`.
    band : float
        Relative band [-].

    Returns
    -------
    bool
    """
    t = np.asarray(time, dtype=float)
    z = np.asarray(value, dtype=float)
    tail = z[t >= t[0] + 0.8 * (t[-1] - t[0])]
    if tail.size == 0 or not np.all(np.isfinite(tail)):
        return False
    return float(np.max(tail) - np.min(tail)) <= 0.1 * band * abs(z[-1])


def energy_balance_residual(res: Mapping[str, np.ndarray]) -> float:
    """Relative energy-balance residual |W_in − W_out − W_f − ΔT| / W_in at the end of a run.

    Parameters
    ----------
    res : mapping
        The result of :func:`prsm_fmu.simulate` (needs ``input_work``, ``output_work``,
        ``friction_work`` [J] and ``kinetic_energy`` [J]).

    Returns
    -------
    float
        The residual [-]; the absolute residual [J] if W_in = 0.
    """
    w_in = float(res["input_work"][-1])
    w_out = float(res["output_work"][-1])
    w_f = float(res["friction_work"][-1])
    d_t = float(res["kinetic_energy"][-1] - res["kinetic_energy"][0])
    err = abs(w_in - w_out - w_f - d_t)
    return err / abs(w_in) if w_in != 0.0 else err


def _output_columns(res: Mapping[str, np.ndarray]) -> list[str]:
    """Names of the time series in a simulate result (``time`` first, scalars left out)."""
    return [k for k, v in res.items() if isinstance(v, np.ndarray) and v.ndim == 1]


def write_csv(res: Mapping[str, np.ndarray], path: str) -> None:
    """Write every time series of a simulate result to a CSV file.

    The header names each column with its unit, e.g. ``time [s],screw_speed [rad/s],...``;
    the values are written with 12 significant digits.  UTF-8 (the unit ``N·m``).

    Parameters
    ----------
    res : mapping
        The result of :func:`prsm_fmu.simulate`.
    path : str
        Output file.
    """
    cols = _output_columns(res)
    data = np.column_stack([res[c] for c in cols])
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow([f"{c} [{unit_of(c)}]" for c in cols])
        for row in data:
            w.writerow([f"{v:.12g}" for v in row])


def _n_stages(res: Mapping[str, np.ndarray]) -> int:
    n = 0
    while f"stage[{n + 1}].carrier_speed_ratio" in res:
        n += 1
    return n


def plot_startup(runs: Sequence[tuple[str, Mapping[str, np.ndarray]]], path: str,
                 title: str = "") -> None:
    """Save a 2×2 figure like seed 000 Fig. 3 for one or more start-up runs.

    Panels: (a) carrier speed ratios ζ_k; (b) driven torques M_Sk [N·m]; (c) axial contact
    forces per roller F_Srzk [N]; (d) efficiency η [-] (left axis) and spline friction f_Sk
    [N] of stages k ≥ 2 (right axis, dotted), all against time in ms.  Stages are told apart
    by colour, runs by line style.  Uses matplotlib's Agg backend (no display needed).

    Parameters
    ----------
    runs : sequence of (label, result)
        Results of :func:`prsm_fmu.simulate`; the label ("" for none) names the run in the
        legends.
    path : str
        Output PNG file.
    title : str
        Figure title.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    styles = ["-", "--", "-.", ":"]
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.5), sharex=True)
    ax_z, ax_m, ax_f, ax_e = axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1]
    ax_h = ax_e.twinx()
    for j, (label, res) in enumerate(runs):
        ls = styles[j % len(styles)]
        suffix = f", {label}" if label else ""
        t_ms = np.asarray(res["time"]) * 1e3
        n = _n_stages(res)
        for k in range(1, n + 1):
            c = colours[(k - 1) % len(colours)]
            ax_z.plot(t_ms, res[f"stage[{k}].carrier_speed_ratio"], ls, color=c,
                      label=f"ζ_PS{k}{suffix}")
            ax_m.plot(t_ms, res[f"stage[{k}].driven_torque"], ls, color=c,
                      label=f"M_S{k}{suffix}")
            ax_f.plot(t_ms, res[f"stage[{k}].contact_force"], ls, color=c,
                      label=f"F_Srz{k}{suffix}")
            if k >= 2:
                ax_h.plot(t_ms, res[f"stage[{k}].spline_friction"], ls, color=c, alpha=0.8,
                          label=f"f_S{k}{suffix}")
        ax_e.plot(t_ms, res["efficiency"], ls, color="black", label=f"η{suffix}")
    ax_z.set_ylabel("carrier speed ratio ζ_PSk [-]")
    ax_z.set_title("(a) carrier speed ratios")
    ax_m.set_ylabel("driven torque M_Sk [N·m]")
    ax_m.set_title("(b) driven torques")
    ax_f.set_ylabel("axial contact force per roller F_Srzk [N]")
    ax_f.set_title("(c) screw–roller axial contact forces")
    ax_e.set_ylabel("efficiency η [-]")
    ax_h.set_ylabel("spline friction f_Sk [N]")
    ax_e.set_title("(d) efficiency (black) and spline friction (colour)")
    for ax in (ax_f, ax_e):
        ax.set_xlabel("time [ms]")
    for ax in (ax_z, ax_m, ax_f):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    ax_e.grid(True, alpha=0.3)
    h1, l1 = ax_e.get_legend_handles_labels()
    h2, l2 = ax_h.get_legend_handles_labels()
    ax_e.legend(h1 + h2, l1 + l2, fontsize=8, loc="center right")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _sample_indices(time: np.ndarray, n_rows: int = 11) -> list[int]:
    """Indices of the samples nearest to n_rows evenly spaced times over the run."""
    targets = np.linspace(time[0], time[-1], n_rows)
    idx = [int(np.argmin(np.abs(time - t))) for t in targets]
    return sorted(set(idx))


def startup_table(res: Mapping[str, np.ndarray], n_rows: int = 11) -> str:
    """The start-up run as a fixed-width text table at ~``n_rows`` evenly spaced times.

    Columns: time [ms], ζ_PSk [-], M_Sk [N·m], F_Srzk [N] for every stage k, f_Sk [N] for
    k ≥ 2 and η [-].
    """
    t = np.asarray(res["time"])
    n = _n_stages(res)
    cols: list[tuple[str, Callable[[int], float]]] = [("time [ms]", lambda i: t[i] * 1e3)]
    for k in range(1, n + 1):
        cols.append((f"ζ_PS{k} [-]", lambda i, k=k: res[f"stage[{k}].carrier_speed_ratio"][i]))
    for k in range(1, n + 1):
        cols.append((f"M_S{k} [N·m]", lambda i, k=k: res[f"stage[{k}].driven_torque"][i]))
    for k in range(1, n + 1):
        cols.append((f"F_Srz{k} [N]", lambda i, k=k: res[f"stage[{k}].contact_force"][i]))
    for k in range(2, n + 1):
        cols.append((f"f_S{k} [N]", lambda i, k=k: res[f"stage[{k}].spline_friction"][i]))
    cols.append(("η [-]", lambda i: res["efficiency"][i]))
    widths = [max(len(h), 10) for h, _ in cols]
    lines = ["  ".join(h.rjust(w) for (h, _), w in zip(cols, widths))]
    for i in _sample_indices(t, n_rows):
        cells = []
        for (h, f), w in zip(cols, widths):
            v = float(f(i))
            cells.append((f"{v:.4f}" if h.startswith(("time", "ζ", "η")) else f"{v:.2f}").rjust(w))
        lines.append("  ".join(cells))
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# argument types
# ---------------------------------------------------------------------------------------------
def _finite_float(text: str) -> float:
    """argparse type: a finite number."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is out of range: must be a finite number")
    return v


def _nonzero_float(text: str) -> float:
    """argparse type: a finite, non-zero number."""
    v = _finite_float(text)
    if v == 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is out of range: must be non-zero")
    return v


def _positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    v = _finite_float(text)
    if not v > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is out of range: must be > 0")
    return v


def _mechanism_names() -> list[str]:
    """Presets that are multi-stage PRSMs (MechanismParams), i.e. usable by the models."""
    return [n for n in _presets.names() if isinstance(_presets.load(n), MechanismParams)]


def _preset(text: str) -> MechanismParams:
    """argparse type: the name of a PRSM preset, loaded."""
    try:
        p = _presets.load(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not isinstance(p, MechanismParams):
        raise argparse.ArgumentTypeError(
            f"preset {text!r} is not a planetary roller screw mechanism the models can run: "
            f"must be one of {', '.join(_mechanism_names())}")
    return p


# ---------------------------------------------------------------------------------------------
# subcommands
# ---------------------------------------------------------------------------------------------
def cmd_startup(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run the seed 000 §3.1 start-up scenario; print a table; write CSV and PNG.

    The screw speed is stepped to ``args.speed`` [rad/s] at t = 0 with the carriers at rest
    (drive "speed") under a constant ``args.load`` [N] on the last nut, simulated to
    ``args.t_end`` [s] with outputs every ``args.interval`` [s].

    Returns
    -------
    int
        0 on success, 2 for inconsistent arguments (after ``parser.error``), 1 if the
        simulation fails.
    """
    n_steps = round(args.t_end / args.interval)
    if n_steps < 1 or abs(n_steps * args.interval - args.t_end) > 1e-9 * args.t_end:
        parser.error(f"argument --t-end: {args.t_end!r} s must be a whole multiple of "
                     f"--interval {args.interval!r} s")
    if n_steps > 10_000_000:
        parser.error(f"argument --interval: {args.interval!r} s gives {n_steps} output "
                     "intervals over --t-end; at most 10 000 000")
    params: MechanismParams = args.preset
    res = simulate(params, fidelity=args.fidelity, drive="speed", screw_speed=args.speed,
                   load_force=args.load, t_end=args.t_end, output_interval=args.interval,
                   stepper=args.stepper, rtol=args.tolerance, atol=1e-2 * args.tolerance)
    n = params.n_stages
    if args.fidelity == "auto":
        print(f"fidelity auto at tolerance {args.tolerance:g}: starts with "
              f"{res['auto_choice'].describe()}; switches along the run (step_fidelity)")
    print(f"start-up: preset {params.name}, fidelity {args.fidelity}, screw speed step to "
          f"{args.speed:g} rad/s at t = 0 (carriers at rest), load {args.load:g} N, "
          f"t_end {args.t_end:g} s, output interval {args.interval:g} s")
    print(f"µ_SR = {params.mu_screw_roller:g}, µ_SS = {params.mu_spline:g}, "
          f"µ_NS = {params.mu_nut_screw:g}")
    print()
    print(startup_table(res))
    print()
    t = res["time"]
    for k in range(1, n + 1):
        z = res[f"stage[{k}].carrier_speed_ratio"]
        ts = settling_time(t, z)
        note = ""
        if not is_settled(t, z):
            note = (" — NOT settled: ζ still drifts over the last 20 % of the run, so this "
                    "time is relative to an unfinished transient; lengthen --t-end")
        print(f"carrier {k}: settles (1 % band) at t = {ts * 1e3:.4f} ms, "
              f"ζ_PS{k} final = {z[-1]:.5f}{note}")
    print(f"efficiency: {res['efficiency'][0]:.4f} at t = 0, {res['efficiency'][-1]:.4f} at "
          f"t = {t[-1] * 1e3:g} ms")
    print(f"cost and accuracy: {res['rhs_calls']} rhs calls, {res['cpu_time']:.3f} s CPU, "
          f"energy-balance residual |W_in − W_out − W_f − ΔT| / W_in = "
          f"{energy_balance_residual(res):.2e}")
    os.makedirs(args.out, exist_ok=True)
    csv_path = os.path.join(args.out, "startup.csv")
    png_path = os.path.join(args.out, "startup.png")
    write_csv(res, csv_path)
    plot_startup([("", res)], png_path,
                 title=f"{params.name}: start-up to {args.speed:g} rad/s under "
                       f"{args.load:g} N ({args.fidelity}; µ_SR {params.mu_screw_roller:g}, "
                       f"µ_SS {params.mu_spline:g})")
    print(f"wrote {csv_path} and {png_path}")
    return 0


def cmd_steady(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Print the steady state (:func:`prsm_fmu.steady_state`) as a table of name, value, unit.

    Returns
    -------
    int
        0.
    """
    params: MechanismParams = args.preset
    ss = steady_state(params, screw_speed=args.speed, load_force=args.load)
    print(f"steady state: preset {params.name}, screw speed {args.speed:g} rad/s, "
          f"load {args.load:g} N")
    width = max(len(k) for k in ss)
    for k, v in ss.items():
        print(f"{k.ljust(width)}  {v:>16.8g}  {unit_of(k)}")
    return 0


def cmd_presets(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Print the preset names, one per line.

    Returns
    -------
    int
        0.
    """
    for name in _presets.names():
        print(name)
    return 0


def cmd_sweep(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run a parameter study; print the claims' verdicts and where the results are.

    Returns
    -------
    int
        0 if every point ran, 1 if some point failed (it is recorded in the table with its
        error), 2 for a bad study file or bad arguments.
    """
    from .sweep import StudyError, load_study, run_study

    if args.scheduler and (args.workers or args.no_dask):
        parser.error("argument --scheduler: not allowed with --workers or --no-dask")
    if args.workers is not None and args.no_dask:
        parser.error("argument --workers: not allowed with --no-dask")
    try:
        study = load_study(args.study, backend=args.backend)
    except (OSError, StudyError) as exc:
        parser.error(f"argument STUDY: {exc}")
    n_points = len(study.points())
    where = "this process" if args.no_dask else (
        f"the Dask cluster at {args.scheduler}" if args.scheduler else
        f"a local Dask cluster of {args.workers or os.cpu_count()} worker(s)")
    print(f"study {study.name}: {study.title}")
    print(f"{n_points} points ({', '.join(study.swept) or 'no swept parameter'}), preset "
          f"{study.preset}, backend {study.backend}, on {where}")
    try:
        res = run_study(study, args.out, executor="loop" if args.no_dask else "dask",
                        scheduler=args.scheduler, workers=args.workers, fmu_dir=args.fmu_dir,
                        resume=not args.rerun_all, figures=not args.no_figures,
                        progress=None if args.quiet else sys.stderr)
    except (ValueError, RuntimeError, FileNotFoundError) as exc:
        print(f"prsm-fmu: error: {exc}", file=sys.stderr)
        return 1
    n_ok = sum(1 for r in res.rows if r.get("status") == "ok")
    print(f"{n_ok} of {len(res.rows)} points ok ({res.skipped} from an earlier run), "
          f"{res.wall_time:.1f} s")
    if res.trends:
        print()
        width = max(len(t.trend.statement) for t in res.trends)
        for t in res.trends:
            print(f"{t.verdict:>13}  {t.trend.statement.ljust(width)}  {t.observed}")
    for r in res.failed:
        print(f"point {int(r['point'])} failed: {r.get('error', '')}")
    print()
    print(f"wrote {res.table_path}, {os.path.join(res.out_dir, 'report.md')}"
          + "".join(f", {f}" for f in res.figures))
    return 0 if not res.failed else 1


def _set_value(text: str) -> tuple[str, object]:
    """argparse type of ``--set NAME=VALUE``: a mechanism or stage parameter (SI)."""
    from .sweep.study import parameter_kind

    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE")
    try:
        kind = parameter_kind(name)
    except KeyError:
        kind = ""
    if kind not in ("mechanism", "stage"):
        raise argparse.ArgumentTypeError(
            f"{name!r} is not a mechanism or stage parameter ({', '.join(MECHANISM_FIELD_NAMES)}, "
            "stage[k].<field>, stage[k].pitch)")
    integer = name.endswith((".screw_starts", ".n_rollers", ".carriers", ".threads_per_roller"))
    try:
        v: object = int(value) if integer else _finite_float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name} = {value!r} is not an integer") from None
    return name, v


def _teeth(text: str) -> tuple[int, int]:
    """argparse type of ``--teeth Z_R,Z_IG``."""
    try:
        z_r, z_ig = (int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not two integers Z_R,Z_IG") from None
    if z_r < 1 or z_ig < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is out of range: teeth must be >= 1")
    return z_r, z_ig


def _fractions(text: str) -> tuple[float, ...]:
    """argparse type of ``--sections F1,F2,...``."""
    try:
        values = tuple(_positive_float(x) for x in text.split(","))
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    return values


def cmd_check(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Print the seed 001 design checks of a preset (optionally modified with ``--set``).

    Returns
    -------
    int
        0 if no check fails, 1 if a condition is violated, 2 for bad arguments.
    """
    from .design_checks import (MATERIALS, DesignInputs, check_design, default_load,
                                format_report)
    from .sweep.study import apply_overrides, resolve_preset

    try:
        params = resolve_preset(args.preset)
    except ValueError as exc:
        parser.error(f"argument PRESET: {exc}")
    try:
        params = apply_overrides(params, dict(args.set or []))
    except ValueError as exc:
        parser.error(f"argument --set: {exc}")
    if args.set:
        params = params.with_changes(name=f"{params.name} with "
                                          + ", ".join(f"{k} = {v}" for k, v in args.set))
    load = args.load if args.load is not None else default_load(args.preset)
    try:
        inputs = DesignInputs(axial_load=load, extended_length=args.length,
                              material=MATERIALS[args.material],
                              safety_factor=args.safety_factor,
                              stability_factor=args.stability_factor, ends=args.ends,
                              section_fractions=args.sections, teeth=args.teeth)
        report = check_design(params, inputs)
    except ValueError as exc:
        parser.error(str(exc))
    if args.load is None and load is not None:
        print(f"(axial load: {load:g} N, the largest load of the preset's seed scenario; "
              "--load to change)")
    print(format_report(report))
    return 0 if report.valid else 1


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``prsm-fmu`` with its subcommands.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = argparse.ArgumentParser(
        prog="prsm-fmu",
        description="Planetary roller screw mechanism (PRSM) dynamics. SI units throughout.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser(
        "startup", help="seed 000 §3.1 start-up: screw speed step, carriers at rest",
        description="Step the screw speed at t = 0 with the carriers at rest (seed 000 §3.1), "
                    "print a table, the carriers' settling times and the energy balance, and "
                    "write OUT/startup.csv and OUT/startup.png.")
    p.add_argument("--preset", type=_preset, default="seed000_two_stage",
                   help="preset name (see 'prsm-fmu presets'); default %(default)s")
    p.add_argument("--fidelity", choices=FIDELITIES + ("auto",), default="dynamic",
                   help="model level (auto: dynamic while the carriers lag, quasi-static once "
                        "they follow, docs/accuracy.md §4); default %(default)s")
    p.add_argument("--tolerance", type=_positive_float, default=1e-8,
                   help="rtol of the adaptive steppers (atol = 0.01 tolerance) and, with auto, "
                        "the accepted model error [-]; default %(default)g")
    p.add_argument("--speed", type=_nonzero_float, default=100.0,
                   help="screw speed after the step [rad/s], non-zero; default %(default)g")
    p.add_argument("--load", type=_finite_float, default=5000.0,
                   help="load force on the last nut [N], positive resists extension; "
                        "default %(default)g")
    p.add_argument("--t-end", type=_positive_float, default=1e-3,
                   help="simulated time [s], > 0; default %(default)g")
    p.add_argument("--interval", type=_positive_float, default=1e-6,
                   help="output interval [s], > 0, dividing --t-end; default %(default)g")
    p.add_argument("--stepper", choices=STEPPERS, default=None,
                   help="time stepper; default by fidelity (rosenbrock for dynamic)")
    p.add_argument("--out", default="out",
                   help="output directory for startup.csv and startup.png; default %(default)s")
    p.set_defaults(func=cmd_startup, parser=p)

    p = sub.add_parser("steady", help="steady state at constant speed and load",
                       description="Print the steady state (root finding, no time stepping).")
    p.add_argument("--preset", type=_preset, default="seed000_two_stage",
                   help="preset name; default %(default)s")
    p.add_argument("--speed", type=_nonzero_float, default=100.0,
                   help="screw speed [rad/s], non-zero; default %(default)g")
    p.add_argument("--load", type=_finite_float, default=5000.0,
                   help="load force on the last nut [N], positive resists extension; "
                        "default %(default)g")
    p.set_defaults(func=cmd_steady, parser=p)

    p = sub.add_parser("presets", help="list the preset names",
                       description="List the preset names, one per line.")
    p.set_defaults(func=cmd_presets, parser=p)

    p = sub.add_parser(
        "sweep", help="run a parameter study (TOML) on the FMU or the model, locally or on Dask",
        description="Run every point of a study (studies/*.toml; docs/sweeps.md) and write "
                    "OUT/results.csv, OUT/report.md, the figures OUT/*.png and the series "
                    "OUT/series/*.npz. Points already in OUT/results.csv are skipped. Exit "
                    "status 1 if a point failed (it is recorded with its error).")
    p.add_argument("study", metavar="STUDY", help="study file (TOML)")
    p.add_argument("--out", default=None,
                   help="output directory; default out/sweeps/<study name>")
    p.add_argument("--backend", choices=("fmu", "model"), default=None,
                   help="simulate the FMU (speed prescribed by the master) or the model "
                        "(prsm_fmu.simulate); default: the study's")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes of the local Dask cluster; default: the cores")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of an existing Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--no-dask", action="store_true",
                   help="run the points one after the other in this process")
    p.add_argument("--fmu-dir", default=None,
                   help="directory holding PRSM<n>.fmu (default: build them into OUT/fmu)")
    p.add_argument("--rerun-all", action="store_true",
                   help="run every point again, also those already done")
    p.add_argument("--no-figures", action="store_true", help="do not draw the figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep, parser=p)

    from .design_checks import END_FACTORS, MATERIALS

    p = sub.add_parser(
        "check", help="seed 001 design checks of a preset: meshing, lead, gears, strength, "
                      "buckling",
        description="Check a preset against seed 001's parameter-matching conditions and "
                    "print a verdict naming every violated condition (exit status 1 if one "
                    "is violated). Without --load the largest load of the preset's seed "
                    "scenario is used; without --length the longest stable extension is "
                    "reported.")
    p.add_argument("preset", metavar="PRESET", help="preset name (see 'prsm-fmu presets')")
    p.add_argument("--load", type=_positive_float, default=None,
                   help="axial load F_a [N] (compressive for buckling)")
    p.add_argument("--length", type=_positive_float, default=None,
                   help="extended (unsupported) length L of the screw column [m]")
    p.add_argument("--material", choices=tuple(MATERIALS), default="carbon_steel",
                   help="screw material (straight-line buckling constants); default %(default)s")
    p.add_argument("--safety-factor", type=_finite_float, default=2.0,
                   help="K in [σ] = σ_s / K, >= 1; default %(default)g")
    p.add_argument("--stability-factor", type=_finite_float, default=3.0,
                   help="n_st in F_a <= F_cr / n_st, >= 1; default %(default)g")
    p.add_argument("--ends", choices=tuple(END_FACTORS), default="pinned-pinned",
                   help="end conditions of the column; default %(default)s")
    p.add_argument("--sections", type=_fractions, default=None, metavar="F1,F2,...",
                   help="share of L per screw section, stage 1 first; default equal")
    p.add_argument("--teeth", type=_teeth, default=None, metavar="Z_R,Z_IG",
                   help="teeth of the roller-end gear and of the ring gear")
    p.add_argument("--set", type=_set_value, action="append", metavar="NAME=VALUE",
                   help="change a parameter first, e.g. stage[2].screw_radius=0.015 (SI); "
                        "repeatable")
    p.set_defaults(func=cmd_check, parser=p)

    p = sub.add_parser(
        "regress", help="compare the built FMU's outputs with the stored baselines",
        description="Build PRSM2.fmu in a child process (or take --fmu), run every regression "
                    "case (baselines/tolerances.toml) with fmpy and compare each output with "
                    "its tolerance tube; write OUT/report.html with a plot of every output "
                    "that left its tube. Exit status 1 if one did. --update rewrites the "
                    "baselines at tight tolerance and baselines/REPORT.md (docs/regression.md).")
    p.add_argument("--update", action="store_true",
                   help="write new baselines and a report of what changed against the old")
    p.add_argument("--fmu", default=None, help="use this FMU instead of building one")
    p.add_argument("--baselines", default=None, metavar="DIR|FMU",
                   help="baselines directory, or an FMU holding them in extra/baselines "
                        "(default: the repository's baselines/)")
    p.add_argument("--case", action="append", default=None, metavar="NAME",
                   help="only this case (repeatable); default every case")
    p.add_argument("--set", type=_regress_value, action="append", metavar="NAME=VALUE",
                   help="set an FMU parameter in every case first, e.g. mu_screw_roller=0.101 "
                        "(to see what a change does); repeatable")
    p.add_argument("--out", default="out/regress", help="output directory (default %(default)s)")
    p.set_defaults(func=cmd_regress, parser=p)
    return parser


def _regress_value(text: str) -> tuple[str, float | str]:
    """``NAME=VALUE`` of ``regress --set``: a float if it parses as one, else a string."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE")
    try:
        return name.strip(), float(value)
    except ValueError:
        return name.strip(), value.strip()


def cmd_regress(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Build the FMU (child process), run the regression cases, compare or update baselines.

    Returns
    -------
    int
        0 if every case passes (or the baselines were written), 1 if one fails.
    """
    from pathlib import Path

    from . import regress
    from .regress.report import verdict_table, write_report

    out = Path(args.out)
    if args.fmu:
        fmu = Path(args.fmu)
        if not fmu.is_file():
            parser.error(f"argument --fmu: {fmu}: no such file")
    else:
        print(f"building PRSM2.fmu into {out / 'fmu'} (python -m fmu_build, child process) ...",
              flush=True)
        fmu = regress.build_fmu(out / "fmu")
    where = Path(args.baselines) if args.baselines else regress.DEFAULT_DIR
    if args.update:
        if where.suffix == ".fmu" or args.set:
            parser.error("argument --update: writes into a baselines directory, without --set")
        print(regress.update(fmu, where, args.case))
        print(f"wrote the baselines and {where / 'REPORT.md'}: review the report, then pack "
              "them into the FMU by rebuilding it (python -m fmu_build)")
        return 0
    params = dict(args.set) if args.set else None
    try:
        results = regress.check(fmu, where, args.case, parameters=params)
    except ValueError as exc:
        parser.error(f"argument --case: {exc}")
    print(verdict_table(results))
    failed = [r.case.name for r in results if not r.passed]
    if failed:
        path = write_report(results, out, f"{fmu.name} against {where}")
        print(f"FAIL: {len(failed)} of {len(results)} cases ({', '.join(failed)}); report: "
              f"{path}")
        return 1
    print(f"PASS: {len(results)} cases, every output inside its tube")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``prsm-fmu`` console script.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit code: 0 on success, 2 for bad arguments (a message naming the argument is
        printed on stderr), 1 if a simulation step fails.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        return int(args.func(args, args.parser))
    except SystemExit as exc:          # argparse: --help (0) or a bad argument (2)
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 2)
    except StepFailure as exc:
        print(f"prsm-fmu: error: the simulation failed: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
