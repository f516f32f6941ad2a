"""The master's co-simulation step written out for one plan: Python source, compiled once.

:class:`~system_models.master.Master` works out once per run what each input of each block
reads (a constant, a source that has already stepped, a source read at t_k), which outputs
the coupling error estimate compares with their extrapolation and which scales it updates.
:func:`step_source` turns that plan into the text of one function ``step(m, t, h)`` with every
input's expression written out in the order of the plan: no loop over the plan, no branch on
its entries, the blocks' methods and the outputs held in local variables.  The arithmetic and
its order are the master's (module docstring of :mod:`system_models.master`):

* a constant: its value, slope 0;
* Gauss–Seidel, a source that has already stepped: its value at t_(k+1) with slope 0 for a
  discrete port or extrapolation order 0; else its value at t_k and slope
  (y(t_(k+1)) − y(t_k)) / h;
* a source read at t_k: its value there; slope 0 for a discrete port, else
  (y(t_k) − y(t_(k−1))) / (t_k − t_(k−1)) at extrapolation order 1 once two points exist (0
  before), and the prediction y(t_k) + slope·h enters the coupling error estimate;
* a block that interpolates gets the values and slopes, a block whose inputs are held
  value + h/2·slope;
* after the steps the feedthrough blocks get their inputs at t_(k+1) and update their outputs,
  in list order; then the error estimate ``max |y(t_(k+1)) − prediction| / max(scale, |y|)``
  over the predictions in plan order, and the running maxima of the watched outputs.

:func:`compile_step` compiles the source (once per distinct source in a process) and binds it
to the blocks of a run.
"""

from __future__ import annotations

import time as _time
from typing import Any, Callable, Sequence

__all__ = ["step_source", "compile_step"]

#: compiled step functions by their source (the same plan in many runs compiles once)
_CODE: dict[str, Any] = {}


def step_source(plan: Sequence[Sequence[tuple]], sources: Sequence[Sequence[tuple]],
                interpolates: Sequence[bool], feedthrough: Sequence[bool],
                read_after: Sequence[bool], watched: Sequence[tuple[int, int]],
                gauss_seidel: bool, extrapolation: int) -> str:
    """The text of ``step(m, t, h)`` for a master's plan (module docstring).

    Parameters
    ----------
    plan : sequence of sequence of tuple
        Per block, per input: ``(kind, source block or constant, port, discrete)``, kind 0 a
        constant, 1 a source that has already stepped, 2 a source read at t_k.
    sources : sequence of sequence of tuple
        Per block, per input: ``("const", value)`` or ``("port", block, port, discrete)``
        (the feedthrough update reads these at t_(k+1)).
    interpolates, feedthrough, read_after : sequence of bool
        Per block: it takes values and slopes; its outputs depend on its inputs at the same
        instant; its outputs are read right after its step (Gauss–Seidel).
    watched : sequence of (int, int)
        (block, port) of the outputs whose running maximum scales the error estimate.
    gauss_seidel : bool
        Gauss–Seidel order (else Jacobi).
    extrapolation : {0, 1}
        Order of the input extrapolation.

    Returns
    -------
    str
        Python source defining ``step``; names it expects in its namespace: ``set_<i>``,
        ``do_<i>``, ``get_<i>``, ``update_<i>`` (the blocks' bound methods), ``const_<i>_<j>``
        (the constants), ``clock``.
    """
    n = len(plan)
    first = extrapolation == 1
    hold_new = extrapolation == 0
    out = ["def step(m, t, h):",
           "    y = m.y",
           f"    {', '.join(f'y{i}' for i in range(n))}{',' if n == 1 else ''} = y",
           "    timers = m._block_time",
           "    half_h = 0.5 * h"]
    if first:
        out += ["    y_prev = m.y_prev",
                "    first = y_prev is not None",
                "    dtp = (t - m.t_prev) if first else 1.0",
                "    if first:",
                f"        {', '.join(f'p{i}' for i in range(n))}{',' if n == 1 else ''} = y_prev"]
    out.append(f"    {' = '.join(f'n{i}' for i in range(n))} = None")
    predictions: list[tuple[int, int, str]] = []
    for i in range(n):
        vals, slopes = [], []
        for j, (kind, s, p, discrete) in enumerate(plan[i]):
            v = f"v{i}_{j}"
            if kind == 0:
                out.append(f"    {v} = const_{i}_{j}")
                slopes.append("0.0")
            elif kind == 1:
                if discrete or hold_new:
                    out.append(f"    {v} = n{s}[{p}]")
                    slopes.append("0.0")
                else:
                    out.append(f"    {v} = y{s}[{p}]")
                    out.append(f"    s{i}_{j} = (n{s}[{p}] - {v}) / h")
                    slopes.append(f"s{i}_{j}")
            else:
                out.append(f"    {v} = y{s}[{p}]")
                if discrete:
                    slopes.append("0.0")
                else:
                    sl = f"s{i}_{j}"
                    out.append(f"    {sl} = ({v} - p{s}[{p}]) / dtp if first else 0.0" if first
                               else f"    {sl} = 0.0")
                    out.append(f"    r{i}_{j} = {v} + {sl} * h")
                    slopes.append(sl)
                    predictions.append((s, p, f"r{i}_{j}"))
            vals.append(v)
        out.append("    c0 = clock()")
        if interpolates[i]:
            out.append(f"    set_{i}([{', '.join(vals)}], [{', '.join(slopes)}])")
        else:
            held = ", ".join(f"{v} + half_h * {sl}" for v, sl in zip(vals, slopes))
            out.append(f"    set_{i}([{held}])")
        out.append(f"    do_{i}(t, h)")
        if gauss_seidel and read_after[i]:
            out.append(f"    n{i} = get_{i}()")
        out.append(f"    timers[{i}] += clock() - c0")
    if not gauss_seidel:
        for i in range(n):
            out += ["    c0 = clock()", f"    n{i} = get_{i}()",
                    f"    timers[{i}] += clock() - c0"]
    for i in range(n):
        if feedthrough[i]:
            vals = [f"const_{i}_{j}" if src[0] == "const" else f"n{src[1]}[{src[2]}]"
                    for j, src in enumerate(sources[i])]
            out += ["    c0 = clock()", f"    set_{i}([{', '.join(vals)}])",
                    f"    update_{i}(t + h)", f"    n{i} = get_{i}()",
                    f"    timers[{i}] += clock() - c0"]
    out.append("    err = 0.0")
    if predictions or watched:
        out.append("    scale = m.scale")
    rows = sorted({s for s, _, _ in predictions} | {s for s, _ in watched})
    for s in rows:
        out.append(f"    q{s} = scale[{s}]")
    # max(a, b) is a unless b > a (Python's max): written as that comparison
    for s, p, pred in predictions:
        out += [f"    a = q{s}[{p}]", f"    b = abs(n{s}[{p}])", "    ref = b if b > a else a",
                f"    b = abs(n{s}[{p}] - {pred}) / ref", "    if b > err:", "        err = b"]
    for s, p in watched:
        out += [f"    b = abs(n{s}[{p}])", f"    if b > q{s}[{p}]:", f"        q{s}[{p}] = b"]
    out.append(f"    m.y_prev, m.t_prev, m.y = y, t, [{', '.join(f'n{i}' for i in range(n))}]")
    out.append("    m._stats['substeps'] += 1")
    out.append("    return err")
    return "\n".join(out) + "\n"


def compile_step(source: str, blocks: Sequence[Any], sources: Sequence[Sequence[tuple]]
                 ) -> Callable[[Any, float, float], float]:
    """``step(m, t, h)`` from :func:`step_source`'s ``source``, bound to ``blocks`` (their
    methods as they are now) and the constants of ``sources``."""
    code = _CODE.get(source)
    if code is None:
        code = _CODE[source] = compile(source, "<master step>", "exec")
    ns: dict[str, Any] = {"clock": _time.perf_counter}
    for i, b in enumerate(blocks):
        ns[f"set_{i}"], ns[f"do_{i}"], ns[f"get_{i}"] = b.set_inputs, b.do_step, b.get_outputs
        ns[f"update_{i}"] = b.update_outputs
        for j, src in enumerate(sources[i]):
            if src[0] == "const":
                ns[f"const_{i}_{j}"] = src[1]
    exec(code, ns)
    return ns["step"]
