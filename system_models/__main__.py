"""``python -m system_models`` = ``prsm-ema``."""

import sys

from .cli import main

sys.exit(main())
