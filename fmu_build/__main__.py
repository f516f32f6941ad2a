"""Command line ``prsm-fmu-build`` (also ``python -m fmu_build``): build the PRSM FMUs.

::

    prsm-fmu-build [PRSM1 PRSM2 PRSM3 | --all] [--native [--platform P ...] [--fmi-version V]]
                   [--engine native|python] [--engine-platform P ...] [--dest DIR] [--no-validate]
    prsm-fmu-build --preset NAME --name ID [--native] [--engine native|python] [--dest DIR]

``--native`` builds ``<name>-native.fmu`` instead: the kinematic, quasi-static and dynamic
levels and ``auto`` in C, no Python needed to run it (:mod:`fmu_build.native`), with binaries for linux64,
win64 and darwin64 cross-compiled by Zig's C compiler (``pip install ziglang``), or only the
platforms named by ``--platform``; and ``<name>-native-fmi3.fmu``, the same as FMI 3.0
(:mod:`fmu_build.fmi3`; ``--fmi-version 2`` or ``3`` builds one of them).

A bad argument is answered with one line naming it and its allowed values, exit status 2,
before anything is built (:mod:`prsm_fmu.arguments`); a failed build exits with 1.
"""

from __future__ import annotations

import sys

from prsm_fmu.arguments import ArgumentParser, one_line, writable_dir
from prsm_fmu.command import run_command
from prsm_fmu.extras import require

from .mechanisms import FMUS
from .platforms import FMI2_PLATFORMS, PYTHONFMU_PLATFORMS

DESCRIPTION = ("Build the planetary roller screw FMUs (FMI 2.0 co-simulation, pythonfmu) into "
               "DIR: PRSM2 by default, any of the standard FMUs by name or all with --all, or "
               "an FMU from any preset of prsm_fmu.presets with --preset NAME --name ID (ID "
               "is the FMI modelIdentifier, e.g. PRSM2_assembly). Each FMU is checked with "
               "fmpy validate and the project's modelDescription rules unless --no-validate. "
               "With --native: the native C FMU <name>-native.fmu (kinematic, quasi-static and "
               "dynamic levels and auto; runs without Python), with binaries for linux64 (glibc 2.17 "
               "and later), win64 and darwin64 (x86_64 and arm64), cross-compiled with Zig's C "
               "compiler (pip install ziglang), and its FMI 3.0 twin <name>-native-fmi3.fmu. "
               "Also runs as 'python -m fmu_build'.")


def build_parser() -> ArgumentParser:
    """The argument parser of ``prsm-fmu-build``."""
    ap = ArgumentParser(prog="prsm-fmu-build", description=DESCRIPTION)
    ap.add_argument("names", nargs="*", metavar="FMU",
                    help=f"FMUs to build, of {', '.join(FMUS)} (default: PRSM2)")
    ap.add_argument("--all", action="store_true", help="build every standard FMU")
    ap.add_argument("--preset", help="build from this preset of prsm_fmu.presets instead")
    ap.add_argument("--name", help="FMU name (modelIdentifier) for --preset, e.g. PRSM2_assembly")
    ap.add_argument("--dest", type=writable_dir, default="dist", metavar="DIR",
                    help="output directory (default: dist)")
    ap.add_argument("--start", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter start value other than the preset's, e.g. "
                         "fidelity=dynamic (for hosts that cannot set it); repeatable")
    ap.add_argument("--native", action="store_true",
                    help="build the native C FMU <name>-native.fmu (kinematic, quasi-static and "
                         "dynamic levels and auto; needs ziglang) instead of the Python one")
    ap.add_argument("--engine-platform", action="append", choices=PYTHONFMU_PLATFORMS,
                    metavar="P", help="also pack the Python FMU's engine for platform P, of "
                    f"{', '.join(PYTHONFMU_PLATFORMS)} (cross-compiled with Zig; a machine's "
                    "first win64 build compiles Zig's Windows runtime, minutes); repeatable")
    ap.add_argument("--engine", choices=("native", "python"), default="native",
                    help="what computes the physics of the Python FMU: native (default) packs "
                         "the compiled engine for this platform (needs gcc to build; the "
                         "Python model runs where it cannot, logged), python the Python "
                         "reference model only")
    ap.add_argument("--platform", action="append", choices=FMI2_PLATFORMS, metavar="P",
                    help="with --native: build the binary of this platform only, of "
                         f"{', '.join(FMI2_PLATFORMS)} (default: all); repeatable")
    ap.add_argument("--fmi-version", action="append", choices=["2", "3"], metavar="V",
                    help="with --native: build the FMI V FMU, of 2 (<name>-native.fmu) and 3 "
                         "(<name>-native-fmi3.fmu); default both; repeatable")
    ap.add_argument("--no-validate", action="store_true",
                    help="skip fmpy validate and the modelDescription checks")
    return ap


def _with_fmi3(fmus: list, plats: tuple[str, ...], check: bool, keep_fmi2: bool) -> list:
    """The FMI 3.0 FMU of each FMI 2.0 native FMU in ``fmus`` (:mod:`fmu_build.fmi3`), after it
    or (``keep_fmi2`` false) instead of it."""
    from .fmi3 import build_native_fmi3

    out = []
    for fmu in fmus:
        fmu3 = build_native_fmi3(fmu, check=check, targets=plats)
        if keep_fmi2:
            out.append(fmu)
        else:
            fmu.unlink()
        out.append(fmu3)
    return out


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

    check = not args.no_validate
    try:
        start = dict(item.split("=", 1) for item in args.start)
    except ValueError:
        print("prsm-fmu-build: error: argument --start: must be NAME=VALUE", file=sys.stderr)
        return 2
    if args.platform and not args.native:
        print("prsm-fmu-build: error: argument --platform: not allowed without --native: "
              "must be used with --native (the native FMU's binaries)", file=sys.stderr)
        return 2
    if args.fmi_version and not args.native:
        print("prsm-fmu-build: error: argument --fmi-version: not allowed without --native: "
              "must be used with --native (the native FMU's FMI versions)", file=sys.stderr)
        return 2
    plats = tuple(dict.fromkeys(args.platform)) if args.platform else FMI2_PLATFORMS
    versions = set(args.fmi_version or ["2", "3"])
    try:
        if args.preset:
            from prsm_fmu import presets
            from prsm_fmu.params import MechanismParams

            if args.names or args.all or not args.name:
                ap.error("argument --preset: needs --name ID and no FMU names or --all")
            if not args.name.isidentifier():
                ap.error(f"argument --name: {args.name!r} is not allowed: must be a valid "
                         "identifier (the FMI modelIdentifier), e.g. PRSM2_assembly")
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
                targets = [build_native(args.name, params, args.preset, args.dest, check, start,
                                        plats)]
            else:
                targets = [build_fmu(args.name, params, args.preset, args.dest, check, start,
                                     engine=args.engine == "native",
                                     engine_platforms=tuple(args.engine_platform or ()))]
        else:
            unknown = [n for n in args.names if n not in FMUS]
            if unknown:
                ap.error(f"argument FMU: invalid choice(s) {', '.join(map(repr, unknown))}: "
                         f"must be one of {', '.join(FMUS)} (or use --preset)")
            names = list(FMUS) if args.all else (args.names or ["PRSM2"])
            targets = [build_named(n, args.dest, check, start, native=args.native,
                                   engine=args.engine == "native", targets=plats,
                                   engine_platforms=tuple(args.engine_platform or ()))
                       for n in names]
        if args.native and "3" in versions:
            targets = _with_fmi3(targets, plats, check, keep_fmi2="2" in versions)
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
