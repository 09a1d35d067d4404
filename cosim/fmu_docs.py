"""Markdown tables of the FMUs' variables, read from their modelDescription.xml.

    python -m cosim.fmu_docs [FMU_DIR]     # prints the tables pasted into README.md

The README's variable tables are generated from the built FMUs so that they cannot drift
from the contract; ``tests/test_readme_variables.py`` checks that they are in sync.
Array elements ``x[1] .. x[20]`` are shown once as ``x[i]``.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

from fmpy import read_model_description

_ELEMENT = re.compile(r"^(?P<base>[A-Za-z_]\w*)\[(?P<index>\d+)\]$")
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
            match = _ELEMENT.match(v.name)
            name = f"{match['base']}[i]" if match else v.name
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


def main(argv: list[str] | None = None) -> int:
    """Print the variable tables of every FMU; exit code 0, or 2 if an FMU file is missing."""
    import argparse

    from cosim.fmus import FMUS, build_all, fmu_folder

    parser = argparse.ArgumentParser(
        prog="python -m cosim.fmu_docs",
        description="Print the Markdown variable tables of the FMUs (pasted into README.md; "
                    "tests/test_readme_variables.py checks they are in sync).")
    parser.add_argument("fmu_dir", nargs="?", type=Path, default=None, metavar="FMU_DIR",
                        help="folder holding the built FMUs (default: build them into build/fmus, "
                             "rebuilt when fmu_src/ changed)")
    args = parser.parse_args(argv)
    folder = args.fmu_dir
    if folder is None:
        folder = fmu_folder()
        build_all(folder)
    missing = [f"{spec.name}.fmu" for spec in FMUS if not (folder / f"{spec.name}.fmu").is_file()]
    if missing:
        parser.exit(2, f"error: {folder}: no {', '.join(missing)} (build them with "
                       f"`python build_fmu.py --out {folder}`, or omit FMU_DIR)\n")
    for spec in FMUS:
        print(f"#### `{spec.name}.fmu`: {spec.summary}\n")
        print(markdown_table(folder / f"{spec.name}.fmu"))
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
