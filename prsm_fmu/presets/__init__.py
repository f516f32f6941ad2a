"""Registry of parameter sets taken from the papers.

One module per source (``li2021`` … ``recirculating_article``); each module's docstring cites the paper
(as docs/references.md names it) and section and states every assumption, and each exposes ``PRESETS``: a mapping from registry
key to a function returning the parameters.  :func:`load` returns them validated.
"""

from __future__ import annotations

import functools
import importlib
from typing import Callable, Union

from ..kinematics import RecirculatingParams
from ..params import MechanismParams

Params = Union[MechanismParams, RecirculatingParams]

#: the source modules whose ``PRESETS`` the registry collects
MODULES = ("li2021", "kinematics_article", "assembly_article", "friction_article", "recirculating_article")


@functools.cache
def _registry() -> dict[str, Callable[[], Params]]:
    registry: dict[str, Callable[[], Params]] = {}
    for module_name in MODULES:
        module = importlib.import_module(f"{__name__}.{module_name}")
        for key, factory in module.PRESETS.items():
            if key in registry:
                raise RuntimeError(f"preset {key!r} is defined twice (again in {module_name})")
            registry[key] = factory
    return registry


def names() -> tuple[str, ...]:
    """Registry keys of every preset, sorted, for listing and for ``load``.

    Returns
    -------
    tuple of str
    """
    return tuple(sorted(_registry()))


def load(name: str) -> Params:
    """Build and validate a preset by its registry key.

    Parameters
    ----------
    name : str
        Registry key, e.g. ``"li2021_two_stage"``; see :func:`names`.

    Returns
    -------
    MechanismParams or RecirculatingParams
        Validated parameters in SI units.

    Raises
    ------
    ValueError
        If ``name`` is unknown (the message lists the known names), or if the preset's data
        fail validation.
    """
    try:
        factory = _registry()[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown preset {name!r}: must be one of {', '.join(names())}") from None
    return factory().validate()
