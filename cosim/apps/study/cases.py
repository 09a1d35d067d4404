"""The cases of a study: the grid of its axes and each case's identity.

A case is the study's scene plus typed overrides (:class:`~cosim.master.scene.Override`) of
its varied variables; :func:`case_id` identifies it by a hash of those values, so that
``--resume`` recognises the cases already computed.
"""
from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from ...master.scene import Override


def _canonical(value: Any) -> Any:
    """The form a value is hashed in: every number as a float (``1`` and ``1.0`` are one case)."""
    if isinstance(value, bool):
        return value
    if isinstance(value, (int, float)):
        return repr(float(value))
    return str(value)


def case_id(values: Mapping[str, Any]) -> str:
    """Stable identity of a case: 12 hex digits of SHA-256 over its sorted varied values."""
    text = json.dumps([[k, _canonical(values[k])] for k in sorted(values)], separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def toml_literal(value: Any) -> str:
    """``value`` as the TOML literal ``--set`` parses back to the same value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string


def fixed_text(override: Override) -> str:
    """The form a fixed override is stored in ``study.json`` (``variable=<TOML literal>``),
    compared on ``--resume``; never parsed back."""
    key = f"{override.instance}.{override.variable}" if override.instance else override.variable
    return f"{key}={toml_literal(override.value)}"


@dataclass(frozen=True)
class Case:
    """One run of a study: its position, identity and varied values."""

    index: int
    id: str
    values: dict[str, Any]

    @property
    def overrides(self) -> list[Override]:
        return [Override.of(k, v) for k, v in self.values.items()]


@dataclass
class Axis:
    """One axis of the grid: one variable, or several zipped together (same length)."""

    variables: list[str]
    values: list[tuple]          # one tuple (one value per variable) per point of the axis

    def __len__(self) -> int:
        return len(self.values)


def grid(axes: Sequence[Axis]) -> list[Case]:
    """Every case of the axes' grid, the last axis varying fastest."""
    out = []
    for index, points in enumerate(itertools.product(*(a.values for a in axes))):
        values = {}
        for axis, point in zip(axes, points):
            values.update(zip(axis.variables, point))
        out.append(Case(index, case_id(values), values))
    return out
