"""The co-simulation master: fixed macro steps over blocks behind one small interface.

:class:`Master` steps a list of :class:`~system_models.blocks.Block` (the PRSM FMU through
fmpy, plain Python blocks) connected output → input:

* **Time grid.**  Communication points t_k = t0 + k·h, computed from the integer k (no
  accumulated drift); the run ends exactly at t_end = t0 + n·h (a t_end that is not a whole
  number of steps is refused).  A retried step is split into m equal substeps whose last one
  ends exactly on t_(k+1).
* **Orders.**  ``jacobi``: every block steps from the outputs at t_k (parallel in principle).
  ``gauss-seidel``: blocks step in list order, each one using the outputs at t_(k+1) of the
  blocks before it (interpolated over the step) and the extrapolated outputs of the others.
* **Input extrapolation.**  Order 0 holds an output's last value over the next step; order 1
  extrapolates it linearly from its last two communication points (Gauss–Seidel: interpolates
  between t_k and t_(k+1) when the source has already stepped).  A block that interpolates
  inputs gets value and slope; a block whose inputs are held (an FMI 2.0 FMU) gets the mean of
  the linear signal over the step, value + slope·h/2.  Discrete ports (a sampled controller's
  commands) are never extrapolated.
* **Feedthrough.**  After each step, blocks with ``feedthrough`` get their inputs at t_(k+1)
  and recompute their outputs there (in list order), so e.g. the load force at t_(k+1) uses
  the rod's position at t_(k+1).
* **Rejection and retry** (:class:`RetryPolicy`).  Before each macro step the master takes
  every block's state (the FMU's with ``fmi2GetFMUstate``).  If a block refuses the step
  (fmi2Discard → :class:`~system_models.blocks.StepRefused`), or the coupling error estimate
  exceeds ``tolerance``, every block is set back and the macro step is redone as 2, 4, … equal
  substeps, up to ``max_halvings`` times.
* **Errors.**  A refused step that no retry can take raises :class:`CoSimulationError` naming
  the time, the block and its reason (the FMU's log message).  The master never returns a
  truncated result; the error carries what was computed up to the failure as ``partial``.

Coupling error estimate (for ``tolerance``): for every continuous connection whose value over
the step was extrapolated (not yet known), |y(t_(k+1)) − extrapolation(t_(k+1))| divided by
the larger of the output's nominal magnitude (:attr:`Port.nominal`) and the largest |y| seen
so far on it.
"""

from __future__ import annotations

import math
import struct
import time as _time
from array import array
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .blocks import Block, StepRefused
from .retry_limit import MAX_HALVINGS
from .step_code import compile_step, step_source

__all__ = ["Master", "RetryPolicy", "Result", "CoSimulationError", "ORDERS"]

ORDERS = ("jacobi", "gauss-seidel")



def whole_steps(t0: float, t_end: float, h: float) -> int:
    """Number n of macro steps h [s] from t0 to t_end [s]; ValueError unless t_end = t0 + n·h.

    Raises
    ------
    ValueError
        If ``t_end − t0`` is not a positive whole number of steps (to 1e-9 relative).
    """
    span = float(t_end) - t0
    n = int(round(span / h))
    if n < 1 or abs(t0 + n * h - t_end) > 1e-9 * max(abs(t_end), abs(t0), h):
        raise ValueError(f"t_end = {t_end!r} s is not t0 + n·h for a whole n >= 1 "
                         f"(t0 = {t0!r} s, h = {h!r} s, (t_end − t0)/h = {span / h!r})")
    return n


@dataclass(frozen=True)
class RetryPolicy:
    """When and how often a macro step is redone with smaller substeps.

    Attributes
    ----------
    max_halvings : int
        Most halvings of a macro step (0: no roll-back; a refused step is an error at once).
    tolerance : float or None
        Largest accepted coupling error estimate (relative, see module docstring); None:
        only refused steps are retried.
    """

    max_halvings: int = 0
    tolerance: float | None = None

    def __post_init__(self) -> None:
        if isinstance(self.max_halvings, bool) or not isinstance(self.max_halvings, int) \
                or not 0 <= self.max_halvings <= MAX_HALVINGS:
            raise ValueError(f"max_halvings = {self.max_halvings!r} is out of range: must be an "
                             f"integer in [0, {MAX_HALVINGS}]")
        if self.tolerance is not None and not (math.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"tolerance = {self.tolerance!r} is out of range: must be > 0 or None")


class CoSimulationError(RuntimeError):
    """The run cannot continue (a block refused a step that no retry could take).

    Attributes
    ----------
    time : float
        Communication point where the failed macro step starts [s].
    block : str
        The block that refused.
    reason : str
        Its reason (for an FMU: its log messages for the call).
    partial : Result or None
        The outputs up to ``time`` (not a result of the run: the run failed).
    """

    def __init__(self, message: str, time: float, block: str, reason: str,
                 partial: "Result | None" = None) -> None:
        super().__init__(message)
        self.time, self.block, self.reason, self.partial = time, block, reason, partial


@dataclass
class Result:
    """Outputs of a run on the macro grid.

    Attributes
    ----------
    time : ndarray
        t0 + k·h, k = 0..n [s].
    values : dict
        ``"block.port"`` → ndarray of the output at each communication point.
    units : dict
        ``"block.port"`` → unit.
    stats : dict
        ``macro_steps``, ``substeps`` (block steps taken, retries included), ``retries``,
        ``refusals``, ``max_coupling_error``, ``wall_time`` [s], ``block_time`` (per block [s]).
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    units: dict[str, str]
    stats: dict[str, Any] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "time":
            return self.time
        return self.values[name]

    def __contains__(self, name: str) -> bool:
        return name == "time" or name in self.values

    def names(self) -> list[str]:
        return list(self.values)


class Master:
    """Fixed-step co-simulation master (module docstring).

    Parameters
    ----------
    blocks : sequence of Block
        The blocks, in Gauss–Seidel order.  Names must be unique.
    connections : mapping
        ``"block.input"`` → ``"block.output"`` or a constant (float).  Every input of every
        block must be connected; units must agree.
    step : float
        Macro (communication) step h [s].
    t0 : float
        Start time [s].
    order : {"jacobi", "gauss-seidel"}
    extrapolation : {0, 1}
        Order of the input extrapolation.
    retry : RetryPolicy
    record : sequence of str, optional
        ``"block.port"`` outputs to record (default: all).
    nominals : mapping, optional
        ``"block.port"`` → typical magnitude of an output, overriding :attr:`Port.nominal`
        (scales the coupling error estimate).
    """

    def __init__(self, blocks: Sequence[Block], connections: Mapping[str, Any], step: float,
                 t0: float = 0.0, order: str = "gauss-seidel", extrapolation: int = 0,
                 retry: RetryPolicy = RetryPolicy(), record: Sequence[str] | None = None,
                 nominals: Mapping[str, float] | None = None) -> None:
        if order not in ORDERS:
            raise ValueError(f"order = {order!r} is not allowed: must be one of {', '.join(ORDERS)}")
        if extrapolation not in (0, 1):
            raise ValueError(f"extrapolation = {extrapolation!r} is not allowed: must be 0 or 1")
        if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0.0):
            raise ValueError(f"step = {step!r} is out of range: must be a finite number > 0 [s]")
        if not math.isfinite(t0):
            raise ValueError(f"t0 = {t0!r} is out of range: must be finite")
        self.blocks = list(blocks)
        self.index = {}
        for i, b in enumerate(self.blocks):
            if b.name in self.index:
                raise ValueError(f"two blocks are named {b.name!r}")
            self.index[b.name] = i
        self.step, self.t0 = float(step), float(t0)
        self.order, self.extrapolation, self.retry = order, extrapolation, retry
        self._sources = self._connect(connections)
        self._record = self._record_list(record)
        self._nominal = [[port.nominal for port in b.outputs] for b in self.blocks]
        for ref, value in (nominals or {}).items():
            i, port = self._split(ref)
            names = self.blocks[i].output_names()
            if port not in names:
                raise ValueError(f"nominals: {ref!r}: block has no output {port!r}")
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"nominals: {ref} = {value!r} must be a finite number > 0")
            self._nominal[i][names.index(port)] = float(value)
        self._select_outputs()
        self._plan_step()

    # ---- set-up ------------------------------------------------------------------------------
    def _split(self, ref: str) -> tuple[int, str]:
        name, _, port = ref.partition(".")
        if name not in self.index or not port:
            raise ValueError(f"{ref!r} does not name a port 'block.port' of a block "
                             f"({', '.join(self.index)})")
        return self.index[name], port

    def _connect(self, connections: Mapping[str, Any]) -> list[list[tuple]]:
        sources: list[list[tuple | None]] = [[None] * len(b.inputs) for b in self.blocks]
        for target, source in connections.items():
            i, port = self._split(target)
            names = self.blocks[i].input_names()
            if port not in names:
                raise ValueError(f"{target!r}: block {self.blocks[i].name!r} has no input "
                                 f"{port!r} (inputs: {', '.join(names)})")
            j = names.index(port)
            if isinstance(source, (int, float)) and not isinstance(source, bool):
                sources[i][j] = ("const", float(source))
                continue
            s, sport = self._split(str(source))
            onames = self.blocks[s].output_names()
            if sport not in onames:
                raise ValueError(f"{source!r}: block {self.blocks[s].name!r} has no output "
                                 f"{sport!r}")
            p = onames.index(sport)
            out, inp = self.blocks[s].outputs[p], self.blocks[i].inputs[j]
            if out.unit and inp.unit and out.unit != inp.unit:
                raise ValueError(f"connection {source} → {target}: unit {out.unit!r} does not "
                                 f"match {inp.unit!r}")
            sources[i][j] = ("port", s, p, out.discrete)
        for i, b in enumerate(self.blocks):
            for j, src in enumerate(sources[i]):
                if src is None:
                    raise ValueError(f"input {b.name}.{b.inputs[j].name} is not connected")
        return sources  # type: ignore[return-value]

    def _record_list(self, record: Sequence[str] | None) -> list[tuple[int, int, str, str]]:
        out = []
        if record is None:
            for i, b in enumerate(self.blocks):
                for p, port in enumerate(b.outputs):
                    out.append((i, p, f"{b.name}.{port.name}", port.unit))
            return out
        for ref in record:
            i, port = self._split(ref)
            names = self.blocks[i].output_names()
            if port not in names:
                raise ValueError(f"record {ref!r}: block has no output {port!r}")
            p = names.index(port)
            out.append((i, p, ref, self.blocks[i].outputs[p].unit))
        return out

    def _select_outputs(self) -> None:
        """Ask every block to give only the outputs that are connected or recorded
        (:meth:`~system_models.blocks.Block.select_outputs`); for a block that agrees, the
        connections, recorded columns and nominal magnitudes are renumbered to the positions
        in its shorter list of outputs."""
        used: list[set[int]] = [set() for _ in self.blocks]
        for srcs in self._sources:
            for src in srcs:
                if src[0] == "port":
                    used[src[1]].add(src[2])
        for i, p, _, _ in self._record:
            used[i].add(p)
        pos: list[dict[int, int] | None] = []
        for i, b in enumerate(self.blocks):
            ports = sorted(used[i])
            if len(ports) < len(b.outputs) and b.select_outputs(ports):
                pos.append({p: k for k, p in enumerate(ports)})
                self._nominal[i] = [self._nominal[i][p] for p in ports]
            else:
                pos.append(None)
        if all(m is None for m in pos):
            return
        for srcs in self._sources:
            for j, src in enumerate(srcs):
                if src[0] == "port" and pos[src[1]] is not None:
                    srcs[j] = ("port", src[1], pos[src[1]][src[2]], src[3])
        self._record = [(i, p if pos[i] is None else pos[i][p], name, unit)
                        for i, p, name, unit in self._record]

    def _plan_step(self) -> None:
        """What each step needs, worked out once: the outputs whose coupling error is
        estimated (sources of continuous connections read before their block has stepped:
        their running maxima scale the estimate), the getters of the recorded outputs per
        block, and the feedthrough blocks whose outputs right after ``do_step`` nobody reads
        (their outputs at t_(k+1) come from the feedthrough update)."""
        gs = self.order == "gauss-seidel"
        watched = set()
        read_after_step: set[int] = set()      # blocks read in the step loop once stepped
        for i, srcs in enumerate(self._sources):
            for src in srcs:
                if src[0] == "const":
                    continue
                _, s_, p_, discrete = src
                if gs and s_ < i:
                    read_after_step.add(s_)
                elif not discrete:
                    watched.add((s_, p_))
        #: (block, port) of the outputs whose running maximum scales the coupling error
        self._watched = sorted(watched)
        # a feedthrough block read by an earlier feedthrough block's update sees its outputs
        # from right after its step: those must be read then
        for i, b in enumerate(self.blocks):
            if b.feedthrough:
                for src in self._sources[i]:
                    if src[0] != "const" and src[1] > i and self.blocks[src[1]].feedthrough:
                        read_after_step.add(src[1])
        self._read_after_step = [not (b.feedthrough and gs and i not in read_after_step)
                                 for i, b in enumerate(self.blocks)]
        by_block: dict[int, list[int]] = {}
        for i, p_, _, _ in self._record:
            by_block.setdefault(i, []).append(p_)
        # one getter per block in recording order, when the recorded columns come block by
        # block (the default: every output); else a per-column row.  The values are packed
        # as doubles with struct (float() of each, as array('d') converts them, at a fraction
        # of array.extend's cost per value)
        order = [i for i, _, _, _ in self._record]
        grouped = all(order[k] <= order[k + 1] for k in range(len(order) - 1))
        # (None: the block's whole row, its every output in order)
        self._row_getters = ([(i, None if ps == list(range(len(self._nominal[i]))) else
                               itemgetter(*ps) if len(ps) > 1 else (lambda v, q=ps[0]: (v[q],)),
                               struct.Struct(f"{len(ps)}d").pack)
                              for i, ps in by_block.items()] if grouped else None)
        self._row_pack = struct.Struct(f"{len(self._record)}d").pack
        # each input's branch in _step, fixed by the order: 0 constant, 1 a source that has
        # already stepped (Gauss-Seidel, earlier in the list), 2 a source read at t_k
        self._plan = [[(0, src[1], 0, True) if src[0] == "const" else
                       ((1 if gs and src[1] < i else 2), src[1], src[2], src[3])
                       for src in srcs] for i, srcs in enumerate(self._sources)]
        #: the step written out for this plan (compiled and bound to the blocks per run)
        self._step_code = step_source(
            self._plan, self._sources, [b.interpolates_inputs for b in self.blocks],
            [b.feedthrough for b in self.blocks], self._read_after_step, self._watched, gs,
            self.extrapolation)

    # ---- stepping ----------------------------------------------------------------------------
    def _values(self, i: int, y: list) -> list[float]:
        out = []
        for src in self._sources[i]:
            out.append(src[1] if src[0] == "const" else y[src[1]][src[2]])
        return out

    def _initialize(self) -> None:
        blocks = self.blocks
        y: list[list[float] | None] = [None if b.feedthrough else b.get_outputs() for b in blocks]
        pending = [i for i, b in enumerate(blocks) if b.feedthrough]
        while pending:
            progress = False
            for i in list(pending):
                if all(src[0] == "const" or y[src[1]] is not None for src in self._sources[i]):
                    blocks[i].set_inputs(self._values(i, y))
                    blocks[i].update_outputs(self.t0)
                    y[i] = blocks[i].get_outputs()
                    pending.remove(i)
                    progress = True
            if not progress:
                raise ValueError("algebraic loop between feedthrough blocks "
                                 f"{', '.join(blocks[i].name for i in pending)}")
        for i, b in enumerate(blocks):
            b.set_inputs(self._values(i, y))
        self.y = [b.get_outputs() for b in blocks]
        self._step_fn = compile_step(self._step_code, blocks, self._sources)
        self.y_prev: list | None = None
        self.t_prev: float | None = None
        self.scale = [[max(abs(v), nom) for v, nom in zip(row, noms)]
                      for row, noms in zip(self.y, self._nominal)]

    def _step(self, t: float, h: float) -> float:
        """One co-simulation step over [t, t + h]; returns the coupling error estimate (the
        step of :mod:`system_models.step_code` for this run's plan and blocks)."""
        return self._step_fn(self, t, h)

    def _snapshot(self) -> tuple:
        states = [b.get_state() for b in self.blocks]
        return (states, self.y, self.y_prev, self.t_prev, [list(r) for r in self.scale])

    def _restore(self, snap: tuple) -> None:
        states, self.y, self.y_prev, self.t_prev, scale = snap
        self.scale = [list(r) for r in scale]
        for b, s in zip(self.blocks, states):
            b.set_state(s)

    def _free(self, snap: tuple) -> None:
        for b, s in zip(self.blocks, snap[0]):
            b.free_state(s)

    def _macro_step(self, k: int, t: float, t_next: float) -> None:
        """Macro step ``k`` under a retry policy (halvings or a coupling tolerance): rolled
        back and retried in substeps; a step without one is taken by :meth:`_steps`."""
        pol = self.retry
        snap = self._snapshot()
        try:
            m = 1
            while True:
                try:
                    err = 0.0
                    for j in range(m):
                        ta = t + j * (t_next - t) / m
                        tb = t_next if j == m - 1 else t + (j + 1) * (t_next - t) / m
                        err = max(err, self._step(ta, tb - ta))
                    if pol.tolerance is not None and err > pol.tolerance \
                            and m < 2 ** pol.max_halvings:
                        self._stats["retries"] += 1
                        self._restore(snap)
                        m *= 2
                        continue
                    self._stats["max_coupling_error"] = max(self._stats["max_coupling_error"], err)
                    self._stats["max_substeps_per_step"] = max(self._stats["max_substeps_per_step"], m)
                    return
                except StepRefused as exc:
                    self._stats["refusals"] += 1
                    if m >= 2 ** pol.max_halvings:
                        raise
                    self._stats["retries"] += 1
                    self._restore(snap)
                    m *= 2
        finally:
            self._free(snap)

    # ---- run ---------------------------------------------------------------------------------
    def run(self, t_end: float, progress: Callable[[float, float], None] | None = None) -> Result:
        """Simulate from t0 to ``t_end`` and return the recorded outputs.

        Raises
        ------
        ValueError
            If ``t_end − t0`` is not a positive whole number of steps (to 1e-9 relative).
        CoSimulationError
            If a block refuses a step that no retry can take (message: time, block, reason).
        """
        h, t0 = self.step, self.t0
        n = whole_steps(t0, t_end, h)
        self._stats = {"macro_steps": 0, "substeps": 0, "retries": 0, "refusals": 0,
                       "max_coupling_error": 0.0, "max_substeps_per_step": 1}
        self._block_time = [0.0] * len(self.blocks)
        wall0 = _time.perf_counter()
        self._initialize()
        rows = array("d")                        # the recorded rows, one after the other
        self._record_row(rows)
        times = [t0]
        # with a progress callback, one step per _advance (it is called after each); else all
        self._chunk = 1 if progress is not None else n
        k = 0
        while k < n:
            k = self._advance(k, n, times, rows, wall0)
            if progress is not None:
                progress(times[-1], t_end)
        return self._result(times, rows, wall0)

    def _advance(self, k: int, n: int, times: list[float], rows: array, wall0: float) -> int:
        """Take macro steps from ``k`` of ``n`` (as many as the run's chunk), appending their
        end times to ``times`` and their recorded outputs to ``rows``; return the index of
        the next step to take.

        Raises
        ------
        CoSimulationError
            If a block refuses a step and no retry can take it.
        """
        return self._steps(k, min(n, k + self._chunk), n, times, rows, wall0)

    def _steps(self, k: int, stop: int, n: int, times: list[float], rows: array,
               wall0: float) -> int:
        """Macro steps ``k`` to ``stop`` − 1 of ``n`` (:meth:`_advance`); returns ``stop``."""
        h, t0 = self.step, self.t0
        stats = self._stats
        pol = self.retry
        plain = pol.max_halvings == 0 and pol.tolerance is None
        step, record, append = self._step_fn, self._record_row, times.append
        while k < stop:
            t, t_next = t0 + k * h, t0 + (k + 1) * h
            try:
                if plain:            # _macro_step without roll-back, written out
                    err = step(self, t, t_next - t)
                    if err > stats["max_coupling_error"]:
                        stats["max_coupling_error"] = err
                else:
                    self._macro_step(k, t, t_next)
            except StepRefused as exc:
                partial = self._result(times, rows, wall0)
                tried = (f"; retried with up to {2 ** pol.max_halvings} substeps"
                         if pol.max_halvings else "; no retry (max_halvings = 0)")
                raise CoSimulationError(
                    f"co-simulation stopped at t = {t:.9g} s (macro step {k + 1} of {n}, "
                    f"h = {h:g} s): block {exc.block!r} refused the step from t = "
                    f"{exc.time:.9g} s over {exc.step:.3g} s: {exc.reason}{tried}. The run is "
                    f"incomplete: no result beyond t = {times[-1]:.9g} s.", t, exc.block,
                    exc.reason, partial) from exc
            stats["macro_steps"] += 1
            record(rows)
            append(t_next)
            k += 1
        return k

    def _record_row(self, rows: array) -> None:
        """Append the recorded outputs at the current communication point to ``rows``."""
        y = self.y
        getters = self._row_getters
        add = rows.frombytes
        if getters is None:
            add(self._row_pack(*[y[i][p] for i, p, _, _ in self._record]))
            return
        for i, get, pack in getters:
            add(pack(*(y[i] if get is None else get(y[i]))))

    def _result(self, times: list[float], rows: array, wall0: float) -> Result:
        data = np.frombuffer(rows, dtype=float).reshape(len(times), len(self._record))
        stats = dict(self._stats)
        stats["wall_time"] = _time.perf_counter() - wall0
        stats["block_time"] = {b.name: tb for b, tb in zip(self.blocks, self._block_time)}
        return Result(np.asarray(times, dtype=float),
                      {name: data[:, c].copy() for c, (_, _, name, _) in enumerate(self._record)},
                      {name: unit for _, _, name, unit in self._record}, stats)

    def terminate(self) -> None:
        """Terminate every block (releases FMU instances)."""
        for b in self.blocks:
            b.terminate()
