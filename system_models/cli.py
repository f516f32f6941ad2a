"""The ``prsm-ema`` command line: run the electromechanical actuator's scenes.

::

    prsm-ema list
    prsm-ema run --scene NAME|FILE.toml [--fidelity kinematic|quasi-static|dynamic|auto]
                 [--step H] [--out DIR] [--prsm fmu|python] [--fmu PATH]
                 [--order jacobi|gauss-seidel] [--extrapolation 0|1] [--retry N]
                 [--loop python|native] [--no-plots]

``run`` builds ``dist/PRSM2.fmu`` first if it is missing or older than the sources (with
``python -m fmu_build`` in a child process), co-simulates the scene with fmpy stepping the FMU,
prints the scene's checks (each with the measured value and its limit) and the power
bookkeeping, and writes ``DIR/<scene>.csv`` (every output, units in the header),
``DIR/<scene>_*.png`` and ``DIR/<scene>_summary.json``.  A progress bar appears on runs longer
than two seconds.

Exit status: 0 every check passed; 1 a check failed, or the co-simulation stopped (a refused
step: the message names the time, the block and the reason), or the ``fmu`` extra that
``--prsm fmu|native`` needs is not installed (one line naming it); 2 bad arguments (one line on
stderr naming the argument and its allowed values, before anything runs); 130 Ctrl-C (one
line; the outputs are written whole or not at all).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from prsm_fmu.arguments import ArgumentParser, existing_file, float_in, int_in, writable_dir
from prsm_fmu.engine import ENGINE_ENV, ENGINES

__all__ = ["main", "entry", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``prsm-ema`` (bad arguments: one line, exit status 2)."""
    from .retry_limit import MAX_HALVINGS

    ap = ArgumentParser(prog="prsm-ema", description=__doc__.splitlines()[0])
    ap.add_argument("--engine", choices=ENGINES, default=None,
                    help="what computes the PRSM physics (the FMU's and the Python block's): "
                         "native (default) the compiled engine where it loads, python the "
                         "Python reference model (sets PRSM_FMU_ENGINE)")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    sub.add_parser("list", help="list the scenes (./scenes first, then the built-in ones)",
                   description="List the scenes, one per line with its description: those in "
                               "./scenes first, then the built-in ones.")
    r = sub.add_parser("run", help="run a scene, print its checks, write CSV and plots",
                       description="Co-simulate a scene (the PRSM FMU stepped by fmpy, or the "
                                   "plain Python model), print its checks and the power "
                                   "bookkeeping, and write DIR/<scene>.csv, plots and a summary. "
                                   "Exit status 0 if every check passed, 1 if one failed or the "
                                   "run stopped, 2 for bad arguments.")
    r.add_argument("--scene", required=True, help="scene name (see 'prsm-ema list') or a .toml file")
    r.add_argument("--fidelity", choices=["kinematic", "quasi-static", "dynamic", "auto"],
                   help="PRSM fidelity level (default: the scene's)")
    r.add_argument("--step", type=float_in(0.0, lo_open=True, unit="s"),
                   help="communication step h [s] (default: the scene's)")
    r.add_argument("--out", type=writable_dir, default="out",
                   help="output directory (default: out)")
    r.add_argument("--prsm", choices=["fmu", "native", "python"], default="fmu",
                   help="the PRSM as the FMU stepped by fmpy (default), as the native C FMU "
                        "(kinematic, quasi-static and dynamic levels; needs gcc to build) or as "
                        "the plain Python model")
    r.add_argument("--fmu", type=existing_file,
                   help="the FMU file (default: dist/<mechanism>.fmu, or "
                        "dist/<mechanism>-native.fmu with --prsm native, built if missing)")
    r.add_argument("--order", choices=["jacobi", "gauss-seidel"], help="coupling order")
    r.add_argument("--extrapolation", type=int_in(0, 1), help="input extrapolation order, 0 or 1")
    r.add_argument("--retry", type=int_in(0, MAX_HALVINGS), metavar="N",
                   help="retry a refused step up to N times with halved substeps, N in "
                        f"[0, {MAX_HALVINGS}] (default: the scene's)")
    r.add_argument("--loop", choices=["python", "native"], default="python",
                   help="who takes the macro steps: the Python master (default) or its "
                        "translation to C (the same outputs bit for bit, ~10x less CPU; direct "
                        "topology with the PRSM as an FMU; needs gcc)")
    r.add_argument("--no-plots", action="store_true", help="write the CSV and summary only")
    return ap


def _cmd_list() -> int:
    from .scenes import list_scenes

    rows = list_scenes()
    w = max(len(n) for n, _ in rows) if rows else 0
    for name, desc in rows:
        print(f"{name:<{w}}  {desc}")
    return 0


def _refuse(message: str) -> int:
    """A bad scene or argument: one line on stderr, exit status 2, nothing run."""
    print(f"prsm-ema: error: {' '.join(message.split())}", file=sys.stderr)
    return 2


def _plots(run, out: Path, workers=None) -> list[Path]:
    """The run's figures for its topology (system_models.output, .plots_geared); ``workers``:
    a started :class:`~system_models.output.FigureWorkers` to draw them in."""
    scene, system = run.scene, run.system
    if scene.topology == "geared":
        from .plots_geared import write_geared_plots

        return write_geared_plots(run.result, out, scene.name, system.reference,
                                  description=scene.description, ratio=system.gear.ratio,
                                  lead_per_radian=system.lead_per_radian,
                                  backlash=system.gear.backlash,
                                  current_limit=system.motor.current_limit)
    from .output import write_plots

    if workers is not None:
        write_plots = workers.write_plots
    params = system.prsm.params()
    res = run.result
    equilibrium = None
    if any("carrier_speed_ratio" in o for o in scene.outputs):
        from prsm_fmu import steady_state

        ss = steady_state(params, screw_speed=float(res["prsm.screw_speed"][-1]),
                          load_force=float(res["load.force"][-1]))
        equilibrium = {k: float(ss[f"stage[{k}].carrier_speed_ratio"])
                       for k in range(1, params.n_stages + 1)}
    return write_plots(res, out, scene.name, system.reference, system.master.blocks[0].mode,
                       system.motor.current_limit, description=scene.description,
                       voltage_limit=system.motor.voltage_limit,
                       n_rollers=[st.n_rollers for st in params.stages],
                       carrier_equilibrium=equilibrium)


def _cmd_run(args, ap) -> int:
    from .figure_process import early_drawer, long_lived_imports

    drawer = None
    if not args.no_plots:
        # the figures' process forked once numpy and the output module (both processes use
        # them) are imported here, so that they are imported once, not in each (~0.1 s of CPU
        # less; the drawer's matplotlib import follows numpy's either way): it imports
        # matplotlib while the scene is checked, the FMU loaded and the scene run
        with long_lived_imports():
            from . import output  # noqa: F401

        drawer = early_drawer()
    try:
        return _checked_run(args, ap, drawer)
    finally:
        if drawer is not None:
            drawer.close()


def _checked_run(args, ap, drawer) -> int:
    from prsm_fmu.extras import require

    from .fmu import FMUError, ensure_fmu
    from .master import RetryPolicy, whole_steps
    from .output import FigureWorkers
    from .scene_check import check_fmu_stages, check_output_dir, check_scene
    from .scenes import load_scene

    try:
        scene = load_scene(args.scene)
        if args.retry is not None and args.retry < 0:
            raise ValueError(f"--retry {args.retry}: must be >= 0")
        # the whole scene, the run's size and the output directory, before anything runs
        facts = check_scene(scene, prsm=args.prsm, fidelity=args.fidelity, step=args.step,
                            order=args.order, extrapolation=args.extrapolation,
                            loop=args.loop)
        mech = scene.prsm.get("mechanism", "PRSM1" if scene.topology == "geared" else "PRSM2")
        if args.prsm != "python" and args.fmu:
            check_fmu_stages(args.fmu, facts["n_stages"], mech, native=args.prsm == "native")
        check_output_dir(args.out)          # last: it creates the directory the run writes to
    except ValueError as exc:
        return _refuse(str(exc))
    # the figures' processes (the drawer forked already, else started now) import matplotlib
    # while the FMU is checked and the scene runs; geared scenes draw theirs here
    if drawer is not None and scene.topology != "direct":
        drawer.close()
        drawer = None
    workers = (None if args.no_plots or scene.topology != "direct"
               else FigureWorkers(drawer=drawer).start())
    try:
        if args.prsm == "python":
            build_errors: tuple[type[Exception], ...] = (FMUError,)
        else:
            # the fmu extra, before anything runs: fmpy steps the FMU, pythonfmu builds it (and
            # the native FMU's builder imports it)
            require("fmpy", "pythonfmu", purpose=f"running the PRSM as an FMU (--prsm {args.prsm})")
            from fmu_build.errors import BuildError

            build_errors = (FMUError, BuildError)
        if args.step is not None:
            try:
                whole_steps(scene.t0, scene.t_end, args.step)
            except ValueError as exc:
                ap.error(f"argument --step: {exc}; must divide the scene's run into whole steps")
        retry = None
        if args.retry is not None:
            retry = RetryPolicy(max_halvings=args.retry, tolerance=scene.retry.get("tolerance"))
        fmu_path = None
        if args.prsm != "python":
            default = f"dist/{mech}{'-native' if args.prsm == 'native' else ''}.fmu"
            try:
                fmu_path = ensure_fmu(args.fmu or default, rebuild_stale=args.fmu is None)
            except FMUError as exc:
                print(f"prsm-ema: {exc}", file=sys.stderr)
                return 1
        print(f"scene {scene.name}: {scene.description}")
        return _run_and_write(args, ap, scene, fmu_path, retry, workers, build_errors)
    finally:
        if workers is not None:
            workers.close()


def _run_and_write(args, ap, scene, fmu_path, retry, workers,
                   build_errors: tuple[type[Exception], ...]) -> int:
    from prsm_fmu.command import deferred_interrupt

    from .master import CoSimulationError
    from .output import write_csv, write_summary
    from .progress import Progress
    from .run import run_scene

    prog = Progress(t_start=scene.t0)
    try:
        # Ctrl-C is held back to the master's steps: raised inside an FMU's own Python it would
        # be the FMU's fatal error, not an interruption (prsm_fmu.command.deferred_interrupt)
        with deferred_interrupt() as check:
            def progress(t: float, t_end: float) -> None:
                check()
                prog(t, t_end)

            run = run_scene(scene, prsm="python" if args.prsm == "python" else "fmu",
                            fmu_path=fmu_path, fidelity=args.fidelity,
                            step=args.step, order=args.order, extrapolation=args.extrapolation,
                            retry=retry, progress=progress, loop=args.loop)
    except KeyboardInterrupt:
        prog.close()                    # end the bar's line; prsm_fmu.command says the rest
        raise
    except CoSimulationError as exc:
        prog.close()
        from .step_hint import step_limit_hint

        hint = step_limit_hint(scene, args.step or scene.step, args.order or scene.order,
                               scene.extrapolation if args.extrapolation is None
                               else args.extrapolation)
        print(f"prsm-ema: {exc}" + (f" {hint}" if hint else ""), file=sys.stderr)
        return 1
    except (ValueError, *build_errors) as exc:
        prog.close()
        if isinstance(exc, build_errors):
            print(f"prsm-ema: {exc}", file=sys.stderr)
            return 1
        ap.error(str(exc))          # the scene and the options do not fit: one line, status 2
    prog.close()
    s = run.summary()
    st = s["stats"]
    what = f"FMU {fmu_path}" if args.prsm != "python" else "plain Python model"
    print(f"PRSM: {what}, fidelity {s['fidelity']}; master: {s['order']}, extrapolation order "
          f"{s['extrapolation']}, h = {s['step']:g} s, {st['macro_steps']} steps "
          f"({st['retries']} retries) in {st['wall_time']:.2f} s")
    d = s["system"]
    if scene.topology == "geared":
        print(f"actuator: gear ratio {d['gear_ratio']:g}, rod {1e6 * d['rod_per_motor_radian_m']:.4g} µm "
              f"per motor radian, inertia on the screw {d['inertia_on_screw_kg_m2']:.4g} kg·m² "
              f"(of which the PRSM's own {d['prsm_own_inertia_on_screw_kg_m2']:.3g}), reflected "
              f"mass {d['reflected_mass_kg']:.4g} kg, k_t {d['motor_torque_constant_Nm_A']:.5g} N·m/A")
    else:
        print(f"actuator: inertia on the screw {d['inertia_on_screw_kg_m2']:.4g} kg·m² "
              f"(reflected mass {d['reflected_mass_kg']:.4g} kg), peak torque "
              f"{d['motor_peak_torque_Nm']:.4g} N·m, controller sample time "
              f"{1e6 * d['controller_sample_time_s']:.4g} µs")
    if s["final"]:
        print("at the end: " + ", ".join(f"{k} = {v:.6g} {run.result.units.get(k, '')}".rstrip()
                                         for k, v in s["final"].items()))
    for c in run.checks:
        print(c.line())
    e = run.energy
    if e:
        print(f"power bookkeeping: electrical input {e['electrical_input']:.6g} J = copper losses "
              f"{e['copper_losses']:.6g} J + friction {e['friction_work']:.6g} J + load work "
              f"{e['load_work']:.6g} J + Δstored {e['delta_magnetic_energy'] + e['delta_kinetic_energy']:.6g} J "
              f"+ residual {e['residual']:.3g} J ({e['relative_residual']:.3g} relative)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    drawing, drawn = None, []
    if not args.no_plots and workers is not None and workers.active:
        # the figures are drawn in the workers while this process writes the CSV
        import threading

        drawing = threading.Thread(target=lambda: drawn.append(_plots(run, out, workers)))
        drawing.start()
    files = [write_csv(run.result, out / f"{scene.name}.csv", scene.outputs)]
    if drawing is not None:
        drawing.join()
    if not args.no_plots:
        files += drawn[0] if drawn else _plots(run, out)
    files.append(write_summary(out / f"{scene.name}_summary.json", s))
    print("wrote " + ", ".join(str(f) for f in files))
    print("all checks passed" if run.passed else "SOME CHECKS FAILED")
    return 0 if run.passed else 1


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``prsm-ema``; returns the exit status (2: a bad argument, one line on
    stderr; 0 for ``--help``; 1 also for a missing ``fmu`` extra, one line naming it; 130
    after Ctrl-C, :mod:`prsm_fmu.command`)."""
    from prsm_fmu.command import run_command

    ap = build_parser()

    def body() -> int:
        try:
            args = ap.parse_args(argv)
            if args.engine is not None:
                os.environ[ENGINE_ENV] = args.engine
            if args.command == "list":
                return _cmd_list()
            return _cmd_run(args, ap)
        except SystemExit as exc:          # argparse: --help (0) or a bad argument (2)
            return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)

    return run_command("prsm-ema", body)


def entry() -> None:
    """The ``prsm-ema`` console script and ``python -m system_models``: :func:`main`, then the
    process ends at once with its status (:func:`prsm_fmu.command.end_process`: the
    interpreter's teardown skipped; everything is written and every child process has ended
    when :func:`main` returns)."""
    from prsm_fmu.command import end_process

    end_process(main())


if __name__ == "__main__":
    entry()
