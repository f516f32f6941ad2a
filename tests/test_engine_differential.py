"""Randomized differential test of the C engine (fmu_build.native_stepper) against the Python
reference (the model and the stepper it translates), and of both against a tight reference.

Each case draws a mechanism (one, two or three stages; masses, inertias, roller and carrier
counts, spline and bearing radii, the three Coulomb coefficients, the viscous and
differential-sliding terms and the slip velocity scale drawn within their bounds around a
preset's values) and a scenario: a level (kinematic,
quasi-static, dynamic), a drive (torque, or speed: a prescribed acceleration, zero in some
pieces), a stepper (at the slaved levels the Python default ``closed_form`` and
``closed_form_explicit``; at the dynamic level ``rosenbrock``), adaptive
or fixed internal steps, a tolerance, a communication step, a start (at rest, creeping inside
the friction band, moving either way) and piecewise-constant inputs of either sign (step inputs,
reversals through zero, holding torques inside the friction band).

Checks, per communication step:

* engine == reference: every state equal to <= 1e-12 relative (counted: how many are bit for
  bit), or both refuse the step (a Painleve state: the rigid contact has no solution there);
* engine within its tolerance of scipy's Radau IIA at rtol 1e-12 started from the same state,
  for adaptive steps (fixed internal steps promise no tolerance): the weighted RMS norm of the
  difference over all states, with the steppers' own weights atol + rtol max(|x|, |x_ref|)
  (atol = tolerance / 100, as the FMU), at most RADAU_NORM.  The steppers aim at a local error
  norm of 1 by their error estimates, which are asymptotic; RADAU_NORM = 10 leaves that
  estimate one order of magnitude.  Required of every adaptive method of the engine,
  ``closed_form_explicit`` (Dormand-Prince 5(4) in the friction band, as the Python stepper of
  that name, which it equals bit for bit) included since its steps land on the band edges'
  kinks: before, the long run (seed 20261126, 300 cases, every step) found 2 of its 250 steps
  beyond the bound (norms 22 and 28.5) and it was measured only; with the landing (and
  ROS34PW2's slip error norm) the same long run has 734 steps of 193 cases within 0.743, the
  250 of ``closed_form_explicit`` within 0.605.  Radau at rtol 1e-12 costs ~0.3 s per step across the friction band, so the suite
  checks the first step of the first RADAU_CASES adaptive cases; ``PRSM_ENGINE_LONG=1`` checks
  every step of every adaptive case.

The suite runs DIFF_CASES cases (seeded; the counts of cases, steps, bit-for-bit steps and
Radau checks are printed); ``PRSM_ENGINE_CASES=N`` runs N cases, ``PRSM_ENGINE_SEED=S``
another seed.

``fidelity = "auto"`` (prsm_auto.c against prsm_fmu/models/adaptive.py's SwitchingStepper with
ROS34PW2 dynamic steps, the Python stepper ``rosenbrock`` of an auto model) has cases of its own,
AUTO_CASES of them (``PRSM_ENGINE_AUTO_CASES=N``; same seed variable), drawn to cross levels: the
same random mechanisms, a tolerance of 1e-4 to 0.1 (the model error that decides the level),
either start level, start-ups (carriers at rest under a turning screw), load steps, reversals
and the speed drive, 2-10 communication steps per piece of held inputs.  Per step the states
must agree as above and both must have stepped the same level; the level switches are counted
and at least one case in five must switch (else the draw misses what it is for).  Radau is
checked on steps that were dynamic from start to end (the quasi-static steps leave the
dynamic model by design), on the first such step of the first RADAU_CASES cases or, with
``PRSM_ENGINE_LONG=1``, every one.
"""

from __future__ import annotations

import math
import os
import random
import shutil
from dataclasses import dataclass, replace

import pytest

from prsm_fmu import presets
from prsm_fmu.models import AdaptiveModel, make_model
from prsm_fmu.simulate import tuned_stepper_options
from prsm_fmu.steppers import StepFailure, make_stepper

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")

#: cases in the suite (kept under its time budget) and the default seed
DIFF_CASES = 300
DIFF_SEED = 20261126
#: the relative difference engine vs reference accepted where not bit for bit
REL = 1e-12
#: largest error norm against Radau (module docstring) and the cases checked in the suite
RADAU_NORM = 10.0
RADAU_CASES = 12


def _three_stage():
    from fmu_build.mechanisms import three_stage

    return three_stage()


def _single_stage():
    # the friction-torque article's single stage (its viscous and differential-sliding terms
    # are drawn in _draw_one like the others)
    return presets.load("friction_single_stage")


BASES = {1: _single_stage, 2: lambda: presets.load("li2021_two_stage"), 3: _three_stage}
_base_cache: dict = {}


def _base(n: int):
    if n not in _base_cache:
        _base_cache[n] = BASES[n]()
    return _base_cache[n]


def _log_uniform(rng: random.Random, lo: float, hi: float) -> float:
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


def _draw_mechanism(rng: random.Random, tally: "Tally"):
    """:func:`_draw_one` until it passes MechanismParams.validate (the rejected draws are
    counted: e.g. more rollers than fit around the screw)."""
    while True:
        try:
            return _draw_one(rng)
        except ValueError:
            tally.rejected_mechanisms += 1


def _draw_one(rng: random.Random):
    """A mechanism with the geometry of a 1-, 2- or 3-stage base and every tunable value drawn
    within its bounds (factors 0.3-3 on masses and inertias, 0.3-1 on the spline and bearing
    radii, which keeps the spline radius in [0.01, 1] x the screw radius; 3-12 rollers, 1 or 2
    carriers; each Coulomb coefficient zero in a quarter of the cases)."""
    n = rng.choice((1, 2, 3))
    base = _base(n)
    stages = []
    for st in base.stages:
        kw = {f: getattr(st, f) * _log_uniform(rng, 0.3, 3.0)
              for f in ("screw_mass", "nut_mass", "roller_mass", "carrier_mass", "screw_inertia",
                        "roller_inertia", "carrier_inertia")}
        # where the base has none: a spline inside the screw, a bearing around the nut
        kw["spline_radius"] = (st.spline_radius or st.screw_radius) * rng.uniform(0.3, 1.0)
        kw["bearing_radius"] = (st.bearing_radius or 2.0 * st.nut_radius) * rng.uniform(0.3, 1.0)
        kw["n_rollers"] = rng.randint(3, 12)
        kw["carriers"] = rng.choice((1, 2))
        stages.append(replace(st, **kw))

    def mu(hi: float) -> float:
        return 0.0 if rng.random() < 0.25 else rng.uniform(0.0, hi)

    # now and then a screw-roller coefficient near or beyond the self-locking limit (the axial
    # part of the contact normal, ~0.7 for 45 degree flanks): refused on construction, or
    # Painleve states (no rigid-contact solution) along the run
    mu_sr = rng.uniform(0.55, 0.95) if rng.random() < 0.08 else mu(0.3)
    # the viscous term per thread (the article: 1e-3 N.s/m; up to its bound 1e5 here) and the
    # differential-sliding arm (the article: ~1e-6 m; bound 1e-3 m), each absent in half of
    # the cases
    mu_v = 0.0 if rng.random() < 0.5 else _log_uniform(rng, 1e-4, 1e2)
    mu_d = 0.0 if rng.random() < 0.5 else _log_uniform(rng, 1e-7, 1e-4)
    params = replace(base, stages=tuple(stages), mu_screw_roller=mu_sr, mu_spline=mu(0.2),
                     mu_nut_screw=mu(0.2), mu_viscous=mu_v, mu_differential=mu_d,
                     slip_velocity_scale=_log_uniform(rng, 1e-4, 1e-2))
    return params.validate()


@dataclass
class Scenario:
    level: str
    drive: str
    stepper: str
    tol: float
    substeps: int
    h: float
    screw_speed: float
    pieces: list          # [(n_steps, (u0, u1)), ...]


def _draw_scenario(rng: random.Random, params, model_q) -> Scenario:
    level = rng.choice(("kinematic", "quasi-static", "quasi-static", "dynamic", "dynamic"))
    drive = rng.choice(("torque", "torque", "speed"))
    if level == "dynamic":
        stepper = "rosenbrock"
    else:
        stepper = rng.choice(("closed_form", "closed_form", "closed_form_explicit"))
    tol = rng.choice((1e-3, 1e-4, 1e-6, 1e-8))
    substeps = rng.choice((0, 0, 0, 0, 0, 2, 5))
    h = rng.choice((1e-5, 1e-4, 1e-3))
    band = model_q._advance_law().band_speed
    start = rng.choice(("rest", "rest", "creep", "moving"))
    speed = {"rest": 0.0, "creep": rng.uniform(-1.0, 1.0) * band,
             "moving": rng.choice((-1.0, 1.0)) * _log_uniform(rng, 0.1, 300.0)}[start]
    # the load's torque on screw 1 without friction: F c_out [N.m per N]
    c_out = model_q.mechanism.c_out
    pieces = []
    for _ in range(rng.randint(1, 3)):
        load = rng.choice((-1.0, 1.0)) * _log_uniform(rng, 10.0, 8000.0)
        if rng.random() < 0.15:
            load = 0.0
        if drive == "speed":
            first = rng.choice((0.0, rng.uniform(-3e4, 3e4)))
        else:
            # from back-driving (r < -1) through the holding band (|r| < 1) to driving (r > 1)
            r = rng.choice((0.0, rng.uniform(-2.0, 2.0), rng.uniform(-1.0, 1.0)))
            first = r * abs(load) * c_out if load else rng.uniform(-5.0, 5.0)
        pieces.append((rng.randint(1, 4), (first, load)))
    return Scenario(level, drive, stepper, tol, substeps, h, speed, pieces)


#: internal steps allowed per communication step (both sides fail alike beyond it; it bounds
#: the time of a stiff dynamic case in Python)
MAX_SUBSTEPS = 500


def _reference_stepper(model, sc: Scenario):
    # the Python FMU's stepper options (prsm_fmu.configure): atol a hundredth of the tolerance
    atol = 1e-2 * sc.tol
    if sc.substeps:
        return make_stepper(sc.stepper, model, rtol=sc.tol, atol=atol, fixed_substeps=sc.substeps,
                            max_substeps=MAX_SUBSTEPS)
    return make_stepper(sc.stepper, model, max_substeps=MAX_SUBSTEPS,
                        **tuned_stepper_options(sc.stepper, sc.tol, atol))


def _engine(model, sc: Scenario):
    from fmu_build.native_stepper import NativeStepper

    return NativeStepper(model, rtol=sc.tol, atol=1e-2 * sc.tol, stepper=sc.stepper,
                         fixed_substeps=sc.substeps or None, max_substeps=MAX_SUBSTEPS)


def _close(a: float, b: float) -> bool:
    return a == b or abs(a - b) <= REL * max(abs(a), abs(b))


def _radau_norm(model, t, x, u, h, y, tol):
    """Weighted RMS norm of y minus Radau's (rtol 1e-12) state after h from x."""
    ref = make_stepper("radau", model, rtol=1e-12, atol=1e-14)
    z, _ = ref.advance(t, x, u, h)
    atol = 1e-2 * tol
    s = sum(((a - b) / (atol + tol * max(abs(a), abs(b)))) ** 2 for a, b in zip(y, z))
    return math.sqrt(s / len(y)), z


@dataclass
class Tally:
    cases: int = 0
    steps: int = 0
    bit_equal: int = 0
    refused_both: int = 0
    radau_cases: int = 0
    radau_checked: int = 0
    worst_radau: float = 0.0
    rejected_mechanisms: int = 0
    refused_construction: int = 0


def _refused_alike(make, params, sc: Scenario, tally, label: str, exc: Exception) -> list[str]:
    """The reference refused ``params`` (a self-locking thread, ``exc``): the engine must refuse
    them as well.  It is handed a model ``make(params)`` of the same level built without the
    screw-roller friction, whose params then carry the refused value.  Its failures (none
    where the engine refused for the same reason, counted)."""
    model = make(replace(params, mu_screw_roller=0.0))
    model.params = params
    try:
        _engine(model, sc)
    except ValueError as exc_engine:
        tally.refused_construction += 1
        return [] if "mu_screw_roller" in str(exc_engine) else [
            f"{label}: the engine refused for another reason: {exc_engine} (ref: {exc})"]
    return [f"{label}: the reference refused ({exc}), the engine did not"]


def _mechanism_label(params) -> str:
    return (f"{params.n_stages} stages mu=({params.mu_screw_roller:.3g}, {params.mu_spline:.3g},"
            f" {params.mu_nut_screw:.3g}, viscous {params.mu_viscous:.3g}, differential "
            f"{params.mu_differential:.3g}) v_eps={params.slip_velocity_scale:.3g}")


def _step_both(ref, eng, t: float, xa, xb, u, h: float, tally, label: str,
               level_check=None) -> tuple:
    """One communication step of the reference and the engine, counted in ``tally``:
    ``(ya, yb, None)`` where they agree; ``(None, None, failure)`` where the case ends, with
    failure None where both refused the step (counted) and a message otherwise.
    ``level_check()`` (auto), called after both stepped, returns a message where they stepped
    different levels."""
    fa = fb = None
    try:
        ya, _ = ref.advance(t, xa, u, h)
    except StepFailure as exc:
        fa = exc
    try:
        yb, _ = eng.advance(t, xb, u, h)
    except StepFailure as exc:
        fb = exc
    tally.steps += 1
    if fa is not None or fb is not None:
        if fa is None or fb is None:
            return None, None, f"{label}: t={t:.6g} only one refused: ref {fa!r}, engine {fb!r}"
        tally.refused_both += 1
        return None, None, None
    why = level_check() if level_check is not None else None
    if why:
        return None, None, f"{label}: t={t:.6g} u={u} {why}"
    if ya == yb:
        tally.bit_equal += 1
    elif not all(_close(a, b) for a, b in zip(ya, yb)):
        rel = max(abs(a - b) / max(abs(a), abs(b), 1e-300) for a, b in zip(ya, yb))
        return None, None, (f"{label}: t={t:.6g} u={u} engine {yb[1]!r} vs reference "
                            f"{ya[1]!r} (screw speed; largest rel. difference {rel:.3g})")
    return ya, yb, None


def run_case(rng: random.Random, tally: Tally, long: bool) -> list[str]:
    """One random case; returns its failures (empty if none)."""
    params = _draw_mechanism(rng, tally)
    # the scenario's scales (band speed, load torque) do not depend on mu_screw_roller
    model_q = make_model(replace(params, mu_screw_roller=0.0), "quasi-static", "torque")
    sc = _draw_scenario(rng, params, model_q)
    label = f"{_mechanism_label(params)} {sc}"
    tally.cases += 1
    try:
        model = make_model(params, sc.level, sc.drive)
        ref = _reference_stepper(model, sc)
    except ValueError as exc:
        return _refused_alike(lambda p: make_model(p, sc.level, sc.drive), params, sc, tally,
                              label, exc)
    eng = _engine(model, sc)
    u0 = sc.pieces[0][1]
    x0 = model.initial_state(u0, screw_speed=sc.screw_speed) if sc.level != "dynamic" else \
        model.initial_state(u0, screw_speed=sc.screw_speed, carrier_ratio=None)
    xa = xb = x0
    t = 0.0
    failures = []
    radau = not sc.substeps and (long or tally.radau_cases < RADAU_CASES)
    tally.radau_cases += radau
    first = True
    for n_steps, u in sc.pieces:
        for _ in range(n_steps):
            ya, yb, why = _step_both(ref, eng, t, xa, xb, u, sc.h, tally, label)
            if ya is None:
                return failures + ([why] if why else [])
            if radau and (first or long):
                try:
                    norm, z = _radau_norm(model, t, xb, u, sc.h, yb, sc.tol)
                except StepFailure:
                    norm, z = None, None
                if norm is not None:
                    tally.radau_checked += 1
                    tally.worst_radau = max(tally.worst_radau, norm)
                    if not norm <= RADAU_NORM:
                        failures.append(f"{label}: t={t:.6g} u={u} engine {yb[1]!r} vs Radau "
                                        f"{z[1]!r} (screw speed): error norm {norm:.3g} > {RADAU_NORM}")
            first = False
            xa, xb = ya, yb
            t += sc.h
    return failures


#: auto cases in the suite
AUTO_CASES = 100
#: auto's tolerances (its model error, and the steppers' rtol as in the FMU)
AUTO_TOLERANCES = (1e-1, 1e-2, 1e-3, 1e-4)


@dataclass
class AutoTally:
    cases: int = 0
    steps: int = 0
    bit_equal: int = 0
    refused_both: int = 0
    refused_construction: int = 0
    rejected_mechanisms: int = 0
    switches: int = 0
    switching_cases: int = 0
    dynamic_steps: int = 0
    quasi_static_steps: int = 0
    radau_cases_done: int = 0
    radau_checked: int = 0
    worst_radau: float = 0.0


def _draw_auto_scenario(rng: random.Random, model_q) -> tuple[Scenario, str, float | None]:
    """A scenario for auto: the level fields as :func:`_draw_scenario`'s, the start level and
    the carriers' start ratio (None: at equilibrium, 0: at rest)."""
    drive = rng.choice(("torque", "torque", "speed"))
    tol = rng.choice(AUTO_TOLERANCES)
    substeps = rng.choice((0, 0, 0, 0, 2, 5))
    h = rng.choice((1e-5, 1e-4, 1e-3))
    band = model_q._advance_law().band_speed
    start = rng.choice(("rest", "creep", "moving", "moving", "moving"))
    speed = {"rest": 0.0, "creep": rng.uniform(-1.0, 1.0) * band,
             "moving": rng.choice((-1.0, 1.0)) * _log_uniform(rng, 1.0, 300.0)}[start]
    # a start-up (carriers at rest under the turning screw) or the carriers at equilibrium
    ratio = rng.choice((None, None, 0.0))
    level0 = rng.choice(("dynamic", "quasi-static"))
    c_out = model_q.mechanism.c_out
    pieces = []
    for _ in range(rng.randint(1, 3)):
        load = rng.choice((-1.0, 1.0)) * _log_uniform(rng, 10.0, 8000.0)
        if rng.random() < 0.15:
            load = 0.0
        if drive == "speed":
            first = rng.choice((0.0, 0.0, rng.uniform(-3e4, 3e4)))
        else:
            r = rng.choice((0.0, rng.uniform(-2.0, 2.0), rng.uniform(-1.0, 1.0)))
            first = r * abs(load) * c_out if load else rng.uniform(-5.0, 5.0)
        pieces.append((rng.randint(2, 10), (first, load)))
    return Scenario("auto", drive, "rosenbrock", tol, substeps, h, speed, pieces), level0, ratio


def _auto_model(params, sc: Scenario, level0: str) -> AdaptiveModel:
    return AdaptiveModel(params, sc.drive, tolerance=sc.tol, start=level0)


def run_auto_case(rng: random.Random, tally: AutoTally, long: bool) -> list[str]:
    """One random auto case; returns its failures (empty if none)."""
    params = _draw_mechanism(rng, tally)
    model_q = make_model(replace(params, mu_screw_roller=0.0), "quasi-static", "torque")
    sc, level0, ratio = _draw_auto_scenario(rng, model_q)
    label = f"auto from {level0} (carrier ratio {ratio}) {_mechanism_label(params)} {sc}"
    tally.cases += 1
    try:
        ref_model = _auto_model(params, sc, level0)
        ref = _reference_stepper(ref_model, sc)
    except ValueError as exc:
        return _refused_alike(lambda p: _auto_model(p, sc, level0), params, sc, tally, label, exc)
    eng_model = _auto_model(params, sc, level0)     # its own: each stepper sets its model's mode
    eng = _engine(eng_model, sc)
    x0 = ref_model.initial_state(sc.pieces[0][1], screw_speed=sc.screw_speed, carrier_ratio=ratio)
    xa = xb = x0
    t = 0.0
    failures: list[str] = []
    radau = not sc.substeps and (long or tally.radau_cases_done < RADAU_CASES)
    checked = False
    switched = 0
    def level_check() -> str | None:
        if ref_model.mode == eng_model.mode:
            return None
        return f"the reference stepped {ref_model.mode}, the engine {eng_model.mode}"

    for n_steps, u in sc.pieces:
        for _ in range(n_steps):
            mode0 = ref_model.mode
            ya, yb, why = _step_both(ref, eng, t, xa, xb, u, sc.h, tally, label, level_check)
            if ya is None:
                return failures + ([why] if why else [])
            if ref_model.mode == "dynamic":
                tally.dynamic_steps += 1
            else:
                tally.quasi_static_steps += 1
            if ref_model.mode != mode0:
                switched += 1
            if radau and mode0 == ref_model.mode == "dynamic" and (long or not checked):
                checked = True
                try:
                    norm, z = _radau_norm(ref_model.dynamic, t, xb, u, sc.h, yb, sc.tol)
                except StepFailure:
                    norm, z = None, None
                if norm is not None:
                    tally.radau_checked += 1
                    tally.worst_radau = max(tally.worst_radau, norm)
                    if not norm <= RADAU_NORM:
                        failures.append(f"{label}: t={t:.6g} u={u} engine {yb[1]!r} vs Radau "
                                        f"{z[1]!r} (screw speed): error norm {norm:.3g} > "
                                        f"{RADAU_NORM}")
            xa, xb = ya, yb
            t += sc.h
    tally.radau_cases_done += radau and checked
    tally.switches += switched
    tally.switching_cases += switched > 0
    return failures


def _run_cases(run, tally, cases_env: str, default: int) -> tuple[int, list[str]]:
    """``run(rng, tally, long)`` for as many cases as ``cases_env`` says (default ``default``),
    seeded by ``PRSM_ENGINE_SEED``, every step with ``PRSM_ENGINE_LONG``: (seed, failures)."""
    n = int(os.environ.get(cases_env) or default)
    seed = int(os.environ.get("PRSM_ENGINE_SEED", DIFF_SEED))
    long = bool(os.environ.get("PRSM_ENGINE_LONG"))
    rng = random.Random(seed)
    failures: list[str] = []
    for _ in range(n):
        failures += run(rng, tally, long)
    return seed, failures


def test_engine_auto_equals_the_reference_on_random_cases(capsys):
    tally = AutoTally()
    seed, failures = _run_cases(run_auto_case, tally, "PRSM_ENGINE_AUTO_CASES", AUTO_CASES)
    with capsys.disabled():
        print(f"\nengine vs reference, auto (seed {seed}): {tally.cases} cases, {tally.steps} "
              f"steps ({tally.dynamic_steps} dynamic, {tally.quasi_static_steps} quasi-static), "
              f"{tally.bit_equal} bit for bit, {tally.switches} level switches in "
              f"{tally.switching_cases} cases, {tally.refused_both} steps refused by both, "
              f"{tally.refused_construction} mechanisms refused by both, "
              f"{tally.rejected_mechanisms} mechanisms redrawn, {tally.radau_checked} dynamic "
              f"steps checked against Radau (worst norm {tally.worst_radau:.3g}), "
              f"{len(failures)} failing cases")
    assert not failures, "\n".join(failures[:20])
    # the draw is for crossing levels: at least one case in five switches
    assert 5 * tally.switching_cases >= tally.cases, tally


#: start choices compared in the suite
CHOICE_CASES = 100


def test_auto_start_choice_in_c_equals_the_reference_on_random_cases(capsys):
    """The level fidelity = auto starts with, chosen in C (prsm_auto_choose: what the native FMU
    runs at initialization) and by prsm_fmu.models.auto.choose_for_start (torque drive, no
    communication step), on random mechanisms (a quarter of them without friction, where the
    kinematic level can be chosen), tolerances, start inputs, speeds, carriers at rest or at
    equilibrium and kinematic efficiencies: the same level and the same estimated model errors
    of the kinematic and the quasi-static level, bit for bit (NaN where both are NaN); the
    quasi-static and the dynamic level are each chosen in some case.  (The kinematic level is
    not reached: without friction the quasi-static level's efficiency rounds to 1 - 2.2e-16, and
    the estimate of its friction outputs' error, |eta - eta_0| / (1 - eta), is then 1 for
    eta_0 = 1.)"""
    from fmu_build.native_stepper import auto_start_level
    from prsm_fmu.models.auto import choose_for_start

    n = int(os.environ.get("PRSM_ENGINE_CHOICE_CASES") or CHOICE_CASES)
    seed = int(os.environ.get("PRSM_ENGINE_SEED", DIFF_SEED))
    rng = random.Random(seed)
    tally = Tally()
    levels: dict[str, int] = {}
    failures, refused = [], 0
    for _ in range(n):
        params = _draw_mechanism(rng, tally)
        frictionless = rng.random() < 0.25
        if frictionless:
            params = replace(params, mu_screw_roller=0.0, mu_spline=0.0, mu_nut_screw=0.0,
                             mu_viscous=0.0, mu_differential=0.0)
        tol = rng.choice((1e-1, 3e-2, 1e-2, 1e-3, 1e-4))
        inputs = (rng.choice((0.0, rng.uniform(-20.0, 20.0))),
                  rng.choice((0.0, rng.uniform(-5000.0, 5000.0))))
        speed = rng.choice((0.0, rng.uniform(-300.0, 300.0)))
        at_rest = rng.random() < 0.5
        eff = rng.choice((1.0, rng.uniform(0.5, 1.0)))
        if frictionless and rng.random() < 0.5:
            inputs, eff = (0.0, 0.0), 1.0        # no input, the kinematic level lossless
        try:
            ref = choose_for_start(params, tol, "torque", inputs, screw_speed=speed,
                                   carrier_ratio=0.0 if at_rest else None,
                                   kinematic_efficiency=eff)
        except ValueError as exc:          # a self-locking thread: the C refuses it as well
            try:
                auto_start_level(params, tol, inputs, speed, at_rest, eff)
            except ValueError:
                refused += 1
                continue
            failures.append(f"{params.name}: the reference refused ({exc}), the C did not")
            continue
        level, e_kin, e_qs = auto_start_level(params, tol, inputs, speed, at_rest, eff)
        levels[level] = levels.get(level, 0) + 1
        got = (level, e_kin, e_qs)
        want = (ref.fidelity, ref.errors["kinematic"], ref.errors["quasi-static"])
        if not all(a == b or (a != a and b != b) for a, b in zip(got, want)):
            failures.append(f"tol {tol} inputs {inputs} speed {speed} at rest {at_rest} eff "
                            f"{eff}: C {got}, reference {want}")
    with capsys.disabled():
        print(f"\nauto's start choice, C vs reference (seed {seed}): {n} cases, levels chosen "
              f"{levels}, {refused} refused by both, {len(failures)} failing")
    assert not failures, "\n".join(failures[:20])
    assert {"quasi-static", "dynamic"} <= set(levels), levels


def test_engine_equals_the_reference_on_random_cases(capsys):
    tally = Tally()
    seed, failures = _run_cases(run_case, tally, "PRSM_ENGINE_CASES", DIFF_CASES)
    with capsys.disabled():
        print(f"\nengine vs reference (seed {seed}): {tally.cases} cases, {tally.steps} steps, "
              f"{tally.bit_equal} bit for bit, {tally.refused_both} steps refused by both, "
              f"{tally.refused_construction} mechanisms refused by both, "
              f"{tally.rejected_mechanisms} mechanisms redrawn, {tally.radau_checked} steps of {tally.radau_cases} cases checked against Radau (worst norm "
              f"{tally.worst_radau:.3g}), {len(failures)} failing cases")
    assert not failures, "\n".join(failures[:20])


@pytest.mark.parametrize("load,tol,h,n_steps", [(-2006.6, 1e-4, 1e-4, 3), (-5202.0, 1e-4, 1e-4, 3),
                                                (3000.0, 1e-6, 1e-3, 2)])
def test_from_rest_the_engine_meets_its_tolerance_against_radau(load, tol, h, n_steps):
    """PRSM2 (Li et al. (2021) §3.1) from rest, 0 N.m, quasi-static: back-driven by a pulling
    load (-2006.6 N, -5202 N: the screw speeds up through the friction band) and held against
    a pushing one (3 kN: it creeps backwards).  The engine with the Python default stepper
    repeats the Python model bit for bit, and each communication step's screw speed is within
    the tolerance (relative, plus the absolute tolerance tol/100 rad/s) of Radau IIA at rtol
    1e-12 from the same state.  The engine stepping the band by Dormand-Prince (the former
    native default) missed by 1 % at tol 1e-4: 1.25865 rad/s against 1.24565 after 0.1 ms."""
    from fmu_build.native_stepper import NativeStepper

    model = make_model(presets.load("li2021_two_stage"), "quasi-static", "torque")
    u = (0.0, load)
    x = model.initial_state(u)
    eng = NativeStepper(model, rtol=tol, atol=1e-2 * tol, stepper="closed_form")
    py = make_stepper("closed_form", model, **tuned_stepper_options("closed_form", tol, 1e-2 * tol))
    xp = x
    for i in range(n_steps):
        y, _ = eng.advance(i * h, x, u, h)
        xp, _ = py.advance(i * h, xp, u, h)
        z, _ = make_stepper("radau", model, rtol=1e-12, atol=1e-14).advance(i * h, x, u, h)
        assert y == xp, i
        assert abs(y[1] - z[1]) <= tol * abs(z[1]) + 1e-2 * tol, (i, y[1], z[1])
        x = y
    # the pulling load back-drives the screw (positive speed), the pushing one reverses it
    assert (x[1] > 0.0) == (load < 0.0)
