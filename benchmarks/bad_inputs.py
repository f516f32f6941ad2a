"""Bad inputs, one command: the counts of every bad-input test of the suite, in one run.

Runs, in one pytest session (a child process; the FMUs are built once for it), the tests that
feed both FMUs bad or extreme inputs (docs/fmu.md, "Bad inputs: one command"):
tests/test_bad_inputs.py (inputs beyond their bounds, crafted FMU states, the native sources
under AddressSanitizer/UndefinedBehaviorSanitizer driven by a seeded random C host, every Real
parameter at its extremes, random mechanisms within the ranges with inputs at their bounds),
tests/test_state_bounds.py, tests/test_dostep_work_bound.py, tests/test_status_queries.py and
tests/test_scene_files.py, and prints the count lines those tests print, then the totals:
cases tried, refusals (with the message naming the field where the test prints it), accepted
steps or states (each with finite outputs); and the zeros the issue asks for: tracebacks, hangs (a doStep over 10 s, as
timed by the random-mechanism sweep, or the session over its time limit), non-finite outputs of
accepted steps, sanitizer reports.  Exit status 1 if any of those is not zero, a test failed, or
an expected count line is missing.

Usage::

    python benchmarks/bad_inputs.py

About 1 min on one core (most of it building the two FMUs).
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FILES = ("tests/test_bad_inputs.py", "tests/test_state_bounds.py",
         "tests/test_dostep_work_bound.py", "tests/test_status_queries.py",
         "tests/test_scene_files.py")
#: the whole session at most [s]: beyond it, a hang
SESSION_LIMIT_S = 600.0
#: a doStep slower than this [s] counts as a hang (the issue's threshold)
HANG_S = 10.0

#: (name, pattern) of each count line the tests print; groups: tried, refused, finite, bad
LINES = (
    ("crafted pythonfmu states", r"(\d+) crafted states tried: (\d+) refused whole, (\d+) "
     r"accepted with finite outputs"),
    ("crafted states, both FMUs", r"(\d+) crafted states \(seed \d+\): (\d+) refused by both "
     r"with the same message, (\d+) accepted by both with finite outputs"),
    ("sanitizer host", r"sanitizer host, seed \d+: rounds \d+ calls (\d+) refused (\d+) "
     r"accepted_steps (\d+) accepted_states \d+ nonfinite (\d+)"),
    ("parameters at their extremes", r"(\d+) extreme parameter values tried: (\d+) refused or "
     r"constant, (\d+) steps taken, (\d+) with a non-finite output"),
    ("random mechanisms, pythonfmu", r"pythonfmu: (\d+) random mechanisms \(seed \d+\): (\d+) "
     r"refused at initialization, (\d+) steps taken with finite outputs, (\d+) refused with "
     r"a message and the state unchanged, (\d+) wrong; slowest doStep ([\d.]+) s"),
    ("random mechanisms, native", r"native: (\d+) random mechanisms \(seed \d+\): (\d+) refused "
     r"at initialization, (\d+) steps taken with finite outputs, (\d+) refused with a "
     r"message and the state unchanged, (\d+) wrong; slowest doStep ([\d.]+) s"),
)
#: the verdict lines of the inputs beyond their bounds: the message names the field
VERDICT = re.compile(r"^  (refused|WRONG): inputs .*: input (screw_torque|load_force) = ", re.M)
SANITIZER = re.compile(r"AddressSanitizer|LeakSanitizer|UndefinedBehaviorSanitizer|"
                       r"runtime error:")


def main() -> int:
    cmd = [sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", *FILES]
    start = time.perf_counter()
    try:
        run = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                             timeout=SESSION_LIMIT_S)
        out, session_hang = run.stdout + run.stderr, 0
    except subprocess.TimeoutExpired as exc:
        out, session_hang = (exc.stdout or b"").decode(errors="replace"), 1
    took = time.perf_counter() - start
    tried = refused = finite = bad = 0
    slowest = 0.0
    missing = []
    for name, pattern in LINES:
        m = re.search(pattern, out)
        if not m:
            missing.append(name)
            continue
        print(f"  {name}: {m.group(0)}")
        g = [float(x) for x in m.groups()]
        if name.startswith("random mechanisms"):     # + the steps refused, then the rest
            g = [g[0], g[1] + g[3], g[2], g[4], g[5]]
        tried += int(g[0])
        refused += int(g[1])
        finite += int(g[2])
        if len(g) > 3:
            bad += int(g[3])
        if len(g) > 4:
            slowest = max(slowest, g[4])
    verdicts = VERDICT.findall(out)
    named = sum(1 for v, _ in verdicts if v == "refused")
    tried += len(verdicts)
    refused += named
    bad += len(verdicts) - named
    summary = re.findall(r"(\d+) (passed|failed|skipped|errors?)", out.splitlines()[-1] if out
                         else "")
    tests = {k: int(n) for n, k in summary}
    tracebacks = out.count("Traceback (most recent call last)")
    sanitizer = len(SANITIZER.findall(out))
    hangs = session_hang + (slowest > HANG_S)
    print(f"  inputs beyond their bounds: {len(verdicts)} tried, {named} refused naming the "
          "field")
    print(f"tests: {tests} in {took:.0f} s ({' '.join(FILES)})")
    print(f"cases tried {tried} (crafted states, C calls, parameter values, mechanisms, inputs; "
          f"a case may take several steps): refused with a message {refused}, accepted steps or "
          f"states with finite outputs {finite}")
    print(f"tracebacks {tracebacks}, hangs {hangs} (slowest doStep of the random mechanisms "
          f"{slowest:.3f} s; limit {HANG_S:g} s), non-finite or wrong {bad}, sanitizer reports "
          f"{sanitizer}" + ("" if "sanitizer host" not in missing
                             else " (sanitizer fuzz did not run: see the skip reason)"))
    if missing:
        print(f"missing count lines: {', '.join(missing)}")
    failed = tests.get("failed", 0) + tests.get("error", 0) + tests.get("errors", 0)
    return int(bool(failed or tracebacks or hangs or bad or sanitizer or missing))


if __name__ == "__main__":
    sys.exit(main())
