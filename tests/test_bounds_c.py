"""The C checks of the inputs' and the state's bounds equal the Python ones, message for message.

``fmu_build/native/prsm_bounds.h`` (the native FMU's doStep and state restore, and the engine's
one-call step of the pythonfmu FMU) mirrors :func:`prsm_fmu.param_ranges.input_violation` and
:func:`~prsm_fmu.param_ranges.state_violation`, its bounds generated into ``prsm_constants.h``
from the same table.  Compiled here with gcc against PRSM2's constants and called through
ctypes on seeded random inputs and states drawn around every bound (counts printed): the C
must refuse exactly where Python does, with the same message.
"""

from __future__ import annotations

import ctypes
import random
import shutil
import subprocess

import pytest

from fmu_build import native
from prsm_fmu import presets
from prsm_fmu.param_ranges import input_violation, state_violation

SEED = 20261126
CASES = 3000

WRAPPER = r"""
#include "prsm_bounds.h"
int check_input(const double *u, char *msg, int len) { return prsm_input_violation(u, msg, len); }
int check_state(const double *x, int n, const double *speeds, char *msg, int len) {
    return prsm_state_violation(x, n, speeds, msg, len);
}
"""


@pytest.fixture(scope="module")
def bounds_c(tmp_path_factory):
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc is not installed")
    d = tmp_path_factory.mktemp("bounds_c")
    (d / "prsm_constants.h").write_text(native.constants_header(presets.load("li2021_two_stage")))
    (d / "wrapper.c").write_text(WRAPPER)
    lib = d / "bounds.so"
    subprocess.run([gcc, "-std=c99", "-O2", "-fPIC", "-shared", "-ffp-contract=off",
                    f"-I{d}", f"-I{native.SOURCE_DIR}", str(d / "wrapper.c"), "-o", str(lib),
                    "-lm"], check=True, capture_output=True)
    dll = ctypes.CDLL(str(lib))
    dbl = ctypes.POINTER(ctypes.c_double)
    dll.check_input.argtypes = [dbl, ctypes.c_char_p, ctypes.c_int]
    dll.check_state.argtypes = [dbl, ctypes.c_int, dbl, ctypes.c_char_p, ctypes.c_int]
    return dll


def _near(rng: random.Random, bound: float) -> float:
    """A value around ``bound`` [any unit]: just inside, on it, just beyond, far inside,
    zero, non-finite, with either sign."""
    v = rng.choice([bound, bound * (1 + 1e-15), bound * (1 - 1e-15), bound * 1.5,
                    bound * rng.random(), 0.0, float("inf"), float("nan"), 1e-310])
    return -v if rng.random() < 0.5 else v


def test_input_checks_equal_python(bounds_c):
    """Inputs (torque, load) around 1e6 N.m, 1e8 N and the smallest magnitude 1e-150 (the
    bounds of docs/fmu.md): the C refuses where Python does, with its message."""
    rng = random.Random(f"{SEED}-inputs")
    msg = ctypes.create_string_buffer(600)
    refused = 0
    for _ in range(CASES):
        u = [_near(rng, rng.choice([1e6, 1e-150])), _near(rng, rng.choice([1e8, 1e-150]))]
        rc = bounds_c.check_input((ctypes.c_double * 2)(*u), msg, 600)
        why = input_violation(tuple(u))
        assert (rc != 0) == (why is not None), u
        if why is not None:
            assert msg.value.decode() == why, u
            refused += 1
    print(f"\n{CASES} input pairs, {refused} refused by both with the same message")
    assert 0 < refused < CASES


@pytest.mark.parametrize("n", [5, 7])
def test_state_checks_equal_python(bounds_c, n):
    """States of the quasi-static (5: angle, speed, three works) and the dynamic level (7: two
    carrier speeds too) with each component around its bound (angle 1e15 rad, works 1e150 J;
    the speeds' bounds are the caller's, drawn here per case among 1e5, 4e76 and 1.4e77 rad/s,
    or not given: then no speed is refused), and quotients around 1e300 (a carrier speed over a
    subnormal screw speed, the output work over a subnormal input work)."""
    rng = random.Random(f"{SEED}-states-{n}")
    msg = ctypes.create_string_buffer(600)
    refused = 0
    kinds = dict.fromkeys(("(angle)", "(speed)", "(work)", "(carrier speed)", "(output work)"), 0)
    for _ in range(CASES):
        x = [rng.uniform(-1.0, 1.0) for _ in range(n)]
        speeds = (None if rng.random() < 0.2 else
                  [rng.choice([1e5, 4e76, 1.4e77]) for _ in range(n - 4)])
        k = rng.randrange(n + 2)
        if k < n:
            bound = (1e15 if k == 0 else 1e150 if k >= n - 3
                     else speeds[k - 1] if speeds else 1e5)
            x[k] = _near(rng, bound)
        elif k == n:                     # a quotient: carrier speed / screw speed
            x[1] = rng.choice([1e-310, -1e-310, 1e-300, 0.0])
            if n > 5:
                x[2] = _near(rng, 1.0)
        else:                            # output work / input work
            x[n - 3] = rng.choice([1e-310, 1e-300, 0.0, -1e-310])
            x[n - 2] = _near(rng, 1.0)
        c_speeds = (ctypes.c_double * (n - 4))(*speeds) if speeds else None
        rc = bounds_c.check_state((ctypes.c_double * n)(*x), n, c_speeds, msg, 600)
        why = state_violation(x, speeds)
        assert (rc != 0) == (why is not None), x
        if why is not None:
            assert msg.value.decode() == why, x
            refused += 1
            kinds[next(k for k in kinds if k in why)] += 1
    print(f"\n{CASES} states of {n} components, {refused} refused by both with the same message "
          f"({', '.join(f'{k}: {v}' for k, v in kinds.items())})")
    assert 0 < refused < CASES
    assert all(kinds[k] > 0 for k in kinds if n > 5 or k != "(carrier speed)"), kinds
