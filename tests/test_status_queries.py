"""Status queries after a refused call: the pythonfmu FMU answers as the native FMU does.

docs/fmu.md's error table: every refusal leaves the state as it was, so
``fmi2GetBooleanStatus(fmi2Terminated)`` answers fmi2OK and false after a refused ``doStep``
(a retry with other inputs, another step or another state may succeed), and true after
``fmi2Terminate`` and after the same ``doStep`` (time, step size, inputs) was refused twice in a
row (a deterministic FMU cannot take it; hosts that retry unchanged then stop).  pythonfmu 0.7's
own library answers true from the first refused step on; the FMU's binary is a wrapper that
answers the queries itself (fmu_build/status_wrapper.py).  Expected answers are the table's,
written out below, not either FMU's output; the two FMUs must also agree with each other.
"""

from __future__ import annotations

import ctypes
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import DISCARD, OK, Host, built_fmus  # noqa: E402
from test_native_fmu import ERROR, native, native_host  # noqa: E402,F401 - fixture
from test_native_guards import _terminated  # noqa: E402

NAN = float("nan")
#: the table's answer (status, fmi2Terminated) while a retry may succeed, and once it cannot
GOES_ON, STOPS = (OK, 0), (OK, 1)
H_STEP = 1e-3                 # communication step [s]


def both(**kw) -> dict[str, Host]:
    """The pythonfmu and the native PRSM2, initialized with the same start values."""
    return {"pythonfmu": Host("PRSM2", **kw), "native": native_host("PRSM2", **kw)}


def free(hosts: dict[str, Host]) -> None:
    for h in hosts.values():
        h.fmu.freeInstance()


#: (case, start values, the refused call (t, h), the inputs set before it, a call that succeeds)
#: the failed integration: the dynamic level spinning up from rest under 15 N.m starts with
#: internal steps of ~1e-9 s (its error control at the carriers' spin-up), so max_substeps = 10
#: cover a few 1e-9 s: 0.1 s is refused, 1e-9 s taken
CASES = [
    ("step size", {}, (0.0, -1.0), {}, (0.0, 1e-3)),
    ("NaN input", {}, (0.0, 1e-3), {"screw_torque": NAN}, (0.0, 1e-3)),
    ("failed integration", {"fidelity": "dynamic", "max_substeps": 10, "screw_torque": 15.0},
     (0.0, 0.1), {}, (0.0, 1e-9)),
]


@pytest.mark.parametrize("case,start,refused,inputs,good", CASES, ids=[c[0] for c in CASES])
def test_after_a_refused_step_both_fmus_answer_as_the_error_table(native, case, start, refused,
                                                                    inputs, good):
    hosts = both(start=start)
    got: dict[str, list] = {}
    try:
        for kind, h in hosts.items():
            h.set(inputs)
            answers = [h.step(*refused), _terminated(h)]        # refused once: may go on
            answers += [h.step(*refused), _terminated(h)]       # the same call again: cannot
            h.set({"screw_torque": 0.0} if "screw_torque" in inputs else {})
            answers += [h.step(*good), _terminated(h)]          # another call succeeds
            h.fmu.terminate()
            answers.append(_terminated(h))
            got[kind] = answers
    finally:
        free(hosts)
    want = [DISCARD, GOES_ON, DISCARD, STOPS, OK, GOES_ON, STOPS]
    for kind, answers in got.items():
        print(f"  {case}, {kind}: {answers}")
    assert got["pythonfmu"] == want and got["native"] == want


def test_a_changed_input_or_a_restored_state_lets_a_refused_call_go_on(native):
    """Two refusals in a row make fmi2Terminated true only for the same call: with an input
    changed between them, or a state restored, it stays false."""
    hosts = both()
    got: dict[str, list] = {}
    try:
        for kind, h in hosts.items():
            state = h.fmu.getFMUstate()
            h.set({"screw_torque": NAN})
            answers = [h.step(0.0, H_STEP), _terminated(h)]
            h.set({"screw_torque": float("inf")})               # another input: another call
            answers += [h.step(0.0, H_STEP), _terminated(h)]
            h.fmu.setFMUstate(state)                            # another state (inputs 0 again)
            h.set({"screw_torque": float("inf")})
            answers += [h.step(0.0, H_STEP), _terminated(h)]
            h.fmu.freeFMUstate(state)
            got[kind] = answers
    finally:
        free(hosts)
    want = [DISCARD, GOES_ON, DISCARD, GOES_ON, DISCARD, GOES_ON]
    print(f"  {got}")
    assert got["pythonfmu"] == want and got["native"] == want



def _halving_master(h: Host, stop: float, h0: float) -> tuple[float, int, bool]:
    """An fmusim-like master: on fmi2Discard it asks fmi2Terminated and, while false, retries
    from the same time with half the step; (time reached, refusals, stopped by the FMU)."""
    t, step, refusals = 0.0, h0, 0
    while stop - t > 1e-12 and step > 1e-12:
        if h.step(t, step) == OK:
            t += step
            step = min(2.0 * step, stop - t)
            continue
        refusals += 1
        if _terminated(h) != GOES_ON:
            return t, refusals, True
        step /= 2.0
    return t, refusals, False


def _raw_pythonfmu(tmp: Path) -> Path | None:
    """PRSM2.fmu with pythonfmu's own library as its binary (the FMU before the wrapper), or
    None where it has no wrapped linux64 binary (pythonfmu's library beside the wrapper)."""
    raw = tmp / "PRSM2.fmu"
    with zipfile.ZipFile(built_fmus()["PRSM2"]) as z, zipfile.ZipFile(raw, "w") as dst:
        names = z.namelist()
        if "binaries/linux64/pythonfmu-export.so" not in names:
            return None
        for n in names:
            data = z.read(n)
            dst.writestr(n, z.read("binaries/linux64/pythonfmu-export.so")
                         if n == "binaries/linux64/PRSM2.so" else data)
    return raw


def test_a_master_that_halves_refused_steps_reaches_the_stop_time_with_both_fmus(native, tmp_path):
    """From rest under 15 N.m with max_substeps = 10 the dynamic level cannot take 0.1 s in one
    step; a master that halves refused steps while fmi2Terminated is false must reach 0.01 s
    with both FMUs, after the same refusals.  pythonfmu's own library (the FMU before the
    wrapper) answers true at the first refusal, so the same master stops at t = 0."""
    start = {"fidelity": "dynamic", "max_substeps": 10, "screw_torque": 15.0}
    hosts = both(start=start)
    try:
        runs = {kind: _halving_master(h, 0.01, 0.1) for kind, h in hosts.items()}
    finally:
        free(hosts)
    print(f"  (time reached [s], refusals, stopped by the FMU): {runs}")
    for t, refusals, stopped in runs.values():
        assert abs(t - 0.01) <= 1e-12 and refusals > 0 and not stopped
    assert runs["pythonfmu"] == runs["native"]
    raw = _raw_pythonfmu(tmp_path)
    assert raw is not None, "the FMU's linux64 binary is not the status wrapper"
    h = Host("PRSM2", path=raw, start=start)
    try:
        t, refusals, stopped = _halving_master(h, 0.01, 0.1)
    finally:
        h.fmu.freeInstance()
    print(f"  pythonfmu's own library: t = {t} s, {refusals} refusal(s), stopped {stopped}")
    assert (t, refusals, stopped) == (0.0, 1, True)


def test_a_refused_initialization_reads_as_able_to_go_on_until_the_same_step_is_refused_again(native):
    """tolerance = 1 is out of [1e-12, 0.1].  The native FMU refuses fmi2ExitInitializationMode
    (fmi2Error) and stays in initialization mode, where the parameter can be corrected; the
    pythonfmu FMU can only refuse at fmi2DoStep (docs/fmu.md, Errors): fmi2Discard, and
    fmi2Terminated false after the first refusal and true after the same step again (it cannot
    go on until fmi2Reset).  Both answer (fmi2OK, false) before any retry."""
    from fmpy.fmi1 import FMICallException

    py = Host("PRSM2", start={"tolerance": 1.0})
    nat = native_host("PRSM2", start={"tolerance": 1.0}, initialize=False)
    try:
        with pytest.raises(FMICallException) as refused:
            nat.fmu.exitInitializationMode()
        nat_answers = [refused.value.status, _terminated(nat)]
        nat.set({"tolerance": 1e-6})                  # corrected in initialization mode
        nat.fmu.exitInitializationMode()
        nat_answers += [nat.step(0.0, H_STEP), _terminated(nat)]
        py_answers = [py.step(0.0, H_STEP), _terminated(py), py.step(0.0, H_STEP), _terminated(py)]
        py.fmu.reset()                                # a fresh instance with valid start values
        py.fmu.setupExperiment(startTime=0.0)
        py.fmu.enterInitializationMode()
        py.fmu.exitInitializationMode()
        py_answers += [py.step(0.0, H_STEP), _terminated(py)]
    finally:
        py.fmu.freeInstance()
        nat.fmu.freeInstance()
    print(f"  native: {nat_answers}; pythonfmu: {py_answers}")
    assert nat_answers == [ERROR, GOES_ON, OK, GOES_ON]
    assert py_answers == [DISCARD, GOES_ON, DISCARD, STOPS, OK, GOES_ON]


def test_other_status_queries_are_answered_alike(native):
    """fmi2GetStatus: fmi2Discard (doStep never runs asynchronously); fmi2GetBooleanStatus of
    another kind (fmi2DoStepStatus = 0): fmi2Discard, nothing written."""
    hosts = both()
    got = {}
    try:
        for kind, h in hosts.items():
            c = ctypes.c_void_p(h.fmu.component)
            s, b = ctypes.c_int(7), ctypes.c_int(7)
            got[kind] = (h.fmu.dll.fmi2GetStatus(c, 0, ctypes.byref(s)), s.value,
                         h.fmu.dll.fmi2GetBooleanStatus(c, 0, ctypes.byref(b)), b.value)
    finally:
        free(hosts)
    print(f"  {got}")
    assert got["pythonfmu"] == got["native"] == (DISCARD, 7, DISCARD, 7)


def _restore(h: Host, state, how: str) -> int:
    """Restore ``state`` as made (``"handle"``) or through its bytes (``"bytes"``); the status."""
    from fmpy.fmi1 import FMICallException
    try:
        if how == "handle":
            h.fmu.setFMUstate(state)
        else:
            copy = h.fmu.deSerializeFMUstate(h.fmu.serializeFMUstate(state))
            try:
                h.fmu.setFMUstate(copy)
            finally:
                h.fmu.freeFMUstate(copy)
    except FMICallException as exc:
        return exc.status
    return OK


@pytest.mark.parametrize("how", ["handle", "bytes"])
def test_a_state_restored_after_terminate_brings_its_phase_back(native, how):
    """A state taken while stepping and restored after fmi2Terminate answers fmi2Terminated
    false and steps again; one taken after fmi2Terminate answers true (the native FMU and the
    Python slave both restore the phase with the state: the error table's "true after
    fmi2Terminate" holds for the phase the FMU is in).  Before, the pythonfmu FMU's binary kept
    answering true after such a restore while the native FMU answered false.  ``bytes``: the
    state serialized and read back (the binary reads the phase from the bytes)."""
    hosts = both()
    got: dict[str, list] = {}
    try:
        for kind, h in hosts.items():
            assert h.step(0.0, H_STEP) == OK
            stepping = h.fmu.getFMUstate()
            h.fmu.terminate()
            answers = [_terminated(h)]                          # terminated: true
            terminated = h.fmu.getFMUstate()
            answers += [_restore(h, stepping, how), _terminated(h)]  # stepping again: false
            answers.append(h.step(H_STEP, H_STEP))              # ... and it steps
            h.fmu.terminate()
            answers.append(_terminated(h))                      # terminated again: true
            answers += [_restore(h, stepping, how), _terminated(h),
                        _restore(h, terminated, how), _terminated(h)]   # the terminated state
            h.fmu.freeFMUstate(stepping)
            h.fmu.freeFMUstate(terminated)
            got[kind] = answers
    finally:
        free(hosts)
    want = [STOPS, OK, GOES_ON, OK, STOPS, OK, GOES_ON, OK, STOPS]
    for kind, answers in got.items():
        print(f"  restored by {how}, {kind}: {answers}")
    assert got["pythonfmu"] == want and got["native"] == want


#: reads the phase of serialized states with the wrapper's own function (its source included):
#: argv: files of states; prints each one's phase, then, for the first, the phases of all its
#: truncations and of seeded random mutations (1-4 bytes each) as counts per answer
_PHASE_HOST = r"""
#include PRSM_WRAPPER
static unsigned char buf[1 << 20];
int main(int argc, char **argv) {
    size_t len = 0;
    for (int k = 1; k < argc; k++) {
        FILE *f = fopen(argv[k], "rb");
        size_t n = fread(buf, 1, sizeof buf, f);
        fclose(f);
        printf("%d ", serialized_phase(buf, n));
        if (k == 1) len = n;
    }
    FILE *f = fopen(argv[1], "rb");
    len = fread(buf, 1, sizeof buf, f);
    fclose(f);
    int counts[6] = {0};
    for (size_t n = 0; n <= len; n++) {                 /* every truncation, on the heap */
        unsigned char *d = malloc(n ? n : 1);
        memcpy(d, buf, n);
        counts[serialized_phase(d, n) + 1]++;
        free(d);
    }
    srand(11);
    for (int r = 0; r < 50000; r++) {
        unsigned char *d = malloc(len);
        memcpy(d, buf, len);
        for (int j = 0; j <= r % 4; j++) d[rand() % len] = (unsigned char)rand();
        counts[serialized_phase(d, len) + 1]++;
        free(d);
    }
    printf("| %zu truncations + 50000 mutations:", len + 1);
    for (int k = 0; k < 5; k++) printf(" %d", counts[k]);
    printf("\n");
    return 0;
}
"""


def test_the_wrapper_reads_the_phase_of_serialized_states_and_survives_bad_bytes(native,
                                                                                 tmp_path):
    """The wrapper's reader of a serialized state's phase (serialized_phase), compiled under
    AddressSanitizer and UndefinedBehaviorSanitizer: the states of the pythonfmu FMU taken
    while stepping and after fmi2Terminate read as the wrapper's phases 2 and 3 (its enum:
    instantiated 0, initialization 1, stepping 2, terminated 3); every truncation of the first
    and 50000 seeded random mutations (seed 11) give an answer in -1..3 without a sanitizer
    report."""
    import shutil
    import subprocess
    import sys
    if sys.platform != "linux" or shutil.which("gcc") is None:
        pytest.skip("needs gcc on Linux")
    from test_bad_inputs import _sanitizers_work
    why = _sanitizers_work(tmp_path)
    if why:
        pytest.skip(why)
    h = Host("PRSM2")
    try:
        assert h.step(0.0, H_STEP) == OK
        (tmp_path / "stepping.bin").write_bytes(h.state_bytes())
        h.fmu.terminate()
        (tmp_path / "terminated.bin").write_bytes(h.state_bytes())
    finally:
        h.fmu.freeInstance()
    with zipfile.ZipFile(native["PRSM2"]) as z:            # fmi2Functions.h and its includes
        for name in z.namelist():
            if name.startswith("sources/") and name.endswith(".h"):
                (tmp_path / Path(name).name).write_bytes(z.read(name))
    wrapper = Path(__file__).resolve().parents[1] / "fmu_build" / "native" / \
        "prsm_status_wrapper.c"
    (tmp_path / "host.c").write_text(_PHASE_HOST)
    p = subprocess.run(["gcc", "-std=c99", "-g", "-O1", "-fsanitize=address,undefined",
                        "-fno-sanitize-recover=undefined", f"-I{tmp_path}",
                        f'-DPRSM_WRAPPER="{wrapper}"', "-DPRSM_VR_TORQUE=0", "-DPRSM_VR_LOAD=1",
                        '-DPRSM_INNER_STEM="none"', str(tmp_path / "host.c"), "-o",
                        str(tmp_path / "host"), "-ldl"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    run = subprocess.run([str(tmp_path / "host"), str(tmp_path / "stepping.bin"),
                          str(tmp_path / "terminated.bin")], capture_output=True, text=True,
                         timeout=300)
    print(f"  serialized phases (stepping, terminated): {run.stdout.strip()}")
    assert "ERROR: AddressSanitizer" not in run.stderr and "runtime error" not in run.stderr, \
        run.stderr[-3000:]
    assert run.returncode == 0
    phases, counts = run.stdout.split("|")
    assert phases.split() == ["2", "3"]
    # answers -1 (unreadable), 0, 1, 2, 3: every case gives one of them
    n = [int(x) for x in counts.split(":")[1].split()]
    assert sum(n) == int(counts.split()[0]) + 50000
