"""Results of a run: summary numbers, ``history.csv``, ``summary.json`` and PNG plots.

Energy balance (J), from the outputs of the FMUs alone::

    E_initial + sum_buildings E_input(t)
        = sum_buildings (E_kinetic + E_strain + E_damping)(t)
          + sum_contacts E_dissipated(t) + residual(t)

``E_initial`` is the mechanical energy the buildings start with (x0, v0),
``E_input`` the work of the ground motion on the relative motion.  In a
monolithic solution the residual is the elastic energy stored in contacts
that are closed at t (zero once they open); in co-simulation it also holds
the coupling error: the work the buildings receive from the mean contact
forces minus what the contact FMUs account for.  ``energy_residual_relative``
divides by ``E_initial + E_input`` at the end.

Folders are written completely under a temporary sibling name and renamed
at the end: a folder under its final name is always complete.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .files import replaced_folder
from .master import SimulationResult
from .scene import _element


def _final(result: SimulationResult, column: str) -> float:
    return float(result[column][-1]) if result.has(column) else 0.0


def impact_times(result: SimulationResult, contact: str) -> np.ndarray:
    """End times (s) of the communication steps in which ``contact`` counted a new impact."""
    counts = result[f"{contact}.impacts"]
    new = np.flatnonzero(np.diff(counts) > 0) + 1
    return result.time[new]


def energy_history(result: SimulationResult) -> dict[str, np.ndarray]:
    """Energy terms over time (J), summed over buildings / contacts."""
    scene = result.scene
    zero = np.zeros_like(result.time)

    def total(instances, variable):
        out = zero.copy()
        for name in instances:
            if result.has(f"{name}.{variable}"):
                out = out + result[f"{name}.{variable}"]
        return out

    buildings = [b.name for b in scene.buildings]
    contacts = [c.name for c in scene.contacts]
    kinetic = total(buildings, "E_kinetic")
    strain = total(buildings, "E_strain")
    initial = kinetic[0] + strain[0]
    terms = dict(time=result.time, input=initial + total(buildings, "E_input"), kinetic=kinetic, strain=strain,
                 damping=total(buildings, "E_damping"), contact=total(contacts, "E_dissipated"),
                 external=total(buildings, "E_external"))
    terms["residual"] = terms["input"] - (kinetic + strain + terms["damping"] + terms["contact"])
    return terms


def summarize(result: SimulationResult) -> dict[str, Any]:
    """The numbers a person wants from a run (SI units in the key names)."""
    scene = result.scene
    contacts = {}
    for c in scene.contacts:
        name = c.name
        fmax = result[f"{name}.F_max"] if result.has(f"{name}.F_max") else result[f"{name}.F"]
        delta = result[f"{name}.delta"] if result.has(f"{name}.delta") else np.zeros(1)
        times = impact_times(result, name)
        contacts[name] = dict(
            impacts=int(_final(result, f"{name}.impacts")),
            peak_force_N=float(np.max(fmax)),
            peak_mean_force_N=float(np.max(result[f"{name}.F"])),
            dissipated_energy_J=_final(result, f"{name}.E_dissipated"),
            max_penetration_m=float(max(0.0, np.max(delta))),
            first_impact_s=float(times[0]) if times.size else None,
        )
        ratio = result.stats.get("step_over_time_scale", {}).get(name)
        if ratio is not None:       # plain force law: how finely the master sampled its impacts
            contacts[name]["step_over_time_scale"] = float(ratio)
    buildings = {}
    for b in scene.buildings:
        n = scene.n_storeys(b.name)
        x = np.abs(np.column_stack([result[f"{b.name}.x[{i}]"] for i in range(1, n + 1)]))
        d = np.abs(np.column_stack([result[f"{b.name}.drift[{i}]"] for i in range(1, n + 1)]))
        kx, fx = np.unravel_index(np.argmax(x), x.shape)
        kd, fd = np.unravel_index(np.argmax(d), d.shape)
        buildings[b.name] = dict(
            n_storeys=n,
            peak_displacement_m=float(x[kx, fx]), peak_displacement_floor=int(fx + 1),
            peak_displacement_time_s=float(result.time[kx]),
            peak_drift_m=float(d[kd, fd]), peak_drift_storey=int(fd + 1),
            peak_base_shear_N=float(np.max(np.abs(result[f"{b.name}.base_shear"]))),
        )
    e = energy_history(result)
    energy_in = float(e["input"][-1])
    residual = float(e["residual"][-1])
    summary: dict[str, Any] = dict(
        scene=scene.name,
        description=scene.description,
        coupling=result.strategy,
        step_s=scene.step,
        stop_time_s=float(result.time[-1]),
        instances=list(result.instances),
        peak_force_N=max([c["peak_force_N"] for c in contacts.values()], default=0.0),
        impacts=sum(c["impacts"] for c in contacts.values()),
        dissipated_energy_J=sum(c["dissipated_energy_J"] for c in contacts.values()),
        buildings=buildings,
        contacts=contacts,
        energy_initial_J=float(e["input"][0]),
        energy_input_J=energy_in,
        energy_kinetic_J=float(e["kinetic"][-1]),
        energy_strain_J=float(e["strain"][-1]),
        energy_damping_J=float(e["damping"][-1]),
        energy_contact_J=float(e["contact"][-1]),
        energy_residual_J=residual,
        energy_residual_relative=residual / energy_in if energy_in > 0 else 0.0,
        wall_time_s=result.wall_time_s,
        communication_steps=result.communication_steps,
        rollbacks=result.rollbacks,
        fmu_calls=result.fmu_calls,
        do_step_calls=sum(result.do_steps.values()),
        warnings=sampling_warnings(contacts),
    )
    return summary


#: plain-law step / impact time scale above which a run's summary warns (energy error ~ ratio)
SAMPLING_WARNING = 0.02


def sampling_warnings(contacts: dict[str, dict[str, Any]]) -> list[str]:
    """What a person must know before trusting the numbers of a run that completed: plain-law
    contacts stepped too coarsely to resolve their impacts."""
    out = []
    for name, c in contacts.items():
        ratio = c.get("step_over_time_scale", 0.0)
        if ratio > SAMPLING_WARNING:
            out.append(f"{name}: plain force law stepped at up to {ratio:.2g} times the impact time scale: "
                       f"expect its dissipated energy off by about {ratio:.0%} at CR 0.65 (more at higher CR), "
                       f"its peak force by less (docs/accuracy.md); use resolve_impacts=true or coupling=\"adaptive\"")
    return out


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable block for the terminal."""
    lines = [f"scene {summary['scene']}: {summary['description']}".rstrip(": "),
             f"  {summary['coupling']}, h = {summary['step_s']:g} s, t = 0..{summary['stop_time_s']:g} s, "
             f"{summary['communication_steps']} steps, {summary['fmu_calls']} FMI calls, "
             f"wall time {summary['wall_time_s']:.3f} s"]
    for name, b in summary["buildings"].items():
        lines.append(f"  {name:<10} peak displacement {b['peak_displacement_m']:.4g} m (floor "
                     f"{b['peak_displacement_floor']}), peak drift {b['peak_drift_m']:.4g} m "
                     f"(storey {b['peak_drift_storey']})")
    if summary["contacts"]:
        lines.append(f"  pounding: {summary['impacts']} impacts, peak force {summary['peak_force_N']:.4g} N, "
                     f"dissipated {summary['dissipated_energy_J']:.4g} J")
    else:
        lines.append("  no contact element")
    lines.append(f"  energy: input {summary['energy_initial_J'] + 0:.4g} J initial + "
                 f"{summary['energy_input_J'] - summary['energy_initial_J']:.4g} J ground; residual "
                 f"{summary['energy_residual_J']:.3g} J ({100 * summary['energy_residual_relative']:.3g} %)")
    lines += [f"  warning: {w}" for w in summary.get("warnings", [])]
    return "\n".join(lines)


def write_history(result: SimulationResult, path: Path) -> None:
    header = ",".join(["time"] + result.columns)
    data = np.column_stack([result.time, result.values])
    # 10 significant digits: far below every tolerance the tests use
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.10g")


def write_results(result: SimulationResult, folder: str | Path, plots: bool = True,
                  summary: dict[str, Any] | None = None) -> Path:
    """Write ``history.csv``, ``summary.json`` and the plots into ``folder``.

    Everything goes to a temporary sibling first, renamed at the end; an
    existing ``folder`` is replaced only once the new one is complete.
    """
    with replaced_folder(folder) as tmp:
        summary = summary or summarize(result)
        write_history(result, tmp / "history.csv")
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        if plots:
            plot_all(result, tmp)
    return Path(folder)


# -- plots -------------------------------------------------------------------------------------------
def plot_all(result: SimulationResult, folder: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = [plot_displacements(result, folder / "displacements.png", plt),
           plot_energy(result, folder / "energy.png", plt)]
    if result.scene.contacts:
        out += [plot_contact_force(result, folder / "contact_force.png", plt),
                plot_hysteresis(result, folder / "hysteresis.png", plt)]
    return out



def _finish(fig, ax, path: Path, plt, title: str, loc: str = "best") -> None:
    """Title, grid and legend as every result plot has them; save at 110 dpi and free the figure."""
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc=loc, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

def plot_displacements(result: SimulationResult, path: Path, plt) -> Path:
    scene = result.scene
    fig, ax = plt.subplots(figsize=(10, 4.5))
    floors: dict[str, set[int]] = {b.name: {scene.n_storeys(b.name)} for b in scene.buildings}
    for level in scene.levels:
        floors[level.left].add(level.floor_left)
        floors[level.right].add(level.floor_right)
    for b in scene.buildings:
        for f in sorted(floors[b.name], reverse=True)[:3]:  # top floor and up to two pounding floors
            ax.plot(result.time, result[f"{b.name}.x[{f}]"], lw=0.9, label=f"{b.name} floor {f}")
    marked = False
    for level in scene.levels:
        times = impact_times(result, level.instance)
        if times.size:
            k = np.searchsorted(result.time, times)
            ax.plot(times, result[f"{level.left}.x[{level.floor_left}]"][k], "rv", ms=5,
                    label=None if marked else "impact")
            marked = True
    ax.set_xlabel("time [s]")
    ax.set_ylabel("displacement relative to the ground [m]")
    _finish(fig, ax, path, plt, f"{scene.name}: floor displacements", loc="upper right")
    return path


def plot_contact_force(result: SimulationResult, path: Path, plt) -> Path:
    fig, ax = plt.subplots(figsize=(10, 4))
    for c in result.scene.contacts:
        line, = ax.plot(result.time, result[f"{c.name}.F"] / 1e3, lw=0.9, label=f"{c.name} mean F over step")
        if result.has(f"{c.name}.F_max"):  # the FMU's running maximum of the instantaneous force
            ax.plot(result.time, result[f"{c.name}.F_max"] / 1e3, "--", lw=0.8, color=line.get_color(),
                    label=f"{c.name} peak force so far")
        times = impact_times(result, c.name)
        if times.size:
            ax.plot(times, np.zeros_like(times), "|", color=line.get_color(), ms=10)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("contact force [kN]")
    _finish(fig, ax, path, plt, f"{result.scene.name}: contact force", loc="upper right")
    return path


def plot_hysteresis(result: SimulationResult, path: Path, plt) -> Path:
    """Contact force against penetration at the communication points.

    The mean force of a step is plotted against the penetration at its end:
    with impacts shorter than the step the loop is sampled coarsely (run
    with a small ``step`` to resolve it, as ``single_impact`` does).
    """
    fig, ax = plt.subplots(figsize=(6, 5))
    for c in result.scene.contacts:
        if not result.has(f"{c.name}.delta"):
            continue
        delta = result[f"{c.name}.delta"]
        force = result[f"{c.name}.F"]
        on = (delta > 0) | (force > 0)  # NaN elsewhere: one polyline per contact episode
        d = np.where(on, delta, np.nan)
        ax.plot(d * 1e3, np.where(on, force, np.nan) / 1e3, ".-", lw=0.8, ms=3, label=c.name)
    ax.set_xlabel("penetration delta [mm]")
    ax.set_ylabel("contact force (mean over step) [kN]")
    _finish(fig, ax, path, plt, f"{result.scene.name}: force-penetration loops")
    return path


def plot_energy(result: SimulationResult, path: Path, plt) -> Path:
    e = energy_history(result)
    t = e["time"]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    parts = [e["kinetic"], e["strain"], e["damping"], e["contact"]]
    labels = ["kinetic", "strain", "structural damping", "contact dissipation"]
    ax.stackplot(t, *[p / 1e3 for p in parts], labels=labels, alpha=0.75)
    ax.plot(t, e["input"] / 1e3, "k-", lw=1.2, label="input (initial + ground)")
    ax.plot(t, e["residual"] / 1e3, "r--", lw=1.0, label="residual")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("energy [kJ]")
    _finish(fig, ax, path, plt, f"{result.scene.name}: energy balance", loc="upper left")
    return path
