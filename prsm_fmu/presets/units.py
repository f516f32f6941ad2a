"""The papers' units in SI, in one place for every preset.

The papers give lengths in mm and moments of inertia in kg·mm².  1 mm = 1e-3 m, so
1 kg·mm² = 1 kg·(1e-3 m)² = 1e-6 kg·m²: the inertia factor is the square of the length
factor, and is written as such so that the two cannot disagree.
"""

from __future__ import annotations

#: metres per millimetre [m/mm]
MM = 1e-3
#: kg·m² per kg·mm² (= MM²)
KG_MM2 = MM * MM
