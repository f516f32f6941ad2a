"""Command line: ``python -m fmu_build [PRSM1 PRSM2 PRSM3 | --all] [--dest DIR]``.

Also ``--preset NAME --name ID`` to build an FMU from any preset of ``prsm_fmu.presets``
(``ID`` is the FMI modelIdentifier, e.g. ``PRSM2_seed002``).
"""

from __future__ import annotations

import argparse
import sys

from . import FMUS, BuildError, build_fmu, build_named


def main(argv: list[str] | None = None) -> int:
    """Build the FMUs named on the command line; return the exit status."""
    ap = argparse.ArgumentParser(prog="python -m fmu_build", description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", metavar="FMU",
                    help=f"FMUs to build, of {', '.join(FMUS)} (default: PRSM2)")
    ap.add_argument("--all", action="store_true", help="build every standard FMU")
    ap.add_argument("--preset", help="build from this preset of prsm_fmu.presets instead")
    ap.add_argument("--name", help="FMU name (modelIdentifier) for --preset, e.g. PRSM2_seed002")
    ap.add_argument("--dest", default="dist", help="output directory (default: dist)")
    ap.add_argument("--start", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter start value other than the preset's, e.g. "
                         "fidelity=dynamic (for hosts that cannot set it); repeatable")
    ap.add_argument("--no-validate", action="store_true",
                    help="skip fmpy validate and the modelDescription checks")
    args = ap.parse_args(argv)
    check = not args.no_validate
    try:
        start = dict(item.split("=", 1) for item in args.start)
    except ValueError:
        ap.error("--start takes NAME=VALUE")
    try:
        if args.preset:
            from prsm_fmu import presets

            if args.names or args.all or not args.name:
                ap.error("--preset needs --name and no FMU names")
            targets = [build_fmu(args.name, presets.load(args.preset), args.preset, args.dest,
                                 check, start)]
        else:
            names = list(FMUS) if args.all else (args.names or ["PRSM2"])
            targets = [build_named(n, args.dest, check, start) for n in names]
    except (BuildError, ValueError) as exc:
        print(f"fmu_build: {exc}", file=sys.stderr)
        return 1
    for t in targets:
        print(t)
    return 0


if __name__ == "__main__":
    sys.exit(main())
