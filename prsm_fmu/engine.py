"""Which engine steps a model: the compiled core or the Python reference.

The compiled core is the C of the native FMU (``fmu_build/native``: the model and its
steppers), run in-process through ctypes (:class:`fmu_build.native_stepper.NativeStepper`).
It is the default engine of every door: the pythonfmu FMU (which loads the library packed in
its ``resources/binaries/<platform>/``), :func:`prsm_fmu.configure.configure` and so the
actuator loop's Python PRSM block, and :func:`prsm_fmu.simulate.simulate` (which compile it
with gcc on first use, cached).  The Python model and steppers stay the readable reference:
``engine="python"`` selects them, and they run wherever the engine cannot.  The engine runs
every level, ``auto`` included (prsm_auto.c; its dynamic steps ROS34PW2's,
:data:`ENGINE_METHOD`).  It falls back to the reference where:

* no engine library loads (no gcc, another platform, a build without it), or the library
  is older than the level (an FMU packed before ``auto`` was in the engine);
* the engine refuses the configuration on construction (a level, drive or friction term the C
  does not model: its own message says which);
* the stepper asked for is not the engine's method at that level (:data:`ENGINE_METHOD`);
* in an FMU whose packed library was built before the engine solved the contact geometry
  itself (no ``prsm_api_new_geometry``), a geometry parameter differs from the value it was
  built with.  A library of this version solves the contact of the geometry it is given
  (``prsm_geometry.c``): geometry set at initialization runs in the engine.

Each fallback carries its reason (:func:`fallback_reason`), which the FMU logs.  As the engine
learns more (levels, friction terms), the doors widen by themselves: they try the engine first
whenever the stepper asked for is the engine's.  The environment variable
``PRSM_FMU_ENGINE=python`` (:data:`ENGINE_ENV`; the command lines' ``--engine python``) selects
the reference in every door of a process that is given no ``engine`` argument, FMUs included.
"""

from __future__ import annotations

import math
from operator import itemgetter
from typing import Any

__all__ = ["ENGINES", "DEFAULT_ENGINE", "ENGINE_ENV", "ENGINE_METHOD", "check_engine",
           "default_engine", "engine_stepper", "fallback_reason", "is_engine", "library_name",
           "library_solves_geometry", "platform_folder"]

#: the engine choices: the compiled core, or the Python reference
ENGINES = ("native", "python")
#: the engine every door uses unless told otherwise
DEFAULT_ENGINE = "native"
#: environment variable that selects the engine of every door of a process and its children
#: (Dask workers, FMUs loaded in it) where no ``engine`` argument is given; the command lines'
#: ``--engine`` sets it
ENGINE_ENV = "PRSM_FMU_ENGINE"
#: per level, every Python stepper the engine translates operation for operation (equal
#: states bit for bit, tests/test_engine_differential.py), the level's method first; any other
#: stepper runs in Python.  ``auto``: the switching of prsm_fmu/models/adaptive.py with every
#: dynamic step ROS34PW2's (the Python stepper ``rosenbrock`` of an auto model)
ENGINE_STEPPERS = {"kinematic": ("closed_form", "closed_form_explicit"),
                   "quasi-static": ("closed_form", "closed_form_explicit"),
                   "dynamic": ("rosenbrock",), "auto": ("rosenbrock",)}
#: per level, the engine's method: what ``default`` means where the engine runs: the Python
#: default of the level (simulate.DEFAULT_STEPPER), except for ``auto``, whose Python default
#: chooses an explicit, exponential or linearly implicit stepper per dynamic step; the engine
#: takes every dynamic step with ROS34PW2 (the same levels chosen by the same rules, other
#: dynamic steps within the same tolerance).
ENGINE_METHOD = {level: steppers[0] for level, steppers in ENGINE_STEPPERS.items()}
#: the library's file name in an FMU's ``resources/binaries/<platform>/``
LIBRARY_STEM = "prsm_engine"

#: reason why no library could be made for a parameter set (by repr): tried once per process
_unavailable: dict[str, str] = {}


def check_engine(engine: Any) -> str:
    """``engine`` if it is one of :data:`ENGINES`.

    Raises
    ------
    ValueError
        Naming the value and the allowed ones.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine = {engine!r} is not allowed: must be one of "
                         f"{', '.join(map(repr, ENGINES))}")
    return engine


def default_engine() -> str:
    """The engine of the doors that are given none: :data:`ENGINE_ENV` if set, else
    :data:`DEFAULT_ENGINE`.

    Raises
    ------
    ValueError
        Naming the variable, its value and the allowed ones.
    """
    import os

    value = os.environ.get(ENGINE_ENV)
    if value is None or value == "":
        return DEFAULT_ENGINE
    if value not in ENGINES:
        raise ValueError(f"{ENGINE_ENV} = {value!r} is not allowed: must be one of "
                         f"{', '.join(map(repr, ENGINES))}")
    return value


def platform_folder() -> str:
    """The FMI 2.0 platform folder of this process (``linux64``, ``darwin64``, ``win64``)."""
    import platform
    import sys

    bits = "64" if sys.maxsize > 2 ** 32 else "32"
    system = {"Linux": "linux", "Darwin": "darwin", "Windows": "win"}.get(platform.system(),
                                                                           platform.system())
    return system + bits


def library_name() -> str:
    """The engine library's file name on this platform (``prsm_engine.so`` on Linux)."""
    import sys

    ext = ".dll" if sys.platform.startswith("win") else ".dylib" if sys.platform == "darwin" \
        else ".so"
    return LIBRARY_STEM + ext


def is_engine(stepper: Any) -> bool:
    """Whether ``stepper`` is the compiled engine."""
    return getattr(stepper, "name", "") == "native"


def fallback_reason(stepper: Any) -> str | None:
    """Why ``stepper`` is the Python reference although the engine was asked for (None: the
    engine runs, or the reference was asked for)."""
    return getattr(stepper, "engine_fallback", None)


#: the engine's ctypes interface as an FMU packs it (a module of its own name, so that it never
#: shadows the fmu_build package of a process that has one)
PACKED_INTERFACE = "prsm_engine_interface"


def _interface():
    """The module :mod:`fmu_build.native_stepper`: the installed one, else the FMU's copy."""
    try:
        from fmu_build import native_stepper
    except ImportError:
        import importlib

        return importlib.import_module(PACKED_INTERFACE)
    return native_stepper


def library_solves_geometry(library_path: str) -> bool:
    """Whether the engine library at ``library_path`` solves the contact geometry of the
    geometry it is given (``prsm_api_new_geometry``); False if it does not load."""
    try:
        interface = _interface()
        return bool(interface.solves_geometry(interface.load_library(library_path)))
    except Exception:  # noqa: BLE001 - an older interface, a library that does not load
        return False


def _library(params, library_path: str | None):
    """The loaded engine library, or the reason why none loads (str)."""
    try:
        native_stepper = _interface()
    except Exception as exc:  # noqa: BLE001 - any failure means: no engine here
        return f"the engine's interface cannot be imported ({type(exc).__name__}: {exc})"
    if library_path is not None:
        try:
            return native_stepper.load_library(library_path)
        except OSError as exc:
            return f"the engine library {library_path} does not load ({exc})"
    key = repr(params)
    if key in _unavailable:
        return _unavailable[key]
    try:
        return native_stepper.native_library(params)
    except Exception as exc:  # noqa: BLE001 - BuildError (no gcc), OSError
        why = f"no engine library for these parameters ({type(exc).__name__}: {exc})"
        _unavailable[key] = why
        return why


def engine_stepper(model: Any, level: str, stepper: str, rtol: float, atol: float,
                   max_substeps: int = 100000, fixed_substeps: int | None = None,
                   library_path: str | None = None, refusal: str | None = None):
    """The engine's stepper for ``model``, or the reason why it cannot run it.

    Parameters
    ----------
    model : prsm_fmu.models.base.Model
        The model (its parameters, level and drive).
    level : str
        The configured level (``kinematic``, ``quasi-static``, ``dynamic`` or ``auto``).
    stepper : str
        The stepper asked for, or ``"default"``.
    rtol, atol : float
        Relative [-] and absolute [state units] tolerances (the Python steppers' meaning).
    max_substeps, fixed_substeps : int
        Internal steps allowed per advance; equal internal steps (None or 0: adaptive).
    library_path : str, optional
        A prebuilt library to load (an FMU's); default: compiled for ``model``'s parameters.
    refusal : str, optional
        A reason known beforehand why the engine cannot run (then it is not tried).

    Returns
    -------
    tuple
        ``(stepper, None)`` with the engine's stepper, or ``(None, reason)``.
    """
    method = ENGINE_METHOD.get(level)
    allowed = ENGINE_STEPPERS.get(level, ())
    if stepper != "default" and stepper not in allowed:
        return None, (f"stepper = {stepper!r} is not the engine's (it runs "
                      f"{', '.join(allowed) or 'no fixed method'} at fidelity = {level!r})")
    name = method if stepper == "default" else stepper
    if refusal:
        return None, refusal
    if not (math.isfinite(rtol) and math.isfinite(atol)):
        return None, "non-finite tolerances"
    lib = _library(model.params, library_path)
    if isinstance(lib, str):
        return None, lib
    try:
        st = _engine_class()(model, rtol=rtol, atol=atol, max_substeps=max_substeps,
                             fixed_substeps=fixed_substeps or None, library=lib,
                             stepper=name)
    except ValueError as exc:
        return None, f"the engine refuses this configuration: {exc}"
    return st, None


_ENGINE_CLASS: list[type] = []


def _doubles(array) -> memoryview:
    """A memoryview of the doubles of a ctypes array (``tolist`` reads them all at once,
    several times faster than slicing the array)."""
    return memoryview(array).cast("B").cast("d")

#: the places in ``prsm_api_step``'s block of doubles (prsm_api.c, PRSM_IO_*; the state's and
#: the outputs' the C tells): the FMU's time, the communication point, the step size, the
#: inputs, the counts, the time match
STEP_IO_T, STEP_IO_CURRENT, STEP_IO_STEP, STEP_IO_U, STEP_IO_STATS, STEP_IO_MATCH = (
    0, 1, 2, 3, 5, 8)


def _engine_class() -> type:
    """:class:`fmu_build.native_stepper.NativeStepper` with a lean :meth:`advance` for the
    doors' hot path (an FMU's doStep): one ctypes call into preallocated arrays, no numpy, no
    list of rows.  Its results are the same call's (``prsm_api_advance_many`` with one step)."""
    if _ENGINE_CLASS:
        return _ENGINE_CLASS[0]
    import ctypes

    NativeStepper = _interface().NativeStepper

    from .steppers.base import StepFailure, StepStats

    class EngineStepper(NativeStepper):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self._row = (ctypes.c_double * self.n_states)()
            # the same C function without declared argument types: ctypes then converts
            # nothing (the arrays pass as pointers, the doubles are wrapped here), a third of
            # the declared call's cost (benchmarks/fmu_step_cost.py)
            lib = self._lib
            self._call = type(lib.prsm_api_advance_many)(("prsm_api_advance_many", lib))
            self._call.restype = ctypes.c_int
            self._double = ctypes.c_double
            self._msg_len = len(self._msg)
            # the memory of an FMU state (fmi2GetFMUstate, once per communication step of a
            # master that saves and restores) into a buffer made once, through the same
            # function without declared argument types
            self._memory = ctypes.create_string_buffer(self._memory_size)
            self._get_mem = type(lib.prsm_api_get_memory)(("prsm_api_get_memory", lib))
            self._get_mem.restype = None

        def get_memory(self) -> tuple:
            """``(bytes,)``: the C stepper's memory, as :meth:`NativeStepper.get_memory`."""
            self._get_mem(self._handle, self._memory)
            return (self._memory.raw,)

        def advance(self, t: float, x: list[float], u: tuple, h: float):
            if not (0.0 < h < math.inf):
                raise ValueError(f"h = {h!r} is out of range: must be a finite number > 0 [s]")
            xi, ui, counts, double = self._x, self._u, self._stats, self._double
            xi[:] = x
            ui[0] = u[0]
            ui[1] = u[1]
            failed = self._call(self._handle, double(t), xi, ui, double(h), 1, self._row, counts,
                                self._msg, self._msg_len)
            if self._auto:
                self.sync_mode()
            if failed:
                raise StepFailure(self._msg.value.decode())
            stats = StepStats(rhs_calls=counts[0], substeps=counts[1], rejected=counts[2])
            return self._row[:], stats

        def step_block(self, time_match: float, names: tuple[str, ...]):
            """The engine's one-call step of an FMU's doStep (``prsm_api_step``) and its
            outputs, or None for a library without them.

            Parameters
            ----------
            time_match : float
                How far [-] a communication point may lie from the FMU's time, relative to
                max(1 s, |time|), and still be the same point.
            names : tuple of str
                The FMU's Real outputs, in its order.

            Returns
            -------
            tuple or None
                ``(io, step, x, outputs)``: ``io`` the C's block of doubles (a ctypes array
                over the handle's memory, laid out as ``prsm_api.c`` says: [0] the FMU's time
                [s], [1] the communication point [s], [2] the step size [s], [3:5] the inputs,
                [5:8] the last step's rhs calls, accepted and rejected substeps, [8]
                ``time_match``, then the state); ``step(io)`` takes the step and returns 0,
                else 1 (not taken: time, step size or inputs) or 2 (the integration fails or
                ends out of the state's bounds), nothing changed; ``x`` the state's part of
                ``io``; ``outputs()`` the values of ``names`` at ``io``'s state and inputs
                (``prsm_api_step_outputs``: after a step, the outputs at its end), None where
                the C does not compute them all.  ``io`` keeps this stepper (and so the
                handle) alive.
            """
            lib = self._lib
            if not hasattr(lib, "prsm_api_step"):   # an engine library packed before it
                return None
            block = type(lib.prsm_api_step_io)(("prsm_api_step_io", lib))
            block.restype, block.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
            io = (ctypes.c_double * lib.prsm_api_step_io_size()).from_address(
                block(self._handle))
            io.owner = self
            io[STEP_IO_MATCH] = time_match
            size = ctypes.sizeof(ctypes.c_double)
            x = (ctypes.c_double * self.n_states).from_address(
                ctypes.addressof(io) + lib.prsm_api_step_io_x() * size)
            x.owner = io
            # no declared argument types: the array passes as its pointer, nothing converted
            step = type(lib.prsm_api_step)(("prsm_api_step", lib))
            step.restype = ctypes.c_int
            pick = self._picker(names)
            outputs = None
            if pick is not None:
                compute = type(lib.prsm_api_step_outputs)(("prsm_api_step_outputs", lib))
                compute.restype = None
                out = (ctypes.c_double * len(self.output_names)).from_address(
                    ctypes.addressof(io) + lib.prsm_api_step_io_out() * size)
                out.owner = io
                values = _doubles(out)

                def outputs() -> list[float]:
                    compute(io)
                    return pick(values.tolist())

            return io, step, x, outputs

        def _picker(self, names: tuple[str, ...]):
            """A function that picks the values of ``names`` out of the list of the C's
            outputs (in the order of :attr:`output_names`), or None when the C does not
            compute every one of them."""
            position = {name: i for i, name in enumerate(self.output_names)}
            if not names or any(name not in position for name in names):
                return None
            index = [position[name] for name in names]
            if index == list(range(len(position))):
                return lambda values: values
            if len(index) == 1:
                return lambda values: [values[index[0]]]
            pick = itemgetter(*index)        # (a tuple of two or more)
            return lambda values: list(pick(values))

        def output_reader(self, names: tuple[str, ...]):
            """A function ``(t, x, u) -> list`` of the values of the outputs ``names`` at
            state ``x`` with inputs ``u``, computed by the C in one call
            (``prsm_api_outputs``) into preallocated arrays, equal to the model's
            ``outputs`` bit for bit (tests/test_engine_outputs.py); None when the C does not
            compute every one of them (or the library has no prsm_api_outputs)."""
            pick = self._picker(names) if self.output_names else None
            if pick is None:
                return None
            lib = self._lib
            call = type(lib.prsm_api_outputs)(("prsm_api_outputs", lib))
            call.restype = None
            out = (ctypes.c_double * len(self.output_names))()
            values = _doubles(out)
            xi, ui, handle, double = self._x, self._u, self._handle, self._double

            def read(t: float, x: list[float], u: tuple) -> list[float]:
                xi[:] = x
                ui[0] = u[0]
                ui[1] = u[1]
                call(handle, double(t), xi, ui, out)
                return pick(values.tolist())

            return read

    _ENGINE_CLASS.append(EngineStepper)
    return EngineStepper
