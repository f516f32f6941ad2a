"""Quasi-static level: carriers held at their force equilibrium, one mechanical degree of freedom.

Each carrier turns at ζ*_k ω, the ratio at which the screw–roller slip has no component along
the carrier's generalized direction (so the friction's generalized force on the carrier
vanishes, docs/model.md §4).  ζ* depends only on the contact geometry, not on friction or load
(Li et al. (2021) §3.2).  The carriers' inertia is carried by the screw (J_Pk ζ_k² added to screw k).
Contact forces and friction are algebraic.  Exact at steady state; in transients it misses the
carriers' spin-up (Li et al. (2021) Fig. 3), which lasts ~5 carrier time constants.
"""

from __future__ import annotations

from .base import Model
from .slaved import SlavedLevel


class QuasiStaticModel(SlavedLevel, Model):
    """Carriers slaved at their equilibrium ratio; friction and contact forces algebraic."""

    fidelity = "quasi-static"
    carriers = "equilibrium"
