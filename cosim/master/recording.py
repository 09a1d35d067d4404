"""What a run reads and keeps: rows at the output interval, peaks and impacts from every step.

A run reads after every step only what its coupling, its stability guard and its summary need
(the *watched* outputs, one ``fmi2GetReal`` per instance: :meth:`cosim.master.system.System.watch`)
and keeps:

* **rows** (``history.csv``, the plots): the *recorded* outputs at the communication points,
  at most one row per ``output_interval`` (the first point at or after each multiple of it, and
  the last); ``output_interval = 0`` keeps every point.  The recorded set is by default what
  the summary and the plots use (:func:`recorded_columns`), ``"all"`` every output, or a list
  of columns.  Where the adaptive coupling takes long steps (every gap provably open), rows are
  as far apart as its steps.
* **peaks from every step**: the largest ``|x[i]|`` of every floor and ``|base_shear|`` of
  every building and the largest mean force ``F`` and penetration ``delta`` of every contact,
  with the time of the step end where each was reached, whatever the output interval;
* **impact onsets**: every step in which a contact's ``impacts`` grew, as (start, end) times,
  and the contact FMU's ``t_onset`` of its first impact.  The counters (``impacts``, ``grazes``,
  ``contacts_ended``: one ``fmi2GetInteger``) are read only after a step that can have changed
  them, told by Real outputs read with the step anyway (:data:`COUNTER_SIGNALS`): a contact
  began (``t_onset`` moved), one ended (``t_separation`` moved) or the latest one reached
  ``graze_depth`` (``delta_max`` crossed it), the three ways pounding.fmu changes a counter; a
  contact FMU without ``t_separation`` is read after every step in which it had a force or a
  closed gap, or the step after;
* **every contact that ended** (``contacts_ended`` grew): the contact FMU's details of it, read
  with that step (``impacts.csv``: :func:`cosim.master.results.impact_table`);
* **the final value** of every output (read once at the end), including the buildings' in-step
  peaks (``x_peak``, ``drift_peak``).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Container, Iterable, Sequence

import numpy as np

from .models import storeys_are_linear
from .names import column, element_name
from .scene import SceneError

if TYPE_CHECKING:
    from .system import System

#: the recorded sets a run may ask for by name
RECORD_SETS = ("summary", "all")
#: most history values (rows x columns) a run may keep: 2e8 doubles = 1.6 GB
MAX_HISTORY_VALUES = 200_000_000


def building_columns(system: "System", name: str, variables: Iterable[str]) -> list[str]:
    """Columns ``name.var`` (scalars) and ``name.var[i]`` (every floor) that the system has."""
    have = set(system.columns)
    n = system.scene.n_storeys(name)
    out = []
    for var in variables:
        if column(name, var) in have:
            out.append(column(name, var))
        else:
            out += [c for c in (column(name, element_name(var, i)) for i in range(1, n + 1)) if c in have]
    return out


def recorded_columns(system: "System", record: str | Sequence[str] = "summary") -> list[str]:
    """The columns a run records: ``"summary"`` (what summary.json, the terminal summary and the
    plots use: floor displacements, energies, contact force, running peak force, penetration,
    dissipated energy and impacts), ``"all"``, or the given column names (each must exist)."""
    if isinstance(record, str):
        if record == "all":
            return list(system.columns)
        if record != "summary":
            raise SceneError(f"record = {record!r} is not allowed: one of {', '.join(RECORD_SETS)} or a list of "
                             f"columns")
        out = []
        for b in system.buildings:
            out += building_columns(system, b.name, ("x", "E_kinetic", "E_strain", "E_damping", "E_hysteretic",
                                                     "E_input", "E_external"))
            if not storeys_are_linear(b.spec):      # the storey loops (output.plot_storey_loops)
                out += building_columns(system, b.name, ("drift", "V"))
        have = set(system.columns)
        for c in system.contacts:
            out += [x for x in (column(c.name, v) for v in ("F", "F_max", "delta", "E_dissipated", "impacts"))
                    if x in have]
        return out
    unknown = [c for c in record if c not in system.columns]
    if unknown:
        raise SceneError(f"record: no column {unknown[0]!r}; columns are instance.variable, e.g. "
                         f"{system.columns[0]!r}")
    return list(dict.fromkeys(record))


def tracked_columns(system: "System") -> list[str]:
    """What every step must read for the peaks and impact onsets (:class:`Recorder`)."""
    out = []
    for b in system.buildings:
        out += building_columns(system, b.name, ("x", "base_shear"))
    have = set(system.columns)
    for c in system.contacts:
        out += [x for x in (column(c.name, "F"), column(c.name, "delta")) if x in have]
    return out


#: a contact FMU's outputs that describe its latest contact (``impacts.csv``), read after every step
IMPACT_DETAILS = ("t_onset", "v_impact", "F_peak", "delta_max", "contact_time", "E_last", "CR_achieved")


def impact_detail_columns(system: "System") -> list[str]:
    """What every step must read to describe each contact that ends in it (:class:`Recorder`)."""
    have = set(system.columns)
    return [x for c in system.contacts for x in (column(c.name, v) for v in IMPACT_DETAILS) if x in have]


#: a contact FMU's Real outputs that move in every step in which one of its counters does: a
#: contact began (``t_onset``), ended (``t_separation``) or reached ``graze_depth``
#: (``delta_max`` crossed it); the master reads the counters only then (:class:`Recorder`)
COUNTER_SIGNALS = ("t_onset", "t_separation", "delta_max")


def counters_may_have_moved(before: Sequence[float], now: Sequence[float], graze_depth: float) -> bool:
    """Whether a contact's counters can have changed in a step, from its :data:`COUNTER_SIGNALS`
    ``(t_onset, t_separation, delta_max)`` after the step before (``before``) and after this one
    (``now``), and its ``graze_depth`` (m).  pounding.fmu moves a counter only when a contact
    begins (``impacts`` at graze_depth 0: ``t_onset`` is set to its onset time, later than any
    earlier onset), ends (``grazes``, ``contacts_ended``: ``t_separation`` is set to the end of the
    step) or reaches ``graze_depth`` (``impacts``: ``delta_max``, reset to 0 at each onset, rises
    from below it to at least it; a contact that began in the step moved ``t_onset`` already)."""
    return now[0] != before[0] or now[1] != before[1] or before[2] < graze_depth <= now[2]


def counter_signal_columns(system: "System") -> list[str]:
    """The :data:`COUNTER_SIGNALS` of every contact that has them all (read after every step)."""
    have = set(system.columns)
    out = []
    for c in system.contacts:
        cols = [column(c.name, v) for v in COUNTER_SIGNALS]
        if all(x in have for x in cols):
            out += cols
    return out


class Recorder:
    """Rows at the output interval, peaks and impact onsets from every step (module docstring)."""

    def __init__(self, system: "System", stop_time: float, interval: float, columns: Sequence[str]):
        if not (interval >= 0.0 and math.isfinite(interval)):
            raise SceneError(f"output_interval = {interval!r} s must be a number >= 0 (0: every communication point)")
        self.system = system
        self.stop_time = float(stop_time)
        self.interval = float(interval)
        n_y = system.y.size
        index = {c: i for i, c in enumerate(system.columns)}
        self.columns = list(columns)
        self._real = np.array([index[c] for c in self.columns if index[c] < n_y], dtype=np.intp)
        self._int = np.array([index[c] - n_y for c in self.columns if index[c] >= n_y], dtype=np.intp)
        recorded_ints = {c for c in self.columns if index[c] >= n_y}
        self._int_ports = []
        for node in system.nodes:
            for port in (node.integers, node.booleans):
                names = {column(node.name, v) for v in port.names}
                kept = {column(node.name, "impacts")} if node.kind == "contact" else set()
                if names & recorded_ints - kept:
                    self._int_ports.append(port)
        self.columns = [system.columns[i] for i in self._real] + [system.columns[n_y + i] for i in self._int]
        width = max(len(self.columns), 1)
        rows = (int(self.stop_time / self.interval) + 2) if self.interval > 0.0 else 1024
        if self.interval > 0.0 and rows * width > MAX_HISTORY_VALUES:
            raise SceneError(
                f"output_interval = {self.interval:g} s over {self.stop_time:g} s keeps {rows} rows of {width} "
                f"columns, more than {MAX_HISTORY_VALUES:.0e} values: use a longer output interval or "
                f"record fewer columns")
        self.time = np.empty(min(rows, 1 << 16))
        self.values = np.empty((self.time.size, width))
        self.count = 0
        self.next_row = 0.0
        self._eps = 1e-9 * max(self.interval, 1e-12)
        # peaks of every step
        tracked = tracked_columns(system)
        signed = [c for c in tracked if c.rsplit(".", 1)[1] in ("F", "delta")]
        absolute = [c for c in tracked if c not in signed]
        self._abs_cols, self._signed_cols = absolute, signed
        # one running maximum per tracked value, in one gather per step: an absolute peak is the
        # larger of the running maxima of x and of -x (the same number), reached when the first of
        # them reached it (peaks())
        a = [index[c] for c in absolute]
        self._peak_index = np.array(a + a + [index[c] for c in signed], dtype=np.intp)
        self._peak_sign = np.array([1.0] * len(a) + [-1.0] * len(a) + [1.0] * len(signed))
        self._peak = np.zeros(self._peak_index.size)
        self._peak_time = np.zeros(self._peak_index.size)
        # impact onsets of every step
        self._contacts = []
        self._ended = {}
        for node in system.contacts:
            names = node.integers.names
            if "impacts" in names:
                self._contacts.append((node, names.index("impacts"), index[column(node.name, "F")],
                                       index[column(node.name, "delta")]))
            details = [column(node.name, v) for v in IMPACT_DETAILS]
            if "contacts_ended" in names and "grazes" in names and all(c in index for c in details):
                self._ended[node.name] = (names.index("contacts_ended"), names.index("grazes"),
                                          [index[c] for c in details])
        self.impacts = {node.name: 0 for node, *_ in self._contacts}
        # per contact with the counter signals: their places in y, graze_depth (m, as the
        # instance has it) and the values after the previous step (start(), track())
        signals = set(counter_signal_columns(system))
        self._signals: dict[str, tuple[int, int, int, float]] = {}
        for node, *_ in self._contacts:
            cols = [column(node.name, v) for v in COUNTER_SIGNALS]
            if all(c in signals for c in cols):
                self._signals[node.name] = (*(index[c] for c in cols), float(node.spec.value("graze_depth")))
        self._seen: dict[str, tuple[float, float, float]] = {}
        self._counts = {name: (0, 0) for name in self._ended}
        #: contact -> rows of impacts.csv for every contact that ended (None: not tracked)
        self.impact_rows: list[dict] | None = [] if self._ended else None
        #: contact -> the FMU's t_onset of its first impact (s)
        self.first_onsets: dict[str, float] = {}
        self._active = {node.name: False for node, *_ in self._contacts}
        self.onsets: dict[str, list[tuple[float, float]]] = {node.name: [] for node, *_ in self._contacts}

    def start(self, t0: float) -> None:
        """The state at ``t0`` (after initialisation, every output read): the first row, the
        peaks' starting values, the impact counters."""
        y = self.system.y
        y.take(self._peak_index, out=self._peak)
        self._peak *= self._peak_sign
        self._peak_time[:] = t0
        for node, i_impacts, i_F, i_delta in self._contacts:
            self.impacts[node.name] = int(node.integers.values[i_impacts])
            if node.name in self._signals:
                i_onset, i_sep, i_dmax, _ = self._signals[node.name]
                self._seen[node.name] = (y.item(i_onset), y.item(i_sep), y.item(i_dmax))
            self._active[node.name] = y.item(i_F) != 0.0 or y.item(i_delta) >= 0.0
            if node.name in self._ended:
                j_ended, j_grazes, _ = self._ended[node.name]
                self._counts[node.name] = (int(node.integers.values[j_ended]), int(node.integers.values[j_grazes]))
        self.record(t0)

    # -- rows ------------------------------------------------------------------------------------
    def due(self, t_next: float) -> bool:
        """True if a step ending at ``t_next`` (s) is recorded."""
        return t_next >= self.next_row - self._eps or t_next >= self.stop_time - 1e-9 * self.stop_time

    def record(self, t: float) -> None:
        """Keep the recorded columns now (their values were read with the step)."""
        if self.count == self.time.size:
            self.time = np.resize(self.time, 2 * self.time.size)
            self.values = np.resize(self.values, (2 * self.values.shape[0], self.values.shape[1]))
            if self.time.size * self.values.shape[1] > MAX_HISTORY_VALUES:
                raise SceneError(f"the history passed {MAX_HISTORY_VALUES:.0e} values at t = {t:g} s: use a "
                                 f"longer output_interval or record fewer columns")
        k = self.count
        self.time[k] = t
        row = self.values[k]
        nr = self._real.size
        row[:nr] = self.system.y[self._real]
        if self._int.size:
            row[nr:nr + self._int.size] = self.system.ints[self._int]
        self.count += 1
        if self.interval > 0.0:
            self.next_row = (math.floor(t / self.interval + 1e-9) + 1) * self.interval

    def read_ints(self) -> None:
        """Read the recorded Integer and Boolean outputs (a contact's ``impacts`` is read by
        :meth:`track` after every step that can change it, so it is current already)."""
        for port in self._int_ports:
            port.get()

    # -- every step ------------------------------------------------------------------------------------
    def track(self, t_start: float, t_end: float, asleep: Container[str] = ()) -> None:
        """Peaks and impact onsets of the step ``[t_start, t_end]`` that was just accepted.

        ``asleep``: contacts not called since before the step (:mod:`cosim.master.dormancy`).  A
        contact falls asleep only with nothing to do (no force, the gap open) at a step's start, as
        this read after the step before: inactive then and since, its counters unchanged, so it
        is passed over."""
        y = self.system.y
        if self._peak_index.size:
            now = y[self._peak_index]
            now *= self._peak_sign
            up = now > self._peak
            first = up.argmax()                     # the first rise, or 0 if none (cheaper than any())
            if up[first]:
                self._peak[up] = now[up]
                self._peak_time[up] = t_end
        item = y.item
        was_active = self._active
        signals, seen = self._signals, self._seen
        for node, i_impacts, i_F, i_delta in self._contacts:
            name = node.name
            if name in asleep:
                continue
            signal = signals.get(name)
            if signal is not None:
                i_onset, i_sep, i_dmax, graze_depth = signal
                now = (item(i_onset), item(i_sep), item(i_dmax))
                read = counters_may_have_moved(seen[name], now, graze_depth)
                seen[name] = now
            else:
                active = item(i_F) != 0.0 or item(i_delta) >= 0.0
                read = active or was_active[name]
                was_active[name] = active
            if read:
                ints = node.integers.get()
                count = int(ints[i_impacts])
                if count > self.impacts[name]:
                    self.onsets[name].append((t_start, t_end))
                    if name not in self.first_onsets:
                        self.first_onsets[name] = y.item(self._ended[name][2][0]) if name in self._ended else t_start
                    self.impacts[name] = count
                if name in self._ended:
                    self._contact_ended(name, ints, t_end)

    def _contact_ended(self, name: str, ints, t_end: float) -> None:
        """Rows of impacts.csv for the contacts of ``name`` that ended in the step ending at
        ``t_end`` (as :func:`cosim.master.results.impact_table` reads them from a full history)."""
        j_ended, j_grazes, where = self._ended[name]
        ended, grazes = int(ints[j_ended]), int(ints[j_grazes])
        count, grazed = ended - self._counts[name][0], grazes - self._counts[name][1]
        self._counts[name] = (ended, grazes)
        if count <= 0:
            return
        nan = float("nan")
        for _ in range(count - 1):   # ended inside the same step as the detailed one
            self.impact_rows.append(dict(contact=name, kind="impact (not detailed)", t_onset_s=t_end,
                                         approach_speed_m_s=nan, peak_force_N=nan, max_penetration_m=nan,
                                         duration_s=nan, dissipated_energy_J=nan, CR_achieved=nan))
        t_onset, v, F, d, duration, E, CR = (self.system.y.item(i) for i in where)
        self.impact_rows.append(dict(contact=name, kind="graze" if grazed and count == 1 else "impact",
                                     t_onset_s=t_onset, approach_speed_m_s=v, peak_force_N=F, max_penetration_m=d,
                                     duration_s=duration, dissipated_energy_J=E, CR_achieved=CR))

    def peaks(self) -> dict[str, tuple[float, float]]:
        """``column -> (peak, time of the step end where it was reached)``: absolute values for
        floors and base shears, signed maxima for contact forces and penetrations."""
        n = len(self._abs_cols)
        peak, time = self._peak.tolist(), self._peak_time.tolist()
        out = {}
        for i, c in enumerate(self._abs_cols):
            up, down = peak[i], peak[n + i]         # the running maxima of x and of -x
            t = time[i] if up > down else time[n + i] if down > up else min(time[i], time[n + i])
            out[c] = (abs(max(up, down)), t)        # abs: |x| = 0 is +0.0 whatever the sign of x
        out.update(zip(self._signed_cols, zip(peak[2 * n:], time[2 * n:])))
        return out

    def history(self) -> tuple[np.ndarray, np.ndarray]:
        k = self.count
        return self.time[:k].copy(), self.values[:k].copy()
