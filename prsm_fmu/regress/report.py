"""Failure report of a regression run: one PNG per output that left its tube and an HTML page.

Each PNG shows the baseline, its tolerance tube (shaded), the run, the first and the worst point
outside, and below it the run's distance from the baseline against the tube's half-widths.
"""

from __future__ import annotations

import html
import math
import re
from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from .core import CaseResult

__all__ = ["write_report", "verdict_table"]


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)


def plot_output(cr: CaseResult, name: str, path: Path) -> None:
    """The tube plot of one output of one case."""
    from ..figures import save, subplots

    t, yb, yi, lo, hi = cr.plots[name]
    r = next(x for x in cr.results if x.name == name)
    unit = cr.units.get(name, "")
    fig, (ax, ad) = subplots(2, 1, figsize=(9, 6.5), sharex=True, hspace=0.15,
                             gridspec_kw={"height_ratios": [3, 2]}, margins={"top": 0.45})
    ax.fill_between(t, lo, hi, color="tab:green", alpha=0.25, lw=0, label="tolerance tube")
    ax.plot(t, yb, color="tab:green", lw=1.0, label="baseline")
    ax.plot(t, yi, color="tab:red", lw=1.0, ls="--", label="this run")
    out = np.maximum(yi - hi, lo - yi) > 0
    if out.any():
        ax.plot(t[out], yi[out], "x", color="tab:red", ms=4, label="outside the tube")
        ax.axvline(r.t_worst, color="k", lw=0.6, ls=":")
    ax.set_ylabel(f"{name} [{unit}]")
    ax.set_title(f"{cr.case.name}: {name} — {'PASS' if r.passed else 'FAIL'}; largest excess "
                 f"{r.excess:.3g} {unit} at t = {r.t_worst:g} s")
    ax.legend(loc="best", fontsize=8)
    ad.fill_between(t, lo - yb, hi - yb, color="tab:green", alpha=0.25, lw=0,
                    label="tube − baseline")
    ad.plot(t, yi - yb, color="tab:red", lw=1.0, label="run − baseline")
    ad.axhline(0.0, color="k", lw=0.5)
    ad.set_xlabel("time [s]")
    ad.set_ylabel(f"difference [{unit}]")
    ad.legend(loc="best", fontsize=8)
    save(fig, path, dpi=90)


def verdict_table(results: list[CaseResult]) -> str:
    """Plain-text table: case, output, verdict, largest |Δ|, excess and where."""
    rows = [f"{'case':32s} {'output':34s} {'verdict':7s} {'max |Δ|':>10s} {'excess':>10s} "
            f"{'at t [s]':>10s}"]
    for cr in results:
        if cr.error:
            rows.append(f"{cr.case.name:32s} {'-':34s} {'ERROR':7s} {cr.error}")
        for r in cr.results:
            rows.append(f"{cr.case.name:32s} {r.name:34s} {'pass' if r.passed else 'FAIL':7s} "
                        f"{r.max_abs_diff:10.3g} {r.excess:10.3g} "
                        f"{(r.t_worst if not r.passed else math.nan):10.4g}")
    return "\n".join(rows)


def write_report(results: list[CaseResult], out: Path, title: str = "") -> Path:
    """Write ``out/report.html`` (every case and output; a plot for each failure)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    body = [f"<h1>Regression report{(': ' + html.escape(title)) if title else ''}</h1>"]
    n_fail = sum(not cr.passed for cr in results)
    body.append(f"<p>{len(results)} cases, {n_fail} failed.</p>")
    for cr in results:
        body.append(f"<h2>{html.escape(cr.case.name)} — {'PASS' if cr.passed else 'FAIL'}</h2>")
        c = cr.case
        body.append(f"<p>scene <code>{html.escape(c.scene)}</code>, fidelity "
                    f"{html.escape(str(c.fidelity or 'scene'))}; tube ± ({c.abs_frac:g}·max|y| + "
                    f"{c.rel:g}·|y|) over ± {c.dt:g} s (per-output overrides in "
                    "tolerances.toml)</p>")
        if cr.error:
            body.append(f"<p><b>error:</b> {html.escape(cr.error)}</p>")
            continue
        body.append("<table border=1 cellpadding=3><tr><th>output</th><th>verdict</th>"
                    "<th>max |Δ|</th><th>largest excess</th><th>at t [s]</th>"
                    "<th>first out [s]</th><th>points out</th></tr>")
        for r in cr.results:
            unit = html.escape(cr.units.get(r.name, ""))
            body.append(f"<tr><td>{html.escape(r.name)}</td><td>"
                        f"{'pass' if r.passed else '<b>FAIL</b>'}</td><td>{r.max_abs_diff:.3g} "
                        f"{unit}</td><td>{r.excess:.3g} {unit}</td><td>"
                        f"{'' if r.passed else f'{r.t_worst:g}'}</td><td>"
                        f"{'' if r.passed else f'{r.first_out:g}'}</td><td>{r.n_out}</td></tr>")
        body.append("</table>")
        for r in cr.results:
            if not r.passed and r.name in cr.plots:
                png = f"{_slug(cr.case.name)}__{_slug(r.name)}.png"
                plot_output(cr, r.name, out / png)
                body.append(f"<h3>{html.escape(r.name)}</h3>"
                            f"<p>{html.escape(r.reason)}</p><img src='{png}'>")
    path = out / "report.html"
    with atomic_path(path) as tmp:
        Path(tmp).write_text("<!doctype html><meta charset='utf-8'><title>regression report"
                             "</title>\n" + "\n".join(body) + "\n", encoding="utf-8")
    return path
