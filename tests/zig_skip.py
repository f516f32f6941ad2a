"""The one skip of the tests that build native binaries where Zig's C compiler is missing."""

from __future__ import annotations

import importlib.util

import pytest


def skip_without_ziglang(why: str = "the native FMU's binaries are compiled with its C compiler",
                         module_level: bool = True) -> None:
    """Skip the calling test module (or test, ``module_level=False``) without ziglang."""
    if importlib.util.find_spec("ziglang") is None:
        pytest.skip(f"ziglang is not installed (pip install -e \".[fmu]\"): {why}",
                    allow_module_level=module_level)
