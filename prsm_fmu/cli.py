"""The ``prsm-fmu`` command line.

Subcommands::

    prsm-fmu startup [--preset li2021_two_stage] [--fidelity dynamic|auto|...]
                     [--tolerance 1e-8] [--speed 100] [--load 5000] [--t-end 1e-3]
                     [--interval 1e-6] [--out out]
    prsm-fmu steady  [--preset li2021_two_stage] [--speed 100] [--load 5000]
    prsm-fmu presets
    prsm-fmu sweep   STUDY.toml [--out DIR] [--workers N | --scheduler tcp://host:port |
                     --no-dask] [--backend fmu|model] [--fmu native|python] [--fmu-dir DIR]
                     [--rerun-all]
    prsm-fmu check   PRESET [--load N] [--length M] [--material NAME] [--safety-factor K]
                     [--stability-factor N] [--ends ENDS] [--teeth Z_R,Z_IG] [--set NAME=VALUE]
    prsm-fmu regress [--update] [--fmu PRSM2.fmu] [--baselines DIR|FMU] [--case NAME ...]
                     [--set NAME=VALUE] [--out DIR] [--loop native|python]
    prsm-fmu plot    RESULT.csv --fmu PRSM2.fmu [--out RESULT.png] [--variables NAME ...]

``startup`` runs the start-up scenario of Li et al. (2021) §3.1 (the screw speed stepped at t = 0 with
the carriers at rest, a constant load on the last nut), prints a table, the carriers' settling
times and the run's cost and energy balance, and writes ``startup.csv`` and ``startup.png``.
``steady`` prints the steady state found by root finding (:func:`prsm_fmu.steady_state`).
``sweep`` runs a parameter study (:mod:`prsm_fmu.sweep`, docs/sweeps.md) and ``check`` the
design checks of the two-stage kinematics article (:mod:`prsm_fmu.design_checks`).  ``regress`` compares the built
FMU's outputs with the stored baselines (:mod:`prsm_fmu.regress`, docs/regression.md).
``plot`` draws the result CSV of ``fmpy simulate`` with the FMU's units
(:mod:`prsm_fmu.result_plot`).  A bad argument is answered with one line naming it and its
allowed values, exit status 2, before anything is computed (:mod:`prsm_fmu.arguments`).
All quantities are SI (m, N, N.m, rad/s, s, W, J); units are spelled as in the FMU
(:mod:`prsm_fmu.units`).

The helpers :func:`write_csv` and :func:`plot_startup` are shared with :mod:`prsm_fmu.report`;
:func:`settling_time`, :func:`is_settled`, :func:`energy_balance_residual` and :func:`unit_of`
live in :mod:`prsm_fmu.results` (below the CLI and the sweeps) and are re-exported here.
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
from .arguments import (ArgumentParser, existing_dir, existing_file, finite_float, float_in,
                        int_in, one_line, positive_float, writable_dir)
from .atomic import atomic_path
from .command import run_command
from .engine import ENGINE_ENV, ENGINES
from .extras import require
from .configure import MAX_INITIAL_SPEED, TOLERANCE_RANGE
from .fmu_variables import Variable, fmu_variables
from .models import FIDELITIES
from .params import MECHANISM_FIELD_NAMES, MechanismParams
from .results import energy_balance_residual, is_settled, settling_time
from .simulate import simulate
from .steady_state import steady_state
from .steppers import StepFailure
from .units import DIMENSIONLESS, MILLISECOND, NEWTON, NEWTON_METRE, label, unit_of

__all__ = ["main", "build_parser", "settling_time", "is_settled", "energy_balance_residual", "unit_of",
           "write_csv", "plot_startup", "startup_table"]

#: argparse type of ``--speed``: the range of the FMU's ``initial_screw_speed`` parameter
#: (:data:`prsm_fmu.configure.MAX_INITIAL_SPEED`), without 0 (no start-up to standstill)
SCREW_SPEED = float_in(-MAX_INITIAL_SPEED, MAX_INITIAL_SPEED, nonzero=True, unit="rad/s")

#: steppers accepted by ``--stepper`` (see prsm_fmu.steppers)
STEPPERS = ("rk4", "explicit_adaptive", "rosenbrock", "radau")


def _output_columns(res: Mapping[str, np.ndarray]) -> list[str]:
    """Names of the time series in a simulate result (``time`` first, scalars left out)."""
    return [k for k, v in res.items() if isinstance(v, np.ndarray) and v.ndim == 1]


def write_csv(res: Mapping[str, np.ndarray], path: str) -> None:
    """Write every time series of a simulate result to a CSV file.

    The header names each column with its unit as the FMU spells it
    (:mod:`prsm_fmu.units`), e.g. ``time [s],screw_speed [rad/s],...``; the values are written
    with 12 significant digits.  UTF-8.

    Parameters
    ----------
    res : mapping
        The result of :func:`prsm_fmu.simulate`.
    path : str
        Output file.
    """
    cols = _output_columns(res)
    data = np.column_stack([res[c] for c in cols])
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow([label(c, unit_of(c)) for c in cols])
        for row in data:
            w.writerow([f"{v:.12g}" for v in row])


def _n_stages(res: Mapping[str, np.ndarray]) -> int:
    n = 0
    while f"stage[{n + 1}].carrier_speed_ratio" in res:
        n += 1
    return n


def plot_startup(runs: Sequence[tuple[str, Mapping[str, np.ndarray]]], path: str,
                 title: str = "") -> None:
    """Save a 2×2 figure like Li et al. (2021) Fig. 3 for one or more start-up runs.

    Panels: (a) carrier speed ratios ζ_k; (b) driven torques M_Sk [N.m]; (c) axial contact
    forces per roller F_Srzk [N]; (d) efficiency η [1] (left axis) and spline friction f_Sk
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

    from .figures import save, subplots

    styles = ["-", "--", "-.", ":"]
    colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, axes = subplots(2, 2, figsize=(10, 7.5), sharex=True, wspace=0.45, hspace=0.25,
                         margins={"right": 0.9, "top": 0.5 + (0.3 if title else 0.0)})
    ax_z, ax_m, ax_f, ax_e = axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1]
    ax_h = ax_e.twinx()
    for j, (run_label, res) in enumerate(runs):
        ls = styles[j % len(styles)]
        suffix = f", {run_label}" if run_label else ""
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
    ax_z.set_ylabel(label("carrier speed ratio ζ_PSk", DIMENSIONLESS))
    ax_z.set_title("(a) carrier speed ratios")
    ax_m.set_ylabel(label("driven torque M_Sk", NEWTON_METRE))
    ax_m.set_title("(b) driven torques")
    ax_f.set_ylabel(label("axial contact force per roller F_Srzk", NEWTON))
    ax_f.set_title("(c) screw–roller axial contact forces")
    ax_e.set_ylabel(label("efficiency η", DIMENSIONLESS))
    ax_h.set_ylabel(label("spline friction f_Sk", NEWTON))
    ax_e.set_title("(d) efficiency (black) and spline friction (colour)")
    for ax in (ax_f, ax_e):
        ax.set_xlabel(label("time", MILLISECOND))
    for ax in (ax_z, ax_m, ax_f):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    ax_e.grid(True, alpha=0.3)
    h1, l1 = ax_e.get_legend_handles_labels()
    h2, l2 = ax_h.get_legend_handles_labels()
    ax_e.legend(h1 + h2, l1 + l2, fontsize=8, loc="center right")
    if title:
        fig.suptitle(title)
    save(fig, path)


def _sample_indices(time: np.ndarray, n_rows: int = 11) -> list[int]:
    """Indices of the samples nearest to n_rows evenly spaced times over the run."""
    targets = np.linspace(time[0], time[-1], n_rows)
    idx = [int(np.argmin(np.abs(time - t))) for t in targets]
    return sorted(set(idx))


def startup_table(res: Mapping[str, np.ndarray], n_rows: int = 11) -> str:
    """The start-up run as a fixed-width text table at ~``n_rows`` evenly spaced times.

    Columns: time [ms], ζ_PSk [1], M_Sk [N.m], F_Srzk [N] for every stage k, f_Sk [N] for
    k ≥ 2 and η [1] (units spelled as in :mod:`prsm_fmu.units`).
    """
    t = np.asarray(res["time"])
    n = _n_stages(res)
    cols: list[tuple[str, Callable[[int], float]]] = [(label("time", MILLISECOND),
                                                        lambda i: t[i] * 1e3)]
    for k in range(1, n + 1):
        cols.append((label(f"ζ_PS{k}", DIMENSIONLESS), lambda i, k=k: res[f"stage[{k}].carrier_speed_ratio"][i]))
    for k in range(1, n + 1):
        cols.append((label(f"M_S{k}", NEWTON_METRE), lambda i, k=k: res[f"stage[{k}].driven_torque"][i]))
    for k in range(1, n + 1):
        cols.append((label(f"F_Srz{k}", NEWTON), lambda i, k=k: res[f"stage[{k}].contact_force"][i]))
    for k in range(2, n + 1):
        cols.append((label(f"f_S{k}", NEWTON), lambda i, k=k: res[f"stage[{k}].spline_friction"][i]))
    cols.append((label("η", DIMENSIONLESS), lambda i: res["efficiency"][i]))
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
#: schemes of the Dask scheduler addresses ``--scheduler`` takes
SCHEDULER_SCHEMES = ("tcp", "tls", "ucx", "ws", "wss")


def _scheduler_address(text: str) -> str:
    """argparse type of ``--scheduler``: ``[SCHEME://]HOST[:PORT]`` of a Dask scheduler."""
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    host, port = rest, ""
    if rest.startswith("["):                      # [IPv6]:port
        end = rest.find("]")
        host, port = rest[:end + 1], rest[end + 1:].removeprefix(":")
    elif rest.count(":") == 1:
        host, port = rest.split(":")
    ok = (scheme in SCHEDULER_SCHEMES and host and not any(c.isspace() or c in "/?#"
                                                           for c in host)
          and (not port or (port.isdigit() and 1 <= int(port) <= 65535)))
    if not ok:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a Dask scheduler address: must be SCHEME://HOST:PORT with SCHEME "
            f"one of {', '.join(SCHEDULER_SCHEMES)} and PORT in [1, 65535], e.g. "
            "tcp://host:8786")
    return text


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
    """Run the Li et al. (2021) §3.1 start-up scenario; print a table; write CSV and PNG.

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
                     "intervals over --t-end; must give at most 10 000 000")
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
        parser.error("argument --scheduler: must not be combined with --workers or --no-dask")
    if args.workers is not None and args.no_dask:
        parser.error("argument --workers: must not be combined with --no-dask")
    try:
        study = load_study(args.study, backend=args.backend)
    except (OSError, StudyError) as exc:
        parser.error(f"argument STUDY: {exc}; must be a study file (TOML, docs/sweeps.md)")
    n_points = len(study.points())
    where = "this process" if args.no_dask else (
        f"the Dask cluster at {args.scheduler}" if args.scheduler else
        f"a local Dask cluster of {args.workers or os.cpu_count()} worker(s)")
    print(f"study {study.name}: {study.title}")
    print(f"{n_points} points ({', '.join(study.swept) or 'no swept parameter'}), preset "
          f"{study.preset}, backend {study.backend}, on {where}")
    try:
        res = run_study(study, os.path.join(args.out, study.name), executor="loop" if args.no_dask else "dask",
                        scheduler=args.scheduler, workers=args.workers, fmu_dir=args.fmu_dir,
                        fmu=args.fmu,
                        resume=not args.rerun_all, figures=not args.no_figures,
                        progress=None if args.quiet else sys.stderr)
    except (ValueError, RuntimeError, OSError) as exc:
        print(f"prsm-fmu: error: {one_line(exc)}", file=sys.stderr)
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
            f"{name!r} is not a mechanism or stage parameter: must be one of "
            f"{', '.join(MECHANISM_FIELD_NAMES)}, stage[k].<field>, stage[k].pitch")
    integer = name.endswith((".screw_starts", ".n_rollers", ".carriers", ".threads_per_roller"))
    try:
        v: object = int(value) if integer else finite_float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name} = {value!r} is not allowed: must be an "
                                         "integer") from None
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
        values = tuple(positive_float(x) for x in text.split(","))
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    return values


def cmd_check(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Print the design checks of the two-stage kinematics article for a preset (optionally modified with ``--set``).

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
        params.validate(geometry=False)        # ranges, as everywhere; meshing is graded
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
        option = next((o for f, o in _CHECK_OPTIONS.items() if str(exc).startswith(f)), "")
        parser.error(f"argument {option}: {exc}" if option else str(exc))
    if args.load is None:
        print(f"(axial load: {load:g} N, the largest load of {args.preset}'s paper scenario; "
              "--load to change)" if load is not None else
              f"(axial load: none — {args.preset}'s paper scenario gives no load, so strength "
              "and buckling report the allowable load only; --load F_a [N] checks them)")
    print(format_report(report, _CHECK_INPUTS))
    return 0 if report.valid else 1


#: DesignInputs field -> the option that sets it (in error messages and the verdict)
_CHECK_OPTIONS = {"axial_load": "--load", "extended_length": "--length",
                  "safety_factor": "--safety-factor", "stability_factor": "--stability-factor",
                  "section_fractions": "--sections", "teeth": "--teeth"}
#: missing inputs as the verdict names them
_CHECK_INPUTS = {"axial_load": "--load F_a", "extended_length": "--length L",
                 "teeth": "--teeth Z_R,Z_IG"}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``prsm-fmu`` with its subcommands.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = ArgumentParser(
        prog="prsm-fmu",
        description="Planetary roller screw mechanism (PRSM) dynamics. SI units throughout.")
    parser.add_argument("--engine", choices=ENGINES, default=None, help="what computes the PRSM physics in every door of this run (simulate, the Python block, the FMUs loaded, sweep workers): native (default) the compiled "
                        "engine where it loads, python the Python reference model (sets PRSM_FMU_ENGINE)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser(
        "startup", help="Li et al. (2021) §3.1 start-up: screw speed step, carriers at rest",
        description="Step the screw speed at t = 0 with the carriers at rest (Li et al. (2021) §3.1), "
                    "print a table, the carriers' settling times and the energy balance, and "
                    "write OUT/startup.csv and OUT/startup.png.")
    p.add_argument("--preset", type=_preset, default="li2021_two_stage",
                   help="preset name (see 'prsm-fmu presets'); default %(default)s")
    p.add_argument("--fidelity", choices=FIDELITIES + ("auto",), default="dynamic",
                   help="model level (auto: dynamic while the carriers lag, quasi-static once "
                        "they follow, docs/accuracy.md §4); default %(default)s")
    p.add_argument("--tolerance", type=float_in(*TOLERANCE_RANGE), default=1e-8,
                   help="rtol of the adaptive steppers (atol = 0.01 tolerance) and, with auto, "
                        "the accepted model error [1]; default %(default)g")
    p.add_argument("--speed", type=SCREW_SPEED, default=100.0,
                   help="screw speed after the step [rad/s], non-zero, within the FMU's "
                        f"initial_screw_speed range ±{MAX_INITIAL_SPEED:g}; default %(default)g")
    p.add_argument("--load", type=finite_float, default=5000.0,
                   help="load force on the last nut [N], positive resists extension; "
                        "default %(default)g")
    p.add_argument("--t-end", type=float_in(0.0, lo_open=True, unit="s"), default=1e-3,
                   help="simulated time [s], > 0; default %(default)g")
    p.add_argument("--interval", type=float_in(0.0, lo_open=True, unit="s"), default=1e-6,
                   help="output interval [s], > 0, dividing --t-end; default %(default)g")
    p.add_argument("--stepper", choices=STEPPERS, default=None,
                   help="time stepper; default by fidelity (rosenbrock for dynamic)")
    p.add_argument("--out", type=writable_dir, default="out",
                   help="output directory for startup.csv and startup.png; default %(default)s")
    p.set_defaults(func=cmd_startup, parser=p)

    p = sub.add_parser("steady", help="steady state at constant speed and load",
                       description="Print the steady state (root finding, no time stepping).")
    p.add_argument("--preset", type=_preset, default="li2021_two_stage",
                   help="preset name; default %(default)s")
    p.add_argument("--speed", type=SCREW_SPEED, default=100.0,
                   help=f"screw speed [rad/s], non-zero, within ±{MAX_INITIAL_SPEED:g}; "
                        "default %(default)g")
    p.add_argument("--load", type=finite_float, default=5000.0,
                   help="load force on the last nut [N], positive resists extension; "
                        "default %(default)g")
    p.set_defaults(func=cmd_steady, parser=p)

    p = sub.add_parser("presets", help="list the preset names",
                       description="List the preset names, one per line.")
    p.set_defaults(func=cmd_presets, parser=p)

    p = sub.add_parser(
        "sweep", help="run a parameter study (TOML) on the FMU or the model, locally or on Dask",
        description="Run every point of a study (studies/*.toml; docs/sweeps.md) and write "
                    "into a folder of its own, OUT/<study name>/: results.csv, report.md, the "
                    "figures *.png and the series series/*.npz. Points already in its "
                    "results.csv are skipped; another study's results are never touched. Exit "
                    "status 1 if a point failed (it is recorded with its error).")
    p.add_argument("study", metavar="STUDY", help="study file (TOML)")
    p.add_argument("--out", type=writable_dir, default=os.path.join("out", "sweeps"),
                   help="parent directory: the study writes into OUT/<study name>/; "
                        "default %(default)s")
    p.add_argument("--backend", choices=("fmu", "model"), default=None,
                   help="simulate the FMU (speed prescribed by the master) or the model "
                        "(prsm_fmu.simulate); default: the study's")
    p.add_argument("--workers", type=int_in(1), default=None,
                   help="worker processes of the local Dask cluster; default: the cores")
    p.add_argument("--scheduler", type=_scheduler_address, default=None, metavar="ADDRESS",
                   help="address of an existing Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--no-dask", action="store_true",
                   help="run the points one after the other in this process")
    p.add_argument("--fmu", choices=("native", "python"), default=None,
                   help="the FMU of the FMU backend: the native C FMU PRSM<n>-native.fmu "
                        "(default where Zig's C compiler, pip install ziglang, can build it) or "
                        "the Python FMU PRSM<n>.fmu (pythonfmu); the same results")
    p.add_argument("--fmu-dir", type=existing_dir, default=None,
                   help="directory holding the FMUs (PRSM<n>-native.fmu or PRSM<n>.fmu, by "
                        "--fmu; default: build them into OUT/<study>/fmu)")
    p.add_argument("--rerun-all", action="store_true",
                   help="run every point again, also those already done")
    p.add_argument("--no-figures", action="store_true", help="do not draw the figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep, parser=p)

    from .design_checks import END_FACTORS, MATERIALS

    p = sub.add_parser(
        "check", help="design checks of a preset after the two-stage kinematics article: meshing, lead, gears, strength, "
                      "buckling",
        description="Check a preset against the two-stage kinematics article's parameter-matching conditions and "
                    "print a verdict naming every violated condition (exit status 1 if one "
                    "is violated). Always checked: geometric meshing and lead matching of "
                    "every stage. Gear engagement needs --teeth. Strength of every screw needs "
                    "an axial load: --load, or else the largest load of the preset's paper "
                    "scenario if it has one (li2021_two_stage, assembly_two_stage and friction_single_stage do; kinematics_two_stage's "
                    "scenario has none, so its default run reports the allowable loads and "
                    "leaves strength and buckling not checked). Buckling needs the load and "
                    "--length; with the load only, the longest stable extension is reported. "
                    "The verdict lists every check not done and the option that would do it. "
                    "--set values are validated like the preset's parameters.")
    p.add_argument("preset", metavar="PRESET", help="preset name (see 'prsm-fmu presets')")
    p.add_argument("--load", type=float_in(0.0, lo_open=True, unit="N"), default=None,
                   help="axial load F_a [N] (compressive for buckling); default: the largest "
                        "load of the preset's paper scenario, if any")
    p.add_argument("--length", type=float_in(0.0, lo_open=True, unit="m"), default=None,
                   help="extended (unsupported) length L of the screw column [m]")
    p.add_argument("--material", choices=tuple(MATERIALS), default="carbon_steel",
                   help="screw material (straight-line buckling constants); default %(default)s")
    p.add_argument("--safety-factor", type=float_in(1.0), default=2.0,
                   help="K in [σ] = σ_s / K, >= 1; default %(default)g")
    p.add_argument("--stability-factor", type=float_in(1.0), default=3.0,
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
    p.add_argument("--fmu", type=existing_file, default=None,
                   help="use this FMU instead of building one")
    p.add_argument("--baselines", default=None, metavar="DIR|FMU",
                   help="baselines directory, or an FMU holding them in extra/baselines "
                        "(default: the repository's baselines/)")
    p.add_argument("--case", action="append", default=None, metavar="NAME",
                   help="only this case (repeatable); default every case")
    p.add_argument("--set", type=_regress_value, action="append", metavar="NAME=VALUE",
                   help="set an FMU parameter in every case first, e.g. mu_screw_roller=0.101 "
                        "(to see what a change does); repeatable")
    p.add_argument("--out", type=writable_dir, default="out/regress",
                   help="output directory (default %(default)s)")
    from .regress.core import LOOPS

    p.add_argument("--loop", choices=LOOPS, default=LOOPS[0],
                   help="who takes the macro steps: the actuator loop compiled to C (native; "
                        "the Python master where gcc is missing) or the Python master; the "
                        "same outputs bit for bit (default %(default)s)")
    p.set_defaults(func=cmd_regress, parser=p)

    from .result_plot import DEFAULT_VARIABLES

    p = sub.add_parser(
        "plot", help="plot an FMU's result CSV (fmpy simulate --output-file) with its units",
        description="Draw the result CSV that 'fmpy simulate FMU --output-file CSV' writes, one "
                    "panel per variable against time, each axis labelled with the unit the "
                    "FMU's modelDescription gives it (matplotlib; fmpy's own --show-plot needs "
                    "plotly). Writes the PNG named by --out.")
    p.add_argument("result", metavar="RESULT", type=existing_file,
                   help="result CSV with a header row of variable names starting with 'time'")
    p.add_argument("--fmu", type=existing_file, required=True,
                   help="the FMU that produced it (for the units)")
    p.add_argument("--out", type=_png_path, default=None,
                   help="output PNG; default RESULT with the suffix .png")
    p.add_argument("--variables", nargs="+", default=list(DEFAULT_VARIABLES), metavar="NAME",
                   help="variables to draw, stage[k].NAME for every stage; default "
                        + " ".join(DEFAULT_VARIABLES))
    p.set_defaults(func=cmd_plot, parser=p)
    return parser


def _png_path(text: str) -> str:
    """argparse type of ``plot --out``: a .png file in a writable directory."""
    if not text.lower().endswith(".png"):
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed: must be a .png file")
    writable_dir(os.path.dirname(text) or ".")
    return text


def cmd_plot(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Plot an FMU result CSV with the FMU's units; print what was drawn and where.

    Returns
    -------
    int
        0, or 2 for a file that is not a result CSV or not an FMU.
    """
    from .result_plot import fmu_units, plot_fmu_result, read_result_csv

    try:
        res = read_result_csv(args.result)
    except ValueError as exc:
        parser.error(f"argument RESULT: {exc}; must be the CSV of 'fmpy simulate "
                     "--output-file'")
    try:
        units = fmu_units(args.fmu)
    except ValueError as exc:
        parser.error(f"argument --fmu: {exc}")
    out = args.out or os.path.splitext(args.result)[0] + ".png"
    try:
        drawn = plot_fmu_result(res, units, out, args.variables,
                                title=f"{os.path.basename(args.fmu)}: {os.path.basename(args.result)}")
    except ValueError as exc:
        parser.error(f"argument --variables: {exc}")
    t = res["time"]
    print(f"{os.path.basename(args.result)}: {len(t)} samples, t = {t[0]:g} … {t[-1]:g} s; "
          f"drew {', '.join(drawn)}")
    print(f"wrote {out}")
    return 0


def _regress_value(text: str) -> tuple[str, float | str]:
    """``NAME=VALUE`` of ``regress --set``: a float if it parses as one, else a string."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE")
    try:
        return name.strip(), float(value)
    except ValueError:
        return name.strip(), value.strip()


def _parameter_problem(variables: Mapping[str, Variable], name: str,
                       value: float | str) -> str:
    """Why ``name = value`` cannot be set as an FMU parameter ("" if it can)."""
    params = [n for n, v in variables.items() if v.causality == "parameter"]
    v = variables.get(name)
    if v is None or v.causality != "parameter":
        return (f"{name!r} is not a parameter of the FMU: must be one of {', '.join(params)}")
    if v.type in ("Real", "Integer"):
        if not isinstance(value, float) or not math.isfinite(value) or (
                v.type == "Integer" and value != int(value)):
            return (f"{name} = {value!r} is not allowed: must be a finite "
                    f"{'integer' if v.type == 'Integer' else 'number'}")
        lo = v.min if v.min is not None else -math.inf
        hi = v.max if v.max is not None else math.inf
        if not lo <= value <= hi:
            return f"{name} = {value!r} is out of range: must be in [{lo:g}, {hi:g}]"
    return ""


def cmd_regress(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Build the FMU if missing or older than its sources (child process), run the regression
    cases, compare or update baselines.

    Returns
    -------
    int
        0 if every case passes (or the baselines were written), 1 if one fails.
    """
    import zipfile
    from pathlib import Path

    from . import regress

    out = Path(args.out)
    where = Path(args.baselines) if args.baselines else regress.DEFAULT_DIR
    if args.update and (where.suffix == ".fmu" or args.set):
        parser.error("argument --update: writes into a baselines directory: must not be "
                     "combined with --set or an FMU as --baselines")
    # everything a bad argument can spoil is checked before the FMU is built
    try:
        known = [c.name for c in regress.load_cases(where)]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        parser.error(f"argument --baselines: {where}: no readable tolerances.toml "
                     f"({type(exc).__name__}: {exc}); must be a baselines directory or an FMU "
                     "holding extra/baselines")
    unknown = [c for c in args.case or () if c not in known]
    if unknown:
        parser.error(f"argument --case: unknown case(s) {', '.join(unknown)}: must be one of "
                     f"{', '.join(known)}")
    # the fmu extra, before anything is built or run: pythonfmu builds the FMU and runs inside
    # it, fmpy steps it
    require("fmpy", "pythonfmu", purpose="regress (building and running the FMU)")
    if args.fmu:
        fmu = Path(args.fmu)
        try:
            fmu_vars = fmu_variables(fmu)
        except ValueError as exc:
            parser.error(f"argument --fmu: {exc}")
    else:
        fmu = out / "fmu" / "PRSM2.fmu"
        why = regress.why_build(fmu)
        if why is None:
            print(f"using {fmu} (built from the current sources)", flush=True)
        else:
            print(f"building {fmu} ({why}; python -m fmu_build, child process) ...",
                  flush=True)
            try:
                regress.build_fmu(fmu.parent)
            except RuntimeError as exc:
                print(f"prsm-fmu: error: {one_line(exc)}", file=sys.stderr)
                return 1
        fmu_vars = fmu_variables(fmu)
    return _regress_checked(args, parser, fmu, fmu_vars, where, out)


def _regress_checked(args, parser, fmu, fmu_vars, where, out) -> int:
    """``regress`` once the FMU is there: its fit, then --update or the check."""
    from . import regress
    from .regress.report import verdict_table, write_report

    for name, value in args.set or ():
        problem = _parameter_problem(fmu_vars, name, value)
        if problem:
            parser.error(f"argument --set: {problem}")
    problem = regress.fmu_mismatch(fmu_vars, where, args.case, outputs=not args.update)
    if problem:
        if args.fmu:
            parser.error(f"argument --fmu: {args.fmu}: {problem}")
        print(f"prsm-fmu: error: {problem}", file=sys.stderr)
        return 1
    if args.update:
        print(regress.update(fmu, where, args.case, loop=args.loop))
        print(f"wrote the baselines and {where / 'REPORT.md'}: review the report, then pack "
              "them into the FMU by rebuilding it (python -m fmu_build)")
        return 0
    params = dict(args.set) if args.set else None
    results = regress.check(fmu, where, args.case, parameters=params, loop=args.loop)
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
        printed on stderr), 1 if a simulation step fails or an extra the command needs is not
        installed (one line naming it), 130 after Ctrl-C (:mod:`prsm_fmu.command`).
    """
    parser = build_parser()

    def body() -> int:
        try:
            args = parser.parse_args(argv)
            if args.engine is not None:
                os.environ[ENGINE_ENV] = args.engine
            return int(args.func(args, args.parser))
        except SystemExit as exc:          # argparse: --help (0) or a bad argument (2)
            code = exc.code
            return code if isinstance(code, int) else (0 if code is None else 2)
        except StepFailure as exc:
            print(f"prsm-fmu: error: the simulation failed: {exc}", file=sys.stderr)
            return 1

    return run_command("prsm-fmu", body)


if __name__ == "__main__":
    sys.exit(main())
