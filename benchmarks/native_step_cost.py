"""Cost of one ``doStep`` of the native PRSM2 FMU against the pythonfmu PRSM2 FMU, same C host.

Both FMUs run the quasi-static level in the C program of tests/fmi_c_host.c (dlopen, FMI 2.0
calls, nothing else; the pythonfmu FMU gets libpython by ``LD_PRELOAD`` as docs/fmu.md
describes): a PI speed loop, 1 ms communication steps, reference 100 rad/s then -60 rad/s from
step 150 (a reversal through the friction band, then steady running), load 3000 N.  The host
measures, in separate runs, the monotonic-clock time of each ``fmi2DoStep`` call (the clock's
own cost, ~20 ns, is in both) and the process CPU time of the whole loop (``fmi2SetReal`` of
the inputs, ``fmi2DoStep``, ``fmi2GetReal`` of the speed the controller needs: the pythonfmu FMU
computes its outputs there).  Each FMU runs ``ROUNDS`` times per mode, interleaved; the median
per step is printed and the ratios pythonfmu / native, measured in this one run (goal ≥ 100x,
floor ≥ 20x).  The native FMU also runs the same loop at the dynamic level (ROS34PW2, the
carriers as states): its doStep over the native quasi-static doStep is printed, the dynamic
level's price where no FMI call overhead hides it.

Run: ``python benchmarks/native_step_cost.py`` (about 30 s, builds included; needs gcc).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from fmpy import extract, read_model_description

from prsm_fmu.fmi_enum import enumeration_value

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_fmu_c_host import C_HOST, _headers, _libpython  # noqa: E402 - the one C host

STEPS = 20000
ROUNDS = 3


def build(dest: Path) -> tuple[Path, Path]:
    """PRSM2.fmu and PRSM2-native.fmu, built in child processes."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for extra in ([], ["--native"]):
        subprocess.run([sys.executable, "-m", "fmu_build", "PRSM2", *extra, "--dest", str(dest)],
                       check=True, env=env, capture_output=True)
    return dest / "PRSM2.fmu", dest / "PRSM2-native.fmu"


def compile_host(d: Path) -> Path:
    (d / "host.c").write_text(C_HOST)
    subprocess.run(["gcc", "-std=c99", "-O2", f"-I{_headers()}", str(d / "host.c"), "-o",
                    str(d / "host"), "-ldl", "-lm"], check=True)
    return d / "host"


def run(host: Path, fmu: Path, python: bool, mode: str, fidelity: str = "quasi-static") -> float:
    """ns per step of one run of the host: ``mode`` "step" (doStep alone) or "loop"."""
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    level = enumeration_value(next(v for v in md.modelVariables if v.name == "fidelity"), fidelity)
    unzip = Path(extract(str(fmu)))
    ident = md.coSimulation.modelIdentifier
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "LD_"))}
    env["PRSM_HOST_TIME"] = mode
    if python:
        env["LD_PRELOAD"] = str(_libpython())
        env["PYTHONHOME"] = f"{sys.base_prefix}:{sys.base_exec_prefix}"
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p and Path(p).is_dir())
    args = [str(host), str(unzip / "binaries" / "linux64" / f"{ident}.so"),
            (unzip / "resources").as_uri(), md.guid, str(level), str(STEPS),
            str(vr["screw_torque"]), str(vr["load_force"]), str(vr["fidelity"]),
            str(vr["screw_speed"]), str(vr["screw_speed"])]
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise RuntimeError(f"{fmu.name}: host failed:\n{proc.stderr[-2000:]}")
    values = dict(line.split() for line in proc.stderr.splitlines()
                  if line.startswith(("loop_ns", "dostep_ns")))
    return float(values["dostep_ns_per_step" if mode == "step" else "loop_ns_per_step"])


def main() -> None:
    if _libpython() is None:
        sys.exit("this Python has no shared libpython: the pythonfmu FMU cannot run in a C host")
    with tempfile.TemporaryDirectory(prefix="native_cost_") as tmp:
        tmp = Path(tmp)
        py_fmu, nat_fmu = build(tmp)
        host = compile_host(tmp)
        results: dict[str, list[tuple[float, float]]] = {"pythonfmu": [], "native": [],
                                                           "native dynamic": []}
        for _ in range(ROUNDS):
            for name, fmu, python, level in (("pythonfmu", py_fmu, True, "quasi-static"),
                                             ("native", nat_fmu, False, "quasi-static"),
                                             ("native dynamic", nat_fmu, False, "dynamic")):
                results[name].append((run(host, fmu, python, "step", level),
                                      run(host, fmu, python, "loop", level)))
    med = {k: (statistics.median(r[0] for r in v), statistics.median(r[1] for r in v))
           for k, v in results.items()}
    print(f"PRSM2, quasi-static (and the native FMU at dynamic), C host, {STEPS} steps of 1 ms "
          f"(reversal, then steady), median of {ROUNDS} runs, per step:")
    print(f"{'FMU':<16}{'doStep [us]':>14}{'loop CPU [us]':>15}")
    for k, (step, loop) in med.items():
        print(f"{k:<16}{step / 1e3:>14.3f}{loop / 1e3:>15.3f}")
    r_step = med["pythonfmu"][0] / med["native"][0]
    r_loop = med["pythonfmu"][1] / med["native"][1]
    print(f"ratio pythonfmu / native: doStep {r_step:.0f}x, loop {r_loop:.0f}x "
          f"(goal >= 100x, floor >= 20x)")
    print(f"native dynamic / native quasi-static: doStep "
          f"{med['native dynamic'][0] / med['native'][0]:.1f}x, loop "
          f"{med['native dynamic'][1] / med['native'][1]:.1f}x; native dynamic / pythonfmu "
          f"quasi-static doStep {med['native dynamic'][0] / med['pythonfmu'][0]:.2f}")


if __name__ == "__main__":
    main()
