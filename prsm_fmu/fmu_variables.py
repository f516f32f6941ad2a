"""An FMU's variables, read from its ``modelDescription.xml`` (no fmpy needed).

Used where a tool needs the FMU's own vocabulary before running it: the units of a result's
columns (:mod:`prsm_fmu.result_plot`) and the names and ranges of the parameters a command
line sets (``prsm-fmu regress --set``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass

__all__ = ["Variable", "fmu_variables"]


@dataclass(frozen=True)
class Variable:
    """One ScalarVariable: its causality, type element (``Real``, ``Integer``, ...), unit
    (through its declared type if it has one; None if neither gives one) and bounds."""

    name: str
    causality: str
    type: str
    unit: str | None
    min: float | None
    max: float | None


def fmu_variables(fmu: str | os.PathLike) -> dict[str, Variable]:
    """Every variable of an FMU by name, in the order of its modelDescription.

    Raises
    ------
    ValueError
        If the file is not an FMU (a zip with a readable modelDescription.xml), naming it.
    """
    try:
        with zipfile.ZipFile(fmu) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError) as exc:
        raise ValueError(f"{fmu} is not an FMU ({type(exc).__name__}: {exc}); must be an "
                         "FMI 2.0 .fmu file") from None
    declared = {t.get("name"): (t[0].get("unit") if len(t) else None)
                for t in root.iter("SimpleType")}
    out: dict[str, Variable] = {}
    for sv in root.iter("ScalarVariable"):
        typed = sv[0] if len(sv) else None
        get = typed.get if typed is not None else (lambda key: None)
        lo, hi = get("min"), get("max")
        out[sv.get("name")] = Variable(
            sv.get("name"), sv.get("causality", "local"),
            typed.tag if typed is not None else "",
            get("unit") or declared.get(get("declaredType")),
            float(lo) if lo is not None else None, float(hi) if hi is not None else None)
    return out
