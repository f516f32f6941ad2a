"""The result table: one CSV row per point, every float with all its digits.

Columns: ``point`` (index in the study), ``id`` (hash of the point's inputs), the swept
parameters, ``status`` (``ok`` / ``error``), ``error`` (the exception's type and message) and
the metrics (:mod:`prsm_fmu.sweep.metrics`).  Floats are written with ``repr`` (17 significant
digits, so they read back bit for bit), missing values as ``nan``.  Nothing in the table
depends on where or how fast a point ran, so the same study gives the same file whatever the
number of workers; run times go to ``timing.csv`` beside it.

CSV and not Parquet: a study's table has tens to thousands of rows, which CSV holds in well
under a second; it needs no dependency beyond the standard library (pyarrow is ~100 MB), it can
be appended to row by row while the study runs (so that an interrupted study keeps what it has
done), and it is readable and diffable as text.
"""

from __future__ import annotations

import csv
import math
import os
from typing import Any, Iterable, Mapping, Sequence

from ..atomic import atomic_path

__all__ = ["columns", "format_value", "write_table", "append_rows", "read_table", "row_of",
           "markdown_table"]

FIXED_HEAD = ("point", "id")
FIXED_MID = ("status", "error")


def columns(swept: Sequence[str], metrics: Sequence[str]) -> list[str]:
    """The table's header."""
    return list(FIXED_HEAD) + list(swept) + list(FIXED_MID) + list(metrics)


def format_value(v: Any) -> str:
    """Text of one cell: floats exact (repr), NaN as ``nan``, others as str."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    if v is None:
        return ""
    return str(v)


def row_of(result, header: Sequence[str]) -> list[str]:
    """The cells of a :class:`~prsm_fmu.sweep.points.PointResult` in header order."""
    cells = []
    for col in header:
        if col == "point":
            v: Any = result.index
        elif col == "id":
            v = result.id
        elif col == "status":
            v = result.status
        elif col == "error":
            v = " ".join(result.error.split())          # one line
        elif col in result.values:
            v = result.values[col]
        else:
            v = result.metrics.get(col, math.nan)
        cells.append(format_value(v))
    return cells


def write_table(path: str, header: Sequence[str], rows: Iterable[Sequence[str]]) -> None:
    """Write the whole table (atomically: a temporary file renamed over ``path``)."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow(r)


def append_rows(path: str, header: Sequence[str], rows: Iterable[Sequence[str]]) -> None:
    """Append rows, one open of the file (writing the header first if the file is new)."""
    new = not os.path.exists(path)
    with open(path, "a", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        if new:
            w.writerow(header)
        w.writerows(rows)


def read_table(path: str) -> tuple[list[str], list[dict[str, str]]]:
    """(header, rows as dicts of text); ([], []) if the file does not exist."""
    if not os.path.exists(path):
        return [], []
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            return [], []
        rows = [dict(zip(header, r)) for r in reader if len(r) == len(header)]
    return header, rows


def parse_number(text: str) -> float:
    """A cell as float (NaN for empty or non-numeric text)."""
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def numeric_rows(rows: Iterable[Mapping[str, str]]) -> list[dict[str, Any]]:
    """Rows with every numeric-looking cell converted to float (others kept as text)."""
    out = []
    for r in rows:
        d: dict[str, Any] = {}
        for k, v in r.items():
            if k in ("id", "status", "error"):
                d[k] = v
                continue
            try:
                d[k] = float(v)
            except ValueError:
                d[k] = v
        out.append(d)
    return out


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A Markdown table of ``rows`` under ``headers`` (cells as ``str``, ``|`` escaped)."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for r in rows:
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |")
    return "\n".join(lines)
