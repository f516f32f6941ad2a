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

Restoring a state: the same C host as a master that tries each step first (fmi2GetFMUstate, the
trial doStep, fmi2SetFMUstate back, the step again; PRSM_HOST_TIME=restore) times each call at
the dynamic level, for the native FMU's sources as they are ("new") and with the FMI layer of
the code before a restore kept the instance's model (prsm_fmi2.c of commit ``OLD_COMMIT``, read
with git: "old"; skipped where git cannot show it), both compiled here by gcc with the FMU's
flags.  The restore's cost is printed beside the doStep's, and old / new, in this one run.

Run: ``python benchmarks/native_step_cost.py`` (about 30 s, builds included; needs gcc).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from fmpy import extract, read_model_description

from fmu_build.platforms import COMPILE_FLAGS
from prsm_fmu.fmi_enum import enumeration_value

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_fmu_c_host import C_HOST, _headers, _libpython  # noqa: E402 - the one C host

STEPS = 20000
ROUNDS = 3
#: the last commit whose fmi2SetFMUstate built the model again on every restore
OLD_COMMIT = "aa6e7d9"


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


def restore_libraries(fmu: Path, d: Path) -> dict[str, Path]:
    """The native FMU's library compiled from its sources/ ("new") and, where git shows it,
    with prsm_fmi2.c of OLD_COMMIT instead ("old"): the same compiler and flags for both."""
    with zipfile.ZipFile(fmu) as z:
        listed = ET.fromstring(z.read("modelDescription.xml")).find("CoSimulation/SourceFiles")
        sources = [f.get("name") for f in listed]
        texts = {Path(n).name: z.read(n) for n in z.namelist() if n.startswith("sources/")}
    old = subprocess.run(["git", "show", f"{OLD_COMMIT}:fmu_build/native/prsm_fmi2.c"], cwd=ROOT,
                         capture_output=True)
    variants = {"new": {}} | ({"old": {"prsm_fmi2.c": old.stdout}} if old.returncode == 0 else {})
    libs = {}
    for name, replaced in variants.items():
        src = d / f"src_{name}"
        src.mkdir()
        for file, text in (texts | replaced).items():
            (src / file).write_bytes(text)
        libs[name] = d / f"{name}.so"
        subprocess.run(["gcc", *COMPILE_FLAGS, *(str(src / s) for s in sources), "-o",
                        str(libs[name]), "-lm"], check=True)
    return libs


def run(host: Path, fmu: Path, python: bool, mode: str, fidelity: str = "quasi-static",
        library: Path | None = None) -> float | dict[str, float]:
    """ns per step of one run of the host: ``mode`` "step" (doStep alone) or "loop"; for
    ``mode`` "restore" ns per call of the trial doStep and of fmi2SetFMUstate and
    fmi2GetFMUstate (a dict).  ``library``: this binary instead of the FMU's own."""
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
    args = [str(host), str(library or unzip / "binaries" / "linux64" / f"{ident}.so"),
            (unzip / "resources").as_uri(), md.guid, str(level), str(STEPS),
            str(vr["screw_torque"]), str(vr["load_force"]), str(vr["fidelity"]),
            str(vr["screw_speed"]), str(vr["screw_speed"])]
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        raise RuntimeError(f"{fmu.name}: host failed:\n{proc.stderr[-2000:]}")
    values = {k: float(v) for k, v in (line.split() for line in proc.stderr.splitlines()
                                       if line.startswith(("loop_ns", "dostep_ns", "setstate_ns",
                                                           "getstate_ns")))}
    if mode == "restore":
        return values
    return values["dostep_ns_per_step" if mode == "step" else "loop_ns_per_step"]


def main() -> None:
    if _libpython() is None:
        sys.exit("this Python has no shared libpython: the pythonfmu FMU cannot run in a C host")
    with tempfile.TemporaryDirectory(prefix="native_cost_") as tmp:
        tmp = Path(tmp)
        py_fmu, nat_fmu = build(tmp)
        host = compile_host(tmp)
        libs = restore_libraries(nat_fmu, tmp)
        restores: dict[str, list[dict[str, float]]] = {name: [] for name in libs}
        results: dict[str, list[tuple[float, float]]] = {"pythonfmu": [], "native": [],
                                                           "native dynamic": []}
        for _ in range(ROUNDS):
            for name, lib in libs.items():
                restores[name].append(run(host, nat_fmu, False, "restore", "dynamic", lib))
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
    print_restores(restores)


def print_restores(restores: dict[str, list[dict[str, float]]]) -> None:
    """The medians per call of the restore runs, and old / new."""
    keys = ("dostep_ns_per_step", "setstate_ns_per_call", "getstate_ns_per_call")
    med = {name: {k: statistics.median(r[k] for r in runs) for k in keys}
           for name, runs in restores.items()}
    print(f"native dynamic, trial step and restore before each of {STEPS} steps, C host, "
          f"median of {ROUNDS} runs, per call [us] (gcc {' '.join(COMPILE_FLAGS)}):")
    print(f"{'FMI layer':<22}{'doStep':>10}{'SetFMUstate':>13}{'GetFMUstate':>13}")
    labels = {"new": "new (this tree)", "old": f"old ({OLD_COMMIT})"}
    for name, m in med.items():
        print(f"{labels[name]:<22}{m[keys[0]] / 1e3:>10.3f}{m[keys[1]] / 1e3:>13.3f}"
              f"{m[keys[2]] / 1e3:>13.3f}")
    if "old" in med:
        print(f"fmi2SetFMUstate old / new: {med['old'][keys[1]] / med['new'][keys[1]]:.0f}x; "
              f"SetFMUstate / doStep: old {med['old'][keys[1]] / med['old'][keys[0]]:.2f}, "
              f"new {med['new'][keys[1]] / med['new'][keys[0]]:.3f}")
    else:
        print(f"(git cannot show {OLD_COMMIT}: the old FMI layer is not measured)")


if __name__ == "__main__":
    main()
