"""Work-precision charts: error against cost for every fidelity level × stepper × step or tolerance.

For each scene (a data structure, :data:`SCENES`: the Li et al. (2021) start-up of the mechanism alone,
and the actuator-loop scenes of system_models/ with the PRSM as the plain Python block:
position step, sine tracking, load step, speed reversal), every configuration of the grid is
run and compared with the scene's reference:

* **reference**: the dynamic level with ``solve_ivp(Radau)`` at rtol 1e-12 (stepper ``radau``,
  restarted on each communication step), checked against a second reference at rtol 1e-11;
  their difference is printed (it is the floor below which an error cannot be resolved);
* **error** (docs/accuracy.md §1), per output: max over the scene's fixed grid of output times (every
  communication step) of |y − y_ref| / max|y_ref|, over the FMU's outputs
  (``OUTPUTS`` of benchmarks/step_cost.py); a configuration's error is the largest of them.
  The reference is the *dynamic* level's, so a lower level's error includes its model error;
* **cost**: CPU seconds per simulated second of the stepping (``time.process_time`` over the
  stepper's advances, best of several repeats; outputs are evaluated outside the timing) and
  right-hand-side calls per simulated second.

The start-up scenes also run the dynamic level's ROS34PW2 in C (:data:`NATIVE`: the native
FMU's code in-process, the same steps as the Python ROS34PW2 bit for bit), printed apart from
the Python steppers' cheapest configuration with its own speed-up over Radau.

Each scene writes ``docs/figures/wp_<scene>.csv`` (one row per configuration, with the error of
every output) and ``docs/figures/wp_<scene>.png`` (log–log error against cost, Pareto front
marked), and prints the cheapest configuration at the scene's target error and its speed-up over
``solve_ivp(Radau)`` restarted on each communication step (the cheapest Radau tolerance that
meets the target; Radau at rtol 1e-6 is printed too).  Errors are reproducible to round-off: the
steppers are deterministic and nothing is random; the costs are measured in this run, on this
machine, and vary from run to run.

Each scene with an ``auto`` entry also prints what ``fidelity = "auto"`` picks at the target
(prsm_fmu.models.auto), its estimated model error per level against the measured one, and the
speed-up of its choice over the dynamic level's implicit stepper.

Run: ``python benchmarks/work_precision.py`` (about 7 min, most of it the loop scenes' Radau
references; ``--scene startup``, ``--quick`` for a small grid, ``--out DIR``).  ``--replot``
runs nothing: it redraws each selected scene's PNG from its CSV in ``--out`` through the same
:func:`plot` (after a change to the charts' titles, labels or styles).  ``--stepper NAME``
re-runs only that stepper's configurations and replaces its rows of each selected scene's CSV
(:func:`rerun_stepper`: after a change to one stepper).
docs/accuracy.md explains the charts.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import math
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from prsm_fmu import presets, simulate
from prsm_fmu.models import FIDELITIES, make_model
from prsm_fmu.models.auto import choose_for_start
from prsm_fmu.simulate import tuned_stepper_options
from prsm_fmu.steppers import StepFailure, make_stepper

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"


def _load_sibling(name: str):
    """Import benchmarks/<name>.py by path (works when this file is run as a script or loaded
    by the tests)."""
    path = Path(__file__).with_name(f"{name}.py")
    mod_name = f"_prsm_benchmarks_{name}"
    if mod_name in sys.modules:
        return sys.modules[mod_name]
    spec = importlib.util.spec_from_file_location(mod_name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    spec.loader.exec_module(mod)
    return mod


#: the FMU's outputs (docs/fmu.md, "Variables") for two stages, as benchmarks/step_cost.py measures them
OUTPUTS: tuple[str, ...] = tuple(_load_sibling("step_cost").OUTPUTS)

#: rtol of the reference and of its check; atol = rtol · 1e-2 (per state, times state_scale)
REFERENCE_RTOL, CHECK_RTOL = 1e-12, 1e-11
#: ``auto``'s tolerance (the model error it accepts) when its dynamic steps are RK4's, which
#: have none: the start-up's target
AUTO_FIXED_STEP_TOLERANCE = 1e-6
#: errors below this are plotted at it (round-off; a log axis has no zero)
ERROR_FLOOR = 1e-16
#: the dynamic level's ROS34PW2 in C (fmu_build.native_stepper, the compiled engine both FMUs run): the
#: configuration's outputs, errors and rhs calls are simulate's with the Python ROS34PW2 at the
#: same options, its cost the timed replay with the C stepper (one call into C for the run's
#: communication steps, NativeStepper.advance_many), whose final outputs must equal
#: simulate's bit for bit (checked, as for every configuration)
NATIVE = "rosenbrock_native"


# ---- configurations --------------------------------------------------------------------------

@dataclass(frozen=True)
class Config:
    """One point of the grid: a fidelity level, a stepper and its step count or tolerance.

    Attributes
    ----------
    fidelity : str
        ``kinematic``, ``quasi-static``, ``dynamic`` or ``auto`` (prsm_fmu/models/adaptive.py:
        the level of each step chosen along the run; its ``rtol`` is both the model tolerance
        and the dynamic steps' rtol, as the FMU's ``tolerance``).
    stepper : str
        ``rk4`` (explicit fixed), ``explicit_adaptive`` (Dormand–Prince 5(4)), ``exponential``
        (dynamic level: exponential Rosenbrock exprb32), ``rosenbrock``
        (implicit, ROS34PW2), ``closed_form`` (slaved levels), ``default`` (``auto`` only: its
        own choice of DP5(4) or ROS34PW2 per step, the FMU's default), ``radau``
        (``solve_ivp`` restarted on each communication step: the baseline and the reference)
        or :data:`NATIVE` (ROS34PW2 in C, the speed drive's start-up scenes).
    knob : str
        ``substeps`` (internal steps per communication step), ``rtol`` or ``""`` (none).
    value : float
        The knob's value (0 when there is none).
    """

    fidelity: str
    stepper: str
    knob: str = ""
    value: float = 0.0

    @property
    def rtol(self) -> float:
        """Relative tolerance [-] (1e-8, simulate's default, for steppers without one; for
        ``auto`` with RK4, :data:`AUTO_FIXED_STEP_TOLERANCE`, its model tolerance)."""
        if self.knob == "rtol":
            return self.value
        return AUTO_FIXED_STEP_TOLERANCE if self.fidelity == "auto" else 1e-8

    @property
    def atol(self) -> float:
        """Absolute tolerance relative to state_scale: rtol·1e-3 (benchmarks/step_cost.py);
        rtol·1e-2 for the references."""
        return self.rtol * (1e-2 if self.rtol <= CHECK_RTOL else 1e-3)

    @property
    def stepper_options(self) -> dict:
        """Extra options for the stepper (on top of simulate's tuned ones, which hold the
        tolerances :attr:`rtol` and :attr:`atol` scaled as the FMU scales them,
        ``prsm_fmu.steppers.options.TOLERANCE_FACTOR``)."""
        opts: dict = {}
        if self.knob == "substeps":
            opts["substeps"] = int(self.value)
        return opts

    @property
    def label(self) -> str:
        """Short human-readable name."""
        if self.knob == "substeps":
            return f"{self.fidelity} {self.stepper} ×{int(self.value)}"
        if self.knob == "rtol":
            return f"{self.fidelity} {self.stepper} rtol {self.value:.0e}"
        return f"{self.fidelity} {self.stepper}"


@dataclass
class RunResult:
    """What running one configuration of a scene gives.

    Attributes
    ----------
    outputs : dict
        Output name → array over the scene's output times (including t = 0).
    cpu : float
        CPU seconds spent stepping the whole run [s] (best of the repeats).
    rhs_calls : int
        Right-hand-side calls of the whole run.
    """

    outputs: dict
    cpu: float
    rhs_calls: int


def standard_grid(fidelities=FIDELITIES, substeps=(1, 2, 4, 8, 16, 32),
                  rtols=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                  radau_rtols=(1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
                  auto_rtols=(1e-4, 1e-5, 1e-6, 1e-7, 1e-8)) -> tuple[Config, ...]:
    """fidelity × {rk4 × substeps, explicit_adaptive × rtol, rosenbrock × rtol}, closed_form
    for the slaved levels, ``auto`` (switching along the run) with RK4 × up to 4 substeps or
    the adaptive steppers for its dynamic steps (AUTO_FIXED_STEP_TOLERANCE with RK4), and the
    restarted-Radau baseline on the dynamic level."""
    grid: list[Config] = []
    for fid in fidelities:
        grid += [Config(fid, "rk4", "substeps", n) for n in substeps]
        grid += [Config(fid, "explicit_adaptive", "rtol", r) for r in rtols]
        grid += [Config(fid, "rosenbrock", "rtol", r) for r in rtols]
        if fid == "dynamic":
            grid += [Config(fid, "exponential", "rtol", r) for r in rtols]
        if fid != "dynamic":
            grid.append(Config(fid, "closed_form"))
    grid += [Config("auto", "rk4", "substeps", n) for n in substeps if n <= 4]
    for st in ("explicit_adaptive", "rosenbrock", "default"):
        grid += [Config("auto", st, "rtol", r) for r in auto_rtols]
    if "dynamic" in fidelities:
        grid += [Config("dynamic", "radau", "rtol", r) for r in radau_rtols]
    return tuple(grid)


def native_grid(rtols=(1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)) -> tuple[Config, ...]:
    """The dynamic level's ROS34PW2 in C (:data:`NATIVE`) × rtol; none without gcc."""
    if shutil.which("gcc") is None:
        return ()
    return tuple(Config("dynamic", NATIVE, "rtol", r) for r in rtols)


def python_points(points: list) -> list:
    """The points of the Python steppers (all but :data:`NATIVE`)."""
    return [p for p in points if p.config.stepper != NATIVE]


# ---- scenes ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Scene:
    """A scene of the work-precision study (add new ones to :data:`SCENES`).

    Attributes
    ----------
    name : str
        Key and file stem (``wp_<name>.csv/png``).
    title : str
        One line for the chart and the printout.
    t_end, comm_step : float
        Simulated time and communication step (= output interval) [s]; the error grid is
        every communication step.
    run : callable
        ``run(config, time_it=True) -> RunResult``: runs one configuration (raises
        StepFailure, or returns non-finite outputs, when it fails); with ``time_it=False``
        the cost need not be measured (the references).
    grid : tuple of Config
        The configurations to run.
    target_error : float
        The error at which the cheapest configuration is reported.
    outputs : tuple of str
        The outputs the error is taken over.
    reference_fidelity : str
        The level of the reference (the most detailed one).
    speedup_to_beat : float or None
        The speed-up over restarted Radau asked for at the target (printed beside the
        measured one).
    auto : callable or None
        ``auto(tolerance) -> AutoChoice``: what ``fidelity = "auto"`` picks for this scene
        (prsm_fmu.models.auto); the printout checks its estimate against the measured errors.
    """

    name: str
    title: str
    t_end: float
    comm_step: float
    run: Callable[..., RunResult]
    grid: tuple[Config, ...]
    target_error: float = 1e-6
    outputs: tuple[str, ...] = OUTPUTS
    reference_fidelity: str = "dynamic"
    speedup_to_beat: float | None = None
    auto: Callable[[float], object] | None = None


def timed(fn: Callable[[], object], min_total: float = 0.1, max_repeats: int = 15) -> float:
    """Smallest CPU time of ``fn()`` over repeats (at least 3, until min_total s are spent) [s]."""
    best = math.inf
    spent = 0.0
    n = 0
    while n < 3 or (spent < min_total and n < max_repeats):
        c0 = time.process_time()
        fn()
        dt = time.process_time() - c0
        best = min(best, dt)
        spent += dt
        n += 1
    return best


def make_simulate_runner(params, drive: str, t_end: float, comm_step: float, inputs: dict,
                         initial: dict) -> Callable[..., RunResult]:
    """``run(config)`` for a scene of the mechanism alone through :func:`prsm_fmu.simulate`.

    The outputs and rhs calls are simulate's; the cost is measured on a replay of the same
    stepping (same model, same stepper options as simulate builds them) with only the
    stepper's advances inside the timing, since simulate's own ``cpu_time`` includes the
    output evaluation.  The replay's final outputs must equal simulate's bit for bit (checked).

    Parameters
    ----------
    params : MechanismParams
    drive : {"torque", "speed"}
    t_end, comm_step : float
        [s]
    inputs : dict
        Constant inputs by simulate keyword (``screw_speed``/``screw_torque``, ``load_force``).
    initial : dict
        simulate's initial-condition keywords.
    """
    n_steps = int(round(t_end / comm_step))
    # the model's inputs: the constant motor torque, or (speed drive) the constant speed's zero
    # acceleration; the speed drive starts at the prescribed speed
    if drive == "speed":
        u = (0.0, float(inputs["load_force"]))
        speed0 = float(inputs["screw_speed"])
    else:
        u = (float(inputs["screw_torque"]), float(inputs["load_force"]))
        speed0 = float(initial.get("initial_screw_speed", 0.0))

    def run(cfg: Config, time_it: bool = True) -> RunResult:
        native = cfg.stepper == NATIVE
        stepper = "rosenbrock" if native else cfg.stepper
        res = simulate(params, cfg.fidelity, drive, t_end=t_end, output_interval=comm_step,
                       stepper=stepper, rtol=cfg.rtol, atol=cfg.atol,
                       stepper_options=cfg.stepper_options, **inputs, **initial)
        outputs = {k: v for k, v in res.items() if isinstance(v, np.ndarray)}
        if not time_it:
            return RunResult(outputs, math.nan, int(res["rhs_calls"]))
        auto = {} if cfg.fidelity != "auto" else dict(
            tolerance=cfg.rtol, inputs=u, comm_step=comm_step, screw_speed=speed0,
            carrier_ratio=initial.get("initial_carrier_ratio", 0.0))
        model = make_model(params, cfg.fidelity, drive, **auto)
        opts = tuned_stepper_options(stepper, cfg.rtol, cfg.atol)
        opts.update(cfg.stepper_options)
        if native:
            from fmu_build.native_stepper import NativeStepper

            def make():
                # the native stepper scales the tolerances itself, as the native FMU does
                return NativeStepper(model, rtol=cfg.rtol, atol=cfg.atol)
        else:
            def make():
                return make_stepper(stepper, model, **opts)
        x0 = model.initial_state(u, screw_speed=speed0,
                                 carrier_ratio=initial.get("initial_carrier_ratio", 0.0))
        last = []

        def replay():
            st = make()
            if native:            # one call into C for the run (the state after every step)
                last[:] = [st.advance_many(0.0, x0, u, comm_step, n_steps)[0][-1]]
                return
            x = x0
            for i in range(n_steps):
                x, _ = st.advance(i * comm_step, x, u, comm_step)
            last[:] = [x]

        cpu = timed(replay)
        y_end = model.outputs(n_steps * comm_step, last[0], u)
        for name in model.output_names:
            a, b = y_end[name], res[name][-1]
            if not (a == b or (math.isnan(a) and math.isnan(b))):
                raise RuntimeError(f"{cfg.label}: the timed replay ends at {name} = {a!r}, "
                                   f"simulate at {b!r}: the replay is not simulate's stepping")
        return RunResult(outputs, cpu, int(res["rhs_calls"]))

    return run


LI2021 = presets.load("li2021_two_stage")

#: Li et al. (2021) §3.1 start-up: screw speed stepped to 100 rad/s with the carriers at rest, F = 5 kN
STARTUP = Scene(
    name="startup",
    title="Li et al. (2021) start-up: ω stepped to 100 rad/s, carriers at rest, F = 5 kN, 0–1 ms, "
          "communication step 10 µs",
    t_end=1e-3, comm_step=1e-5,
    run=make_simulate_runner(LI2021, "speed", 1e-3, 1e-5,
                             {"screw_speed": 100.0, "load_force": 5000.0},
                             {"initial_carrier_ratio": 0.0}),
    grid=standard_grid() + native_grid(),
    target_error=1e-6,
    speedup_to_beat=100.0,
    auto=lambda tol: choose_for_start(LI2021, tol, "speed", (0.0, 5000.0), screw_speed=100.0,
                                      carrier_ratio=0.0, comm_step=1e-5),
)

#: the same start-up with the paper's 1 µs output interval as communication step: how the
#: speed-up over restarted Radau depends on the communication step (a reduced grid)
STARTUP_1US = Scene(
    name="startup_1us",
    title="Li et al. (2021) start-up as above, communication step 1 µs (sensitivity to the "
          "communication step; reduced grid)",
    t_end=1e-3, comm_step=1e-6,
    run=make_simulate_runner(LI2021, "speed", 1e-3, 1e-6,
                             {"screw_speed": 100.0, "load_force": 5000.0},
                             {"initial_carrier_ratio": 0.0}),
    grid=(standard_grid(("dynamic",), substeps=(1, 2), rtols=(1e-5, 1e-6, 1e-7),
                        radau_rtols=(1e-5, 1e-6, 1e-7), auto_rtols=(1e-6, 1e-7))
          + (Config("quasi-static", "closed_form"),) + native_grid((1e-5, 1e-6, 1e-7))),
    target_error=1e-6,
    speedup_to_beat=20.0,
)

# ---- actuator-loop scenes (system_models/, the PRSM as the plain Python block) -------------

#: outputs of a loop scene's error: the scene's own list without ``prsm.efficiency`` (a ratio of
#: powers that jumps between 0 and its value where a power changes sign, at instants that differ
#: by a step between levels) and ``controller.reference`` (an input), plus the carrier speeds
#: (the quantity the quasi-static level approximates)
LOOP_EXCLUDED = ("prsm.efficiency", "controller.reference")


def loop_outputs(scene_name: str, n_stages: int = 2) -> tuple[str, ...]:
    """The outputs a loop scene's error is taken over (see :data:`LOOP_EXCLUDED`)."""
    from system_models.scenes import load_scene

    outs = [o for o in load_scene(scene_name).outputs if o not in LOOP_EXCLUDED]
    return tuple(outs + [f"prsm.stage[{k}].carrier_speed" for k in range(1, n_stages + 1)])


def load_loop_scene(scene_name: str, t_end: float | None = None):
    """A scene of system_models/scenes, optionally cut to ``t_end`` [s]."""
    from dataclasses import replace

    from system_models.scenes import load_scene

    sc = load_scene(scene_name)
    return sc if t_end is None else replace(sc, t_end=float(t_end))


def make_loop_runner(scene_name: str, t_end: float | None = None,
                     outputs: tuple[str, ...] | None = None) -> Callable[..., RunResult]:
    """``run(config)`` for an actuator-loop scene with the PRSM as the plain Python block.

    The configuration sets the PRSM block's ``fidelity``, ``stepper``, ``tolerance`` and
    ``substeps`` (the FMU's parameters); controller, motor, load and master are the scene's.
    Outputs: the master's on the communication grid.  Cost: CPU seconds (``process_time``)
    inside the PRSM block's ``do_step`` calls (its stepping; output evaluation and the other
    blocks excluded), one run; rhs calls: the sum of the block's ``step_rhs_calls``.  A step
    the block refuses (StepFailure inside, e.g. a fixed explicit step beyond its stability
    limit) makes the run fail.
    """
    from dataclasses import replace

    from system_models.ema import build_system
    from system_models.master import CoSimulationError

    sc = load_loop_scene(scene_name, t_end)
    outs = outputs or loop_outputs(scene_name)

    def run(cfg: Config, time_it: bool = True) -> RunResult:
        par = dict(sc.prsm.get("parameters", {}))
        par.update(stepper=cfg.stepper, tolerance=cfg.rtol,
                   substeps=int(cfg.value) if cfg.knob == "substeps" else 0)
        scene = replace(sc, prsm={**sc.prsm, "parameters": par})
        system = build_system(scene, prsm="python", fidelity=cfg.fidelity)
        blk = next(b for b in system.master.blocks if b.name == "prsm")
        spent = [0.0]
        inner = blk.do_step

        def do_step(t, h, _inner=inner):
            c0 = time.process_time()
            try:
                return _inner(t, h)
            finally:
                spent[0] += time.process_time() - c0

        blk.do_step = do_step
        try:
            res = system.run()
        except CoSimulationError as exc:
            raise StepFailure(str(exc).splitlines()[0]) from None
        outputs_ = {n: np.asarray(res[n], float) for n in outs}
        rhs = int(np.sum(res["prsm.step_rhs_calls"]))
        return RunResult(outputs_, spent[0] if time_it else math.nan, rhs)

    return run


def loop_grid(rtols=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7),
              radau_rtols=(1e-4, 1e-6, 1e-8, 1e-10),
              auto_rtols=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7)) -> tuple[Config, ...]:
    """The loop scenes' grid: closed form and RK4 ×1 for the slaved levels (exact for their own
    model: the points show the level's model error), ROS34PW2 × rtol for every level and for
    ``auto``'s dynamic steps, the restarted-Radau baseline.  No explicit stepper on the dynamic level: at the loop's 0.1 ms
    step the carriers' time constant falls to 10 ns near standstill (h/τ ~ 10⁴), where RK4
    needs ~4 000 substeps per step and DP5(4) as many (docs/accuracy.md §2)."""
    grid: list[Config] = []
    for fid in ("kinematic", "quasi-static"):
        grid += [Config(fid, "closed_form"), Config(fid, "rk4", "substeps", 1)]
        grid += [Config(fid, "rosenbrock", "rtol", r) for r in (1e-4, 1e-8)]
    grid += [Config("dynamic", "rosenbrock", "rtol", r) for r in rtols]
    grid += [Config("dynamic", "exponential", "rtol", r) for r in rtols]
    grid += [Config("auto", st, "rtol", r) for st in ("rosenbrock", "default") for r in auto_rtols]
    grid += [Config("dynamic", "radau", "rtol", r) for r in radau_rtols]
    return tuple(grid)


def loop_trajectory(scene_name: str, t_end: float | None = None):
    """Screw speed, acceleration and load force along a quasi-static run of a loop scene (the
    cheapest level that has the carriers' equilibrium), and the lumped mechanism: what
    ``auto`` evaluates its lag estimate on (docs/accuracy.md §4)."""
    from system_models.run import run_scene as run_loop

    r = run_loop(load_loop_scene(scene_name, t_end), prsm="python", fidelity="quasi-static")
    res = r.result
    return (np.asarray(res["prsm.screw_speed"]), np.asarray(res["prsm.screw_acceleration"]),
            np.asarray(res["load.force"]), r.system.prsm.params())


def loop_auto_choice(scene_name: str, tolerance: float, t_end: float | None = None):
    """``auto``'s level for a loop scene at ``tolerance``: the estimate along a quasi-static run
    (:func:`prsm_fmu.models.auto.estimate_along`; the carriers start at equilibrium)."""
    from prsm_fmu.models.auto import estimate_along

    w, a, f, params = loop_trajectory(scene_name, t_end)
    sc = load_loop_scene(scene_name, t_end)
    return estimate_along(params, tolerance, w, a, f, comm_step=sc.step)


def _loop_scene(name: str, title: str, target: float, t_end: float | None = None,
                speedup: float | None = None, grid: tuple[Config, ...] | None = None) -> Scene:
    sc = load_loop_scene(name, t_end)
    return Scene(name=name, title=title, t_end=sc.t_end, comm_step=sc.step,
                 run=make_loop_runner(name, t_end), grid=loop_grid() if grid is None else grid,
                 target_error=target, outputs=loop_outputs(name), speedup_to_beat=speedup,
                 auto=lambda tol: loop_auto_choice(name, tol, t_end))


#: the actuator's position step (system_models/scenes/position_step.toml), PRSM in Python
POSITION_STEP = _loop_scene(
    "position_step", "actuator loop: rod position step 0 → 10 mm against the surface load, "
    "0–0.25 s, communication step 0.1 ms, Gauss–Seidel, PRSM as Python block", 1e-4)

#: sine tracking (system_models/scenes/sine_tracking.toml) cut to its first 0.5 s: the ramp-in
#: and one full period, four speed reversals
SINE_TRACKING = _loop_scene(
    "sine_tracking", "actuator loop: ±5 mm, 2 Hz sine with velocity feed-forward, 0–0.5 s "
    "(ramp-in and one period, four reversals), communication step 0.1 ms, PRSM as Python block",
    1e-4, t_end=0.5)

#: load step (system_models/scenes/load_step.toml): the servo holds 5 mm against a 3 kN gust;
#: the target is looser (5e-3): a scene where ``auto`` picks the quasi-static level
LOAD_STEP = _loop_scene(
    "load_step", "actuator loop: hold 5 mm, 3 kN gust load step at 20 ms, 0–0.2 s, "
    "communication step 0.1 ms, PRSM as Python block", 5e-3)

#: speed reversal (system_models/scenes/speed_reversal.toml): the speed loop ramps the screw
#: from +100 to −100 rad/s through zero against 2 kN, so every friction force changes sign
#: inside the friction band; the whole 0.1 s at the loop scenes' target 1e-4 (the scene's own
#: energy-balance limit).  Grid: the loop scenes' plus the explicit steppers on the dynamic
#: level, which this scene, unlike the others, lets through: the ramp crosses the friction
#: band, where the carriers' time constant collapses, within a few communication steps, so
#: DP5(4) adapts past it at ~3 internal steps per communication step, and RK4 × substeps shows
#: what a fixed explicit step gives there (bounded but wrong, docs/accuracy.md §3.1)
SPEED_REVERSAL = _loop_scene(
    "speed_reversal", "actuator loop: screw speed +100 → −100 rad/s through zero against "
    "2 kN (driving → back-driven), 0–0.1 s, communication step 0.1 ms, PRSM as Python block",
    1e-4, grid=loop_grid()
    + tuple(Config("dynamic", "rk4", "substeps", n) for n in (1, 32))
    + tuple(Config("dynamic", "explicit_adaptive", "rtol", r)
            for r in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)))

#: every scene
SCENES: dict[str, Scene] = {s.name: s for s in (STARTUP, STARTUP_1US, POSITION_STEP,
                                                 SINE_TRACKING, LOAD_STEP, SPEED_REVERSAL)}

#: scenes whose printout compares ``auto``'s choice with the dynamic level's implicit stepper
#: (issue 5: ≥ 50× at error ≤ 1e-4 on the position step)
AUTO_SPEEDUP_TO_BEAT = {"position_step": 50.0}


# ---- the framework ---------------------------------------------------------------------------

def output_errors(y: dict, ref: dict, outputs) -> dict[str, float]:
    """Per output: max_t |y − y_ref| / max_t |y_ref| (absolute where y_ref ≡ 0); nan if y is
    not finite."""
    errs = {}
    for name in outputs:
        a, b = np.asarray(y[name], float), np.asarray(ref[name], float)
        if a.shape != b.shape or not np.all(np.isfinite(a)):
            errs[name] = math.nan
            continue
        scale = float(np.max(np.abs(b)))
        errs[name] = float(np.max(np.abs(a - b))) / (scale if scale > 0.0 else 1.0)
    return errs


@dataclass
class Point:
    """One configuration's measured error and cost."""

    config: Config
    status: str                     # "ok" or "failed: <reason>"
    error: float = math.nan         # max over outputs
    errors: dict = field(default_factory=dict)
    cpu_per_s: float = math.nan     # CPU s per simulated s
    rhs_per_s: float = math.nan     # rhs calls per simulated s
    rhs_calls: int = 0
    pareto: bool = False


def reference(scene: Scene, rtol: float) -> RunResult:
    """The scene's reference run at ``rtol`` (radau on the reference level)."""
    return scene.run(Config(scene.reference_fidelity, "radau", "rtol", rtol), time_it=False)


def measure(scene: Scene, cfg: Config, ref: RunResult) -> Point:
    """Run one configuration and measure it against the reference."""
    try:
        r = scene.run(cfg)
    except StepFailure as exc:
        return Point(cfg, "failed: " + str(exc).splitlines()[0][:120])
    errs = output_errors(r.outputs, ref.outputs, scene.outputs)
    if any(math.isnan(e) for e in errs.values()):
        return Point(cfg, "failed: non-finite outputs", errors=errs)
    return Point(cfg, "ok", max(errs.values()), errs, r.cpu / scene.t_end,
                 r.rhs_calls / scene.t_end, r.rhs_calls)


def mark_pareto(points: list[Point]) -> None:
    """Flag the points no other point beats in both cost (CPU) and error."""
    ok = sorted((p for p in points if p.status == "ok"), key=lambda p: (p.cpu_per_s, p.error))
    best = math.inf
    for p in ok:
        p.pareto = p.error < best
        best = min(best, p.error)


def cheapest(points: list[Point], target: float, stepper: str | None = None) -> Point | None:
    """The cheapest (CPU) successful point with error ≤ target (optionally of one stepper)."""
    cands = [p for p in points if p.status == "ok" and p.error <= target
             and (stepper is None or p.config.stepper == stepper)]
    return min(cands, key=lambda p: p.cpu_per_s) if cands else None


def run_scene(scene: Scene, grid: tuple[Config, ...] | None = None, verbose: bool = True) -> dict:
    """Reference, check and every configuration of one scene.

    Returns
    -------
    dict
        ``points`` (list of Point), ``reference_difference`` (error of the rtol-1e-11 check
        against the rtol-1e-12 reference), ``reference`` (RunResult).
    """
    say = print if verbose else (lambda *a, **k: None)
    grid = scene.grid if grid is None else grid
    say(f"\n== scene {scene.name}: {scene.title}")
    c0 = time.process_time()
    ref = reference(scene, REFERENCE_RTOL)
    check = reference(scene, CHECK_RTOL)
    ref_diff = max(output_errors(check.outputs, ref.outputs, scene.outputs).values())
    say(f"reference: {scene.reference_fidelity} radau rtol {REFERENCE_RTOL:g}; check at rtol "
        f"{CHECK_RTOL:g} differs by {ref_diff:.2e} (error measure of docs/accuracy.md §1) "
        f"[{time.process_time() - c0:.1f} s CPU]")
    if not ref_diff <= scene.target_error / 100:
        say(f"WARNING: the reference is not 100x more accurate than the target {scene.target_error:g}")
    points = []
    for i, cfg in enumerate(grid, 1):
        p = measure(scene, cfg, ref)
        points.append(p)
        if p.status == "ok":
            say(f"[{i:3d}/{len(grid)}] {cfg.label:42s} error {p.error:9.2e}  "
                f"CPU {p.cpu_per_s:9.3e} s/s  rhs {p.rhs_calls:7d}")
        else:
            say(f"[{i:3d}/{len(grid)}] {cfg.label:42s} {p.status}")
    mark_pareto(points)
    return {"points": points, "reference_difference": ref_diff, "reference": ref}


def summary(scene: Scene, result: dict) -> list[str]:
    """Lines: the Pareto front, the cheapest configuration at the target and its speed-ups."""
    pts = result["points"]
    lines = ["Pareto front (cheapest first):"]
    for p in sorted((p for p in pts if p.pareto), key=lambda p: p.cpu_per_s):
        lines.append(f"  {p.config.label:42s} error {p.error:9.2e}  CPU {p.cpu_per_s:9.3e} s/s")
    best = cheapest(python_points(pts), scene.target_error)
    base = cheapest(pts, scene.target_error, "radau")
    native = cheapest(pts, scene.target_error, NATIVE)
    conventional = next((p for p in pts if p.config.stepper == "radau" and p.config.value == 1e-6
                         and p.status == "ok"), None)
    if best is None:
        lines.append(f"no configuration reaches error ≤ {scene.target_error:g}")
        return lines
    lines.append(f"cheapest at error ≤ {scene.target_error:g}: {best.config.label} "
                 f"(error {best.error:.2e}, {best.cpu_per_s:.3e} CPU s/s, "
                 f"{best.rhs_per_s:.3g} rhs/s)")
    if base is not None:
        lines.append(f"  speed-up over solve_ivp(Radau) restarted each communication step at "
                     f"the cheapest tolerance meeting the target ({base.config.label}, error "
                     f"{base.error:.2e}): {base.cpu_per_s / best.cpu_per_s:.1f}x"
                     + (f"  (to beat: ≥ {scene.speedup_to_beat:g}x)" if scene.speedup_to_beat else ""))
    if conventional is not None:
        lines.append(f"  speed-up over Radau at rtol 1e-6 (error {conventional.error:.2e}): "
                     f"{conventional.cpu_per_s / best.cpu_per_s:.1f}x")
    if native is not None:
        lines.append(f"the same ROS34PW2 in C (the compiled engine both FMUs run, fmu_build.native_stepper), "
                     f"cheapest at error ≤ {scene.target_error:g}: {native.config.label} (error "
                     f"{native.error:.2e}, {native.cpu_per_s:.3e} CPU s/s): "
                     f"{best.cpu_per_s / native.cpu_per_s:.1f}x the Python steppers' cheapest"
                     + (f"; speed-up over restarted Radau {base.cpu_per_s / native.cpu_per_s:.1f}x"
                        if base is not None else "")
                     + (f"  (to beat: ≥ {scene.speedup_to_beat:g}x)" if scene.speedup_to_beat else ""))
    lines += auto_summary(scene, result)
    lines += tolerance_summary(result)
    return lines


#: the steppers whose knob is a tolerance that the user sets (the FMU's ``tolerance``): the
#: adaptive ones, on the dynamic level and for ``auto``'s dynamic steps, and the baseline Radau
#: (the FMU's stepper ``radau``: it lands on the friction law's kinks as they do)
ADAPTIVE = ("rosenbrock", "exponential", "explicit_adaptive", "default", NATIVE, "radau")


def tolerance_summary(result: dict) -> list[str]:
    """Per fidelity and adaptive stepper, each tolerance's error / tolerance and whether the run
    meets its tolerance (error ≤ tolerance) — on the dynamic level and ``auto`` only: the slaved
    levels' error is their model error."""
    pts = [p for p in result["points"] if p.config.knob == "rtol"
           and p.config.stepper in ADAPTIVE and p.config.fidelity in ("dynamic", "auto")]
    lines = ["error / tolerance of every adaptive stepper (meets: ≤ 1):"]
    groups: dict = {}
    for p in pts:
        groups.setdefault((p.config.fidelity, p.config.stepper), []).append(p)
    for (fid, st), group in groups.items():
        cells = []
        for p in sorted(group, key=lambda p: -p.config.value):
            if p.status != "ok":
                cells.append(f"{p.config.value:.0e} {p.status}")
                continue
            ratio = p.error / p.config.value
            cells.append(f"{p.config.value:.0e} {ratio:.2f} " + ("meets" if ratio <= 1.0 else "MISSES"))
        lines.append(f"  {fid:8s} {st:18s} " + ", ".join(cells))
    return lines


def level_floor(points: list[Point], fidelity: str) -> Point | None:
    """A level's most accurate successful point: its model error (for the slaved levels the
    closed form, exact for their own model)."""
    cands = [p for p in points if p.status == "ok" and p.config.fidelity == fidelity]
    return min(cands, key=lambda p: p.error) if cands else None


def auto_summary(scene: Scene, result: dict) -> list[str]:
    """``auto``'s estimate against the measured model errors, its choice at the target and its
    cost against the dynamic level's implicit stepper (docs/accuracy.md §4)."""
    if scene.auto is None:
        return []
    pts = result["points"]
    choice = scene.auto(scene.target_error)
    lines = ["auto: estimated model error against measured (the level's most accurate point):"]
    for fid in FIDELITIES:
        floor = level_floor(pts, fid)
        meas = f"{floor.error:.2e} ({floor.config.label})" if floor else "not run"
        lines.append(f"  {fid:13s} estimated {choice.errors[fid]:9.2e}  measured {meas}")
    lines.append(f"auto's estimate at tolerance {scene.target_error:g} asks for the "
                 f"{choice.fidelity} level somewhere in the run ({choice.describe()})")
    mine = cheapest([p for p in pts if p.config.fidelity == "auto"], scene.target_error)
    implicit = cheapest([p for p in pts if p.config.fidelity == "dynamic"], scene.target_error,
                        "rosenbrock")
    if mine is None:
        lines.append(f"  no auto configuration (switching along the run) meets "
                     f"{scene.target_error:g}" + ("" if any(p.config.fidelity == "auto"
                                                          for p in pts) else " (none run)"))
    else:
        lines.append(f"  cheapest auto configuration meeting it: {mine.config.label} "
                     f"(error {mine.error:.2e}, {mine.cpu_per_s:.3e} CPU s/s)")
    if implicit is not None and mine is not None:
        to_beat = AUTO_SPEEDUP_TO_BEAT.get(scene.name)
        lines.append(f"  speed-up of auto over the dynamic level with the implicit "
                     f"stepper ({implicit.config.label}, error {implicit.error:.2e}, "
                     f"{implicit.cpu_per_s:.3e} CPU s/s): "
                     f"{implicit.cpu_per_s / mine.cpu_per_s:.1f}x"
                     + (f"  (to beat: ≥ {to_beat:g}x)" if to_beat else ""))
    if implicit is not None:
        floor = min((p for p in python_points(pts) if p.status == "ok"),
                    key=lambda p: p.cpu_per_s)
        lines.append(f"  bound: the cheapest configuration of the grid at any error "
                     f"({floor.config.label}, error {floor.error:.2e}) is "
                     f"{implicit.cpu_per_s / floor.cpu_per_s:.1f}x cheaper than that implicit "
                     "stepper: no choice of level can be faster than this")
    own = sorted((p for p in pts if p.config.fidelity == "auto" and p.config.stepper == "default"),
                 key=lambda p: -p.config.value)
    if own:
        lines.append("  auto with its default stepper (the FMU's) against its own tolerance: "
                     + ", ".join(f"{p.config.value:.0e} → " + (
                         f"{p.error:.2e} " + ("meets" if p.error <= p.config.value else "MISSES")
                         if p.status == "ok" else p.status) for p in own))
    cheaper = FIDELITIES[:FIDELITIES.index(choice.fidelity)]
    if cheaper:
        nxt = level_floor(pts, cheaper[-1])
        if nxt is not None:
            lines.append(f"  the next cheaper level, {cheaper[-1]}, "
                         + ("does not meet" if nxt.error > scene.target_error else "MEETS")
                         + f" it (model error {nxt.error:.2e})")
    return lines


def write_csv(scene: Scene, result: dict, path: Path) -> None:
    """One row per configuration (errors per output included); every row also carries the
    scene's reference check difference (the chart's floor), so that :func:`replot` can redraw
    the chart from the CSV alone."""
    best = cheapest(result["points"], scene.target_error)
    ref_diff = f"{result['reference_difference']:.6e}"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scene", "fidelity", "stepper", "knob", "value", "status", "error",
                    "cpu_s_per_sim_s", "rhs_calls", "rhs_per_sim_s", "pareto",
                    f"cheapest_at_{scene.target_error:g}", "reference_difference"]
                   + [f"err:{o}" for o in scene.outputs])
        for p in result["points"]:
            c = p.config
            w.writerow([scene.name, c.fidelity, c.stepper, c.knob, f"{c.value:g}", p.status,
                        f"{p.error:.6e}", f"{p.cpu_per_s:.4e}", p.rhs_calls,
                        f"{p.rhs_per_s:.6g}", int(p.pareto), int(p is best), ref_diff]
                       + [f"{p.errors.get(o, math.nan):.6e}" for o in scene.outputs])


#: the reference check difference (the charts' grey floor) of the CSVs written before
#: :func:`write_csv` stored it (its ``reference_difference`` column): the numbers
#: docs/accuracy.md states for those runs (§1: 6e-13 for the start-up; §2, actuator-loop
#: scenes: "checked at 1e-11 (3e-13, 9e-13, 3e-13, 3e-13)" in the order position step, sine
#: tracking, load step, speed reversal, and 2.9e-13 for the speed reversal in its own
#: paragraph).  docs/accuracy.md gives none for ``startup_1us``: its 2e-12 is the difference
#: of the scene's two references (:func:`reference` at rtol 1e-12 and 1e-11, deterministic),
#: run again for this table (2.01e-12; the start-up's came out 6.36e-13, as stated).
LEGACY_REFERENCE_DIFFERENCE = {"startup": 6e-13, "startup_1us": 2e-12,
                               "position_step": 3e-13, "sine_tracking": 9e-13,
                               "load_step": 3e-13, "speed_reversal": 2.9e-13}


def read_csv(path: Path) -> dict:
    """A scene's CSV as :func:`write_csv` writes it, back as the result :func:`plot` draws.

    Returns
    -------
    dict
        ``scene`` (name), ``target_error`` (from the ``cheapest_at_<target>`` column),
        ``points`` (list of Point: configuration, status, errors, costs and Pareto flag as
        stored), ``cheapest`` (the point flagged cheapest at the target, or None),
        ``reference_difference`` (the stored column, else :data:`LEGACY_REFERENCE_DIFFERENCE`)
        and ``reference_difference_source`` (where that came from, for the printout).
    """
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        columns = list(reader.fieldnames or ())
        rows = list(reader)
    if not rows:
        raise ValueError(f"{path}: no configurations")
    names = {r["scene"] for r in rows}
    if len(names) != 1:
        raise ValueError(f"{path}: rows of several scenes {sorted(names)}")
    name = names.pop()
    flag = next((c for c in columns if c.startswith("cheapest_at_")), None)
    if flag is None:
        raise ValueError(f"{path}: no cheapest_at_<target> column")
    outputs = [c[len("err:"):] for c in columns if c.startswith("err:")]
    points, best = [], None
    for r in rows:
        cfg = Config(r["fidelity"], r["stepper"], r["knob"], float(r["value"]))
        p = Point(cfg, r["status"], float(r["error"]),
                  {o: float(r[f"err:{o}"]) for o in outputs}, float(r["cpu_s_per_sim_s"]),
                  float(r["rhs_per_sim_s"]), int(r["rhs_calls"]), bool(int(r["pareto"])))
        points.append(p)
        if int(r[flag]):
            best = p
    if "reference_difference" in columns:
        ref_diff, source = float(rows[0]["reference_difference"]), "csv"
    elif name in LEGACY_REFERENCE_DIFFERENCE:
        ref_diff = LEGACY_REFERENCE_DIFFERENCE[name]
        source = "LEGACY_REFERENCE_DIFFERENCE (docs/accuracy.md; startup_1us re-derived)"
    else:
        raise ValueError(f"{path}: no reference_difference column and no stored value for "
                         f"scene {name!r}")
    return {"scene": name, "target_error": float(flag[len("cheapest_at_"):]), "points": points,
            "cheapest": best, "reference_difference": ref_diff,
            "reference_difference_source": source}


def replot(scene: Scene, csv_path: Path, png_path: Path) -> dict:
    """Redraw a scene's chart from its CSV through :func:`plot` (no run): the title, the
    legend and the styles are the code's, the points the CSV's.

    The CSV must be the scene's, at the scene's target error, and the point it flags cheapest
    must be the one :func:`plot` marks (checked).  Returns :func:`read_csv`'s result.
    """
    result = read_csv(csv_path)
    if result["scene"] != scene.name:
        raise ValueError(f"{csv_path} holds scene {result['scene']!r}, not {scene.name!r}")
    if result["target_error"] != scene.target_error:
        raise ValueError(f"{csv_path} was written at target {result['target_error']:g}, the "
                         f"scene's is now {scene.target_error:g}: re-run the scene")
    if cheapest(result["points"], scene.target_error) is not result["cheapest"]:
        raise ValueError(f"{csv_path}: the point flagged cheapest at {scene.target_error:g} is "
                         "not the cheapest of the stored points")
    plot(scene, result, png_path)
    return result


def rerun_stepper(scene: Scene, stepper: str, csv_path: Path, png_path: Path) -> dict:
    """Re-run only the scene's configurations of one stepper and put them in place of that
    stepper's rows of the scene's CSV (the other rows kept as stored), then redraw the chart.

    The reference and its check are run again and must give the check difference the CSV
    stored within 10 % (a change of the model since the CSV was written moves it by round-off;
    a change of the references by more than their floor would move it by more), so the kept
    rows' errors still hold to that floor; the CSV then stores the new difference.  Their CPU
    costs are the stored run's; the re-run rows' costs are this run's (the printout says so).
    The Pareto flags and the cheapest point are recomputed over all rows.

    Returns
    -------
    dict
        The merged result (as :func:`read_csv` gives it) with ``replaced``, the new points.
    """
    stored = read_csv(csv_path)
    if stored["scene"] != scene.name or stored["target_error"] != scene.target_error:
        raise ValueError(f"{csv_path} is not scene {scene.name!r} at target "
                         f"{scene.target_error:g}: re-run the whole scene")
    grid = tuple(c for c in scene.grid if c.stepper == stepper)
    if not grid:
        raise ValueError(f"stepper = {stepper!r} has no configuration in scene {scene.name!r}")
    ref = reference(scene, REFERENCE_RTOL)
    check = reference(scene, CHECK_RTOL)
    ref_diff = max(output_errors(check.outputs, ref.outputs, scene.outputs).values())
    if not abs(ref_diff - stored["reference_difference"]) <= 0.1 * stored["reference_difference"]:
        raise ValueError(f"the reference check difference is {ref_diff:.6e}, the CSV's "
                         f"{stored['reference_difference']:.6e}: the references changed, so the "
                         "stored rows' errors do not hold: re-run the whole scene")
    new = {c: measure(scene, c, ref) for c in grid}
    points = [new.pop(p.config, p) for p in stored["points"]] + list(new.values())
    for p in points:
        p.pareto = False
    mark_pareto(points)
    result = {"points": points, "reference_difference": ref_diff, "reference": ref,
              "replaced": [p for p in points if p.config.stepper == stepper]}
    write_csv(scene, result, csv_path)
    plot(scene, result, png_path)
    return result


STEPPER_STYLE = {"rk4": ("tab:blue", "explicit fixed (RK4 × substeps)"),
                 "explicit_adaptive": ("tab:orange", "explicit adaptive (DP5(4), rtol)"),
                 "rosenbrock": ("tab:green", "implicit (ROS34PW2, rtol)"),
                 "exponential": ("tab:olive", "exponential Rosenbrock (exprb32, rtol)"),
                 "closed_form": ("tab:purple", "closed form (slaved levels)"),
                 "default": ("tab:brown", "auto's own choice per step (DP5(4), exprb32 or ROS34PW2)"),
                 "radau": ("tab:gray", "solve_ivp Radau restarted (baseline, rtol)"),
                 NATIVE: ("tab:red", "ROS34PW2 in C (the engine both FMUs run, rtol)")}
FIDELITY_MARKER = {"dynamic": "o", "quasi-static": "s", "kinematic": "^", "auto": "D"}


def plot(scene: Scene, result: dict, path: Path) -> None:
    """Log–log error against CPU cost and against rhs calls, Pareto front marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = [p for p in result["points"] if p.status == "ok"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.6), sharey=True)
    for ax, attr, xlabel in ((axes[0], "cpu_per_s", "CPU seconds per simulated second"),
                             (axes[1], "rhs_per_s", "rhs calls per simulated second")):
        series: dict = {}
        for p in pts:
            series.setdefault((p.config.fidelity, p.config.stepper), []).append(p)
        for (fid, st), ps in series.items():
            ps = sorted(ps, key=lambda p: p.config.value)
            colour = STEPPER_STYLE[st][0]
            xs = [getattr(p, attr) for p in ps]
            ys = [max(p.error, ERROR_FLOOR) for p in ps]
            ax.plot(xs, ys, "-", color=colour, alpha=0.35, lw=1)
            ax.plot(xs, ys, FIDELITY_MARKER[fid], color=colour, ms=5, mfc="none" if fid != "dynamic" else colour)
        front = sorted((p for p in pts if p.pareto), key=lambda p: p.cpu_per_s)
        if attr == "cpu_per_s":
            fx = [p.cpu_per_s for p in front]
            fy = [max(p.error, ERROR_FLOOR) for p in front]
            ax.step(fx, fy, where="post", color="k", lw=1.3, label="Pareto front (CPU)")
            ax.plot(fx, fy, "o", ms=10, mfc="none", mec="k")
        else:
            ax.plot([p.rhs_per_s for p in front], [max(p.error, ERROR_FLOOR) for p in front],
                    "o", ms=10, mfc="none", mec="k", label="Pareto front (CPU), for reference")
        best = cheapest(result["points"], scene.target_error)
        if best is not None:
            ax.plot([getattr(best, attr)], [max(best.error, ERROR_FLOOR)], "*", ms=16, color="gold",
                    mec="k", label=f"cheapest at error ≤ {scene.target_error:g}: {best.config.label}")
        ax.axhline(scene.target_error, ls="--", color="r", lw=0.8)
        ax.axhspan(ERROR_FLOOR, max(result["reference_difference"], ERROR_FLOOR), color="0.85",
                   label="reference check difference (floor)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_ylabel("error: max over outputs and output times of |y − y_ref| / max|y_ref|")
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color=c, marker="o", ls="-", label=lab) for c, lab in STEPPER_STYLE.values()]
    handles += [Line2D([], [], color="k", marker=m, ls="", mfc="none", label=f) for f, m in FIDELITY_MARKER.items()]
    axes[0].legend(handles=handles, fontsize=7, loc="lower left")
    axes[1].legend(fontsize=7, loc="lower left")
    fig.suptitle(scene.title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def quick_grid(scene: Scene) -> tuple[Config, ...]:
    """A small slice of the scene's grid (for a fast look and the reproducibility test)."""
    keep = {("rk4", 1), ("rk4", 4), ("explicit_adaptive", 1e-6), ("rosenbrock", 1e-6),
            ("closed_form", 0.0), ("radau", 1e-6)}
    return tuple(c for c in scene.grid if (c.stepper, c.value) in keep)


def main(argv=None) -> None:
    """Run the scenes, print the summaries, write CSV and PNG files."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", action="append", choices=sorted(SCENES),
                    help="scene to run (repeatable; default: all)")
    ap.add_argument("--quick", action="store_true", help="a small slice of the grid")
    ap.add_argument("--out", type=Path, default=FIGURES, help="output directory (docs/figures)")
    ap.add_argument("--replot", action="store_true",
                    help="run nothing: redraw each scene's wp_<scene>.png from its "
                         "wp_<scene>.csv in --out")
    ap.add_argument("--stepper", metavar="NAME",
                    help="re-run only this stepper's configurations of each selected scene and "
                         "replace its rows of wp_<scene>.csv in --out (the other rows and their "
                         "CPU costs kept as stored; the references must reproduce the stored "
                         "check difference), then redraw the PNG")
    args = ap.parse_args(argv)
    if args.replot and args.quick:
        ap.error("--replot runs nothing: --quick does not apply")
    if args.stepper and (args.replot or args.quick):
        ap.error("--stepper re-runs one stepper's rows: --replot and --quick do not apply")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.scene or list(SCENES):
        scene = SCENES[name]
        if args.replot:
            csv_path, png_path = args.out / f"wp_{name}.csv", args.out / f"wp_{name}.png"
            result = replot(scene, csv_path, png_path)
            n_ok = sum(p.status == "ok" for p in result["points"])
            print(f"replotted {png_path} from {csv_path}: {n_ok} of {len(result['points'])} "
                  f"points ok, floor {result['reference_difference']:.2g} (from "
                  f"{result['reference_difference_source']})")
            continue
        if args.stepper:
            csv_path, png_path = args.out / f"wp_{name}.csv", args.out / f"wp_{name}.png"
            c0 = time.time()
            result = rerun_stepper(scene, args.stepper, csv_path, png_path)
            print(f"\n== scene {name}: re-ran the {len(result['replaced'])} {args.stepper} "
                  f"configurations (this run's CPU costs; the other rows' are the stored run's), "
                  f"reference check difference {result['reference_difference']:.2e} as stored")
            for p in result["replaced"]:
                print(f"  {p.config.label:42s} " + (f"error {p.error:9.2e}  CPU {p.cpu_per_s:9.3e} "
                      f"s/s  rhs {p.rhs_calls:7d}" if p.status == "ok" else p.status))
            for line in tolerance_summary(result):
                print(line)
            print(f"wrote {csv_path} and {png_path} [{time.time() - c0:.0f} s]")
            continue
        grid = quick_grid(scene) if args.quick else scene.grid
        c0 = time.time()
        result = run_scene(scene, grid)
        for line in summary(scene, result):
            print(line)
        csv_path, png_path = args.out / f"wp_{name}.csv", args.out / f"wp_{name}.png"
        write_csv(scene, result, csv_path)
        plot(scene, result, png_path)
        print(f"wrote {csv_path} and {png_path} [{time.time() - c0:.0f} s]")


if __name__ == "__main__":
    main()
