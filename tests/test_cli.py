"""Tests of the ``prsm-fmu`` command line (prsm_fmu.cli), run in-process."""

from __future__ import annotations

import csv
import math
import os

import numpy as np
import pytest

from prsm_fmu.cli import energy_balance_residual, is_settled, main, settling_time, unit_of
from text_numbers import number_after  # noqa: E402


@pytest.fixture(scope="module")
def startup_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("startup")
    code = main(["startup", "--out", str(out), "--interval", "1e-5"])
    return code, out


def test_startup_exit_code_and_files(startup_run):
    code, out = startup_run
    assert code == 0
    csv_path = out / "startup.csv"
    png_path = out / "startup.png"
    assert csv_path.is_file()
    assert png_path.is_file() and os.path.getsize(png_path) > 1000
    with open(csv_path, encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert header[0] == "time [s]"
    assert header[1] == "screw_speed [rad/s]"
    assert "stage[1].carrier_speed_ratio [1]" in header
    assert "screw_torque [N.m]" in header
    assert all(h.endswith("]") and " [" in h and "[?]" not in h for h in header)
    data = np.array(rows[1:], dtype=float)
    assert data.shape[0] >= 100              # 1 ms / 10 µs + 1 = 101 rows
    assert data.shape[1] == len(header)
    assert data[-1, 0] == pytest.approx(1e-3)
    speed = data[:, header.index("screw_speed [rad/s]")]
    assert np.allclose(speed, 100.0)


def test_startup_prints_table_settling_and_cost(tmp_path, capsys):
    assert main(["startup", "--out", str(tmp_path), "--interval", "1e-5", "--t-end",
                 "5e-4"]) == 0
    text = capsys.readouterr().out
    assert "ζ_PS1" in text and "M_S1 [N.m]" in text and "f_S2 [N]" in text
    assert "carrier 1: settles" in text and "carrier 2: settles" in text
    assert "rhs calls" in text and "energy-balance residual" in text


@pytest.mark.parametrize("argv, name", [
    (["startup", "--speed", "nan"], "--speed"),
    (["startup", "--interval", "-1"], "--interval"),
    (["startup", "--t-end", "1e-3", "--interval", "3e-4"], "--t-end"),
    (["startup", "--load", "abc"], "--load"),
    (["startup", "--preset", "no_such_preset"], "--preset"),
    (["startup", "--preset", "recirculating_screw"], "--preset"),
    (["startup", "--fidelity", "exact"], "--fidelity"),
    (["steady", "--speed", "0"], "--speed"),
])
def test_bad_arguments_exit_2_naming_the_argument(argv, name, tmp_path, capsys):
    assert main(argv + ["--out", str(tmp_path)] if argv[0] == "startup" else argv) == 2
    err = capsys.readouterr().err
    assert name in err
    assert not (tmp_path / "startup.csv").exists()


def test_steady_and_presets(capsys):
    assert main(["steady", "--preset", "li2021_two_stage", "--speed", "100",
                 "--load", "5000"]) == 0
    text = capsys.readouterr().out
    line = next(ln for ln in text.splitlines() if ln.startswith("efficiency"))
    assert 0.5 < float(line.split()[1]) < 1.0
    assert main(["presets"]) == 0
    names = capsys.readouterr().out.split()
    assert "li2021_two_stage" in names and "assembly_two_stage" in names


def test_settling_time_helper():
    t = np.linspace(0.0, 1.0, 101)
    z = 1.0 - np.exp(-t / 0.1)
    z = z / z[-1]                            # final value exactly 1
    # |z − 1| = 0.01 where exp(−t/0.1) ≈ 0.01·(1 − e^−10): t ≈ 0.1·ln(100)
    assert settling_time(t, z) == pytest.approx(0.1 * math.log(100.0), abs=2e-3)
    assert settling_time(t, np.ones_like(t)) == 0.0
    assert math.isnan(settling_time(t, np.zeros_like(t)))
    assert is_settled(t, z) and not is_settled(t, t)


def test_energy_balance_residual_and_units():
    res = {"input_work": np.array([0.0, 10.0]), "output_work": np.array([0.0, 7.0]),
           "friction_work": np.array([0.0, 2.0]), "kinetic_energy": np.array([1.0, 1.5])}
    assert energy_balance_residual(res) == pytest.approx(0.05)
    assert unit_of("stage[2].driven_torque") == "N.m"
    assert unit_of("time") == "s"


def test_startup_auto_matches_the_dynamic_level_within_its_tolerance(tmp_path, capsys):
    """--fidelity auto (dynamic while the carriers spin up, quasi-static after): with the same
    stepper for the dynamic steps, the written carrier ratios, efficiency and spline friction
    agree with the dynamic level's run to the tolerance (they differ only after the switch)."""
    runs = {}
    for fid in ("dynamic", "auto"):
        out = tmp_path / fid
        assert main(["startup", "--fidelity", fid, "--tolerance", "1e-6", "--interval", "1e-5",
                     "--stepper", "explicit_adaptive", "--out", str(out)]) == 0
        with open(out / "startup.csv") as fh:
            header = fh.readline().strip().split(",")
        runs[fid] = (header, np.loadtxt(out / "startup.csv", delimiter=",", skiprows=1))
    out = capsys.readouterr().out
    assert number_after(out, "fidelity auto at tolerance ") == 1e-6 and ": starts with 'dynamic'" in out
    header, dyn = runs["dynamic"]
    _, auto = runs["auto"]
    for name in ("stage[1].carrier_speed_ratio [1]", "stage[2].carrier_speed_ratio [1]",
                 "efficiency [1]", "stage[2].spline_friction [N]"):
        j = header.index(name)
        assert np.max(np.abs(auto[:, j] - dyn[:, j])) <= 1e-6 * np.max(np.abs(dyn[:, j])), name
