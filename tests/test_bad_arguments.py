"""Every console script answers a bad argument with one line, exit status 2, and nothing else.

A table of bad command lines for ``prsm-fmu`` (every subcommand), ``prsm-fmu-build`` and
``prsm-ema``.  Each is run in-process (``main(argv)``, SystemExit caught) and must:

* end with exit status 2;
* print exactly one line on stderr, ``PROG: error: ...``, naming the argument (the table's
  expected fragment) and what is allowed ("must be", "choose from", "required", ...);
* print no traceback;
* compute nothing: the output directory it was given stays absent.

A few lines go through the installed console scripts (subprocess) to prove the entry points.
The test counts what it tried and reports every line that misbehaved at once.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STUDY = str(ROOT / "studies" / "li2021_friction.toml")
FILE = str(ROOT / "README.md")                 # an existing file that is not a study/FMU/CSV
OUT = "{out}"                                  # replaced by a fresh directory per line

#: what an error line says about the allowed values (one of these must appear; an unknown
#: option has no allowed values to name, the line points to --help for the options)
ALLOWED = re.compile(r"must (?:not )?(?:be|divide|give)|choose from|arguments are required|needs|"
                     r"is not NAME=VALUE|is not two integers|unrecognized arguments")

# (script, argv, fragment the one line must contain)
CASES: list[tuple[str, list[str], str]] = [
    # prsm-fmu: the command itself
    ("prsm-fmu", [], "COMMAND"),
    ("prsm-fmu", ["bogus"], "COMMAND"),
    ("prsm-fmu", ["presets", "extra"], "extra"),
    # startup
    ("prsm-fmu", ["startup", "--speed", "abc", "--out", OUT], "--speed"),
    ("prsm-fmu", ["startup", "--speed", "0", "--out", OUT], "--speed"),
    ("prsm-fmu", ["startup", "--speed", "nan", "--out", OUT], "--speed"),
    ("prsm-fmu", ["startup", "--load", "inf", "--out", OUT], "--load"),
    ("prsm-fmu", ["startup", "--load", "1e3x", "--out", OUT], "--load"),
    ("prsm-fmu", ["startup", "--t-end", "-1", "--out", OUT], "--t-end"),
    ("prsm-fmu", ["startup", "--t-end", "0", "--out", OUT], "--t-end"),
    ("prsm-fmu", ["startup", "--interval", "0", "--out", OUT], "--interval"),
    ("prsm-fmu", ["startup", "--interval", "1e-12", "--out", OUT], "--interval"),
    ("prsm-fmu", ["startup", "--t-end", "1e-3", "--interval", "3e-4", "--out", OUT], "--t-end"),
    ("prsm-fmu", ["startup", "--tolerance", "0", "--out", OUT], "--tolerance"),
    ("prsm-fmu", ["startup", "--tolerance", "2", "--out", OUT], "--tolerance"),
    ("prsm-fmu", ["startup", "--tolerance", "x", "--out", OUT], "--tolerance"),
    ("prsm-fmu", ["startup", "--fidelity", "exact", "--out", OUT], "--fidelity"),
    ("prsm-fmu", ["startup", "--stepper", "euler", "--out", OUT], "--stepper"),
    ("prsm-fmu", ["startup", "--preset", "no_such_preset", "--out", OUT], "--preset"),
    ("prsm-fmu", ["startup", "--preset", "recirculating_screw", "--out", OUT], "--preset"),
    ("prsm-fmu", ["startup", "--out", FILE + "/sub"], "--out"),
    ("prsm-fmu", ["startup", "--bogus", "--out", OUT], "--bogus"),
    # steady
    ("prsm-fmu", ["steady", "--speed", "0"], "--speed"),
    ("prsm-fmu", ["steady", "--speed", "fast"], "--speed"),
    ("prsm-fmu", ["steady", "--load", "nan"], "--load"),
    ("prsm-fmu", ["steady", "--preset", "nope"], "--preset"),
    # sweep
    ("prsm-fmu", ["sweep"], "STUDY"),
    ("prsm-fmu", ["sweep", "missing.toml", "--out", OUT], "STUDY"),
    ("prsm-fmu", ["sweep", FILE, "--out", OUT], "STUDY"),
    ("prsm-fmu", ["sweep", STUDY, "--workers", "0", "--out", OUT], "--workers"),
    ("prsm-fmu", ["sweep", STUDY, "--workers", "-3", "--out", OUT], "--workers"),
    ("prsm-fmu", ["sweep", STUDY, "--workers", "two", "--out", OUT], "--workers"),
    ("prsm-fmu", ["sweep", STUDY, "--backend", "gpu", "--out", OUT], "--backend"),
    ("prsm-fmu", ["sweep", STUDY, "--fmu", "c", "--out", OUT], "--fmu"),
    ("prsm-fmu", ["sweep", STUDY, "--scheduler", "not an address", "--out", OUT], "--scheduler"),
    ("prsm-fmu", ["sweep", STUDY, "--scheduler", "tcp://host:99999", "--out", OUT],
     "--scheduler"),
    ("prsm-fmu", ["sweep", STUDY, "--scheduler", "http://host:8786", "--out", OUT],
     "--scheduler"),
    ("prsm-fmu", ["sweep", STUDY, "--scheduler", "tcp://h:8786", "--no-dask", "--out", OUT],
     "--scheduler"),
    ("prsm-fmu", ["sweep", STUDY, "--workers", "2", "--no-dask", "--out", OUT], "--workers"),
    ("prsm-fmu", ["sweep", STUDY, "--fmu-dir", "/no/such/dir", "--out", OUT], "--fmu-dir"),
    ("prsm-fmu", ["sweep", STUDY, "--out", FILE + "/sub"], "--out"),
    # check
    ("prsm-fmu", ["check"], "PRESET"),
    ("prsm-fmu", ["check", "nope"], "PRESET"),
    ("prsm-fmu", ["check", "recirculating_screw"], "PRESET"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--load", "-5"], "--load"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--load", "5kN"], "--load"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--length", "0"], "--length"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--material", "wood"], "--material"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--safety-factor", "0.5"], "--safety-factor"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--stability-factor", "nan"],
     "--stability-factor"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--ends", "glued"], "--ends"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--sections", "1,2,3"], "--sections"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--sections", "a,b"], "--sections"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--teeth", "1"], "--teeth"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--teeth", "0,5"], "--teeth"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "screw_radius"], "--set"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "load_force=3"], "--set"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "stage[1].screw_radius=-1"],
     "stage[1].screw_radius"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "stage[2].roller_inertia=0"],
     "stage[2].roller_inertia"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "stage[1].flank_angle=2"],
     "stage[1].flank_angle"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "stage[1].screw_starts=0"],
     "stage[1].screw_starts"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "stage[1].screw_starts=2.5"],
     "stage[1].screw_starts"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "stage[3].screw_radius=0.01"],
     "stage[3]"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "mu_spline=2"], "mu_spline"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "mu_spline=abc"], "--set"),
    ("prsm-fmu", ["check", "kinematics_two_stage", "--set", "slip_velocity_scale=-1e-4"],
     "slip_velocity_scale"),
    # regress (all found before an FMU is built)
    ("prsm-fmu", ["regress", "--fmu", "/no/such.fmu", "--out", OUT], "--fmu"),
    ("prsm-fmu", ["regress", "--fmu", FILE, "--out", OUT], "--fmu"),
    ("prsm-fmu", ["regress", "--case", "no_such_case", "--out", OUT], "--case"),
    ("prsm-fmu", ["regress", "--baselines", "/no/such/dir", "--out", OUT], "--baselines"),
    ("prsm-fmu", ["regress", "--set", "novalue", "--out", OUT], "--set"),
    ("prsm-fmu", ["regress", "--update", "--set", "mu_spline=0.2", "--out", OUT], "--update"),
    ("prsm-fmu", ["regress", "--out", FILE + "/sub"], "--out"),
    ("prsm-fmu", ["regress", "--loop", "fast", "--out", OUT], "--loop"),
    ("prsm-fmu", ["regress", "--fmu", "{fmu}", "--set", "no_such=1", "--out", OUT], "no_such"),
    ("prsm-fmu", ["regress", "--fmu", "{fmu}", "--set", "mu_spline=1.5", "--out", OUT],
     "mu_spline"),
    ("prsm-fmu", ["regress", "--fmu", "{fmu}", "--set", "rod_position=1", "--out", OUT],
     "rod_position"),
    # plot
    ("prsm-fmu", ["plot"], "RESULT"),
    ("prsm-fmu", ["plot", "missing.csv", "--fmu", "{fmu}"], "RESULT"),
    ("prsm-fmu", ["plot", FILE, "--fmu", "{fmu}", "--out", OUT + "/r.png"], "RESULT"),
    ("prsm-fmu", ["plot", "{csv}", "--fmu", FILE, "--out", OUT + "/r.png"], "--fmu"),
    ("prsm-fmu", ["plot", "{csv}", "--fmu", "{fmu}", "--out", OUT + "/r.pdf"], "--out"),
    ("prsm-fmu", ["plot", "{csv}", "--fmu", "{fmu}", "--variables", "nothing",
                  "--out", OUT + "/r.png"], "--variables"),
    # prsm-fmu-build
    ("prsm-fmu-build", ["PRSM9", "--dest", OUT], "FMU"),
    ("prsm-fmu-build", ["--bogus", "--dest", OUT], "--bogus"),
    ("prsm-fmu-build", ["--preset", "nope", "--name", "X", "--dest", OUT], "--preset"),
    ("prsm-fmu-build", ["--preset", "li2021_two_stage", "--dest", OUT], "--preset"),
    ("prsm-fmu-build", ["--preset", "li2021_two_stage", "--name", "2bad", "--dest", OUT],
     "--name"),
    ("prsm-fmu-build", ["--preset", "recirculating_screw", "--name", "R", "--dest", OUT],
     "--preset"),
    ("prsm-fmu-build", ["--dest", FILE + "/sub"], "--dest"),
    # the native FMU's platforms: FMI 2.0 folder names of the ones built; only with --native
    ("prsm-fmu-build", ["--native", "--platform", "win32", "--dest", OUT], "--platform"),
    ("prsm-fmu-build", ["--platform", "win64", "--dest", OUT], "--platform"),
    ("prsm-fmu-build", ["--native", "--fmi-version", "1", "--dest", OUT], "--fmi-version"),
    ("prsm-fmu-build", ["--fmi-version", "3", "--dest", OUT], "--fmi-version"),
    # prsm-ema
    ("prsm-ema", [], "COMMAND"),
    ("prsm-ema", ["fly"], "COMMAND"),
    ("prsm-ema", ["list", "extra"], "extra"),
    ("prsm-ema", ["run", "--out", OUT], "--scene"),
    ("prsm-ema", ["run", "--scene", "no_such_scene", "--out", OUT], "--scene"),
    ("prsm-ema", ["run", "--scene", "position_step", "--step", "abc", "--out", OUT], "--step"),
    ("prsm-ema", ["run", "--scene", "position_step", "--step", "0", "--out", OUT], "--step"),
    ("prsm-ema", ["run", "--scene", "position_step", "--step", "-1e-4", "--out", OUT], "--step"),
    ("prsm-ema", ["run", "--scene", "position_step", "--step", "nan", "--out", OUT], "--step"),
    ("prsm-ema", ["run", "--scene", "position_step", "--step", "inf", "--out", OUT], "--step"),
    ("prsm-ema", ["run", "--scene", "position_step", "--step", "10", "--prsm", "python",
                  "--out", OUT], "--step"),
    ("prsm-ema", ["run", "--scene", "position_step", "--retry", "1000", "--out", OUT],
     "--retry"),
    ("prsm-ema", ["run", "--scene", "position_step", "--retry", "-1", "--out", OUT], "--retry"),
    ("prsm-ema", ["run", "--scene", "position_step", "--retry", "x", "--out", OUT], "--retry"),
    ("prsm-ema", ["run", "--scene", "position_step", "--extrapolation", "2", "--out", OUT],
     "--extrapolation"),
    ("prsm-ema", ["run", "--scene", "position_step", "--extrapolation", "one", "--out", OUT],
     "--extrapolation"),
    ("prsm-ema", ["run", "--scene", "position_step", "--fidelity", "exact", "--out", OUT],
     "--fidelity"),
    ("prsm-ema", ["run", "--scene", "position_step", "--prsm", "modelica", "--out", OUT],
     "--prsm"),
    ("prsm-ema", ["run", "--scene", "position_step", "--order", "random", "--out", OUT],
     "--order"),
    ("prsm-ema", ["run", "--scene", "position_step", "--fmu", "/no/such.fmu", "--out", OUT],
     "--fmu"),
    ("prsm-ema", ["run", "--scene", "position_step", "--prsm", "python", "--out",
                  FILE + "/sub"], "--out"),
    # the native FMU runs the kinematic, quasi-static and dynamic levels (auto is refused
    # before a build)
    ("prsm-ema", ["run", "--scene", "position_step", "--prsm", "native", "--fidelity", "auto",
                  "--out", OUT], "--prsm native: fidelity 'auto'"),
    # startup and steady: the screw speed and the tolerance within the FMU's parameter ranges
    # (initial_screw_speed, tolerance; test_startup_bounds_are_the_fmus below)
    ("prsm-fmu", ["startup", "--speed", "1e7", "--out", OUT], "--speed"),
    ("prsm-fmu", ["startup", "--speed=-2e4", "--out", OUT], "--speed"),
    ("prsm-fmu", ["steady", "--speed", "1e5"], "--speed"),
    ("prsm-fmu", ["startup", "--tolerance", "1e-13", "--out", OUT], "--tolerance"),
]

#: lines run through the installed console scripts as well (every script, a few each)
SUBPROCESS = [0, 3, 29, 42, 80, 81, 86, 88, 93, 99]


def _main(script: str):
    if script == "prsm-fmu":
        from prsm_fmu.cli import main
    elif script == "prsm-fmu-build":
        from fmu_build.__main__ import main
    else:
        from system_models.cli import main
    return main


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, str]:
    """A minimal FMU file (a zip with a modelDescription: one bounded parameter, one output)
    and a result CSV, for the lines that need existing inputs; nothing is built."""
    d = tmp_path_factory.mktemp("inputs")
    fmu = d / "Tiny.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Tiny" guid="{0}">
  <ModelVariables>
    <ScalarVariable name="mu_spline" valueReference="0" causality="parameter"
                    variability="fixed"><Real start="0.1" min="0" max="1" unit="1"/></ScalarVariable>
    <ScalarVariable name="rod_position" valueReference="1" causality="output"
                    variability="continuous"><Real unit="m"/></ScalarVariable>
  </ModelVariables>
</fmiModelDescription>""")
    csv_path = d / "result.csv"
    csv_path.write_text('"time","rod_position"\n0.0,0.0\n0.1,0.01\n', encoding="utf-8")
    return {"fmu": str(fmu), "csv": str(csv_path)}


def _argv(argv: list[str], out: Path, files: dict[str, str]) -> list[str]:
    return [a.replace(OUT, str(out)).replace("{fmu}", files["fmu"]).replace("{csv}", files["csv"])
            for a in argv]


def _problems(code, err: str, fragment: str, out: Path) -> list[str]:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    found = []
    if code != 2:
        found.append(f"exit status {code!r}, not 2")
    if "Traceback" in err:
        found.append("a traceback")
    if len(lines) != 1:
        found.append(f"{len(lines)} lines on stderr, not 1")
    elif not (": error: " in lines[0] and fragment in lines[0] and ALLOWED.search(lines[0])):
        found.append(f"the line does not name {fragment!r} and what is allowed")
    if out.exists():
        found.append(f"{out} was written")
    return found


def test_every_bad_command_line_gets_one_line_and_status_2(tmp_path, files, monkeypatch):
    monkeypatch.chdir(tmp_path)              # prsm-ema looks for ./scenes; defaults write here
    tried, failures = 0, []
    for i, (script, argv, fragment) in enumerate(CASES):
        out = tmp_path / f"out{i}"
        args = _argv(argv, out, files)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = _main(script)(args)
            except SystemExit as exc:
                code = exc.code
            except Exception as exc:  # noqa: BLE001 - recorded as a failure of this line
                code = f"{type(exc).__name__}: {exc}"
                err.write("Traceback (raised out of main)\n")
        tried += 1
        problems = _problems(code, err.getvalue(), fragment, out)
        if problems:
            failures.append(f"[{i}] {script} {' '.join(args)}: {'; '.join(problems)}\n"
                            f"      stderr: {err.getvalue().strip()!r}")
    print(f"tried {tried} bad command lines in-process: {tried - len(failures)} answered right")
    assert tried == len(CASES) >= 100
    assert not failures, f"{len(failures)} of {tried} bad command lines:\n" + "\n".join(failures)


def test_the_console_scripts_answer_the_same_way(tmp_path, files):
    """The installed entry points (next to this interpreter) give the same one line."""
    bindir = Path(sys.executable).parent
    tried, failures = 0, []
    for i in SUBPROCESS:
        script, argv, fragment = CASES[i]
        exe = bindir / script
        if not exe.exists():
            exe = shutil.which(script)
        assert exe, f"console script {script} is not installed"
        out = tmp_path / f"out{i}"
        proc = subprocess.run([str(exe), *_argv(argv, out, files)], capture_output=True,
                              text=True, cwd=tmp_path, timeout=120,
                              env={**os.environ, "PYTHONWARNINGS": "ignore"})
        tried += 1
        problems = _problems(proc.returncode, proc.stderr, fragment, out)
        if problems or proc.stdout.strip():
            failures.append(f"[{i}] {script} {' '.join(argv)}: {problems}, stdout "
                            f"{proc.stdout!r}, stderr {proc.stderr!r}")
    print(f"tried {tried} bad command lines through the console scripts")
    assert tried == len(SUBPROCESS)
    assert {CASES[i][0] for i in SUBPROCESS} == {"prsm-fmu", "prsm-fmu-build", "prsm-ema"}
    assert not failures, "\n".join(failures)


def test_startup_bounds_are_the_fmus(tmp_path):
    """``startup --speed`` and ``--tolerance`` are refused exactly outside the ranges the FMU
    declares for initial_screw_speed and tolerance (read from a built FMU's modelDescription,
    not from the code): just outside each bound is refused naming the bound; the bound itself
    parses."""
    pytest.importorskip("pythonfmu")
    from test_fmu import built_fmus

    from prsm_fmu.cli import build_parser
    from prsm_fmu.fmu_variables import fmu_variables

    v = fmu_variables(built_fmus()["PRSM2"])
    speed, tol = v["initial_screw_speed"], v["tolerance"]
    parser = build_parser()
    for option, value, ok in [("--speed", speed.max, True), ("--speed", speed.min, True),
                              ("--speed", speed.max * (1 + 1e-9), False),
                              ("--speed", speed.min * (1 + 1e-9), False),
                              ("--tolerance", tol.min, True), ("--tolerance", tol.max, True),
                              ("--tolerance", tol.min * (1 - 1e-9), False),
                              ("--tolerance", tol.max * (1 + 1e-9), False)]:
        argv = ["startup", f"{option}={value!r}", "--out", str(tmp_path / "o")]
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            try:
                parser.parse_args(argv)
                code = 0
            except SystemExit as exc:
                code = exc.code
        assert (code == 0) == ok, (argv, err.getvalue())
        if not ok:
            lo = speed.min if option == "--speed" else tol.min
            hi = speed.max if option == "--speed" else tol.max
            assert f"[{lo:g}, {hi:g}]" in err.getvalue(), err.getvalue()

