"""Ground-motion records: bundled data against their documentation, parsers, exact calculus."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy.integrate import quad

from fmu_src.ground_records import BUNDLED, G, RECORDS_DIR, Record, RecordError, load_record


def manifest_rows():
    """The project's own copy of the manifest (never ../shared)."""
    with (RECORDS_DIR / "records_manifest.csv").open(newline="") as fh:
        return {row["file"]: row for row in csv.DictReader(fh)}


def test_bundled_names_and_files_are_the_project_copies():
    assert set(BUNDLED) == {"elcentro1940", "kobe1995", "sanfernando1971", "parkfield1966"}
    for meta in BUNDLED.values():
        assert meta.path.parent == RECORDS_DIR and meta.path.is_file()
        assert "shared" not in meta.path.parts
    with pytest.raises(TypeError):
        BUNDLED["mine"] = None  # immutable mapping


@pytest.mark.parametrize("name", sorted(BUNDLED))
def test_bundled_record_matches_documented_pga_duration_and_peak_time(name):
    meta = BUNDLED[name]
    row = manifest_rows()[meta.file]
    rec = load_record(name)
    assert rec.npts == int(row["npts"])
    assert rec.dt == float(row["dt_s"])
    # record_length_s = (npts - 1) dt, given to 0.01 s in the manifest.
    assert rec.duration == pytest.approx(float(row["record_length_s"]), abs=1e-9)
    # pga_g is rounded to 4 decimals: half a unit of the last digit.
    assert rec.pga_g == pytest.approx(float(row["pga_g"]), abs=5e-5)
    i = int(np.argmax(np.abs(rec.acceleration)))
    assert np.sign(rec.acceleration[i]) == int(row["pga_sign"])
    assert i * rec.dt == pytest.approx(float(row["pga_time_s"]), abs=0.5 * rec.dt)  # t(PGA) given to 0.01 s
    assert "recorded by" in rec.credit and rec.source.endswith(meta.file)


def test_bundled_values_are_file_values_times_g():
    rec = load_record("kobe1995")
    raw = np.loadtxt(BUNDLED["kobe1995"].path)
    np.testing.assert_array_equal(rec.acceleration, raw * G)


# -- exact piecewise-linear calculus -----------------------------------------------------------------
@pytest.fixture
def rec():
    rng = np.random.default_rng(11)
    return Record("random", 0.02, rng.normal(size=40), start_time=0.3)


def test_at_interpolates_linearly_and_is_zero_outside(rec):
    a = rec.acceleration
    assert rec.at(0.3) == a[0] and rec.at(0.3 + 39 * 0.02) == pytest.approx(a[-1], abs=1e-15)
    assert rec.at(0.31) == pytest.approx(0.5 * (a[0] + a[1]), rel=1e-12)
    assert rec.at(0.29) == 0.0 and rec.at(rec.end_time + 1e-9) == 0.0
    t = np.array([0.0, 0.31, 0.35, 5.0])
    np.testing.assert_allclose(rec.at(t), [rec.at(float(x)) for x in t], rtol=1e-15)


def test_mean_velocity_displacement_are_exact_integrals(rec):
    knots = list(rec.times)
    for t0, t1 in [(0.0, 0.5), (0.333, 0.337), (0.5, 0.9), (1.0, 1.5), (0.2, 2.0)]:
        integral = quad(rec.at, t0, t1, points=[k for k in knots if t0 < k < t1], limit=200)[0]
        assert rec.mean_over(t0, t1) == pytest.approx(integral / (t1 - t0), rel=1e-10, abs=1e-13)
    # velocity: quadrature of a on each linear piece (exact to round-off)
    for t in [0.1, 0.45, 0.777, 1.079, 3.0]:
        ref = quad(rec.at, 0.0, t, points=[k for k in knots if k < t], limit=200)[0]
        assert rec.velocity(t) == pytest.approx(ref, rel=1e-10, abs=1e-13)
        refd = quad(rec.velocity, 0.0, t, points=[k for k in knots if k < t], limit=200)[0]
        assert rec.displacement(t) == pytest.approx(refd, rel=1e-10, abs=1e-13)
    # At the samples the velocity is the trapezoid rule (exact for a piecewise-linear signal).
    trap = np.concatenate([[0.0], np.cumsum(0.5 * rec.dt * (rec.acceleration[1:] + rec.acceleration[:-1]))])
    np.testing.assert_allclose(rec.velocity(rec.times), trap, rtol=1e-12, atol=1e-14)
    # After the end: constant velocity, linear displacement.
    tend = rec.end_time
    assert rec.velocity(tend + 3.0) == pytest.approx(trap[-1], rel=1e-12)
    assert rec.displacement(tend + 3.0) - rec.displacement(tend) == pytest.approx(3.0 * trap[-1], rel=1e-10)


def test_step_means_telescope_to_the_velocity(rec):
    """A ZOH building fed mean_over gets exact velocity increments: sum(mean * h) = v(T)."""
    h = 0.0137
    t = h * np.arange(200)
    means = rec.mean_over(t[:-1], t[1:])
    assert np.sum(means * h) == pytest.approx(rec.velocity(t[-1]), rel=1e-12)


def test_scaling_target_pga_time_shift_and_units(tmp_path):
    base = load_record("elcentro1940")
    assert load_record("elcentro1940", scale=2.0).pga == pytest.approx(2 * base.pga, rel=1e-15)
    scaled = load_record("elcentro1940", target_pga=4.0, scale=7.0)  # target wins
    assert scaled.pga == pytest.approx(4.0, rel=1e-14)
    shifted = load_record("elcentro1940", time_shift=1.5)
    t = np.linspace(0, 45, 997)
    # (t + 1.5) - 1.5 != t in floating point: a time error of ~1e-15 s times a slope of up to
    # ~1e3 m/s^3 gives ~1e-12 m/s^2, against a PGA of 3 m/s^2.
    np.testing.assert_allclose(shifted.at(t + 1.5), base.at(t), rtol=0, atol=1e-10)
    assert shifted.at(1.49) == 0.0
    path = tmp_path / "gal.txt"
    path.write_text("100\n-250.5\n30\n")
    rec = load_record(path, dt=0.01, units="cm/s2")
    np.testing.assert_allclose(rec.acceleration, [1.0, -2.505, 0.3], rtol=1e-15)
    assert load_record(path, dt=0.01, units="m/s2").pga == 250.5
    with pytest.raises(ValueError, match="units = 'ft/s2'"):
        load_record(path, dt=0.01, units="ft/s2")
    with pytest.raises(RecordError, match="bundled record 'kobe1995' is in g"):
        load_record("kobe1995", units="m/s2")


# -- parsers -----------------------------------------------------------------------------------------
AT2_NEW = """PEER NGA STRONG MOTION DATABASE RECORD
Imperial Valley-02, 5/19/1940, El Centro Array #9, 180
ACCELERATION TIME SERIES IN UNITS OF G
NPTS=      7, DT=   .0100 SEC,      
  .9984852E-03  -.8338791E-03  -.1000000E-01   .2500000E+00  -.3000000E+00
   .1000000E-02  -.2000000E-02
"""
AT2_SPACED = AT2_NEW.replace("NPTS=      7, DT=   .0100 SEC,      ", "NPTS =      7 , DT =   .010 SEC ,")
AT2_OLD = AT2_NEW.replace("NPTS=      7, DT=   .0100 SEC,      ", "7    0.0100    NPTS, DT")
AT2_VALUES = [.9984852E-03, -.8338791E-03, -.01, .25, -.3, .001, -.002]


@pytest.mark.parametrize("text", [AT2_NEW, AT2_SPACED, AT2_OLD], ids=["npts=", "npts =", "old-style"])
@pytest.mark.parametrize("newline", ["\n", "\r\n"], ids=["LF", "CRLF"])
def test_at2_header_styles_and_line_endings(tmp_path, text, newline):
    path = tmp_path / "rec.AT2"
    path.write_bytes(text.replace("\n", newline).encode())
    rec = load_record(path)
    assert rec.dt == 0.01 and rec.npts == 7
    np.testing.assert_allclose(rec.acceleration, np.array(AT2_VALUES) * G, rtol=1e-15)
    assert rec.name == "rec"


def test_at2_glued_fortran_fields_and_format_override(tmp_path):
    text = AT2_NEW.replace("  .9984852E-03  -.8338791E-03", "  .9984852E-03-.8338791E-03")
    path = tmp_path / "glued.dat"   # no .AT2 suffix: sniffed from the header, or forced
    path.write_text(text)
    for fmt in ("auto", "at2"):
        np.testing.assert_allclose(load_record(path, fmt=fmt).acceleration, np.array(AT2_VALUES) * G, rtol=1e-15)


def test_single_column_and_csv(tmp_path):
    col = tmp_path / "acc.txt"
    col.write_text("0.0\n1.5E-1\n\n-.2\n3.27205E-5\n")
    rec = load_record(col, dt=0.005)
    np.testing.assert_allclose(rec.acceleration, np.array([0, 0.15, -0.2, 3.27205e-5]) * G)
    assert rec.duration == pytest.approx(0.015)
    for header in ("time,acc (g)\n", ""):
        path = tmp_path / f"t{len(header)}.csv"
        path.write_text(header + "0,0\n0.02,0.1\n0.04,-6.00E-05\n0.06,0.2\n")
        rec = load_record(path)
        assert rec.dt == pytest.approx(0.02, rel=1e-12) and rec.npts == 4
        assert rec.acceleration[2] == pytest.approx(-6e-5 * G)
    late = tmp_path / "late.csv"
    late.write_text("1.00,0.1\n1.01,0.2\n1.02,0.0\n")
    assert load_record(late, time_shift=0.5).start_time == pytest.approx(1.5)


def at2_with(tmp_path, old, new, name="bad.AT2"):
    path = tmp_path / name
    assert old in AT2_NEW
    path.write_text(AT2_NEW.replace(old, new))
    return path


@pytest.mark.parametrize("make, line, match", [
    (lambda p: at2_with(p, "-.1000000E-01", "-.1000000X-01"), 5, r"'-\.1000000X-01' is not a number"),
    (lambda p: at2_with(p, "NPTS=      7", "NPTS=      9"), 6, r"7 values, but NPTS = 9"),
    (lambda p: at2_with(p, "NPTS=      7", "NPTS=      5"), 6, r"more values than NPTS = 5"),
    (lambda p: at2_with(p, "ACCELERATION TIME SERIES IN UNITS OF G", "VELOCITY IN CM/S"), 3, r"expected 'ACCELERATION"),
    (lambda p: at2_with(p, "NPTS=      7, DT=   .0100 SEC,", "no count here"), 4, r"expected 'NPTS="),
    (lambda p: at2_with(p, "UNITS OF G", "UNITS OF FURLONGS"), 3, r"unknown unit 'FURLONGS'"),
    (lambda p: at2_with(p, "DT=   .0100 SEC", "DT=   .0000 SEC"), 4, r"DT = \.0000 s must be > 0"),
])
def test_malformed_at2_names_file_and_line(tmp_path, make, line, match):
    path = make(tmp_path)
    with pytest.raises(RecordError, match=match) as info:
        load_record(path)
    assert info.value.line == line and info.value.path == str(path)
    assert str(info.value).startswith(f"{path}, line {line}: ")


def test_malformed_column_and_csv_name_file_and_line(tmp_path):
    col = tmp_path / "acc.txt"
    col.write_text("0.1\n0.2\nabc\n")
    with pytest.raises(RecordError, match=r"acc\.txt, line 3: 'abc' is not a number"):
        load_record(col, dt=0.01)
    good = tmp_path / "good.txt"
    good.write_text("0.1\n0.2\n")
    with pytest.raises(RecordError, match=r"good\.txt: a single-column file has no time step"):
        load_record(good)
    with pytest.raises(RecordError, match=r"good\.txt, line 2: a single-column file has one value per line"):
        good.write_text("0.1\n0.2 0.3 0.4\n")
        load_record(good, fmt="column", dt=0.01)
    gap = tmp_path / "gap.csv"
    gap.write_text("time,acc\n0,0\n0.01,1\n0.03,2\n0.04,3\n0.05,4\n")
    # the sample at 0.02 s is missing: the jump is at line 4 (0.03 s), where it was written
    with pytest.raises(RecordError, match=r"gap\.csv, line 4: time jumps from 0\.01 s \(line 3\) to 0\.03 s"):
        load_record(gap)
    three = tmp_path / "three.csv"
    three.write_text("t,a\n0,1\n0.1,2,3\n")
    with pytest.raises(RecordError, match=r"three\.csv, line 3: expected 2 columns"):
        load_record(three)
    wrong_dt = tmp_path / "ok.csv"
    wrong_dt.write_text("0,1\n0.1,2\n0.2,3\n")
    with pytest.raises(RecordError, match=r"dt = 0.05 s was given but the record's time step is 0.1"):
        load_record(wrong_dt, dt=0.05)


def test_missing_file_and_bad_options(tmp_path):
    missing = tmp_path / "nope.AT2"
    with pytest.raises(RecordError, match=r"nope\.AT2: file not found") as info:
        load_record(missing)
    assert isinstance(info.value, ValueError) and info.value.line is None
    with pytest.raises(ValueError, match="format = 'xls'"):
        load_record("elcentro1940", fmt="xls")
    flat = tmp_path / "flat.txt"
    flat.write_text("0\n0\n0\n")
    with pytest.raises(RecordError, match="cannot scale to a target PGA"):
        load_record(flat, dt=0.01, target_pga=3.0)


# -- encodings, limits, honest messages (issue 14) -------------------------------------------------------
CSV_TEXT = "time,acc\n0,0\n0.02,0.1\n0.04,-6.00E-05\n0.06,0.2\n"


@pytest.mark.parametrize("encoding, bom", [("utf-8", b"\xef\xbb\xbf"), ("utf-16-le", b"\xff\xfe"),
                                           ("utf-16-be", b"\xfe\xff"), ("utf-16-le", b""),
                                           ("utf-16-be", b"")],
                         ids=["utf8-bom", "utf16le-bom", "utf16be-bom", "utf16le", "utf16be"])
@pytest.mark.parametrize("header", [True, False], ids=["header", "headerless"])
def test_byte_order_marks_and_utf16_read_every_row(tmp_path, encoding, bom, header):
    text = CSV_TEXT if header else CSV_TEXT.split("\n", 1)[1]
    path = tmp_path / "rec.csv"
    path.write_bytes(bom + text.encode(encoding))
    rec = load_record(path)
    np.testing.assert_allclose(rec.acceleration, np.array([0, 0.1, -6e-5, 0.2]) * G, rtol=1e-15)
    assert rec.dt == pytest.approx(0.02, rel=1e-12)
    col = tmp_path / "rec.txt"
    col.write_bytes(bom + "0.1\n-0.2\n0.3\n".encode(encoding))
    np.testing.assert_allclose(load_record(col, dt=0.01).acceleration, np.array([0.1, -0.2, 0.3]) * G)


def test_headerless_csv_keeps_its_first_row(tmp_path):
    """A first row is a header only when none of its cells is a number: Fortran D exponents,
    a header of two lines, and a row half text half number (an error, not a header)."""
    path = tmp_path / "d.csv"
    path.write_text("0.0,1.0D-1\n0.01,2.0D-1\n0.02,0\n")
    np.testing.assert_allclose(load_record(path).acceleration, np.array([0.1, 0.2, 0.0]) * G)
    path.write_text("time,acc\ns,g\n0,1\n0.1,2\n")
    assert load_record(path).npts == 2
    path.write_text("t,0.5\n0,1\n0.1,2\n")
    with pytest.raises(RecordError, match=r"d\.csv, line 1: 't' is not a number"):
        load_record(path)


def test_time_jump_reported_at_its_own_line_with_the_value_as_written(tmp_path):
    rows = [f"{i * 0.01:.2f},{np.sin(i / 7):.5f}" for i in range(1000)]
    del rows[500]                                  # data row 501 (file line 502) jumps by 2 dt
    path = tmp_path / "jump.csv"
    path.write_text("time,acceleration\n" + "\n".join(rows) + "\n")
    with pytest.raises(RecordError) as info:
        load_record(path)
    message = str(info.value)
    assert info.value.line == 502
    assert message == (f"{path}, line 502: time jumps from 4.99 s (line 501) to 5.01 s, a step of 0.02 s; "
                       f"the record's time step is 0.01 s")
    assert "np." not in message
    back = tmp_path / "back.csv"
    back.write_text("0,1\n0.01,2\n0.005,3\n")
    with pytest.raises(RecordError, match=r"back\.csv, line 3: time 0.005 s does not increase \(line 2: 0.01 s\)"):
        load_record(back)
    # steps growing by 6e-7 s each (at most 0.6 % of dt: no jump) drift 7.5 % of dt off the grid
    drift = tmp_path / "drift.csv"
    drift.write_text("".join(f"{i * 0.01 + 3e-7 * i * i:.9f},0\n" for i in range(100)))
    with pytest.raises(RecordError, match=r"drift\.csv, line \d+: non-uniform time step: t = 0\.\d+ s, expected"):
        load_record(drift)


def test_devices_and_oversized_files_are_refused_before_reading(tmp_path, monkeypatch):
    import fmu_src.ground_records as gr

    with pytest.raises(RecordError, match=r"^/dev/zero: is not a regular file \(a device, pipe or socket\)"):
        load_record("/dev/zero", dt=0.01)
    huge = tmp_path / "huge.txt"
    with huge.open("wb") as fh:                   # sparse: no disk used, and never read
        fh.truncate(gr.MAX_RECORD_BYTES + 1)
    with pytest.raises(RecordError, match=r"huge\.txt: is 32\.0 MiB; the limit of a record file is 32 MiB "
                                          r"\(1,000,000 samples\)"):
        load_record(huge, dt=0.01)
    at2 = tmp_path / "many.AT2"
    at2.write_text(AT2_NEW.replace("NPTS=      7", "NPTS= 2000000"))
    with pytest.raises(RecordError, match=r"many\.AT2, line 4: NPTS = 2000000 is more than 1,000,000 samples"):
        load_record(at2)
    monkeypatch.setattr(gr, "MAX_RECORD_SAMPLES", 3)   # the same check on a small file
    col = tmp_path / "col.txt"
    col.write_text("1\n2\n3\n4\n5\n")
    with pytest.raises(RecordError, match=r"col\.txt, line 4: more than 3 samples, the limit of a record"):
        load_record(col, dt=0.01)
    csv_path = tmp_path / "four.csv"
    csv_path.write_text("t,a\n0,1\n1,2\n2,3\n3,4\n")
    with pytest.raises(RecordError, match=r"four\.csv, line 5: more than 3 samples"):
        load_record(csv_path)


def test_binary_file_is_refused(tmp_path):
    path = tmp_path / "blob.txt"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(RecordError, match=r"blob\.txt: holds zero bytes but is not UTF-16 text"):
        load_record(path, dt=0.01)


def test_implausible_pga_for_the_stated_unit_warns(tmp_path):
    gal = tmp_path / "gal.txt"
    gal.write_text("0\n30.5\n-12\n0\n")                 # a record in cm/s^2 ...
    wrong = load_record(gal, dt=0.01)                    # ... read as g: 30.5 g, played with a warning
    assert len(wrong.warnings) == 1
    assert wrong.warnings[0].startswith(f"{gal}: its PGA read with units = 'g' is 30.5 g, outside 0.001-5 g")
    assert "cm/s2 read as g" in wrong.warnings[0]
    assert load_record(gal, dt=0.01, units="cm/s2").warnings == ()          # 0.031 g
    # the check is on the file's values in the stated unit, before any scaling
    assert load_record(gal, dt=0.01, target_pga_g=0.3).warnings == wrong.warnings
    assert load_record(gal, dt=0.01, units="cm/s2", scale=1e-3).warnings == ()
    low = tmp_path / "low.txt"
    low.write_text("0\n0.0005\n0\n")
    assert "is 0.0005 g, outside" in load_record(low, dt=0.01).warnings[0]
    for name in BUNDLED:
        assert load_record(name).warnings == ()
    # beyond MAX_PGA_G (100 g) a record is refused, unless a target scales it
    gal.write_text("0\n300.5\n-120\n0\n")
    with pytest.raises(ValueError, match=r"gal\.txt: its PGA is 300.5 g, above the limit of 100 g: check units"):
        load_record(gal, dt=0.01)
    assert load_record(gal, dt=0.01, target_pga_g=0.3).pga == pytest.approx(0.3 * G, rel=1e-14)


# -- scaling to engineers' targets (issue 15) --------------------------------------------------------------
def test_target_pga_in_g_and_scale_factor():
    base = load_record("elcentro1940")
    rec = load_record("elcentro1940", target_pga_g=0.3)
    assert rec.pga == pytest.approx(0.3 * G, rel=1e-14)
    assert rec.scale_factor == pytest.approx(0.3 * G / base.pga, rel=1e-15)
    np.testing.assert_allclose(rec.acceleration, base.acceleration * rec.scale_factor, rtol=1e-15)
    assert load_record("elcentro1940", target_pga=0.3 * G).pga == pytest.approx(rec.pga, rel=1e-15)


@pytest.mark.parametrize("period, damping", [(0.5, 0.05), (1.0, 0.05), (0.2, 0.02)])
def test_target_sa_gives_that_pseudo_acceleration(period, damping):
    from fmu_src.response_spectrum import response_spectrum

    rec = load_record("kobe1995", target_sa=4.9, sa_period=period, sa_damping=damping)
    spec = response_spectrum(rec.acceleration, rec.dt, [period], damping)  # of the scaled samples
    assert spec.pseudo_acceleration[0] == pytest.approx(4.9, rel=1e-12)
    base = response_spectrum(load_record("kobe1995").acceleration, rec.dt, [period], damping)
    assert rec.scale_factor == pytest.approx(4.9 / base.pseudo_acceleration[0], rel=1e-14)


def test_scaling_targets_are_exclusive_and_bounded(tmp_path):
    with pytest.raises(ValueError, match=r"at most one of target_pga, target_pga_g, target_sa may be set; "
                                         r"got target_pga = 2.9 and target_sa = 4.9 \(set the others to 0\)"):
        load_record("elcentro1940", target_pga=2.9, target_sa=4.9, sa_period=0.5)
    with pytest.raises(ValueError, match=r"target_sa = 4.9 m/s\^2 needs the period sa_period"):
        load_record("elcentro1940", target_sa=4.9)
    with pytest.raises(ValueError, match=r"ELC-180\.txt: scaling by 1e\+300 gives a PGA of 3.\d+e\+299 g, "
                                         r"above the limit of 100 g$"):
        load_record("elcentro1940", scale=1e300)
    with pytest.raises(ValueError, match=r"above the limit of 100 g"):
        load_record("elcentro1940", target_pga=1e300)
    with pytest.raises(ValueError, match=r"target_pga_g = -1.0 must be finite and > 0"):
        load_record("elcentro1940", target_pga_g=-1.0)
    flat = tmp_path / "flat.txt"
    flat.write_text("0\n0\n0\n")
    with pytest.raises(RecordError, match="all samples are zero: cannot scale to a target PSa"):
        load_record(flat, dt=0.01, target_sa=3.0, sa_period=1.0)


def test_plain_single_column_read_equals_the_careful_read(tmp_path):
    """The one-number-per-line fast path (_plain_column) against the line-by-line reader it
    short-cuts (_parse_column_lines): the same samples bit for bit on every bundled record and
    on random plain columns in every line ending and spacing; anything else (comments, commas,
    blank lines, Fortran D exponents, two values on a line, a word, a non-finite value) is left
    to the careful reader, which still names the file and line of a problem."""
    from pathlib import Path

    from fmu_src.ground_records import _parse_column, _parse_column_lines, _plain_column, _Text

    for meta in BUNDLED.values():
        text = _Text(meta.path, meta.path.read_text())
        plain = _plain_column(text.text)
        assert plain is not None                           # the bundled files take the fast path
        careful = _parse_column_lines(meta.path, text)
        assert plain.dtype == careful.dtype and np.array_equal(plain, careful)
    rng = np.random.default_rng(5)
    for trial in range(40):
        values = rng.normal(0.0, 10.0 ** rng.integers(-6, 3), int(rng.integers(1, 200)))
        fmt = ["{:.6f}", "{:.17g}", "{:e}", "  {:.9E}\t"][trial % 4]
        newline = ["\n", "\r\n", "\r"][trial % 3]
        body = newline.join(fmt.format(v) for v in values) + (newline if trial % 2 else "")
        plain = _plain_column(body)
        careful = _parse_column_lines(Path("x.txt"), _Text(Path("x.txt"), body))
        assert plain is not None and np.array_equal(plain, careful) and plain.size == values.size
    for body in ("1.0\n# comment\n2.0\n", "1.0,\n2.0\n", "1.0\n\n2.0\n", "1.0D-3\n2.0\n", "1.0 2.0\n3.0\n",
                 "1.0\nabc\n", "1.0\nnan\n", "inf\n", "1.0\x0c2.0\n"):
        assert _plain_column(body) is None
    path = tmp_path / "bad.txt"
    path.write_text("0.1\n0.2\n0.3 0.4\n")
    with pytest.raises(RecordError, match=r"bad.txt.*line 3"):
        _parse_column(path, _Text(path, path.read_text()))


def test_over_step_equals_the_four_methods_bit_for_bit():
    """ground_motion.fmu's doStep values (Record.over_step) are the doubles of at, mean_over,
    velocity and displacement, before, inside and after the record, on and between samples."""
    rec = load_record("kobe1995", target_pga_g=0.4, time_shift=0.7)
    rng = np.random.default_rng(11)
    starts = np.concatenate((rng.uniform(-1.0, rec.end_time + 2.0, 3000),
                             rec.start_time + rec.dt * rng.integers(-5, rec.npts + 5, 500)))
    for t0 in starts:
        t0 = float(t0)
        h = float(rng.choice([1e-3, 0.01, 0.02, 0.32, rng.uniform(1e-9, 1.0)]))
        t1 = t0 + h
        assert rec.over_step(t0, t1) == (rec.at(t1), rec.mean_over(t0, t1), rec.velocity(t1), rec.displacement(t1))
    with pytest.raises(ValueError, match="t1 > t0"):
        rec.over_step(1.0, 1.0)
