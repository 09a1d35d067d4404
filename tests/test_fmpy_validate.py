"""Every built FMU is a complete, valid FMI 2.0 co-simulation FMU (issue 7, part 1).

* ``fmpy.validation.validate_fmu`` finds no problem (XML schema, variable names,
  ModelStructure, start values, causality/variability combinations, units);
* the model description is complete: a description on the model and on every
  variable, a unit on every dimensional Real, a default experiment, the
  InitialUnknowns that FMI 2.0 requires;
* the capability flags are true statements: ``canGetAndSetFMUstate`` (restore a
  saved state and replay the same steps bit for bit) and
  ``canHandleVariableCommunicationStepSize`` (steps of different lengths give the
  same trajectory where the FMU's integration is exact);
* pythonfmu binaries: linux64 and win64 are in every FMU.
"""
from __future__ import annotations

import math
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from cosim.fmus import CAPABILITIES, FMUS

NAMES = [spec.name for spec in FMUS]

# Real variables that are dimensionless by definition (no unit is the FMI convention).
# A new Real variable without a unit and not listed here fails the completeness test.
DIMENSIONLESS = {
    "building": {"zeta"},
    "ground_motion": {"scale"},
    "pounding": {"CR", "n", "zeta"},
}

# Parameters that make the initial outputs non-trivial (an initial displacement, a
# contact element with inputs set).
INTERESTING = {
    "building": {"n_storeys": 2, "m[1]": 2e5, "m[2]": 2e5, "k[1]": 3e7, "k[2]": 3e7, "x0[1]": 0.01},
    "ground_motion": {},
    "pounding": {},
}


def _md(fmu_path, name):
    return read_model_description(str(fmu_path(name)))


@pytest.mark.parametrize("name", NAMES)
def test_fmpy_validate_finds_no_problem(fmu_path, name):
    assert validate_fmu(str(fmu_path(name))) == []


@pytest.mark.parametrize("name", NAMES)
def test_model_description_is_complete(fmu_path, name):
    md = _md(fmu_path, name)
    assert md.fmiVersion == "2.0" and md.coSimulation is not None
    assert md.description, "the model has no description"
    exp = md.defaultExperiment
    assert exp is not None, "no DefaultExperiment"
    start, stop, step = float(exp.startTime), float(exp.stopTime), float(exp.stepSize)
    assert 0.0 <= start < stop and 0.0 < step <= stop - start
    defined_units = {u.name for u in md.unitDefinitions}
    for v in md.modelVariables:
        assert v.description and v.description.strip(), f"{name}.{v.name} has no description"
        if v.type == "Real" and v.name.split("[")[0] not in DIMENSIONLESS.get(name, set()):
            assert v.unit, f"{name}.{v.name} is a Real without a unit"
        if v.unit:
            assert v.unit in defined_units, f"{name}.{v.name}: unit {v.unit!r} not in UnitDefinitions"
    # FMI 2.0 (section 2.2.8): InitialUnknowns lists exactly the outputs with initial
    # "approx"/"calculated" (plus calculated parameters); outputs with initial "exact"
    # must not be listed.  fmpy checks the same set; asserted here so that a change of
    # `initial` in fmi_slave.py cannot silently leave the list stale.
    expected = {v.name for v in md.modelVariables
                if (v.causality == "output" and v.initial in ("approx", "calculated"))
                or v.causality == "calculatedParameter"}
    assert {u.variable.name for u in md.initialUnknowns} == expected
    assert {u.variable.name for u in md.outputs} == {v.name for v in md.modelVariables if v.causality == "output"}


@pytest.mark.parametrize("name", NAMES)
def test_capability_flags_are_the_supported_ones(fmu_path, name):
    cs = _md(fmu_path, name).coSimulation
    for flag, value in CAPABILITIES.items():
        assert getattr(cs, flag) is value, f"{name}: {flag} = {getattr(cs, flag)}"
    # pythonfmu keeps the state as a Python object: it cannot serialise it to bytes
    assert cs.canSerializeFMUstate is False
    assert cs.canInterpolateInputs is False  # inputs are held over the step (zero-order hold)


@pytest.mark.parametrize("name", NAMES)
def test_binaries_cover_linux64_and_win64(fmu_path, name):
    md = _md(fmu_path, name)
    ident = md.coSimulation.modelIdentifier
    with zipfile.ZipFile(fmu_path(name)) as zf:
        files = set(zf.namelist())
    assert f"binaries/linux64/{ident}.so" in files
    assert f"binaries/win64/{ident}.dll" in files


# -- running the FMUs through fmpy's FMU2Slave, the way any FMI host would -------------------------
class _Slave:
    """Minimal FMI host around fmpy's FMU2Slave (set by name, read outputs)."""

    def __init__(self, path, unzip, md, instance="probe"):
        self.md = md
        self.vars = {v.name: v for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=instance)
        self.fmu.instantiate()

    def set(self, values):
        for name, value in values.items():
            v = self.vars[name]
            {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger, "Boolean": self.fmu.setBoolean,
             "String": self.fmu.setString}[v.type]([v.valueReference], [value])

    def outputs(self):
        reals = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        ints = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Integer"]
        values = list(self.fmu.getReal([v.valueReference for v in reals])) if reals else []
        values += list(self.fmu.getInteger([v.valueReference for v in ints])) if ints else []
        return np.array(values, dtype=float)

    def start(self, parameters):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(parameters)
        self.fmu.exitInitializationMode()

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def _inputs(md, t):
    """Smooth test inputs by unit: two bodies oscillating towards each other, a ground
    acceleration, a floor force.  Amplitudes are typical of the scenes (cm, dm/s, m/s^2, kN)."""
    amplitude = {"m": 0.05, "m/s": 0.3, "m/s2": 2.0, "N": 1e5}
    values = {}
    for i, v in enumerate(v for v in md.modelVariables if v.causality == "input" and v.type == "Real"):
        sign = -1.0 if v.name.endswith("2") else 1.0  # x2, v2 move against x1, v1
        values[v.name] = sign * amplitude.get(v.unit, 1.0) * math.sin(2 * math.pi * 1.3 * t + 0.1 * i)
    return values


@pytest.fixture(scope="module")
def unzipped(fmu_path):
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = extract(str(fmu_path(name)))
        return cache[name]
    return get


@pytest.mark.parametrize("name", NAMES)
def test_get_and_set_fmu_state_replays_exactly(fmu_path, unzipped, name):
    md = _md(fmu_path, name)
    s = _Slave(fmu_path(name), unzipped(name), md)
    try:
        s.start(INTERESTING[name])
        h = 0.01
        for k in range(20):
            s.set(_inputs(md, k * h))
            s.fmu.doStep(k * h, h)
        state = s.fmu.getFMUstate()
        first = []
        for k in range(20, 60):
            s.set(_inputs(md, k * h))
            s.fmu.doStep(k * h, h)
            first.append(s.outputs())
        s.fmu.setFMUstate(state)
        second = []
        for k in range(20, 60):
            s.set(_inputs(md, k * h))
            s.fmu.doStep(k * h, h)
            second.append(s.outputs())
        s.fmu.freeFMUstate(state)
    finally:
        s.close()
    first, second = np.array(first), np.array(second)
    assert np.any(first[0] != first[-1]), "the outputs did not change: the test would prove nothing"
    np.testing.assert_array_equal(second, first)  # a restored state replays bit for bit


def _end_state(s, md, name, steps):
    """Step through ``steps`` (list of h) with inputs constant in time; return the outputs."""
    inputs = _inputs(md, 0.3)
    t = 0.0
    for h in steps:
        s.set(inputs)
        s.fmu.doStep(t, h)
        t += h
    return dict(zip([v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
                    + [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Integer"],
                    s.outputs()))


# Outputs that are exact functions of the time reached, whatever the step partition:
# the building's zero-order-hold solution (matrix exponential) with constant inputs,
# and the ground motion's piecewise-linear record and its exact integrals.  ``ag_mean``
# is the mean over the *last* step, so it depends on the partition by definition.
PARTITION_FREE = {"building": ("x[1]", "x[2]", "v[1]", "v[2]", "E_input", "E_damping", "E_external"),
                  "ground_motion": ("ag", "vg", "dg")}


@pytest.mark.parametrize("name", sorted(PARTITION_FREE))
def test_variable_communication_step_gives_the_same_trajectory(fmu_path, unzipped, name):
    md = _md(fmu_path, name)
    uniform = [0.02] * 25                          # 0.5 s in equal steps
    varied = [0.005, 0.015, 0.03, 0.01, 0.04] * 5  # 0.5 s in five different lengths
    results = []
    for steps in (uniform, varied):
        s = _Slave(fmu_path(name), unzipped(name), md, instance=f"probe_{len(results)}")
        try:
            s.start(INTERESTING[name])
            results.append(_end_state(s, md, name, steps))
        finally:
            s.close()
    for key in PARTITION_FREE[name]:
        a, b = results[0][key], results[1][key]
        assert a != 0.0, f"{name}.{key} stayed 0: the test would prove nothing"
        # exact discretisations: only round-off differs (25 steps, products of 2x2..4x4 matrices)
        assert b == pytest.approx(a, rel=1e-9, abs=1e-12), key


def test_pounding_accepts_varying_steps(fmu_path, unzipped):
    """The contact FMU integrates inside each step, so any step length is accepted; its
    force output is the mean of the step (contract: ``F h`` = ``impulse``, F >= 0)."""
    md = _md(fmu_path, "pounding")
    s = _Slave(fmu_path("pounding"), unzipped("pounding"), md)
    names = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"] + \
            [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Integer"]
    try:
        s.start(INTERESTING["pounding"])
        t = 0.0
        for h in [0.005, 0.015, 0.03, 0.01, 0.04] * 8:
            s.set(_inputs(md, t))
            s.fmu.doStep(t, h)
            t += h
            out = dict(zip(names, s.outputs()))
            assert out["F"] >= 0.0
            # the impulse is the mean force times this step's length (to round-off)
            assert out["impulse"] == pytest.approx(out["F"] * h, rel=1e-12, abs=1e-9)
    finally:
        s.close()
    assert out["impacts"] > 0 and out["E_dissipated"] > 0.0, "no impact happened: the test would prove nothing"


@pytest.mark.parametrize("name", NAMES)
def test_exact_outputs_start_at_their_start_value(fmu_path, unzipped, name):
    """initial="exact" promises that an output's start value is its value at t0 (FMI 2.0,
    section 2.2.7).  A host that reads outputs during initialisation (libcosim does)
    relies on it.  Outputs computed from parameters must be initial="calculated"."""
    md = _md(fmu_path, name)
    s = _Slave(fmu_path(name), unzipped(name), md)
    try:
        s.start(INTERESTING[name])
        names = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"] + \
                [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Integer"]
        values = dict(zip(names, s.outputs()))
    finally:
        s.close()
    wrong = {v.name: (float(v.start), values[v.name]) for v in md.modelVariables
             if v.name in values and v.initial == "exact" and values[v.name] != float(v.start)}
    assert not wrong, f"{name}: initial='exact' outputs that are not at their start value after " \
                      f"initialisation (start, value): {wrong}"
