"""Bad communication steps from a host (issue 13, "Bad input").

A step of 0, a negative or non-finite step, a step too small for the FMU's arithmetic
(1e-300 s), a non-finite time, and a host that goes back in time (or skips time) without
restoring a saved state: each doStep is refused with fmi2Discard (pythonfmu 0.7 cannot
return fmi2Error from doStep) and a message logged with status fmi2Error that names the
value and the allowed range, and the instance is left exactly as it was: the next valid
step gives the outputs of an instance that never saw the bad call, bit for bit.
"""
from __future__ import annotations

import math

import pytest

from fmu_src.fmi_slave import MAX_STEP, MIN_STEP
from test_pounding_fmu import module_host

from fmpy.fmi1 import FMICallException  # noqa: E402

H = 1e-3
OUTPUTS = ("F", "F1", "F2", "F_max", "E_dissipated", "delta", "delta_dot")


host = module_host("bad_steps")


def _approach(k):
    """Two free 1e5 kg bodies closing at 1 m/s: an impact from the third step on."""
    x1 = -2.5e-3 + k * H
    return x1, 1.0, 0.0, 0.0


def _run(host, bad=None, at=3, steps=8):
    """Outputs after ``steps`` steps of H; ``bad`` = (t, h) tried once before step ``at``."""
    host.setup("jankowski", True, m1=1e5, m2=1e5, gap=0.0)
    refused = None
    for k in range(steps):
        if bad is not None and k == at:
            host.messages.clear()
            with pytest.raises(FMICallException) as exc:
                host.step(bad[0], bad[1], *_approach(k))
            refused = exc.value.status, [m for s, m in host.messages if s == 3]
        host.step(k * H, H, *_approach(k))
    return host.real(*OUTPUTS) + [host.integer("impacts")], refused


@pytest.fixture(scope="module")
def clean(host):
    return _run(host)[0]


@pytest.mark.parametrize("t,h,fragments", [
    (3 * H, 0.0, ("h = 0.0 s", f"{MIN_STEP:.3g} s <= h <= {MAX_STEP:g} s")),
    (3 * H, -0.01, ("h = -0.01 s", "allowed range")),
    (3 * H, math.nan, ("h = nan s", "allowed range")),
    (3 * H, math.inf, ("h = inf s", "allowed range")),
    (3 * H, 1e-300, ("h = 1e-300 s", f"{MIN_STEP:.3g} s <= h")),
    (3 * H, 2 * MAX_STEP, (f"h = {2 * MAX_STEP!r} s", f"h <= {MAX_STEP:g} s")),
    (math.nan, H, ("t = nan s is not finite",)),
    (1 * H, H, ("went back in time", "allowed: t = 0.0030000000000000001 s")),
    (5 * H, H, ("went forward, skipping time", "fmi2SetFMUstate")),
])
def test_bad_step_is_refused_and_the_instance_stays_usable(host, clean, t, h, fragments):
    outputs, (status, errors) = _run(host, (t, h))
    assert status == 2                        # fmi2Discard, message logged as fmi2Error
    assert errors, "no message logged with status fmi2Error"
    for fragment in fragments:
        assert any(fragment in m for m in errors), (fragment, errors)
    assert outputs == clean                   # nothing of the refused call remains


def test_a_tiny_step_is_refused_where_time_cannot_resolve_it(host):
    # at t = 1e6 s a step of 1e-9 s is below 64 ulp of t (1.5e-8 s): t + h is no longer t + h
    host.setup("jankowski", True)
    host.messages.clear()
    with pytest.raises(FMICallException):
        host.step(1e6, 1e-9, -1.0, 0.0, 0.0, 0.0)
    assert any("h = 1e-09 s at t = 1000000 s is outside the allowed range 1.42e-08 s" in m
               for s, m in host.messages if s == 3), host.messages
    host.step(1e6, 1e-3, -1.0, 0.0, 0.0, 0.0)     # a valid step then runs


def test_restoring_a_state_allows_going_back(host):
    # fmi2SetFMUstate rewinds the time too: a rollback is not "going back in time"
    host.setup("jankowski", True, m1=1e5, m2=1e5, gap=0.0)
    for k in range(3):
        host.step(k * H, H, *_approach(k))
    state = host.fmu.getFMUstate()
    host.step(3 * H, H, *_approach(3))
    host.fmu.setFMUstate(state)
    host.step(3 * H, H / 2, *_approach(3))        # retried from 3 ms with half the step
    host.fmu.freeFMUstate(state)


@pytest.mark.parametrize("fmu", ["building", "ground_motion"])
def test_every_fmu_refuses_a_zero_step(fmu_path, tmp_path, fmu):
    from cosim.master.fmi import FMU, FMUError

    with FMU(fmu_path(fmu)) as f:
        inst = f.instantiate("x")
        inst.setup(0.0, 1.0)
        inst.exit_initialization()
        with pytest.raises(FMUError, match=r"h = 0.0 s at t = 0 s is outside the allowed range"):
            inst.do_step(0.0, 0.0)
        inst.do_step(0.0, 0.01)
        inst.free()
