"""The native FMU as FMI 3.0 co-simulation (``<name>-native-fmi3.fmu``, built beside the FMI 2.0
one by ``python -m fmu_build --native``): what tests/test_fmi3.py does not cover.

The FMUs are the ones tests/test_native_fmu.py builds once per session.  Expected values are the
FMI 2.0 native FMU's, run by fmpy's FMI 2.0 host on the same inputs: every output, step by step,
to 1e-12 of its largest magnitude (the issue's bound), over Li et al. (2021)'s start-up at each
level and a speed reversal through zero; its variables attribute by attribute; and FMI's rules
for refused calls, with the FMI 2.0 FMU's messages for the same refusals.
"""

from __future__ import annotations

from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi3 import FMU3Slave  # noqa: E402

from test_fmu import DISCARD, OK, Host  # noqa: E402
from test_native_fmu import ERROR, all_outputs, built_native, native, native_host  # noqa: E402,F401

#: the bound of the issue: FMI 3.0 outputs equal the FMI 2.0 FMU's to 1e-12 (of each output's
#: largest magnitude over the run)
BOUND = 1e-12


@pytest.fixture(scope="module")
def fmu3(native) -> Path:
    path = native["PRSM2"].with_name("PRSM2-native-fmi3.fmu")
    assert path.is_file(), "python -m fmu_build --native builds the FMI 3.0 FMU beside the FMI 2.0 one"
    return path


class Host3(Host):
    """One instance of the FMI 3.0 FMU driven through fmpy's FMU3Slave; records every message
    (stepping and freeing as :class:`test_fmu.Host`)."""

    def __init__(self, path: Path, start: dict | None = None, initialize: bool = True) -> None:
        self.md = read_model_description(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.messages: list[tuple[int, str]] = []
        self.fmu = FMU3Slave(guid=self.md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName="prsm3")
        self.fmu.instantiate(loggingOn=True, logMessage=self._log)
        self.fmu.enterInitializationMode(startTime=0.0)
        self.set(start or {})
        if initialize:
            self.fmu.exitInitializationMode()

    def _log(self, env, status, category, message) -> None:
        self.messages.append((status, message.decode("utf-8")))

    def _access(self, name: str, what: str):
        v = self.vars[name]
        kind = {"Float64": "Float64", "Int32": "Int32", "Enumeration": "Int64",
                "Boolean": "Boolean", "String": "String"}[v.type]
        return v, getattr(self.fmu, f"{what}{kind}")

    def set(self, values: dict) -> None:
        for name, value in values.items():
            v, setter = self._access(name, "set")
            if v.type == "Enumeration" and isinstance(value, str):
                value = {i.name: int(i.value) for i in v.declaredType.items}[value]
            setter([v.valueReference], [value])

    def get(self, names) -> list:
        out = []
        for name in names:
            v, getter = self._access(name, "get")
            value = getter([v.valueReference])[0]
            out.append(value.decode("utf-8") if isinstance(value, bytes) else value)
        return out

    def state_bytes(self) -> bytes:
        s = self.fmu.getFMUState()
        try:
            return bytes(self.fmu.serializeFMUState(s))
        finally:
            self.fmu.freeFMUState(s)


def test_model_description_has_the_fmi2_variables_attribute_by_attribute(fmu3):
    # (fmpy validate: tests/test_fmi3.py)
    md2 = read_model_description(str(built_native()["PRSM2"]))
    md3 = read_model_description(str(fmu3))
    assert md3.fmiVersion == "3.0" and md3.coSimulation is not None
    assert md3.guid == md2.guid           # the instantiation token is the FMI 2.0 GUID
    v2 = {v.name: v for v in md2.modelVariables}
    v3 = {v.name: v for v in md3.modelVariables}
    # the variables FMI 3.0 adds: its independent variable and local ones (the event indicators
    # FMI 3.0 lists by variable); nothing of FMI 2.0's is missing
    assert set(v2) <= set(v3) and "time" in set(v3) - set(v2)
    assert v3["time"].causality == "independent"
    assert all(v3[n].causality == "local" for n in set(v3) - set(v2) - {"time"})
    assert "stage[1].contact_force" in v3 and "stage[2].carrier_speed_ratio" in v3
    type3 = {"Real": "Float64", "Integer": "Int32", "Enumeration": "Enumeration",
             "Boolean": "Boolean", "String": "String"}
    for name, a in v2.items():
        b = v3[name]
        assert (b.valueReference, b.causality, b.variability, b.initial, b.unit, b.description) \
            == (a.valueReference, a.causality, a.variability, a.initial, a.unit, a.description), name
        assert b.type == type3[a.type], name
        if a.type == "Real" and a.start is not None:
            assert float(b.start) == float(a.start), name
        elif a.start is not None:
            assert str(b.start).lower() == str(a.start).lower(), name
        if a.type == "Enumeration":
            assert [(i.name, int(i.value)) for i in b.declaredType.items] \
                == [(i.name, int(i.value)) for i in a.declaredType.items], name
    out2 = sorted(u.variable.name for u in md2.outputs)
    assert sorted(u.variable.name for u in md3.outputs) == out2 and len(out2) > 20


# ---- the same results as the FMI 2.0 FMU ------------------------------------------------------------

#: Li et al. (2021) §3.1 start-up: the screw at 100 rad/s, carriers at rest, 5 kN on the rod,
#: 0-1 ms in steps of 10 µs; the torque held at 19 N.m, near the steady torque at the
#: quasi-static level (19.2 N.m, from the screw acceleration at 0 and 1 N.m: the screw keeps
#: turning at about 100 rad/s)
STARTUP = {"initial_screw_speed": 100.0, "initial_carrier_equilibrium": False}


def _startup(host, n: int = 100, h: float = 1e-5) -> list[list[float]]:
    names = [v for v in all_outputs(host) if host.vars[v].type in ("Real", "Float64")]
    rows = []
    for k in range(n):
        host.set({"screw_torque": 19.0, "load_force": 5000.0})
        assert host.step(k * h, h) == OK, host.messages
        rows.append(host.get(names))
    return rows, names


def _reversal(host, n: int = 300, h: float = 1e-3) -> list[list[float]]:
    """The PI speed loop of tests/test_native_fmu.py (reference 100 -> -60 rad/s at step 150,
    3 kN): the screw reverses through zero speed and the friction band."""
    names = [v for v in all_outputs(host) if host.vars[v].type in ("Real", "Float64")]
    integral, speed, rows = 0.0, host.get(["screw_speed"])[0], []
    for k in range(n):
        err = (100.0 if k < 150 else -60.0) - speed
        integral += err * h
        host.set({"screw_torque": min(40.0, max(-40.0, 0.05 * err + 2.0 * integral)),
                  "load_force": 3000.0})
        assert host.step(k * h, h) == OK, host.messages
        rows.append(host.get(names))
        speed = host.get(["screw_speed"])[0]
    return rows, names


SCENARIOS = [("startup", "kinematic"), ("startup", "quasi-static"), ("startup", "dynamic"),
             ("reversal", "quasi-static"), ("reversal", "dynamic"), ("reversal", "auto")]


@pytest.mark.parametrize("scenario,fidelity", SCENARIOS)
def test_fmi3_runs_equal_the_fmi2_fmu(fmu3, scenario, fidelity):
    start = {"fidelity": fidelity, **(STARTUP if scenario == "startup" else {})}
    run = _startup if scenario == "startup" else _reversal
    results = []
    for host in (native_host("PRSM2", start=start), Host3(fmu3, start=start)):
        try:
            results.append(run(host))
        finally:
            host.free()
    (rows2, names), (rows3, names3) = results
    assert names3 == names and len(rows3) == len(rows2) > 0
    worst_rel = 0.0
    print(f"\n{scenario} at {fidelity}: {len(rows2)} steps, {len(names)} outputs; "
          "max |FMI 3.0 - FMI 2.0| per output (abs, rel to the output's max |value|):")
    for j, name in enumerate(names):
        ref = max(abs(r[j]) for r in rows2)
        diff = max(abs(a[j] - b[j]) for a, b in zip(rows3, rows2))
        rel = diff / ref if ref > 0.0 else diff
        worst_rel = max(worst_rel, rel)
        print(f"  {name:40s} abs {diff:.3e}  rel {rel:.3e}")
    print(f"  worst rel {worst_rel:.3e} (bound {BOUND:g})")
    assert worst_rel <= BOUND
    speed = [r[names.index("screw_speed")] for r in rows2]
    if scenario == "reversal":
        assert min(speed) < -50.0 < 90.0 < max(speed)           # it did reverse
    else:
        # still turning forward near 100 rad/s (at the dynamic level the carriers spinning up
        # from rest slow the screw: 92 rad/s at its lowest)
        assert 80.0 < min(speed) and max(speed) < 110.0
    if (scenario, fidelity) == ("startup", "dynamic"):
        ratio = [r[names.index("stage[1].carrier_speed_ratio")] for r in rows2]
        assert abs(ratio[-1] - ratio[0]) > 0.1                   # the carriers did spin up


# ---- refusals: as the FMI 2.0 FMU's ---------------------------------------------------------------

def _last(host) -> str:
    return host.messages[-1][1] if host.messages else ""


def test_refused_step_is_discarded_logged_and_changes_nothing(fmu3):
    h = 1e-3
    host2, host3 = native_host("PRSM2"), Host3(fmu3)
    try:
        names = [v for v in all_outputs(host2) if host2.vars[v].type == "Real"]
        for k in range(20):
            for host in (host2, host3):
                host.set({"screw_torque": 5.0, "load_force": 3000.0})
                assert host.step(k * h, h) == OK
        before, y0 = host3.state_bytes(), host3.get(names)
        assert host3.get(["time"]) == [pytest.approx(20 * h, rel=1e-15)]
        for host in (host2, host3):
            host.set({"screw_torque": float("nan")})
            assert host.step(20 * h, h) == DISCARD
        assert "screw_torque" in _last(host3) and host3.messages[-1][0] == DISCARD
        assert _last(host3) == _last(host2)          # the FMI 2.0 FMU's message, word for word
        for host in (host2, host3):
            host.set({"screw_torque": 5.0})
            assert host.step(20 * h, 0.0) == DISCARD
        assert "step size" in _last(host3) and _last(host3) == _last(host2)
        assert host3.step(21 * h, h) == ERROR and "currentCommunicationPoint" in _last(host3)
        assert host3.get(names) == y0 and host3.state_bytes() == before
        # lastSuccessfulTime after a refused step: the FMU's time, unchanged
        with pytest.raises(FMICallException) as exc:
            host3.fmu.doStep(20 * h, float("inf"))
        assert exc.value.status == DISCARD
        assert host3.state_bytes() == before
        assert host3.step(20 * h, h) == OK              # and it goes on from there
    finally:
        host2.free()
        host3.free()


def _gap(reason: str):
    """A refusal prsm_fmi3.c does not yet make as FMI 3.0 and the project's rules ask (strict:
    the test fails once it does, so that the mark is removed)."""
    return pytest.mark.xfail(strict=True, reason=reason)


#: (call on the FMU, a word its one logged line must hold); each must be refused with fmi3Error
#: and change nothing
WRONG_CALLS = [
    pytest.param(lambda f, v: f.getInt32([v["step_fidelity"].valueReference]), "step_fidelity",
                 id="getInt32-of-an-Enumeration",
                 marks=_gap("fmi3GetInt32 reads an Enumeration; FMI 3.0 reads one with "
                            "fmi3GetInt64 only")),
    pytest.param(lambda f, v: f.getInt64([v["step_substeps"].valueReference]), "step_substeps",
                 id="getInt64-of-an-Int32",
                 marks=_gap("fmi3GetInt64 reads an Int32 variable; FMI 3.0 reads one with "
                            "fmi3GetInt32 only")),
    pytest.param(lambda f, v: f.getFloat64([v["step_substeps"].valueReference]), "step_substeps",
                 id="getFloat64-of-an-Int32"),
    pytest.param(lambda f, v: f.setFloat64([v["screw_speed"].valueReference], [1.0]),
                 "screw_speed", id="set-an-output"),
    pytest.param(lambda f, v: f.setFloat64([v["stage[1].screw_lead"].valueReference], [0.02]),
                 "stage[1].screw_lead", id="set-a-geometry-parameter-after-initialization"),
    pytest.param(lambda f, v: f.setFloat64([v["mu_screw_roller"].valueReference], [0.1]),
                 "mu_screw_roller", id="set-a-parameter-after-initialization"),
    pytest.param(lambda f, v: f.setFloat64([v["time"].valueReference], [1.0]), "time",
                 id="set-time",
                 marks=_gap("the message says 'value reference N is no variable' without "
                            "naming time")),
    pytest.param(lambda f, v: f.setInt64([v["fidelity"].valueReference], [2 ** 40]), "fidelity",
                 id="setInt64-out-of-32-bits",
                 marks=_gap("the message names the value reference, not the variable")),
    pytest.param(lambda f, v: f.getFloat64([10 ** 6]), "1000000", id="no-such-value-reference"),
    pytest.param(lambda f, v: f.enterEventMode(), "fmi3EnterEventMode", id="enterEventMode"),
]


@pytest.mark.parametrize("call,word", WRONG_CALLS)
def test_a_call_of_the_wrong_type_or_not_allowed_is_an_error_naming_the_variable(fmu3, call, word):
    host = Host3(fmu3)
    try:
        before, n = host.state_bytes(), len(host.messages)
        with pytest.raises(FMICallException) as exc:
            call(host.fmu, host.vars)
        assert exc.value.status == ERROR and len(host.messages) == n + 1
        assert host.messages[-1][0] == ERROR and word in _last(host), _last(host)
        assert host.state_bytes() == before
    finally:
        host.free()


@pytest.mark.parametrize("start,word", [({"fidelity": "auto", "stepper": "closed_form"},
                                         "stepper"),
                                        ({"stepper": "exponential"}, "stepper"),
                                        ({"stage[2].nut_mass": -1.0}, "stage[2].nut_mass")])
def test_initialization_refuses_what_the_fmi2_fmu_refuses(fmu3, start, word):
    messages = []
    for host in (native_host("PRSM2", start=start, initialize=False),
                 Host3(fmu3, start=start, initialize=False)):
        with pytest.raises(FMICallException) as exc:
            host.fmu.exitInitializationMode()
        assert exc.value.status == ERROR and host.messages[-1][0] == ERROR
        messages.append(_last(host))
        host.fmu.freeInstance()
    assert word in messages[1] and messages[1].startswith("initialization failed")
    assert messages[1] == messages[0]                  # the FMI 2.0 FMU's message, word for word


def test_fmu_state_round_trip_is_bit_exact(fmu3):
    h = 1e-3
    host = Host3(fmu3, start={"fidelity": "dynamic"})
    try:
        names = [n for n in all_outputs(host) if host.vars[n].type == "Float64"]
        for k in range(10):
            host.set({"screw_torque": 5.0, "load_force": 3000.0})
            assert host.step(k * h, h) == OK
        saved = host.fmu.getFMUState()
        data = bytes(host.fmu.serializeFMUState(saved))
        ahead = []
        for k in range(10, 15):
            assert host.step(k * h, h) == OK
            ahead.append(host.get(names))
        host.fmu.setFMUState(host.fmu.deserializeFMUState(data))
        again = []
        for k in range(10, 15):
            assert host.step(k * h, h) == OK
            again.append(host.get(names))
        assert again == ahead                          # bit for bit: same state, same steps
        host.fmu.freeFMUState(saved)
        with pytest.raises(FMICallException):          # damaged bytes: refused, logged
            host.fmu.deserializeFMUState(data[:-1])
        assert host.messages[-1][0] == ERROR and "not a serialized state" in _last(host)
    finally:
        host.free()

