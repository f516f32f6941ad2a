"""Pack the regression baselines into the FMU under ``extra/baselines/`` (issue 6).

The FMI standard reserves ``extra/`` for additional files that importers may ignore; the FMI
Reference FMUs ship their reference results there in the same spirit.  For an FMU whose name is
the mechanism the baselines were made with (``PRSM2``), :func:`add_baselines` writes the CSV
baselines, ``tolerances.toml``, the last ``REPORT.md`` and a ``README.md`` that says how to check
them.  Other FMUs are left unchanged.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

__all__ = ["BASELINES", "MECHANISM", "add_baselines"]

#: the repository's baselines (prsm_fmu.regress)
BASELINES = Path(__file__).resolve().parents[1] / "baselines"
#: the FMU the regression scenes use (system_models' default mechanism)
MECHANISM = "PRSM2"

README = """# Regression baselines of {name}

These files are the reviewed reference outputs of this FMU on the actuator scenes of prsm-fmu
(`system_models/scenes`), with their tolerance tubes:

- `<case>.csv`: time [s] and named outputs with their units (header `name [unit]`), one row
  per communication point, made with the FMU parameter `tolerance` at `baseline_tolerance`;
- `tolerances.toml`: per case the scene, the fidelity and the tube, with the reason of each
  number: an output passes when every sample lies within ±(abs_frac·max|y_b| + rel·|y_b|) of
  the baseline, that band widened over ±dt in time;
- `REPORT.md`: what changed when the baselines were last updated.

How to check this FMU against them (prsm-fmu checked out or installed, with fmpy):

    prsm-fmu regress --fmu {name}.fmu --baselines {name}.fmu --out regress_out

It runs every case on this FMU with fmpy inside the actuator loop, compares each output with
its tube, prints a table and writes `regress_out/report.html` with a plot of every output that
left its tube; exit status 0 when all pass.  Without prsm-fmu, the tube is simple to
reproduce: drive the FMU as the scene describes and apply the rule above (docs/regression.md).
"""


def add_baselines(fmu: Path, name: str, source: Path = BASELINES) -> list[str]:
    """Add ``extra/baselines/*`` to ``fmu`` if it is the baselines' mechanism; the names added."""
    source = Path(source)
    if name != MECHANISM or not (source / "tolerances.toml").is_file():
        return []
    files = sorted(source.glob("*.csv")) + [source / "tolerances.toml"]
    if (source / "REPORT.md").is_file():
        files.append(source / "REPORT.md")
    added = []
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as z:
        present = set(z.namelist())
        for f in files:
            arc = f"extra/baselines/{f.name}"
            if arc not in present:
                z.write(f, arc)
                added.append(arc)
        arc = "extra/baselines/README.md"
        if arc not in present:
            z.writestr(arc, README.format(name=name))
            added.append(arc)
    return added
