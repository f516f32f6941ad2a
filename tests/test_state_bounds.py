"""Crafted FMU states against both FMUs: the speeds' bounds follow from the kinetic energy.

docs/fmu.md (bounds of the state): a state is accepted only if its kinetic energy cannot exceed
1e150 J (the work integrals' bound): each of the n speed states i is bounded by the speed at
which its own kinetic energy is 1e150/n J, so that the kinetic energy of any state within the
bounds is at most 1e150 J; every output of an accepted state is finite (``efficiency`` may be
NaN where no power passes).  Checked here, on PRSM2 at the dynamic level (7 states: the angle,
the screw's and two carriers' speeds, three work integrals), in both FMUs with the same
crafted state vectors:

* the bound the refusal names is where it says: the speed at the named bound is accepted, the
  next double above it refused;
* all speeds at their named bounds: accepted, and the FMU's ``kinetic_energy`` output is
  1e150 J (n times 1e150/n J) to rounding; no accepted state reads more;
* seeded random states (values from a pool of huge, tiny, subnormal and bound-adjacent values
  put into the state vector; the count is printed): both FMUs give the same verdict with the
  same message, and an accepted state has finite outputs, as has a step from it unless that
  step is refused.

The native FMU's state is its C struct: the state vector is found in its bytes as the doubles
the Python FMU's state holds (both FMUs run the same steps bit for bit; its first copy).
"""

from __future__ import annotations

import math
import random
from collections import Counter
import re
import struct

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy.fmi1 import FMICallException  # noqa: E402

from test_bad_inputs import _all_finite, _framed, _state  # noqa: E402
from test_fmu import OK, Host, run_fmu  # noqa: E402
from test_native_fmu import native, native_host  # noqa: E402,F401 - fixture

E_MAX = 1e150                # [J], docs/fmu.md: the kinetic energy a state may carry at most
BOUND = re.compile(r"state x\[(\d+)\] \(speed\) = \S+ rad/s is out of range: must be in "
                   r"\[-(\S+), (\S+)\] rad/s")


class Pair:
    """The pythonfmu and the native PRSM2 at the dynamic level after the same 20 steps; each
    crafted state vector is restored into both."""

    def __init__(self) -> None:
        self.py = Host("PRSM2", "crafted", start={"fidelity": "dynamic"})
        self.nat = native_host("PRSM2", instance="crafted", start={"fidelity": "dynamic"})
        run_fmu(self.py, 20, ["screw_speed"])
        run_fmu(self.nat, 20, ["screw_speed"])
        self.magic, self.fields = _state(self.py)
        self.x = list(self.fields["x"])
        self.t = self.fields["t"]
        packed = struct.pack(f"<{len(self.x)}d", *self.x)
        self.nat_bytes = self.nat.state_bytes()
        # the first copy is the state vector (the C struct holds it before the stepper's
        # memory, which may hold the same doubles as its continuation point)
        assert packed in self.nat_bytes, "the native state vector is not found"
        self.offset = self.nat_bytes.index(packed)

    def free(self) -> None:
        self.py.free()
        self.nat.free()

    def restore(self, xs: list[float]) -> dict[str, str | None]:
        """Restore ``xs`` into both: FMU -> None (accepted) or the reason of the refusal."""
        out: dict[str, str | None] = {}
        n = len(self.py.messages)
        s = self.py.fmu.deSerializeFMUstate(_framed(self.magic, self.fields, x=tuple(xs)))
        self.py.fmu.setFMUstate(s)
        self.py.fmu.freeFMUstate(s)
        refused = [m for _, m in self.py.messages[n:] if "the state is refused" in m]
        out["pythonfmu"] = refused[0].split("nothing restored: ", 1)[1] if refused else None
        if refused:
            self.py.step(self.t)                   # the refusal is reported once
        data = bytearray(self.nat_bytes)
        data[self.offset:self.offset + 8 * len(xs)] = struct.pack(f"<{len(xs)}d", *xs)
        n = len(self.nat.messages)
        try:         # the native FMU checks the bytes already when it deserializes them
            s = self.nat.fmu.deSerializeFMUstate(bytes(data))
        except FMICallException:
            out["native"] = self.nat.messages[n:][-1][1].split("not a valid state: ", 1)[1]
            return out
        try:
            self.nat.fmu.setFMUstate(s)
            out["native"] = None
        except FMICallException:
            out["native"] = self.nat.messages[n:][-1][1].split("nothing changed: ", 1)[1]
        self.nat.fmu.freeFMUstate(s)
        return out


def _kinetic_energy(host: Host) -> float:
    return host.get_real(["kinetic_energy"])[0]


def _bounds(pair: Pair) -> dict[int, float]:
    """Speed index -> the bound the refusal of a speed of 1e308 there names (both FMUs alike)."""
    out = {}
    for i in range(1, len(pair.x) - 3):
        xs = list(pair.x)
        xs[i] = 1e308
        why = pair.restore(xs)
        assert why["pythonfmu"] == why["native"] and why["native"], why
        m = BOUND.search(why["native"])
        assert m and int(m.group(1)) == i and m.group(2) == m.group(3), why
        out[i] = float(m.group(2))
    return out


def test_the_speed_bounds_hold_the_kinetic_energy_at_most_1e150_joule(native):
    pair = Pair()
    try:
        bounds = _bounds(pair)
        print(f"  speed bounds [rad/s]: {bounds}")
        verdicts = []
        for i, b in bounds.items():
            for v, want in ((b, None), (-b, None), (math.nextafter(b, math.inf), "refused")):
                xs = list(pair.x)
                xs[i] = v
                why = pair.restore(xs)
                verdicts.append((i, v, why, want))
        xs = list(pair.x)
        for i, b in bounds.items():
            xs[i] = b
        why = pair.restore(xs)
        energies = {"pythonfmu": _kinetic_energy(pair.py), "native": _kinetic_energy(pair.nat)}
        finite = _all_finite(pair.py) and _all_finite(pair.nat)
    finally:
        pair.free()
    for i, v, got, want in verdicts:
        print(f"  x[{i}] = {v!r}: {got}")
    for i, v, got, want in verdicts:
        assert got["pythonfmu"] == got["native"], (i, v, got)
        assert (got["native"] is None) == (want is None), (i, v, got)
    print(f"  every speed at its bound: {why}; kinetic energy {energies} J")
    assert why == {"pythonfmu": None, "native": None} and finite
    # 3 speeds, each carrying 1e150/3 J: 1e150 J in all, to the rounding of three terms
    for e in energies.values():
        assert E_MAX * (1 - 1e-14) <= e <= E_MAX * (1 + 1e-14)


def test_random_crafted_states_get_the_same_verdict_and_finite_outputs_from_both_fmus(native):
    pair = Pair()
    rnd = random.Random(2026)
    verdicts = []
    try:
        bounds = _bounds(pair)
        near = [v for b in bounds.values()
                for v in (b, -b, math.nextafter(b, math.inf), b / 2.0)]
        pool = [1e308, -1e308, 1e155, 1e77, 1e76, 1e75, 1e15, -1e15, 1.0000000000000002e15,
                1e150, -1e150, 1.0000000000000002e150, 5e-324, -5e-324, 1e-200, 0.0, 1.0,
                -1e30] + near
        for k in range(80):
            xs = list(pair.x)
            for _ in range(rnd.randint(1, 4)):
                xs[rnd.randrange(len(xs))] = rnd.choice(pool)
            why = pair.restore(xs)
            verdict = "refused" if why["native"] else "accepted"
            if verdict == "accepted":
                ok = _all_finite(pair.py) and _all_finite(pair.nat) and max(
                    _kinetic_energy(pair.py), _kinetic_energy(pair.nat)) <= E_MAX * (1 + 1e-14)
                after = [h.step(pair.t) for h in (pair.py, pair.nat)]
                ok = ok and after[0] == after[1] and (after[0] != OK or (
                    _all_finite(pair.py) and _all_finite(pair.nat)))
                verdict += "" if ok else " WRONG"
            verdicts.append((xs, why, verdict))
    finally:
        pair.free()
    counts = Counter(verdict for _, _, verdict in verdicts)
    print("\n".join(f"  {verdict}: x = {xs}: {why['native']}" for xs, why, verdict in verdicts))
    print(f"  {len(verdicts)} crafted states (seed 2026): {counts['refused']} refused by both "
          f"with the same message, {counts['accepted']} accepted by both with finite outputs")
    assert all(why["pythonfmu"] == why["native"] for _, why, _ in verdicts)
    assert all(v in ("refused", "accepted") for _, _, v in verdicts)
    assert counts["refused"] > 0 and counts["accepted"] > 0 and len(verdicts) == 80
