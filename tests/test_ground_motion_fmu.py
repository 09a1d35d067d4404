"""ground_motion.fmu through fmpy: plays the bundled records with their documented PGA."""
from __future__ import annotations

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from fmu_src.ground_records import BUNDLED, G
from test_building_fmu import Slave  # the same minimal fmpy driver


@pytest.fixture(scope="module")
def ground_fmu(fmu_path):
    return fmu_path("ground_motion")


def play(s, h, steps):
    rows = []
    for _ in range(steps):
        s.step(h)
        rows.append(s.get("ag", "ag_mean", "vg", "dg"))
    return np.array(rows)


def test_ground_motion_fmu_validates(ground_fmu):
    assert validate_fmu(str(ground_fmu)) == []


def test_plays_el_centro_with_documented_pga_and_zero_after_the_end(ground_fmu):
    s = Slave(ground_fmu, "elc")
    pga, duration, t_end = s.get("pga", "duration", "t_end")
    assert pga / G == pytest.approx(BUNDLED["elcentro1940"].pga_g, abs=5e-5)  # manifest: 4 decimals
    assert duration == pytest.approx(39.48, abs=1e-9) and t_end == duration
    h, steps = 0.01, 4100
    out = play(s, h, steps)
    t = h * np.arange(1, steps + 1)
    raw = np.loadtxt(BUNDLED["elcentro1940"].path) * G   # the file itself, independent of the parser
    # With h = dt the step ends are the samples (up to time round-off ~1e-13 s * slope).
    np.testing.assert_allclose(out[:3947, 0], raw[1:3948], rtol=0, atol=1e-9)
    assert np.max(np.abs(out[:, 0])) == pytest.approx(pga, rel=1e-9)
    after = t > 39.48 + 1e-9
    assert np.all(out[after, 0] == 0.0)
    assert np.all(out[t > 39.49 + 1e-9, 1] == 0.0)
    # vg is the trapezoid integral of the samples (exact for the piecewise-linear record) ...
    trap = np.concatenate([[0.0], np.cumsum(0.5 * 0.01 * (raw[1:] + raw[:-1]))])
    # (two summation orders over ~4000 terms of ~1e-3 m/s: round-off ~1e-12; 1e-10 of a 0.3 m/s peak)
    np.testing.assert_allclose(out[:3947, 2], trap[1:3948], rtol=0, atol=1e-10)
    # ... and the step means add up to it: what makes a ZOH building's velocity exact.
    np.testing.assert_allclose(np.cumsum(out[:, 1]) * h, out[:, 2], rtol=0, atol=1e-10)
    assert np.all(np.diff(out[after, 2]) == 0.0)  # constant velocity after the end
    s.close()


def test_target_pga_and_time_shift(ground_fmu):
    s = Slave(ground_fmu, "kobe", record="kobe1995", target_pga=3.0, time_shift=2.0)
    assert s.get("pga")[0] == pytest.approx(3.0, rel=1e-14)
    out = play(s, 0.02, 2400)
    t = 0.02 * np.arange(1, 2401)
    assert np.all(out[t < 2.0 - 1e-9, :] == 0.0)
    assert np.max(np.abs(out[:, 0])) == pytest.approx(3.0, rel=1e-9)
    raw = np.loadtxt(BUNDLED["kobe1995"].path)
    i = int(np.argmax(np.abs(raw)))
    k = int(round((2.0 + i * 0.02) / 0.02)) - 1    # the step ending at the shifted peak
    assert out[k, 0] == pytest.approx(3.0 * np.sign(raw[i]), rel=1e-9)
    s.close()


def test_plays_a_user_file(ground_fmu, tmp_path):
    path = tmp_path / "pulse.txt"
    path.write_text("0\n100\n0\n")
    s = Slave(ground_fmu, "pulse", record=str(path), format="column", dt=0.1, units="cm/s2")
    out = play(s, 0.05, 6)
    np.testing.assert_allclose(out[:, 0], [0.5, 1.0, 0.5, 0.0, 0.0, 0.0], atol=1e-12)
    # Triangle pulse of area 0.1 m/s: ground velocity ends at 0.1 m/s.
    assert out[-1, 2] == pytest.approx(0.1, rel=1e-12)
    s.close()


def test_bad_file_gives_an_error_naming_file_and_line(ground_fmu, tmp_path):
    missing = tmp_path / "missing.AT2"
    s = Slave(ground_fmu, "missing", record=str(missing))
    assert any(str(missing) in m and "file not found" in m for m in s.messages), s.messages
    with pytest.raises(Exception):
        s.step(0.01)
    s.close()
    bad = tmp_path / "bad.txt"
    bad.write_text("0.1\n0.2\n0.3x\n")
    s = Slave(ground_fmu, "bad", record=str(bad), dt=0.01)
    assert any(f"{bad}, line 3: '0.3x' is not a number" in m for m in s.messages), s.messages
    s.close()
    ok = tmp_path / "ok.txt"
    ok.write_text("0.1\n0.2\n")
    s = Slave(ground_fmu, "nodt", record=str(ok))
    assert any(f"{ok}: a single-column file has no time step: give dt" in m for m in s.messages), s.messages
    s.close()


def test_target_pga_g_and_target_sa_with_their_outputs(ground_fmu):
    from fmu_src.ground_records import load_record
    from fmu_src.response_spectrum import response_spectrum

    s = Slave(ground_fmu, "g", record="elcentro1940", target_pga_g=0.3)
    pga, factor, sa = s.get("pga", "scale_factor", "sa_at_period")
    assert pga == pytest.approx(0.3 * G, rel=1e-14) and sa == 0.0
    assert factor == pytest.approx(0.3 * G / load_record("elcentro1940").pga, rel=1e-14)
    s.close()
    s = Slave(ground_fmu, "sa", record="kobe1995", target_sa=4.9, sa_period=0.5)
    factor, sa, ag0 = s.get("scale_factor", "sa_at_period", "ag")
    assert sa == pytest.approx(4.9, rel=1e-12)
    out = play(s, 0.02, 2300)                  # the played samples (h = dt) have that PSa
    played = response_spectrum(np.concatenate([[ag0], out[:, 0]]), 0.02, [0.5])
    # samples read at t = k h: time round-off ~1e-13 s times the record's slope
    assert played.pseudo_acceleration[0] == pytest.approx(4.9, rel=1e-9)
    s.close()
    # sa_period alone reports the record's PSa without scaling it
    s = Slave(ground_fmu, "report", record="kobe1995", sa_period=1.0, sa_damping=0.02)
    factor, sa = s.get("scale_factor", "sa_at_period")
    rec = load_record("kobe1995")
    assert factor == 1.0
    assert sa == pytest.approx(response_spectrum(rec.acceleration, rec.dt, [1.0], 0.02).pseudo_acceleration[0],
                               rel=1e-15)
    s.close()


@pytest.mark.parametrize("params, message", [
    (dict(target_pga=2.9, target_pga_g=0.3),
     "at most one of target_pga, target_pga_g, target_sa may be set; got target_pga = 2.9 and target_pga_g = 0.3"),
    (dict(target_sa=4.9), "target_sa = 4.9 m/s2 needs sa_period (s), the period it applies at"),
    (dict(sa_period=1e-4), "sa_period = 0.0001 s is outside the allowed range 0.001 <= sa_period <= 100"),
    (dict(target_pga=1e300), "target_pga = 1e+300 m/s2 is outside the allowed range 0 <= target_pga <= 980.665"),
])
def test_bad_scaling_is_refused_at_exit_initialization(ground_fmu, tmp_path, params, message):
    never = tmp_path / "never_read.txt"        # the check comes before the file is touched
    s = Slave(ground_fmu, "bad", record=str(never), dt=0.01, **params)
    assert any(message in m for m in s.messages), s.messages
    assert not any("file not found" in m for m in s.messages)
    with pytest.raises(Exception):
        s.step(0.01)
    s.close()


def test_implausible_pga_is_played_with_a_logged_warning(ground_fmu, tmp_path):
    gal = tmp_path / "gal.txt"
    gal.write_text("0\n30.5\n-12\n0\n")
    s = Slave(ground_fmu, "gal", record=str(gal), dt=0.01)
    assert any(f"{gal}: its PGA read with units = 'g' is 30.5 g" in m for m in s.messages), s.messages
    s.step(0.01)                                # a warning, not an error
    assert s.get("ag")[0] == pytest.approx(30.5 * G)
    s.close()
