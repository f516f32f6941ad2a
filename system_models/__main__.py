"""``python -m system_models`` = ``prsm-ema``."""

from .cli import entry

entry()
