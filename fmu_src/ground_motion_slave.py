"""ground_motion.fmu: plays a recorded ground acceleration (a source, no inputs).

The record (``fmu_src/ground_records.py``) is loaded once, at the end of initialisation:
a bundled name (shipped inside the FMU as ``resources/<its package>/records``) or a file path
(PEER ``.AT2``, single column with ``dt``, or ``time, acceleration`` CSV).  A bad file makes
``fmi2ExitInitializationMode`` fail with a message naming the file and the line.

Per doStep ``[t, t + h]`` the outputs are exact for the piecewise-linear record (zero before
its first and after its last sample): ``ag`` at ``t + h``, ``ag_mean`` the mean over the step
(what a zero-order-hold building needs: its velocity increments are then exact), the ground
velocity ``vg`` and displacement ``dg`` at ``t + h``.

Scaling: ``scale``, or one target: ``target_pga`` (m/s^2), ``target_pga_g`` (g) or ``target_sa``
(m/s^2), the pseudo-spectral acceleration at ``sa_period`` (s) with damping ``sa_damping``.  Two
targets at once, or ``target_sa`` without ``sa_period``, are refused at
``fmi2ExitInitializationMode`` before the file is read.  Outputs ``scale_factor`` (what was
applied) and ``sa_at_period`` (PSa of the played record at ``sa_period``, 0 without a period).
A record whose PGA is implausible for its stated unit is played, with a warning in the log.

Knots (``n_knots``, ``t_knot[k]``, ``ag_knot[k]``, k = 1..KNOT_CAPACITY): the record over the
last step ``[t, t + h]`` exactly, as the polyline through ``(t, ag(t+))``, every sample strictly
inside and ``(t + h, ag(t + h-))`` (a jump where the record starts or ends is two knots at one
time; ``fmu_src/record_knots.py``).  A building fed these knots integrates the record exactly
over any step length.  A step that needs more than KNOT_CAPACITY knots still succeeds and sets
``n_knots = 0``: use ``ag_mean`` for it.  Elements beyond ``n_knots`` are 0; before the first
step ``n_knots = 0``.  The last knot's time is ``current_time + step_size`` as the host's doubles
add (every other knot lies earlier), so a host that reads every ``t_knot`` finds ``n_knots``
from it without an fmi2GetInteger (cosim/master/knots.py).  The knots are computed when first read after a step (a host that does
not read them does not pay for them).
"""
from __future__ import annotations

import functools
import math
from pathlib import Path

from pythonfmu.enums import Fmi2Status

from .fmi_slave import SlaveBase as Fmi2Slave, SlaveError, Variable, array
from .ground_records import FORMATS, G, MAX_PGA_G, UNITS, record_from_parameters, scaling_conflict
from .record_knots import KNOT_CAPACITY, step_knots
from .response_spectrum import DEFAULT_DAMPING, PERIOD_LIMITS, pseudo_acceleration


class GroundMotion(Fmi2Slave):
    """Recorded ground acceleration in SI units (see module docstring)."""

    DESCRIPTION = "Recorded ground acceleration (bundled SLAMMER/PEER records or PEER AT2, column, CSV files)"
    DEFAULT_EXPERIMENT = (0.0, 40.0, 0.01)
    VARIABLES = (
        Variable("record", "String", start="elcentro1940",
                 description="bundled record (elcentro1940 kobe1995 sanfernando1971 parkfield1966) or a file path"),
        Variable("format", "String", start="auto", choices=FORMATS, description="file format"),
        Variable("dt", start=0.0, unit="s", low=0.0,
                 description="sampling interval of a single-column file; 0 = from the file"),
        Variable("units", "String", start="g", choices=tuple(UNITS), description="units of the values in the file"),
        Variable("scale", start=1.0, description="factor on the record (ignored when a target is set)"),
        Variable("target_pga", start=0.0, unit="m/s2", low=0.0, high=MAX_PGA_G * G,
                 description="scale the record to this peak ground acceleration; 0 = not set"),
        Variable("target_pga_g", start=0.0, unit="1", low=0.0, high=MAX_PGA_G,
                 description="scale the record to this peak ground acceleration in g (a ratio to 9.80665 m/s2); 0 = not set"),
        Variable("target_sa", start=0.0, unit="m/s2", low=0.0, high=MAX_PGA_G * G,
                 description="scale the record to this pseudo-spectral acceleration at sa_period; 0 = not set"),
        Variable("sa_period", start=0.0, unit="s", low=0.0, high=PERIOD_LIMITS[1],
                 description=f"oscillator period of target_sa and sa_at_period ({PERIOD_LIMITS[0]:g} s or "
                             f"longer); 0 = none"),
        Variable("sa_damping", start=DEFAULT_DAMPING, unit="1", low=0.0, high=1.0, high_open=True,
                 description="damping ratio of the oscillator of target_sa and sa_at_period"),
        Variable("time_shift", start=0.0, unit="s", description="time of the first sample"),
        Variable("ag", causality="output", unit="m/s2", description="ground acceleration at the end of the step"),
        Variable("ag_mean", causality="output", unit="m/s2", description="mean ground acceleration over the last step"),
        Variable("vg", causality="output", unit="m/s", description="ground velocity at the end of the step"),
        Variable("dg", causality="output", unit="m", description="ground displacement at the end of the step"),
        Variable("pga", causality="output", unit="m/s2", description="peak ground acceleration of the (scaled) record"),
        Variable("duration", causality="output", unit="s", description="record length (npts - 1) dt"),
        Variable("t_end", causality="output", unit="s",
                 description="time of the last sample (time_shift + duration); zero motion afterwards"),
        Variable("scale_factor", causality="output", unit="1",
                 description="factor applied to the record's values (after the unit conversion)"),
        Variable("sa_at_period", causality="output", unit="m/s2",
                 description="pseudo-spectral acceleration of the played record at sa_period (0 if none)"),
        Variable("n_knots", "Integer", causality="output", start=0,
                 description=f"knots of the last step in t_knot/ag_knot (2..{KNOT_CAPACITY}); 0 = none "
                             f"(before the first step, or a step spanning more record samples: use ag_mean)"),
        *array("t_knot", KNOT_CAPACITY, causality="output", unit="s",
               description="time of a knot of the record over the last step [t, t+h] (first t, last t+h)"),
        *array("ag_knot", KNOT_CAPACITY, causality="output", unit="m/s2",
               description="ground acceleration at the knot (the record is linear between knots)"),
    )

    PRIVATE_STATE = ("_knot_step",)
    _KNOTS = ("n_knots", "t_knot", "ag_knot")

    def __init__(self, **kwargs):
        self._knot_step = None       # (t0, t1) of the step whose knots are not computed yet
        super().__init__(**kwargs)
        self._record = None
        self._start_time = 0.0

    # -- knots, computed when read ---------------------------------------------------------------
    def _scalar_getter(self, attr):
        if attr == "n_knots":
            return lambda: (self._fill_knots(), self.n_knots)[1]
        return None

    def _element_getter(self, attr, idx):
        if attr not in self._KNOTS:
            return super()._element_getter(attr, idx)

        def get():
            self._fill_knots()
            return getattr(self, attr)[idx]
        return get

    def _array_reader(self, attr):
        if attr not in self._KNOTS:
            return functools.partial(getattr, self, attr)

        def read():
            self._fill_knots()
            return getattr(self, attr)
        return read

    def _fill_knots(self) -> None:
        if self._knot_step is None:
            return
        t0, t1 = self._knot_step
        self._knot_step = None
        knots = step_knots(self._record, t0, t1, KNOT_CAPACITY)
        self.t_knot[:] = 0.0
        self.ag_knot[:] = 0.0
        if knots is None:
            self.n_knots = 0
        else:
            times, values = knots
            self.n_knots = times.size
            self.t_knot[:times.size] = times
            self.ag_knot[:times.size] = values

    def setup_experiment(self, start_time, stop_time, tolerance):
        self._start_time = float(start_time or 0.0)

    def validate(self):
        conflict = scaling_conflict(self.target_pga, self.target_pga_g, self.target_sa)
        if conflict:
            yield conflict
        if self.target_sa > 0.0 and self.sa_period == 0.0:
            yield f"target_sa = {self.target_sa!r} m/s2 needs sa_period (s), the period it applies at"
        if 0.0 < self.sa_period < PERIOD_LIMITS[0]:
            yield (f"sa_period = {self.sa_period!r} s is outside the allowed range "
                   f"{PERIOD_LIMITS[0]:g} <= sa_period <= {PERIOD_LIMITS[1]:g} (or 0 = none)")

    def initialize(self) -> None:
        parameters = {v.name: getattr(self, v.name) for v in self.VARIABLES if v.causality == "parameter"}
        try:
            record = record_from_parameters(parameters, records_dir=self._records_dir())
        except ValueError as exc:  # RecordError names the file and line
            raise SlaveError(f"record = {self.record!r}: {exc}") from None
        for warning in record.warnings:
            self.log(f"{self.instance_name}: record = {self.record!r}: {warning}", Fmi2Status.warning)
        self._record = record
        self.pga = record.pga
        self.duration = record.duration
        self.t_end = record.end_time
        self.scale_factor = record.scale_factor
        self.sa_at_period = (pseudo_acceleration(record.acceleration, record.dt, self.sa_period, self.sa_damping)
                             if self.sa_period > 0.0 else 0.0)
        t = self._start_time
        self.ag = self.ag_mean = record.at(t)
        self.vg = record.velocity(t)
        self.dg = record.displacement(t)
        self.n_knots = 0
        self.t_knot[:] = 0.0
        self.ag_knot[:] = 0.0
        self._knot_step = None

    def _records_dir(self) -> Path | None:
        """This FMU's own bundled records (``resources/<package>/records``), if it has them.

        Taken from the resources folder of this instance, not from the module's ``__file__``:
        a module imported by an earlier instance of the FMU may come from a folder the host
        has deleted since (``fmpy.simulate_fmu`` does).
        """
        if self.resources:
            folder = Path(self.resources) / __package__ / "records"
            if folder.is_dir():
                return folder
        return None

    def step(self, current_time: float, step_size: float) -> None:
        t1 = current_time + step_size
        self.ag, self.ag_mean, self.vg, self.dg = self._record.over_step(float(current_time), t1)
        self._knot_step = (current_time, t1)

    def _step_outputs_problem(self) -> str | None:
        """A step changes ag, ag_mean, vg and dg; the knots it leaves are record samples (finite,
        checked when the record was read) and the step's ends (finite times, checked before the
        step), and the rest are set at initialisation.  So the four are checked (their sum: a sum
        that is not finite sends it to the base's exact check), not the knot arrays: summing those
        was half of a ground doStep."""
        if math.isfinite(self.ag + self.ag_mean + self.vg + self.dg):
            return None
        return self._outputs_problem()
