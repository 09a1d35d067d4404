"""Spectrum files (cosim/apps/spectra.py): the CSV reads back to the numbers, nothing is overwritten."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from cosim.apps.spectra import COLUMNS, spectrum_table, write_spectrum
from fmu_src.ground_records import G, load_record
from fmu_src.response_spectrum import default_periods, response_spectrum


@pytest.fixture(scope="module")
def spectra():
    periods = default_periods(30)
    out = []
    for name in ("elcentro1940", "kobe1995"):
        rec = load_record(name, target_pga_g=0.3)
        out.append(response_spectrum(rec.acceleration, rec.dt, periods, name=name))
    return out


def test_csv_holds_every_spectrum_with_units(tmp_path, spectra):
    paths = write_spectrum(spectra, tmp_path)
    assert [p.name for p in paths] == ["spectrum.csv", "spectrum.png"]
    assert paths[1].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = paths[0].read_text().splitlines()
    assert lines[0].startswith("# elastic response spectra, damping ratio 0.05")
    rows = list(csv.DictReader(lines[1:]))
    assert list(rows[0]) == ["period_s"] + [f"{n}.{c[0]}" for n in ("elcentro1940", "kobe1995") for c in COLUMNS]
    table = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    for s in spectra:
        # written with 10 significant digits
        np.testing.assert_allclose(table["period_s"], s.periods, rtol=1e-9)
        np.testing.assert_allclose(table[f"{s.name}.Sd_m"], s.displacement, rtol=1e-9)
        np.testing.assert_allclose(table[f"{s.name}.PSa_g"], s.pseudo_acceleration / G, rtol=1e-9)
        np.testing.assert_allclose(table[f"{s.name}.PSv_m_s"] * 2 * np.pi / table["period_s"],
                                   table[f"{s.name}.PSa_m_s2"], rtol=1e-8)


def test_existing_files_are_never_replaced(tmp_path, spectra):
    mine = tmp_path / "spectrum.png"
    mine.write_text("the user's own file")
    with pytest.raises(FileExistsError, match=r"spectrum\.png exists: spectra are never written over a file"):
        write_spectrum(spectra, tmp_path)
    assert mine.read_text() == "the user's own file"
    assert not (tmp_path / "spectrum.csv").exists()            # nothing half-written


def test_one_table_needs_one_grid_and_distinct_names(spectra):
    rec = load_record("parkfield1966")
    other = response_spectrum(rec.acceleration, rec.dt, [0.5, 1.0], name="parkfield1966")
    with pytest.raises(ValueError, match="differ in periods or damping"):
        spectrum_table([spectra[0], other])
    with pytest.raises(ValueError, match="two spectra have the same name"):
        spectrum_table([spectra[0], spectra[0]])
