"""How the host applies ``pounding.fmu``'s force, and the structures' own motion it shows.

:class:`HostObserver` reads the host's relative velocity at each step start, takes the FMU's
own force out of it with the host's *delivery kernel* (declared through :data:`HOSTS`, or
identified once at the first impact edge), and learns the structures' relative acceleration
from what is left; :class:`~.resolver.ImpactResolver` follows it.  Pure physics (SI units, no
FMI); the argument why it converges and cannot create energy is in ``docs/fmi_hosts.md``.
"""
from __future__ import annotations

import copy
import math
from types import MappingProxyType

import numpy as np

#: taps of a host's delivery kernel the observer identifies: a one-step-late (Jacobi) HHT-alpha
#: host spreads one step's impulse over four steps (0, w0, w1, w2)
_KERNEL_TAPS = 4
#: identification rows after which an unclear edge is given up (the extrapolated structural
#: motion it is measured against drifts away with the horizon)
_MAX_EDGE_ROWS = 12
#: standard error every identified weight must have at most: a weight off by e leaves
#: e F h / m of our own force in the learnt structural increment of each step
_WEIGHT_STANDARD_ERROR = 0.01
#: |sum of the weights - 1| above which the host is inconsistent: it delivers more or less than
#: the impulse we hand over (wiring, masses m1/m2 not those the host integrates)
_MOMENTUM_TOLERANCE = 0.05
#: weights below this are taken as zero (shortens the settling window); above the standard error
_NEGLIGIBLE_WEIGHT = 0.02
#: chi-square per row below which the rows fit a kernel (the row errors are estimated
#: generously, so a consistent fit gives well under 1)
_CHI2_CONSISTENT = 4.0
#: weight of the latest clean step in the running mean square of the prediction errors
_SCATTER_WEIGHT = 0.3
#: part of a row's impulse taken as the error of its structural baseline from the structures'
#: reaction to the force itself, which the clean stretch before the edge cannot show
_REACTION = 0.01


def _padded(w) -> tuple[float, ...]:
    """A kernel as ``_KERNEL_TAPS`` weights (zeros appended)."""
    return (tuple(w) + (0.0,) * _KERNEL_TAPS)[:_KERNEL_TAPS]


#: mean delivery delay [steps] assumed before the first impact has shown the host's: that of a
#: zero-order hold in Gauss-Seidel order.  Any other guess costs more than it saves: handing the
#: first impulse over a step early to a Gauss-Seidel host stops its bodies before they touch
_ASSUMED_LEAD = 0.0


def _hht_kernel(alpha: float, late: bool) -> tuple[float, ...]:
    """Delivery kernel of an HHT-alpha host (alpha = 0: Newmark average acceleration) that takes
    our F as its load at the step end: ``v += h ((1 - g) a_n + g a_(n+1))`` with
    ``M a_(n+1) = (1 + alpha) p_(n+1) - alpha p_n``, ``g = 1/2 - alpha``; ``late``: one step late."""
    g = 0.5 - alpha
    w = (g * (1.0 + alpha), (1.0 - g) * (1.0 + alpha) - g * alpha, -(1.0 - g) * alpha)
    w = w[:2] if alpha == 0.0 else w
    return ((0.0,) + w) if late else w


#: the kernel the timing energy is booked with when no standard kernel fits an edge: one step
#: late (Jacobi order), so that an unclear host is taken back from rather than trusted
_UNFIT_SUSPECT = (0.0, 1.0)


def _mean_delay(w) -> float:
    """Mean delay of a kernel, in steps (0: the impulse reaches the host in its own step)."""
    return sum(j * x for j, x in enumerate(w))


#: kernels of the structural integrators in use: zero-order hold, symplectic Euler and velocity
#: Verlet (1); Newmark average acceleration (1/2, 1/2); HHT-alpha; each also one step late
_STANDARD_KERNELS = tuple(
    kernel for late in (False, True)
    for kernel in ((((0.0, 1.0) if late else (1.0,)),)
                   + tuple(_hht_kernel(a, late) for a in (0.0, -0.05, -0.1, -0.15, -0.2, -0.25, -0.3, -1.0 / 3.0))))


#: what a host may declare about itself (``pounding.fmu`` parameter ``host``): its delivery
#: kernel, and whether its positions are exact for a force held over the step (then they are
#: learnt from too, as the structures' displacement over the step).  ``any``: nothing declared,
#: the kernel is identified from the host's response to the first impact.
HOSTS = MappingProxyType({
    "any": None,
    "zoh": ((1.0,), True),              # exact for a held force, Gauss-Seidel order (building.fmu)
    "zoh_late": ((0.0, 1.0), True),     # the same one step late: Jacobi order (libcosim)
    "trapezoidal": ((0.5, 0.5), False),           # Newmark average acceleration, F as load at the step end
    "trapezoidal_late": ((0.0, 0.5, 0.5), False),  # the same, Jacobi order
})


class HostObserver:
    """What the host does with our force, and the structures' own relative acceleration.

    Over its step ``k`` every consistent host changes the relative velocity by

        ``dV_k = A_k - h_k sum_j w_j F_(k-j) / m``

    ``A_k``: the structures' contribution (storey springs, dampers, other contacts, as the host
    integrates them); ``w``: the host's *delivery kernel* of our mean forces ``F``, with
    ``sum w = 1`` (momentum).  Exact zero-order hold, symplectic Euler, velocity Verlet in
    Gauss-Seidel order: ``w = (1)``; the same in Jacobi order: ``(0, 1)``; Newmark average
    acceleration holding ``F`` as its load at the step end: ``(1/2, 1/2)``; HHT-alpha: three
    taps (:func:`_hht_kernel`).  Position increments depend on the host's integrator and are
    never used.

    * ``A_k`` is *clean* -- free of our force -- when no force of ours can reach the observed
      step (the last ``support`` forces are zero) or when ``w`` is known.  The structural
      acceleration over the next step is the linear extrapolation of the last two clean
      means; the difference between a clean increment and the one assumed is returned as
      the correction of the resolver's own state.
    * ``w`` is identified once, at the first contact *edge* that says it clearly.  After a
      clean stretch the structural increments are extrapolated; the host's departures from
      that extrapolation over the steps that follow our first force are the impulses it
      delivered, ``h_k sum_j w_j F_(k-j)``: weighted least squares, each row weighted by the
      scatter of the clean one-step predictions grown with the horizon.  Accepted as any
      kernel when every weight is known to 0.01 (fine steps, free masses), or as one of the
      standard hosts' kernels when it fits and excludes, by 5 sigma, every standard kernel
      that times the impulse differently.  A sum of weights off 1 by more than 5 % marks the
      host inconsistent (logged once): safe mode.
    * While the kernel is unknown (and in safe mode) a step whose increment may hold our force
      is not learnt from: the structural acceleration is held at the value it had reached.
      Bodies that showed no structural motion before are then exactly right (free masses);
      others drift from the host by what the structures do that the hold misses, without
      feedback, until the edge is decided.  The hand-over is timed meanwhile for the latest
      standard host the rows do not exclude (:meth:`_identify`).

    Plain numbers and tuples only, besides the list of notices: :meth:`snapshot` saves it with
    the FMU state.
    """

    def __init__(self, m: float, extrapolate: bool = True, host: str = "any"):
        if host not in HOSTS:
            raise ValueError(f"host = {host!r} is not allowed: one of {', '.join(HOSTS)}")
        self.m = m
        self.extrapolate = extrapolate
        declared = HOSTS[host]
        self.exact_positions = bool(declared and declared[1])   # positions learnt from too
        self.untimed = declared is None  # the current episode began before the host's kernel was known
        self.last = None            # (delta [m], delta_dot [m/s], h [s]) of the host at the last step start
        self.forces = ()            # our mean forces [N] of the latest steps, latest first
        self.means = ()             # clean structural mean accelerations [m/s^2], latest first
        self.spans = ()             # their step sizes [s]
        self.scatter = 0.0          # (m/s)^2, mean square error of the one-step prediction of clean increments
        self.kernel = None          # delivery weights w_0, w_1, ... (declared or identified)
        self.support = _KERNEL_TAPS # steps over which one step's force reaches the host (the kernel's length)
        self.lead = _ASSUMED_LEAD   # steps, mean delay of the host's delivery: the kernel's, or assumed
        self.quiet_steps = _KERNEL_TAPS  # steps since our last nonzero force
        self.inconsistent = False   # clear evidence that the host does not conserve momentum
        self.provisional = _STANDARD_KERNELS[0]  # the standard kernel the edges so far fit best
        self.provisional_lead = None  # steps, its mean delay (None: nothing measured yet)
        self.suspect = _STANDARD_KERNELS[0]  # the kernel the timing energy is booked with while unknown
        if declared:
            self._set_kernel(declared[0])
        self.a0 = 0.0               # m/s^2, structural relative acceleration at the step start
        self.a1 = 0.0               # m/s^3, its rate over the step
        self.predicted = 0.0        # m/s, structural rate change assumed over the last step
        self.predicted_position = 0.0  # m, and the displacement, from rest
        self.rows = ()              # rows of the current edge: (x, r, sigma, dV, used, t_mid, h)
        self.edge_given_up = False  # the current edge gave no clear answer
        self.clock = 0.0            # s, start of the observed step from the start of the edge
        self.baseline = (0.0, 0.0)  # (m/s^2, m/s^3) structural acceleration extrapolated over the edge
        self.internal = 0.0         # N s, impulse the resolver's own bodies received in the last step
        self.timing = 0.0           # N s, impulse delivered to the host minus received internally, this episode
        self.debt = 0.0             # J, energy the hand-over's timing gave the host this episode (_book_timing)
        self.repaid = 0.0           # J, of it taken back this episode by impulse withheld (ImpactResolver._withhold)
        #: this episode's work on both sides (passivity): the resolver's own bodies', sum of impulse
        #: times mean approach rate [J]; the host's, the same sum for our force of j steps before each
        #: step, j = 0 .. _KERNEL_TAPS - 1 [J] (any kernel w delivers sum_j w_j of them)
        self.own_work = 0.0
        self.host_work = (0.0,) * _KERNEL_TAPS
        self.own = (0.0, 0.0, 0.0)  # (N s, m/s, m/s): the resolver's own impulse and rates, last step (record)
        #: standard kernels the current edge's rows do not exclude (all of them before any row)
        self.plausible = _STANDARD_KERNELS
        self.notices = []           # messages for the FMU log (drained by the adapter)

    def snapshot(self) -> "HostObserver":
        """A copy as independent as ``copy.deepcopy`` gives, for an FMU state: every attribute is a
        number, a bool, None or a tuple of them, except the list of notices, copied
        (tests/test_contact_snapshots.py walks both).  A deep copy cost 60 us of the 80 us of a
        pounding.fmu fmi2GetFMUstate, which a rolling-back master pays for every contact."""
        new = copy.copy(self)
        new.notices = list(self.notices)
        return new

    def _set_kernel(self, kernel) -> None:
        self.kernel = kernel
        self.support = len(kernel) if kernel is not None else _KERNEL_TAPS
        self.lead = _mean_delay(kernel) if kernel is not None else \
            (self.provisional_lead if self.provisional_lead is not None else _ASSUMED_LEAD)

    def pending(self) -> bool:
        """True if part of an impulse we handed over may not have reached the host yet."""
        return self.quiet_steps < self.support - 1

    def structural_rate(self, r: float) -> float:
        """Rate change [m/s] the structures give over the first ``r`` s of the current step."""
        return self.a0 * r + 0.5 * self.a1 * r * r

    def observe(self, delta: float, delta_dot: float, h: float) -> tuple[float, float]:
        """Take the host's state at a step start; returns the correction (m, m/s) of the
        structural motion assumed over the last step, and predicts the next step."""
        cx = cu = 0.0
        held = False
        if self.last is not None:
            D, V, hp = self.last
            dV = delta_dot - V
            quiet = self.quiet_steps >= self.support
            hits = self.forces[:self.support]
            delivered = 0.0
            if not quiet and self.untimed:
                I, u0, u1 = self.own
                self.own_work += I * 0.5 * (u0 + u1)
                mean = hp * 0.5 * (V + delta_dot)
                self.host_work = tuple(W + mean * F for W, F in zip(self.host_work, _padded(self.forces)))
            if quiet:
                clean = dV
                self.rows, self.edge_given_up = (), False
                if self.internal == 0.0:        # the episode is over
                    self.timing = self.debt = self.repaid = 0.0
                    self.untimed = self.kernel is None
                    self.own_work, self.host_work = 0.0, (0.0,) * _KERNEL_TAPS
            elif self.kernel is not None:
                delivered = self._delivered(self.kernel, hits, hp)
                clean = dV + delivered
                self._book_timing(delivered * self.m, self.internal, clean)
            else:
                clean = None
                verdict = None if self.inconsistent else self._edge(dV, hp, hits)
                if verdict is not None:
                    cx, cu = verdict
                elif self.edge_given_up and not self.rows:
                    # no clear edge: the timing energy booked as the suspect kernel delivers,
                    # the structures' motion as the best-fitting one does
                    self._book_timing(self._delivered(self.delivery_kernel(), hits, hp) * self.m, self.internal,
                                      dV + self._delivered(self.provisional, hits, hp))
            if clean is not None:
                du = clean - self.predicted
                if self.exact_positions:
                    # the host's displacement over the step, minus what the delivered impulse
                    # held over it does from rest: the structures' own
                    moved = delta - D - V * hp + 0.5 * delivered * hp
                    cx, cu = cx + moved - self.predicted_position, cu + du
                    self._learn_step(clean, moved, hp)
                else:
                    cx, cu = cx + 0.5 * du * hp, cu + du
                    self._learn(clean / hp, hp)
                if quiet and self.means:
                    self.scatter += _SCATTER_WEIGHT * (du * du - self.scatter)
            held = clean is None
        if not (self.exact_positions and not held and self.last is not None):
            self._predict(held)
        self.last = (delta, delta_dot, h)
        return cx, cu

    def record(self, F: float, h: float, internal: float, own=(0.0, 0.0, 0.0)) -> None:
        """Book our mean force [N] of the step just taken, the impulse [N s] the resolver's own
        bodies received in it, what the structures were assumed to do, and ``own``: the impulse
        [N s] the resolver's own bodies received whatever was withheld, their rate [m/s] at the
        step start and at its end (:meth:`passivity`)."""
        self.own = own
        self.forces = (F,) + self.forces[:_KERNEL_TAPS - 1]
        self.quiet_steps = self.quiet_steps + 1 if F == 0.0 else 0
        self.internal = internal
        self.predicted = self.structural_rate(h)
        self.predicted_position = 0.5 * self.a0 * h * h + self.a1 * h * h * h / 6.0

    def owed(self) -> float:
        """Energy [J] the hand-over's timing gave the host this episode and was not taken back."""
        return self.debt - self.repaid

    def projected_debt(self, emitted, internal, h: float) -> tuple[float, list[float]]:
        """Energy [J] the timing will have given the host once the impulses ``emitted`` [N s]
        (this step's first, then the next steps') have reached it, the resolver's own bodies
        receiving ``internal`` [N s] in the same steps: the host delivering them with its
        kernel, or the suspect one while it is unknown, the structures' acceleration as
        predicted (``int C A dt``, :meth:`_book_timing`, continued over the coming steps);
        and ``C`` [N s] at the start of each of those steps."""
        kernel = self.delivery_kernel()
        forces, C, debt, Cs = self.forces, self.timing, self.debt, []
        for j, (J, I) in enumerate(zip(emitted, internal)):
            Cs.append(C)
            forces = (J / h,) + forces[:_KERNEL_TAPS - 1]
            C1 = C + h * sum(w * F for w, F in zip(kernel, forces)) - I
            debt += 0.5 * (C + C1) * (self.a0 + self.a1 * (j + 0.5) * h) * h
            C = C1
        return debt, Cs

    def delivery_kernel(self) -> tuple[float, ...]:
        """The host's kernel, or while it is unknown the latest standard one the edges do not
        exclude (``suspect``: the timing energy is booked for it)."""
        return _padded(self.kernel if self.kernel is not None else self.suspect)

    def passivity(self, kernel, own, h: float) -> tuple[float, list[float]]:
        """Energy [J] the host will have given the contact less than the resolver's own bodies
        did, over this episode, if it delivers our impulses with ``kernel``; and the host's mean
        rates [m/s] over this step and the coming ones.  Positive: energy created in the host.

        Both sides are summed alike, each step's impulse times the mean approach rate over the
        step (the host's work on the contact by the trapezoidal rule: exact for symplectic Euler
        and Newmark, third order for a zero-order hold).  Over the steps observed
        (:attr:`host_work`) the host's rates are measured: whatever moved its bodies is in them,
        the other contacts of a structure included, which ``int C A dt`` (:meth:`_book_timing`)
        misses (the shear buildings of the host matrix at 10 ms: 3 to 5 times what it books).
        Over this step and the coming ones (``own``: the resolver's own impulses [N s], the
        impulses handed over [N s], the resolver's own rates [m/s] at the steps' boundaries,
        this step's start first) the host's rate is the resolver's plus the difference measured
        at this step's start, changed by what the host receives more or less than the resolver's
        bodies (the structural motion taken equal on both sides: a drift extrapolated from one
        step in contact was noise that withheld from exact hosts).  Zero for a host that the
        resolver follows exactly."""
        m = self.m
        created = self.own_work - sum(w * W for w, W in zip(kernel, self.host_work))
        impulses, emitted, rates = own
        forces, V, rates_host = self.forces, self.last[1], []
        D = V - rates[0]                      # m/s, the host's rate minus the resolver's
        for j in range(len(emitted) + len(kernel)):
            I = impulses[j] if j < len(impulses) else 0.0
            forces = ((emitted[j] / h if j < len(emitted) else 0.0),) + forces[:len(kernel) - 1]
            delivered = h * sum(w * F for w, F in zip(kernel, forces))
            u0 = rates[min(j, len(rates) - 1)]
            u1 = rates[min(j + 1, len(rates) - 1)]
            D1 = D - (delivered - I) / m
            V0, V1 = u0 + D, u1 + D1
            created += I * 0.5 * (u0 + u1) - delivered * 0.5 * (V0 + V1)
            rates_host.append(0.5 * (V0 + V1))
            D = D1
        return created, rates_host

    def plausible_kernels(self) -> tuple:
        """The host's kernel when known, else the standard kernels the current edge does not exclude."""
        return (_padded(self.kernel),) if self.kernel is not None else tuple(_padded(w) for w in self.plausible)

    def _book_timing(self, delivered: float, internal: float, clean: float) -> None:
        """Energy the hand-over's timing gave the host over one observed step (rule 7).

        With ``C`` the impulse delivered to the host minus the impulse the resolver's own bodies
        received, cumulated, the host's relative velocity is the resolver's minus ``C / m``, so
        the contact's work on the host exceeds its work on the resolver's bodies by
        ``int C A dt`` over an episode (``A`` the structures' acceleration): zero for free
        masses, zero for a hand-over on time, positive (energy created) for a late one while the
        structures pull the bodies apart.  ``clean`` is ``A`` integrated over the step."""
        C = self.timing + delivered - internal
        self.debt += 0.5 * (self.timing + C) * clean
        self.timing = C

    # -- learning ---------------------------------------------------------------------------------
    def _delivered(self, kernel, hits, hp: float) -> float:
        """Rate change [m/s] the host gave our forces ``hits`` (latest first) over a step ``hp``."""
        return hp * sum(w * F for w, F in zip(kernel, hits)) / self.m

    def _learn(self, a: float, h: float) -> None:
        self.means = ((a,) + self.means)[:2]
        self.spans = ((h,) + self.spans)[:2]

    def _learn_step(self, rate: float, moved: float, h: float) -> None:
        """Exact positions: the linear acceleration that reproduces both structural increments
        of the last step (rate [m/s], displacement [m]), continued over the next one."""
        self._learn(rate / h, h)
        if self.extrapolate:
            b1 = 12.0 * (0.5 * rate * h - moved) / (h * h * h)
            self.a0, self.a1 = rate / h + 0.5 * b1 * h, b1
        else:
            self.a0, self.a1 = rate / h, 0.0

    def _predict(self, held: bool) -> None:
        if held:                    # nothing learnt: hold the acceleration reached
            self.a0 += self.a1 * self.last[2]
            self.a1 = 0.0
        elif not self.means:
            self.a0 = self.a1 = 0.0
        elif len(self.means) == 1 or not self.extrapolate:
            self.a0, self.a1 = self.means[0], 0.0
        else:
            slope = (self.means[0] - self.means[1]) / (0.5 * (self.spans[0] + self.spans[1]))
            self.a0 = self.means[0] + 0.5 * slope * self.spans[0]
            self.a1 = slope

    def _edge(self, dV: float, hp: float, hits):
        """One step of an edge while the kernel is unknown: a row of its least-squares problem.

        Returns the kernel's verdict, the correction (cx, cu) of the edge's steps, or None."""
        if self.edge_given_up:
            return None
        if not self.rows:
            # the edge starts with the observed step: its structural motion is measured
            # against the extrapolation of the clean increments before it, a line in time
            self.clock = 0.0
            self.baseline = (self.a0, self.a1)
        b0, b1 = self.baseline
        P = b0 * hp + b1 * (self.clock * hp + 0.5 * hp * hp)
        x = tuple(hp * F for F in (hits + (0.0,) * _KERNEL_TAPS)[:_KERNEL_TAPS])
        r = (P - dV) * self.m                   # N s: the impulse the host delivered, if A = P
        # error of the extrapolated structural increment: the RMS of the one-step
        # predictions of the clean increments before the edge, grown with the horizon as
        # a linear extrapolation's error does, (j + 1)(j + 2) / 2 after j steps;
        # plus the structures' reaction to the force itself, taken as 1 % of the row's
        # impulses; plus the round-off of the increments
        j = self.clock / hp
        scale = max(abs(v) for v in x)
        sigma = self.m * math.sqrt(self.scatter) * 0.5 * (j + 1.0) * (j + 2.0) \
            + _REACTION * scale + 1e-12 * (scale + (abs(dV) + abs(P)) * self.m)
        self.rows = self.rows + ((x, r, sigma, dV, self.predicted, self.clock + 0.5 * hp, hp, self.internal),)
        self.clock += hp
        verdict = self._identify()
        if verdict is None and self.rows:
            self._book_edge(_padded(self.suspect), _padded(self.provisional))
        return verdict

    def _book_edge(self, kernel, fitted=None) -> None:
        """Book the hand-over's timing over the edge's rows as ``kernel`` delivers them, the
        structural increments as ``fitted`` (default: ``kernel``) takes our force out of them."""
        fitted = kernel if fitted is None else fitted
        self.timing = self.debt = 0.0
        for x, _, _, dV, _, _, _, internal in self.rows:
            delivered = sum(wj * xj for wj, xj in zip(kernel, x))
            structural = dV + sum(wj * xj for wj, xj in zip(fitted, x)) / self.m
            self._book_timing(delivered, internal, structural)

    def _identify(self):
        """Decide the kernel from the edge's rows if they say it clearly (class docstring);
        returns the correction (cx, cu) of the edge's steps when decided, else None."""
        rows = self.rows
        X = np.array([row[0] for row in rows])
        s = np.array([row[2] for row in rows])
        Xw = X / s[:, None]
        rw = np.array([row[1] for row in rows]) / s
        # 1. any kernel, if the rows pin every weight down to 0.01
        if len(rows) > _KERNEL_TAPS:
            normal = Xw.T @ Xw
            if np.linalg.cond(normal) < 1e14:
                w = np.linalg.solve(normal, Xw.T @ rw)
                cov = np.linalg.inv(normal)
                se = np.sqrt(np.abs(np.diag(cov)))
                chi2 = float(np.sum((Xw @ w - rw) ** 2)) / (len(rows) - _KERNEL_TAPS)
                if se.max() < _WEIGHT_STANDARD_ERROR and chi2 < _CHI2_CONSISTENT:
                    return self._accept(w)
                # the delivered total alone can be clear before every weight is: a host that
                # delivers a wrong impulse is named as soon as its sum is off by 5 sigma
                off = abs(float(w.sum()) - 1.0)
                if chi2 < _CHI2_CONSISTENT and off > max(_MOMENTUM_TOLERANCE, 5.0 * math.sqrt(abs(cov.sum()))):
                    return self._accept(w)
        # 2. one of the standard hosts, if it fits and every host that times the impulse
        #    differently (mean delay off by more than 0.1 step) is excluded by 5 sigma
        chi2 = {w: float(np.sum((Xw @ np.array(_padded(w)) - rw) ** 2)) for w in _STANDARD_KERNELS}
        best = min(chi2, key=chi2.get)
        fits = chi2[best] < _CHI2_CONSISTENT * len(rows)
        # ... once every tap of it has been seen (one row fits (1/2, 1/2) and a host that
        # delivers half the impulse alike)
        if fits and len(best) <= len(rows) and all(chi2[w] - chi2[best] > 25.0 for w in _STANDARD_KERNELS
                                                    if abs(_mean_delay(w) - _mean_delay(best)) > 0.1):
            return self._accept(np.array(_padded(best)))
        if fits:
            # meanwhile, time the hand-over for the earliest standard host the rows do not
            # exclude: a hand-over a step early to a Gauss-Seidel host stops its bodies before
            # they touch, which costs far more than a late one to a Jacobi host
            self.provisional, self.provisional_lead = best, _mean_delay(best)
            self._set_kernel(None)
        # the timing energy is booked for the best-fitting standard host, or one step late when
        # none fits.  (Booking it for the latest standard host the rows do not exclude took the
        # shear buildings' symplectic Euler/Jacobi cell at 10 ms from 3.5 % to 0.6 % created, but
        # withheld from an exact Gauss-Seidel host at 20 ms enough to lose one of five impacts,
        # tests/test_resolver_attached.py)
        self.suspect = best if fits else _UNFIT_SUSPECT
        # the hosts the rows do not exclude by 5 sigma (every standard one when none fits)
        self.plausible = tuple(w for w in _STANDARD_KERNELS if chi2[w] - chi2[best] <= 25.0) if fits \
            else _STANDARD_KERNELS
        if len(rows) >= _MAX_EDGE_ROWS or not any(F != 0.0 for F in self.forces[:_KERNEL_TAPS - 1]):
            self.edge_given_up = True
            self.rows = ()
        return None

    def _accept(self, w):
        """Book a kernel; returns the correction (cx, cu) of what the edge's steps assumed."""
        rows, self.rows = self.rows, ()
        total = float(w.sum())
        if abs(total - 1.0) > _MOMENTUM_TOLERANCE:
            self.inconsistent = True
            self.notices.append(
                f"the host delivers {total:.3g} times the impulse of F (delivery weights "
                f"{', '.join(f'{x:.3g}' for x in w)}); a consistent host delivers it once "
                f"(allowed: |sum - 1| <= {_MOMENTUM_TOLERANCE:g}). Check that F acts on body 2 along +x "
                f"and on body 1 along -x, and that m1, m2 are the masses the host moves. Safe mode: the "
                f"structures' motion is no longer learnt while an impulse is on its way")
            return 0.0, 0.0
        w = np.where(np.abs(w) < _NEGLIGIBLE_WEIGHT, 0.0, w)
        w = w / w.sum()
        self._set_kernel(tuple(float(x) for x in w[:int(np.flatnonzero(w)[-1]) + 1]))
        # the edge's structural increments, now clean: learn them, correct what was assumed
        self.timing = self.debt = 0.0
        cx = cu = 0.0
        for x, _, _, dV, used, t_mid, hp, internal in rows:
            delivered = sum(wj * xj for wj, xj in zip(self.kernel, x))
            clean = dV + delivered / self.m
            self._book_timing(delivered, internal, clean)
            cu += clean - used
            cx += (clean - used) * (self.clock - t_mid)
            self._learn(clean / hp, hp)
        return cx, cu
