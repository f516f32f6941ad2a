"""Command line ``prsm-fmu-build`` (also ``python -m fmu_build``): build the PRSM FMUs.

::

    prsm-fmu-build [PRSM1 PRSM2 PRSM3 | --all] [--native] [--dest DIR] [--no-validate]
    prsm-fmu-build --preset NAME --name ID [--native] [--dest DIR]

``--native`` builds ``<name>-native.fmu`` instead: the kinematic, quasi-static and dynamic
levels in C, no Python needed to run it (:mod:`fmu_build.native`; needs gcc).

A bad argument is answered with one line naming it and its allowed values, exit status 2,
before anything is built (:mod:`prsm_fmu.arguments`); a failed build exits with 1.
"""

from __future__ import annotations

import sys

from prsm_fmu.arguments import ArgumentParser, one_line, writable_dir
from prsm_fmu.command import run_command
from prsm_fmu.extras import require

from .mechanisms import FMUS

DESCRIPTION = ("Build the planetary roller screw FMUs (FMI 2.0 co-simulation, pythonfmu) into "
               "DIR: PRSM2 by default, any of the standard FMUs by name or all with --all, or "
               "an FMU from any preset of prsm_fmu.presets with --preset NAME --name ID (ID "
               "is the FMI modelIdentifier, e.g. PRSM2_seed002). Each FMU is checked with "
               "fmpy validate and the project's modelDescription rules unless --no-validate. "
               "With --native: the native C FMU <name>-native.fmu (kinematic, quasi-static and "
               "dynamic levels, needs gcc; runs without Python). "
               "Also runs as 'python -m fmu_build'.")


def build_parser() -> ArgumentParser:
    """The argument parser of ``prsm-fmu-build``."""
    ap = ArgumentParser(prog="prsm-fmu-build", description=DESCRIPTION)
    ap.add_argument("names", nargs="*", metavar="FMU",
                    help=f"FMUs to build, of {', '.join(FMUS)} (default: PRSM2)")
    ap.add_argument("--all", action="store_true", help="build every standard FMU")
    ap.add_argument("--preset", help="build from this preset of prsm_fmu.presets instead")
    ap.add_argument("--name", help="FMU name (modelIdentifier) for --preset, e.g. PRSM2_seed002")
    ap.add_argument("--dest", type=writable_dir, default="dist", metavar="DIR",
                    help="output directory (default: dist)")
    ap.add_argument("--start", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter start value other than the preset's, e.g. "
                         "fidelity=dynamic (for hosts that cannot set it); repeatable")
    ap.add_argument("--native", action="store_true",
                    help="build the native C FMU <name>-native.fmu (kinematic, quasi-static and "
                         "dynamic levels; needs gcc) instead of the Python one")
    ap.add_argument("--no-validate", action="store_true",
                    help="skip fmpy validate and the modelDescription checks")
    return ap


def main(argv: list[str] | None = None) -> int:
    """Build the FMUs named on the command line; return the exit status.

    Returns
    -------
    int
        0 if every FMU was built, 1 if a build failed or the ``fmu`` extra is not installed
        (one line naming it), 2 for bad arguments, 130 after Ctrl-C.
    """
    return run_command("prsm-fmu-build", lambda: _main(argv))


def _main(argv: list[str] | None) -> int:
    ap = build_parser()
    try:
        args = ap.parse_args(argv)
    except SystemExit as exc:           # --help (0) or a bad argument (2, one line printed)
        return exc.code if isinstance(exc.code, int) else 2
    # the extra, before anything is built: pythonfmu builds the Python FMU (and the builder
    # the native one shares imports it), fmpy validates them and gives the native FMU its
    # FMI headers
    require("pythonfmu", "fmpy", purpose="building an FMU")
    from . import BuildError, build_fmu, build_named, build_native
    from .native import structural_start

    check = not args.no_validate
    try:
        start = dict(item.split("=", 1) for item in args.start)
    except ValueError:
        print("prsm-fmu-build: error: argument --start: must be NAME=VALUE", file=sys.stderr)
        return 2
    problem = structural_start(start) if args.native else ""
    if problem:
        print(f"prsm-fmu-build: error: argument {problem}", file=sys.stderr)
        return 2
    try:
        if args.preset:
            from prsm_fmu import presets
            from prsm_fmu.params import MechanismParams

            if args.names or args.all or not args.name:
                ap.error("argument --preset: needs --name ID and no FMU names or --all")
            if not args.name.isidentifier():
                ap.error(f"argument --name: {args.name!r} is not allowed: must be a valid "
                         "identifier (the FMI modelIdentifier), e.g. PRSM2_seed002")
            try:
                params = presets.load(args.preset)
            except ValueError as exc:
                ap.error(f"argument --preset: {exc}")
            if not isinstance(params, MechanismParams):
                ap.error(f"argument --preset: {args.preset!r} is not a planetary roller screw "
                         "mechanism the FMU can run: must be one of "
                         + ", ".join(n for n in presets.names()
                                     if isinstance(presets.load(n), MechanismParams)))
            if args.native:
                targets = [build_native(args.name, params, args.preset, args.dest, check, start)]
            else:
                targets = [build_fmu(args.name, params, args.preset, args.dest, check, start)]
        else:
            unknown = [n for n in args.names if n not in FMUS]
            if unknown:
                ap.error(f"argument FMU: invalid choice(s) {', '.join(map(repr, unknown))}: "
                         f"must be one of {', '.join(FMUS)} (or use --preset)")
            names = list(FMUS) if args.all else (args.names or ["PRSM2"])
            targets = [build_named(n, args.dest, check, start, native=args.native) for n in names]
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 2
    except (BuildError, ValueError, OSError) as exc:
        print(f"prsm-fmu-build: error: {one_line(exc)}", file=sys.stderr)
        return 1
    for t in targets:
        print(t)
    return 0


if __name__ == "__main__":
    sys.exit(main())
