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

from .names import column, element_name

if TYPE_CHECKING:
    from .scene import Scene


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

    def to_dict(self) -> dict[str, Any]:
        out = dict(impacts=self.impacts, peak_force_N=self.peak_force_N, peak_mean_force_N=self.peak_mean_force_N,
                   dissipated_energy_J=self.dissipated_energy_J, max_penetration_m=self.max_penetration_m,
                   first_impact_s=self.first_impact_s)
        if self.step_over_time_scale is not None:
            out["step_over_time_scale"] = self.step_over_time_scale
        return out


@dataclass(frozen=True)
class BuildingSummary:
    """One building over a run: peak floor displacement (and where, when), peak drift, base shear;
    and its storeys' inelastic demand (``building.fmu``'s outputs at the end of the run):

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
            scene=self.scene, description=self.description, coupling=self.coupling, step_s=self.step_s,
            stop_time_s=self.stop_time_s, instances=list(self.instances), peak_force_N=self.peak_force_N,
            impacts=self.impacts, dissipated_energy_J=self.dissipated_energy_J,
            buildings={name: b.to_dict() for name, b in self.buildings.items()},
            contacts={name: c.to_dict() for name, c in self.contacts.items()},
            energy_initial_J=self.energy_initial_J, energy_input_J=self.energy_input_J,
            energy_kinetic_J=self.energy_kinetic_J, energy_strain_J=self.energy_strain_J,
            energy_damping_J=self.energy_damping_J, energy_contact_J=self.energy_contact_J,
            energy_contact_stored_J=self.energy_contact_stored_J, energy_hysteretic_J=self.energy_hysteretic_J,
            energy_residual_J=self.energy_residual_J, energy_residual_relative=self.energy_residual_relative)
        out.update(self.cost.to_dict())
        out["warnings"] = list(self.warnings)
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
        first_impact_s=float(times[0]) if times.size else None,
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


def _final_row(result: SimulationResult, name: str, variable: str, n: int) -> np.ndarray | None:
    """``variable[1..n]`` of instance ``name`` at the end of the run (None if the run has not
    got it: the final read, whatever history.csv keeps)."""
    columns = [column(name, element_name(variable, i)) for i in range(1, n + 1)]
    if not all(result.known(c) for c in columns):
        return None
    return np.array([result.value_at_end(c) for c in columns])


def _building_summary(result: SimulationResult, name: str, n: int) -> BuildingSummary:
    """Peaks of a building: the largest of those located inside the steps by the building
    (``x_peak``, ``drift_peak``) and those seen at the step ends; the time of the peak
    displacement is the step end where that floor's largest sampled ``|x|`` was seen."""
    xs = [column(name, element_name("x", i)) for i in range(1, n + 1)]
    if all(c in result.peaks for c in xs):
        sampled = np.array([result.peaks[c][0] for c in xs])
        sampled_time = np.array([result.peaks[c][1] for c in xs])
    else:
        x = np.abs(np.column_stack([result[c] for c in xs]))
        rows = np.argmax(x, axis=0)
        sampled = x[rows, np.arange(n)]
        sampled_time = result.time[rows]
    in_step = _in_step_peaks(result, name, "x_peak", n)
    peaks = sampled if in_step is None else np.maximum(sampled, in_step)
    fx = int(np.argmax(peaks))
    drift = _in_step_peaks(result, name, "drift_peak", n)
    if drift is None:
        d = np.abs(np.column_stack([result[column(name, element_name("drift", i))] for i in range(1, n + 1)]))
        drift = np.max(d, axis=0)
    fd = int(np.argmax(drift))
    spec = result.scene.instance(name)
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
        n_storeys=n, peak_displacement_m=float(peaks[fx]), peak_displacement_floor=fx + 1,
        peak_displacement_time_s=float(sampled_time[fx]), peak_drift_m=float(drift[fd]),
        peak_drift_storey=fd + 1, peak_base_shear_N=_peak(result, column(name, "base_shear")),
        hysteresis=hysteresis, peak_ductility=peak_mu, peak_ductility_storey=storey_mu,
        residual_drift_m=residual_m, residual_drift_storey=residual_storey,
        hysteretic_energy_J=_final(result, column(name, "E_hysteretic")))


def summarize(result: SimulationResult) -> Summary:
    """The numbers a person wants from a run (SI units in the names)."""
    scene = result.scene
    contacts = {c.name: _contact_summary(result, c.name) for c in scene.contacts}
    buildings = {b.name: _building_summary(result, b.name, scene.n_storeys(b.name)) for b in scene.buildings}
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
        cost=result.cost, warnings=sampling_warnings(contacts), energy_hysteretic_J=float(e["hysteretic"]))


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
                       f"its peak force by less (docs/accuracy.md); use resolve_impacts=true or coupling=\"adaptive\"")
    return out
