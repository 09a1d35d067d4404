"""The FMI layer (cosim/fmi.py): typed access, status checks, log routing, reset, FMU state."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.master.fmi import FMU, FMUError


@pytest.fixture(scope="module")
def building(fmu_path):
    fmu = FMU(fmu_path("building"))
    yield fmu
    fmu.close()


def start(inst, **params):
    inst.setup(0.0, 1.0)
    inst.set(params)
    inst.exit_initialization()


def test_variable_lookup_by_name_and_type(building):
    m1 = building.variable("m[1]", "parameter")
    assert m1.type == "Real" and m1.unit == "kg"
    assert building.variable("n_storeys").type == "Integer"
    assert building.variable("damping").type == "String"
    assert building.variable("x[3]", "output").causality == "output"
    with pytest.raises(KeyError, match="did you mean"):
        building.variable("mass[1]")
    with pytest.raises(KeyError, match="is an output, not a parameter"):
        building.variable("x[1]", "parameter")


def test_an_unknown_variable_composes_its_suggestions_only_when_shown():
    """A probe for a variable the FMU lacks (the master counts an FMU's knots that way at every
    run's start) costs no difflib search; shown or pickled, the error reads as before."""
    import pickle

    from cosim.master.interface import declared_interface

    interface = declared_interface("building")
    with pytest.raises(KeyError) as probe:
        interface.variable("t_knot[999]", "input")
    assert probe.value._message is None
    eager = KeyError(interface.unknown_variable_message("t_knot[999]", "input"))
    assert str(probe.value) == str(eager) and "did you mean" in str(eager)
    again = pickle.loads(pickle.dumps(probe.value))
    assert type(again) is KeyError and str(again) == str(eager)


def test_typed_set_get_and_vectorised_ports(building):
    inst = building.instantiate("b")
    try:
        start(inst, **{"n_storeys": 2, "m[1]": 1.0e5, "m[2]": 2.0e5, "k[1]": 4.0e7, "k[2]": 3.0e7,
                       "x0[1]": 0.01, "x0[2]": 0.02, "damping": "rayleigh"})
        got = inst.get(["n_storeys", "m[2]", "damping", "x[1]", "x[2]"])
        assert got == {"n_storeys": 2, "m[2]": 2.0e5, "damping": "rayleigh", "x[1]": 0.01, "x[2]": 0.02}
        port = inst.real_port(["x[1]", "x[2]", "E_strain"])
        values = port.get()
        # strain energy of the initial state, closed form 0.5 k1 x1^2 + 0.5 k2 (x2 - x1)^2
        assert values[:2].tolist() == [0.01, 0.02]
        assert values[2] == pytest.approx(0.5 * 4e7 * 0.01**2 + 0.5 * 3e7 * 0.01**2, rel=1e-12)
        inputs = inst.real_port(["ag", "F[1]"])
        inputs.set([0.0, 1.0e3])
        assert inst.get(["F[1]"])["F[1]"] == 1.0e3
        calls = inst.calls
        inst.do_step(0.0, 0.01)
        assert inst.calls == calls + 1 and inst.do_steps == 1
        with pytest.raises(TypeError, match="Integer"):
            inst.set({"n_storeys": 2.5})
        with pytest.raises(TypeError, match="String"):
            inst.set({"damping": 3})
    finally:
        inst.free()


def test_bad_parameter_raises_fmu_error_with_the_slave_message(building):
    inst = building.instantiate("bad")
    try:
        with pytest.raises(FMUError) as info:
            start(inst, **{"m[1]": -5.0})
        err = info.value
        # pythonfmu returns OK from fmi2ExitInitializationMode: the logged error must still raise
        assert err.function == "fmi2ExitInitializationMode"
        assert "m[1]" in str(err) and "-5" in str(err) and "\n" not in str(err)
        assert str(err).startswith("bad:")
        # a refused instance keeps refusing, with the message, at its first step
        with pytest.raises(FMUError, match="m\\[1\\]"):
            inst.do_step(0.0, 0.01)
    finally:
        inst.free()


def test_log_messages_reach_the_instance_that_logged_them(building):
    good, bad = building.instantiate("good"), building.instantiate("bad2")
    try:
        start(good)
        with pytest.raises(FMUError):
            start(bad, **{"k[1]": -1.0})
        assert any("k[1]" in m.text for m in bad.messages)
        assert not any("k[1]" in m.text for m in good.messages)
    finally:
        good.free()
        bad.free()


def test_reset_restores_start_values_and_reproduces_the_run(building):
    inst = building.instantiate("r")
    try:
        def run():
            start(inst, **{"m[1]": 1.0e5, "k[1]": 4.0e7, "x0[1]": 0.05})
            port = inst.real_port(["x[1]", "v[1]"])
            out = []
            for k in range(50):
                inst.do_step(k * 0.01, 0.01)
                out.append(port.get().copy())
            return np.array(out)

        first = run()
        inst.reset()
        assert inst.get(["x0[1]", "m[1]"]) == {"x0[1]": 0.0, "m[1]": building.variable("m[1]").start}
        second = run()
        np.testing.assert_array_equal(first, second)  # deterministic: bit-identical after fmi2Reset
    finally:
        inst.free()


def test_fmu_state_rollback(building):
    inst = building.instantiate("s")
    try:
        start(inst, **{"m[1]": 1.0e5, "k[1]": 4.0e7, "x0[1]": 0.05})
        port = inst.real_port(["x[1]", "v[1]", "E_damping"])
        inst.do_step(0.0, 0.01)
        state = inst.get_state()
        inst.do_step(0.01, 0.01)
        after = port.get().copy()
        inst.do_step(0.02, 0.01)
        inst.set_state(state)
        inst.do_step(0.01, 0.01)
        np.testing.assert_array_equal(port.get(), after)
        inst.free_state(state)
    finally:
        inst.free()


def test_the_declared_interfaces_are_the_built_fmus(fmu_dir):
    """The scene loader and the parameter defaults read the slaves' declarations when no FMU is at
    hand: they must say what the built FMUs' model descriptions say (the descriptions round
    start values to 16 significant digits: half a unit of the 16th digit is 5e-16 relative)."""
    from cosim.master.interface import interfaces, parameter_defaults

    built, declared = interfaces(fmu_dir), interfaces(None)
    assert built.keys() == declared.keys()
    for name in built:
        b, d = built[name].variables, declared[name].variables
        assert list(b) == list(d), name
        for var in b:
            assert (b[var].type, b[var].causality, b[var].variability, b[var].unit) == \
                   (d[var].type, d[var].causality, d[var].variability, d[var].unit), (name, var)
            if b[var].type == "Real" and b[var].start is not None:
                assert b[var].start == pytest.approx(d[var].start, rel=5e-16, abs=0.0), (name, var)
            else:
                assert b[var].start == d[var].start, (name, var)
        assert dict(parameter_defaults(name)) == {v: d[v].start for v in d if d[v].causality == "parameter"}


def test_unprototyped_step_calls_match_fmpy(building):
    """The ports and doStep call the FMI functions without ctypes' argument conversion
    (cosim/master/fmi.py ``_unchecked``): every port kind, whole and first-``count``, reads and
    writes what fmpy's prototyped calls do, and a failing call's status still raises.  A count
    or component passed as a C int would lose its upper half (a heap address): reads would fail
    or return other variables."""
    from ctypes import c_void_p

    from cosim.master.fmi import HOT_CALLS

    inst = building.instantiate("fast")
    try:
        assert inst.component > 2**32        # the upper half matters (64-bit heap address)
        start(inst, **{"n_storeys": 3, "x0[1]": 0.01, "x0[2]": 0.02, "x0[3]": 0.04, "damping": "rayleigh"})
        slave, vr = inst._slave, {n: inst.variable(n).value_reference for n in ("x[1]", "x[2]", "x[3]", "ag", "F[1]")}
        real = inst.real_port(["x[3]", "x[1]", "x[2]"])
        assert real.get().tolist() == slave.getReal([vr["x[3]"], vr["x[1]"], vr["x[2]"]]) == [0.04, 0.01, 0.02]
        assert real.get_first(2).tolist() == [0.04, 0.01]
        inputs = inst.real_port(["ag", "F[1]"])
        inputs.values[:] = [0.5, 2.0e3]
        inputs.set_first(1)
        assert slave.getReal([vr["ag"], vr["F[1]"]]) == [0.5, 0.0]
        inputs.set()
        assert slave.getReal([vr["ag"], vr["F[1]"]]) == [0.5, 2.0e3]
        count = inst.integer_port(["n_storeys"])
        assert count.get().tolist() == [3]
        inst.do_step(0.0, 0.01)
        inst.do_step(0.01, 0.01)
        assert inst.do_steps == 2
        assert real.get().tolist() == slave.getReal([vr["x[3]"], vr["x[1]"], vr["x[2]"]])
        assert set(inst.unchecked) == set(HOT_CALLS)
        assert isinstance(inst.c_component, c_void_p) and inst.c_component.value == inst.component
        with pytest.raises(FMUError):
            inst.do_step(0.0, 0.01)          # a step that does not start at the current time
    finally:
        inst.free()
