"""The README documents every FMU variable, and its tables are the FMUs' own (no drift)."""
from pathlib import Path

import pytest

from cosim.fmus import FMUS
from cosim.apps.fmu_docs import markdown_table

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.mark.parametrize("name", [spec.name for spec in FMUS])
def test_readme_holds_the_generated_variable_table(fmu_path, name):
    table = markdown_table(fmu_path(name))
    text = README.read_text()
    missing = [line for line in table.splitlines() if line not in text]
    assert not missing, (f"README.md is out of date for {name}.fmu; regenerate with "
                         f"`pounding-cosim fmu-docs` ({len(missing)} lines differ, first: {missing[0]})")
