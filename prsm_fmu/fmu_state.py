"""The PRSM FMU's state as bytes, and its validation before anything is restored.

The FMU state (``fmi2GetFMUstate`` / ``fmi2SerializeFMUstate``, prsm_fmu/slave.py) is a tuple of
plain builtins (:data:`FIELDS`).  :func:`to_bytes` writes it as :data:`MAGIC` followed by a
pickle; :func:`from_bytes` reads it back with an unpickler that refuses every class or function
reference and every byte after the pickle's end, and never raises: bad bytes give an
:class:`Invalid` that ``fmi2SetFMUstate`` reports.  :func:`check` validates a state whole (type
and length of every field, finiteness of every number of the model's state and of the stepper's
memory) so that the slave restores nothing from a state that fails anywhere.  Needs no
pythonfmu.
"""

from __future__ import annotations

import io
import math
import pickle
from typing import Any, NamedTuple

from .param_ranges import input_violation

__all__ = ["TAG", "MAGIC", "FIELDS", "PHASES", "Invalid", "to_bytes", "from_bytes", "check"]

#: format tag of the state tuple (its first field)
TAG = "prsm-fmu-state/2"
#: first bytes of a serialized state
MAGIC = b"PRSMFMU2"
#: the state tuple's fields, in order
FIELDS = ("tag", "model", "n_stages", "parameters", "inputs", "phase", "time", "x",
          "inputs_held", "memory", "counters", "init_error")
#: the FMU's phases (FMI 2.0 co-simulation states as the slave tracks them)
PHASES = ("instantiated", "initialization", "stepping", "failed", "terminated")
#: the phases with a model (and a state vector)
RUNNING = ("stepping", "terminated")
#: the largest FMI 2.0 Integer (a C int): a counter above it cannot be read by fmi2GetInteger
INT32_MAX = 2**31 - 1
#: deepest nesting of the stepper's memory (tuples in tuples) a state may hold
_MAX_DEPTH = 8


class Invalid(NamedTuple):
    """Bytes that are not a PRSM FMU state (``fmi2DeSerializeFMUstate`` gives this)."""

    reason: str


class _BuiltinsOnly(pickle.Unpickler):
    def find_class(self, module: str, name: str):  # noqa: D102 - refuse every global
        raise pickle.UnpicklingError(f"the bytes refer to {module}.{name}")


def to_bytes(state: tuple) -> bytes:
    """The serialized form of ``state``: :data:`MAGIC` + a pickle of builtins."""
    return MAGIC + pickle.dumps(state, protocol=4)


def from_bytes(data: bytes) -> tuple | Invalid:
    """The state tuple in ``data``, or :class:`Invalid` saying why it is none (never raises)."""
    if not data.startswith(MAGIC):
        return Invalid("the bytes are not a serialized PRSM FMU state (bad header)")
    buf = io.BytesIO(data[len(MAGIC):])
    try:
        state = _BuiltinsOnly(buf).load()
    except Exception as exc:  # noqa: BLE001 - any unpickling error
        return Invalid(f"the bytes are not a serialized PRSM FMU state ({exc})")
    rest = len(data) - len(MAGIC) - buf.tell()
    if rest:
        return Invalid(f"the bytes are not a serialized PRSM FMU state ({rest} bytes after "
                       "its end)")
    if not (isinstance(state, tuple) and state and state[0] == TAG):
        return Invalid("the bytes are not a serialized PRSM FMU state (bad content)")
    return state


def _is_float(v: Any) -> bool:
    return isinstance(v, float)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _finite_floats(v: Any, n: int | None = None) -> bool:
    return (isinstance(v, tuple) and (n is None or len(v) == n)
            and all(_is_float(e) and math.isfinite(e) for e in v))


def _plain(v: Any, depth: int = 0) -> str | None:
    """Why ``v`` is not a plain, finite memory value (None if it is one; bytes: the compiled
    engine's memory, whose length its ``set_memory`` checks)."""
    if v is None or isinstance(v, (bool, str, bytes)) or _is_int(v):
        return None
    if _is_float(v):
        return None if math.isfinite(v) else f"non-finite number {v!r}"
    if isinstance(v, tuple):
        if depth >= _MAX_DEPTH:
            return f"nested deeper than {_MAX_DEPTH}"
        for e in v:
            why = _plain(e, depth + 1)
            if why:
                return why
        return None
    return f"a {type(v).__name__}"


def check(state: Any, model: str, n_stages: int, parameter_types: tuple[type, ...]) -> str | None:
    """Why ``state`` cannot be restored in FMU ``model`` (None if it is a whole, valid state).

    Parameters
    ----------
    state : object
        What ``fmi2SetFMUstate`` received.
    model : str
        The FMU's model name (``PRSM2``); a state of another FMU is refused.
    n_stages : int
        Its stage count.
    parameter_types : tuple of type
        The Python type of each parameter value (float, int or bool), in table order.

    Returns
    -------
    str or None
        The first problem found, naming the field; None if the state is valid.  The length of
        the state vector and the stepper's memory are checked against the model by the slave.
    """
    if isinstance(state, Invalid):
        return state.reason
    if not isinstance(state, tuple) or len(state) != len(FIELDS):
        return (f"not a PRSM FMU state of format {TAG!r}: a {type(state).__name__}"
                + (f" of {len(state)} fields" if isinstance(state, tuple) else ""))
    f = dict(zip(FIELDS, state))
    if f["tag"] != TAG:
        return f"format {f['tag']!r} is not {TAG!r}"
    if f["model"] != model or f["n_stages"] != n_stages:
        return (f"a state of {f['model']!r} ({f['n_stages']!r} stages) cannot be set in "
                f"{model!r} ({n_stages} stages)")
    par = f["parameters"]
    if not (isinstance(par, tuple) and len(par) == len(parameter_types)):
        return f"parameters: need a tuple of {len(parameter_types)} values"
    for i, (v, typ) in enumerate(zip(par, parameter_types)):
        ok = (isinstance(v, bool) if typ is bool else _is_int(v) if typ is int
              else _is_float(v))
        if not ok:
            return f"parameters[{i}] = {v!r} is not a {typ.__name__}"
    if not (isinstance(f["inputs"], tuple) and len(f["inputs"]) == 2
            and all(_is_float(v) for v in f["inputs"])):
        return f"inputs = {f['inputs']!r}: need 2 floats"
    if f["phase"] not in PHASES:
        return f"phase = {f['phase']!r}: must be one of {', '.join(PHASES)}"
    if not (_is_float(f["time"]) and math.isfinite(f["time"])):
        return f"time = {f['time']!r}: must be a finite float [s]"
    running = f["phase"] in RUNNING
    if running and not _finite_floats(f["x"]):
        return f"x = {f['x']!r}: the state vector must be a tuple of finite floats"
    if not running and f["x"] is not None:
        return f"x = {f['x']!r}: must be None in phase {f['phase']!r}"
    if not _finite_floats(f["inputs_held"], 2):
        return f"inputs_held = {f['inputs_held']!r}: need 2 finite floats"
    why = input_violation(f["inputs_held"])
    if why is not None:             # the outputs of such a state could overflow (docs/fmu.md)
        return why                  # (the state vector's bounds need the model: PRSMSlave)
    why = _plain(f["memory"])
    if why:
        return f"memory: {why}"
    c = f["counters"]
    if not (isinstance(c, tuple) and len(c) == 3 and all(_is_int(v) for v in c)
            and 0 <= c[0] <= INT32_MAX and 0 <= c[1] <= INT32_MAX and c[2] in (0, 1, 2)):
        return (f"counters = {c!r}: need step_rhs_calls and step_substeps in [0, {INT32_MAX}] "
                "(an FMI Integer) and step_fidelity 0, 1 or 2")
    if not (f["init_error"] is None or isinstance(f["init_error"], str)):
        return f"init_error = {f['init_error']!r}: must be None or a str"
    return None
