"""Writing a run's results: ``history.csv``, ``summary.json``, PNG plots, and the terminal summary.

Folders follow the package's output rule and are written complete or not at all
(:mod:`cosim.files`: a new or empty folder, or an earlier run's with ``overwrite``; written
under a hidden sibling and renamed at the end).  :func:`write_into` fills a folder already
claimed (:func:`cosim.master.runner.run_scene` claims it before the run starts, so that an
unwritable path or a full disk is known in a second); :func:`write_results` claims and fills.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from fmu_src.ground_records import G

from ..files import history_bytes, output_target, written_folder, PLOT_BYTES
from .fmi import raise_pending_interrupt
from .names import column, element_name
from .results import (IMPACT_COLUMNS, SimulationResult, Summary, energy_history, impact_table, impact_times,
                      summarize)


def format_summary(summary: Summary) -> str:
    """A short human-readable block for the terminal."""
    s, cost = summary, summary.cost
    lines = [f"scene {s.scene}: {s.system or s.description}".rstrip(": ")]
    if s.overrides:
        lines.append(f"  overrides: {', '.join(s.overrides)}")
    lines += [
             f"  {s.coupling}, h = {s.step_s:g} s, t = 0..{s.stop_time_s:g} s, "
             f"{cost.communication_steps} steps, {cost.fmu_calls} FMI calls, "
             f"wall time {cost.wall_time_s:.3f} s"]
    for name, b in s.buildings.items():
        lines.append(f"  {name:<10} peak displacement {b.peak_displacement_m:.4g} m (floor "
                     f"{b.peak_displacement_floor}), peak drift {b.peak_drift_m:.4g} m "
                     f"(storey {b.peak_drift_storey})")
        lines.append(f"  {'':<10} drift ratio {100 * b.peak_drift_ratio:.3g} % (storey "
                     f"{b.peak_drift_ratio_storey}), floor acceleration {b.peak_acceleration_m_s2 / G:.3g} g "
                     f"(floor {b.peak_acceleration_floor}){'' if b.peaks_in_step else ', at communication points'}")
        if b.yields:
            lines.append(f"  {'':<10} {b.hysteresis} storeys: peak ductility {b.peak_ductility:.3g} (storey "
                         f"{b.peak_ductility_storey}), residual drift {b.residual_drift_m:.3g} m (storey "
                         f"{b.residual_drift_storey}), hysteretic energy {b.hysteretic_energy_J:.4g} J")
    if s.contacts:
        grazes = f" (and {s.grazes} graze{'s' if s.grazes != 1 else ''}: contacts shallower than graze_depth)" \
            if s.grazes else ""
        lines.append(f"  pounding: {s.impacts} impacts{grazes}, peak force {s.peak_force_N:.4g} N, "
                     f"dissipated {s.dissipated_energy_J:.4g} J")
    else:
        lines.append("  no contact element")
    hysteretic = f"; hysteretic {s.energy_hysteretic_J:.4g} J" if any(b.yields for b in s.buildings.values()) else ""
    lines.append(f"  energy: input {s.energy_initial_J + 0:.4g} J initial + "
                 f"{s.energy_input_J - s.energy_initial_J:.4g} J ground{hysteretic}; residual "
                 f"{s.energy_residual_J:.3g} J ({100 * s.energy_residual_relative:.3g} %)")
    lines += [f"  warning: {w}" for w in s.warnings]
    return "\n".join(lines)


def write_history(result: SimulationResult, path: Path) -> None:
    """``history.csv``: ``time`` and every column, one row per communication point."""
    header = ",".join(["time"] + result.columns)
    data = np.column_stack([result.time, result.values])
    # 10 significant digits: far below every tolerance the tests use
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.10g")


def history_units(result: SimulationResult) -> list[tuple[str, str, str, str]]:
    """``(column, unit, description, type)`` of every history column, from the FMUs' model
    descriptions (``time`` in s first; a unitless ratio has unit ``1``, a count or flag none)."""
    scene = result.scene
    interfaces = scene.interfaces or {}
    fmu_of = {spec.name: spec.fmu for spec in scene.instances()}
    out = [("time", "s", "time of the communication point", "Real")]
    for name in result.columns:
        instance, variable = name.split(".", 1)
        interface = interfaces.get(fmu_of.get(instance))
        info = interface.variables.get(variable) if interface is not None else None
        out.append((name, (info.unit or "") if info else "", (info.description or "") if info else "",
                    info.type if info else "Real"))
    return out


def write_history_units(result: SimulationResult, path: Path) -> None:
    """``history_units.csv``: one row per column of ``history.csv``: ``column,unit,description``."""
    with path.open("w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(["column", "unit", "description"])
        writer.writerows(row[:3] for row in history_units(result))


def write_history_parquet(result: SimulationResult, path: Path) -> None:
    """``history.parquet``: the history's columns (Real as float64, Integer and Boolean as int32)
    with each column's unit and description in its field metadata, the scene in the table's."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = [result.time] + [result.values[:, j] for j in range(len(result.columns))]
    fields, columns = [], []
    for (name, unit, description, kind), values in zip(history_units(result), arrays):
        array = pa.array(values.astype(np.float64) if kind == "Real" else values.astype(np.int32))
        fields.append(pa.field(name, array.type, metadata={"unit": unit, "description": description}))
        columns.append(array)
    table = pa.Table.from_arrays(columns, schema=pa.schema(fields, metadata={"scene": result.scene.name}))
    pq.write_table(table, path)


def write_impacts(result: SimulationResult, path: Path) -> None:
    """``impacts.csv``: :func:`~cosim.master.results.impact_table`, units in the column names."""
    with path.open("w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow([name for name, _ in IMPACT_COLUMNS])
        for row in impact_table(result):
            writer.writerow([row[name] if isinstance(row[name], str) else f"{row[name]:.10g}"
                             for name, _ in IMPACT_COLUMNS])


def write_into(folder: Path, result: SimulationResult, plots: bool = True, summary: Summary | None = None,
               parquet: bool = False) -> None:
    """Write ``history.csv`` (with ``history_units.csv``), ``impacts.csv``, ``summary.json`` and the
    plots (``parquet``: also ``history.parquet``) into the (claimed, empty) ``folder`` (not after a
    Ctrl-C that arrived during the last FMI call: :func:`~cosim.master.fmi.deferred_interrupts`)."""
    raise_pending_interrupt()
    summary = summary or summarize(result)
    write_history(result, folder / "history.csv")
    write_history_units(result, folder / "history_units.csv")
    if parquet:
        write_history_parquet(result, folder / "history.parquet")
    if result.scene.contacts:
        write_impacts(result, folder / "impacts.csv")
    (folder / "summary.json").write_text(json.dumps(summary.to_dict(), indent=2) + "\n")
    if plots:
        plot_all(result, folder)


def write_results(result: SimulationResult, folder: str | Path, plots: bool = True,
                  summary: Summary | None = None, *, overwrite: bool = False, parquet: bool = False) -> Path:
    """Write the results (:func:`write_into`) into ``folder`` by the output rule
    (:func:`cosim.files.output_target`: an earlier run's folder is replaced only with
    ``overwrite``); complete or not at all.  Returns the folder."""
    target = output_target(folder, overwrite=overwrite)
    expected = history_bytes(len(result.time), len(result.columns)) + (PLOT_BYTES if plots else 0)
    with written_folder(target, "run", overwrite=overwrite, expected_bytes=expected) as pending:
        write_into(pending.path, result, plots, summary, parquet=parquet)
    return pending.target


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
    if yielding_buildings(result):
        out.append(plot_storey_loops(result, folder / "storey_loops.png", plt))
    return out


def yielding_buildings(result: SimulationResult) -> list[str]:
    """The buildings of a run whose storeys yield (``hysteresis`` other than linear)."""
    return [b.name for b in result.scene.buildings if str(b.value("hysteresis")) != "linear"]



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
            ax.plot(result.time, result[column(b.name, element_name("x", f))], lw=0.9, label=f"{b.name} floor {f}")
    marked = False
    for level in scene.levels:
        times = impact_times(result, level.instance)
        if times.size:
            k = np.searchsorted(result.time, times)
            ax.plot(times, result[column(level.left, element_name("x", level.floor_left))][k], "rv", ms=5,
                    label=None if marked else "impact")
            marked = True
    ax.set_xlabel("time [s]")
    ax.set_ylabel("displacement relative to the ground [m]")
    _finish(fig, ax, path, plt, f"{scene.name}: floor displacements", loc="upper right")
    return path


def plot_contact_force(result: SimulationResult, path: Path, plt) -> Path:
    """Each contact's mean force over the steps and its running peak; every impact (not the
    grazes) marked at its own peak force, above the curve, so that no mark reads as a force of 0
    or below."""
    fig, ax = plt.subplots(figsize=(10, 4))
    rows = [r for r in impact_table(result) if r["kind"] == "impact"]
    for c in result.scene.contacts:
        line, = ax.plot(result.time, result[f"{c.name}.F"] / 1e3, lw=0.9, label=f"{c.name} mean F over step")
        if result.has(f"{c.name}.F_max"):  # the FMU's running maximum of the instantaneous force
            ax.plot(result.time, result[f"{c.name}.F_max"] / 1e3, "--", lw=0.8, color=line.get_color(),
                    label=f"{c.name} peak force so far")
        mine = [r for r in rows if r["contact"] == c.name]
        if mine:
            ax.plot([r["t_onset_s"] for r in mine], [r["peak_force_N"] / 1e3 for r in mine], "v",
                    color=line.get_color(), ms=6, label=f"{c.name} impact (onset, its peak force)")
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("contact force [kN]")
    _finish(fig, ax, path, plt, f"{result.scene.name}: contact force", loc="upper right")
    return path


#: impacts drawn in hysteresis.png: the largest by peak force (more overlap into one blot)
LOOPS_PLOTTED = 6


def plot_hysteresis(result: SimulationResult, path: Path, plt) -> Path:
    """Force-penetration loops of the largest impacts, each from its own trajectory inside the
    steps (:func:`cosim.master.impacts.replay_contact`: the contact FMU's arithmetic replayed on
    the steps it took, which the run logs whatever it records).  A result without that log (not
    made by :func:`cosim.master.simulate.simulate`) draws the recorded step means against the
    end-of-step penetration, labelled as such."""
    from .impacts import replay_contact

    fig, ax = plt.subplots(figsize=(6, 5))
    loops, fallback = [], []
    for c in result.scene.contacts:
        trajectories = replay_contact(result, c.name)
        if trajectories is None:
            if result.has(f"{c.name}.delta") and result.has(f"{c.name}.F"):
                fallback.append(c.name)
        else:
            loops += trajectories
    for t in sorted(loops, key=lambda t: t.peak_force, reverse=True)[:LOOPS_PLOTTED]:
        ax.plot(t.penetration * 1e3, t.force / 1e3, lw=1.0, label=f"{t.contact} at {t.t_onset:.3f} s")
    for name in fallback:
        delta, force = result[f"{name}.delta"], result[f"{name}.F"]
        on = (delta > 0) | (force > 0)  # NaN elsewhere: one polyline per contact episode
        ax.plot(np.where(on, delta, np.nan) * 1e3, np.where(on, force, np.nan) / 1e3, ".-", lw=0.8, ms=3,
                label=f"{name} (step means, end-of-step penetration)")
    ax.set_xlabel("penetration delta [mm]")
    ax.set_ylabel("contact force [kN]")
    shown = min(len(loops), LOOPS_PLOTTED)
    title = f"{result.scene.name}: force-penetration loops" + (
        f" ({shown} largest of {len(loops)} contacts)" if loops else "")
    _finish(fig, ax, path, plt, title)
    return path


def plot_storey_loops(result: SimulationResult, path: Path, plt, storeys: int = 3) -> Path:
    """Storey shear against storey drift of every yielding building, at the communication
    points: one panel per building, its ``storeys`` lowest storeys (where yielding concentrates
    in a shear building) with the yield shears ``+-Fy`` marked."""
    names = yielding_buildings(result)
    fig, axes = plt.subplots(1, len(names), figsize=(6 * len(names), 5), squeeze=False)
    for ax, name in zip(axes[0], names):
        spec = result.scene.instance(name)
        n = result.scene.n_storeys(name)
        for i in range(1, min(n, storeys) + 1):
            d = result[column(name, element_name("drift", i))]
            V = result[column(name, element_name("V", i))]
            line, = ax.plot(d * 1e3, V / 1e6, lw=0.7, label=f"storey {i}")
            fy = float(spec.value(element_name("Fy", i)))
            ax.axhline(fy / 1e6, color=line.get_color(), ls=":", lw=0.8)
            ax.axhline(-fy / 1e6, color=line.get_color(), ls=":", lw=0.8)
        ax.set_xlabel("storey drift [mm]")
        ax.set_ylabel("storey shear [MN]")
        ax.set_title(f"{result.scene.name}: {name} ({spec.value('hysteresis')} storeys); dotted: +-Fy")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_energy(result: SimulationResult, path: Path, plt) -> Path:
    e = energy_history(result)
    t = e["time"]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    parts = [e["kinetic"], e["strain"], e["damping"], e["contact"], e["stored"]]
    labels = ["kinetic", "strain", "structural damping", "contact dissipation", "contact spring"]
    if np.any(e["hysteretic"]):
        parts.append(e["hysteretic"])
        labels.append("hysteretic (yielding storeys)")
    ax.stackplot(t, *[p / 1e3 for p in parts], labels=labels, alpha=0.75)
    ax.plot(t, e["input"] / 1e3, "k-", lw=1.2, label="input (initial + ground)")
    ax.plot(t, e["residual"] / 1e3, "r--", lw=1.0, label="residual")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("energy [kJ]")
    _finish(fig, ax, path, plt, f"{result.scene.name}: energy balance", loc="upper left")
    return path
