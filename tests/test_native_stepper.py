"""The native FMU's C model and ROS34PW2 in-process (fmu_build.native_stepper) against the
Python model and stepper they translate: equal states, rhs calls and right-hand sides."""

from __future__ import annotations

import random
import shutil

import pytest

from prsm_fmu import presets
from prsm_fmu.models import AdaptiveModel, make_model
from prsm_fmu.simulate import tuned_stepper_options
from prsm_fmu.steppers import StepFailure, make_stepper

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")


def _native(model, **kw):
    from fmu_build.native_stepper import NativeStepper

    return NativeStepper(model, **kw)


def _start_up_alike(model, u: tuple[float, float]) -> list[float]:
    """100 steps of 10 us from 100 rad/s with the carriers at rest, inputs ``u`` held, by the
    Python ROS34PW2 and the C: states, rhs calls and substeps equal bit for bit at every step;
    the last state."""
    x0 = model.initial_state(u, screw_speed=100.0, carrier_ratio=0.0)
    py = make_stepper("rosenbrock", model, **tuned_stepper_options("rosenbrock", 1e-6, 1e-9))
    nat = _native(model, rtol=1e-6, atol=1e-9)
    xa = xb = x0
    for i in range(100):
        xa, sa = py.advance(i * 1e-5, xa, u, 1e-5)
        xb, sb = nat.advance(i * 1e-5, xb, u, 1e-5)
        assert xb == xa and (sb.rhs_calls, sb.substeps) == (sa.rhs_calls, sa.substeps), i
    return xa


def _single_stage():
    """The friction-torque article's single-stage PRSM with the Coulomb friction only (the C has
    no viscous or differential-sliding term): two unknowns in the iteration matrix."""
    from dataclasses import replace

    return replace(presets.load("friction_single_stage"), mu_viscous=0.0, mu_differential=0.0)


@pytest.mark.parametrize("drive,u,stages", [("speed", (0.0, 5000.0), 2),
                                            ("torque", (19.75, 5000.0), 2),
                                            ("speed", (0.0, 5000.0), 1),
                                            ("speed", (0.0, 5000.0), 3)])
def test_start_up_equals_the_python_rosenbrock_bit_for_bit(drive, u, stages):
    """Li et al.'s (2021) start-up (100 rad/s, carriers at rest, 5 kN; speed drive: the speed held,
    torque drive: 19.75 N.m) over 1 ms in steps of 10 us: the carriers' transient is stiff
    (time constants of ~0.01-0.5 ms), so every part of the stepper runs (first-step bound,
    Jacobian reuse and refresh, continuation); and the same start-up of a single-stage PRSM
    (2 unknowns in the iteration matrix: the unrolled 2x2 LU) and of a three-stage one (4: the
    general LU)."""
    from fmu_build.mechanisms import three_stage

    params = {1: _single_stage, 2: lambda: presets.load("li2021_two_stage"),
              3: three_stage}[stages]()
    xa = _start_up_alike(make_model(params, "dynamic", drive), u)
    # the carriers spun up from rest towards their equilibrium ratio (~0.37 of the screw speed)
    assert all(20.0 < w < 50.0 for w in xa[2:2 + params.n_stages])


def test_another_geometry_runs_on_the_same_library_bit_for_bit():
    """Li et al.'s PRSM2 with a thinner stage 1 (r_S 9, r_R 3, r_N 15 mm: r_N = r_S + 2 r_R =
    n_S r_R) and 40° flanks on stage 2: the library compiled for the preset serves it (no other
    compile), and its dynamic start-up (100 rad/s, carriers at rest, 19.75 N.m against 5 kN,
    100 steps of 10 us) equals the Python ROS34PW2's bit for bit, while differing from the
    preset's."""
    import math
    from dataclasses import replace

    from fmu_build.native_stepper import native_library

    base = presets.load("li2021_two_stage")
    s1, s2 = base.stages
    params = replace(base, stages=(
        replace(s1, screw_radius=0.009, roller_radius=0.003, nut_radius=0.015),
        replace(s2, flank_angle=math.radians(40.0))))
    assert native_library(params) is native_library(base)
    u = (19.75, 5000.0)
    runs = []
    for p in (params, base):
        runs.append(_start_up_alike(make_model(p, "dynamic", "torque"), u))
    assert runs[0] != runs[1]


@pytest.mark.parametrize("three,drive", [(False, "speed"), (False, "torque"), (True, "torque")])
def test_rhs_equals_the_python_model_at_random_states(three, drive):
    from fmu_build.mechanisms import three_stage

    params = three_stage() if three else presets.load("li2021_two_stage")
    model = make_model(params, "dynamic", drive)
    nat = _native(model)
    rng = random.Random(25)
    n = params.n_stages
    for _ in range(500):
        x = ([rng.uniform(-10.0, 10.0), rng.uniform(-200.0, 200.0)]
             + [rng.uniform(-100.0, 100.0) for _ in range(n)] + [0.0, 0.0, 0.0])
        first = rng.uniform(-3e4, 3e4) if drive == "speed" else rng.uniform(-40.0, 40.0)
        u = (first, rng.uniform(-8000.0, 8000.0))
        assert nat.rhs(x, u) == model.rhs(0.0, x, u), (x, u)


def test_memory_round_trip_repeats_the_next_advance():
    model = make_model(presets.load("li2021_two_stage"), "dynamic", "speed")
    u = (0.0, 5000.0)
    nat = _native(model)
    x = model.initial_state(u, screw_speed=100.0, carrier_ratio=0.0)
    for i in range(5):
        x, _ = nat.advance(i * 1e-5, x, u, 1e-5)
    memory = nat.get_memory()
    a, sa = nat.advance(5e-5, x, u, 1e-5)
    nat.set_memory(memory)
    b, sb = nat.advance(5e-5, x, u, 1e-5)
    assert a == b and sa.rhs_calls == sb.rhs_calls
    with pytest.raises(ValueError, match="memory"):
        nat.set_memory((b"short",))


def test_refuses_what_it_does_not_model_and_reports_a_failed_step():
    params = presets.load("li2021_two_stage")
    with pytest.raises(ValueError, match="stepper"):
        _native(AdaptiveModel(params, "torque", tolerance=1e-3), stepper="closed_form")
    with pytest.raises(ValueError, match="rtol"):
        _native(make_model(params, "dynamic", "torque"), rtol=0.0)
    from dataclasses import replace

    with pytest.raises(ValueError, match="stepper"):
        _native(make_model(params, "dynamic", "torque"), stepper="closed_form")
    model = make_model(params, "dynamic", "speed")
    nat = _native(model, max_substeps=1)
    x = model.initial_state((0.0, 5000.0), screw_speed=100.0, carrier_ratio=0.0)
    with pytest.raises(StepFailure, match="max_substeps"):
        nat.advance(0.0, x, (0.0, 5000.0), 1e-3)


def test_advance_many_equals_single_advances():
    model = make_model(presets.load("li2021_two_stage"), "dynamic", "speed")
    u = (0.0, 5000.0)
    x0 = model.initial_state(u, screw_speed=100.0, carrier_ratio=0.0)
    one, many = _native(model), _native(model)
    rows, stats = many.advance_many(0.0, x0, u, 1e-5, 30)
    x, calls = x0, 0
    for i in range(30):
        x, s = one.advance(i * 1e-5, x, u, 1e-5)
        calls += s.rhs_calls
        assert rows[i] == x, i
    assert stats.rhs_calls == calls


@pytest.mark.parametrize("stepper", [None, "closed_form_explicit", "closed_form"])
def test_quasi_static_level_equals_the_python_closed_form_explicit(stepper):
    """The slaved level in C: the closed form under held inputs and, where it declines (the
    screw starting from rest against a load: the friction band), Dormand-Prince 5(4) (None, the
    former default, and closed_form_explicit) or the exponential band step (closed_form),
    against the Python stepper of that name at the same tolerances."""
    model = make_model(presets.load("li2021_two_stage"), "quasi-static", "torque")
    u = (19.75, 5000.0)
    x0 = model.initial_state(u)
    name = stepper or "closed_form_explicit"
    py = make_stepper(name, model, **tuned_stepper_options(name, 1e-6, 1e-8))
    nat = _native(model, rtol=1e-6, atol=1e-8, stepper=stepper)
    xa = xb = x0
    band_steps = 0
    for i in range(50):
        xa, sa = py.advance(i * 1e-3, xa, u, 1e-3)
        xb, sb = nat.advance(i * 1e-3, xb, u, 1e-3)
        band_steps += sa.rhs_calls > 1
        assert xb == xa and sb.rhs_calls == sa.rhs_calls, i
    assert band_steps >= 1 and xa[1] > 0.0          # it left the band, numerically stepped


@pytest.mark.parametrize("drive,u", [("speed", (-500.0, 2000.0)), ("torque", (-0.5, 2000.0))])
def test_reversal_through_zero_speed_equals_the_python_rosenbrock_bit_for_bit(drive, u):
    """Through zero screw speed every sliding speed passes its friction band, where both steppers
    end internal steps on the friction law's kinks (and shorten the steps that approach them):
    the C must take the same cuts.  Speed drive: 0.5 rad/s braked at 500 rad/s² through zero to
    −0.5 rad/s in 2 ms; torque drive: −0.5 N·m with 2 kN on the rod from 0.5 rad/s, carriers
    at equilibrium, 0.1 ms steps."""
    model = make_model(presets.load("li2021_two_stage"), "dynamic", drive)
    x0 = model.initial_state(u, screw_speed=0.5, carrier_ratio=None)
    for rtol in (1e-4, 1e-7):
        py = make_stepper("rosenbrock", model, **tuned_stepper_options("rosenbrock", rtol, rtol * 1e-3))
        nat = _native(model, rtol=rtol, atol=rtol * 1e-3)
        xa = xb = x0
        cut_or_rejected = 0
        for i in range(20):
            xa, sa = py.advance(i * 1e-4, xa, u, 1e-4)
            xb, sb = nat.advance(i * 1e-4, xb, u, 1e-4)
            cut_or_rejected += sa.rejected
            assert xb == xa and (sb.rhs_calls, sb.substeps, sb.rejected) == (
                sa.rhs_calls, sa.substeps, sa.rejected), (rtol, i)
        assert xa[1] < 0.0 < x0[1]              # the screw went through zero speed
        assert cut_or_rejected > 0


def test_auto_keeps_its_level_in_the_memory_and_across_a_refused_step():
    """fidelity = auto (Li et al.'s (2021) two stages, tolerance 1e-3, starting dynamic at
    50 rad/s, carriers at equilibrium, 3 N.m against 1 kN, then a reversal to -9 N.m against
    200 N): the level is part of the engine's memory — a memory saved after 20 steps and
    restored repeats the next 40 states and levels (both levels among them) bit for bit; reset
    goes back to the start level; a refused step (max_substeps = 1) leaves the memory and the
    model's level as they were."""
    params = presets.load("li2021_two_stage")
    model = AdaptiveModel(params, "torque", tolerance=1e-3, start="dynamic")
    nat = _native(model, rtol=1e-3, atol=1e-5, stepper="rosenbrock")
    u1, u2 = (3.0, 1000.0), (-9.0, 200.0)
    x = model.initial_state(u1, screw_speed=50.0, carrier_ratio=None)
    h = 1e-3
    for i in range(20):
        x, _ = nat.advance(i * h, x, u1, h)
    memory, x20, mode20 = nat.get_memory(), list(x), model.mode

    def run(stepper):
        y, rows = list(x20), []
        for i in range(40):
            y, _ = stepper.advance((20 + i) * h, y, u1 if i < 20 else u2, h)
            rows.append((y, model.mode))
        return rows

    first = run(nat)
    modes = {m for _, m in first}
    assert modes == {"dynamic", "quasi-static"}, modes      # it switches in these steps
    nat.set_memory(memory)
    assert model.mode == mode20
    assert run(nat) == first
    nat.reset()
    assert model.mode == "dynamic"
    # a refused step: the memory and the level stay as they were before it
    tight = _native(model, rtol=1e-3, atol=1e-5, stepper="rosenbrock", max_substeps=1)
    tight.set_memory(memory)
    before, mode_before, refused = tight.get_memory(), model.mode, 0
    y = list(x20)
    for i in range(40):
        try:
            y, _ = tight.advance((20 + i) * h, y, u1 if i < 20 else u2, h)
        except StepFailure:
            refused += 1
            assert tight.get_memory() == before and model.mode == mode_before, i
            break
        before, mode_before = tight.get_memory(), model.mode
    assert refused == 1
