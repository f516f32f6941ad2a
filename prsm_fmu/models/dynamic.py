"""Dynamic level: the Lagrange model of seed 000 §2 with one degree of freedom per carrier.

Generalized coordinates: the screw angle and the carrier angles (seed 000 Eq. 21).  The carriers
are driven only by screw–roller friction; their time constants are ~0.01–0.5 ms, so the system
is stiff: use the Rosenbrock stepper, or an explicit one with steps below the limit printed by
``benchmarks/step_cost.py``.  simulate and the FMU use the Rosenbrock stepper with the options
of ``simulate.TUNED_OPTIONS`` (Jacobian reuse, a first step bounded by the stiffness), which gave
the cheapest 1 ms steps at the reference solver's error.  Derivation: docs/model.md §3.
"""

from __future__ import annotations

from .base import Model


class DynamicModel(Model):
    """Rigid-body dynamic model with carrier dynamics (states: module docstring of base)."""

    fidelity = "dynamic"
    carriers = "dynamic"
