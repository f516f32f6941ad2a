"""The bad inputs of the sweep that found accepted steps with infinite outputs, kept in the suite.

* Inputs: a screw torque of 1e155 N.m or a load of 1e155 N (accepted before, with
  ``input_power`` and ``friction_power`` infinite), a subnormal torque: both FMUs refuse the
  step, state unchanged.
* Crafted FMU states of the pythonfmu FMU: a screw speed of ±1e308, a subnormal speed (5e-324)
  with spinning carriers, a counter of 2**200 (which left a Python OverflowError pending in
  ``fmi2GetInteger``), held inputs of 1e155: each refused whole; then seeded random states
  (values from the same pool put into the state vector): each either refused or, accepted, a
  step from it whose outputs are all finite.
* The native FMU's sources under AddressSanitizer and UndefinedBehaviorSanitizer, driven by a
  seeded random C host through parameters, inputs, step sizes, communication points and FMU
  states (tests/fmi_fuzz_host.c): no sanitizer report, no non-finite output of an accepted
  step or state.  Skipped, with the reason, where gcc or its sanitizer runtimes are missing.

* Every Real parameter at its table's extremes in the native FMU: refused, or finite outputs.

``pytest -s`` prints each case's verdict and the counts.
"""

from __future__ import annotations

import math
import pickle
import random
import shutil
import subprocess
import sys
import time
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import DISCARD, OK, Host, run_fmu  # noqa: E402
from test_native_fmu import native, native_host  # noqa: E402,F401 - fixture

#: values the sweep put everywhere (huge, tiny, subnormal)
POOL = (1e308, -1e308, 1e155, -1e155, 1e30, 5e-324, -5e-324, 1e-200, 1e6, -1e6, 0.0, 1.0)


def _all_finite(host: Host) -> bool:
    """Every Real output finite; ``efficiency`` may be NaN, where no power passes through
    (docs/fmu.md, Variables: standstill |ω| <= 8.9e-12 rad/s, e.g. a crafted screw speed of
    1e-200 rad/s), never infinite."""
    return all(math.isfinite(v) or (n == "efficiency" and math.isnan(v))
               for n, v in zip(host.outputs, host.get_real(host.outputs)))


@pytest.mark.parametrize("make", [lambda: Host("PRSM2"), lambda: native_host("PRSM2")],
                         ids=["pythonfmu", "native"])
def test_huge_or_subnormal_inputs_are_refused(native, make):
    host = make()
    verdicts = []
    try:
        run_fmu(host, 3, ["screw_speed"])
        vr = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
        for u in ((1e155, 0.0), (0.0, 1e155), (-1e155, 3000.0), (5e-324, 0.0), (1e7, 0.0),
                  (0.0, -1e9)):
            host.fmu.setReal(vr, list(u))
            before = host.state_bytes()              # the state holds the inputs just set
            status = host.step(3e-3)
            ok = status == DISCARD and host.state_bytes() == before \
                and "is out of range" in host.messages[-1][1]
            verdicts.append((u, ok, host.messages[-1][1]))
        host.fmu.setReal(vr, [10.0, 3000.0])
        assert host.step(3e-3) == OK and _all_finite(host)       # and it goes on
    finally:
        host.free()
    for u, ok, msg in verdicts:
        print(f"  {'refused' if ok else 'WRONG'}: inputs {u}: {msg.split(': ', 1)[-1]}")
    assert all(ok for _, ok, _ in verdicts), verdicts


def _state(host: Host) -> tuple[bytes, dict]:
    good = host.state_bytes()
    names = ("tag", "model", "n", "par", "u", "phase", "t", "x", "u_held", "memory",
             "counters", "init_error")
    return good[:8], dict(zip(names, pickle.loads(good[8:])))


def _framed(magic: bytes, fields: dict, **changes) -> bytes:
    return magic + pickle.dumps(tuple({**fields, **changes}.values()), protocol=4)


def _try_state(host: Host, data: bytes, t: float) -> str:
    """'refused' (nothing restored) or 'finite' (accepted, a step from it all finite);
    anything else names what went wrong."""
    before = host.state_bytes()
    n = len(host.messages)
    state = host.fmu.deSerializeFMUstate(data)
    host.fmu.setFMUstate(state)
    host.fmu.freeFMUstate(state)
    if any(m.startswith("fmi2SetFMUstate: the state is refused") for _, m in host.messages[n:]):
        if host.state_bytes() != before:
            return "refused but changed"
        host.step(t)                           # the refusal is reported once, then goes on
        return "refused"
    ints = host.fmu.getInteger([host.vars["step_rhs_calls"].valueReference])
    if not (_all_finite(host) and all(-2**31 <= i < 2**31 for i in ints)):
        return "accepted with non-finite outputs"
    if host.step(t) == OK and not _all_finite(host):
        return "a step from it gave non-finite outputs"
    return "finite"


def test_crafted_states_are_refused_or_give_finite_outputs():
    host = Host("PRSM2", "crafted", start={"fidelity": "dynamic"})
    verdicts = []
    try:
        run_fmu(host, 20, ["screw_speed"])
        magic, f = _state(host)
        x = list(f["x"])
        t = f["t"]
        named = {
            "screw speed 1e308": x[:1] + [1e308] + x[2:],
            "screw speed -1e308": x[:1] + [-1e308] + x[2:],
            "subnormal screw speed, carriers spinning": x[:1] + [5e-324] + [50.0, 50.0] + x[4:],
            "input work subnormal, output work 1e10": x[:-3] + [5e-324, 1e10, 0.0],
            "work 1e300": x[:-3] + [1e300, 1e300, 0.0],
        }
        for what, xs in named.items():
            verdicts.append((what, _try_state(host, _framed(magic, f, x=tuple(xs)), t), "refused"))
        verdicts.append(("counter 2**200", _try_state(host, _framed(
            magic, f, counters=(2**200, 0, 2)), t), "refused"))
        verdicts.append(("held inputs 1e155 N.m", _try_state(host, _framed(
            magic, f, u_held=(1e155, 0.0)), t), "refused"))
        rnd = random.Random(28)
        for k in range(60):
            xs = list(x)
            for _ in range(rnd.randint(1, 3)):
                xs[rnd.randrange(len(xs))] = rnd.choice(POOL)
            verdicts.append((f"random state {k}: x = {xs}",
                             _try_state(host, _framed(magic, f, x=tuple(xs)), t), None))
    finally:
        host.free()
    for what, got, want in verdicts:
        print(f"  {got}: {what}")
    counts = {v: sum(got == v for _, got, _ in verdicts) for v in ("refused", "finite")}
    print(f"  {len(verdicts)} crafted states tried: {counts['refused']} refused whole, "
          f"{counts['finite']} accepted with finite outputs (seed 28)")
    assert all(got == want for _, got, want in verdicts if want), verdicts[:7]
    assert all(got in ("refused", "finite") for _, got, _ in verdicts)
    assert len(verdicts) == 67


def _sanitizers_work(d: Path) -> str | None:
    """None if gcc builds and runs a program with -fsanitize=address,undefined, else why not."""
    if shutil.which("gcc") is None:
        return "gcc is not installed"
    (d / "probe.c").write_text("int main(void) { return 0; }\n")
    p = subprocess.run(["gcc", "-fsanitize=address,undefined", str(d / "probe.c"), "-o",
                        str(d / "probe")], capture_output=True, text=True)
    if p.returncode != 0:
        return f"gcc cannot build with -fsanitize=address,undefined: {p.stderr.strip()[:200]}"
    if subprocess.run([str(d / "probe")], capture_output=True).returncode != 0:
        return "a program built with the sanitizers does not run here"
    return None


def skip_without_sanitizers(d: Path) -> None:
    """Skip (with the reason) where the sanitizer hosts cannot be built and run."""
    if sys.platform != "linux":
        pytest.skip("the sanitizer hosts are written for Linux")
    why = _sanitizers_work(d)
    if why:
        pytest.skip(why)


def fmu_sources(fmu: Path, where: Path) -> list[str]:
    """The native FMU's sources unpacked into ``where``; the C files it lists to compile
    (<SourceFiles> of its modelDescription)."""
    with zipfile.ZipFile(fmu) as z:
        for name in z.namelist():
            if name.startswith("sources/"):
                (where / Path(name).name).write_bytes(z.read(name))
        listed = ET.fromstring(z.read("modelDescription.xml")).find("CoSimulation/SourceFiles")
    sources = [str(where / f.get("name")) for f in listed]
    assert sources
    return sources


def run_sanitized(args: list[str]) -> subprocess.CompletedProcess:
    """Run a host built with the sanitizers (leak check on); assert it reported nothing and
    exited with 0."""
    run = subprocess.run(args, capture_output=True, text=True, timeout=600,
                         env={"ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0",
                              "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"})
    assert "ERROR: AddressSanitizer" not in run.stderr and "runtime error" not in run.stderr, \
        run.stderr[-3000:]
    assert run.returncode == 0, (run.stdout[-2000:], run.stderr[-2000:])
    return run


def test_native_sources_under_sanitizers_survive_random_calls(native, tmp_path):
    skip_without_sanitizers(tmp_path)
    from fmpy import read_model_description

    fmu = native["PRSM2"]
    sources = fmu_sources(fmu, tmp_path)
    host_c = Path(__file__).resolve().parent / "fmi_fuzz_host.c"
    p = subprocess.run(["gcc", "-std=c99", "-g", "-O0", "-fsanitize=address,undefined",
                        "-fno-sanitize-recover=undefined", "-ffp-contract=off",
                        f"-I{tmp_path}", *sources, str(host_c), "-o", str(tmp_path / "fuzz"),
                        "-lm"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    md = read_model_description(str(fmu))
    real = [v.valueReference for v in md.modelVariables
            if v.causality == "parameter" and v.type == "Real"]
    ints = [v.valueReference for v in md.modelVariables
            if v.causality == "parameter" and v.type in ("Integer", "Enumeration")]
    # every Real output must be finite, but the efficiency: NaN where no power passes through
    # (docs/fmu.md; its own tests are tests/test_efficiency_definition.py)
    outs = [v.valueReference for v in md.modelVariables
            if v.causality == "output" and v.type == "Real" and v.name != "efficiency"]
    vr = {v.name: v.valueReference for v in md.modelVariables}
    seed, rounds = 28, 5
    args = [str(tmp_path / "fuzz"), str(seed), str(rounds), str(len(real)), *map(str, real),
            str(len(ints)), *map(str, ints), str(len(outs)), *map(str, outs),
            str(vr["screw_torque"]), str(vr["load_force"]), md.guid]
    run = run_sanitized(args)
    print(f"  sanitizer host, seed {seed}: {run.stdout.strip()}")
    assert "nonfinite 0" in run.stdout


def test_crafted_native_states_are_refused_whole(native):
    """The native FMU's serialized state is its C struct: the state vector is found by the bytes
    of the screw speed it reports, and the same crafted values as above are written there; each
    state is refused by fmi2DeSerializeFMUstate (fmi2Error), nothing restored."""
    import struct

    from fmpy.fmi1 import FMICallException

    host = native_host("PRSM2", start={"fidelity": "dynamic"})
    verdicts = []
    try:
        run_fmu(host, 20, ["screw_speed"])
        good = host.state_bytes()
        speed = host.get_real(["screw_speed"])[0]
        at = good.find(struct.pack("<d", speed))
        assert at > 0 and good.count(struct.pack("<d", speed)) >= 1
        x = list(struct.unpack_from("<9d", good, at - 8))     # angle, speed, 2 carriers, 3 works, ...
        cases = {"screw speed 1e308": {1: 1e308}, "screw speed -1e308": {1: -1e308},
                 "subnormal screw speed, carriers spinning": {1: 5e-324, 2: 50.0, 3: 50.0},
                 "input work subnormal, output work 1e10": {4: 5e-324, 5: 1e10},
                 "work 1e300": {4: 1e300, 5: 1e300}}
        for what, change in cases.items():
            data = bytearray(good)
            for i, v in change.items():
                struct.pack_into("<d", data, at - 8 + 8 * i, v)
            before = host.state_bytes()
            try:
                state = host.fmu.deSerializeFMUstate(bytes(data))
                host.fmu.setFMUstate(state)
                got = "accepted"
            except FMICallException:
                got = "refused"
            verdicts.append((what, got, host.state_bytes() == before, host.messages[-1][1]))
        assert x[1] == speed
    finally:
        host.free()
    for what, got, same, msg in verdicts:
        print(f"  {got}{'' if same else ' (CHANGED)'}: {what}: {msg.split(': ', 2)[-1]}")
    assert all(got == "refused" and same for _, got, same, _ in verdicts)


def test_native_outputs_finite_at_every_real_parameters_extremes(native):
    """Every Real parameter of the table at its extremes (5e-324 for an open lower end at 0, the
    closed ends themselves, the largest double below an open upper end), quasi-static and
    dynamic, 3 steps at 15 N.m against 1 kN: each is refused at initialization or its steps'
    outputs are all finite (the native FMU only: the pythonfmu FMU's share of the same sweep,
    run once by hand, took ~30 s; both gave 0 non-finite outputs over 650 steps)."""
    from fmpy.fmi1 import FMICallException

    from prsm_fmu import presets
    from prsm_fmu.param_ranges import fmu_rules

    tried = refused = stepped = 0
    bad = []
    host = native_host("PRSM2", initialize=False)
    vr = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
    try:
        for rule in fmu_rules(presets.load("li2021_two_stage").stages):
            r = rule.range
            if r.integer or rule.when or rule.hi_parameter:
                continue
            lo = 5e-324 if r.lo_open else r.lo
            hi = math.nextafter(r.hi, -math.inf) if r.hi_open else r.hi
            for value in (lo, hi):
                for fidelity in ("quasi-static", "dynamic"):
                    tried += 1
                    host.fmu.reset()
                    host.fmu.setupExperiment(startTime=0.0)
                    host.fmu.enterInitializationMode()
                    try:
                        host.set({rule.name: value, "fidelity": fidelity})
                        host.fmu.exitInitializationMode()
                    except FMICallException:              # refused, or a constant here
                        refused += 1
                        continue
                    host.fmu.setReal(vr, [15.0, 1000.0])
                    for k in range(3):
                        if host.step(k * 1e-3) != OK:
                            break
                        stepped += 1
                        if not _all_finite(host):
                            bad.append((rule.name, value, fidelity, k))
    finally:
        host.fmu.freeInstance()
    print(f"  {tried} extreme parameter values tried: {refused} refused or constant, "
          f"{stepped} steps taken, {len(bad)} with a non-finite output")
    assert not bad, bad
    assert stepped > 100


# ---- inputs at their bounds on random mechanisms within the parameters' ranges --------------
#: the inputs' bounds as docs/fmu.md states them (Variables: bounds of the inputs): |T| <= 1e6
#: N.m, |F| <= 1e8 N, and a nonzero input at least 1e-150 in magnitude
T_MAX, F_MAX, U_MIN = 1e6, 1e8, 1e-150
#: the Li et al. (2021) two-stage mechanism's lengths [m] and its largest (the second nut's
#: radius, 27.5 mm): a scale s keeps every length within (0, 1] m while s <= 1/0.0275 = 36.4
LI_LARGEST_LENGTH = 0.0275
RANDOM_MECHANISMS = 80          # per FMU; the same seeded draws for both


def _random_mechanism(rnd: random.Random) -> dict:
    """Parameters within docs/fmu.md's ranges: every length of Li et al.'s two stages times one
    scale 10^U(-300, log10(36.4)) (the geometry's relations r_N = r_S + 2 r_R = n_S r_R hold at
    any scale), each mass in (0, 1e4] kg and inertia in (0, 1e3] kg.m2 drawn log-uniformly from
    1e-300 up, friction coefficients in [0, 1), the viscous coefficient in [0, 1e5] N.s/m, the
    differential arm in [0, 1e-3] m, the slip scale in [1e-300, 1] m/s, a random level."""
    from prsm_fmu import presets
    li = presets.load("li2021_two_stage")
    s = 10.0 ** rnd.uniform(-300.0, math.log10(1.0 / LI_LARGEST_LENGTH))
    d: dict = {}
    for k, st in enumerate(li.stages, 1):
        for f in ("screw_radius", "roller_radius", "nut_radius", "screw_lead", "spline_radius"):
            if getattr(st, f):
                d[f"stage[{k}].{f}"] = getattr(st, f) * s
        for f, top in (("screw_mass", 4), ("nut_mass", 4), ("roller_mass", 4),
                       ("carrier_mass", 4), ("screw_inertia", 3), ("roller_inertia", 3),
                       ("carrier_inertia", 3)):
            d[f"stage[{k}].{f}"] = 10.0 ** rnd.uniform(-300.0, top)
    d["stage[1].bearing_radius"] = li.stages[0].screw_radius * s
    d.update({"mu_screw_roller": rnd.random(), "mu_spline": rnd.random(),
              "mu_nut_screw": rnd.choice((0.0, rnd.random())),
              "mu_viscous": rnd.uniform(0.0, 1e5), "mu_differential": rnd.uniform(0.0, 1e-3),
              "slip_velocity_scale": 10.0 ** rnd.uniform(-300.0, 0.0),
              "fidelity": rnd.choice(("kinematic", "quasi-static", "dynamic", "auto"))})
    return d


def _inputs_at_bounds(rnd: random.Random) -> list[tuple[float, float]]:
    """Three input pairs, each component 0 or at one end of its bound, either sign."""
    def one(top: float) -> float:
        return rnd.choice((0.0, top, -top, U_MIN, -U_MIN))
    return [(one(T_MAX), one(F_MAX)) for _ in range(3)]


def inputs_at_bounds_counts(make, seed: int = 2611, n: int = RANDOM_MECHANISMS) -> dict:
    """Drive ``n`` seeded random mechanisms (:func:`_random_mechanism`) with inputs at their
    bounds, steps of 1e-6, 1e-3 and 0.1 s: counts of mechanisms refused at initialization
    (native: fmi2ExitInitializationMode; pythonfmu: its first doStep), steps refused
    (fmi2Discard with a message, state unchanged), steps taken, and ``bad``: accepted steps with
    a non-finite output or a refusal without its one-line message or with the state changed."""
    from fmpy.fmi1 import FMICallException
    rnd = random.Random(seed)
    counts = {"mechanisms": n, "init_refused": 0, "steps_refused": 0, "steps_taken": 0,
              "bad": [], "slowest_step_s": 0.0}
    for case in range(n):
        par, inputs = _random_mechanism(rnd), _inputs_at_bounds(rnd)
        host = make()
        try:
            host.set(par)
            try:
                host.fmu.exitInitializationMode()
            except FMICallException:
                counts["init_refused"] += 1
                continue
            vr = [host.vars["screw_torque"].valueReference, host.vars["load_force"].valueReference]
            t = 0.0
            for u, h in zip(inputs, (1e-6, 1e-3, 0.1)):
                host.fmu.setReal(vr, list(u))
                before = host.state_bytes()
                start = time.perf_counter()
                status = host.step(t, h)
                counts["slowest_step_s"] = max(counts["slowest_step_s"],
                                               time.perf_counter() - start)
                if status == OK:
                    t += h
                    counts["steps_taken"] += 1
                    if not _all_finite(host):
                        counts["bad"].append((case, u, h, "non-finite output"))
                elif host.state_bytes() != before or not host.messages \
                        or "refused" not in host.messages[-1][1]:
                    counts["bad"].append((case, u, h, "refusal changed the state or said nothing"))
                elif "initialization failed" in host.messages[-1][1]:
                    counts["init_refused"] += 1          # pythonfmu: a refused initialization
                    break
                else:
                    counts["steps_refused"] += 1
        finally:
            host.fmu.freeInstance()
    return counts


@pytest.mark.parametrize("kind", ["pythonfmu", "native"])
def test_inputs_at_their_bounds_on_random_mechanisms_give_finite_outputs(native, kind):
    """docs/fmu.md's claim that the inputs' constant bounds suffice: on 80 seeded random
    mechanisms within the parameters' ranges (lengths scaled over 300 decades, masses and
    inertias over ~300), inputs at the bounds (±1e6 N.m, ±1e8 N, ±1e-150, 0) never give an
    accepted step a non-finite output; a step is taken or refused whole with its message."""
    make = {"pythonfmu": Host, "native": native_host}[kind]
    c = inputs_at_bounds_counts(lambda: make("PRSM2", initialize=False))
    print(f"  {kind}: {c['mechanisms']} random mechanisms (seed 2611): {c['init_refused']} refused at "
          f"initialization, {c['steps_taken']} steps taken with finite outputs, "
          f"{c['steps_refused']} refused with a message and the state unchanged, "
          f"{len(c['bad'])} wrong; slowest doStep {c['slowest_step_s']:.3f} s")
    assert not c["bad"], c["bad"]
    assert c["steps_taken"] >= 20           # the draws reach stepping mechanisms, not only refusals
