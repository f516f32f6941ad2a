"""Plot an FMU's simulation result (the CSV of ``fmpy simulate --output-file``) with its units.

fmpy writes a result CSV whose header holds the variable names only, and its own plot needs
plotly, which no extra of this project installs.  :func:`plot_fmu_result` draws the result with
matplotlib (a core dependency) and labels every axis with the unit the FMU's modelDescription
gives the variable (:func:`fmu_units`), spelled as everywhere else (:mod:`prsm_fmu.units`).
The console route is ``prsm-fmu plot RESULT.csv --fmu PRSM2.fmu --out RESULT.png``.

Per-stage variables ``stage[k].<name>`` share one panel per name (one line per stage).
"""

from __future__ import annotations

import csv
import os
from typing import Mapping, Sequence

import numpy as np

from .fmu_variables import fmu_variables
from .units import DIMENSIONLESS, SECOND, label

__all__ = ["read_result_csv", "fmu_units", "plot_fmu_result", "DEFAULT_VARIABLES"]

#: panels drawn when no variables are named (those the result has, stage[k] for every k)
DEFAULT_VARIABLES = ("screw_speed", "rod_position", "stage[k].contact_force",
                     "stage[k].driven_torque", "efficiency", "friction_power")


def read_result_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Columns of a result CSV (first row: names, quoted or not; a column ``time``).

    Raises
    ------
    ValueError
        If the file is not such a CSV (naming the file and what is wrong).
    """
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2 or not rows[0] or rows[0][0].strip() != "time":
        raise ValueError(f"{path}: not a result CSV (need a header row starting with 'time' "
                         "and at least one row of values)")
    names = [n.strip() for n in rows[0]]
    try:
        data = np.array([[float(v) for v in r] for r in rows[1:] if r], dtype=float)
    except ValueError as exc:
        raise ValueError(f"{path}: not a result CSV ({exc})") from None
    if data.ndim != 2 or data.shape[1] != len(names):
        raise ValueError(f"{path}: not a result CSV (rows do not match the {len(names)} names)")
    return {n: data[:, j] for j, n in enumerate(names)}


def fmu_units(fmu: str | os.PathLike) -> dict[str, str]:
    """Unit of every variable of an FMU, from its modelDescription.xml (``1`` if it has none).

    Raises
    ------
    ValueError
        If the file is not an FMU.
    """
    return {n: v.unit or DIMENSIONLESS for n, v in fmu_variables(fmu).items()}


def _panels(res: Mapping[str, np.ndarray], variables: Sequence[str]) -> list[list[str]]:
    """Columns of each panel: ``stage[k].x`` expands to every stage the result has."""
    panels = []
    for v in variables:
        if v.startswith("stage[k]."):
            field = v[len("stage[k]."):]
            cols = [n for n in res if n.startswith("stage[") and n.endswith("]." + field)]
        else:
            cols = [v] if v in res else []
        if cols:
            panels.append(cols)
    return panels


def plot_fmu_result(res: Mapping[str, np.ndarray], units: Mapping[str, str],
                    path: str | os.PathLike, variables: Sequence[str] = DEFAULT_VARIABLES,
                    title: str = "") -> list[str]:
    """Save one panel per variable against time [s]; returns the columns drawn.

    Parameters
    ----------
    res : mapping
        ``time`` [s] and the variables (:func:`read_result_csv`).
    units : mapping
        Unit of each variable (:func:`fmu_units`).
    path : path-like
        Output PNG file.
    variables : sequence of str
        Names to draw (``stage[k].<name>``: every stage); those the result lacks are skipped.
    title : str
        Figure title.

    Raises
    ------
    ValueError
        If none of ``variables`` is in the result.
    """
    from .figures import save, subplots

    panels = _panels(res, variables)
    if not panels:
        raise ValueError(f"none of the variables {', '.join(variables)} is in the result: "
                         f"must be among {', '.join(n for n in res if n != 'time')} "
                         "(stage[k].NAME for every stage)")
    fig, axes = subplots(len(panels), 1, figsize=(8, 2.2 * len(panels) + 0.8), sharex=True,
                         squeeze=False, hspace=0.2,
                         margins={"top": 0.3 + (0.3 if title else 0.0)})
    t = res["time"]
    for ax, cols in zip(axes[:, 0], panels):
        for c in cols:
            ax.plot(t, res[c], label=c)
        name = cols[0].split(".", 1)[1] if len(cols) > 1 else cols[0]
        ax.set_ylabel(label(name, units.get(cols[0], DIMENSIONLESS)), fontsize=8)
        ax.grid(True, alpha=0.3)
        if len(cols) > 1:
            ax.legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel(label("time", SECOND))
    if title:
        fig.suptitle(title)
    save(fig, path)
    return [c for cols in panels for c in cols]
