"""The separation a scene's buildings need, per pounding level and record, checked by co-simulation.

``pounding-cosim separation SCENE [--records ...] [--pga G]`` calls :func:`scene_separations`
and writes what it returns (:func:`write_separations`: ``separation.csv``, ``separation.png``).

For each record (the scene's own, or each of ``records`` played with the scene's scaling, or
scaled to ``pga_g``) and each pounding level of the scene:

* **the separation that avoids contact**, ``S = max_t (x_left - x_right)`` of the two uncoupled
  responses at that level (:mod:`cosim.apps.separation`): exact for linear buildings at rest at
  the start (method ``exact``: modal responses, peaks located between samples and in the free
  vibration after the record); for any other building (yielding storeys, a building that does not
  start at rest) found by bisection on the gap with co-simulation runs (method ``bisection``,
  :func:`bisect_separation`: the uncoupled run brackets it, each run tells contact from none);
* beside it the code rules ABS, SRSS, EC8 0.7 SRSS and DDC from the two buildings' peak floor
  displacements, taken from the histories and from the record's response spectrum;
* **the check** (``check=True``): co-simulation runs with the level's gap at ``0.99 S`` (the
  other levels at ``1.01`` times theirs, so that this level's contact is the first) must show a
  contact at that level, and one run with every level at ``1.01 S`` none anywhere.

Contact here is any touch (the contact's largest force ``F_max > 0``), grazes included.
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..files import output_target, written_folder
from ..master.loader import load_scene
from ..master.names import column, element_name
from ..master.scene import Override, Scene, SceneError
from ..master.simulate import simulate
from ..master.system import Catalog, System
from ..peers.reference import scene_inputs
from .separation import (RULE_NAMES, Separation, SeparationEstimate, code_separations, correlation,
                         required_separation, separation_estimates, spectral_peak_displacement)

#: the gap factors of the check runs: contact expected below, none above
CHECK_FACTORS = (0.99, 1.01)
#: bisection ends when the bracket is this narrow, relative to the separation (1e-4) or absolute
#: (1e-5 m): the co-simulation resolves a floor's position to about 3e-5 m before the first impact
#: at default settings (0.013-0.063 mm on the four record scenes against the reference), so a
#: narrower bracket would only measure the coupling error
BISECTION_RTOL, BISECTION_ATOL = 1e-4, 1e-5
#: at most this many bisection runs per level and record (each halves the bracket)
MAX_BISECTIONS = 40
#: a gap no level can close: the uncoupled run (m)
UNCOUPLED_GAP = 1.0e3


@dataclass(frozen=True)
class GapCheck:
    """Co-simulation runs at ``factors`` (below, above) times the separation: the contacts at this
    level in each (touches, grazes included)."""

    factors: tuple[float, float]
    gaps_m: tuple[float, float]
    contacts_below: int
    contacts_above: int

    @property
    def passed(self) -> bool:
        """Contact below the separation, none above it."""
        return self.contacts_below > 0 and self.contacts_above == 0


@dataclass(frozen=True)
class LevelSeparation:
    """The separation of one pounding level under one record, with the code rules beside it.

    ``method`` is ``exact`` (linear buildings, modal) or ``bisection`` (co-simulation runs);
    ``estimate`` holds the separation, the two peak displacements from the histories and from the
    spectrum, the correlation ``rho`` and every rule (:class:`~cosim.apps.separation.SeparationEstimate`).
    """

    level: str
    left: str
    right: str
    floor_left: int
    floor_right: int
    record: str
    pga_g: float
    periods_s: tuple[float, float]
    dampings: tuple[float, float]
    method: str
    estimate: SeparationEstimate
    check: GapCheck | None = None
    runs: int = 0

    @property
    def separation_m(self) -> float:
        return self.estimate.exact.gap

    def row(self) -> dict[str, Any]:
        """One row of ``separation.csv`` (SI units in the names)."""
        e = self.estimate
        out: dict[str, Any] = dict(
            level=self.level, left=f"{self.left}[{self.floor_left}]", right=f"{self.right}[{self.floor_right}]",
            record=self.record, pga_g=self.pga_g, method=self.method, separation_m=e.exact.gap,
            time_s=e.exact.time, T1_left_s=self.periods_s[0], T1_right_s=self.periods_s[1], rho=e.rho,
            u_left_m=e.peaks_history[0], u_right_m=e.peaks_history[1])
        out.update({f"{name}_m": e.rules_history[name] for name in RULE_NAMES})
        out.update(u_left_spectrum_m=e.peaks_spectrum[0], u_right_spectrum_m=e.peaks_spectrum[1])
        out.update({f"{name}_spectrum_m": e.rules_spectrum[name] for name in RULE_NAMES})
        c = self.check
        out.update(gap_below_m=c.gaps_m[0] if c else "", contacts_below=c.contacts_below if c else "",
                   gap_above_m=c.gaps_m[1] if c else "", contacts_above=c.contacts_above if c else "",
                   check=("passed" if c.passed else "FAILED") if c else "", runs=self.runs)
        return out


class _Runner:
    """Co-simulation runs of one scene with the level gaps given: one system, reset between runs
    (:meth:`cosim.master.system.System.reset`); ``count`` runs so far."""

    def __init__(self, scene: Scene, source: str | Path, overrides: Sequence[Override], catalog: Catalog):
        self.scene, self.source, self.overrides, self.catalog = scene, source, list(overrides), catalog
        self.count = 0
        self.system = System(scene, catalog)

    def close(self) -> None:
        self.system.close()

    def run(self, gaps: dict[str, float], stop_time: float | None = None):
        overrides = [Override(level, "gap", float(g)) for level, g in gaps.items()]
        if stop_time is not None:
            overrides.append(Override(None, "stop_time", float(stop_time)))
        self.system.reset(load_scene(self.source, self.overrides + overrides, self.catalog))
        self.count += 1
        return simulate(self.system, progress=False)


def contacts_at(result, level: str) -> int:
    """Touches of the contact instance ``level`` in a run: impacts plus grazes, or 1 if its largest
    force is positive while its counters say none (a touch still in progress at the end)."""
    # the final read (every output, whatever the run recorded)
    count = int(result.value_at_end(column(level, "impacts")))
    count += int(result.value_at_end(column(level, "grazes")))
    if count == 0 and result.value_at_end(column(level, "F_max")) > 0.0:
        count = 1
    return count


def _is_linear_at_rest(scene: Scene) -> bool:
    """The exact method's conditions: every building linear (no ``hysteresis`` parameter, or
    ``linear``) and at rest at t = 0."""
    for b in scene.buildings:
        try:
            if str(b.value("hysteresis")) != "linear":
                return False
        except KeyError:        # a building.fmu without yielding storeys
            pass
        n = int(b.value("n_storeys"))
        for i in range(1, n + 1):
            if float(b.value(element_name("x0", i))) != 0.0 or float(b.value(element_name("v0", i))) != 0.0:
                return False
    return True


def record_overrides(record: str | None, pga_g: float | None) -> list[Override]:
    """The ``--set`` equivalents of ``--records R`` and ``--pga G``: the record, and the PGA target
    in g replacing the scene's scaling."""
    out = []
    if record is not None:
        out.append(Override("ground", "record", str(record)))
    if pga_g is not None:
        if not (math.isfinite(pga_g) and pga_g > 0.0):
            raise SceneError(f"--pga {pga_g!r}: a PGA in g must be > 0")
        out += [Override("ground", "target_pga", 0.0), Override("ground", "target_sa", 0.0),
                Override("ground", "target_pga_g", float(pga_g))]
    return out


def scene_separations(scene: str | Path, overrides: Sequence[Override] = (), records: Sequence[str] | None = None,
                      pga_g: float | None = None, *, check: bool = True, method: str | None = None,
                      catalog: Catalog | None = None,
                      progress: Callable[[str], None] | None = None) -> list[LevelSeparation]:
    """:class:`LevelSeparation` of every pounding level of ``scene`` under every record.

    ``records``: bundled names or files (default: the scene's own record); ``pga_g``: scale each
    to this PGA (g) instead of the scene's scaling.  ``method``: ``exact`` or ``bisection``
    (default: ``exact`` where it applies, see the module docstring).  ``check``: the runs at
    0.99 and 1.01 times the separation.  ``catalog``: loaded FMUs (needed for ``check`` and
    ``bisection``).  ``progress`` receives a line per finished level.
    """
    if method not in (None, "exact", "bisection"):
        raise ValueError(f"method = {method!r}: one of 'exact', 'bisection'")
    out = []
    for record in (records or [None]):
        base = list(overrides) + record_overrides(record, pga_g)
        loaded = load_scene(scene, base, catalog)
        if loaded.ground is None:
            raise SceneError(f"{loaded.source}: has no ground motion ([ground] table): the separation is "
                             f"defined for an earthquake record")
        if not loaded.levels:
            raise SceneError(f"{loaded.source}: has no pounding level (needs two buildings and a [pounding] table)")
        use = method or ("exact" if _is_linear_at_rest(loaded) else "bisection")
        if use == "exact" and not _is_linear_at_rest(loaded):
            raise SceneError(f"{loaded.source}: the exact separation needs linear buildings at rest at t = 0; "
                             f"use the bisection method")
        if (check or use == "bisection") and catalog is None:
            raise ValueError("check runs and the bisection method need a catalog of built FMUs")
        inputs = scene_inputs(loaded)
        rec = inputs["ground"]
        index = {b.name: k for k, b in enumerate(loaded.buildings)}
        runner = _Runner(loaded, scene, base, catalog) if catalog is not None else None
        try:
            rows = []
            uncoupled = None
            if use == "bisection":
                uncoupled = runner.run({lv.instance: UNCOUPLED_GAP for lv in loaded.levels})
            for level in loaded.levels:
                left, right = inputs["buildings"][index[level.left]], inputs["buildings"][index[level.right]]
                if use == "exact":
                    estimate = separation_estimates(left, right, level.floor_left, level.floor_right,
                                                    rec.acceleration, rec.dt)
                else:
                    estimate = _simulated_estimate(runner, uncoupled, loaded, level, left, right, rec)
                rows.append(LevelSeparation(
                    level.instance, level.left, level.right, level.floor_left, level.floor_right, rec.name,
                    rec.pga_g, (float(left.periods[0]), float(right.periods[0])),
                    (float(left.modal_damping_ratios[0]), float(right.modal_damping_ratios[0])), use, estimate))
            if check:
                rows = _checked(runner, loaded, rows)
            if runner is not None:
                rows = [replace(r, runs=runner.count) for r in rows]
        finally:
            if runner is not None:
                runner.close()
        for r in rows:
            if progress is not None:
                progress(format_row(r))
        out += rows
    return out


def _checked(runner: _Runner, scene: Scene, rows: list[LevelSeparation]) -> list[LevelSeparation]:
    """The check runs of the module docstring for every level of one record."""
    below, above = CHECK_FACTORS
    gaps_above = {r.level: above * r.separation_m for r in rows}
    none = runner.run(gaps_above)
    out = []
    for r in rows:
        if r.separation_m <= 0.0:      # the floors only move apart: nothing to check
            out.append(r)
            continue
        # the level's first contact comes no later than the peak closing: run a second past it
        stop = min(scene.stop_time, max(r.estimate.exact.time + 1.0, scene.step))
        touched = runner.run({**gaps_above, r.level: below * r.separation_m}, stop_time=stop)
        out.append(replace(r, check=GapCheck((below, above), (below * r.separation_m, above * r.separation_m),
                                             contacts_at(touched, r.level), contacts_at(none, r.level))))
    return out


def _simulated_estimate(runner: _Runner, uncoupled, scene: Scene, level, left, right, record) -> SeparationEstimate:
    """Separation by bisection (any buildings); peaks and rules from the uncoupled run."""
    xl = uncoupled[column(level.left, element_name("x", level.floor_left))]
    xr = uncoupled[column(level.right, element_name("x", level.floor_right))]
    sampled = required_separation(uncoupled.time, xl, xr)
    onsets = {}                 # gap -> when the latest contact began, in the runs that touched

    def touches(gap: float) -> bool:
        result = runner.run({**{lv.instance: UNCOUPLED_GAP for lv in scene.levels}, level.instance: gap})
        touched = contacts_at(result, level.instance) > 0
        if touched and result.known(column(level.instance, "t_onset")):
            onsets[gap] = result.value_at_end(column(level.instance, "t_onset"))
        return touched

    exact = bisect_separation(touches, sampled)
    if onsets:
        # when: the touch in the run with the largest gap that still touched, just below the
        # separation (the peak closing to within the bracket), not the uncoupled run's sample,
        # a step end (long steps: up to 0.32 s from the peak)
        exact = Separation(exact.gap, onsets[max(onsets)])
    peaks = (_peak(uncoupled, level.left, level.floor_left), _peak(uncoupled, level.right, level.floor_right))
    spectrum = (spectral_peak_displacement(left, level.floor_left, record.acceleration, record.dt),
                spectral_peak_displacement(right, level.floor_right, record.acceleration, record.dt))
    rho = correlation(left.periods[0], right.periods[0], left.modal_damping_ratios[0], right.modal_damping_ratios[0])
    return SeparationEstimate(exact, peaks, spectrum, rho, code_separations(*peaks, rho), code_separations(*spectrum, rho))


def _peak(result, building: str, floor: int) -> float:
    """Peak |x| of a floor: the building's in-step peak output at the end when it has one, else
    the largest of every step's end (the run's tracked peaks; long steps keep few rows)."""
    name = column(building, element_name("x_peak", floor))
    if result.known(name):
        return result.value_at_end(name)
    x = column(building, element_name("x", floor))
    if x in result.peaks:
        return result.peaks[x][0]
    return float(np.max(np.abs(result[x])))


def bisect_separation(touches: Callable[[float], bool], sampled: Separation) -> Separation:
    """The smallest gap (m) at which ``touches(gap)`` is False, by bisection.

    ``sampled`` is the separation read from the uncoupled run's samples, a lower bound: a gap
    below it is closed in that very run.  The upper end starts 0.1 % above and grows until a run
    shows no contact; the bracket is then halved until it is narrower than
    ``max(BISECTION_ATOL, BISECTION_RTOL * gap)``.  Returns its upper end (no contact there).
    """
    if sampled.gap <= 0.0:
        return sampled
    lo = sampled.gap * (1.0 - 1e-9)          # closed in the uncoupled run itself
    hi = sampled.gap * 1.001 + BISECTION_ATOL
    runs = 0
    while touches(hi):
        runs += 1
        lo, hi = hi, sampled.gap + 2.0 * (hi - sampled.gap)
        if runs > MAX_BISECTIONS:
            raise RuntimeError(f"bisection: the floors still touch at a gap of {hi:.6g} m, "
                               f"{hi / sampled.gap:.3g} times the uncoupled separation")
    while hi - lo > max(BISECTION_ATOL, BISECTION_RTOL * hi) and runs < MAX_BISECTIONS:
        mid = 0.5 * (lo + hi)
        runs += 1
        if touches(mid):
            lo = mid
        else:
            hi = mid
    return Separation(hi, sampled.time)


# -- presenting ----------------------------------------------------------------------------------------
def _check_text(c: GapCheck | None) -> str:
    if c is None:
        return ""
    below = f"{c.contacts_below} contact{'s' if c.contacts_below != 1 else ''}"
    above = "no contact" if c.contacts_above == 0 else f"{c.contacts_above} contacts"
    return f"{below} / {above}" + ("" if c.passed else "  CHECK FAILED")


HEADER = (f"{'level':<12} {'record':<16} {'PGA':>7} {'S (m)':>8} {'at t':>8} | {'u_l':>7} {'u_r':>7} "
          + " ".join(f"{n:>7}" for n in RULE_NAMES) + " | spectra: "
          + " ".join(f"{n:>7}" for n in RULE_NAMES) + " | 0.99 S / 1.01 S")


def format_row(r: LevelSeparation) -> str:
    e = r.estimate
    t = f"{e.exact.time:.2f} s" if math.isfinite(e.exact.time) else "-"
    return (f"{r.level:<12} {r.record:<16} {r.pga_g:5.3f} g {e.exact.gap:8.4f} {t:>8} | {e.peaks_history[0]:7.4f} "
            f"{e.peaks_history[1]:7.4f} " + " ".join(f"{e.rules_history[n]:7.4f}" for n in RULE_NAMES)
            + " |          " + " ".join(f"{e.rules_spectrum[n]:7.4f}" for n in RULE_NAMES) + f" | {_check_text(r.check)}")


def format_separations(rows: Sequence[LevelSeparation]) -> str:
    """The terminal table: one line per level and record (metres), the check at the end."""
    text = []
    for r in rows:
        line = (f"{r.level}: {r.left} floor {r.floor_left} (T1 = {r.periods_s[0]:.3g} s) against {r.right} floor "
                f"{r.floor_right} (T1 = {r.periods_s[1]:.3g} s), rho = {r.estimate.rho:.4f}, method {r.method}")
        if line not in text:
            text.append(line)
    text += ["", "separation S that avoids contact, and the code rules from the peak displacements u_l, u_r (m):",
             HEADER]
    text += [format_row(r) for r in rows]
    return "\n".join(text)


def separation_csv(rows: Sequence[LevelSeparation]) -> str:
    out = io.StringIO()
    table = [r.row() for r in rows]
    writer = csv.DictWriter(out, fieldnames=list(table[0]), lineterminator="\n")
    writer.writeheader()
    for row in table:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
    return out.getvalue()


def plot_separations(rows: Sequence[LevelSeparation], path: Path) -> Path:
    """Bars per level and record: the separation beside each rule, from histories (solid) and
    spectra (hatched), in metres."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [f"{r.record}\n{r.level}" if len({x.level for x in rows}) > 1 else r.record for r in rows]
    x = np.arange(len(rows))
    width = 0.8 / (1 + 2 * len(RULE_NAMES))
    fig, ax = plt.subplots(figsize=(max(7.0, 1.6 * len(rows) + 3), 4.8))
    ax.bar(x - 0.4 + width / 2, [r.separation_m for r in rows], width, color="k", label="S (uncoupled responses)")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, name in enumerate(RULE_NAMES):
        ax.bar(x - 0.4 + width * (1.5 + k), [r.estimate.rules_history[name] for r in rows], width,
               color=colours[k % len(colours)], label=f"{name} (peaks from histories)")
        ax.bar(x - 0.4 + width * (1.5 + len(RULE_NAMES) + k), [r.estimate.rules_spectrum[name] for r in rows], width,
               color=colours[k % len(colours)], alpha=0.45, hatch="//", label=f"{name} (peaks from spectra)")
    tallest = max(max(r.separation_m, *r.estimate.rules_history.values(), *r.estimate.rules_spectrum.values())
                  for r in rows)
    ax.set_ylim(0.0, 1.45 * tallest if tallest > 0 else 1.0)   # room for the legend above the bars
    ax.set_xticks(x)
    ax.set_xticklabels(labels, fontsize=8)
    ax.set_ylabel("separation [m]")
    ax.set_title("separation that avoids pounding and code estimates")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_separations(rows: Sequence[LevelSeparation], folder: str | Path, plots: bool = True, *,
                      overwrite: bool = False, default: bool = False) -> Path:
    """``separation.csv``, ``separation.txt`` (and ``separation.png``) into ``folder`` by the output
    rule (:func:`cosim.files.output_target`: a new or empty folder, or this package's own with
    ``overwrite``; ``default``: the program chose the path, numbered when taken), complete or not
    at all.  Returns the folder written."""
    target = output_target(folder, overwrite=overwrite, default=default)
    with written_folder(target, "separation", overwrite=overwrite, default=default) as pending:
        (pending.path / "separation.csv").write_text(separation_csv(rows), encoding="utf-8")
        (pending.path / "separation.txt").write_text(format_separations(rows) + "\n", encoding="utf-8")
        if plots:
            plot_separations(rows, pending.path / "separation.png")
    return pending.target
