"""The most halvings of a macro step a retry may take: its own module so that argument parsing
(``prsm-ema run --retry N``) checks the range without importing the co-simulation master."""

from __future__ import annotations

__all__ = ["MAX_HALVINGS"]

#: most halvings of a macro step a RetryPolicy allows (2**30 substeps)
MAX_HALVINGS = 30
