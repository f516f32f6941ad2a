"""Enumeration values for FMI hosts driven from Python (fmpy's model description).

FMI 2.0 sets an Enumeration with ``fmi2SetInteger`` and its item's integer value; users name
the item (``fidelity = "dynamic"``).  :func:`enumeration_value` maps one onto the other from
the modelDescription's TypeDefinitions, so that no table of values is copied into a host.
Needs fmpy's ``ModelVariable`` only by duck typing (``name``, ``declaredType.items``).
"""

from __future__ import annotations

from typing import Any

__all__ = ["enumeration_value"]


def enumeration_value(variable: Any, value: Any) -> int:
    """The integer value of Enumeration ``variable``'s item ``value`` (item name or int).

    Parameters
    ----------
    variable : fmpy.model_description.ModelVariable
        An Enumeration variable (``variable.declaredType.items`` hold its items).
    value : str or int
        An item name, or an integer value (passed on unchecked: the FMU checks it).

    Raises
    ------
    ValueError
        If ``value`` is neither an item name nor an int (the message lists the items).
    """
    items = {i.name: int(i.value) for i in variable.declaredType.items}
    if isinstance(value, str) and value in items:
        return items[value]
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    raise ValueError(f"{variable.name} = {value!r} is not an item of "
                     f"{variable.declaredType.name}: must be one of "
                     f"{', '.join(f'{k} ({c})' for k, c in items.items())}")
