"""The native FMU's C model and steppers in-process: a stepper for :mod:`prsm_fmu` models.

:class:`NativeStepper` advances a :class:`prsm_fmu.models.base.Model` (its state, inputs and
communication steps) with the C code of the native FMU (``fmu_build/native``): the same
mechanics and, at the dynamic level, the same ROS34PW2 with the FMU's tuned options, translated
operation for operation, so that its states equal those of :func:`prsm_fmu.steppers.make_stepper`
``("rosenbrock", model, **tuned_stepper_options("rosenbrock", rtol, atol))`` bit for bit
(tests/test_native_stepper.py).  It is what the dynamic level costs without Python: the
work-precision study times the Li et al. (2021) start-up with it.

The C is compiled with gcc, with the geometry of the model's preset built in as its default
(:func:`fmu_build.native.constants_header`; the stepper passes the model's own geometry, whose
contact the C solves, ``prsm_geometry.c``), into a shared library cached by the hash of its
sources in a directory of the user's own in the system's temporary directory; it exchanges only
doubles and ints with Python (``prsm_api.c``, through ctypes).  Every friction term is modelled
(Coulomb, the friction-torque article's viscous and differential-sliding terms, the joints);
both drives at every level, and ``fidelity = "auto"`` (an :class:`~prsm_fmu.models.AdaptiveModel`:
the switching between the dynamic and the quasi-static level of prsm_fmu/models/adaptive.py,
in ``prsm_auto.c``, its dynamic steps ROS34PW2's, as the Python stepper ``rosenbrock`` of that
model).
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path
from typing import Any

from prsm_fmu import geometry
from prsm_fmu.steppers.base import StepFailure, StepStats, Stepper

__all__ = ["NativeStepper", "native_library", "load_library", "library_output_names",
           "contact_solver", "solves_geometry", "auto_start_level", "GEOMETRY_REALS",
           "LIB_SOURCES"]

#: the library's sources: the model, its steppers and the flat interface
LIB_SOURCES = ("prsm_model.c", "prsm_ros.c", "prsm_band.c", "prsm_geometry.c", "prsm_auto.c",
               "prsm_api.c")
_STAGE_REALS = ("screw_mass", "nut_mass", "roller_mass", "carrier_mass", "screw_inertia",
                "roller_inertia", "carrier_inertia", "spline_radius", "bearing_radius")
#: the geometry's real parameters per stage, in the order prsm_api_new_geometry reads them (and
#: of the built-in PRSM_GEOMETRY rows); screw_starts is its integer one
GEOMETRY_REALS = ("screw_radius", "roller_radius", "nut_radius", "screw_lead", "flank_angle")
_LEVELS = {"kinematic": 0, "quasi-static": 1, "dynamic": 2, "auto": 3}
#: auto's start level as prsm_api_new_auto reads it, and its level codes (prsm_api_auto_mode)
_AUTO_START = {"dynamic": 0, "quasi-static": 1}
_AUTO_MODES = {2: "dynamic", 1: "quasi-static"}
#: the Python steppers the C translates, per level, and the band method of each (1: the
#: exponential band step, 0: Dormand-Prince 5(4); None: the dynamic level's ROS34PW2)
STEPPERS = {"kinematic": {"closed_form": 1, "closed_form_explicit": 0},
            "quasi-static": {"closed_form": 1, "closed_form_explicit": 0},
            "dynamic": {"rosenbrock": None},
            "auto": {"rosenbrock": None}}
_MSG = 600
#: libraries loaded in this process, by source hash and by the parameters' repr
_loaded: dict[str, ctypes.CDLL] = {}
_by_params: dict[str, ctypes.CDLL] = {}
#: per stage count, a loaded library that solves any geometry (NativeStepper passes the model's)
_by_stages: dict[int, ctypes.CDLL] = {}


def native_library(params) -> ctypes.CDLL:
    """The C model for ``params`` as a loaded shared library: built on first use with ``params``'
    geometry as its default, then reused in this process for every mechanism of as many stages
    (the stepper passes each model's geometry, whose contact the C solves).

    Raises
    ------
    BuildError
        When gcc is missing or fails.
    """
    key = repr(params)
    if key in _by_params:
        return _by_params[key]
    # a library that solves the geometry it is given serves every mechanism with as many
    # stages: another geometry compiles nothing
    dll = _by_stages.get(params.n_stages)
    if dll is None:
        dll = load_library(str(library_file(params)))
        if solves_geometry(dll):
            _by_stages[params.n_stages] = dll
    _by_params[key] = dll
    return dll


def library_file(params) -> Path:
    """The shared library of ``params``' geometry, compiled with gcc on first use and cached
    (fmu_build.native.cached_library).

    Raises
    ------
    BuildError
        When gcc is missing or fails.
    """
    from . import native     # the build tools: not needed where a library is only loaded

    return native.cached_library("prsm", library_sources(params), LIB_SOURCES)


def library_sources(params) -> dict[str, bytes]:
    """The engine library's files for ``params``' geometry: the C sources and headers, and
    ``prsm_constants.h`` generated from the parameters (fmu_build.native.constants_header)."""
    from . import native

    files = {f: (native.SOURCE_DIR / f).read_bytes() for f in LIB_SOURCES + native.HEADERS}
    files["prsm_constants.h"] = native.constants_header(params).encode()
    return files


def load_library(path: str) -> ctypes.CDLL:
    """The library at ``path`` (from :func:`library_file`, or packed in an FMU) loaded, with
    its functions' argument types declared; loaded once per path and process.

    Raises
    ------
    OSError
        When the file cannot be loaded (missing, other platform).
    """
    if path in _loaded:
        return _loaded[path]
    dll = ctypes.CDLL(path)
    dbl, i32, vp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int), ctypes.c_void_p
    dll.prsm_api_new.restype = vp
    dll.prsm_api_new.argtypes = [dbl, i32, ctypes.c_char_p, ctypes.c_int]
    dll.prsm_api_new_terms.restype = vp
    dll.prsm_api_new_terms.argtypes = [dbl, i32, dbl, i32, ctypes.c_char_p, ctypes.c_int]
    if solves_geometry(dll):
        dll.prsm_api_new_geometry.restype = vp
        dll.prsm_api_new_geometry.argtypes = [dbl, i32, dbl, i32, dbl, i32, ctypes.c_char_p,
                                              ctypes.c_int]
    dll.prsm_api_set_tolerances.argtypes = [vp, ctypes.c_double, ctypes.c_double]
    dll.prsm_api_n_states.argtypes = [vp]
    dll.prsm_api_advance_many.argtypes = [vp, ctypes.c_double, dbl, dbl, ctypes.c_double,
                                          ctypes.c_int, dbl, i32, ctypes.c_char_p, ctypes.c_int]
    dll.prsm_api_rhs.argtypes = [vp, dbl, dbl, dbl]
    dll.prsm_api_get_memory.argtypes = [vp, ctypes.c_char_p]
    dll.prsm_api_set_memory.argtypes = [vp, ctypes.c_char_p]
    dll.prsm_api_free.argtypes = [vp]
    dll.prsm_api_set_band.argtypes = [vp, ctypes.c_int]
    dll.prsm_api_undo_advance.argtypes = [vp]
    if hasattr(dll, "prsm_api_contact_geometry"):   # (and these)
        dll.prsm_api_contact_geometry.restype = ctypes.c_int
        dll.prsm_api_contact_geometry.argtypes = [ctypes.c_double, ctypes.c_double,
                                                  ctypes.c_double, ctypes.c_int,
                                                  ctypes.c_double, dbl]
        geometry.use_compiled_solver(contact_solver(dll))
    if hasattr(dll, "prsm_api_new_auto"):    # (an engine library packed before auto was added)
        dll.prsm_api_new_auto.restype = vp
        dll.prsm_api_new_auto.argtypes = [dbl, i32, dbl, i32, dbl, i32, ctypes.c_double,
                                          ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        dll.prsm_api_auto_mode.argtypes = [vp]
        dll.prsm_api_auto_info.argtypes = [vp, dbl]
        dll.prsm_api_handle_memory_size.argtypes = [vp]
        dll.prsm_api_reset.argtypes = [vp]
        dll.prsm_api_auto_choose.argtypes = [dbl, i32, dbl, i32, dbl, i32, ctypes.c_double, dbl,
                                             ctypes.c_double, ctypes.c_int, ctypes.c_double, dbl,
                                             ctypes.c_char_p, ctypes.c_int]
    if hasattr(dll, "prsm_api_outputs"):     # (an engine library packed before they were added)
        dll.prsm_api_output_name.restype = ctypes.c_char_p
        dll.prsm_api_output_name.argtypes = [ctypes.c_int]
        dll.prsm_api_outputs.argtypes = [vp, ctypes.c_double, dbl, dbl, dbl]
    if hasattr(dll, "prsm_api_advance_schedule"):     # (likewise)
        dll.prsm_api_advance_schedule.restype = ctypes.c_int
        dll.prsm_api_advance_schedule.argtypes = [vp, dbl, ctypes.c_int, dbl, dbl, dbl, i32, dbl,
                                                  dbl, i32, ctypes.c_char_p, ctypes.c_int]
    _loaded[path] = dll
    return dll


def solves_geometry(lib: ctypes.CDLL) -> bool:
    """Whether ``lib`` solves the contact geometry of any stage geometry it is given
    (``prsm_api_new_geometry``); a library built before bakes its build's geometry in."""
    return hasattr(lib, "prsm_api_new_geometry")


def contact_solver(lib: ctypes.CDLL):
    """``lib``'s contact-geometry solver (``prsm_api_contact_geometry``) as a function
    ``(r_s [m], r_r [m], lead [m], n_s, beta [rad]) -> tuple`` of the 13 values of
    :func:`prsm_fmu.geometry._newton_contact`, which it equals bit for bit; None for a library
    without it."""
    if not hasattr(lib, "prsm_api_contact_geometry"):
        return None
    call, n = lib.prsm_api_contact_geometry, lib.prsm_api_n_contact()

    def solve(r_s: float, r_r: float, lead: float, n_s: int, beta: float) -> tuple:
        out = (ctypes.c_double * n)()
        call(r_s, r_r, lead, n_s, beta, out)
        return tuple(out)

    return solve


def library_output_names(lib: ctypes.CDLL) -> tuple[str, ...]:
    """The names of the outputs ``prsm_api_outputs`` of ``lib`` writes, in its order (the C's
    tables, generated from :func:`fmu_build.native.api_outputs`); () for a library without it."""
    if not hasattr(lib, "prsm_api_outputs"):
        return ()
    return tuple(lib.prsm_api_output_name(i).decode() for i in range(lib.prsm_api_n_outputs()))


def _engine_arrays(params, level: int, drive: int, tolerance: float, kinematic_efficiency: float,
                   substeps: int, max_substeps: int) -> tuple:
    """The ctypes arrays ``prsm_api_new_geometry`` reads (reals, ints, term_reals, term_ints,
    geo_reals, geo_ints; ``prsm_api_new_terms`` reads the first four)."""
    reals = [float(getattr(st, f)) for st in params.stages for f in _STAGE_REALS]
    reals += [params.mu_screw_roller, params.mu_spline, params.mu_nut_screw,
              params.slip_velocity_scale, tolerance, kinematic_efficiency]
    ints = [int(v) for st in params.stages for v in (st.n_rollers, st.carriers)]
    ints += [level, drive, substeps, max_substeps]
    term_reals = [float(params.mu_viscous), float(params.mu_differential)]
    term_ints = [int(st.threads_per_roller) for st in params.stages]
    geo = [float(getattr(st, f)) for st in params.stages for f in GEOMETRY_REALS]
    starts = [int(st.screw_starts) for st in params.stages]
    return ((ctypes.c_double * len(reals))(*reals), (ctypes.c_int * len(ints))(*ints),
            (ctypes.c_double * 2)(*term_reals), (ctypes.c_int * len(term_ints))(*term_ints),
            (ctypes.c_double * len(geo))(*geo), (ctypes.c_int * len(starts))(*starts))


def auto_start_level(params, tolerance: float, inputs: tuple, screw_speed: float,
                     carriers_at_rest: bool, kinematic_efficiency: float = 1.0,
                     library: ctypes.CDLL | None = None) -> tuple[str, float, float]:
    """The level ``fidelity = "auto"`` starts with under the torque drive, chosen by the C
    (``prsm_api_auto_choose``, what the native FMU runs at initialization; the Python
    :func:`prsm_fmu.models.auto.choose_for_start` with no communication step).

    Parameters
    ----------
    params : MechanismParams
    tolerance : float
        Accepted model error [-].
    inputs : tuple
        Motor torque [N·m] and load force [N] at the start.
    screw_speed : float
        Screw speed at the start [rad/s].
    carriers_at_rest : bool
        Carriers at rest (True) or at their equilibrium (False) at the start.
    kinematic_efficiency : float
        The kinematic level's constant efficiency [-].
    library : ctypes.CDLL, optional
        Default: :func:`native_library` of ``params``.

    Returns
    -------
    tuple
        (level, estimated model error of the kinematic level, of the quasi-static level).

    Raises
    ------
    ValueError
        The C's message (a value out of range).
    """
    lib = library if library is not None else native_library(params)
    arrays = _engine_arrays(params, 1, 0, 0.5, kinematic_efficiency, 0, 1000)
    errors = (ctypes.c_double * 2)()
    msg = ctypes.create_string_buffer(_MSG)
    code = lib.prsm_api_auto_choose(*arrays, float(tolerance),
                                    (ctypes.c_double * 2)(*map(float, inputs)),
                                    float(screw_speed), 1 if carriers_at_rest else 0,
                                    float(kinematic_efficiency), errors, msg, _MSG)
    if code < 0:
        raise ValueError(msg.value.decode())
    return ("kinematic", "quasi-static", "dynamic")[code], errors[0], errors[1]


class NativeStepper(Stepper):
    """ROS34PW2 (dynamic level) or the closed form with its exponential or Dormand-Prince band
    step (slaved levels) in C, for a :mod:`prsm_fmu` model of the mechanism (either drive).

    Parameters
    ----------
    model : prsm_fmu.models.base.Model
        A kinematic, quasi-static, dynamic or auto (:class:`~prsm_fmu.models.AdaptiveModel`,
        its ``tolerance`` and ``start``) model, torque or speed drive; its parameters, level
        and drive select the C model.  For auto, the model's ``mode`` is set after every
        advance to the level of that step, as the Python stepper sets it.
    rtol, atol : float
        Relative [-] and absolute [state units] tolerances of the adaptive steps (the Python
        steppers' meaning).
    max_substeps : int
        Internal steps (accepted and rejected) allowed per advance.
    fixed_substeps : int or None
        Equal internal steps per advance (without error control) instead of adaptive ones.
    library : ctypes.CDLL, optional
        The loaded library (:func:`load_library`) to run, e.g. the one packed in an FMU, built
        for ``model``'s geometry; default: :func:`native_library` of the model's parameters.
    stepper : str or None
        The Python stepper whose steps the C repeats (:data:`STEPPERS`): at the slaved levels
        ``"closed_form"`` (the exponential band step, the Python default) or
        ``"closed_form_explicit"``; at the dynamic level and for auto ``"rosenbrock"``.  None:
        at the slaved levels ``closed_form_explicit``, elsewhere ``rosenbrock``.

    Raises
    ------
    ValueError
        Naming what the C does not model, or a value out of range (the C's own checks).
    """

    name = "native"

    def __init__(self, model: Any, rtol: float = 1e-6, atol: float = 1e-8,
                 max_substeps: int = 100000, fixed_substeps: int | None = None,
                 library: ctypes.CDLL | None = None, stepper: str | None = None) -> None:
        super().__init__(model)
        params = model.params
        level = getattr(model, "fidelity", "")
        if level not in _LEVELS:
            raise ValueError(f"fidelity = {level!r} is not allowed for the native stepper: must "
                             f"be one of {', '.join(_LEVELS)}")
        allowed = STEPPERS[level]
        if stepper is not None and stepper not in allowed:
            raise ValueError(f"stepper = {stepper!r} is not allowed for the native stepper at "
                             f"fidelity = {level!r}: must be one of {', '.join(allowed)}")
        band = allowed.get(stepper or "closed_form_explicit")
        for name, value in (("rtol", rtol), ("atol", atol)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} = {value!r} is out of range: must be a finite number > 0")
        kinematic_efficiency = getattr(model, "efficiency", 1.0)
        arrays = _engine_arrays(params, _LEVELS[level], 1 if model.drive == "speed" else 0,
                                min(rtol, 0.5), kinematic_efficiency, fixed_substeps or 0,
                                max_substeps)
        self._lib = lib = library if library is not None else native_library(params)
        n_reals, n_ints = len(arrays[0]), len(arrays[1])
        if (n_reals, n_ints) != (lib.prsm_api_n_reals(), lib.prsm_api_n_ints()):
            raise ValueError(f"the C model reads {lib.prsm_api_n_reals()} doubles and "
                             f"{lib.prsm_api_n_ints()} ints, not {n_reals} and {n_ints}")
        msg = ctypes.create_string_buffer(_MSG)
        self._auto = level == "auto"
        if self._auto:
            if not hasattr(lib, "prsm_api_new_auto"):
                raise ValueError("fidelity = 'auto' is not in this engine library (built before "
                                 "it was added)")
            handle = lib.prsm_api_new_auto(*arrays, float(model.tolerance),
                                           _AUTO_START[model.start], msg, _MSG)
        elif solves_geometry(lib):
            # the model's own geometry: the engine solves its contact (prsm_geometry.c)
            handle = lib.prsm_api_new_geometry(*arrays, msg, _MSG)
        else:       # a library packed before: the geometry it was built with
            handle = lib.prsm_api_new_terms(*arrays[:4], msg, _MSG)
        if not handle:
            raise ValueError(msg.value.decode())
        self._handle = ctypes.c_void_p(handle)
        lib.prsm_api_set_tolerances(self._handle, rtol, atol)
        if band is not None:
            lib.prsm_api_set_band(self._handle, band)
        n = lib.prsm_api_n_states(self._handle)
        if n != self.n_states:
            raise ValueError(f"the C model has {n} states, the model {self.n_states}")
        self._x = (ctypes.c_double * n)()
        self._u = (ctypes.c_double * 2)()
        self._stats = (ctypes.c_int * 3)()
        self._msg = msg
        self._memory_size = (lib.prsm_api_handle_memory_size(self._handle)
                             if hasattr(lib, "prsm_api_handle_memory_size")
                             else lib.prsm_api_memory_size())
        #: the names of the outputs :meth:`outputs` computes, in the C's order, for either
        #: drive (u[0] is the motor torque or the prescribed acceleration, as the model's);
        #: () where the library has no prsm_api_outputs
        self.output_names: tuple[str, ...] = library_output_names(lib)

    def outputs(self, t: float, x: list[float], u: tuple) -> dict[str, float]:
        """The C model's outputs at ``x`` with inputs ``u`` (those of :attr:`output_names`,
        equal to the model's ``outputs`` bit for bit).

        Raises
        ------
        ValueError
            When the library has no ``prsm_api_outputs``.
        """
        names = self.output_names
        if not names:
            raise ValueError("the engine computes no outputs here (a library without "
                             "prsm_api_outputs)")
        out = (ctypes.c_double * len(names))()
        self._x[:] = x
        self._u[0], self._u[1] = u[0], u[1]
        self._lib.prsm_api_outputs(self._handle, t, self._x, self._u, out)
        return dict(zip(names, out[:]))

    def advance(self, t: float, x: list[float], u: tuple, h: float) -> tuple[list[float], StepStats]:
        rows, stats = self.advance_many(t, x, u, h, 1)
        return rows[0], stats

    def advance_many(self, t0: float, x: list[float], u: tuple, h: float,
                     n_steps: int) -> tuple[list[list[float]], StepStats]:
        """``n_steps`` advances of ``h`` [s] from ``t0`` [s] (the i-th from ``t0 + i h``) with
        the inputs ``u`` held, in one call into C: the states after each advance, and the
        work of all of them.  Equal to calling :meth:`advance` ``n_steps`` times."""
        if not (0.0 < h < math.inf):
            raise ValueError(f"h = {h!r} is out of range: must be a finite number > 0 [s]")
        if len(x) != self.n_states or n_steps < 1:
            raise ValueError(f"len(x) = {len(x)} must be model.n_states = {self.n_states} and "
                             f"n_steps = {n_steps!r} >= 1")
        n = self.n_states
        out = (ctypes.c_double * (n * n_steps))()
        self._x[:] = x
        self._u[0], self._u[1] = u[0], u[1]
        rc = self._lib.prsm_api_advance_many(self._handle, t0, self._x, self._u, h, n_steps, out,
                                             self._stats, self._msg, _MSG)
        if self._auto:
            self.sync_mode()
        if rc:
            raise StepFailure(self._msg.value.decode())
        stats = StepStats()
        stats.rhs_calls, stats.substeps, stats.rejected = self._stats
        flat = out[:]
        return [flat[i * n:(i + 1) * n] for i in range(n_steps)], stats

    def advance_schedule(self, x: list[float], start, length, u, record):
        """A whole run of known inputs in one call into C (``prsm_api_advance_schedule``): the
        i-th advance from ``start[i]`` [s] over ``length[i]`` [s] with the inputs ``u[i]`` held,
        each from the state the one before ended in, the first from ``x``; after each advance
        with ``record[i]`` true, the outputs of :attr:`output_names` at its end state and inputs.
        Equal to :meth:`advance` and :meth:`outputs` called advance by advance.

        Parameters
        ----------
        x : list of float
            Start state.
        start, length : array_like of float, shape (n,)
            Start time [s] and length [s] of each advance.
        u : array_like of float, shape (n, 2)
            Inputs held over each advance (the model's, e.g. [N.m, N] or [rad/s², N]).
        record : array_like of bool, shape (n,)
            Whether the outputs after that advance are wanted.

        Returns
        -------
        tuple
            ``(y, x_end, stats, done, reason)``: ``y`` the recorded outputs (a row per recorded
            advance, a column per name of :attr:`output_names`; the rows after a failure are
            unset), ``x_end`` the last state reached, ``stats`` the work (:class:`StepStats`),
            ``done`` the advances completed (n unless one failed or ended in a non-finite
            state) and ``reason`` why not ('' when all were done).

        Raises
        ------
        ValueError
            When the library has no ``prsm_api_advance_schedule`` or ``prsm_api_outputs``, or
            for arrays of unequal lengths or a length that is not a finite number > 0 [s].
        """
        import numpy as np

        lib = self._lib
        if not self.output_names or not hasattr(lib, "prsm_api_advance_schedule"):
            raise ValueError("the engine library has no prsm_api_advance_schedule")
        start = np.ascontiguousarray(start, dtype=np.float64)
        length = np.ascontiguousarray(length, dtype=np.float64)
        u = np.ascontiguousarray(u, dtype=np.float64)
        flags = np.ascontiguousarray(record, dtype=np.intc)
        n = len(start)
        if len(length) != n or u.shape != (n, 2) or len(flags) != n or len(x) != self.n_states:
            raise ValueError(f"start, length, u and record must have {n} rows (u 2 columns) and "
                             f"x {self.n_states} values: got {len(length)}, {u.shape}, "
                             f"{len(flags)}, {len(x)}")
        bad = length[~((length > 0.0) & (length < math.inf))]
        if len(bad):
            raise ValueError(f"length = {float(bad[0])!r} is out of range: must be a finite "
                             "number > 0 [s]")
        y = np.empty((int(flags.astype(bool).sum()), len(self.output_names)))
        x_end = (ctypes.c_double * self.n_states)()
        self._x[:] = x
        dbl = ctypes.POINTER(ctypes.c_double)
        done = lib.prsm_api_advance_schedule(
            self._handle, self._x, n, start.ctypes.data_as(dbl), length.ctypes.data_as(dbl),
            u.ctypes.data_as(dbl), flags.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
            y.ctypes.data_as(dbl), x_end, self._stats, self._msg, _MSG)
        if self._auto:
            self.sync_mode()
        stats = StepStats()
        stats.rhs_calls, stats.substeps, stats.rejected = self._stats
        return y, x_end[:], stats, done, "" if done == n else self._msg.value.decode()

    def rhs(self, x: list[float], u: tuple) -> list[float]:
        """The C model's right-hand side at ``x`` with inputs ``u`` (the model's ``rhs``)."""
        dx = (ctypes.c_double * self.n_states)()
        self._x[:] = x
        self._u[0], self._u[1] = u[0], u[1]
        self._lib.prsm_api_rhs(self._handle, self._x, self._u, dx)
        return dx[:]

    def sync_mode(self) -> None:
        """For auto: set the model's ``mode`` to the level of the C's last step (what
        :meth:`prsm_fmu.models.AdaptiveModel.outputs` reads)."""
        self.model.mode = _AUTO_MODES[self._lib.prsm_api_auto_mode(self._handle)]

    def auto_info(self) -> dict:
        """For auto: what the C computed on construction (``prsm_api_auto_info``):
        ``slaved_inertia`` [kg·m²], ``nut_term`` (m·c_out of the last nut) [kg·m/rad],
        ``tolerance`` [-] and the lag coefficients c_k = τ_k|F|/|ω| [N·s²/rad] of each carrier,
        ``forward`` (driving) and ``backward`` (back-driven)."""
        n = self.model.params.n_stages
        out = (ctypes.c_double * (3 + 2 * n))()
        if self._lib.prsm_api_auto_info(self._handle, out):
            raise ValueError("not an auto stepper")
        v = out[:]
        return {"slaved_inertia": v[0], "nut_term": v[1], "tolerance": v[2],
                "forward": tuple(v[3:3 + n]), "backward": tuple(v[3 + n:])}

    def get_memory(self) -> tuple:
        """``(bytes,)``: the C stepper's memory (step proposal, continuation, last stage)."""
        buf = ctypes.create_string_buffer(self._memory_size)
        self._lib.prsm_api_get_memory(self._handle, buf)
        return (buf.raw,)

    def set_memory(self, m: tuple) -> None:
        """Restore a memory from :meth:`get_memory` of a native stepper of the same build."""
        m = tuple(m)
        if len(m) != 1 or not isinstance(m[0], bytes) or len(m[0]) != self._memory_size:
            raise ValueError(f"{self.name}: memory must be (bytes of length "
                             f"{self._memory_size},) from get_memory")
        self._lib.prsm_api_set_memory(self._handle, m[0])
        if self._auto:
            self.sync_mode()

    def undo_advance(self) -> None:
        """Put the memory back as it was before the last advance (its result refused by the
        caller); the state is the caller's own and needs no undoing."""
        self._lib.prsm_api_undo_advance(self._handle)
        if self._auto:
            self.sync_mode()

    def reset(self) -> None:
        """Forget the memory (for auto: back to its start level, as the Python stepper)."""
        if hasattr(self._lib, "prsm_api_reset"):
            self._lib.prsm_api_reset(self._handle)
            if self._auto:
                self.sync_mode()
        else:
            self.set_memory((bytes(self._memory_size),))

    def __del__(self) -> None:
        handle = getattr(self, "_handle", None)
        if handle:
            self._lib.prsm_api_free(handle)
            self._handle = None

