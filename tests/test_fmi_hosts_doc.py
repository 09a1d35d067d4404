"""docs/fmi_hosts.md for FMI users (issue 13, point 8): its example host runs, agrees with the
monolithic reference, and the page holds exactly the code that runs."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from cosim.peers import hosts

DOCS = Path(__file__).resolve().parents[1] / "docs"
EXAMPLE = DOCS / "examples" / "newmark_host.py"


def _example():
    spec = importlib.util.spec_from_file_location("newmark_host", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_page_shows_the_example_that_runs():
    code = EXAMPLE.read_text()
    body = code[code.index("import sys"):code.index('\n\nif __name__ == "__main__":')]
    assert body in (DOCS / "fmi_hosts.md").read_text(), "docs/fmi_hosts.md no longer shows docs/examples/newmark_host.py"


def test_the_newmark_example_host_agrees_with_the_reference(fmu_path):
    result = _example().simulate(str(fmu_path("pounding")))
    case = hosts.two_oscillators()       # the same two buildings, gap and law
    ref = hosts.reference(case)
    # the criteria at 1 ms; measured 2e-6 and 1e-4
    assert result["impacts"] == ref.impacts == 5
    assert result["F_max"] == pytest.approx(ref.peak_force_N, rel=0.02)
    assert result["E_dissipated"] == pytest.approx(ref.dissipated_energy_J, rel=0.03)
    assert result["F_max"] == pytest.approx(ref.peak_force_N, rel=1e-4)
    assert result["E_dissipated"] == pytest.approx(ref.dissipated_energy_J, rel=1e-3)
