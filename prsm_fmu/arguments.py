"""Command-line arguments shared by every console script (prsm-fmu, prsm-fmu-build, prsm-ema).

A bad argument is answered with **one line** on stderr that names the argument and its allowed
range or values, and exit status 2, before anything is computed:

* :class:`ArgumentParser` is argparse's parser whose ``error`` prints
  ``PROG: error: MESSAGE (see PROG --help)`` and nothing else (argparse prints the usage
  first, several lines for a subcommand);
* the argument types (:func:`float_in`, :func:`int_in`, :func:`writable_dir`,
  :func:`existing_file`, ...) refuse a value with a message that states what is allowed;
  argparse prefixes it with ``argument --NAME:``.

Check output directories with :func:`writable_dir` at parse time: a run that computes for
minutes and then cannot write its results loses them.
"""

from __future__ import annotations

import argparse
import math
import os
from typing import Callable, NoReturn

__all__ = ["ArgumentParser", "float_in", "int_in", "finite_float", "positive_float",
           "nonzero_float", "writable_dir", "existing_file", "existing_dir", "one_line"]


def one_line(text: object) -> str:
    """``text`` with every run of whitespace (newlines included) collapsed to one space."""
    return " ".join(str(text).split())


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser, reporting a bad argument in one line (module docstring).

    Subparsers made with ``add_subparsers`` are of this class too.
    """

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE (see PROG --help)`` on stderr and exit with status 2."""
        if message.endswith("expected one argument"):
            # argparse reads a value such as -1e-4 as an option
            message += ": must be followed by a value (a negative one as --NAME=VALUE)"
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see '{self.prog} --help')\n")


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return ""


def float_in(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
             hi_open: bool = False, nonzero: bool = False,
             unit: str = "") -> Callable[[str], float]:
    """argparse type: a finite number within [lo, hi] (ends open as asked).

    Parameters
    ----------
    lo, hi : float, optional
        Bounds; None: unbounded on that side.
    lo_open, hi_open : bool
        Exclude the bound.
    nonzero : bool
        Also refuse 0.
    unit : str
        Unit named in the message (e.g. ``"s"``).

    Returns
    -------
    callable
        ``str -> float``, raising ``argparse.ArgumentTypeError`` with the allowed range.
    """
    what = "a finite number" + (f" [{unit}]" if unit else "")
    rng = _interval(lo, hi, lo_open, hi_open)
    allowed = " ".join(x for x in (what, rng, "other than 0" if nonzero else "") if x)

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number: must be {allowed}") \
                from None
        ok = math.isfinite(v) and not (nonzero and v == 0.0)
        if ok and lo is not None:
            ok = v > lo if lo_open else v >= lo
        if ok and hi is not None:
            ok = v < hi if hi_open else v <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"{text!r} is out of range: must be {allowed}")
        return v

    parse.__name__ = "number"
    return parse


def int_in(lo: int | None = None, hi: int | None = None) -> Callable[[str], int]:
    """argparse type: an integer within [lo, hi] (None: unbounded on that side)."""
    allowed = " ".join(x for x in ("an integer", _interval(lo, hi, False, False)) if x)

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer: must be {allowed}") \
                from None
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{text!r} is out of range: must be {allowed}")
        return v

    parse.__name__ = "integer"
    return parse


#: argparse type: any finite number
finite_float = float_in()
#: argparse type: a finite number > 0
positive_float = float_in(0.0, lo_open=True)
#: argparse type: a finite number other than 0
nonzero_float = float_in(nonzero=True)


def writable_dir(text: str) -> str:
    """argparse type: a directory that exists and is writable, or can be created.

    Nothing is created here; the command creates it when it writes.
    """
    if not text:
        raise argparse.ArgumentTypeError("'' is not a directory: must be a directory path")
    path = os.path.abspath(text)
    probe = path
    while not os.path.exists(probe):
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    if not os.path.isdir(probe):
        raise argparse.ArgumentTypeError(
            f"{text!r} cannot be a directory: {probe} is a file; must be a writable directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not writable ({probe} does not allow it); must be a writable directory")
    return text


def existing_file(text: str) -> str:
    """argparse type: a file that exists."""
    if not os.path.isfile(text):
        raise argparse.ArgumentTypeError(f"{text!r}: no such file; must be an existing file")
    return text


def existing_dir(text: str) -> str:
    """argparse type: a directory that exists."""
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r}: no such directory; must be an existing "
                                         "directory")
    return text
