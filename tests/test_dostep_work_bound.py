"""The work of one doStep at the documented bounds: counted, never timed (docs/fmu.md, "Work of
one doStep").

The worst configuration allowed: PRSM3 (the largest FMU) with stiff carriers (carrier mass and
inertia 10^-6 of PRSM3's), ``tolerance`` 1e-12 (the smallest), ``max_substeps`` 100 000 (the
largest), one communication step of 100 s from rest under 40 N.m and 3 kN.  The FMU's own path
(``prsm_fmu.configure.configure``, what the slave calls) is taken:

* where the Python model steps, one doStep takes at most 10 000 internal steps whatever
  ``max_substeps`` above it, and fixed ``substeps`` above 10 000 are refused at initialization
  with one line naming the value and the range;
* the compiled engine takes up to ``max_substeps`` = 100 000 (fixed) internal steps.

Each internal step costs a bounded number of rhs calls; the bounds below are worked out from
the methods' stages, and the counts are printed.
"""

from __future__ import annotations

import pytest

from fmu_build.mechanisms import three_stage
from prsm_fmu.configure import configure
from prsm_fmu.steppers.base import StepFailure

U = (40.0, 3000.0)          # screw_torque [N.m], load_force [N]
H = 100.0                   # one communication step [s]


def _stiff():
    p = three_stage()
    for k, st in enumerate(p.stages, start=1):
        p = p.with_stage(k, carrier_mass=st.carrier_mass * 1e-6,
                         carrier_inertia=st.carrier_inertia * 1e-6)
    return p


def _solver(**kw) -> dict:
    s = dict(fidelity="dynamic", stepper="default", tolerance=1e-12, max_substeps=100_000,
             substeps=0, kinematic_efficiency=1.0, initial_screw_speed=0.0,
             initial_screw_angle=0.0, initial_carrier_equilibrium=False)
    s.update(kw)
    return s


def _counted(model) -> list[int]:
    calls = [0]
    rhs = model.rhs

    def counted(t, x, u):
        calls[0] += 1
        return rhs(t, x, u)

    model.rhs = counted
    return calls


# rhs calls per internal step, at most (PRSM3: 8 states: angle, screw speed, 3 carrier speeds,
# 3 work integrals): ROS34PW2 4 stages + a finite-difference Jacobian of 8 columns + 1 = 13;
# Dormand-Prince 7 stages; the exponential Rosenbrock method 2 stages + a Jacobian of 8 + 1 = 11
PER_STEP = {"rosenbrock": 4 + 8 + 1, "explicit_adaptive": 7, "exponential": 2 + 8 + 1}


@pytest.mark.parametrize("stepper", sorted(PER_STEP))
def test_the_python_model_refuses_after_10000_internal_steps_at_max_substeps_100000(stepper):
    model, st, x, _level, _name = configure(_stiff(), _solver(stepper=stepper), U,
                                            engine="python")
    calls = _counted(model)
    with pytest.raises(StepFailure) as refused:
        st.advance(0.0, x, U, H)
    text = str(refused.value)
    bound = PER_STEP[stepper] * 10_001     # at most 10 000 steps, the refused attempt included
    print(f"  {stepper}: {calls[0]} rhs calls (bound {bound}); {text[:90]}")
    assert "more than max_substeps = 10000 internal steps" in text
    assert 0 < calls[0] <= bound


def test_fixed_substeps_of_the_python_model_are_bounded_by_10000():
    """rk4 (Python only): 10 000 substeps are taken (4 rhs calls each: 40 000 in all); 10 001
    are refused at initialization in one line naming the value and the range."""
    model, st, x, _level, _name = configure(_stiff(), _solver(stepper="rk4", substeps=10_000), U,
                                            engine="python")
    calls = _counted(model)
    st.advance(0.0, x, U, 1e-3)
    print(f"  rk4, 10000 substeps: {calls[0]} rhs calls")
    assert calls[0] == 4 * 10_000
    with pytest.raises(ValueError) as refused:
        configure(_stiff(), _solver(stepper="rk4", substeps=10_001), U, engine="python")
    text = str(refused.value)
    print(f"  {text}")
    assert "substeps = 10001 is out of range" in text and "[0, 10000]" in text
    assert "\n" not in text


def test_the_engine_takes_max_substeps_100000_fixed_steps_or_refuses_beyond_max_substeps():
    """The engine's loops at their bound: 100 000 fixed ROS34PW2 steps of the stiff PRSM3 end
    (counted by the engine: substeps = 100 000); adaptive with max_substeps = 10 from rest it
    refuses naming the limit."""
    pytest.importorskip("fmu_build.native_stepper")
    model, st, x, _level, _name = configure(_stiff(), _solver(substeps=100_000), U)
    if st.name != "native":
        pytest.skip(f"the engine does not run here: {getattr(st, 'engine_fallback', '')}")
    _x1, stats = st.advance(0.0, x, U, H)
    print(f"  engine, substeps = 100000: {stats.substeps} substeps, {stats.rhs_calls} rhs calls")
    assert stats.substeps == 100_000
    model, st, x, _level, _name = configure(_stiff(), _solver(max_substeps=10), U)
    with pytest.raises(StepFailure) as refused:
        st.advance(0.0, x, U, H)
    assert "more than max_substeps = 10 internal steps" in str(refused.value)
