"""Markdown tables of the FMUs' variables, read from their modelDescription.xml.

    pounding-cosim fmu-docs [FMU_DIR]     # prints the tables pasted into README.md

The README's variable tables are generated from the built FMUs so that they cannot drift
from the contract; ``tests/test_readme_variables.py`` checks that they are in sync.
Array elements ``x[1] .. x[20]`` are shown once as ``x[i]``.
"""
from __future__ import annotations

import re
from pathlib import Path

from fmpy import read_model_description

from ..fmus import FMUS
from ..master.names import element

_ORDER = ("parameter", "input", "output")


def _strip_element(text: str) -> str:
    return re.sub(r"\s*\(element \d+\)", "", text or "")


def variable_rows(fmu: str | Path) -> list[tuple[str, str, str, str, str, str]]:
    """Rows (name, causality, type, unit, start, description), arrays collapsed to ``name[i]``."""
    md = read_model_description(str(fmu))
    rows, seen = [], set()
    for causality in _ORDER:
        for v in md.modelVariables:
            if v.causality != causality:
                continue
            base, index = element(v.name)
            name = f"{base}[i]" if index is not None else v.name
            if name in seen:
                continue
            seen.add(name)
            description = _strip_element(v.description).replace(v.name, name)
            unit = v.unit or ""
            description = description.replace(f" [{unit}]", "") if unit else description
            start = "" if v.start is None else str(v.start)
            rows.append((name, causality, v.type, unit, start, description.strip().strip(";").strip()))
    return rows


def markdown_table(fmu: str | Path) -> str:
    lines = ["| variable | causality | type | unit | start | description |",
             "|---|---|---|---|---|---|"]
    for name, causality, type_, unit, start, description in variable_rows(fmu):
        description = description.replace("|", "\\|")
        lines.append(f"| `{name}` | {causality} | {type_} | {unit} | {start} | {description} |")
    return "\n".join(lines)


def missing_fmus(folder: Path) -> list[str]:
    """The FMU files of the package that ``folder`` lacks."""
    return [f"{spec.name}.fmu" for spec in FMUS if not (Path(folder) / f"{spec.name}.fmu").is_file()]


def tables(folder: Path) -> str:
    """Every FMU's table with its heading, as pasted into README.md."""
    out = []
    for spec in FMUS:
        out.append(f"#### `{spec.name}.fmu`: {spec.summary}\n")
        out.append(markdown_table(Path(folder) / f"{spec.name}.fmu"))
        out.append("")
    return "\n".join(out) + "\n"
