"""system_models.brent: scipy's compiled Brent routine loaded without scipy.optimize's import.

Its roots must be scipy.optimize.brentq's bit for bit (the actuator's steady start depends on
them, and the regression baselines on that): compared on seeded random functions and brackets,
on the steady starts of the scenes, and on its refusals.  The fast path must really be taken
(else the comparison would be of scipy with itself), and must not import scipy.optimize.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy")

from system_models import brent  # noqa: E402

# scipy.optimize is imported inside the tests: importing this module (as the fresh process of
# test_the_compiled_routine_loads_alone does, for its cases) must not import it

#: random cases compared (seeded)
N_CASES = 400


def _cases(seed: int = 20261127):
    """(f, a, b, xtol, rtol): a cubic with one real root r, a tanh step at r with a cubic
    added, or an exponential minus a constant, each bracketing its root at random."""
    rng = np.random.default_rng(seed)
    for k in range(N_CASES):
        r = float(rng.uniform(-5.0, 5.0))
        lo, hi = r - float(rng.uniform(1e-3, 4.0)), r + float(rng.uniform(1e-3, 4.0))
        kind = k % 3
        if kind == 0:
            p = float(rng.uniform(-2.0, 2.0))
            q = p * p / 4.0 + float(rng.uniform(0.1, 3.0))       # x² + p x + q > 0: one root
            s = float(rng.uniform(0.1, 10.0))

            def f(x, r=r, p=p, q=q, s=s):
                return s * (x - r) * (x * x + p * x + q)
        elif kind == 1:
            g, e = float(rng.uniform(0.5, 50.0)), float(rng.uniform(0.0, 0.1))

            def f(x, r=r, g=g, e=e):
                return math.tanh(g * (x - r)) + e * (x - r) ** 3
        else:
            def f(x, r=r):
                return math.exp(x) - math.exp(r)
        tol = [(1e-14, 1e-14), (2e-12, 4 * np.finfo(float).eps), (1e-6, 1e-10)][k % 4 % 3]
        yield f, lo, hi, tol[0], tol[1]


def test_the_compiled_routine_loads_alone():
    """In a fresh process (here scipy.optimize is imported already, and :func:`brent.brentq`
    uses its module): the routine loaded alone imports no scipy.optimize, and its roots of
    the seeded cases are those of scipy.optimize.brentq imported afterwards, bit for bit."""
    assert brent._compiled() is not None
    code = ("import sys\n"
            "sys.path.insert(0, sys.argv[1])\n"
            "from test_brent import _cases\n"
            "from system_models.brent import brentq\n"
            "mine = [brentq(f, a, b, x, r).hex() for f, a, b, x, r in _cases()]\n"
            "alone = 'scipy.optimize' not in sys.modules\n"
            "from scipy.optimize import brentq as theirs\n"
            "same = mine == [theirs(f, a, b, xtol=x, rtol=r).hex() for f, a, b, x, r in _cases()]\n"
            "print(alone, same, len(mine))\n")
    out = subprocess.run([sys.executable, "-c", code, str(Path(__file__).parent)],
                         capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "True", str(N_CASES)], out


def test_roots_are_scipys_bit_for_bit():
    from scipy.optimize import brentq as scipy_brentq

    n = 0
    for f, a, b, xtol, rtol in _cases():
        mine = brent.brentq(f, a, b, xtol=xtol, rtol=rtol)
        theirs = scipy_brentq(f, a, b, xtol=xtol, rtol=rtol)
        assert mine.hex() == theirs.hex(), (a, b, xtol, rtol, mine, theirs)
        n += 1
    assert n == N_CASES
    print(f"{n} seeded cases: the same root, bit for bit")


@pytest.mark.parametrize("scene, fidelity", [("speed_reversal", None),
                                             ("startup_li2021", "kinematic"),
                                             ("startup_li2021", "quasi-static"),
                                             ("startup_li2021", "dynamic")])
def test_steady_starts_are_the_same(monkeypatch, scene, fidelity):
    """The holding torque of each steady start at speed (the scenes regress runs), with the
    compiled routine alone and with scipy.optimize.brentq (the loader made to fail)."""
    from system_models.run import build_scene_system
    from system_models.scenes import load_scene

    def torque() -> float:
        system = build_scene_system(load_scene(scene), prsm="python", fidelity=fidelity)
        return system.prsm.initial_inputs[0]

    fast = torque()
    monkeypatch.setattr(brent, "_zeros", False)
    assert brent._compiled() is None
    slow = torque()
    assert fast != 0.0 and fast.hex() == slow.hex(), (fast, slow)


def test_refusals_are_scipys():
    with pytest.raises(ValueError, match="different signs"):
        brent.brentq(lambda x: x * x + 1.0, -1.0, 1.0)
    with pytest.raises(ValueError, match="is NaN"):
        brent.brentq(lambda x: math.nan if x > 0.5 else x - 0.7, 0.0, 1.0)
    with pytest.raises(ValueError, match="rtol too small"):
        brent.brentq(lambda x: x - 0.5, 0.0, 1.0, rtol=1e-17)
    with pytest.raises(RuntimeError):
        brent.brentq(lambda x: math.tanh(50 * (x - 0.3)), 0.0, 1.0, xtol=1e-300,
                     rtol=1e-15, maxiter=3)
