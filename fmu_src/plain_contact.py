"""Plain contact mode of ``pounding.fmu``: the force law on the host's current inputs only.

Pure physics (SI units, no FMI); the comparison to the in-step resolver (:mod:`.resolver`).
"""
from __future__ import annotations

import copy
import math

from .contact_laws import ContactLaw

class PlainContact:
    """The force law evaluated on the host's current ``delta``, ``delta_dot`` only.

    ``v_imp`` is latched when a contact begins (``|delta_dot|`` at the first step found in
    contact).  The host applies the returned force over the whole step, so the work done on
    the contact in a step is ``F (delta_new - delta_old)``; the dissipated energy is that
    work minus the energy stored in the spring.  Plain numbers besides the law (frozen):
    :meth:`snapshot` saves it with the FMU state.
    """

    def __init__(self, law: ContactLaw, graze_depth: float = 0.0):
        self.law = law
        self.graze_depth = graze_depth   # m: a contact shallower than this is a graze, not an impact
        self.in_contact = False
        self.v_imp = 0.0
        self.F = 0.0                # N, force applied over the current step
        self.delta_prev = 0.0
        self.work = 0.0             # J, work done on the contact so far
        self.impacts = 0            # contacts that reached graze_depth (counted when they do)
        self.grazes = 0             # completed contacts that never reached graze_depth
        self.started = 0            # contacts begun
        self.ended = 0              # contacts completed
        self.counted = False
        self.onset_offset = 0.0     # s: a contact is found at the start of a step
        self.impact_peak = 0.0      # N, largest force of the current/latest contact
        self.peak_steps = 0.0       # s from the onset to the step start where impact_peak was found
        self.F_max = 0.0
        self.delta_max = 0.0
        self.impact_time = 0.0
        self.stepped = False        # a step was taken (its work is booked at the next)
        self.last_CR = math.nan     # -delta_dot / v_imp at the first inputs found out of contact
        self.last_E = 0.0           # J, dissipated by the latest completed contact
        self._E_at_onset = 0.0

    def snapshot(self) -> "PlainContact":
        """A copy for an FMU state (a shallow one is as independent as a deep one: see above)."""
        return copy.copy(self)

    def step(self, delta: float, delta_dot: float, h: float, gap_open: bool = False) -> float:
        """Force [N] for the step of length ``h`` [s] starting at the given inputs.

        ``gap_open`` (the host declares the gap open over the step) changes nothing here: the law
        on the inputs has nothing to predict, and with the bodies apart its force is 0 anyway."""
        if self.stepped:
            self.work += self.F * (delta - self.delta_prev)
        self.stepped = True
        self.delta_prev = delta
        if delta > 0.0:
            if not self.in_contact:
                self.in_contact = True
                self.started += 1
                self.counted = False
                self.v_imp = abs(delta_dot)
                self.delta_max = 0.0
                self.impact_time = 0.0
                self.impact_peak = 0.0
                self._E_at_onset = self.dissipated_energy()
            self.delta_max = max(self.delta_max, delta)
            if not self.counted and self.delta_max >= self.graze_depth:
                self.counted = True
                self.impacts += 1
            self.F = self.law.force(delta, delta_dot, self.v_imp)
            if self.F > self.impact_peak:
                self.impact_peak = self.F
                self.peak_steps = self.impact_time
            self.impact_time += h
        else:
            if self.in_contact:
                self.in_contact = False
                self.ended += 1
                if not self.counted:
                    self.grazes += 1
                self.last_CR = max(0.0, -delta_dot) / self.v_imp if self.v_imp > 0.0 else math.nan
                self.last_E = self.dissipated_energy() - self._E_at_onset
            self.F = 0.0
        self.F_max = max(self.F_max, self.F)
        return self.F

    def peak_delay(self) -> float:
        """Time (s) from the onset of the latest contact to its largest force (a step start)."""
        return self.peak_steps

    def dissipated_energy(self) -> float:
        """Work done on the contact minus the elastic energy stored at the latest inputs [J]."""
        return self.work - self.law.elastic_energy(self.delta_prev)
