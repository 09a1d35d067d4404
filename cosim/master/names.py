"""FMI variable and instance names: the one parser of structured element names ``x[3]``.

FMI 2.0's structured naming writes element ``i`` (1-based) of an array variable ``x`` as
``x[i]``; the building FMU's floors are such elements (``x[3]``, ``F[3]``, ``m[1]``).  Every
module of the master that needs the base name or the index of a variable calls
:func:`element` (once per variable, when an FMU's interface is read; never per step).
"""
from __future__ import annotations

import re

_ELEMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\[(\d+)\]")


def element(name: str) -> tuple[str, int | None]:
    """``"x[3]"`` -> ``("x", 3)``; a scalar name -> ``(name, None)``."""
    match = _ELEMENT.fullmatch(name)
    if match:
        return match.group(1), int(match.group(2))
    return name, None


def element_name(base: str, index: int) -> str:
    """``("x", 3)`` -> ``"x[3]"``."""
    return f"{base}[{index}]"


def base_name(name: str) -> str:
    """The array a variable belongs to: ``"m[2]"`` -> ``"m"``, ``"gap"`` -> ``"gap"``."""
    return name.split("[", 1)[0]


def column(instance: str, variable: str) -> str:
    """The history column of ``variable`` of ``instance``: ``"left.x[3]"``."""
    return f"{instance}.{variable}"
