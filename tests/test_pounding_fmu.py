"""pounding.fmu driven through fmpy: single impacts of two free masses against solve_ivp.

The host is exact for free masses under the piecewise-constant force the FMU returns
(zero-order hold): x += v h -/+ F h^2 / (2 m), v -/+= F h / m.  The reference is
fmu_src.single_impact.simulate_impact (scipy DOP853, rtol 1e-10, events), an integrator
independent of the FMU's internal Dormand-Prince resolver.
"""
from __future__ import annotations

import math

import pytest

from fmu_src.contact_laws import MODELS, law_for
from fmu_src.single_impact import simulate_impact

fmpy = pytest.importorskip("fmpy")
from fmpy import calloc, extract, free, read_model_description  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,  # noqa: E402
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

K_EXAMPLE = 1.8974e11   # 6000 kN/mm^1.5 in N/m^1.5
CRS = (0.1, 0.4, 0.65, 0.9)
# (impact speed m/s, m1 kg, m2 kg, k N/m^1.5): light and heavy bodies, 0.1 .. 10 m/s
CASES = ((0.1, 10.0, 30.0, 1e8), (1.0, 1e5, 1e5, 2.75e9), (10.0, 200.0, 200.0, K_EXAMPLE), (3.0, 5e5, 2e4, 1e11))


class Host:
    """One pounding.fmu instance with a log-capturing logger, reused through fmi2Reset."""

    def __init__(self, path, tmp):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[tuple[int, str]] = []

        def logger(env, instance, status, category, message):
            self.messages.append((status, message.decode()))

        self._callbacks = fmi2CallbackFunctions()
        self._keep = fmi2CallbackLoggerTYPE(logger)
        self._callbacks.logger = self._keep
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=extract(str(path), str(tmp)),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="contact")
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.fresh = True

    def setup(self, model="jankowski", resolve=True, **params):
        if not self.fresh:
            self.fmu.reset()
        self.fresh = False
        self.messages.clear()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        names = list(params)
        self.fmu.setReal([self.vr[n] for n in names], [float(params[n]) for n in names])
        self.fmu.setString([self.vr["model"]], [model])
        self.fmu.setBoolean([self.vr["resolve_impacts"]], [resolve])
        self.refused = None   # a refused fmi2ExitInitializationMode (fmi2Fatal), reused after fmi2Reset
        try:
            self.fmu.exitInitializationMode()
        except FMICallException as exc:
            self.refused = exc

    def step(self, t, h, x1, v1, x2, v2):
        self.fmu.setReal([self.vr[n] for n in ("x1", "v1", "x2", "v2")], [x1, v1, x2, v2])
        self.fmu.doStep(t, h)
        return self.fmu.getReal([self.vr["F"]])[0]

    def real(self, *names):
        return self.fmu.getReal([self.vr[n] for n in names])

    def integer(self, name):
        return self.fmu.getInteger([self.vr[name]])[0]

    def boolean(self, name):
        return self.fmu.getBoolean([self.vr[name]])[0]


def module_host(tag: str):
    """A module-scoped fixture: one pounding.fmu :class:`Host` for the module's tests (its
    folder named after ``tag``), terminated and freed after them."""
    @pytest.fixture(scope="module")
    def host(fmu_path, tmp_path_factory):
        h = Host(fmu_path("pounding"), tmp_path_factory.mktemp(tag))
        yield h
        h.fmu.terminate()
        h.fmu.freeInstance()
    return host


host = module_host("pounding")


def impact_run(host, model, CR, v, m1, m2, k, h, n=1.5, resolve=True, onset=0.37, extra_steps=3):
    """One impact of free masses; returns (FMU outputs, host kinetic energy lost, rebound ratio, ref)."""
    law = law_for(model, k, n, m1, m2, CR)
    ref = simulate_impact(law, v)
    host.setup(model, resolve, CR=CR, k=k, n=n, m1=m1, m2=m2, gap=0.0)
    x1, v1, x2, v2 = -onset * v * h, v, 0.0, 0.0        # contact starts `onset` into the first step
    steps = int(math.ceil((onset * h + 1.2 * ref.contact_duration) / h)) + extra_steps
    t = 0.0
    for _ in range(steps):
        F = host.step(t, h, x1, v1, x2, v2)
        x1 += v1 * h - 0.5 * F / m1 * h * h
        v1 -= F / m1 * h
        x2 += v2 * h + 0.5 * F / m2 * h * h
        v2 += F / m2 * h
        t += h
    # one more step to let plain mode see the separated inputs
    host.step(t, h, x1, v1, x2, v2)
    ke_lost = 0.5 * m1 * v * v - 0.5 * (m1 * v1 * v1 + m2 * v2 * v2)
    out = dict(zip(("F_max", "delta_max", "contact_time", "E_dissipated", "CR_achieved", "v_impact"),
                   host.real("F_max", "delta_max", "contact_time", "E_dissipated", "CR_achieved", "v_impact")))
    out["impacts"] = host.integer("impacts")
    return out, ke_lost, -(v1 - v2) / v, ref


def assert_matches(out, ke_lost, cr_host, ref, m, v, rel=0.01, check_duration=True):
    E0 = 0.5 * m * v * v
    assert out["impacts"] == 1
    assert out["F_max"] == pytest.approx(ref.peak_force, rel=rel)
    assert out["delta_max"] == pytest.approx(ref.max_penetration, rel=rel)
    if check_duration:
        assert out["contact_time"] == pytest.approx(ref.contact_duration, rel=rel)
    # dissipated energy to 1 % of the reference loss, or 1e-4 E0 when the loss itself is tiny
    assert abs(out["E_dissipated"] - ref.dissipated_energy) <= max(rel * ref.dissipated_energy, 1e-4 * E0)
    assert abs(out["CR_achieved"] - ref.achieved_CR) < 0.005
    assert abs(cr_host - ref.achieved_CR) < 0.005
    # energy balance of the host: E_dissipated = kinetic energy lost, to 0.1 % of E0
    assert abs(out["E_dissipated"] - ke_lost) < 1e-3 * E0


def test_fmu_validates(fmu_path):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmu_path("pounding"))) == []


def test_model_description_contract(fmu_path):
    md = read_model_description(str(fmu_path("pounding")))
    by_name = {v.name: v for v in md.modelVariables}
    for name in ("gap", "CR", "k", "n", "model", "m1", "m2", "zeta", "resolve_impacts"):
        assert by_name[name].causality == "parameter"
    for name in ("x1", "v1", "x2", "v2"):
        assert by_name[name].causality == "input"
    for name in ("F", "F_max", "delta", "E_dissipated", "impacts", "v_impact", "delta_dot", "in_contact",
                 "CR_achieved", "E_last", "impulse", "delta_max", "zeta_used", "contact_time", "substeps"):
        assert by_name[name].causality == "output"
    for v in md.modelVariables:
        assert v.description, v.name
        if v.type == "Real":
            assert v.unit, v.name
    assert md.coSimulation.canGetAndSetFMUstate


@pytest.mark.parametrize("model", MODELS)
def test_single_impact_every_model(host, model):
    for i, CR in enumerate(CRS):
        for v, m1, m2, k in (CASES[i % len(CASES)], CASES[(i + 2) % len(CASES)]):
            law = law_for(model, k, 1.5, m1, m2, CR)
            t_c = simulate_impact(law, v).contact_duration
            out, ke, cr_host, ref = impact_run(host, model, CR, v, m1, m2, k, h=0.7 * t_c)
            assert_matches(out, ke, cr_host, ref, law.m, v)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("ratio", [1e-3, 1e-2, 0.1, 0.5, 1.0, 2.0])
def test_step_size_independence(host, model, ratio):
    # Communication step from 1/1000 to twice the contact duration, every model and CR.
    v, m1, m2, k = 10.0, 200.0, 200.0, K_EXAMPLE
    for CR in CRS:
        law = law_for(model, k, 1.5, m1, m2, CR)
        t_c = simulate_impact(law, v).contact_duration
        out, ke, cr_host, ref = impact_run(host, model, CR, v, m1, m2, k, h=ratio * t_c)
        assert_matches(out, ke, cr_host, ref, law.m, v)


def test_no_spurious_impact_after_residual_overlap(host):
    # h = 2 t_c with onset at the start of the step leaves the host bodies overlapping while
    # separating; the FMU must give no force and no second impact.
    model, CR, v, m1, m2, k = "jankowski", 0.5, 1.0, 1e5, 1e5, 2.75e9
    t_c = simulate_impact(law_for(model, k, 1.5, m1, m2, CR), v).contact_duration
    h = 2.0 * t_c
    host.setup(model, True, CR=CR, k=k, m1=m1, m2=m2)
    x1, v1, x2, v2, t = -1e-9, v, 0.0, 0.0, 0.0
    overlaps, forces = [], []
    for _ in range(20):
        F = host.step(t, h, x1, v1, x2, v2)
        forces.append(F)
        x1 += v1 * h - 0.5 * F / m1 * h * h
        v1 -= F / m1 * h
        x2 += v2 * h + 0.5 * F / m2 * h * h
        v2 += F / m2 * h
        overlaps.append(x1 - x2)
        t += h
    assert overlaps[0] > 0.0 and v1 - v2 < 0.0     # residual overlap while separating
    assert forces[0] > 0.0 and all(f == 0.0 for f in forces[1:])
    assert host.integer("impacts") == 1


def test_a_step_declared_open_is_skipped_and_a_wrong_declaration_logged(host):
    """gap_open (docs/fmi_hosts.md, 'Declaring a step open'): a correct declaration over a long
    step gives no force and no message; free masses 2.5 mm apart at 1 m/s declared open over the
    3 ms step in which they meet get no force in it, a warning naming gap_open and the time when
    the overlap shows at its end, then one impact with finite, compressive forces that leaves
    them less kinetic energy; a declaration at a step that starts overlapping is logged and the
    step taken in full."""
    m, v, h = 1e5, 1.0, 3e-3
    host.setup("jankowski", True, k=2.75e9, m1=m, m2=m, gap=0.0)
    x1, v1, x2, v2, t = -0.5, v, 0.0, 0.0, 0.0
    host.fmu.setBoolean([host.vr["gap_open"]], [True])
    assert host.step(t, 0.4, x1, v1, x2, v2) == 0.0            # 0.4 m apart, 0.4 s: proven open
    assert not [msg for _, msg in host.messages if "gap_open" in msg]
    assert host.real("delta") == [-0.5]                         # the inputs at the step start
    t, x1 = 0.4, -2.5e-3
    forces = []
    for k in range(40):
        host.fmu.setBoolean([host.vr["gap_open"]], [k == 0])
        F = host.step(t, h, x1, v1, x2, v2)
        forces.append(F)
        x1, v1 = x1 + v1 * h - 0.5 * F / m * h * h, v1 - F / m * h
        x2, v2 = x2 + v2 * h + 0.5 * F / m * h * h, v2 + F / m * h
        t += h
    warned = [(status, msg) for status, msg in host.messages if "gap_open" in msg]
    assert len(warned) == 1 and warned[0][0] == 1                # fmi2Warning
    assert "t = 0.403 s" in warned[0][1] and "from t = 0.4 s" in warned[0][1] and "overlap by 0.0005" in warned[0][1]
    assert forces[0] == 0.0 and all(math.isfinite(f) and f >= 0.0 for f in forces)
    assert host.integer("impacts") == 1 and not host.boolean("in_contact")
    assert 0.5 * m * (v1 * v1 + v2 * v2) < 0.5 * m * v * v
    # declared at a step that starts overlapping: logged, and the step is taken in full
    host.setup("jankowski", True, k=2.75e9, m1=m, m2=m, gap=0.0)
    host.fmu.setBoolean([host.vr["gap_open"]], [True])
    assert host.step(0.0, 1e-3, 1e-4, v, 0.0, 0.0) > 0.0
    assert any("gap_open = true, but the bodies overlap by 0.0001 m at the step start" in msg
               for _, msg in host.messages)


@pytest.mark.parametrize("model", ["jankowski", "hunt_crossley"])
def test_plain_mode_converges_and_balances_energy(host, model):
    # Plain mode (force law on the inputs only) needs steps far below the contact duration;
    # at t_c / 2000 it agrees with the reference to ~1 % (first-order in h).
    v, m1, m2, k, CR = 1.0, 1e5, 1e5, 2.75e9, 0.65
    law = law_for(model, k, 1.5, m1, m2, CR)
    t_c = simulate_impact(law, v).contact_duration
    out, ke, cr_host, ref = impact_run(host, model, CR, v, m1, m2, k, h=t_c / 2000, resolve=False)
    assert out["F_max"] == pytest.approx(ref.peak_force, rel=0.01)
    assert abs(cr_host - ref.achieved_CR) < 0.01
    assert abs(out["CR_achieved"] - cr_host) < 1e-12   # same inputs
    E0 = 0.5 * law.m * v * v
    assert abs(out["E_dissipated"] - ke) < 1e-3 * E0
    # the same plain mode at h = t_c / 5 is far off: that is what resolve_impacts is for
    out5, _, cr5, _ = impact_run(host, model, CR, v, m1, m2, k, h=t_c / 5, resolve=False)
    assert abs(cr5 - ref.achieved_CR) > 0.02


@pytest.mark.parametrize("resolve", [True, False])
def test_state_save_restore_mid_impact(host, resolve):
    model, CR, v, m1, m2, k = "crvk", 0.4, 2.0, 1e4, 3e4, 1e10
    t_c = simulate_impact(law_for(model, k, 1.5, m1, m2, CR), v).contact_duration
    h = t_c / 7
    host.setup(model, resolve, CR=CR, k=k, m1=m1, m2=m2)
    names = ("F", "F_max", "delta", "delta_dot", "E_dissipated", "v_impact", "delta_max", "contact_time")
    inputs = [(-0.2 * v * h + i * v * h * 0.9, v * (1 - 0.1 * i), 0.0, 0.05 * i) for i in range(12)]
    for i in range(4):
        host.step(i * h, h, *inputs[i])
    assert host.boolean("in_contact")
    state = host.fmu.getFMUstate()
    first = []
    for i in range(4, 12):
        host.step(i * h, h, *inputs[i])
        first.append(host.real(*names) + [host.integer("impacts")])
    host.fmu.setFMUstate(state)
    second = []
    for i in range(4, 12):
        host.step(i * h, h, *inputs[i])
        second.append(host.real(*names) + [host.integer("impacts")])
    host.fmu.freeFMUstate(state)
    assert first == second


def _expect_error(host, *fragments):
    # refused at fmi2ExitInitializationMode: pythonfmu answers fmi2Fatal and logs the slave's message
    assert host.refused is not None and host.refused.status == 4
    errors = [m for s, m in host.messages if s >= 3]   # fmi2Error or fmi2Fatal
    assert errors, host.messages
    for fragment in fragments:
        assert any(fragment in m for m in errors), (fragment, errors)
    with pytest.raises(FMICallException) as exc:   # and every step after
        host.step(0.0, 1e-3, -1e-3, 0.1, 0.0, 0.0)
    assert exc.value.status == 2   # fmi2Discard: the instance stays alive for the host to read the log


@pytest.mark.parametrize("name,value,fragments", [
    ("CR", 0.0, ("CR = 0.0", "0 < CR <= 1")),
    ("CR", 1.5, ("CR = 1.5", "0 < CR <= 1")),
    ("gap", -0.01, ("gap = -0.01 m", "0 <= gap")),
    ("k", 0.0, ("k = 0.0 N/m^n", "0 < k")),
    ("m1", -5.0, ("m1 = -5.0 kg", "0 < m1")),
    ("m2", 0.0, ("m2 = 0.0 kg", "0 < m2")),
    ("n", float("inf"), ("n = inf", "not finite")),
])
def test_bad_parameters_are_reported(host, name, value, fragments):
    host.setup("jankowski", True, **{name: value})
    _expect_error(host, *fragments)


def test_unknown_model_is_reported(host):
    host.setup("stiff_spring", True)
    _expect_error(host, "model = 'stiff_spring'", "one of 'hertz'")


@pytest.mark.parametrize("name,value", [("x1", float("nan")), ("v2", float("inf")), ("x2", -float("inf"))])
def test_non_finite_inputs_are_reported(host, name, value):
    host.setup("jankowski", True)
    inputs = dict(x1=-1e-3, v1=0.1, x2=0.0, v2=0.0)
    inputs[name] = value
    with pytest.raises(FMICallException) as exc:
        host.step(0.0, 1e-3, **inputs)
    assert exc.value.status == 2
    assert any(f"input {name} = {value!r}" in m for s, m in host.messages if s == 3), host.messages


def test_crvk_initialisation_reports_calibrated_constant(host):
    from fmu_src.contact_laws import crvk_constant
    host.setup("crvk", True, CR=0.3, n=1.0, k=1e9)
    host.step(0.0, 1e-3, -1.0, 0.0, 0.0, 0.0)
    assert host.real("zeta_used")[0] == pytest.approx(crvk_constant(0.3, 1.0), rel=1e-12)
