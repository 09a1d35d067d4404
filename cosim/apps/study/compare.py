"""Two variants of a study side by side: a Markdown table and a panel figure.

    pounding-cosim study compare RESULTS.csv --x pounding.gap --pair left.hysteresis \\
        --panels ground.record --y peak_force_N impacts dissipated_energy_J left.peak_ductility --out DIR

A study that varies one column between two values (``--pair``, e.g. ``left.hysteresis``:
``linear`` and ``bilinear``) alongside others (``--x`` on the abscissa, ``--panels`` one row of
panels per value) is read back (:func:`~.results_io.read_results`) and written as

* ``comparison.md``: one table row per (panel value, x), each metric for both variants and
  their ratio (second / first);
* ``comparison.png``: one panel per (panel value, metric), one curve per variant.

Rows that are not ``ok`` are left out and counted in the table's caption.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

from .cases import _canonical
from .results_io import read_results
from .spec import StudyError


def _check_columns(csv_path: Path, header: Sequence[str], names: Sequence[str]) -> None:
    for name in names:
        if name not in header:
            raise StudyError(f"{csv_path} has no column {name!r}; columns: {', '.join(header)}")


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, int):
        return str(value)
    return f"{value:.4g}"


def paired(csv_path: str | Path, x: str, pair: str, panels: str | None, metrics: Sequence[str]):
    """``(variants, table)``: the two values of ``pair`` and ``{(panel, x): {variant: row}}`` of
    the ok rows; a StudyError unless ``pair`` takes exactly two values and each (panel, x,
    variant) has one row."""
    csv_path = Path(csv_path)
    if not csv_path.is_file():
        raise StudyError(f"results file {csv_path} not found")
    header, rows = read_results(csv_path)
    _check_columns(csv_path, header, [x, pair, *metrics] + ([panels] if panels else []))
    variants = list(dict.fromkeys(r[pair] for r in rows))
    if len(variants) != 2:
        raise StudyError(f"{csv_path}: --pair {pair} takes {len(variants)} value(s) {variants}; a comparison "
                         f"needs exactly two")
    table: dict[tuple, dict] = {}
    skipped = 0
    for r in rows:
        if r["status"] != "ok":
            skipped += 1
            continue
        key = (r[panels] if panels else None, _canonical(r[x]))
        cell = table.setdefault(key, {"x": r[x]})
        if r[pair] in cell:
            raise StudyError(f"{csv_path}: several rows share {x} = {r[x]!r}, {pair} = {r[pair]!r}"
                             + (f", {panels} = {r[panels]!r}" if panels else "")
                             + ": another column varies too")
        cell[r[pair]] = r
    return variants, table, skipped


def write_comparison(csv_path: str | Path, x: str, pair: str, panels: str | None, metrics: Sequence[str],
                     out: str | Path) -> tuple[Path, Path]:
    """Write ``comparison.md`` and ``comparison.png`` into ``out`` (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants, table, skipped = paired(csv_path, x, pair, panels, metrics)
    first, second = variants
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    head = ["" if not panels else panels, x]
    for m in metrics:
        head += [f"{m} {first}", f"{m} {second}", "ratio"]
    lines = [f"{pair}: {first} against {second} (ratio = {second} / {first}); "
             f"{Path(csv_path).parent.name}/{Path(csv_path).name}"
             + (f", {skipped} failed or unstable row(s) left out" if skipped else ""), "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    panel_values = list(dict.fromkeys(k[0] for k in table))
    for key in sorted(table, key=lambda k: (panel_values.index(k[0]), table[k]["x"])):
        cell = table[key]
        row = [str(key[0]) if panels else "", _cell(cell["x"])]
        for m in metrics:
            a = cell.get(first, {}).get(m)
            b = cell.get(second, {}).get(m)
            ratio = b / a if isinstance(a, (int, float)) and isinstance(b, (int, float)) and a else None
            row += [_cell(a), _cell(b), "" if ratio is None else f"{ratio:.3g}"]
        lines.append("| " + " | ".join(row) + " |")
    md = out / "comparison.md"
    md.write_text("\n".join(lines) + "\n", encoding="utf-8")

    fig, axes = plt.subplots(len(panel_values), len(metrics), figsize=(3.6 * len(metrics), 2.8 * len(panel_values)),
                             squeeze=False, sharex=True)
    for i, panel in enumerate(panel_values):
        keys = sorted((k for k in table if k[0] == panel), key=lambda k: table[k]["x"])
        for j, m in enumerate(metrics):
            ax = axes[i][j]
            for variant, style in ((first, "o-"), (second, "s--")):
                pts = [(table[k]["x"], table[k][variant][m]) for k in keys
                       if variant in table[k] and table[k][variant][m] is not None]
                if pts:
                    ax.plot(*zip(*pts), style, ms=3, lw=1.1, label=str(variant))
            if i == 0:
                ax.set_title(m, fontsize=9)
            if j == 0:
                ax.set_ylabel(str(panel) if panels else "", fontsize=9)
            if i == len(panel_values) - 1:
                ax.set_xlabel(x, fontsize=9)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=8)
    axes[0][0].legend(title=pair, fontsize=8, title_fontsize=8)
    fig.tight_layout()
    png = out / "comparison.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return md, png
