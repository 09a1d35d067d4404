"""The result of a run: its history, a typed summary and its cost (one shape for every application).

:class:`SimulationResult` is what :func:`cosim.master.simulate.simulate` returns (like
scipy's ``OdeResult``): the recorded outputs of every instance and the run's :class:`Cost`.
:func:`summarize` condenses it into a :class:`Summary` (its ``to_dict()`` is
``summary.json``); :class:`RunResult` (history, summary, cost, result folder) is what
:func:`cosim.master.runner.run_scene` returns.  Studies, the accuracy study and the
calibration read these fields; none re-derives them.  Writing them to files is
:mod:`cosim.master.output`.

Energy balance (J), from the outputs of the FMUs alone::

    E_initial + sum_buildings E_input(t)
        = sum_buildings (E_kinetic + E_strain + E_damping + E_hysteretic)(t)
          + sum_contacts (E_dissipated + E_stored)(t) + residual(t)

``E_initial`` is the mechanical energy the system starts with (the buildings' x0, v0 and
any contact closed at t = 0), ``E_input`` the work of the ground motion on the relative
motion, ``E_strain`` the elastic (stored) part of the storeys' energy, ``E_hysteretic`` what
yielding storeys dissipated (0 for linear storeys), ``E_stored = k delta^(n+1) / (n+1)`` the
elastic energy of a contact spring closed at t (``delta`` > 0, the contact's own output; zero
once it opens: a run that ends during an impact holds that energy in the spring, which is not
a residual).  The residual is the coupling's error: the work the buildings receive from the
mean contact forces minus what the contact FMUs account for.  ``energy_residual_relative``
divides by ``E_initial + E_input`` at the end.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from .impacts import contact_floor_accelerations
from .models import shear_building, storeys_are_linear
from .names import column, element_name

if TYPE_CHECKING:
    from .scene import Scene
    from .steplog import ContactSteps, ContactWindows


@dataclass(frozen=True)
class Cost:
    """What a run cost: ``wall_time_s`` (the simulation loop, s), accepted
    ``communication_steps``, ``rollbacks`` (rejected and retried steps), ``fmu_calls`` (every
    FMI call) and ``do_steps`` (fmi2DoStep calls per instance)."""

    wall_time_s: float
    communication_steps: int
    rollbacks: int
    fmu_calls: int
    do_steps: Mapping[str, int] = field(default_factory=dict)
    #: CPU time of the simulation loop (s, this process): what a benchmark on a shared machine
    #: compares (not a key of summary.json)
    cpu_time_s: float = float("nan")

    @property
    def do_step_calls(self) -> int:
        """fmi2DoStep calls over every instance."""
        return sum(self.do_steps.values())

    @property
    def us_per_fmu_call(self) -> float:
        """Wall time per FMI call (us)."""
        return 1e6 * self.wall_time_s / max(self.fmu_calls, 1)

    def to_dict(self) -> dict[str, Any]:
        """The cost keys of ``summary.json``."""
        return dict(wall_time_s=self.wall_time_s, communication_steps=self.communication_steps,
                    rollbacks=self.rollbacks, fmu_calls=self.fmu_calls, do_step_calls=self.do_step_calls)


@dataclass
class SimulationResult:
    """Every recorded output of a run, plus its cost.

    ``time`` (s), ``values[k, j]`` = column ``columns[j]`` (``instance.variable``) at
    ``time[k]``; ``strategy`` the coupling's name; ``stats`` its own counters (adaptive).
    """

    scene: "Scene"
    strategy: str
    time: np.ndarray
    columns: list[str]
    values: np.ndarray
    cost: Cost
    instances: list[str] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)   # strategy-specific counters (adaptive)
    #: every output at the end of the run (column -> value)
    final: dict[str, float] = field(default_factory=dict)
    #: column -> (peak, time of the step end it was reached): |x[i]|, |base_shear| of the
    #: buildings, F and delta (signed) of the contacts, taken from every step
    peaks: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: contact -> [(start, end) of every step in which its impacts counter grew]
    onsets: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    #: s, the history's row spacing (0: every communication point)
    output_interval: float = 0.0
    #: every output at t0, after initialisation (column -> value)
    initial: dict[str, float] = field(default_factory=dict)
    #: the rows of impacts.csv for every contact that ended, read with its step
    #: (:class:`cosim.master.recording.Recorder`; None: from the history)
    impact_rows: list[dict[str, Any]] | None = None
    #: contact -> the contact FMU's t_onset of its first impact (s), read with its step
    first_onsets: dict[str, float] = field(default_factory=dict)
    #: contact -> every fmi2DoStep its FMU took, with its inputs (:mod:`cosim.master.steplog`: what
    #: the replays of :mod:`cosim.master.impacts` step; empty: not logged)
    contact_steps: dict[str, "ContactSteps"] = field(default_factory=dict)
    #: the steps that hold a contact force, with the pounding buildings' states and inputs
    #: (:class:`cosim.master.steplog.ContactWindows`; None: not logged)
    contact_windows: "ContactWindows | None" = None

    @property
    def energy_residual_J(self) -> float:
        """Energy balance residual at the end (J), see the module docstring."""
        return float(final_energies(self)["residual"])

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"no column {column!r}") from None

    def has(self, column: str) -> bool:
        return column in self.columns

    def value_at_end(self, column: str) -> float:
        """The output's value at the end of the run (the final read, else the last row)."""
        if column in self.final:
            return float(self.final[column])
        return float(self[column][-1]) if self.has(column) else 0.0

    def known(self, column: str) -> bool:
        """True if the run has this output (recorded or read at the end)."""
        return column in self.final or self.has(column)


@dataclass(frozen=True)
class ContactSummary:
    """One contact instance over a run (SI units in the names)."""

    impacts: int
    peak_force_N: float
    peak_mean_force_N: float
    dissipated_energy_J: float
    max_penetration_m: float
    first_impact_s: float | None
    #: plain force law: the largest communication step / impact time scale seen (else None)
    step_over_time_scale: float | None = None
    #: the largest latched approach speed (m/s); not a key of summary.json
    peak_impact_velocity_m_s: float = 0.0
    #: contacts shallower than the contact's graze_depth (not impacts)
    grazes: int = 0

    def to_dict(self) -> dict[str, Any]:
        out = dict(impacts=self.impacts, grazes=self.grazes, peak_force_N=self.peak_force_N,
                   peak_mean_force_N=self.peak_mean_force_N,
                   dissipated_energy_J=self.dissipated_energy_J, max_penetration_m=self.max_penetration_m,
                   first_impact_s=self.first_impact_s)
        if self.step_over_time_scale is not None:
            out["step_over_time_scale"] = self.step_over_time_scale
        return out


@dataclass(frozen=True)
class BuildingSummary:
    """One building over a run: peak floor displacement (and where, when), peak drift, drift ratio
    and absolute floor acceleration (and where), base shear; per floor/storey lists of the peaks.

    Peaks are located inside the steps when the building FMU reports its own running peaks
    (``x_peak``, ``drift_peak``, ``a_peak``, ``drift_ratio_peak``; ``peaks_in_step`` True),
    else taken at the communication points.  A floor that pounds also gets the contact's
    contact force inside the steps (:func:`cosim.master.impacts.contact_floor_accelerations`):
    the building's own peak sees only the force it held over each step.

    Inelastic demand of its storeys (``building.fmu``'s outputs at the end of the run):

    * ``hysteresis``: the storey law (``linear``, ``bilinear``, ``bouc_wen``);
    * ``peak_ductility``: the largest ``mu[i]``, peak drift (located inside the steps) over the
      yield drift ``Fy[i] / k[i]``, and its storey; None when the building has no yield shear;
    * ``residual_drift_m``: the storey drift's plastic part ``drift_residual[i]`` at the end of
      largest magnitude (signed, m), and its storey; 0 for linear storeys;
    * ``hysteretic_energy_J``: energy dissipated by yielding (``E_hysteretic``).
    """

    n_storeys: int
    peak_displacement_m: float
    peak_displacement_floor: int
    peak_displacement_time_s: float
    peak_drift_m: float
    peak_drift_storey: int
    peak_base_shear_N: float
    peak_drift_ratio: float = 0.0
    peak_drift_ratio_storey: int = 1
    peak_acceleration_m_s2: float = 0.0
    peak_acceleration_floor: int = 1
    peaks_in_step: bool = False
    peak_displacements_m: tuple[float, ...] = ()
    peak_drifts_m: tuple[float, ...] = ()
    peak_drift_ratios: tuple[float, ...] = ()
    peak_accelerations_m_s2: tuple[float, ...] = ()
    hysteresis: str = "linear"
    peak_ductility: float | None = None
    peak_ductility_storey: int | None = None
    residual_drift_m: float = 0.0
    residual_drift_storey: int | None = None
    hysteretic_energy_J: float = 0.0

    @property
    def yields(self) -> bool:
        """True for a building with yielding storeys (bilinear or Bouc-Wen)."""
        return self.hysteresis != "linear"

    def to_dict(self) -> dict[str, Any]:
        return dict(n_storeys=self.n_storeys, peak_displacement_m=self.peak_displacement_m,
                    peak_displacement_floor=self.peak_displacement_floor,
                    peak_displacement_time_s=self.peak_displacement_time_s, peak_drift_m=self.peak_drift_m,
                    peak_drift_storey=self.peak_drift_storey, peak_base_shear_N=self.peak_base_shear_N,
                    peak_drift_ratio=self.peak_drift_ratio, peak_drift_ratio_storey=self.peak_drift_ratio_storey,
                    peak_acceleration_m_s2=self.peak_acceleration_m_s2,
                    peak_acceleration_floor=self.peak_acceleration_floor, peaks_in_step=self.peaks_in_step,
                    peak_displacements_m=list(self.peak_displacements_m), peak_drifts_m=list(self.peak_drifts_m),
                    peak_drift_ratios=list(self.peak_drift_ratios),
                    peak_accelerations_m_s2=list(self.peak_accelerations_m_s2),
                    hysteresis=self.hysteresis, peak_ductility=self.peak_ductility,
                    peak_ductility_storey=self.peak_ductility_storey, residual_drift_m=self.residual_drift_m,
                    residual_drift_storey=self.residual_drift_storey, hysteretic_energy_J=self.hysteretic_energy_J)


@dataclass(frozen=True)
class Summary:
    """The numbers a person wants from a run (SI units in the names); ``to_dict()`` is
    ``summary.json``.  Energies at the end of the run (J), see the module docstring."""

    scene: str
    description: str
    coupling: str
    step_s: float
    stop_time_s: float
    instances: list[str]
    peak_force_N: float
    impacts: int
    dissipated_energy_J: float
    buildings: dict[str, BuildingSummary]
    contacts: dict[str, ContactSummary]
    energy_initial_J: float
    energy_input_J: float
    energy_kinetic_J: float
    energy_strain_J: float
    energy_damping_J: float
    energy_contact_J: float
    energy_residual_J: float
    energy_residual_relative: float
    cost: Cost
    warnings: list[str] = field(default_factory=list)
    #: elastic energy held by contacts closed at the end (J), see the module docstring
    energy_contact_stored_J: float = 0.0
    energy_hysteretic_J: float = 0.0
    #: what ran, from the effective parameters (:func:`system_description`)
    system: str = ""
    #: the overrides applied to the scene file (their text)
    overrides: list[str] = field(default_factory=list)
    #: the scene as it ran, in the scene format (:meth:`cosim.master.scene.Scene.as_run`)
    scene_as_run: dict[str, Any] = field(default_factory=dict)
    #: package version, FMU and record files with their SHA-256 (:mod:`cosim.master.provenance`)
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def grazes(self) -> int:
        """Contacts of every level shallower than their graze_depth (not counted as impacts)."""
        return sum(c.grazes for c in self.contacts.values())

    @property
    def max_penetration_m(self) -> float:
        """Deepest penetration of any contact (m)."""
        return max([c.max_penetration_m for c in self.contacts.values()], default=0.0)

    @property
    def first_impact_s(self) -> float | None:
        """Time of the first impact of any contact (s), None without impacts."""
        firsts = [c.first_impact_s for c in self.contacts.values() if c.first_impact_s is not None]
        return min(firsts) if firsts else None

    @property
    def peak_impact_velocity_m_s(self) -> float:
        """Largest approach speed latched by any contact (m/s)."""
        return max([c.peak_impact_velocity_m_s for c in self.contacts.values()], default=0.0)

    def to_dict(self) -> dict[str, Any]:
        """``summary.json``: the keys and their order as the package has always written them."""
        out: dict[str, Any] = dict(
            scene=self.scene, description=self.description, system=self.system, overrides=list(self.overrides),
            coupling=self.coupling, step_s=self.step_s,
            stop_time_s=self.stop_time_s, instances=list(self.instances), peak_force_N=self.peak_force_N,
            impacts=self.impacts, grazes=self.grazes, dissipated_energy_J=self.dissipated_energy_J,
            buildings={name: b.to_dict() for name, b in self.buildings.items()},
            contacts={name: c.to_dict() for name, c in self.contacts.items()},
            energy_initial_J=self.energy_initial_J, energy_input_J=self.energy_input_J,
            energy_kinetic_J=self.energy_kinetic_J, energy_strain_J=self.energy_strain_J,
            energy_damping_J=self.energy_damping_J, energy_contact_J=self.energy_contact_J,
            energy_contact_stored_J=self.energy_contact_stored_J, energy_hysteretic_J=self.energy_hysteretic_J,
            energy_residual_J=self.energy_residual_J, energy_residual_relative=self.energy_residual_relative)
        out.update(self.cost.to_dict())
        out["warnings"] = list(self.warnings)
        out["scene_as_run"] = self.scene_as_run
        out["provenance"] = self.provenance
        return out


@dataclass
class RunResult:
    """One run of a scene (:func:`cosim.master.runner.run_scene`): the validated ``scene``, the
    history ``result``, its ``summary`` and ``cost``, and the result ``folder`` (None when
    nothing was written)."""

    scene: "Scene"
    result: SimulationResult
    summary: Summary
    folder: Path | None = None

    @property
    def cost(self) -> Cost:
        return self.result.cost


def _final(result: SimulationResult, name: str) -> float:
    return result.value_at_end(name)


def impact_times(result: SimulationResult, contact: str) -> np.ndarray:
    """End times (s) of the communication steps in which ``contact`` counted a new impact."""
    if contact in result.onsets:
        return np.array([end for _, end in result.onsets[contact]])
    counts = result[column(contact, "impacts")]
    new = np.flatnonzero(np.diff(counts) > 0) + 1
    return result.time[new]


def first_impact_time(result: SimulationResult, contact: str) -> float | None:
    """Onset time (s) of ``contact``'s first impact: the contact FMU's ``t_onset`` where its impact
    counter first rises (it counts an impact once the penetration reaches graze_depth, after
    the onset), else the start of that step; None without impacts."""
    if contact in result.onsets:          # tracked by the run, from every step
        return result.first_onsets.get(contact, result.onsets[contact][0][0] if result.onsets[contact] else None)
    counts = result[column(contact, "impacts")]
    new = np.flatnonzero(np.diff(counts) > 0)
    if not new.size:
        return None
    k = int(new[0]) + 1
    if result.has(column(contact, "t_onset")):
        return float(result[column(contact, "t_onset")][k])
    return float(result.time[k - 1])


def impact_onsets(result: SimulationResult) -> list[float]:
    """Start times (s) of the communication steps in which any contact counted a new impact,
    sorted (the resolved contact's onset lies in that step; the plain law's in the step before)."""
    times = []
    for c in result.scene.contacts:
        if c.name in result.onsets:
            times.extend(start for start, _ in result.onsets[c.name])
            continue
        counts = result[column(c.name, "impacts")]
        new = np.flatnonzero(np.diff(counts) > 0)
        times.extend(float(t) for t in result.time[new])
    return sorted(times)


#: the columns of ``impacts.csv``, with their units
IMPACT_COLUMNS = (("contact", ""), ("kind", ""), ("t_onset_s", "s"), ("approach_speed_m_s", "m/s"),
                  ("peak_force_N", "N"), ("max_penetration_m", "m"), ("duration_s", "s"),
                  ("dissipated_energy_J", "J"), ("CR_achieved", "1"))


def impact_table(result: SimulationResult) -> list[dict[str, Any]]:
    """One row per contact of every contact instance, sorted by onset: ``kind`` is ``impact``,
    ``graze`` (shallower than graze_depth) or ``in progress`` (not ended at the end of the run).

    Read from the contact FMU's outputs at the end of the step in which the contact ended
    (``contacts_ended`` rises; ``grazes`` rises with it for a graze): onset time, approach speed,
    peak force, largest penetration, duration, dissipated energy and achieved CR of that contact.
    Two contacts ending in one communication step (a fixed step longer than a bounce) leave the
    details of the last only: the others get a row of kind ``impact (not detailed)`` with its
    step's end time and no numbers.
    """
    nan = float("nan")
    if result.impact_rows is not None:   # read with every step by the run
        rows = list(result.impact_rows)
        for c in result.scene.contacts:
            if result.value_at_end(column(c.name, "in_contact")):
                at = (lambda variable: result.value_at_end(column(c.name, variable)))
                rows.append(dict(contact=c.name, kind="in progress", t_onset_s=at("t_onset"),
                                 approach_speed_m_s=at("v_impact"), peak_force_N=at("F_peak"),
                                 max_penetration_m=at("delta_max"), duration_s=at("contact_time"),
                                 dissipated_energy_J=nan, CR_achieved=nan))
        rows.sort(key=lambda r: r["t_onset_s"])
        return rows
    rows: list[dict[str, Any]] = []
    for c in result.scene.contacts:
        name = c.name
        if not result.has(column(name, "contacts_ended")):
            continue

        def at(variable, k):
            return float(result[column(name, variable)][k])

        ended = result[column(name, "contacts_ended")]
        grazes = result[column(name, "grazes")]
        for k in np.flatnonzero(np.diff(ended) > 0) + 1:
            count = int(ended[k] - ended[k - 1])
            grazed = int(grazes[k] - grazes[k - 1])
            for _ in range(count - 1):   # ended inside the same step as the detailed one
                rows.append(dict(contact=name, kind="impact (not detailed)", t_onset_s=float(result.time[k]),
                                 approach_speed_m_s=nan, peak_force_N=nan, max_penetration_m=nan, duration_s=nan,
                                 dissipated_energy_J=nan, CR_achieved=nan))
            rows.append(dict(contact=name, kind="graze" if grazed and count == 1 else "impact",
                             t_onset_s=at("t_onset", k), approach_speed_m_s=at("v_impact", k),
                             peak_force_N=at("F_peak", k), max_penetration_m=at("delta_max", k),
                             duration_s=at("contact_time", k), dissipated_energy_J=at("E_last", k),
                             CR_achieved=at("CR_achieved", k)))
        k = result.time.size - 1
        if result.has(column(name, "in_contact")) and result[column(name, "in_contact")][k]:
            rows.append(dict(contact=name, kind="in progress", t_onset_s=at("t_onset", k),
                             approach_speed_m_s=at("v_impact", k), peak_force_N=at("F_peak", k),
                             max_penetration_m=at("delta_max", k), duration_s=at("contact_time", k),
                             dissipated_energy_J=nan, CR_achieved=nan))
    rows.sort(key=lambda r: r["t_onset_s"])
    return rows


def energy_history(result: SimulationResult) -> dict[str, np.ndarray]:
    """Energy terms over time (J), summed over buildings / contacts."""
    scene = result.scene
    zero = np.zeros_like(result.time)

    def total(instances, variable):
        out = zero.copy()
        for name in instances:
            if result.has(column(name, variable)):
                out = out + result[column(name, variable)]
        return out

    buildings = [b.name for b in scene.buildings]
    contacts = [c.name for c in scene.contacts]
    kinetic = total(buildings, "E_kinetic")
    strain = total(buildings, "E_strain")
    stored = zero.copy()
    for spec in scene.contacts:
        if result.has(column(spec.name, "delta")):
            stored = stored + contact_stored_energy(result[column(spec.name, "delta")], float(spec.value("k")),
                                                    float(spec.value("n")))
    initial = kinetic[0] + strain[0] + stored[0]
    terms = dict(time=result.time, input=initial + total(buildings, "E_input"), kinetic=kinetic, strain=strain,
                 damping=total(buildings, "E_damping"), contact=total(contacts, "E_dissipated"), stored=stored,
                 external=total(buildings, "E_external"), hysteretic=total(buildings, "E_hysteretic"))
    terms["residual"] = terms["input"] - (kinetic + strain + terms["damping"] + terms["contact"] + stored
                                          + terms["hysteretic"])
    return terms


def contact_stored_energy(delta: np.ndarray, k: float, n: float) -> np.ndarray:
    """Elastic energy of a contact spring (J): ``k delta^(n+1) / (n+1)`` where closed (``delta`` > 0,
    m), 0 where open (as :meth:`fmu_src.contact_laws.ContactLaw.elastic_energy`)."""
    closed = np.clip(delta, 0.0, None)
    return k * closed ** (n + 1.0) / (n + 1.0)


def final_energies(result: SimulationResult) -> dict[str, float]:
    """The energy balance at the end of the run (J, see the module docstring), from the final
    values (and the values at t0 for the initial energy)."""
    scene = result.scene
    buildings = [b.name for b in scene.buildings]
    contacts = [c.name for c in scene.contacts]

    def total(instances, variable, at_start=False):
        out = 0.0
        for name in instances:
            col = column(name, variable)
            if at_start:
                if col in result.initial:
                    out += result.initial[col]
                elif result.has(col):
                    out += float(result[col][0])
            elif result.known(col):
                out += result.value_at_end(col)
        return out

    def stored(at_start):           # elastic energy of the contacts closed then
        return sum(float(contact_stored_energy(np.array(total([spec.name], "delta", at_start)),
                                               float(spec.value("k")), float(spec.value("n"))))
                   for spec in scene.contacts)

    initial = total(buildings, "E_kinetic", True) + total(buildings, "E_strain", True) + stored(True)
    e = dict(initial=initial, input=initial + total(buildings, "E_input"), kinetic=total(buildings, "E_kinetic"),
             strain=total(buildings, "E_strain"), damping=total(buildings, "E_damping"),
             contact=total(contacts, "E_dissipated"), stored=stored(False), external=total(buildings, "E_external"),
             hysteretic=total(buildings, "E_hysteretic"))
    e["residual"] = e["input"] - (e["kinetic"] + e["strain"] + e["damping"] + e["contact"] + e["stored"]
                                  + e["hysteretic"])
    return e


def _peak(result: SimulationResult, name: str, signed: bool = False) -> float:
    """The largest value of a column over every step (``signed``: of the value, else of its
    magnitude), from the run's peaks, else from the recorded rows."""
    if name in result.peaks:
        return result.peaks[name][0]
    values = result[name]
    return float(np.max(values) if signed else np.max(np.abs(values)))


def _contact_summary(result: SimulationResult, name: str) -> ContactSummary:
    f_max = column(name, "F_max")
    peak_force = result.value_at_end(f_max) if result.known(f_max) else _peak(result, column(name, "F"), True)
    if result.has(f_max):      # the running maximum, also where the run's end is not its largest
        peak_force = max(peak_force, float(np.max(result[f_max])))
    times = impact_times(result, name)
    ratio = result.stats.get("step_over_time_scale", {}).get(name)
    v_col = column(name, "v_impact")
    v_impact = result.value_at_end(v_col) if result.known(v_col) else 0.0
    if result.has(v_col):
        v_impact = max(abs(v_impact), float(np.max(np.abs(result[v_col]))))
    delta = column(name, "delta")
    return ContactSummary(
        impacts=int(_final(result, column(name, "impacts"))),
        peak_force_N=float(peak_force),
        peak_mean_force_N=_peak(result, column(name, "F"), True),
        dissipated_energy_J=_final(result, column(name, "E_dissipated")),
        max_penetration_m=float(max(0.0, _peak(result, delta, True))) if result.known(delta) else 0.0,
        first_impact_s=first_impact_time(result, name),
        grazes=int(_final(result, column(name, "grazes"))),
        # plain force law: how finely the master sampled its impacts
        step_over_time_scale=float(ratio) if ratio is not None else None,
        peak_impact_velocity_m_s=abs(v_impact))


def _in_step_peaks(result: SimulationResult, name: str, variable: str, n: int) -> np.ndarray | None:
    """A building's running peaks located inside the steps (``x_peak``, ``drift_peak``) at the
    end of the run, or None if the building does not output them."""
    cols = [column(name, element_name(variable, i)) for i in range(1, n + 1)]
    if all(c in result.final for c in cols):
        return np.array([result.final[c] for c in cols])
    return None


#: storey height (m) assumed for drift ratios when the building FMU has no ``storey_height``
DEFAULT_STOREY_HEIGHT = 3.0


def _sampled_peaks(result: SimulationResult, name: str, variable: str, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Per floor/storey largest ``|variable|`` seen at the step ends and the step end where it
    was (s): from every step (``result.peaks``) when the run tracked it, else from the recorded
    rows; None when neither has it."""
    cols = [column(name, element_name(variable, i)) for i in range(1, n + 1)]
    if all(c in result.peaks for c in cols):
        return (np.array([result.peaks[c][0] for c in cols]), np.array([result.peaks[c][1] for c in cols]))
    if all(result.has(c) for c in cols):
        values = np.abs(np.column_stack([result[c] for c in cols]))
        rows = np.argmax(values, axis=0)
        return values[rows, np.arange(n)], result.time[rows]
    return None


def _peaks(result: SimulationResult, name: str, variable: str, n: int) -> tuple[np.ndarray, bool]:
    """Per floor/storey peak of ``|variable|``: the larger of the FMU's in-step running peak
    ``<variable>_peak`` at the end of the run (True when it has one) and the step ends' peaks."""
    in_step = _in_step_peaks(result, name, f"{variable}_peak", n)
    sampled = _sampled_peaks(result, name, variable, n)
    if sampled is None:
        return (in_step if in_step is not None else np.zeros(n)), in_step is not None
    return (sampled[0] if in_step is None else np.maximum(sampled[0], in_step)), in_step is not None


def _final_row(result: SimulationResult, name: str, variable: str, n: int) -> np.ndarray | None:
    """``variable[1..n]`` of instance ``name`` at the end of the run (None if the run has not
    got it: the final read, whatever history.csv keeps)."""
    columns = [column(name, element_name(variable, i)) for i in range(1, n + 1)]
    if not all(result.known(c) for c in columns):
        return None
    return np.array([result.value_at_end(c) for c in columns])


def _building_summary(result: SimulationResult, name: str, n: int,
                      spikes: Mapping[int, float] | None = None) -> BuildingSummary:
    spec = result.scene.instance(name)
    x, in_step = _peaks(result, name, "x", n)
    d, d_in_step = _peaks(result, name, "drift", n)
    a, _ = _peaks(result, name, "a", n)
    base_shear = _peak(result, column(name, "base_shear"))
    # the step ends alone miss the peak between them (-13 % on kobe's left building, -1 % on
    # default_inelastic's, with long steps): building.fmu's running peak of |V[1]| inside the
    # steps (V_peak: k1 drift_peak[1] for linear storeys, located for yielding ones); a history
    # without it (older runs, other building FMUs) has, for linear storeys, k1 times the
    # in-step peak drift (V[1] = k1 drift[1]), for yielding ones the step ends' peak
    shear_peak = _in_step_peaks(result, name, "V_peak", 1)
    if shear_peak is not None:
        base_shear = max(base_shear, float(shear_peak[0]))
    elif d_in_step and storeys_are_linear(spec):
        base_shear = max(base_shear, shear_building(spec).stiffnesses[0] * float(d[0]))
    for floor, value in (spikes or {}).items():   # the contacts' instantaneous peak forces
        a[floor - 1] = max(a[floor - 1], value)
    heights = []
    for i in range(1, n + 1):
        try:
            heights.append(float(spec.value(element_name("storey_height", i))))
        except KeyError:                            # a building.fmu without storey heights
            heights.append(DEFAULT_STOREY_HEIGHT)
    ratio = d / np.array(heights)
    fx, fd, fr, fa = (int(np.argmax(v)) for v in (x, d, ratio, a))
    # when: the step end where that floor's largest |x| was seen (the in-step peak lies in an adjacent step)
    sampled = _sampled_peaks(result, name, "x", n)
    x_time = sampled[1] if sampled is not None else np.zeros(n)
    hysteresis = str(spec.value("hysteresis"))
    # the FMU's in-step peaks and end values (mu = 0 where a storey has no yield shear)
    mu = _final_row(result, name, "mu", n)
    yield_shear = any(float(spec.value(element_name("Fy", i))) > 0.0 for i in range(1, n + 1))
    peak_mu = storey_mu = None
    if mu is not None and yield_shear:
        storey_mu = int(np.argmax(mu)) + 1
        peak_mu = float(mu[storey_mu - 1])
    residual = _final_row(result, name, "drift_residual", n)
    residual_m, residual_storey = 0.0, None
    if residual is not None and hysteresis != "linear":
        residual_storey = int(np.argmax(np.abs(residual))) + 1
        residual_m = float(residual[residual_storey - 1])
    return BuildingSummary(
        n_storeys=n, peak_displacement_m=float(x[fx]), peak_displacement_floor=fx + 1,
        peak_displacement_time_s=float(x_time[fx]), peak_drift_m=float(d[fd]), peak_drift_storey=fd + 1,
        peak_base_shear_N=base_shear,
        peak_drift_ratio=float(ratio[fr]), peak_drift_ratio_storey=fr + 1, peak_acceleration_m_s2=float(a[fa]),
        peak_acceleration_floor=fa + 1, peaks_in_step=in_step, peak_displacements_m=tuple(map(float, x)),
        peak_drifts_m=tuple(map(float, d)), peak_drift_ratios=tuple(map(float, ratio)),
        peak_accelerations_m_s2=tuple(map(float, a)), hysteresis=hysteresis, peak_ductility=peak_mu,
        peak_ductility_storey=storey_mu, residual_drift_m=residual_m, residual_drift_storey=residual_storey,
        hysteretic_energy_J=_final(result, column(name, "E_hysteretic")))


#: |energy residual| / input energy above which a run ends with a warning (issue 15: 1 %); the
#: bundled scenes at their settings stay below 0.2 % (docs/accuracy.md)
ENERGY_RESIDUAL_LIMIT = 0.01
#: -residual / input energy above which the run is said to have created energy: the residual of a
#: consistent co-simulation is the contact's stored elastic energy plus its coupling error, >= 0
#: at the bundled scenes' settings (0 to +0.2 %); 0.1 % leaves room for round-off and the end of a
#: run inside an impact
ENERGY_CREATION_LIMIT = 0.001


def summarize(result: SimulationResult, provenance: Mapping[str, Any] | None = None, *,
              energy_limit: float = ENERGY_RESIDUAL_LIMIT, creation_limit: float = ENERGY_CREATION_LIMIT) -> Summary:
    """The numbers a person wants from a run (SI units in the names).  ``provenance``: what the run
    was made with (:func:`cosim.master.provenance.provenance`), kept as it is.  ``energy_limit``
    and ``creation_limit`` (fractions of the input energy) set when :func:`accuracy_warnings` speaks."""
    scene = result.scene
    contacts = {c.name: _contact_summary(result, c.name) for c in scene.contacts}
    spikes = contact_floor_accelerations(result)
    buildings = {b.name: _building_summary(result, b.name, scene.n_storeys(b.name), spikes.get(b.name))
                 for b in scene.buildings}
    e = final_energies(result)
    energy_in = e["input"]
    residual = e["residual"]
    return Summary(
        scene=scene.name, description=scene.description, coupling=result.strategy, step_s=scene.step,
        stop_time_s=float(result.time[-1]), instances=list(result.instances),
        peak_force_N=max([c.peak_force_N for c in contacts.values()], default=0.0),
        impacts=sum(c.impacts for c in contacts.values()),
        dissipated_energy_J=sum(c.dissipated_energy_J for c in contacts.values()),
        buildings=buildings, contacts=contacts,
        energy_initial_J=e["initial"], energy_input_J=energy_in, energy_kinetic_J=e["kinetic"],
        energy_strain_J=e["strain"], energy_damping_J=e["damping"],
        energy_contact_J=e["contact"], energy_contact_stored_J=e["stored"], energy_residual_J=residual,
        energy_residual_relative=residual / energy_in if energy_in > 0 else 0.0,
        cost=result.cost, warnings=sampling_warnings(contacts) + accuracy_warnings(
            residual, energy_in, result.strategy, scene.step, energy_limit, creation_limit),
        system=system_description(scene, result.value_at_end(column(scene.ground.name, "pga")) if scene.ground else None),
        overrides=list(scene.overrides), scene_as_run=scene.as_run(), provenance=dict(provenance or {}),
        energy_hysteretic_J=float(e["hysteretic"]))


def system_description(scene: "Scene", pga: float | None = None) -> str:
    """One line saying what runs, from the effective parameters (never the scene file's
    description, which an override can make wrong): buildings and their fundamental periods,
    the contact levels, gap and law, the record and its PGA (m/s^2, when known)."""
    from fmu_src.ground_records import G

    from .models import shear_building

    parts = []
    for b in scene.buildings:
        n = int(b.value("n_storeys"))
        parts.append(f"{b.name} {n}-storey (T1 = {float(shear_building(b).periods[0]):.3g} s)")
    text = " and ".join(parts) if len(parts) <= 2 else ", ".join(parts)
    if scene.contacts:
        def law(c):
            return f"gap {float(c.value('gap')):g} m, {c.value('model')} CR {float(c.value('CR')):g}"
        laws = {law(c) for c in scene.contacts}
        pairs = [(lv.floor_left, lv.floor_right) for lv in scene.levels]
        floors = sorted({f for f, g in pairs if f == g})
        if len(floors) == len(pairs) and len(floors) > 2 and floors == list(range(floors[0], floors[-1] + 1)):
            where = f"floors {floors[0]}-{floors[-1]}"
        else:
            where = "floor " + ", ".join(str(f) if f == g else f"{f}/{g}" for f, g in pairs)
        text += f"; pounding at {where}: " + ("; ".join(sorted(laws)) if len(laws) > 1 else laws.pop())
    if scene.ground is not None:
        record = str(scene.ground.value("record"))
        label = record if len(record) <= 40 else "..." + record[-37:]
        text += f"; under {label}" + (f" (PGA {pga / G:.3g} g)" if pga else "")
    else:
        text += "; free vibration"
    return text


#: plain-law step / impact time scale above which a run's summary warns (energy error ~ ratio)
SAMPLING_WARNING = 0.02


def sampling_warnings(contacts: Mapping[str, ContactSummary]) -> list[str]:
    """What a person must know before trusting the numbers of a run that completed: plain-law
    contacts stepped too coarsely to resolve their impacts."""
    out = []
    for name, c in contacts.items():
        ratio = c.step_over_time_scale or 0.0
        if ratio > SAMPLING_WARNING:
            out.append(f"{name}: plain force law stepped at up to {ratio:.2g} times the impact time scale: "
                       f"expect its dissipated energy off by about {ratio:.0%} at CR 0.65 (more at higher CR), "
                       f"its peak force by less, and impacts shorter than a few steps can be missed or merged "
                       f"(docs/accuracy.md); use resolve_impacts=true or coupling=\"adaptive\"")
    return out


def accuracy_warnings(residual: float, energy_in: float, coupling: str, step: float,
                      energy_limit: float = ENERGY_RESIDUAL_LIMIT,
                      creation_limit: float = ENERGY_CREATION_LIMIT) -> list[str]:
    """Warnings where a completed run lost accuracy: its energy balance residual (J) beyond
    ``energy_limit`` of the input energy (J), or energy created (residual below
    ``-creation_limit`` of it); each says what to change."""
    if energy_in <= 0.0:
        return []
    ratio = residual / energy_in
    remedy = (f"use coupling = \"adaptive\" (or \"gauss-seidel\") or a smaller step than h = {step:g} s"
              if coupling == "jacobi" else f"use a smaller step than h = {step:g} s")
    out = []
    if ratio < -creation_limit:
        out.append(f"the run created energy: the energy balance residual is {100 * ratio:.3g} % of the input "
                   f"(limit -{100 * creation_limit:.3g} %, --creation-limit): a contact force handed "
                   f"over late or too coarsely; {remedy}")
    elif abs(ratio) > energy_limit:
        out.append(f"energy balance residual {100 * ratio:.3g} % of the input (limit {100 * energy_limit:.3g} %, "
                   f"--energy-limit): the coupling lost accuracy, expect the impacts and peaks to be off too; "
                   f"{remedy}")
    return out
