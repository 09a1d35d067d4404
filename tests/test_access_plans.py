"""fmi2GetReal / fmi2SetReal through the slave base's access plans (fmu_src/fmi_slave.py) give
exactly what pythonfmu's own variable-by-variable path gives (the oracle: ``Fmi2Slave.get_real``
and ``Fmi2Slave.set_real`` called on the same instance)."""
from __future__ import annotations

import numpy as np
import pytest
from pythonfmu import Fmi2Slave

from fmu_src.building_slave import Building
from fmu_src.fmi_slave import MAX_ACCESS_PLANS, SlaveError
from fmu_src.ground_motion_slave import GroundMotion
from fmu_src.ground_records import G
from fmu_src.record_knots import step_knots


def building(model="linear", name="b"):
    b = Building(instance_name=name, resources=None, visible=False, logger=None)
    b.n_storeys = 3
    b.T1 = 0.5
    b.m[:3] = 3e5
    b.k[:3] = [1.0, 0.8, 0.6]
    if model != "linear":
        b.hysteresis = model
        b.Fy[:3] = [0.1 * 9e5 * G, 0.08 * 9e5 * G, 0.06 * 9e5 * G]
    b.exit_initialization_mode()
    assert b._error is None
    return b


def ground():
    g = GroundMotion(instance_name="g", resources=None, visible=False, logger=None)
    g.target_pga_g = 0.3
    g.exit_initialization_mode()
    assert g._error is None
    return g


def refs_of(slave):
    return {var.name: ref for ref, var in slave.vars.items()}


def vr(slave, *names):
    by_name = refs_of(slave)
    return [by_name[n] for n in names]


def real_refs(slave, causality):
    return [ref for ref, var in slave.vars.items()
            if type(var).__name__ == "Real" and var.causality.name == causality]


@pytest.mark.parametrize("model", ["linear", "bilinear"])
def test_building_reads_equal_pythonfmus(model):
    b = building(model)
    outputs = real_refs(b, "output")
    rng = np.random.default_rng(1)
    lists = [outputs, outputs[::-1], list(rng.permutation(outputs)[:25]), outputs[:7], outputs[40:47] + outputs[:3],
             [outputs[0]] * 3, outputs[-9:]]
    before = [Fmi2Slave.get_real(b, refs) for refs in lists]   # before the first step too
    assert [b.get_real(refs) for refs in lists] == before
    t = 0.0
    for i in range(60):
        b.ag = 3.0 * np.sin(0.3 * i)
        b.F[1] = 2e5 * np.cos(0.2 * i)
        assert b.do_step(t, 0.02)
        t += 0.02
        for refs in lists:
            fast = b.get_real(refs)
            assert fast == Fmi2Slave.get_real(b, refs)
            assert all(type(x) is float for x in fast)
    assert max(b.get_real(outputs)) > 0.0


def test_ground_knots_read_equal_pythonfmus():
    g = ground()
    outputs = real_refs(g, "output")
    interleaved = vr(g, *[f"{a}[{k}]" for k in range(1, 17) for a in ("t_knot", "ag_knot")])
    t = 1.0
    for h in (0.01, 0.13, 0.3, 0.2):
        g.do_step(t, h)
        t += h
        assert g.get_real(interleaved) == Fmi2Slave.get_real(g, interleaved)   # the first read
        fast = g.get_real(outputs)
        assert fast == Fmi2Slave.get_real(g, outputs)
    times, _ = step_knots(g._record, t - 0.2, t)
    assert fast[outputs.index(vr(g, "t_knot[2]")[0])] == times[1]


def test_writes_equal_pythonfmus_and_refusals_stay():
    fast, slow = building(name="fast"), building(name="slow")
    inputs = real_refs(fast, "input")
    rng = np.random.default_rng(2)
    # what issue 17's master writes: ag, a force, then knot times and values interleaved
    interleaved = vr(fast, "ag", "F[3]", *[f"{a}[{k}]" for k in range(1, 34) for a in ("t_knot", "ag_knot")])
    duplicated = vr(fast, "F[1]", "F[2]", "F[1]")      # the last value stays, as in pythonfmu
    for refs in (inputs, inputs[::-1], list(rng.permutation(inputs)[:30]), interleaved, duplicated):
        values = list(rng.normal(size=len(refs)))
        fast.set_real(refs, values)
        Fmi2Slave.set_real(slow, refs, values)
        for name in ("ag", "F", "t_knot", "ag_knot"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))
        assert fast.ag == slow.ag
    # a fixed parameter is still refused after initialisation, through the plan too
    with pytest.raises(SlaveError, match="fixed parameter"):
        fast.set_real(vr(fast, "F[1]", "zeta"), [1.0, 0.2])
    assert fast.zeta == 0.05
    # a value reference that is not a Real: pythonfmu's TypeError
    with pytest.raises(TypeError, match="not of type Real"):
        fast.get_real(vr(fast, "x[1]", "n_storeys"))
    with pytest.raises(TypeError, match="not of type Real"):
        fast.set_real(vr(fast, "F[1]", "n_knots"), [1.0, 2.0])


def test_plans_are_bounded():
    b = building()
    outputs = real_refs(b, "output")
    for i in range(3 * MAX_ACCESS_PLANS):
        assert b.get_real(outputs[i % 50:i % 50 + 3]) == Fmi2Slave.get_real(b, outputs[i % 50:i % 50 + 3])
    assert len(b._read_plans) <= MAX_ACCESS_PLANS
