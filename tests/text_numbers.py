"""Read numbers out of printed text, so that tests compare them as numbers and never as spellings.

The same double prints as ``8.7531688739772769e-15`` from C's ``%.17g`` and as
``8.753168873977277e-15`` from Python's ``repr``; a test that compares the two strings passes or
fails by chance of the digits.  Tests parse the number with :func:`number_after` and compare it
as a float: exactly where both sides are the same computation, else within a tolerance that the
test derives (e.g. half a unit in the last printed digit).
"""

from __future__ import annotations

import csv
import io
import math
import re

#: a decimal floating-point literal as C's printf and Python's repr/format write it
NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan)(?!\w)"

#: a number that is not part of a word (the 2 of ``fmi2DoStep`` is not a number)
_STANDALONE = r"(?<![\w.])(?:" + NUMBER + ")"


def number_after(text: str, label: str, unit: str = "") -> float:
    """The number printed right after the first ``label`` in ``text`` that is followed by a
    number (and then by ``unit``, if given); spaces between them are allowed.

    Parameters
    ----------
    text : str
        Printed output or a message.
    label : str
        Literal text that precedes the number, e.g. ``"σ_1 = "``.
    unit : str, optional
        Literal text that must follow the number, e.g. ``"MPa"`` (tells a value from a formula
        that starts with the same label).

    Returns
    -------
    float

    Raises
    ------
    AssertionError
        If ``label`` is not followed by a number in ``text`` (the message shows the text).
    """
    tail = r"\s*" + re.escape(unit) if unit else ""
    match = re.search(re.escape(label) + r"\s*(" + NUMBER + ")" + tail, text)
    if match is None:
        raise AssertionError(f"no number after {label!r}{' with unit ' + repr(unit) if unit else ''}"
                             f" in {text!r}")
    return float(match.group(1))


def split_numbers(text: str) -> tuple[str, list[float]]:
    """``text`` with every number replaced by ``#``, and the numbers as floats, in order.

    Two messages are equal when their templates are equal as text and their numbers as floats
    (NaN equal to NaN): the spelling of a number does not matter.

    Parameters
    ----------
    text : str

    Returns
    -------
    template : str
    numbers : list of float
    """
    found = [float(m.group(0)) for m in re.finditer(_STANDALONE, text)]
    return re.sub(_STANDALONE, "#", text), found


def same_message(a: str, b: str) -> bool:
    """Whether two messages say the same: equal templates, equal numbers (see :func:`split_numbers`).

    Parameters
    ----------
    a, b : str

    Returns
    -------
    bool
    """
    (ta, na), (tb, nb) = split_numbers(a), split_numbers(b)
    return ta == tb and len(na) == len(nb) and all(
        x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(na, nb))


def _cell(text: str) -> float | str:
    """A CSV cell as a float when it is a number, else as its text."""
    try:
        return float(text)
    except ValueError:
        return text


def _same_value(a: float | str, b: float | str) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b


def same_table(a: str, b: str) -> bool:
    """Whether two CSV texts hold the same table: the same rows and columns, every numeric cell
    equal as a float (NaN equal to NaN), every other cell equal as text.

    Parameters
    ----------
    a, b : str
        CSV texts.

    Returns
    -------
    bool
    """
    ra, rb = list(csv.reader(io.StringIO(a))), list(csv.reader(io.StringIO(b)))
    return len(ra) == len(rb) and all(
        len(x) == len(y) and all(_same_value(_cell(u), _cell(v)) for u, v in zip(x, y))
        for x, y in zip(ra, rb))
