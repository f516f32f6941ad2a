"""The sweep master's compiled step loop equals its Python loop, call for call.

:class:`prsm_fmu.sweep.fmu_runner.FmuRunner` tracks a prescribed screw speed on the torque-driven
FMU (save the state, trial torques, restore, secant).  Its loop runs compiled
(``prsm_fmu/sweep/native/fmu_track.c``, ``loop="native"``) or in Python (``loop="python"``, the
readable reference).  Both make the same FMI calls with the same arguments, so on every point
every output sample, the trial count and the right-hand-side count must be equal bit for bit,
and a point the FMU refuses must fail with the same message.  The points are drawn at random
(seeded): stage count 1–3 (PRSM1's mechanism carries the friction-torque article's viscous and
differential-sliding terms), every fidelity, friction, load and speed of either sign, a step
or a ramp, communication steps from 1 µs to 100 µs, tolerances 1e-6 and 1e-8, on the native FMU
and, for two stages, on the Python FMU; the count of points, of points the FMU refused and of
trials is printed.
"""

from __future__ import annotations

import dataclasses
import math
import os
import random
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")

from conftest import shared_build  # noqa: E402

from prsm_fmu.sweep import ensure_fmus  # noqa: E402
from prsm_fmu.sweep.fmu_runner import FmuPointError, FmuRunner  # noqa: E402
from prsm_fmu.sweep.native_track import loop_library  # noqa: E402
from prsm_fmu.sweep.points import speed_profile  # noqa: E402
from prsm_fmu.sweep.study import resolve_preset  # noqa: E402

#: random points compared (seeded); enough to reach every fidelity on every stage count
CASES = 72
SEED = 20261127
PRESETS = {1: "friction_single_stage", 2: "li2021_two_stage", 3: "li2021_three_stage"}
FIDELITIES = ("kinematic", "quasi-static", "dynamic", "auto")

if loop_library()[0] is None:
    pytest.skip(f"no compiled loop here: {loop_library()[1]}", allow_module_level=True)


@pytest.fixture(scope="module")
def fmus() -> dict[tuple[int, str], str]:
    """(stage count, kind) -> FMU: the native PRSM1..3 and the Python PRSM2."""
    def build(dest: Path) -> None:
        ensure_fmus([1, 2, 3], str(dest), kind="native")
        ensure_fmus([2], str(dest), kind="python")

    d = shared_build("sweep_track_fmus", build)
    found = {(n, "native"): os.path.join(d, f"PRSM{n}-native.fmu") for n in (1, 2, 3)}
    found[2, "python"] = os.path.join(d, "PRSM2.fmu")
    assert all(os.path.isfile(p) for p in found.values())
    return found


def _point(rng: random.Random, n_stages: int):
    base = resolve_preset(PRESETS[n_stages])
    params = dataclasses.replace(base, mu_screw_roller=rng.uniform(0.0, 0.3),
                                 mu_spline=rng.uniform(0.0, 0.3))
    h = rng.choice((1e-6, 1e-5, 1e-4))
    n = rng.randint(20, 120)
    speed = rng.choice((-1.0, 1.0)) * rng.uniform(1.0, 300.0)
    accel = rng.choice((0.0, rng.uniform(0.2, 1.0) * n * h))
    return dict(params=params, fidelity=rng.choice(FIDELITIES), speed=speed, accel=accel,
                load=rng.uniform(-8000.0, 8000.0), t_end=n * h, h=h,
                tolerance=rng.choice((1e-6, 1e-8)))


def _run(runner: FmuRunner, p: dict):
    profile, acc0 = speed_profile(p["speed"], p["accel"])
    try:
        return runner.run(p["params"], p["fidelity"], profile.speed, acc0, p["load"], p["t_end"],
                          p["h"])
    except FmuPointError as exc:
        return f"FmuPointError: {exc}"


def test_the_compiled_loop_gives_the_python_loops_results_on_random_points(fmus):
    rng = random.Random(SEED)
    runners: dict = {}
    counts = {"points": 0, "refused": 0, "trials": 0, "steps": 0}
    seen = set()
    for _ in range(CASES):
        n_stages = rng.choice((1, 2, 3))
        kind = "python" if n_stages == 2 and rng.random() < 0.3 else "native"
        p = _point(rng, n_stages)
        results = []
        for loop in ("python", "native"):
            key = (n_stages, kind, loop, p["tolerance"])
            if key not in runners:
                runners[key] = FmuRunner(fmus[n_stages, kind], tolerance=p["tolerance"],
                                         loop=loop)
            results.append(_run(runners[key], p))
        ref, fast = results
        shown = {k: v for k, v in p.items() if k != "params"}
        where = (f"point {counts['points']}: {n_stages} stages, {kind} FMU, µ_SR = "
                 f"{p['params'].mu_screw_roller!r}, µ_SS = {p['params'].mu_spline!r}, {shown}")
        counts["points"] += 1
        if isinstance(ref, str):
            assert fast == ref, where
            counts["refused"] += 1
            continue
        assert not isinstance(fast, str), (where, fast)
        assert fast.keys() == ref.keys()
        assert (fast["trials"], fast["rhs_calls"]) == (ref["trials"], ref["rhs_calls"]), where
        for name, values in ref.items():
            if isinstance(values, np.ndarray):
                np.testing.assert_array_equal(fast[name], values, err_msg=f"{name}, {where}")
        counts["trials"] += ref["trials"]
        counts["steps"] += len(ref["time"]) - 1
        seen.add((n_stages, p["fidelity"]))
    print(f"\ncompiled vs Python loop: {counts['points']} random points ({counts['refused']} "
          f"refused by the FMU, the same message), {counts['steps']} steps, "
          f"{counts['trials']} trials, 0 differences")
    # the draw reached every fidelity on every stage count (so the seed covers what it claims)
    assert seen == {(n, f) for n in (1, 2, 3) for f in FIDELITIES}, sorted(seen)


def test_a_step_the_fmu_refuses_mid_run_fails_alike_in_both_loops(fmus):
    """The reference speed ramps from a start where it is told the acceleration is 0 (so the
    first steps need the secant and the master learns the gain), then jumps to 1e80 rad/s at
    the sixth step: the secant's torque (~5e81 N·m) is out of the FMU's input range and the FMU
    refuses the step; both loops end the point with the same error, naming the step's time,
    the torque and the FMU's reason, and the runner runs the next point on a new instance."""
    p = resolve_preset("li2021_two_stage")
    errors = []
    for loop in ("python", "native"):
        runner = FmuRunner(fmus[2, "native"], loop=loop)
        with pytest.raises(FmuPointError) as info:
            runner.run(p, "quasi-static", lambda t: 100.0 + 1e5 * t if t < 5.5e-5 else 1e80,
                       0.0, 5000.0, 1e-4, 1e-5)
        errors.append(str(info.value))
        again = runner.run(p, "quasi-static", lambda t: 100.0, 0.0, 5000.0, 1e-4, 1e-5)
        # tracked to ~1e-13 (docs/sweeps.md); 1e-9 of 100 rad/s is far from both round-off
        # and a failed point
        assert np.max(np.abs(again["screw_speed"] - 100.0)) < 1e-7
        assert runner.instances_made == 2
    assert errors[0] == errors[1]
    assert errors[0].startswith("the FMU refused the step at t = 5e-05 s with screw_torque = ")
    assert "screw_torque" in errors[0].partition("the FMU says:")[2]


def test_an_unknown_loop_is_refused_naming_it(fmus):
    with pytest.raises(ValueError, match=r"loop = 'c' is not allowed: must be one of auto, "
                                         r"native, python"):
        FmuRunner(fmus[2, "native"], loop="c")
