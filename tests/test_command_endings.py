"""How the console scripts end when they cannot finish: one line, no traceback, nothing
half-written.

* A missing optional extra (fmu: pythonfmu, fmpy; sweep: dask[distributed]) is simulated by a
  folder put first on PYTHONPATH holding a module of that name whose import raises
  ``ModuleNotFoundError`` — so child processes (the FMU build runs in one) miss it too.  Each
  command must answer in one line naming the extra, exit status 1, before it writes anything.
* Ctrl-C: a real SIGINT sent to ``prsm-ema run`` while it computes must end it with one line
  and exit status 130 (128 + SIGINT), with no output file, whole or partial, in its folder.
* A writer interrupted half-way leaves the previous file as it was (temp file + rename).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "studies" / "li2021_friction.toml"     # backend fmu


def _hide(tmp_path: Path, *modules: str) -> dict[str, str]:
    """Environment whose Python cannot import ``modules`` (a stub raising ModuleNotFoundError
    is found before the installed package)."""
    stubs = tmp_path / "hidden"
    stubs.mkdir(exist_ok=True)
    for m in modules:
        (stubs / f"{m}.py").write_text(
            f"raise ModuleNotFoundError(\"No module named '{m}'\", name={m!r})\n",
            encoding="utf-8")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(stubs), str(REPO)]
                                        + [p for p in [env.get("PYTHONPATH")] if p])
    return env


def _run(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], env=env, cwd=cwd, text=True,
                          capture_output=True, timeout=300)


FMU_EXTRA_CASES = [
    (["system_models", "run", "--scene", "load_step", "--out", "OUT"], "prsm-ema"),
    (["system_models", "run", "--scene", "load_step", "--prsm", "native", "--out", "OUT"],
     "prsm-ema"),
    (["fmu_build", "--dest", "OUT"], "prsm-fmu-build"),
    (["prsm_fmu.cli", "regress", "--out", "OUT"], "prsm-fmu"),
    (["prsm_fmu.cli", "sweep", str(STUDY), "--no-dask", "--out", "OUT"], "prsm-fmu"),
]


@pytest.mark.parametrize("args,prog", FMU_EXTRA_CASES, ids=lambda a: " ".join(a)
                         if isinstance(a, list) else a)
def test_without_the_fmu_extra_each_command_names_it_in_one_line(tmp_path, args, prog):
    env = _hide(tmp_path, "pythonfmu", "fmpy")
    out = tmp_path / "out"
    proc = _run([str(out) if a == "OUT" else a for a in args], env, tmp_path)
    err = proc.stderr.strip()
    assert proc.returncode == 1, (proc.returncode, err[-2000:])
    assert "Traceback" not in proc.stderr and len(err.splitlines()) == 1, err
    assert err.startswith(f"{prog}: error: ") and "'fmu' extra" in err, err
    assert 'pip install -e ".[fmu]"' in err
    # refused before anything was written (the sweep's folder is not even made)
    assert not any(p.is_file() for p in out.rglob("*")) if out.exists() else True


def test_without_dask_a_dask_sweep_names_the_sweep_extra_in_one_line(tmp_path):
    env = _hide(tmp_path, "dask", "distributed")
    proc = _run(["prsm_fmu.cli", "sweep", str(STUDY), "--backend", "model", "--out",
                 str(tmp_path / "out")], env, tmp_path)
    err = proc.stderr.strip()
    assert proc.returncode == 1, err[-2000:]
    assert len(err.splitlines()) == 1 and "'sweep' extra" in err and "--no-dask" in err, err


def test_the_plain_python_model_runs_without_the_fmu_extra(tmp_path):
    """``prsm-ema run --prsm python`` needs neither pythonfmu nor fmpy."""
    env = _hide(tmp_path, "pythonfmu", "fmpy")
    out = tmp_path / "out"
    proc = _run(["system_models", "run", "--scene", "load_step", "--prsm", "python",
                 "--no-plots", "--out", str(out)], env, tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (out / "load_step.csv").is_file() and (out / "load_step_summary.json").is_file()


@pytest.mark.parametrize("prsm, group", [("python", False), ("fmu", False), ("python", True)])
def test_ctrl_c_ends_a_run_with_one_line_status_130_and_no_output(tmp_path, prsm, group):
    """SIGINT once the scene runs (its first line printed): one line on stderr, exit 130,
    no CSV/PNG/JSON and no temporary file left in the output folder.  With the pythonfmu FMU
    the interrupt must not land inside the FMU's Python (a fatal FMU error, exit 1).  ``group``:
    sent as a terminal's Ctrl-C is, to the whole process group, the forked figure process too
    (started before the run, importing matplotlib meanwhile): the same one line, and no process
    of the group left."""
    out = tmp_path / "out"
    out.mkdir()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    fmu = []
    if prsm == "fmu":
        pytest.importorskip("pythonfmu")
        from test_fmu import built_fmus
        fmu = ["--fmu", str(built_fmus()["PRSM2"])]
    proc = subprocess.Popen([sys.executable, "-m", "system_models", "run", "--scene",
                             "sine_tracking", "--prsm", prsm, *fmu, "--out", str(out)],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=group)
    try:
        first = proc.stdout.readline()          # "scene sine_tracking: ..." before the run
        assert first.startswith("scene sine_tracking"), first
        time.sleep(0.5)
        if group:
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    errors = [ln for ln in err.strip().splitlines() if not ln.startswith("[")]   # not the bar
    assert "Traceback" not in err and len(errors) == 1, err
    assert errors[0].startswith("prsm-ema: interrupted")
    assert list(out.iterdir()) == []
    if group:
        time.sleep(0.2)
        with pytest.raises(ProcessLookupError):       # the group is empty: every process ended
            os.killpg(proc.pid, 0)


def test_run_command_maps_ctrl_c_and_missing_extras(capsys):
    from prsm_fmu.command import run_command

    def interrupted() -> int:
        raise KeyboardInterrupt

    def missing() -> int:
        raise ModuleNotFoundError("No module named 'fmpy'", name="fmpy")

    def other() -> int:
        raise ModuleNotFoundError("No module named 'nowhere'", name="nowhere")

    assert run_command("prog", interrupted) == 130
    assert run_command("prog", missing) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("prog: interrupted") and "'fmu' extra" in err[1]
    with pytest.raises(ModuleNotFoundError):       # not an extra's module: not hidden
        run_command("prog", other)


def test_a_writer_interrupted_half_way_leaves_the_old_file(tmp_path):
    """system_models.output.write_csv interrupted after the header: the previous CSV is intact
    and no temporary file is left (the old code truncated it first)."""
    import numpy as np

    from system_models.master import Result
    from system_models.output import write_csv

    class Interrupting(Result):
        def __getitem__(self, name):
            if name == "b":
                raise KeyboardInterrupt
            return super().__getitem__(name)

    path = tmp_path / "run.csv"
    path.write_text("old,contents\n1,2\n", encoding="utf-8")
    t = np.linspace(0.0, 1.0, 5)
    res = Interrupting(t, {"a": t, "b": 2 * t}, {"a": "m", "b": "m"})
    with pytest.raises(KeyboardInterrupt):
        write_csv(res, path)
    assert path.read_text(encoding="utf-8") == "old,contents\n1,2\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv"]


def test_a_run_stopped_by_a_too_large_step_names_the_stability_limit(tmp_path, capsys):
    """load_step (Gauss–Seidel, extrapolation 1, the default 2e5 N/m, 1e3 N.s/m load) at
    h = 1 ms, 10x its own step: the drive trips; the message must name the step as the likely
    cause with the limit the coupling analysis predicts for that loop, and its suggested step
    must run the scene through (every check passing)."""
    import re

    from system_models.cli import main
    from system_models.coupling_analysis import predicted_stable_step

    out = tmp_path / "out"
    code = main(["run", "--scene", "load_step", "--prsm", "python", "--step", "1e-3",
                 "--no-plots", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1, err
    assert "refused the step" in err and "likely cause: the communication step h = 0.001 s" \
        in err, err
    limit = float(re.search(r"stability limit (\S+) s", err).group(1))
    assert limit == pytest.approx(predicted_stable_step("gauss-seidel", 1, 2e5, 1e3), rel=5e-3)
    assert limit < 1e-3
    suggested = float(re.search(r"--step (\S+)$", err).group(1))
    assert suggested <= limit
    assert main(["run", "--scene", "load_step", "--prsm", "python", "--step", f"{suggested!r}",
                 "--no-plots", "--out", str(out)]) == 0


def test_a_failed_fmu_build_in_a_child_is_reported_in_one_line(tmp_path, monkeypatch):
    """regress and sweep build their FMUs in a child process; its failure (here: the child
    cannot import pythonfmu, hidden from it by PYTHONPATH) comes back as one line with the
    child's exit status and its own one-line error, not its whole output squeezed together."""
    pytest.importorskip("pythonfmu")
    from prsm_fmu.regress.core import build_fmu
    from prsm_fmu.sweep.execute import ensure_fmus

    monkeypatch.setenv("PYTHONPATH", _hide(tmp_path, "pythonfmu")["PYTHONPATH"])
    for build in (lambda: build_fmu(tmp_path / "a"),
                  lambda: ensure_fmus([2], str(tmp_path / "b"))):
        with pytest.raises(RuntimeError) as info:
            build()
        text = str(info.value)
        assert "\n" not in text and "Traceback" not in text, text
        assert "exit status 1" in text and "'fmu' extra" in text, text


def test_atomic_outputs_get_the_mode_a_plain_open_gives(tmp_path):
    """The renamed output (atomic_path, and write_atomic's bytes) must have the mode open()
    gives a new file (0666 less the umask), as before, not a temporary file's private 0600."""
    from prsm_fmu.atomic import atomic_path, write_atomic

    plain = tmp_path / "plain.txt"
    plain.write_text("x", encoding="utf-8")
    with atomic_path(tmp_path / "atomic.txt") as part:
        Path(part).write_text("x", encoding="utf-8")
    assert (tmp_path / "atomic.txt").stat().st_mode == plain.stat().st_mode
    write_atomic(tmp_path / "bytes.txt", [b"x"])
    assert (tmp_path / "bytes.txt").stat().st_mode == plain.stat().st_mode


def test_ctrl_c_ends_a_dask_sweep_with_one_line_and_keeps_the_finished_points(tmp_path):
    """A terminal's Ctrl-C reaches the whole process group (the Dask workers too): SIGINT to
    the group once the first point is written ends the study with one line, status 130, no
    worker traceback; the points written so far are complete (the table reads, every series
    loads)."""
    pytest.importorskip("dask.distributed")
    import numpy as np

    from prsm_fmu.sweep.table import read_table

    out = tmp_path / "out"
    series = out / "friction_load" / "series"
    proc = subprocess.Popen([sys.executable, "-m", "prsm_fmu.cli", "sweep",
                             str(REPO / "studies" / "friction_load.toml"), "--workers", "1",
                             "--quiet", "--out", str(out)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and not (series.is_dir()
                                                    and any(series.glob("*.npz"))):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.2)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-3000:]
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err[-3000:]
    header, rows = read_table(str(out / "friction_load" / "results.csv"))
    assert header and all(r["status"] == "ok" for r in rows)
    for f in series.glob("*.npz"):
        with np.load(f) as z:
            assert "time" in z.files
    assert not list(out.rglob("*.part*"))
    print(f"interrupted after {len(rows)} of 8 points")


def test_ctrl_c_stops_regress_instead_of_failing_the_case_and_going_on():
    """regress runs the pythonfmu FMU in this process: a Ctrl-C that lands inside the FMU's
    Python was its fatal error, recorded as a failing case, and the next case ran.  Now the
    interrupt is held to the next macro step and ends the check (SIGINT sent to this process
    0.5 s into the longest case, sine_tracking: 10 000 steps of the Python master, ~0.6 s;
    the C loop, regress's default, is below)."""
    pytest.importorskip("pythonfmu")
    import threading

    from test_fmu import built_fmus

    from prsm_fmu.regress import core

    fmu = built_fmus()["PRSM2"]
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    t0 = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            core.check(fmu, cases=["sine_tracking", "load_step"], loop="python")
    finally:
        timer.cancel()
    assert time.monotonic() - t0 < 30.0


def test_ctrl_c_stops_regress_on_the_c_loop_too(monkeypatch):
    """With the C loop (10 000 steps of sine_tracking in ~0.1 s: too short to aim a timer at)
    the interrupt is looked at between its chunks of macro steps: a SIGINT that came as the
    first case began ends the check there, and the second case never starts."""
    pytest.importorskip("pythonfmu")
    from test_fmu import built_fmus

    from prsm_fmu.regress import core

    started = []
    simulate = core.simulate_case

    def interrupted_at_start(case, *args, **kwargs):
        started.append(case.name)
        os.kill(os.getpid(), signal.SIGINT)
        return simulate(case, *args, **kwargs)

    monkeypatch.setattr(core, "simulate_case", interrupted_at_start)
    with pytest.raises(KeyboardInterrupt):
        core.check(built_fmus()["PRSM2"], cases=["sine_tracking", "load_step"])
    assert started == ["sine_tracking"]


_ENDS = """
import sys
from prsm_fmu.command import end_process
sys.stdout.write("x" * 100000 + "\\n")      # a pipe: block-buffered, still in the buffer
sys.stderr.write("last words\\n")
end_process(int(sys.argv[1]))
"""


@pytest.mark.parametrize("status", [0, 1, 2, 130])
def test_end_process_flushes_both_streams_and_keeps_the_status(status):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop("PYTHONUNBUFFERED", None)
    proc = subprocess.run([sys.executable, "-c", _ENDS, str(status)], capture_output=True,
                          text=True, env=env, timeout=60)
    assert proc.returncode == status
    assert proc.stdout == "x" * 100000 + "\n" and proc.stderr == "last words\n"


def test_prsm_ema_from_the_shell_ends_with_mains_status_and_all_its_output(tmp_path):
    # python -m system_models (= the prsm-ema script: system_models.cli.entry): every line
    # printed and the status of main, for a success (list: 0) and a refused argument (2)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop("PYTHONUNBUFFERED", None)
    listed = subprocess.run([sys.executable, "-m", "system_models", "list"], cwd=tmp_path,
                            capture_output=True, text=True, env=env, timeout=120)
    from system_models.scenes import list_scenes

    assert listed.returncode == 0
    assert [ln.split()[0] for ln in listed.stdout.splitlines()] == [n for n, _ in list_scenes()]
    bad = subprocess.run([sys.executable, "-m", "system_models", "run", "--scene",
                          "position_step", "--retry", "-1"], cwd=tmp_path, capture_output=True,
                         text=True, env=env, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--retry" in bad.stderr
