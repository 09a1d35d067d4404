"""Plots of a study's results: a summary column against a varied one, one curve per value of a third."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any, Sequence

from .cases import _canonical
from .results_io import read_results
from .spec import StudyError


#: units of summary columns by the suffix of their names (SI units in the names, cosim.master.results)
_SUFFIX_UNITS = (("_m_s2", "m/s^2"), ("_m_s", "m/s"), ("_N", "N"), ("_J", "J"), ("_m", "m"), ("_s", "s"),
                 ("_relative", "1"), ("_g", "g"))


def axis_label(name: str) -> str:
    """``name [unit]``: the unit from a summary column's suffix (``peak_force_N``), else that of an
    FMU variable of that name (a varied parameter, ``pounding.gap``) from the FMUs' declared
    interfaces; the bare name when neither says (a count)."""
    from ...fmus import FMU_NAMES
    from ...master.interface import declared_interface

    last = name.rsplit(".", 1)[-1]
    for suffix, unit in _SUFFIX_UNITS:
        if last.endswith(suffix):
            return f"{name} [{unit}]"
    for fmu in FMU_NAMES:
        info = declared_interface(fmu).variables.get(last)
        if info is not None:
            return f"{name} [{info.unit}]" if info.unit else name
    return name


def plot_results(csv_path: str | Path, x: str, y: str, by: str | None = None, where: Sequence[str] = (),
                 out: str | Path | None = None, logy: bool = False) -> Path:
    """Plot column ``y`` against varied column ``x`` of the ok rows, one curve per value of ``by``.

    ``where``: ``"COLUMN=VALUE"`` filters, needed when another varied column
    would put several points on one abscissa of one curve.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    csv_path = Path(csv_path)
    if not csv_path.is_file():
        raise StudyError(f"results file {csv_path} not found")
    header, rows = read_results(csv_path)
    for name in [x, y] + ([by] if by else []):
        if name not in header:
            raise StudyError(f"{csv_path} has no column {name!r}; columns: {', '.join(header)}")
    for condition in where:
        if "=" not in condition:
            raise StudyError(f"--where {condition!r}: expected COLUMN=VALUE")
        column, text = (s.strip() for s in condition.split("=", 1))
        if column not in header:
            raise StudyError(f"--where {condition!r}: no column {column!r}")
        rows = [r for r in rows if str(r[column]) == text or _canonical(r[column]) == _canonical(_parse(text))]
    ok = [r for r in rows if r["status"] == "ok" and r[x] is not None and r[y] is not None]
    if not ok:
        raise StudyError(f"{csv_path}: no ok row to plot" + (f" with {', '.join(where)}" if where else ""))
    groups: dict[Any, list[dict]] = {}
    for r in ok:
        groups.setdefault(r[by] if by else None, []).append(r)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for key, group in groups.items():
        group.sort(key=lambda r: r[x])
        xs = [r[x] for r in group]
        if len(set(map(_canonical, xs))) != len(xs):
            raise StudyError(f"{csv_path}: several rows share {x} = {xs[0]!r}"
                             + (f" for {by} = {key!r}" if by else "")
                             + ": another column varies too; pick one value with --where COLUMN=VALUE")
        ax.plot(xs, [r[y] for r in group], "o-", ms=3, lw=1.2, label=f"{key}" if by else None)
    skipped = len(rows) - len(ok)
    ax.set_xlabel(axis_label(x))
    ax.set_ylabel(axis_label(y))
    if logy:
        ax.set_yscale("log")
    ax.set_title(f"{csv_path.parent.name}: {y} against {x}" + (f" ({skipped} failed/unstable rows left out)"
                                                                 if skipped else ""), fontsize=10)
    ax.grid(alpha=0.3)
    if by:
        ax.legend(title=by, fontsize=8)
    fig.tight_layout()
    out = Path(out) if out else csv_path.parent / f"{_slug(y)}_vs_{_slug(x)}" \
        f"{'_by_' + _slug(by) if by else ''}.png"
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _parse(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _slug(name: str) -> str:
    return re.sub(r"[^\w.-]+", "_", name)
