"""The native FMU's outputs in initialization mode: the model of the preview is kept until the
parameters change (prsm_fmi2.c, preview_model), and what it gives equals a fresh instance's.

tests/fmi_preview_host.c drives one instance with seeded random parameter sets (good and bad
values, tiny changes of 1e-12 that must still count), fidelity changes (auto's start level
depends on the inputs too), input sets, FMU states got and set back and fmi2Reset, and after each
call compares every Real output, read in one fmi2GetReal and one alone, with a fresh instance
given the same values.  It runs under AddressSanitizer and UndefinedBehaviorSanitizer (the
preview's model is freed with the instance: the leak check), and under valgrind where it is
installed.  Skipped, with the reason, where gcc or the sanitizers' runtimes are missing.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_bad_inputs import (  # noqa: E402
    fmu_sources, run_sanitized, skip_without_sanitizers)
from test_native_fmu import native  # noqa: E402,F401 - fixture

HOST = Path(__file__).resolve().parent / "fmi_preview_host.c"

#: seed, rounds and calls per round of the sanitizer run (each call is checked: 3000 checks)
SEED, ROUNDS, CALLS = 12, 60, 50


def _arguments(fmu: Path, seed: int, rounds: int, calls: int) -> list[str]:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    params = [v for v in md.modelVariables if v.causality == "parameter"]
    assert not [v for v in params if v.type == "String"]   # the host sets no String

    def listed(vrs):
        return [str(len(vrs)), *map(str, vrs)]

    vr = {v.name: v.valueReference for v in md.modelVariables}
    return [str(seed), str(rounds), str(calls),
            *listed([v.valueReference for v in params if v.type == "Real"]),
            *listed([v.valueReference for v in params if v.type in ("Integer", "Enumeration")]),
            *listed([v.valueReference for v in params if v.type == "Boolean"]),
            *listed([v.valueReference for v in md.modelVariables
                     if v.causality == "output" and v.type == "Real"]),
            str(vr["screw_torque"]), str(vr["load_force"]), str(vr["fidelity"]), md.guid]


def _counts(stdout: str) -> tuple[int, int, int]:
    m = re.search(r"checks (\d+) finite (\d+) mismatches (\d+)", stdout)
    assert m, stdout[-2000:]
    return int(m.group(1)), int(m.group(2)), int(m.group(3))


def test_kept_preview_model_equals_a_fresh_instance_under_sanitizers(native, tmp_path):
    """60 rounds of 50 random calls (seed 12): 3060 checks of all 31 Real outputs (and one
    alone) against a fresh instance, every one equal; most with finite outputs (a model
    built), some with NaN in both (parameters it refuses)."""
    skip_without_sanitizers(tmp_path)
    fmu = native["PRSM2"]
    sources = fmu_sources(fmu, tmp_path)
    p = subprocess.run(["gcc", "-std=c99", "-g", "-O1", "-fsanitize=address,undefined",
                        "-fno-sanitize-recover=undefined", "-ffp-contract=off",
                        f"-I{tmp_path}", *sources, str(HOST), "-o", str(tmp_path / "host"),
                        "-lm"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    run = run_sanitized([str(tmp_path / "host"), *_arguments(fmu, SEED, ROUNDS, CALLS)])
    print(f"  preview host under sanitizers, seed {SEED}: {run.stdout.strip()[-300:]}")
    checks, finite, mismatches = _counts(run.stdout)
    assert checks == ROUNDS * (CALLS + 1) and mismatches == 0
    # both kinds of parameter set were tried: models built and models refused
    assert checks // 4 < finite < checks, (checks, finite)


def test_kept_preview_model_under_valgrind(native, tmp_path):
    """The same host, built without sanitizers, under valgrind's memcheck: no error, no leak
    (5 rounds of 30 calls, seed 13: 155 checks)."""
    if sys.platform != "linux" or shutil.which("valgrind") is None or shutil.which("gcc") is None:
        pytest.skip("valgrind or gcc is not installed")
    fmu = native["PRSM2"]
    sources = fmu_sources(fmu, tmp_path)
    p = subprocess.run(["gcc", "-std=c99", "-g", "-O1", "-ffp-contract=off", f"-I{tmp_path}",
                        *sources, str(HOST), "-o", str(tmp_path / "host"), "-lm"],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    run = subprocess.run(["valgrind", "--error-exitcode=99", "--leak-check=full",
                          "--errors-for-leak-kinds=definite,indirect,possible",
                          str(tmp_path / "host"), *_arguments(fmu, 13, 5, 30)],
                         capture_output=True, text=True, timeout=600)
    print(f"  preview host under valgrind, seed 13: {run.stdout.strip()[-300:]}")
    assert run.returncode == 0, run.stderr[-3000:]
    checks, _, mismatches = _counts(run.stdout)
    assert checks == 5 * 31 and mismatches == 0
