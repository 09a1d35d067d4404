"""pounding.fmu: contact element between two bodies (thin FMI adapter over fmu_src.resolver).

Body 1 lies on the negative side of body 2; ``delta = x1 - x2 - gap`` > 0 is penetration.
The output force ``F`` (>= 0) pushes body 1 towards -x and body 2 towards +x.

With ``resolve_impacts = true`` (default) every impact is located and integrated inside the
step at its own time scale (:class:`fmu_src.resolver.ImpactResolver`) and ``F`` is the mean
force of the step (``F * h`` = impulse), so the momentum and energy handed to the bodies do
not depend on where the communication points fall.  The resolver follows the host: the
structures' own contribution to the relative motion (storey springs, dampers) is measured
from the inputs of consecutive steps, predicted over the next step and corrected, so that
contacts lasting several steps stay on the host's trajectory; for free masses it is zero.  With ``false`` the force law is
evaluated on the current inputs only (:class:`fmu_src.plain_contact.PlainContact`).  A host
that has proven the gap open over a step may declare it (input ``gap_open``): the contact then
skips the step's work (resolver rule 8), so that a master can catch a sleeping contact up over
any length in a few doSteps (cosim/master/dormancy.py).
See docs/contact_models.md for the models and the in-step rules.
"""
from __future__ import annotations

from pythonfmu.enums import Fmi2Status

from .contact_laws import MODELS, law_for
from .fmi_slave import SlaveBase as Fmi2Slave, SlaveError, Variable
from .host_observer import HOSTS
from .plain_contact import PlainContact
from .plausibility import PlausibilityWatch
from .resolver import ImpactResolver

#: what the FMU does with a step its plausibility watch finds wrong (PlausibilityWatch)
ON_IMPLAUSIBLE = ("warn", "discard")

_OUT = dict(causality="output")


class Pounding(Fmi2Slave):
    """Impact contact element with ten damping models."""

    DESCRIPTION = ("Pounding contact element: spring-dashpot impact laws (Hertz, Kelvin-Voigt, Jankowski, "
                   "Hertz-damp family, crvk) with impacts resolved inside each communication step")
    DEFAULT_EXPERIMENT = (0.0, 1.0, 1e-3)

    VARIABLES = (
        # parameters
        Variable("gap", start=0.0, unit="m", low=0.0,
                 description="initial separation between the bodies; contact when x1 - x2 > gap"),
        Variable("CR", start=0.65, unit="1", low=0.0, low_open=True, high=1.0,
                 description="coefficient of restitution: rebound / approach relative speed"),
        Variable("k", start=2.75e9, unit="N/m^n", low=0.0, low_open=True,
                 description="contact stiffness (force = k delta^n); default Jankowski 2005, concrete, n = 1.5"),
        Variable("n", start=1.5, unit="1", low=0.0, low_open=True,
                 description="stiffness exponent (1 linear, 1.5 Hertz)"),
        Variable("model", type="String", start="jankowski", choices=MODELS,
                 description="impact damping model"),
        Variable("m1", start=1.0e5, unit="kg", low=0.0, low_open=True,
                 description="mass of body 1 (damping laws use m = m1 m2 / (m1 + m2))"),
        Variable("m2", start=1.0e5, unit="kg", low=0.0, low_open=True,
                 description="mass of body 2"),
        Variable("zeta", start=-1.0, unit="1",
                 description="dimensionless damping constant of the model; < 0: from CR by the model's "
                             "published formula (crvk: calibrated to reach CR)"),
        Variable("resolve_impacts", type="Boolean", start=True,
                 description="true: locate and integrate impacts inside each step; false: force law on the "
                             "current inputs only"),
        Variable("graze_depth", start=0.0, unit="m", low=0.0,
                 description="a contact whose penetration stays below this is a graze: counted in grazes, not in "
                             "impacts (0: every contact is an impact; building scenes use 3e-4, three times the "
                             "co-simulation's resolution of the relative floor position, docs/contact_models.md)"),
        Variable("host", type="String", start="any", choices=tuple(HOSTS),
                 description="how the host applies F, if it declares it: 'zoh' exact for a force held over the "
                             "step in Gauss-Seidel order (building.fmu), 'zoh_late' the same one step late "
                             "(Jacobi), 'trapezoidal'/'trapezoidal_late' Newmark average acceleration; 'any': "
                             "measured from the host's response to the first impact"),
        Variable("on_implausible", type="String", start="warn", choices=ON_IMPLAUSIBLE,
                 description="a step that created energy or bounced the bodies (a host applying the force late at "
                             "a coarse step, a plain-law step too long for the impact, impacts multiplying): 'warn' "
                             "logs a warning naming the numbers and the remedy; 'discard' refuses the step with "
                             "fmi2Discard and leaves the instance as before it, so that a host that can roll back "
                             "retries with a smaller step"),
        # inputs
        Variable("gap_open", type="Boolean", causality="input", start=False,
                 description="the host declares that it has proven the gap open (x1 - x2 < gap) over the whole "
                             "coming step: the contact then does no onset search and predicts no flight over it "
                             "(no force, no impact), whatever its length, unless an impact is in progress; false "
                             "(default): every step in full. Bodies found overlapping at either end of a declared "
                             "step are logged as a warning (docs/fmi_hosts.md, 'Declaring a step open')"),
        Variable("x1", causality="input", start=0.0, unit="m", description="displacement of body 1"),
        Variable("v1", causality="input", start=0.0, unit="m/s", description="velocity of body 1"),
        Variable("x2", causality="input", start=0.0, unit="m", description="displacement of body 2"),
        Variable("v2", causality="input", start=0.0, unit="m/s", description="velocity of body 2"),
        # outputs
        Variable("F", start=0.0, unit="N", **_OUT,
                 description="contact force, >= 0, on body 2 along +x and on body 1 along -x; resolved mode: "
                             "mean over the last step (F * h = impulse); plain mode: force law at the inputs"),
        Variable("F1", start=0.0, unit="N", **_OUT,
                 description="force on body 1 along +x, -F (wire it to body 1 without any sign change)"),
        Variable("F2", start=0.0, unit="N", **_OUT,
                 description="force on body 2 along +x, +F"),
        Variable("F_max", start=0.0, unit="N", **_OUT,
                 description="largest instantaneous contact force so far"),
        Variable("delta", start=0.0, unit="m", **_OUT,
                 description="penetration x1 - x2 - gap (< 0: open); resolved mode: internal state at the end "
                             "of the step (after a step declared open: the inputs at its start); plain mode: at "
                             "the inputs"),
        Variable("delta_dot", start=0.0, unit="m/s", **_OUT,
                 description="penetration rate (> 0 approaching), same time point as delta"),
        Variable("in_contact", type="Boolean", start=False, **_OUT,
                 description="true while an impact is in progress (at the end of the step)"),
        Variable("E_dissipated", start=0.0, unit="J", **_OUT,
                 description="energy dissipated by all impacts so far (the current one up to now)"),
        Variable("impacts", type="Integer", start=0, **_OUT,
                 description="number of impacts so far: contacts whose penetration reached graze_depth "
                             "(counted when it does)"),
        Variable("grazes", type="Integer", start=0, **_OUT,
                 description="number of completed contacts whose penetration stayed below graze_depth"),
        Variable("contacts_ended", type="Integer", start=0, **_OUT,
                 description="number of completed contacts, impacts and grazes (one more at each separation)"),
        Variable("t_onset", start=0.0, unit="s", **_OUT,
                 description="time at which the latest contact began"),
        Variable("F_peak", start=0.0, unit="N", **_OUT,
                 description="largest instantaneous force of the latest contact (so far, while in progress)"),
        Variable("t_peak", start=0.0, unit="s", **_OUT,
                 description="time of F_peak (resolved mode: located to an internal step; plain mode: a step start)"),
        Variable("v_impact", start=0.0, unit="m/s", **_OUT,
                 description="approach speed of the latest impact (latched at contact onset)"),
        Variable("CR_achieved", start=0.0, unit="1", **_OUT,
                 description="rebound / approach speed of the latest completed impact (0 before the first; "
                             "plain mode: from the first inputs found out of contact)"),
        Variable("E_last", start=0.0, unit="J", **_OUT,
                 description="energy dissipated by the latest completed impact"),
        Variable("impulse", start=0.0, unit="N.s", **_OUT,
                 description="impulse transmitted during the last step"),
        Variable("delta_max", start=0.0, unit="m", **_OUT,
                 description="largest penetration of the latest impact"),
        Variable("zeta_used", start=0.0, unit="1", **_OUT,
                 description="damping constant in use (published, calibrated or given)"),
        Variable("contact_time", start=0.0, unit="s", **_OUT,
                 description="duration of the latest impact (elapsed, while in progress)"),
        Variable("substeps", type="Integer", start=0, **_OUT,
                 description="internal integration steps in the last doStep (cost counter)"),
        Variable("substeps_total", start=0.0, unit="1", **_OUT,
                 description="internal integration steps of every doStep so far (cost counter; a Real, exact "
                             "to 2^53, so that a master reading only Real outputs can follow it)"),
        Variable("t_separation", start=-1.0, unit="s", **_OUT,
                 description="end of the communication step in which the latest contact ended (-1 before "
                             "any): changes exactly when contacts_ended (and grazes) do"),
    )
    PRIVATE_STATE = ("_contact", "_watch", "_declared_from")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._contact = None        # ImpactResolver or PlainContact, built at initialisation
        self._watch = None          # PlausibilityWatch
        self._declared_from = None  # s, start of the last step if it was declared open (gap_open), else None

    def initialize(self) -> None:
        law = law_for(self.model, self.k, self.n, self.m1, self.m2, self.CR, self.zeta)
        self.zeta_used = law.zeta
        depth = float(self.graze_depth)
        self._contact = (ImpactResolver(law, host=self.host, graze_depth=depth) if self.resolve_impacts
                         else PlainContact(law, graze_depth=depth))
        self._watch = PlausibilityWatch(law)

    def step(self, current_time: float, step_size: float) -> None:
        delta = self.x1 - self.x2 - self.gap
        delta_dot = self.v1 - self.v2
        declared = bool(self.gap_open)
        self._check_declaration(current_time, delta, declared)
        discard = self.on_implausible == "discard"
        saved = (self._contact.snapshot(), self._watch.snapshot(), self._declared_from) if discard else None
        self._declared_from = current_time if declared else None
        c = self._contact
        started, ended = c.started, c.ended
        if self.resolve_impacts:
            out = c.step(delta, delta_dot, step_size, declared)
            F, impulse, substeps = out.mean_force, out.impulse, out.substeps
            notices = c.observer.notices
            if notices:
                for notice in notices:
                    self.log(f"{self.instance_name}: t = {current_time:.9g} s: {notice}", Fmi2Status.warning)
                notices.clear()
        else:
            F = c.step(delta, delta_dot, step_size, declared)
            impulse, substeps = F * step_size, 1
        for kind, message in self._watch.check(c, step_size):
            if discard:
                self._contact, self._watch, self._declared_from = saved
                raise SlaveError(f"step of {step_size:.6g} s refused (on_implausible = 'discard'): {message}")
            self.log(f"{self.instance_name}: t = {current_time:.9g} s: {message}", Fmi2Status.warning)
        self.F, self.impulse, self.substeps = F, impulse, substeps
        self.substeps_total += substeps
        if self.resolve_impacts:
            self.delta, self.delta_dot = c.delta_end, c.delta_dot_end
        else:
            self.delta, self.delta_dot = delta, delta_dot
        self.F1, self.F2 = -self.F, self.F
        self.CR_achieved = 0.0 if c.last_CR != c.last_CR else c.last_CR   # NaN before the first impact ends
        self.E_last = c.last_E
        self.in_contact = c.in_contact
        self.F_max = c.F_max
        self.E_dissipated = c.dissipated_energy()
        self.impacts = c.impacts
        self.grazes = c.grazes
        self.contacts_ended = c.ended
        if c.started != started:
            self.t_onset = current_time + c.onset_offset
        if c.ended != ended:
            self.t_separation = current_time + step_size
        self.F_peak = c.impact_peak
        self.t_peak = self.t_onset + c.peak_delay()
        self.v_impact = c.v_imp
        self.delta_max = c.delta_max
        self.contact_time = c.impact_time

    def _check_declaration(self, t: float, delta: float, declared: bool) -> None:
        """Warn about a host's ``gap_open`` that its own inputs contradict: bodies overlapping
        (``delta`` > 0 m) at the end of a step declared open, or at the start of one (taken in full)."""
        if self._declared_from is not None and delta > 0.0:
            self.log(f"{self.instance_name}: t = {t:.9g} s: gap_open was true over the step from t = "
                     f"{self._declared_from:.9g} s, but the bodies overlap by {delta:.6g} m at its end "
                     f"(x1 - x2 - gap must stay < 0 over a step declared open): the host's proof is wrong, and a "
                     f"contact inside that step may have been missed", Fmi2Status.warning)
        if declared and delta > 0.0:
            self.log(f"{self.instance_name}: t = {t:.9g} s: gap_open = true, but the bodies overlap by "
                     f"{delta:.6g} m at the step start (x1 - x2 - gap must be < 0 over a step declared open): "
                     f"the step is taken in full", Fmi2Status.warning)
