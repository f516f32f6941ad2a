"""The README's FMU showcase runs as written and shows motion; every output spells units alike.

* The README's ``fmpy simulate`` and ``prsm-fmu plot`` lines are taken from README.md and run
  exactly (``.venv/bin/`` is this interpreter's directory) in a directory holding
  ``dist/PRSM2.fmu``: the result CSV must show the mechanism moving the way its inputs push it
  (positive torque above the load's holding torque extends the rod), the rod position must be
  the screw angle times the total lead / 2π (Li et al. (2021) Eq. 2, leads read from the FMU's own
  parameters), and the plot must be written.
* Units: the FMU's modelDescription is the reference.  The headers of ``startup.csv``
  (``prsm-fmu startup``) and of a scene's CSV (``prsm-ema``'s writer), and every axis label of
  the figures the tools draw, must use the FMU's spelling: a column that is an FMU variable has
  the FMU's unit, and every unit written is one the FMU defines, or one of the scaled or
  electrical units listed here that the FMU has no variable in.

The FMU is the session's shared build of PRSM2, made in a child process (tests/test_fmu.py).
"""

from __future__ import annotations

import csv
import math
from dataclasses import replace
import os
import re
import shlex
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import built_fmus  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

#: units written outside the FMU's vocabulary: time (no FMU variable is a time, so its
#: UnitDefinitions have no "s"), axis scalings and the motor's electrical units (each has one
#: spelling; none is an FMU unit spelled differently)
OTHER_UNITS = {"s", "ms", "mm", "µm", "mm/s", "kN", "A", "V"}


@pytest.fixture(scope="module")
def fmu() -> Path:
    return built_fmus()["PRSM2"]


@pytest.fixture(scope="module")
def model_description(fmu) -> tuple[dict[str, str], set[str], dict[str, str]]:
    """(unit of every variable, the UnitDefinitions' names, start values) of the FMU."""
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    units, starts = {}, {}
    for sv in root.iter("ScalarVariable"):
        typed = sv[0]
        if typed.get("unit"):
            units[sv.get("name")] = typed.get("unit")
        if typed.get("start") is not None:
            starts[sv.get("name")] = typed.get("start")
    defined = {u.get("name") for u in root.iter("Unit")}
    return units, defined, starts


# ---------------------------------------------------------------------------------------------
# the README's showcase
# ---------------------------------------------------------------------------------------------
def _readme_fmu_commands() -> list[str]:
    """The README's command lines that simulate the FMU with fmpy and plot the result."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## The FMU"):]
    block = section[section.index("```bash") + 7:]
    block = block[:block.index("```")]
    return [ln.strip() for ln in block.splitlines()
            if ln.strip().startswith((".venv/bin/fmpy simulate", ".venv/bin/prsm-fmu plot"))]


def test_the_readme_fmu_showcase_moves_the_mechanism_and_plots_it(fmu, model_description,
                                                                   tmp_path):
    commands = _readme_fmu_commands()
    assert [c.split()[0:2] for c in commands] == [[".venv/bin/fmpy", "simulate"],
                                                   [".venv/bin/prsm-fmu", "plot"]], commands
    (tmp_path / "dist").mkdir()
    shutil.copy(fmu, tmp_path / "dist" / "PRSM2.fmu")
    bindir = str(Path(sys.executable).parent)
    for cmd in commands:
        argv = shlex.split(cmd)
        argv[0] = os.path.join(bindir, argv[0].removeprefix(".venv/bin/"))
        proc = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, (cmd, proc.stdout, proc.stderr)
    sim = shlex.split(commands[0])
    out_csv = tmp_path / sim[sim.index("--output-file") + 1]
    png = tmp_path / shlex.split(commands[1])[shlex.split(commands[1]).index("--out") + 1]
    assert png.is_file() and png.stat().st_size > 10_000
    with open(out_csv, newline="") as fh:
        rows = list(csv.reader(fh))
    names = rows[0]
    data = np.array(rows[1:], dtype=float)
    col = {n: data[:, j] for j, n in enumerate(names)}
    # the inputs the README sets
    values = sim[sim.index("--start-values") + 1:]
    values = values[:next((i for i, v in enumerate(values) if v.startswith("--")), len(values))]
    start = dict(zip(values[::2], map(float, values[1::2])))
    torque, load = start["screw_torque"], start["load_force"]
    _, _, starts = model_description
    leads = [float(v) for k, v in starts.items() if k.endswith(".screw_lead")]
    total_lead = sum(leads)                                     # Σ L_Sk [m]
    # the torque exceeds even the ideal (lossless) holding torque F·ΣL/2π, so the rod extends
    assert torque > load * total_lead / (2.0 * math.pi)
    t, angle, rod = col["time"], col["screw_angle"], col["rod_position"]
    assert t[-1] > t[0]
    assert np.all(np.diff(col["screw_speed"]) >= 0.0) and col["screw_speed"][-1] > 1.0
    assert rod[-1] > 1e-4                                       # more than 0.1 mm of travel
    # rod travel = screw angle · ΣL / 2π (Li et al. (2021) Eq. 2), at every sample
    np.testing.assert_allclose(rod, angle * total_lead / (2.0 * math.pi), rtol=1e-9,
                               atol=1e-12)


# ---------------------------------------------------------------------------------------------
# one spelling per unit
# ---------------------------------------------------------------------------------------------
_BRACKET = re.compile(r"\[([^\[\]]*)\]\s*$")


def _header_units(path: Path) -> dict[str, str]:
    with open(path, newline="", encoding="utf-8") as fh:
        header = next(csv.reader(fh))
    out = {}
    for h in header:
        m = _BRACKET.search(h)
        assert m, f"{path.name}: column {h!r} has no [unit]"
        out[h[:m.start()].strip()] = m.group(1)
    return out


def _check_units(where: str, units: dict[str, str], fmu_units: dict[str, str],
                 defined: set[str]) -> None:
    for name, unit in units.items():
        fmu_name = name.removeprefix("prsm.")
        if fmu_name in fmu_units:
            assert unit == fmu_units[fmu_name], (where, name, unit, fmu_units[fmu_name])
        assert unit in defined | OTHER_UNITS, (where, name, unit)


@pytest.fixture()
def figure_labels(monkeypatch) -> list[str]:
    """Every axis label of every figure saved while the fixture is active."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    labels: list[str] = []
    real = Figure.savefig

    def spy(self, *args, **kwargs):
        for ax in self.get_axes():
            labels.extend(x for x in (ax.get_xlabel(), ax.get_ylabel()) if x)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", spy)
    return labels


def test_csv_headers_and_plot_labels_spell_units_as_the_fmu(model_description, tmp_path,
                                                            figure_labels):
    from prsm_fmu import presets, simulate
    from prsm_fmu.cli import main
    from prsm_fmu.sweep.plots import PANELS, plot_steady, plot_time_panels
    from system_models.output import write_csv, write_plots
    from system_models.run import run_scene
    from system_models.scenes import load_scene

    fmu_units, defined, _ = model_description
    assert {"N.m", "1", "rad/s2"} <= defined          # the FMU's spelling of the three units
    # startup.csv and its figure
    assert main(["startup", "--t-end", "2e-5", "--interval", "1e-5", "--out",
                 str(tmp_path / "startup")]) == 0
    startup = _header_units(tmp_path / "startup" / "startup.csv")
    assert startup["stage[1].driven_torque"] == fmu_units["stage[1].driven_torque"]
    _check_units("startup.csv", startup, fmu_units, defined)
    # a scene's CSV (prsm-ema's writer) and its figures, on a 0.2 ms run of the start-up scene
    scene = load_scene("startup_li2021")
    scene = replace(scene, t_end=scene.t0 + 20 * scene.step)
    run = run_scene(scene, prsm="python")
    write_csv(run.result, tmp_path / "scene.csv")
    write_plots(run.result, tmp_path, "scene", run.system.reference,
                run.system.master.blocks[0].mode, run.system.motor.current_limit)
    scene_units = _header_units(tmp_path / "scene.csv")
    assert scene_units["prsm.stage[1].driven_torque"] == fmu_units["stage[1].driven_torque"]
    _check_units("scene.csv", scene_units, fmu_units, defined)
    # the sweep's figures, every time panel and a steady panel
    res = simulate(presets.load("li2021_two_stage"), fidelity="quasi-static", drive="speed",
                   screw_speed=100.0, load_force=5000.0, t_end=2e-5, output_interval=1e-5)
    plot_time_panels([("run", res)], str(tmp_path / "time.png"), tuple(PANELS))
    rows = [{"status": "ok", "mu_spline": m, "efficiency@end": 0.8, "friction_torque@max": 0.1,
             "stage[1].contact_force@end": 100.0} for m in (0.1, 0.2)]
    plot_steady(rows, "mu_spline", ["efficiency@end", "friction_torque@max",
                                    "stage[1].contact_force@end"], [],
                str(tmp_path / "steady.png"))
    assert len(figure_labels) > 20
    for text in figure_labels:
        m = _BRACKET.search(text)
        if m:
            assert m.group(1) in defined | OTHER_UNITS, text
    for foreign in ("N·m", "[-]", "rad/s^2", "rad/s²", "kg·m²"):
        assert not any(foreign in text for text in figure_labels), foreign
