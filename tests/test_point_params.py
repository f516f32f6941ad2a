"""A point's validated mechanism (prsm_fmu.sweep.points.point_params): kept for points whose
inputs are equal, never handed to an input that only compares equal, and bad input refused
every time with the same one-line message."""

from __future__ import annotations

import math

import pytest

from prsm_fmu.sweep.points import point_params

PRESET = "li2021_two_stage"


def test_equal_inputs_share_one_mechanism_with_the_overrides_applied():
    """Two points of a study that differ only in the scenario (same overrides) get one
    object; its values are the overrides (Li et al. (2021) §3.1's two-stage PRSM with
    µ_SR = 0.15 and 6 rollers on stage 2, the values of this test)."""
    a = point_params(PRESET, {"mu_screw_roller": 0.15, "stage[2].n_rollers": 6})
    b = point_params(PRESET, {"mu_screw_roller": 0.15, "stage[2].n_rollers": 6})
    assert a is b
    assert a.mu_screw_roller == 0.15 and a.stages[1].n_rollers == 6
    c = point_params(PRESET, {"mu_screw_roller": 0.25, "stage[2].n_rollers": 6})
    assert c.mu_screw_roller == 0.25 and c is not a


def test_an_integer_as_float_is_refused_after_the_integer_was_accepted():
    """7 and 7.0 compare equal (and hash equal) but the stage's roller count must be an
    integer: 7 is accepted, then 7.0 is refused with the range message, and True (== 1)
    too."""
    ok = point_params(PRESET, {"stage[1].n_rollers": 7})
    assert ok.stages[0].n_rollers == 7 and type(ok.stages[0].n_rollers) is int
    with pytest.raises(ValueError, match=r"^stage\[1\]\.n_rollers = 7\S* is out of range: "
                                               "must be an integer"):
        point_params(PRESET, {"stage[1].n_rollers": 7.0})
    point_params(PRESET, {"stage[1].carriers": 1})
    with pytest.raises(ValueError, match=r"^stage\[1\]\.carriers = True is out of range"):
        point_params(PRESET, {"stage[1].carriers": True})


def test_minus_zero_is_not_handed_the_mechanism_of_plus_zero():
    """0.0 and -0.0 compare equal; each point gets its own value's sign (µ_NS = ±0: no bearing
    friction either way, but the parameters are the inputs as given)."""
    plus = point_params(PRESET, {"mu_nut_screw": 0.0})
    minus = point_params(PRESET, {"mu_nut_screw": -0.0})
    assert math.copysign(1.0, plus.mu_nut_screw) == 1.0
    assert math.copysign(1.0, minus.mu_nut_screw) == -1.0


def test_bad_input_is_refused_each_time_with_one_line():
    """µ_SR = 1.5 is outside [0, 1): refused on every call, the same single line."""
    messages = []
    for _ in range(3):
        with pytest.raises(ValueError) as info:
            point_params(PRESET, {"mu_screw_roller": 1.5})
        messages.append(str(info.value))
    assert len(set(messages)) == 1 and "\n" not in messages[0]
    assert messages[0].startswith("mu_screw_roller = 1.5 is out of range")


def test_values_of_other_types_are_not_kept_but_still_checked():
    """A list value (a malformed override) is not a key: it goes straight to validation,
    which refuses it as before."""
    with pytest.raises(ValueError, match=r"^mu_screw_roller = \[0\.1\] is out of range"):
        point_params(PRESET, {"mu_screw_roller": [0.1]})
