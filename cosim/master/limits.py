"""Bounds on what one run may cost, checked before anything runs (no FMU is loaded for it).

A request that would run for hours or eat the machine is refused in a fraction of a second
with the limit stated (:func:`check_run_size`, raising :class:`LimitError`, a
:class:`~cosim.master.scene.SceneError`: bad input, exit 2):

* **communication steps**: ``ceil(stop_time / step)`` at most ``max_steps``
  (:data:`DEFAULT_MAX_STEPS`, ``--max-steps`` raises it on purpose).  The adaptive coupling's
  refined steps count too: the stability guard stops a run whose accepted steps pass the same
  limit (:class:`cosim.master.guard.StabilityGuard`);
* **memory**: the history is kept in memory (``rows x columns`` float64, twice while the result
  is assembled); it must fit in half the memory the system reports available.

The free space for the output files is checked by :mod:`cosim.files` when the folder is
claimed, from :meth:`RunSize.output_bytes`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..files import PLOT_BYTES, history_bytes
from .scene import SceneError
from .system import output_names

if TYPE_CHECKING:
    from .scene import Scene

#: Default bound on a run's communication steps.  The bundled scenes take 1000-4600 steps and
#: the finest runs of the accuracy tables 160 000 (0.25 ms over 40 s); a million steps is about
#: two minutes of the default scene (~90 us per step) and a 0.5 GB history (67 columns).
#: Beyond it a request is much more likely a slip (a step in ms typed as s) than a wish.
DEFAULT_MAX_STEPS = 1_000_000
#: the history and its copy in the result (float64 each)
_HISTORY_COPIES = 2
#: share of the available memory a history may take (the rest: the FMUs, numpy, plots, others)
_MEMORY_SHARE = 0.5


class LimitError(SceneError):
    """A run would exceed a bound (steps, memory, disk); the message states the limit and the
    flag that raises it."""


@dataclass(frozen=True)
class RunSize:
    """The size of a run planned from its scene: communication ``steps`` (at the scene's step),
    history ``columns`` (every output of every instance)."""

    steps: int
    columns: int

    @property
    def rows(self) -> int:
        return self.steps + 1

    @property
    def memory_bytes(self) -> int:
        """Memory the history takes (bytes), with its copy."""
        return _HISTORY_COPIES * 8 * self.rows * (self.columns + 1)

    def output_bytes(self, plots: bool = True) -> int:
        """Upper estimate of the result folder's size (bytes): history.csv, summary.json, plots."""
        return history_bytes(self.rows, self.columns) + 64 * 1024 + (PLOT_BYTES if plots else 0)


def scene_columns(scene: "Scene") -> int:
    """How many output columns a run of ``scene`` records (the System's ``columns``)."""
    interfaces = scene.interfaces or {}
    if not interfaces:
        from .interface import interfaces as declared

        interfaces = declared()
    return sum(len(output_names(spec, interfaces[spec.fmu], type_))
               for spec in scene.instances() for type_ in ("Real", "Integer", "Boolean"))


def available_memory() -> int | None:
    """Memory the system reports available to new allocations (bytes; Linux), or None."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _size(n: float) -> str:
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB", "EB"):
        if n < 1000 or unit == "EB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} EB"


def check_run_size(scene: "Scene", max_steps: int = DEFAULT_MAX_STEPS, stop_time: float | None = None,
                   step: float | None = None) -> RunSize:
    """The planned size of a run of ``scene`` (``stop_time``, ``step`` in s: the scene's unless
    given); raises :class:`LimitError` when it exceeds ``max_steps`` or the memory bound."""
    stop_time = scene.stop_time if stop_time is None else float(stop_time)
    step = scene.step if step is None else float(step)
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise LimitError(f"--max-steps {max_steps!r}: must be a whole number >= 1")
    ratio = stop_time / step
    if not math.isfinite(ratio) or ratio > max_steps:
        raise LimitError(
            f"stop_time = {stop_time:g} s ({scene.origin('stop_time')}) with step = {step:g} s "
            f"({scene.origin('step')}) is {ratio:.3g} communication steps, more than the limit of {max_steps:,} "
            f"(--max-steps): shorten stop_time, lengthen step, or raise --max-steps on purpose")
    size = RunSize(int(math.ceil(ratio - 1e-9)), scene_columns(scene))
    available = available_memory()
    if available is not None and size.memory_bytes > _MEMORY_SHARE * available:
        raise LimitError(
            f"{size.rows:,} history rows x {size.columns + 1} columns need {_size(size.memory_bytes)} of memory, "
            f"more than half of the {_size(available)} available (stop_time = {stop_time:g} s, step = {step:g} s): "
            f"shorten stop_time or lengthen step")
    return size
