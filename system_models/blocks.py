"""The small interface every block of the actuator loop has, FMU or plain Python.

A :class:`Block` is what the co-simulation master (:mod:`system_models.master`) steps: the PRSM
FMU behind fmpy's ``FMU2Slave`` (:class:`system_models.fmu.FMUBlock`), the same mechanism as a
plain Python model (:class:`system_models.prsm.PythonPRSM`), and the motor, controller and load.
The master never looks inside a block; a block never knows which block feeds it.

Life cycle (one instance, one run)::

    block.set_inputs(values)            # start values (the master resolves feedthrough)
    y0 = block.get_outputs()            # outputs at the start time t0
    repeat:                             # t = t0 + k h (the master's grid)
        block.set_inputs(values, slopes)    # inputs over [t, t + h] (see below)
        block.do_step(t, h)                 # raises StepRefused: the block's state is unchanged
        y = block.get_outputs()             # outputs at t + h
    block.terminate()

Inputs over a step.  A block with ``interpolates_inputs = False`` (the PRSM FMU: FMI 2.0 inputs
are held) receives one value per input, held constant over the step.  A block with
``interpolates_inputs = True`` receives a value and a slope per input and sees
``u(τ) = value + slope·(τ − t)`` over ``[t, t + h]``.  Ports flagged ``discrete`` are piecewise
constant (a sampled controller's commands): the master never extrapolates them (slope 0).

Feedthrough.  A block with ``feedthrough = True`` (the load: force = f(position, velocity, t))
has outputs that depend on its inputs at the same instant.  After every step the master sets
its inputs to the sources' new outputs and calls :meth:`Block.update_outputs`, so its outputs at
a communication point are consistent with its inputs there.

State.  :meth:`Block.get_state` / :meth:`Block.set_state` / :meth:`Block.free_state` let the
master roll every block back to the start of a step and retry with smaller steps (the FMU does
this with ``fmi2GetFMUstate``/``fmi2SetFMUstate``).
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Sequence

__all__ = ["Port", "Block", "StepRefused", "PythonBlock"]


@dataclass(frozen=True)
class Port:
    """One input or output of a block.

    Attributes
    ----------
    name : str
        Port name, unique within the block (``"torque"``, ``"stage[2].contact_force"``).
    unit : str
        SI unit (``"N.m"``, ``"rad/s"``, ``"1"`` for dimensionless).
    description : str
        What it is.
    discrete : bool
        Piecewise constant between the block's own sample instants: never extrapolated.
    nominal : float
        Typical magnitude (> 0): the master's coupling error estimate is relative to the larger
        of it and the largest magnitude seen so far.
    """

    name: str
    unit: str
    description: str = ""
    discrete: bool = False
    nominal: float = 1.0

    def __post_init__(self) -> None:
        if not (self.nominal > 0.0 and self.nominal < float("inf")):
            raise ValueError(f"port {self.name}: nominal = {self.nominal!r} must be a finite number > 0")


class StepRefused(RuntimeError):
    """A block refused a step (fmi2Discard for an FMU); its state is as before the call.

    Attributes
    ----------
    block : str
        Name of the block.
    time : float
        Start of the refused step [s].
    step : float
        Its size [s].
    reason : str
        Why (the FMU's log message, or the Python block's).
    """

    def __init__(self, block: str, time: float, step: float, reason: str) -> None:
        super().__init__(f"block {block!r} refused the step t = {time!r} s, h = {step!r} s: {reason}")
        self.block, self.time, self.step, self.reason = block, time, step, reason


class Block(ABC):
    """One block of the co-simulation (see module docstring).

    Attributes
    ----------
    name : str
        Instance name, used in connections as ``"name.port"``.
    inputs, outputs : tuple of Port
        The block's ports, in the order of the value lists.
    interpolates_inputs : bool
        True: :meth:`set_inputs` accepts slopes and the block uses them over the step.
    feedthrough : bool
        True: the outputs depend on the inputs at the same instant (:meth:`update_outputs`).
    """

    name: str = ""
    inputs: tuple[Port, ...] = ()
    outputs: tuple[Port, ...] = ()
    interpolates_inputs: bool = False
    feedthrough: bool = False

    @abstractmethod
    def set_inputs(self, values: Sequence[float], slopes: Sequence[float] | None = None) -> None:
        """Inputs for the next step: values at its start and, if interpolating, slopes [unit/s]."""

    @abstractmethod
    def get_outputs(self) -> list[float]:
        """Outputs at the current communication point, in the order of :attr:`outputs`."""

    @abstractmethod
    def do_step(self, t: float, h: float) -> None:
        """Advance from ``t`` to ``t + h`` [s].

        Raises
        ------
        StepRefused
            The step cannot be taken; the block's state is exactly as before the call.
        """

    def select_outputs(self, ports: Sequence[int]) -> bool:
        """Offer to give only the outputs at positions ``ports`` (ascending) of :attr:`outputs`.

        A block that agrees returns True and from then on :meth:`get_outputs` returns those
        values only, in that order (the master asks for the outputs that are connected or
        recorded; an FMU then reads fewer variables).  The default keeps every output: False.
        """
        return False

    def update_outputs(self, t: float) -> None:
        """Recompute the outputs at ``t`` from the inputs just set (feedthrough blocks only)."""

    @abstractmethod
    def get_state(self) -> Any:
        """A snapshot of the complete state (for roll-back)."""

    @abstractmethod
    def set_state(self, state: Any) -> None:
        """Restore a snapshot taken by :meth:`get_state`."""

    def free_state(self, state: Any) -> None:
        """Release a snapshot (FMUs free the memory; Python blocks need nothing)."""

    def terminate(self) -> None:
        """End the run and release resources."""

    # ---- helpers ----------------------------------------------------------------------------
    def input_names(self) -> list[str]:
        return [p.name for p in self.inputs]

    def output_names(self) -> list[str]:
        return [p.name for p in self.outputs]


class PythonBlock(Block):
    """Base of the plain Python blocks: state is the instance's ``__dict__`` minus constants.

    Subclasses keep their mutable state in attributes listed in :attr:`_state_attrs`;
    :meth:`get_state` deep-copies them, :meth:`set_state` puts copies back.  Inputs are kept in
    ``self.u`` (values at the step start) and ``self.du`` (slopes, zero when not given).
    """

    _state_attrs: tuple[str, ...] = ()

    def __init__(self, name: str) -> None:
        self.name = name
        self.u = [0.0] * len(self.inputs)
        self.du = [0.0] * len(self.inputs)

    def set_inputs(self, values: Sequence[float], slopes: Sequence[float] | None = None) -> None:
        if len(values) != len(self.inputs):
            raise ValueError(f"{self.name}: {len(values)} input values for {len(self.inputs)} inputs")
        self.u = list(map(float, values))
        self.du = [0.0] * len(values) if slopes is None else list(map(float, slopes))

    def get_state(self) -> Any:
        return copy.deepcopy({a: getattr(self, a) for a in self._state_attrs + ("u", "du")})

    def set_state(self, state: Any) -> None:
        for a, v in copy.deepcopy(state).items():
            setattr(self, a, v)
