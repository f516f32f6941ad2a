"""The papers' claims (``[[trend]]`` of a study) checked on the result table.

A claim names a metric, the swept parameter it depends on (``vs``) and what it does:

* ``rises`` / ``falls``: along ``vs``, with every other axis of the study held fixed, each step
  changes the metric by more than ``tolerance`` in that direction;
* ``constant``: within each such line the spread (max − min) is at most ``tolerance`` (in the
  metric's unit; with ``relative = true``, times the largest |value| of the line, and for
  rises / falls each step likewise);
* ``positive`` / ``negative``: the metric has that sign at every point (``vs`` only names the
  parameter the table is read along).

A metric may be a difference or ratio of two columns: ``"A - B"``, ``"A / B"`` (e.g. the change
of the contact force between t = 0 and 0.75 ms).  Lines with a failed point are not judged
(verdict ``not evaluated``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from .study import Study, Trend

__all__ = ["TrendResult", "evaluate", "metric_value", "lines_along"]


@dataclass(frozen=True)
class TrendResult:
    """A claim, what the table shows and the verdict (``agrees``, ``differs``, ``not evaluated``)."""

    trend: Trend
    observed: str
    verdict: str

    @property
    def agrees(self) -> bool:
        return self.verdict == "agrees"


def metric_value(row: Mapping[str, Any], expr: str) -> float:
    """Value of a metric expression (a column, ``A - B`` or ``A / B``) in one row."""
    for op in (" - ", " / "):
        if op in expr:
            a, b = (metric_value(row, part.strip()) for part in expr.split(op, 1))
            if op == " - ":
                return a - b
            return a / b if b != 0 else math.nan
    v = row.get(expr, math.nan)
    return float(v) if isinstance(v, (int, float)) else math.nan


def lines_along(study: Study, rows: Sequence[Mapping[str, Any]], vs: str) -> list[list[Mapping]]:
    """Rows grouped into lines along ``vs``: the other axes fixed, sorted by ``vs``."""
    axis = next(ax for ax in study.axes if vs in ax.names)
    others = [n for ax in study.axes if ax is not axis for n in ax.names]
    groups: dict[tuple, list] = {}
    for r in rows:
        groups.setdefault(tuple(r.get(n) for n in others), []).append(r)
    return [sorted(g, key=lambda r: r[vs]) for g in groups.values()]


def _fmt(v: float) -> str:
    return "nan" if not math.isfinite(v) else f"{v:.6g}"


def evaluate(study: Study, rows: Sequence[Mapping[str, Any]]) -> list[TrendResult]:
    """Every claim of ``study`` judged on ``rows`` (numbers as floats, see ``numeric_rows``)."""
    out = []
    for tr in study.trends:
        lines = lines_along(study, rows, tr.vs)
        texts, verdicts = [], []
        for line in lines:
            if any(r.get("status") != "ok" for r in line):
                verdicts.append(None)
                continue
            ys = [metric_value(r, tr.metric) for r in line]
            if not all(math.isfinite(y) for y in ys):
                verdicts.append(None)
                continue
            d = [b - a for a, b in zip(ys, ys[1:])]
            tol = tr.tolerance * (max(abs(y) for y in ys) if tr.relative else 1.0)
            if tr.expect == "rises":
                ok = all(x > tol for x in d)
                texts.append(" → ".join(_fmt(y) for y in ys))
            elif tr.expect == "falls":
                ok = all(x < -tol for x in d)
                texts.append(" → ".join(_fmt(y) for y in ys))
            elif tr.expect == "constant":
                spread = max(ys) - min(ys)
                ok = spread <= tol
                texts.append(f"spread {spread:.3g}" + (f" ({spread / max(abs(y) for y in ys):.2%})"
                                                       if tr.relative and any(ys) else ""))
            elif tr.expect == "positive":
                ok = all(y > 0 for y in ys)
                texts.append(f"min {_fmt(min(ys))}")
            else:  # negative
                ok = all(y < 0 for y in ys)
                texts.append(f"max {_fmt(max(ys))}")
            verdicts.append(ok)
        if not verdicts or any(v is None for v in verdicts):
            verdict = "not evaluated"
        else:
            verdict = "agrees" if all(verdicts) else "differs"
        out.append(TrendResult(tr, "; ".join(texts), verdict))
    return out
