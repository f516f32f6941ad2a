"""Any FMI 2.0 co-simulation FMU as a :class:`~system_models.blocks.Block`, through fmpy.

:class:`FMUBlock` drives fmpy's ``FMU2Slave``: instantiate (with a logger that keeps every
message), ``setupExperiment``, parameters set in initialization mode, ``doStep``, ``getReal``
(and ``getInteger`` for Integer outputs), ``getFMUstate``/``setFMUstate`` for roll-back.  It
knows nothing about the PRSM.

How it reacts to the FMU (docs/fmu.md, "Errors"):

* ``doStep`` returns fmi2Discard → :class:`~system_models.blocks.StepRefused` with the FMU's
  log messages of that call as the reason.  The FMU's state is as before the call, so the
  master may retry (smaller step) or stop with an error naming the time and the reason.
* any other failing call (fmi2Error, fmi2Fatal) → :class:`FMUError` with the messages; the
  instance must not be used again.  So does an error logged during ``exitInitializationMode``
  (an FMU built with pythonfmu reports a failed initialization that way, with fmi2OK).

:func:`ensure_fmu` builds ``dist/PRSM<n>.fmu`` with ``python -m fmu_build`` in a child process
when it is missing or older than the sources (a process that loads an FMU must not be the one
that built it: pythonfmu imports the generated module while building).
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Sequence

from prsm_fmu.fmi_enum import enumeration_value
from prsm_fmu.fmu_log import STATUS as _STATUS
from prsm_fmu.fmu_log import FmuLog

from .blocks import Block, Port, StepRefused
from .fmu_cache import release, unpack

__all__ = ["FMUBlock", "FMUError", "ensure_fmu", "fmu_is_stale"]

_double = ctypes.c_double


def _bare(dll: Any, name: str) -> Any:
    """The FMI function ``name`` of ``dll`` with no declared argument types (every argument
    must be a ctypes object, or an int for an fmi2Boolean) and fmi2Status as its result."""
    f = type(getattr(dll, name))((name, dll))
    f.restype = ctypes.c_int
    return f


class FMUError(RuntimeError):
    """An FMU call failed with fmi2Error or fmi2Fatal (or the FMU cannot be loaded)."""


_ROOT = Path(__file__).resolve().parents[1]


def _sources() -> list[Path]:
    """The files an FMU is built from: prsm_fmu and fmu_build (Python sources, and the C
    sources of the native FMU), and the regression baselines it packs (``extra/``)."""
    files: list[Path] = []
    for pkg in ("prsm_fmu", "fmu_build"):
        d = _ROOT / pkg
        if d.is_dir():
            files += [p for p in d.rglob("*.py")]
    native = _ROOT / "fmu_build" / "native"
    if native.is_dir():
        files += sorted(native.glob("*.[ch]"))
    baselines = _ROOT / "baselines"
    if baselines.is_dir():
        files += sorted(p for p in baselines.iterdir() if p.is_file())
    return files


def fmu_is_stale(path: str | os.PathLike) -> str | None:
    """Why the FMU at ``path`` needs (re)building, or None if it is up to date."""
    p = Path(path)
    if not p.is_file():
        return "missing"
    built = p.stat().st_mtime
    newer = [s for s in _sources() if s.stat().st_mtime > built]
    if newer:
        return f"older than {newer[0].relative_to(_ROOT)}"
    return None


def ensure_fmu(path: str | os.PathLike = "dist/PRSM2.fmu", rebuild_stale: bool = True,
               stream=None) -> Path:
    """Return ``path``, building it first if missing (or stale) in a child process.

    The FMU's name (``PRSM1``, ``PRSM2``, ``PRSM3``) is the file's stem; the build runs
    ``python -m fmu_build NAME --dest DIR`` with this interpreter (a stem ``PRSM2-native``:
    ``python -m fmu_build --native --fmi-version 2 PRSM2``, the native C FMU).

    Raises
    ------
    FMUError
        If the build fails (its output is in the message), e.g. pythonfmu is not installed.
    """
    p = Path(path)
    why = fmu_is_stale(p)
    if why is None or (why != "missing" and not rebuild_stale):
        return p
    name = p.stem
    extra = []
    if name.endswith("-native"):
        name, extra = name.removesuffix("-native"), ["--native", "--fmi-version", "2"]
    stream = sys.stderr if stream is None else stream
    print(f"building {p} ({why}) with python -m fmu_build {' '.join(extra + [name])} ...",
          file=stream, flush=True)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(_ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH")
                                                        else []))
    proc = subprocess.run([sys.executable, "-m", "fmu_build", *extra, name, "--dest",
                           str(p.parent or ".")],
                          capture_output=True, text=True, env=env, timeout=600)
    if proc.returncode != 0 or not p.is_file():
        hint = ""
        if "No module named 'pythonfmu'" in proc.stderr:
            hint = " (install the fmu extra: pip install -e \".[fmu]\")"
        raise FMUError(f"building {p} failed{hint}:\n{proc.stdout}{proc.stderr}".rstrip())
    return p


class FMUBlock(Block):
    """One instance of an FMI 2.0 co-simulation FMU (module docstring).

    Parameters
    ----------
    path : path-like
        The ``.fmu`` file.
    name : str
        Block (and FMU instance) name.
    inputs, outputs : sequence of str, optional
        Variables used as the block's ports (default: every Real input; every Real output).
        Outputs may also be Integer variables (read as floats).
    parameters : dict, optional
        Start values set in initialization mode (Real, Integer, Boolean or String, by name).
    start_time : float
        ``setupExperiment`` start time [s].
    """

    interpolates_inputs = False    # FMI 2.0 inputs are held over the step (no input derivatives)
    feedthrough = False

    def __init__(self, path: str | os.PathLike, name: str = "fmu",
                 inputs: Sequence[str] | None = None, outputs: Sequence[str] | None = None,
                 parameters: dict[str, Any] | None = None, start_time: float = 0.0) -> None:
        try:
            from fmpy import read_model_description
            from fmpy.fmi2 import FMU2Slave
        except ImportError as exc:
            raise FMUError(f"fmpy is needed to run an FMU ({exc}): pip install -e \".[fmu]\", "
                           "or run the PRSM as the plain Python model (--prsm python)") from None

        self.name = name
        self.path = Path(path)
        if not self.path.is_file():
            raise FMUError(f"{self.path}: no such FMU (build it with python -m fmu_build)")
        md = read_model_description(str(self.path))
        if md.coSimulation is None:
            raise FMUError(f"{self.path} is not a co-simulation FMU")
        self.model_description = md
        self.vars = {v.name: v for v in md.modelVariables}
        in_names = list(inputs) if inputs is not None else [
            v.name for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
        out_names = list(outputs) if outputs is not None else [
            v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        for n in in_names + out_names:
            if n not in self.vars:
                raise FMUError(f"{self.path}: no variable {n!r}")
        self.inputs = tuple(self._port(n) for n in in_names)
        self.outputs = tuple(self._port(n) for n in out_names)
        self._vr_in = [self.vars[n].valueReference for n in in_names]
        self._log = FmuLog()                     # keeps the ctypes callbacks alive
        self.messages = self._log.messages
        # the step loop's calls go straight to the FMU's C functions with buffers made once
        # (fmpy's wrappers build two ctypes arrays per call); statuses are checked here
        from fmpy.fmi2 import fmi2Real, fmi2ValueReference
        self._buf_in = (fmi2Real * len(self._vr_in))()
        self._arr_in = (fmi2ValueReference * len(self._vr_in))(*self._vr_in)
        self._read(range(len(out_names)))
        # unpacked once per FMU file and kept (system_models.fmu_cache), not at every run
        self._unzipdir, self._private_copy = unpack(self.path)
        self._alive = False
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        try:
            self.fmu.instantiate(callbacks=self._log.callbacks, loggingOn=True)
        except Exception as exc:
            release(self._unzipdir, self._private_copy)
            self._unzipdir = None
            raise FMUError(f"{self.path}: instantiation failed: {exc}") from exc
        self._alive = True
        # the step loop's four functions without fmpy's declared argument types, every
        # argument passed as a ctypes object made once (the instance, the lengths) or a
        # c_double: ctypes then converts nothing per call
        dll = self.fmu.dll
        self._c_set_real, self._c_get_real, self._c_get_integer, self._c_do_step = (
            _bare(dll, name) for name in ("fmi2SetReal", "fmi2GetReal", "fmi2GetInteger",
                                          "fmi2DoStep"))
        #: the instance's fmi2Component (fixed from instantiation to fmi2FreeInstance)
        self._component = ctypes.c_void_p(self.fmu.component)
        self._n_in = ctypes.c_size_t(len(self._vr_in))
        try:
            self._call("setupExperiment", startTime=float(start_time))
            self._call("enterInitializationMode")
            self.set_values(parameters or {})
            n0 = len(self.messages)
            self._call("exitInitializationMode")
            # an FMU that cannot return fmi2Error here (pythonfmu's) logs its failure instead
            errors = [m for label, m in self.messages[n0:] if label in ("error", "fatal")]
            if errors:
                raise FMUError(f"{self.name}: exitInitializationMode logged an error: "
                               + "; ".join(errors))
        except FMUError:
            self.terminate()
            raise

    # ---- helpers ------------------------------------------------------------------------------
    def _port(self, name: str) -> Port:
        v = self.vars[name]
        unit = getattr(v, "unit", None) or (v.declaredType.unit if getattr(v, "declaredType", None)
                                            else None) or ("1" if v.type != "Real" else "")
        return Port(name, unit, v.description or "", discrete=v.variability == "discrete")

    def _call(self, fname: str, *args, **kwargs):
        from fmpy.fmi1 import FMICallException

        n0 = len(self.messages)
        try:
            return getattr(self.fmu, fname)(*args, **kwargs)
        except FMICallException as exc:
            raise FMUError(f"{self.name}: {fname} failed with status {exc.status} "
                           f"({_STATUS[exc.status] if 0 <= exc.status < 6 else '?'})"
                           + self._since(n0)) from exc

    def _check(self, fname: str, status: int, n0: int) -> None:
        """Raise :class:`FMUError` for a status above fmi2Warning of a direct call."""
        if status > 1:
            raise FMUError(f"{self.name}: {fname} failed with status {status} "
                           f"({_STATUS[status] if 0 <= status < 6 else '?'})" + self._since(n0))

    def _since(self, n0: int) -> str:
        msgs = self._log.reason(n0)
        return (": " + msgs) if msgs else " (the FMU logged no message)"

    def _read(self, ports: Sequence[int]) -> None:
        """Buffers of the outputs :meth:`get_outputs` reads: ``ports`` (positions in
        :attr:`outputs`), Real ones with one fmi2GetReal, Integer ones with one
        fmi2GetInteger."""
        from fmpy.fmi2 import fmi2Integer, fmi2Real, fmi2ValueReference

        names = [self.outputs[i].name for i in ports]
        real = [k for k, n in enumerate(names) if self.vars[n].type == "Real"]
        ints = [k for k, n in enumerate(names) if self.vars[n].type != "Real"]
        vr_real = [self.vars[names[k]].valueReference for k in real]
        self._vr_int = [self.vars[names[k]].valueReference for k in ints]
        self._buf_real = (fmi2Real * len(vr_real))()
        self._arr_real = (fmi2ValueReference * len(vr_real))(*vr_real)
        self._buf_int = (fmi2Integer * len(self._vr_int))()
        self._arr_int = (fmi2ValueReference * len(self._vr_int))(*self._vr_int)
        self._n_real = ctypes.c_size_t(len(vr_real))
        self._n_int = ctypes.c_size_t(len(self._vr_int))
        # the buffers' values as memoryviews: tolist() reads them all at once, several times
        # faster than slicing a ctypes array
        self._real_values = memoryview(self._buf_real).cast("B").cast("d")
        self._int_values = memoryview(self._buf_int).cast("B").cast("i")
        #: the Real values first, then the Integer ones: where each selected output is in
        #: that list (None: they are in order already)
        merged = real + ints
        self._order = None if merged == sorted(merged) else [merged.index(k)
                                                               for k in range(len(names))]
        self._n_read = len(names)

    def select_outputs(self, ports: Sequence[int]) -> bool:
        """Read only the outputs at ``ports`` (positions in :attr:`outputs`) from now on: the
        variables nobody uses are not read (:meth:`Block.select_outputs`)."""
        self._read(list(ports))
        return True

    def set_values(self, values: dict[str, Any]) -> None:
        """Set variables by name with the setter of their type; an Enumeration takes an item
        name (from the modelDescription's TypeDefinitions) or its integer value."""
        for n, value in values.items():
            if n not in self.vars:
                raise FMUError(f"{self.path}: no variable {n!r} (parameter {n} = {value!r})")
            v = self.vars[n]
            setter = {"Real": "setReal", "Integer": "setInteger", "Boolean": "setBoolean",
                      "String": "setString", "Enumeration": "setInteger"}[v.type]
            conv = {"Real": float, "Integer": int, "Boolean": bool, "String": str,
                    "Enumeration": lambda x, v=v: enumeration_value(v, x)}[v.type]
            try:
                converted = conv(value)
            except ValueError as exc:
                raise FMUError(f"{self.path}: {exc}") from None
            self._call(setter, [v.valueReference], [converted])

    def get_values(self, names: Sequence[str]) -> list[Any]:
        """Read variables by name (any type)."""
        out = []
        for n in names:
            v = self.vars[n]
            getter = {"Real": "getReal", "Integer": "getInteger", "Boolean": "getBoolean",
                      "String": "getString", "Enumeration": "getInteger"}[v.type]
            value = self._call(getter, [v.valueReference])[0]
            out.append(value.decode("utf-8") if isinstance(value, bytes) else value)
        return out

    # ---- Block interface ------------------------------------------------------------------
    def set_inputs(self, values: Sequence[float], slopes: Sequence[float] | None = None) -> None:
        buf = self._buf_in
        n = len(buf)
        if len(values) != n:
            raise ValueError(f"{self.name}: {len(values)} input values for {n} inputs")
        buf[:] = values                  # ctypes converts to double (TypeError if it cannot)
        n0 = len(self.messages)
        status = self._c_set_real(self._component, self._arr_in, self._n_in, buf)
        if status > 1:
            self._check("setReal", status, n0)

    def get_outputs(self) -> list[float]:
        """The selected outputs (every output unless :meth:`select_outputs` narrowed them)."""
        n0 = len(self.messages)
        comp = self._component
        real = self._buf_real
        if len(real):
            status = self._c_get_real(comp, self._arr_real, self._n_real, real)
            if status > 1:
                self._check("getReal", status, n0)
        if not self._vr_int:
            return self._real_values.tolist()
        ints = self._buf_int
        status = self._c_get_integer(comp, self._arr_int, self._n_int, ints)
        if status > 1:
            self._check("getInteger", status, n0)
        out = self._real_values.tolist() + list(map(float, self._int_values.tolist()))
        order = self._order
        return out if order is None else [out[k] for k in order]

    def do_step(self, t: float, h: float) -> None:
        n0 = len(self.messages)
        status = self._c_do_step(self._component, _double(t), _double(h), 1)
        if status == 2:              # fmi2Discard: state unchanged, may retry
            raise StepRefused(self.name, t, h, self._since(n0)[2:])
        if status > 1:
            raise self.step_error(t, h, status, n0)

    def step_error(self, t: float, h: float, status: int, n0: int) -> FMUError:
        """The error of a ``doStep(t, h)`` [s] that returned ``status`` (fmi2Error or worse),
        with the FMU's messages since the ``n0``-th."""
        return FMUError(f"{self.name}: doStep(t = {t!r} s, h = {h!r} s) failed with status "
                        f"{status} ({_STATUS[status] if 0 <= status < 6 else '?'})"
                        + self._since(n0))

    def get_state(self) -> Any:
        return self._call("getFMUstate")

    def set_state(self, state: Any) -> None:
        self._call("setFMUstate", state)

    def free_state(self, state: Any) -> None:
        if self._alive:
            self._call("freeFMUstate", state)

    def terminate(self) -> None:
        if self._alive:
            self._alive = False
            try:
                self.fmu.terminate()
            except Exception:  # noqa: BLE001 - an instance that failed may refuse; free anyway
                pass
            try:
                self.fmu.freeInstance()
            except Exception:  # noqa: BLE001
                pass
        if self._unzipdir is not None:
            release(self._unzipdir, self._private_copy)
            self._unzipdir = None
