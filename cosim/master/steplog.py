"""What a run's replays need, logged as the run goes: every step given to each contact FMU, and
the buildings' states over the steps that hold a contact force.

The true peaks of a run (:mod:`cosim.master.impacts`) replay each contact FMU's arithmetic and
solve the buildings inside the steps that hold an impact.  Neither may depend on the history
rows: the adaptive coupling takes long steps, contacts sleep and catch up in pieces of their
own (:mod:`cosim.master.dormancy`), and rows are kept at an output interval.  So the run logs,
beside the rows:

* :class:`LoggedContact`: every ``fmi2DoStep`` a contact FMU is given, with the start time, the
  step length and the inputs set before it (``t, h, x1, v1, x2, v2, gap_open``: 7 floats; the
  last, 1 for a step the master declared open, :meth:`LoggedContact.declare_open`).  It wraps the
  contact's instance, so the one place it appends is the one place every coupling, catch-up and
  replay steps a contact; a rejected step is taken out again when its FMU state is restored
  (``fmi2SetFMUstate`` truncates the log to its length when the state was saved).  Default
  scene: 259 rows (4012 without dormancy and long steps).
* :class:`ContactWindowLog`: at every accepted step in which some contact holds a force (or held
  one the step before), the step's ends and, at both ends, every floor's ``x, v, a`` of the
  buildings that pound and every contact's ``F``, with each such building's inputs over the
  step (held floor forces, the ground acceleration held or as knots).  Default scene: 222 of its
  543 steps (the contacts last about 0.2 s each).

Both are numbers of the run itself, whatever the recorded set or the output interval; they are
returned on :class:`cosim.master.results.SimulationResult` (``contact_steps``,
``contact_windows``), not written to ``history.csv``.
"""
from __future__ import annotations

from array import array
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .names import column, element_name

if TYPE_CHECKING:
    from .system import System


@dataclass(frozen=True)
class ContactSteps:
    """Every ``fmi2DoStep`` one contact FMU was given, in order: ``table[k] = (t, h, inputs...)``
    (s, s, then the inputs named ``inputs`` as set before the step)."""

    inputs: tuple[str, ...]         # the Real inputs, then ``gap_open`` (1.0: the step was declared open)
    table: np.ndarray

    def __len__(self) -> int:
        return self.table.shape[0]

    @property
    def t(self) -> np.ndarray:
        return self.table[:, 0]

    @property
    def h(self) -> np.ndarray:
        return self.table[:, 1]

    def input(self, name: str) -> np.ndarray:
        return self.table[:, 2 + self.inputs.index(name)]


class LoggedContact:
    """A contact FMU's instance that logs every ``fmi2DoStep`` it takes (module docstring).

    Everything else is the wrapped instance's (attribute access is forwarded): ports, counters,
    messages.  ``get_state`` notes the log's length with the state, ``set_state`` cuts the log back
    to it, ``reset`` empties it.  :meth:`declare_open` sets the FMU's ``gap_open`` input, logged
    with every step."""

    def __init__(self, instance: Any, inputs: Any):
        self._instance = instance
        self._values = inputs.values            # the input port's buffer: what the last set sent
        self._names = tuple(inputs.names) + ("gap_open",)
        self._width = 2 + len(self._names)
        self._log = array("d")                  # rows of (t, h, inputs..., gap_open), 8 bytes a number
        self._marks: dict[int, tuple[Any, int]] = {}    # id(state) -> (state, log length then)
        self._open = 0.0                        # gap_open as last set (1.0: true)
        self._open_port: Any = None             # made at the first declaration

    def __getattr__(self, name: str) -> Any:
        return getattr(self._instance, name)

    def do_step(self, t: float, h: float) -> None:
        self._instance.do_step(t, h)
        log = self._log
        log.append(t)
        log.append(h)
        log.fromlist(self._values.tolist())
        log.append(self._open)

    def declare_open(self, gap_open: bool) -> None:
        """Set the contact FMU's Boolean input ``gap_open``: the coming steps are proven open (true)
        or not (false) (fmu_src/pounding_slave.py).  The master declares one step open and clears
        the declaration right after it (:meth:`cosim.master.dormancy.Dormancy.wake`), so no FMU
        state it saves holds a declaration (the FMU's state would restore it, this log would not)."""
        if self._open_port is None:
            self._open_port = self._instance.boolean_port(["gap_open"])
        self._open_port.set([1 if gap_open else 0])
        self._open = 1.0 if gap_open else 0.0

    def get_state(self) -> Any:
        state = self._instance.get_state()
        self._marks[id(state)] = (state, len(self._log))
        return state

    def set_state(self, state: Any) -> None:
        self._instance.set_state(state)
        mark = self._marks.get(id(state))
        if mark is not None:
            del self._log[mark[1]:]

    def free_state(self, state: Any) -> None:
        self._marks.pop(id(state), None)
        self._instance.free_state(state)

    def reset(self) -> None:
        self._instance.reset()
        del self._log[:]
        self._marks.clear()

    def steps(self) -> ContactSteps:
        """The log so far."""
        table = np.frombuffer(self._log, dtype=float).reshape(-1, self._width).copy()
        return ContactSteps(self._names, table)


@dataclass(frozen=True)
class BuildingInputs:
    """One pounding building's inputs over each logged step: ``values[k]`` the input port's
    first ``width`` values (NaN beyond what step ``k`` sent), ``knots[k]`` its ``n_knots`` (0:
    ``ag`` held over the step; else ``t_knot``/``ag_knot`` interleaved from ``knot_offset``)."""

    names: tuple[str, ...]
    knot_offset: int
    values: np.ndarray
    knots: np.ndarray

    def held_forces(self, n: int) -> np.ndarray:
        """Floor forces (N) held over each step: ``(steps, n)``, 0 where no contact acts."""
        out = np.zeros((self.values.shape[0], n))
        for j, name in enumerate(self.names[:self.knot_offset]):
            if name.startswith("F["):
                out[:, int(name[2:-1]) - 1] = self.values[:, j]
        return out

    def ground(self, k: int, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
        """Ground acceleration (m/s^2) step ``k`` (from ``t0`` to ``t1``, s) was given, as a
        polyline ``(times, values)``: the knots, or the held ``ag`` at both ends."""
        count = int(self.knots[k])
        row = self.values[k]
        if count >= 2:
            o = self.knot_offset
            return row[o:o + 2 * count:2].copy(), row[o + 1:o + 2 * count:2].copy()
        ag = float(row[self.names.index("ag")]) if "ag" in self.names[:self.knot_offset] else 0.0
        return np.array([t0, t1]), np.array([ag, ag])


@dataclass(frozen=True)
class ContactWindows:
    """The steps of a run that hold a contact force (:class:`ContactWindowLog`): ``t0``, ``t1``
    (s) each step's ends; ``start``/``end`` the values of ``columns`` (every floor's ``x, v, a``
    of the pounding buildings, every contact's ``F``) at them; ``inputs`` each pounding
    building's inputs over the step."""

    columns: tuple[str, ...]
    t0: np.ndarray
    t1: np.ndarray
    start: np.ndarray
    end: np.ndarray
    inputs: dict[str, BuildingInputs]

    def __len__(self) -> int:
        return self.t0.size

    def at_start(self, name: str) -> np.ndarray:
        return self.start[:, self.columns.index(name)]

    def at_end(self, name: str) -> np.ndarray:
        return self.end[:, self.columns.index(name)]


def window_columns(system: "System") -> list[str]:
    """What :class:`ContactWindowLog` reads after every step: each contact's ``F``, then every
    floor's ``x``, ``v``, ``a`` of each building a contact acts on."""
    have = set(system.columns)
    out = [column(c.name, "F") for c in system.contacts if column(c.name, "F") in have]
    for b in _pounding_buildings(system):
        n = system.scene.n_storeys(b.name)
        out += [c for var in ("x", "v", "a") for c in (column(b.name, element_name(var, i)) for i in range(1, n + 1))
                if c in have]
    return out


def _pounding_buildings(system: "System") -> list:
    acted_on = {name for lv in system.scene.levels for name in (lv.left, lv.right)}
    return [b for b in system.buildings if b.name in acted_on]


class ContactWindowLog:
    """Logs :class:`ContactWindows` from a run's accepted steps (module docstring).

    After every accepted step (:meth:`track`) it gathers the watched values of
    :func:`window_columns` (one fancy index of ``y``) and keeps the step when a contact force is
    there now or was at its start (a Jacobi building holds the force of the step before)."""

    def __init__(self, system: "System"):
        self.system = system
        self.columns = tuple(window_columns(system))
        index = {c: i for i, c in enumerate(system.columns[:system.y.size])}
        self._index = np.array([index[c] for c in self.columns], dtype=np.intp)
        self._forces = sum(1 for c in self.columns if c.endswith(".F"))
        self._buildings = _pounding_buildings(system) if self._forces else []
        self._rows: list[tuple] = []
        self._prev = system.y[self._index]      # the values at t0: made after initialisation
        # the contact forces' places in y: looked at one by one (a few floats: cheaper than an
        # array reduction), a NaN counted as a force as an array's ``any`` does
        self._force_index = self._index[:self._forces].tolist()
        # whether a contact held a force at the end of the step before (kept, not looked for again)
        self._prev_force = any(map(system.y.item, self._force_index))

    def track(self, t0: float, t1: float) -> None:
        """The step ``[t0, t1]`` was accepted."""
        y = self.system.y
        now = y[self._index]
        force = any(map(y.item, self._force_index))
        held, self._prev_force = self._prev_force, force
        if force or held:
            inputs = []
            for b in self._buildings:
                # what the step was given: the coupling inputs, then its knots if it had any
                values = b.inputs.values
                if b.knot_count is None:
                    inputs.append((values.copy(), 0))
                else:
                    count = max(b.knots_set, 0)
                    inputs.append((values[:b.knot_offset + 2 * count].copy(), count))
            self._rows.append((t0, t1, self._prev, now, inputs))
        self._prev = now

    def windows(self) -> ContactWindows:
        rows = self._rows
        m = len(self.columns)
        inputs = {}
        for j, b in enumerate(self._buildings):
            width = max((r[4][j][0].size for r in rows), default=0)
            values = np.full((len(rows), width), np.nan)
            for k, r in enumerate(rows):
                v = r[4][j][0]
                values[k, :v.size] = v
            names = tuple(b.inputs.names) if rows else ()
            offset = b.knot_offset if b.knot_count is not None else len(names)
            inputs[b.name] = BuildingInputs(names, offset, values, np.array([r[4][j][1] for r in rows], dtype=int))
        return ContactWindows(self.columns, np.array([r[0] for r in rows], dtype=float),
                              np.array([r[1] for r in rows], dtype=float),
                              np.array([r[2] for r in rows], dtype=float).reshape(len(rows), m),
                              np.array([r[3] for r in rows], dtype=float).reshape(len(rows), m), inputs)
