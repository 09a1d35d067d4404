"""The contact's plausibility watch: what a host should hear about (``pounding.fmu``'s self-protection).

:class:`PlausibilityWatch` looks at one contact (:class:`~.resolver.ImpactResolver` or
:class:`~.plain_contact.PlainContact`) after every step and reports, once per impact, what
means the host's numbers are wrong, with the numbers and the remedy.  Pure physics (SI units,
no FMI): the adapter logs the findings or refuses the step (``on_implausible``).
"""
from __future__ import annotations

import copy

from .contact_laws import ContactLaw
from .plain_contact import PlainContact

#: energy the hand-over's timing may give the host before it is reported, as a part of the
#: impact's kinetic energy m v_imp^2 / 2 (HostObserver._book_timing)
TIMING_ENERGY_LIMIT = 0.01
#: a plain-law step longer than this part of the impact time scale T = L / v_imp: the
#: dissipated energy is off by about h / T (the master's stability guard uses the same limit)
PLAIN_STEP_LIMIT = 0.25
#: rebound / approach speed above which a damped plain-law impact created energy
REBOUND_LIMIT = 1.0 + 1e-3
#: impacts begun within this many steps of the previous separation, at least this part of the
#: previous approach speed, count as multiplying (the host bounces the bodies, they do not)
MULTIPLYING_STEPS = 2
MULTIPLYING_SPEED = 0.5
#: multiplying impacts in a row that are reported
MULTIPLYING_COUNT = 2


class PlausibilityWatch:
    """Findings about one contact's impacts that mean the host's numbers are wrong.

    Checked after each step (:meth:`check`), each kind reported once per impact:

    * ``timing_energy`` (resolved): the hand-over's timing has given the host more than
      ``TIMING_ENERGY_LIMIT`` of the impact's kinetic energy (HostObserver._book_timing):
      a host that delivers the force later than the contact could know, at a step coarse for
      the impact;
    * ``rebound`` (plain): a damped law's impact ended faster than it began, or dissipated
      negative energy;
    * ``coarse_plain_step`` (plain): a step longer than ``PLAIN_STEP_LIMIT`` impact time scales;
    * ``multiplying`` (either): ``MULTIPLYING_COUNT`` impacts in a row that began within
      ``MULTIPLYING_STEPS`` steps of the previous separation at more than
      ``MULTIPLYING_SPEED`` of its approach speed.

    Each finding names the numbers and the remedy.  Plain numbers and tuples only, besides the
    law (frozen): :meth:`snapshot` saves it with the FMU state.
    """

    def __init__(self, law: ContactLaw):
        self.law = law
        self.reported = ()          # kinds reported during the current impact
        self.impacts = 0            # impacts seen so far
        self.steps_open = 0         # steps since the last separation
        self.last_speed = 0.0       # m/s, approach speed of the previous impact
        self.in_a_row = 0           # multiplying impacts in a row

    def snapshot(self) -> "PlausibilityWatch":
        """A copy for an FMU state (a shallow one is as independent as a deep one: see above)."""
        return copy.copy(self)

    def check(self, contact, h: float) -> list[tuple[str, str]]:
        """(kind, message) of what is new after a step of ``h`` [s] of ``contact``."""
        found = []
        law, v = self.law, contact.v_imp
        energy = 0.5 * law.m * v * v
        if contact.impacts > self.impacts:                      # new impact(s) this step
            quick = self.impacts > 0 and self.steps_open <= MULTIPLYING_STEPS \
                and v >= MULTIPLYING_SPEED * self.last_speed
            self.in_a_row = self.in_a_row + 1 if quick else 0
            self.impacts, self.last_speed, self.reported = contact.impacts, v, ()
            if self.in_a_row >= MULTIPLYING_COUNT:
                found.append(("multiplying", (
                    f"impacts multiplying: {self.in_a_row + 1} impacts in a row, each within {MULTIPLYING_STEPS} "
                    f"steps of the previous separation at {v:.3g} m/s (at least {MULTIPLYING_SPEED:g} of the "
                    f"previous approach speed): the host bounces the bodies back; use a smaller step "
                    f"(h = {h:.3g} s)")))
        self.steps_open = 0 if contact.in_contact else self.steps_open + 1
        plain = isinstance(contact, PlainContact)
        if v > 0.0:
            observer = getattr(contact, "observer", None)
            debt = observer.owed() if observer is not None else 0.0
            # the impact time scale only for a message or a plain law's checks (a power per step)
            T = law.length_scale(v) / v if plain or debt > TIMING_ENERGY_LIMIT * energy else None
            if debt > TIMING_ENERGY_LIMIT * energy:
                found.append(("timing_energy", (
                    f"the host received {debt:.4g} J more from the contact than the impact returns "
                    f"({debt / energy:.1%} of its kinetic energy {energy:.4g} J, limit {TIMING_ENERGY_LIMIT:.0%}): "
                    f"it applies the force later than the contact could hand it over (before the first "
                    f"impact has shown how the host applies it, or at a step of {h / T:.2g} impact time scales); "
                    f"use a smaller step (below {0.1 * T:.3g} s), or declare the host (parameter host)")))
            if plain:
                if contact.in_contact and h > PLAIN_STEP_LIMIT * T:
                    found.append(("coarse_plain_step", (
                        f"plain force law (resolve_impacts = false) stepped at h = {h:.3g} s = {h / T:.2g} impact "
                        f"time scales T = L / v_imp = {T:.3g} s (limit {PLAIN_STEP_LIMIT:g}): the dissipated energy is "
                        f"off by about {min(h / T, 1.0):.0%}; use resolve_impacts = true, or a step below "
                        f"{PLAIN_STEP_LIMIT * T:.3g} s")))
                ended = not contact.in_contact and contact.impacts and contact.last_CR == contact.last_CR
                if ended and law.zeta > 0.0 and (contact.last_CR > REBOUND_LIMIT or contact.last_E < -1e-3 * energy):
                    found.append(("rebound", (
                        f"the impact ended faster than it began (rebound / approach {contact.last_CR:.4g} with a "
                        f"damped law, dissipated {contact.last_E:.4g} J): the plain force law at h = {h:.3g} s "
                        f"({h / T:.2g} impact time scales) created energy; use resolve_impacts = true, or a step "
                        f"below {0.1 * T:.3g} s")))
        if not found:
            return found
        new = [(k, m) for k, m in found if k not in self.reported]
        self.reported = self.reported + tuple(k for k, _ in new)
        return new

