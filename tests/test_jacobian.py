"""The dynamic level's analytic Jacobian (DynamicModel.analytic_jacobian) against central
differences of its own right-hand side.

The expected values are not the code's formulas: they are (rhs(x + d e_j) − rhs(x − d e_j))/2d,
whose truncation error is O(d²) ≈ 1e-12 relative for d = 1e-6·|x_j| on this smooth, piecewise
rational rhs, plus round-off ≈ eps·|rhs|/d ≈ 1e-10 relative; 1e-6 leaves room for both and fails
for any missing term (a dropped term of the chain changes an entry by O(1) relative).  The states
cover the three presets' friction laws: Li et al. (2021) (Coulomb + spline), the multi-stage assembly article (+ thrust-bearing
friction: the 2×2 spline–bearing solve), the friction-torque article (viscous and differential-sliding terms), both
drives, speeds from 100 rad/s down into the friction band (1e-3 rad/s) and both directions.
"""

from __future__ import annotations

import math
import random

import pytest

from prsm_fmu import presets
from prsm_fmu.models import make_model

SPEEDS = (100.0, 5.0, 0.3, -20.0, 1e-2, 1e-3)


def _states(model, drive, n=18, seed=1):
    rnd = random.Random(seed)
    for trial in range(n):
        w = SPEEDS[trial % len(SPEEDS)]
        x = model.initial_state((0.0, 0.0), screw_speed=w, carrier_ratio=None)
        for i in range(2, 2 + model.n_carrier_states):
            x[i] *= 1.0 + rnd.uniform(-0.05, 0.05)      # carriers off their equilibrium
        drive_input = rnd.uniform(-30.0, 30.0) if drive == "torque" else rnd.uniform(-1e3, 1e3)
        yield x, (drive_input, rnd.uniform(-5000.0, 5000.0))


@pytest.mark.parametrize("drive", ["torque", "speed"])
@pytest.mark.parametrize("preset", ["li2021_two_stage", "assembly_two_stage",
                                    "friction_single_stage"])
def test_analytic_jacobian_matches_central_differences_within_1e_6(preset, drive):
    model = make_model(presets.load(preset), "dynamic", drive)
    checked = 0
    for x, u in _states(model, drive):
        f0 = model.rhs(0.0, x, u)
        if not all(math.isfinite(v) for v in f0):
            continue                                  # no rigid solution there (Painlevé)
        jac = model.analytic_jacobian(0.0, x, u)
        assert len(jac) == model.n_states and all(len(r) == model.n_states for r in jac)
        for j in range(model.n_states):
            d = 1e-6 * max(abs(x[j]), 1e-3)
            xp, xm = list(x), list(x)
            xp[j] += d
            xm[j] -= d
            fp, fm = model.rhs(0.0, xp, u), model.rhs(0.0, xm, u)
            for i in range(model.n_states):
                fd = (fp[i] - fm[i]) / (2.0 * d)
                # scale: the entry itself, or the row's rate over the state's size where the
                # entry is (close to) zero
                scale = max(abs(fd), abs(jac[i][j]), 1e-9 * max(abs(f0[i]), 1.0))
                assert abs(jac[i][j] - fd) <= 1e-6 * scale, (preset, drive, x, u, i, j, fd,
                                                             jac[i][j])
        checked += 1
    assert checked >= 12
