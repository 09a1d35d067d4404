"""building.fmu through fmpy: closed forms, static limits, state save/restore, parameter errors."""
from __future__ import annotations

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException, calloc, free
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.validation import validate_fmu

from fmu_src.shear_building import ShearBuilding


class Slave:
    """A minimal fmpy co-simulation driver that keeps the instance's log messages.

    Deliberately independent of ``cosim/`` so that the FMUs are tested on their own.
    """

    def __init__(self, path, name="slave", **params):
        md = read_model_description(str(path))
        self.vars = {v.name: v for v in md.modelVariables}
        self.messages: list[str] = []
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(**params)
        self.refused = None   # the exception of a refused fmi2ExitInitializationMode (fmi2Fatal)
        try:
            self.fmu.exitInitializationMode()
        except FMICallException as exc:
            self.refused = exc
        self.t = 0.0

    def _log(self, env, instance, status, category, message):
        self.messages.append(message.decode(errors="replace"))

    def set(self, **values):
        for name, value in values.items():
            var = self.vars[name]
            vr = [var.valueReference]
            {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
             "String": self.fmu.setString,
             "Boolean": self.fmu.setBoolean}[var.type](vr, [value])

    def get(self, *names):
        return np.array(self.fmu.getReal([self.vars[n].valueReference for n in names]))

    def step(self, h, **inputs):
        self.set(**inputs)
        self.fmu.doStep(self.t, h)
        self.t += h

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


@pytest.fixture(scope="module")
def building_fmu(fmu_path):
    return fmu_path("building")


def test_building_fmu_validates(building_fmu):
    assert validate_fmu(str(building_fmu)) == []
    md = read_model_description(str(building_fmu))
    names = {v.name: v for v in md.modelVariables}
    for name in ("n_storeys", "m[20]", "k[1]", "T1", "zeta", "damping", "x0[3]", "v0[3]", "ag", "F[20]",
                 "x[1]", "v[1]", "a[1]", "drift[20]", "base_shear", "E_kinetic", "E_strain", "E_damping",
                 "E_input", "E_external"):
        assert name in names, name
    assert names["x[1]"].unit == "m" and names["E_input"].unit == "J" and names["F[2]"].causality == "input"
    assert names["n_storeys"].type == "Integer" and names["damping"].type == "String"


def test_sdof_free_vibration_matches_closed_form(building_fmu):
    """Default building: m = 1e5 kg, k giving T1 = 0.5 s, zeta = 0.05, released from x0 = 2 cm."""
    s = Slave(building_fmu, "free", **{"x0[1]": 0.02, "v0[1]": 0.1})
    w, zeta = 2 * np.pi / 0.5, 0.05
    wd = w * np.sqrt(1 - zeta ** 2)
    h, xs = 0.01, []
    for _ in range(300):
        s.step(h)
        xs.append(s.get("x[1]", "v[1]", "a[1]", "E_kinetic", "E_strain", "E_damping"))
    xs = np.array(xs)
    t = h * np.arange(1, 301)
    u = np.exp(-zeta * w * t) * (0.02 * np.cos(wd * t) + (0.1 + zeta * w * 0.02) / wd * np.sin(wd * t))
    # Exact integration: only round-off (~1e-15 per step) separates the FMU from the closed form.
    np.testing.assert_allclose(xs[:, 0], u, rtol=0, atol=1e-12)
    # Free vibration, no ground motion: absolute = relative acceleration = -w^2 u - 2 zeta w v.
    np.testing.assert_allclose(xs[:, 2], -w * w * xs[:, 0] - 2 * zeta * w * xs[:, 1], rtol=0, atol=1e-9)
    e0 = 0.5 * 1e5 * 0.1 ** 2 + 0.5 * 1e5 * w * w * 0.02 ** 2
    np.testing.assert_allclose(xs[:, 3] + xs[:, 4] + xs[:, 5], e0, rtol=1e-12)
    s.close()


def test_force_at_a_floor_reaches_the_static_deflection(building_fmu):
    """A constant force P on floor 2 of 3: after the transient, storeys 1 and 2 carry P, storey 3 nothing."""
    k = [3e8, 2e8, 1e8]
    params = {"n_storeys": 3, "m[1]": 2e5, "m[2]": 2e5, "m[3]": 1e5, "zeta": 0.1, "damping": "modal",
              **{f"k[{i + 1}]": ki for i, ki in enumerate(k)}}
    s = Slave(building_fmu, "force", **params)
    P, h = 5e5, 0.01
    for _ in range(1500):
        s.step(h, **{"F[2]": P})
    out = s.get("drift[1]", "drift[2]", "drift[3]", "base_shear", "x[3]", "x[4]",
                "E_external", "E_kinetic", "E_strain", "E_damping", "E_input", "a[2]")
    # Slowest mode decays as exp(-zeta w1 t) ~ exp(-0.1 * 17 * 15) ~ 1e-11: static to ~1e-11 relative.
    np.testing.assert_allclose(out[:3], [P / k[0], P / k[1], 0.0], rtol=1e-9, atol=1e-12)
    assert out[3] == pytest.approx(P, rel=1e-9)
    assert out[4] == pytest.approx(P / k[0] + P / k[1], rel=1e-9)
    assert out[5] == 0.0                                      # unused storey 4: output 0
    # Energy: the force did work P * x2; half is stored, half dissipated (static loading by a step force).
    x2 = P / k[0] + P / k[1]
    assert out[6] == pytest.approx(P * x2, rel=1e-9)
    assert out[8] == pytest.approx(0.5 * P * x2, rel=1e-9)
    assert out[6] == pytest.approx(out[7] + out[8] + out[9], rel=1e-10)
    assert out[10] == 0.0 and abs(out[11]) < 1e-6
    s.close()


def test_constant_ground_acceleration_rides_the_ground(building_fmu):
    """Under constant ag the building settles at u = -M K^-1 1 ag and accelerates with the ground."""
    s = Slave(building_fmu, "ride", n_storeys=2, T1=0.4, zeta=0.2)
    ag, h = 1.5, 0.005
    for _ in range(2000):
        s.step(h, ag=ag)
    a = s.get("a[1]", "a[2]", "x[1]", "x[2]", "E_input", "E_kinetic", "E_strain", "E_damping")
    np.testing.assert_allclose(a[:2], ag, rtol=1e-8)
    b = ShearBuilding.from_period(0.4, [1e5, 1e5], [1.0, 1.0], 0.2)
    np.testing.assert_allclose(a[2:4], np.linalg.solve(b.K, -b.masses * ag), rtol=1e-8)
    assert a[4] == pytest.approx(a[5] + a[6] + a[7], rel=1e-10)
    s.close()


def test_free_mass_under_constant_force(building_fmu):
    s = Slave(building_fmu, "free_mass", **{"m[1]": 200.0, "k[1]": 0.0, "zeta": 0.0})
    for _ in range(100):
        s.step(0.01, **{"F[1]": 50.0})
    x, v, a = s.get("x[1]", "v[1]", "a[1]")
    assert (x, v, a) == pytest.approx((50.0 / 400.0, 0.25, 0.25), rel=1e-12)
    s.close()


def test_state_save_restore_is_identical(building_fmu):
    s = Slave(building_fmu, "state", n_storeys=3, T1=0.6, **{"x0[3]": 0.05})
    names = ("x[1]", "x[2]", "x[3]", "v[3]", "a[2]", "E_damping", "E_input", "E_external", "E_strain")
    rng = np.random.default_rng(2)
    inputs = rng.normal(size=(60, 2))
    for i in range(40):
        s.step(0.01, ag=inputs[i, 0], **{"F[2]": 1e4 * inputs[i, 1]})
    state = s.fmu.getFMUstate()
    t0 = s.t
    first = []
    for i in range(40, 60):
        s.step(0.005 if i % 2 else 0.01, ag=inputs[i, 0], **{"F[2]": 1e4 * inputs[i, 1]})
        first.append(s.get(*names))
    s.fmu.setFMUstate(state)
    s.t = t0
    second = []
    for i in range(40, 60):
        s.step(0.005 if i % 2 else 0.01, ag=inputs[i, 0], **{"F[2]": 1e4 * inputs[i, 1]})
        second.append(s.get(*names))
    np.testing.assert_array_equal(np.array(first), np.array(second))
    s.fmu.freeFMUstate(state)
    s.close()


@pytest.mark.parametrize("params, fragment", [
    ({"m[1]": -5.0}, "m[1] = -5.0 kg is outside the allowed range 1e-06 <= m[1] <= 1e+12"),
    ({"m[1]": 1e300}, "m[1] = 1e+300 kg is outside the allowed range 1e-06 <= m[1] <= 1e+12"),
    ({"T1": 1e300}, "T1 = 1e+300 s is outside the allowed range 0 <= T1 <= 100"),
    ({"n_storeys": 0}, "n_storeys = 0 is outside the allowed range 1 <= n_storeys <= 20"),
    ({"n_storeys": 21}, "n_storeys = 21 is outside the allowed range 1 <= n_storeys <= 20"),
    ({"n_storeys": 2, "k[2]": 0.0}, "k[2] = 0"),
    ({"k[1]": 0.0}, "free mass"),
    ({"zeta": 1.5}, "zeta = 1.5 is outside the allowed range 0 <= zeta < 1"),
    ({"damping": "hysteretic"}, "damping = 'hysteretic' is not allowed: one of 'rayleigh', 'modal'"),
])
def test_bad_parameters_give_an_error_naming_the_variable(building_fmu, params, fragment):
    s = Slave(building_fmu, "bad", **params)
    # refused at fmi2ExitInitializationMode, the earliest point FMI allows: pythonfmu can only
    # answer fmi2Fatal there, and logs the slave's message in its wrapper of the exception
    assert s.refused is not None and s.refused.status == 4
    assert any(fragment in m for m in s.messages), s.messages
    with pytest.raises(Exception):  # a refused instance refuses every step too (fmi2Discard)
        s.step(0.01)
    s.close()


def test_unused_storeys_are_ignored_and_non_finite_inputs_refused(building_fmu):
    s = Slave(building_fmu, "unused", n_storeys=2, **{"m[5]": -1.0, "x0[5]": 3.0})
    s.step(0.01, **{"F[5]": 1e9})
    assert not s.messages
    assert s.get("x[5]", "drift[5]", "a[5]").tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(Exception):
        s.step(0.01, **{"F[2]": float("nan")})
    assert any("F[2] = nan N is not finite" in m for m in s.messages), s.messages
    s.close()


@pytest.mark.parametrize("change", [{}, {"T1": 0.9}, {"k[2]": 3.0e8}, {"zeta": 0.02}])
def test_reset_then_new_parameters_equal_a_fresh_instance(building_fmu, change):
    """After fmi2Reset new parameters act as in a fresh instance (studies reset between cases)."""
    params = dict(n_storeys=3, T1=0.6, **{"x0[3]": 0.05})
    names = ("x[1]", "x[3]", "v[3]", "a[2]", "E_damping", "E_input")

    def drive(s):
        out = []
        for i in range(30):
            s.step(0.01 if i % 3 else 0.005, ag=np.sin(0.3 * i), **{"F[2]": 1e4 * np.cos(0.2 * i)})
            out.append(s.get(*names))
        return np.array(out)

    reused = Slave(building_fmu, "reused", **params)
    drive(reused)
    reused.fmu.reset()
    reused.fmu.setupExperiment(startTime=0.0)
    reused.fmu.enterInitializationMode()
    reused.set(**{**params, **change})
    reused.fmu.exitInitializationMode()
    reused.t = 0.0
    fresh = Slave(building_fmu, "fresh", **{**params, **change})
    np.testing.assert_array_equal(drive(reused), drive(fresh))   # bit for bit: same matrices
    reused.close()
    fresh.close()
