"""A run's inputs as a schedule of advances, known before the first step.

:func:`prsm_fmu.simulate.simulate` holds its inputs over each output interval (zero-order
hold); the speed drive splits an interval where the prescribed acceleration jumps
(:meth:`prsm_fmu.profiles.SpeedProfile.pieces`).  :func:`input_schedule` lists those advances
once: their start times, lengths and held inputs, and which of them end an output interval.
Both executors of a run step through the same list: the Python loop advance by advance, and the
compiled engine in one call (``prsm_api_advance_schedule``), so that they cannot differ in what
they step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

__all__ = ["Schedule", "input_schedule"]


@dataclass(frozen=True)
class Schedule:
    """The advances of a run, in order.

    Attributes
    ----------
    start, length : list of float
        Start time [s] and length [s] of each advance.
    u : list of tuple
        The inputs held over each advance: (motor torque [N.m] or prescribed screw
        acceleration [rad/s²], load force [N]).
    record : list of bool
        True for the last advance of an output interval (the outputs are sampled after it).
    """

    start: list[float]
    length: list[float]
    u: list[tuple[float, float]]
    record: list[bool]


def input_schedule(n_steps: int, output_interval: float, load: Callable[[float], float],
                   torque: Callable[[float], float] | None = None, profile=None,
                   first: int = 0) -> Schedule:
    """The advances of ``n_steps`` output intervals of ``output_interval`` [s], the intervals
    ``first`` … ``first + n_steps − 1`` of a run from t = 0.

    Interval i runs from t_i = i·h to t_(i+1) = (i + 1)·h; the load [N] is sampled at t_i.
    Torque drive (``torque`` given): one advance of h with (torque(t_i), load(t_i)).  Speed
    drive (``profile``, a :class:`~prsm_fmu.profiles.SpeedProfile`): the pieces of
    ``profile.pieces(t_i, t_(i+1))`` with (their acceleration, load(t_i)); an interval of one
    piece is one advance from t_i of exactly h.

    Parameters
    ----------
    n_steps : int
        Output intervals, >= 1.
    first : int
        Index of the first of them (a long run is listed in blocks).
    output_interval : float
        h [s].
    load : callable
        Load force [N] as a function of time [s].
    torque : callable, optional
        Motor torque [N.m] as a function of time [s] (torque drive).
    profile : SpeedProfile, optional
        The prescribed screw speed (speed drive).

    Returns
    -------
    Schedule
    """
    if (torque is None) == (profile is None):
        raise ValueError("exactly one of torque (torque drive) and profile (speed drive) must "
                         "be given")
    start: list[float] = []
    length: list[float] = []
    u: list[tuple[float, float]] = []
    record: list[bool] = []
    h = output_interval
    for i in range(first, first + n_steps):
        t = i * h
        if profile is None:
            start.append(t)
            length.append(h)
            u.append((torque(t), load(t)))
            record.append(True)
            continue
        f = load(t)
        pieces = profile.pieces(t, (i + 1) * h)
        if len(pieces) == 1:      # the whole interval: step exactly h, as the torque drive
            pieces = [(t, h, pieces[0][2])]
        for start_k, length_k, alpha in pieces:
            start.append(start_k)
            length.append(length_k)
            u.append((alpha, f))
            record.append(False)
        record[-1] = True
    return Schedule(start, length, u, record)
