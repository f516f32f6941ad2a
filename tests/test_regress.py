"""Regression of the FMU's outputs against the stored baselines (issue 6, prsm_fmu.regress).

* the tube itself on synthetic signals (value and time tolerance);
* ``prsm-fmu regress`` builds the FMU in a child process and every case passes (a rebuilt FMU
  with no change passes); a second run uses that FMU, one older than its sources is stale;
* the FMU carries the baselines in ``extra/baselines`` and they check the same way;
* µ_SR + 1 % (an FMU start value changed for the run, the baselines untouched) fails exactly on
  the outputs friction acts on and passes on those it cannot reach (table in the module);
* ``--update`` writes a report naming an output that moved;
* the speed-ups change no number: every case's outputs through the C loop with one shared
  extraction of the FMU are the Python master's with an extraction per case, bit for bit.
"""

from __future__ import annotations

import os
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import built_fmus  # noqa: E402 - one FMU build per session

from prsm_fmu import cli, regress  # noqa: E402
from prsm_fmu.regress import core  # noqa: E402
from prsm_fmu.regress.report import write_report  # noqa: E402
from prsm_fmu.regress.tube import Tolerance, compare  # noqa: E402

BASELINES = Path(__file__).resolve().parents[1] / "baselines"

#: outputs µ_SR acts on directly: the friction torque at the screw-roller thread changes the
#: torque the motor must give, hence its current, the driven torques, the contact forces (the
#: friction component of the thread force), the spline friction they cause, the efficiency,
#: friction power and work
FRICTION = {"motor.torque", "motor.current", "prsm.stage[1].driven_torque",
            "prsm.stage[2].driven_torque", "prsm.stage[1].contact_force",
            "prsm.stage[2].contact_force", "prsm.stage[2].spline_friction", "prsm.efficiency",
            "prsm.friction_power", "prsm.friction_work"}
RATIOS = {"prsm.stage[1].carrier_speed_ratio", "prsm.stage[2].carrier_speed_ratio"}


def expected(case: str, output: str) -> bool | None:
    """Expected verdict under µ_SR + 1 %: True pass, False fail, None not asserted.

    * kinematic level: no thread friction, nothing may change;
    * the reference is a prescribed profile; the quasi-static carrier ratio is the contact
      geometry's equilibrium (independent of µ); the start-up's load is a pure 5 kN force;
    * the dynamic carriers spin up under the friction torque: their ratios must fail;
    * the loop-held outputs (screw speed, rod position and velocity, load force in the loop
      scenes) change by what the controller lets through: reported, not asserted.
    """
    if case == "startup_li2021_kinematic":
        return True
    if output == "controller.reference":
        return True
    if output in RATIOS:
        return case != "startup_li2021_dynamic"
    if output == "load.force" and case.startswith("startup"):
        return True
    if output in FRICTION:
        return False
    return None


def test_tube_value_and_time_tolerance():
    t = np.linspace(0.0, 1.0, 1001)
    y = np.where(t < 0.5, 0.0, 1.0)                       # a jump at 0.5 s
    shifted = np.where(t < 0.5015, 0.0, 1.0)               # 1.5 ms later
    ok, *_ = compare("y", t, y, t, shifted, Tolerance(abs=1e-3, rel=0.0, dt=2e-3))
    assert ok.passed
    bad, *_ = compare("y", t, y, t, shifted, Tolerance(abs=1e-3, rel=0.0, dt=1e-3))
    assert not bad.passed and bad.first_out == pytest.approx(0.501)
    y2 = np.sin(t)
    r, *_ = compare("y", t, y2, t, y2 + 2e-3 * (t > 0.7), Tolerance(abs=1e-3, rel=0.0, dt=0.0))
    assert not r.passed and r.first_out == pytest.approx(0.7, abs=1.1e-3)
    assert r.excess == pytest.approx(1e-3, rel=1e-9)
    r, *_ = compare("y", t, y2, t, y2 * (1 + 1e-3), Tolerance(abs=0.0, rel=1.1e-3, dt=0.0))
    assert r.passed
    r, *_ = compare("y", t, y2, t[:500], y2[:500], Tolerance(abs=1.0, rel=0.0, dt=0.0))
    assert not r.passed and "covers" in r.reason


def test_tube_with_undefined_samples():
    """The efficiency is NaN where no power flows: a baseline NaN is not compared (a run
    value there passes), a run NaN where the baseline is defined fails, and NaN samples of
    the baseline do not spoil the tube's scale (Case.tolerance) or its neighbours' edges."""
    t = np.linspace(0.0, 1.0, 101)
    y = np.where((t > 0.3) & (t < 0.4), np.nan, 0.5 + 0.1 * t)
    case = core.Case("c", "scene", None, abs_frac=1e-2, rel=0.0, dt=0.0)
    tol = case.tolerance("prsm.efficiency", y)
    # abs = 1e-2 × max|y| over the defined samples = 1e-2 × (0.5 + 0.1 × 1.0) = 6e-3
    assert tol.abs == pytest.approx(6e-3, rel=1e-12)
    same, *_ = compare("e", t, y, t, y.copy(), tol)
    assert same.passed
    # the run's times differ from the baseline's by the CSV's rounding (1e-13 s here): a NaN
    # sample must not spread to its neighbours through the interpolation
    shifted, *_ = compare("e", t, y, t + 1e-13, y.copy(), tol)
    assert shifted.passed, shifted.reason
    filled = np.where(np.isnan(y), 0.9, y)                 # defined where the baseline is not
    r, *_ = compare("e", t, y, t, filled, tol)
    assert r.passed
    lost = y.copy()
    lost[70] = np.nan                                      # undefined where the baseline is not
    r, *_ = compare("e", t, y, t, lost, tol)
    assert not r.passed and r.first_out == pytest.approx(0.7) and r.n_out == 1
    off = y + 1e-2 * (t > 0.8)                             # 1e-2 > 6e-3 after 0.8 s
    r, *_ = compare("e", t, y, t, off, tol)
    assert not r.passed and r.first_out == pytest.approx(0.81, abs=1e-9)
    # time tolerance: the NaN samples take the edges of defined neighbours within dt
    r, *_ = compare("e", t, y, t, filled, Tolerance(abs=6e-3, rel=0.0, dt=0.02))
    assert not r.passed                                    # 0.9 is far from 0.53..0.54
    # ... and a run undefined one sample (0.01 s) beyond the baseline's undefined span passes
    # with dt = 0.02 s (the span shifted in time), fails with dt = 0
    late = y.copy()
    late[40] = np.nan                                      # the baseline's NaN ends at 0.39 s
    r, *_ = compare("e", t, y, t, late, Tolerance(abs=6e-3, rel=0.0, dt=0.02))
    assert r.passed
    r, *_ = compare("e", t, y, t, late, Tolerance(abs=6e-3, rel=0.0, dt=0.0))
    assert not r.passed and r.first_out == pytest.approx(0.4)


def test_regress_builds_and_a_rebuilt_fmu_passes(tmp_path, capsys):
    """The command itself: FMU built in a child process, every case inside its tubes; a second
    run uses that FMU, and one dated before its sources would be built again."""
    code = cli.main(["regress", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "PASS: 7 cases" in out
    fmu = tmp_path / "fmu" / "PRSM2.fmu"
    assert fmu.is_file() and "(missing;" in out
    assert not (tmp_path / "report.html").exists()
    built = fmu.stat().st_mtime_ns
    assert cli.main(["regress", "--out", str(tmp_path), "--case", "startup_li2021_kinematic"]) == 0
    again = capsys.readouterr().out
    assert f"using {fmu}" in again and "building" not in again, again
    assert fmu.stat().st_mtime_ns == built                # not rewritten
    os.utime(fmu, (0, 0))                                 # 1970: older than every source
    assert regress.why_build(fmu).startswith("older than ")


def _renamed_output(src: Path, dest: Path, old: str, new: str) -> Path:
    """A copy of the FMU ``src`` whose modelDescription calls the variable ``old`` ``new``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(f'name="{old}"'.encode(), f'name="{new}"'.encode())
            zout.writestr(item, data)
    return dest


def test_regress_refuses_an_fmu_that_does_not_fit_before_running(tmp_path, capsys):
    """--fmu of the wrong stage count, or lacking an output the baselines compare: one line
    naming --fmu and the mismatch, exit status 2, no case run (no verdict row, no report)."""
    fmus = built_fmus()
    code = cli.main(["regress", "--fmu", str(fmus["PRSM3"]), "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert code == 2
    assert len(cap.err.strip().splitlines()) == 1 and "--fmu" in cap.err
    assert "3-stage" in cap.err and "2-stage" in cap.err, cap.err
    assert "startup_li2021" not in cap.out and not (tmp_path / "report.html").exists()

    odd = _renamed_output(fmus["PRSM2"], tmp_path / "PRSM2_odd.fmu", "friction_power",
                          "friction_power_W")
    code = cli.main(["regress", "--fmu", str(odd), "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert code == 2
    assert len(cap.err.strip().splitlines()) == 1 and "no output friction_power" in cap.err
    assert "startup_li2021" not in cap.out and not (tmp_path / "report.html").exists()


def test_fmu_carries_the_baselines():
    fmus = built_fmus()
    with zipfile.ZipFile(fmus["PRSM2"]) as z:
        names = set(z.namelist())
        for f in list(BASELINES.glob("*.csv")) + [BASELINES / "tolerances.toml"]:
            assert z.read(f"extra/baselines/{f.name}") == f.read_bytes(), f.name
        readme = z.read("extra/baselines/README.md").decode()
    assert "prsm-fmu regress --fmu PRSM2.fmu --baselines PRSM2.fmu" in readme
    assert {f"extra/baselines/{c.name}.csv" for c in regress.load_cases(BASELINES)} <= names
    with zipfile.ZipFile(fmus["PRSM1"]) as z:
        assert not any(n.startswith("extra/baselines") for n in z.namelist())


def test_mu_sr_plus_one_percent_fails_where_it_should(tmp_path):
    """µ_SR + 1 % as a start value of the run; baselines read from inside the FMU."""
    from system_models.prsm import PRSMConfig

    fmu = built_fmus()["PRSM2"]
    mu = PRSMConfig("PRSM2", {}).params().mu_screw_roller
    results = regress.check(fmu, fmu, parameters={"mu_screw_roller": 1.01 * mu})
    assert [r.case.name for r in results] == [c.name for c in regress.load_cases(BASELINES)]
    wrong = []
    for cr in results:
        assert not cr.error, cr.error
        for name, passed in cr.verdicts().items():
            want = expected(cr.case.name, name)
            if want is not None and want != passed:
                wrong.append((cr.case.name, name, "pass" if passed else "FAIL"))
    assert not wrong, wrong
    assert results[0].passed and not any(cr.passed for cr in results[1:])
    # the report of one failing case: a table and a tube plot per output outside its tube
    rev = next(cr for cr in results if cr.case.name == "speed_reversal")
    html = write_report([rev], tmp_path).read_text()
    assert "FAIL" in html and "prsm.friction_power" in html
    assert (tmp_path / "speed_reversal__prsm.friction_power.png").stat().st_size > 1000


def test_update_reports_what_changed(tmp_path):
    fmu = built_fmus()["PRSM2"]
    where = tmp_path / "baselines"
    where.mkdir()
    shutil.copy(BASELINES / "tolerances.toml", where)
    name = "startup_li2021_quasi-static"
    base = core.read_csv((BASELINES / f"{name}.csv").read_text(encoding="utf-8"))
    moved = dict(base.values)
    moved["prsm.efficiency"] = moved["prsm.efficiency"] * 1.01      # an "old" baseline 1 % off
    core.write_csv(where / f"{name}.csv", base.time, moved, base.units)
    text = regress.update(fmu, where, [name, "startup_li2021_kinematic"])
    assert "**prsm.efficiency** left the old tube" in text
    assert "startup_li2021_kinematic\n\nNew baseline" in text
    assert (where / "REPORT.md").read_text(encoding="utf-8") == text
    new = core.read_csv((where / f"{name}.csv").read_text(encoding="utf-8"))
    assert np.allclose(new.values["prsm.efficiency"], base.values["prsm.efficiency"],
                       rtol=1e-11, atol=0)


def _same_bits(a, b) -> bool:
    """Equal arrays, NaN where NaN (the efficiency where no power flows), bit for bit."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def test_the_fast_run_of_every_case_is_the_old_run_bit_for_bit():
    """What ``check`` runs now (the C loop, no scene checks) against what it ran before (``run_scene`` of the scene at the case's fidelity: the
    Python master, the FMU unpacked for the run, the checks evaluated): the same times and
    every output the same double, in all 7 cases.  The C loop must really run here (gcc is
    present on the test machines), else the comparison would be of the old run with itself."""
    from system_models.run import run_scene
    from system_models.scenes import load_scene

    fmu = built_fmus()["PRSM2"]
    cases = regress.load_cases(BASELINES)
    assert len(cases) == 7 and not any(c.parameters for c in cases)
    assert all(core.scene_loop(load_scene(c.scene)) == "native" for c in cases)
    new = core._run_cases(cases, fmu, None)
    compared = 0
    for case, res in zip(cases, new):
        assert not isinstance(res, str), res
        old = run_scene(case.scene, prsm="fmu", fmu_path=fmu, fidelity=case.fidelity).result
        assert _same_bits(res.time, old.time), case.name
        assert sorted(res.values) == sorted(old.values), case.name
        for name in old.values:
            assert _same_bits(res[name], old[name]), (case.name, name)
            compared += 1
    print(f"{compared} outputs of 7 cases equal bit for bit")
