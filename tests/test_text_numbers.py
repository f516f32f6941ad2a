"""The helpers that read numbers out of printed text (tests/text_numbers.py).

The case that made the README's test command fail: the C prints a step size with ``%.17g``,
Python with ``repr``; the same double, two spellings.
"""

from __future__ import annotations

import math

import pytest

from text_numbers import number_after, same_message, same_table, split_numbers

C_SPELLING = "fmi2DoStep: step size 8.7531688739772769e-15 s below h_min"
PY_SPELLING = "fmi2DoStep: step size 8.753168873977277e-15 s below h_min"


def test_the_two_spellings_differ_as_text_and_are_one_double():
    assert C_SPELLING != PY_SPELLING                      # what the old text compare saw
    assert float("8.7531688739772769e-15") == float("8.753168873977277e-15")
    assert number_after(C_SPELLING, "step size ") == number_after(PY_SPELLING, "step size ")
    assert same_message(C_SPELLING, PY_SPELLING)


def test_number_after_reads_signs_exponents_and_skips_a_label_without_the_unit():
    assert number_after("x = -1.5e-3 m", "x = ") == -0.0015
    assert number_after("t = 0 s", "t = ") == 0.0
    assert number_after("a = inf", "a = ") == math.inf
    # the first "σ_1 = " starts a formula; the one followed by the unit is the value
    text = "σ_1 = 4 F_a / (π d²) < [σ]: σ_1 = 16.74 MPa"
    assert number_after(text, "σ_1 = ", "MPa") == 16.74
    with pytest.raises(AssertionError, match="no number after"):
        number_after("speed = fast", "speed = ")


def test_split_numbers_leaves_words_with_digits_alone():
    template, numbers = split_numbers("stage[2] of PRSM2 at t = 0.012 s: nan, -1e-30, information")
    assert template == "stage[#] of PRSM2 at t = # s: #, #, information"
    assert numbers[0] == 2.0 and numbers[1] == 0.012 and math.isnan(numbers[2])
    assert numbers[3] == -1e-30 and len(numbers) == 4


def test_same_message_tells_other_numbers_and_other_words_apart():
    assert not same_message("t = 0.012 s", "t = 0.0121 s")
    assert not same_message("t = 0.012 s", "t = 0.012 ms")
    assert same_message("value nan", "value nan")          # equal NaNs count as equal
    assert not same_message("a 1", "a 1 2")


def test_same_table_compares_cells_as_numbers():
    a = "time [s],x [m],status\n0,1e-3,ok\n0.1,nan,error\n"
    assert same_table(a, "time [s],x [m],status\n0.0,0.001,ok\n1e-1,nan,error\n")
    assert not same_table(a, "time [s],x [m],status\n0,1.0000000000000002e-3,ok\n0.1,nan,error\n")
    assert not same_table(a, "time [s],x [m],status\n0,1e-3,ok\n")               # a row fewer
    assert not same_table(a, "time [s],x [m],status\n0,1e-3,ok\n0.1,nan,failed\n")
