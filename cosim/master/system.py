"""System assembly: the FMU instances of a scene, parameterised and connected.

:class:`Catalog` loads each FMU file once (model description read, archive
extracted once).  :class:`System` instantiates exactly the instances a
:class:`~cosim.master.scene.Scene` calls for, sets every parameter as an FMU
variable, and wires the scene's connections as one linear map per instance:
``u_i = A_i @ y`` where ``y`` is the vector of every Real output of every
instance (each instance's outputs are a view into ``y``, filled in place by
``fmi2GetReal``).  :func:`cosim.master.simulate.simulate` advances a system with a
coupling strategy (:mod:`cosim.master.coupling`).

A catalog maps FMU names to objects with ``interface`` and ``instantiate(name)``; the
instances honour the protocol of :class:`cosim.master.fmi.Instance`
(:class:`~cosim.master.fmi.InstanceProtocol`), so a catalog of fakes builds a system with
no FMU at all (the coupling strategies' tests do).

Reuse (parameter studies): build the ``System`` once, then for each case
``system.reset(scene)`` (fmi2Reset + parameters of the new scene, same
instances and connections) and ``simulate(system, ...)`` again.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from ..fmus import BUILDING, FMU_NAMES, fmu_spec
from .fmi import FMU, InstanceProtocol, PortProtocol
from .models import storeys_are_linear
from .names import column
from .steplog import LoggedContact

if TYPE_CHECKING:
    from .scene import InstanceSpec, Scene


def output_names(spec: "InstanceSpec", interface: Any, type: str) -> list[str]:
    """The outputs of type ``type`` an instance records: every one of its FMU, but for a building
    only the floors it has (``n_storeys``)."""
    names = interface.names("output", type)
    if spec.fmu == BUILDING:
        n = int(spec.parameters["n_storeys"])
        names = [x for x in names if (interface.variables[x].index or 0) <= n]
    return names


class Catalog(Mapping[str, FMU]):
    """The package's FMUs in one folder, each loaded (extracted) once."""

    def __init__(self, fmu_dir: str | Path, names: Sequence[str] = FMU_NAMES):
        self.fmu_dir = Path(fmu_dir)
        self._fmus: dict[str, FMU] = {}
        try:
            for name in names:
                self._fmus[name] = FMU(self.fmu_dir / f"{name}.fmu")
        except Exception:
            self.close()
            raise

    def __getitem__(self, name: str) -> FMU:
        return self._fmus[name]

    def __iter__(self):
        return iter(self._fmus)

    def __len__(self) -> int:
        return len(self._fmus)

    def close(self) -> None:
        for fmu in self._fmus.values():
            fmu.close()

    def __enter__(self) -> "Catalog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ReadPlan:
    """What the nodes read after a step (shared by the nodes of a system): ``rows`` is True for
    a step whose end is recorded (:class:`cosim.master.recording.Recorder`), when each node
    reads its recorded outputs together with the watched ones, in the same call."""

    __slots__ = ("rows",)

    def __init__(self) -> None:
        self.rows = True


@dataclass
class Node:
    """One instance in the system: its ports and its input map.

    ``outputs.values`` is a view of ``System.y`` (every Real output); ``inputs`` are set from
    ``A @ y`` by :meth:`pull`.  ``integers`` and ``booleans`` hold the Integer (impacts) and
    Boolean (in_contact) outputs, views of ``System.ints``.

    A run reads only what it needs (:meth:`System.watch`): after every step the outputs the
    coupling, the guard and the summary need (``watched``, scattered into ``y`` at
    ``watched_index``), at recorded steps those and the recorded ones (``rows``), one
    ``fmi2GetReal`` either way.  Without a plan every output is read (``outputs``).
    """

    spec: "InstanceSpec"
    instance: InstanceProtocol
    outputs: PortProtocol
    integers: PortProtocol
    booleans: PortProtocol
    inputs: PortProtocol
    A: np.ndarray
    kind: str                   # the FMU's role: "ground", "contact" or "building"
    y: np.ndarray | None = None
    plan: ReadPlan | None = None
    watched: PortProtocol | None = None
    watched_index: np.ndarray | None = None
    rows: PortProtocol | None = None
    rows_index: np.ndarray | None = None
    #: building with knot inputs: the input port carries [A @ y | t_knot[1], ag_knot[1], ...]
    knot_offset: int = 0
    knot_count: PortProtocol | None = None
    knots_set: int = -1         # n_knots the instance has now (set only when it changes)
    knot_ag: int = -1           # where the held ``ag`` input sits in the input port (-1: none)
    hold_mean: bool = False     # a step inside one record interval holds its mean (linear storeys)
    #: the instance's name (``spec.name``, which a :meth:`System.reset` keeps), an attribute: the
    #: master's loops look it up for every contact at every step
    name: str = field(init=False)

    def __post_init__(self) -> None:
        self.name = self.spec.name
        self._n_in = self.A.shape[0]            # coupling inputs (rows of A)
        # most inputs copy one output with a factor (+-1): a gather is much cheaper than A @ y
        A = self.A
        single = A.shape[0] and bool(np.all(np.count_nonzero(A, axis=1) == 1))
        self._source = np.argmax(A != 0.0, axis=1) if single else None
        self._factor = A[np.arange(A.shape[0]), self._source] if single else None

    def _inputs(self, y: np.ndarray, out: np.ndarray) -> None:
        if self._source is not None:
            np.multiply(y[self._source], self._factor, out=out)
        else:
            np.dot(self.A, y, out=out)

    def pull(self, y: np.ndarray) -> None:
        """Set the inputs from the current outputs of the system."""
        n_in = self._n_in
        if n_in:
            self._inputs(y, self.inputs.values[:n_in])
            if self.knot_count is None:
                self.inputs.set()
            else:
                self.inputs.set_first(n_in)

    def pull_with_knots(self, y: np.ndarray, knots: np.ndarray) -> None:
        """Set the inputs and the ground motion over the coming step, ``knots`` interleaved
        ``[t_1, ag_1, t_2, ag_2, ...]`` (:meth:`cosim.master.knots.GroundLookahead.cut`): one
        fmi2SetReal, and fmi2SetInteger when the number of knots changes.

        A step inside one record interval (two knots: the record is linear over it) gets the
        ground acceleration held at its exact mean, ``ag = (a0 + a1) / 2`` with ``n_knots = 0``:
        the zero-order-hold step of earlier versions (exact velocity increments), which a linear
        building takes with one cached matrix product; a step over several intervals, and every
        step of a yielding building, gets the knots (first-order hold, exact for the record).
        A yielding building's step costs the same either way, and the mean's error in the
        response (second order in the step) is what kept ``kasai_maison_inelastic`` off the
        criteria at 10 ms: its relative floor velocity before the first impact was 0.22 % off
        the reference's at 10 ms, 0.05 % at 5 ms."""
        n_in = self._n_in
        inputs = self.inputs
        buf = inputs.values
        if n_in:
            self._inputs(y, buf[:n_in])
        size = knots.size
        if size == 4 and self.hold_mean:
            buf[self.knot_ag] = 0.5 * (knots.item(1) + knots.item(3))
            inputs.set_first(n_in)
            count = 0
        else:
            o = self.knot_offset
            buf[o:o + size] = knots
            inputs.set_first(o + size)
            count = size >> 1
        if count != self.knots_set:
            self.knot_count.set([count])
            self.knots_set = count

    def push(self) -> None:
        """Read the outputs the run watches (into the system's ``y``): one fmi2GetReal."""
        port = self.watched
        if port is None:
            self.outputs.get()
            self.integers.get()
            self.booleans.get()
            return
        if self.plan.rows:
            port, index = self.rows, self.rows_index
        else:
            index = self.watched_index
        if index.size:
            port.get()
            self.y[index] = port.values

    def push_all(self) -> None:
        """Read every output (initialisation, the end of a run)."""
        self.outputs.get()
        self.integers.get()
        self.booleans.get()

    def step(self, y: np.ndarray, t: float, h: float) -> None:
        """pull, fmi2DoStep, push."""
        self.pull(y)
        self.instance.do_step(t, h)
        self.push()


class System:
    """The FMU instances of a scene, parameterised and connected.

    Attributes: ``nodes`` (Gauss-Seidel order: ground, contacts, buildings),
    ``ground`` / ``contacts`` / ``buildings`` (lists of nodes), ``y`` (every
    Real output), ``ints`` (every Integer and Boolean output), ``columns`` (names
    ``instance.variable`` of ``y`` then ``ints``).
    """

    def __init__(self, scene: "Scene", catalog: Mapping[str, Any]):
        self.scene = scene
        self.catalog = catalog
        self.nodes: list[Node] = []
        self.t0 = 0.0
        self.plan = ReadPlan()
        self._in_names: dict[str, list[str]] = {}
        self._outputs: dict[str, tuple[int, list[str]]] = {}   # instance -> (offset in y, Real outputs)
        self.knots = 0              # knot capacity the buildings' input ports carry (0: none)
        created: list[InstanceProtocol] = []
        try:
            self._build(scene, created)
        except Exception:
            for inst in created:
                inst.free()
            raise
        self.initialized = False

    # -- assembly --------------------------------------------------------------------------------
    def _output_names(self, spec: "InstanceSpec", fmu: Any, type: str) -> list[str]:
        return output_names(spec, fmu.interface, type)

    def _build(self, scene: "Scene", created: list[InstanceProtocol]) -> None:
        specs = scene.instances()
        out_names = {s.name: self._output_names(s, self.catalog[s.fmu], "Real") for s in specs}
        int_names = {s.name: self._output_names(s, self.catalog[s.fmu], "Integer") for s in specs}
        bool_names = {s.name: self._output_names(s, self.catalog[s.fmu], "Boolean") for s in specs}
        offsets, n_y = {}, 0
        for s in specs:
            offsets[s.name] = n_y
            n_y += len(out_names[s.name])
        n_i = sum(len(int_names[s.name]) + len(bool_names[s.name]) for s in specs)
        self.y = np.zeros(n_y)
        self.ints = np.zeros(n_i, dtype=np.int32)
        self.columns = [column(s.name, v) for s in specs for v in out_names[s.name]] + \
                       [column(s.name, v) for s in specs for v in int_names[s.name] + bool_names[s.name]]
        index = {c: i for i, c in enumerate(self.columns[:n_y])}

        # inputs each instance receives, in a fixed order, and the map A from y
        in_names: dict[str, list[str]] = {s.name: [] for s in specs}
        for c in scene.connections():
            if c.input not in in_names[c.target]:
                in_names[c.target].append(c.input)
        matrices = {s.name: np.zeros((len(in_names[s.name]), n_y)) for s in specs}
        for c in scene.connections():
            matrices[c.target][in_names[c.target].index(c.input), index[column(c.source, c.output)]] += c.factor

        i_offset = 0
        for s in specs:
            fmu = self.catalog[s.fmu]
            inst = fmu.instantiate(s.name)
            created.append(inst)
            o = offsets[s.name]
            outputs = inst.real_port(out_names[s.name], self.y[o:o + len(out_names[s.name])])
            ni = len(int_names[s.name])
            integers = inst.integer_port(int_names[s.name], self.ints[i_offset:i_offset + ni])
            i_offset += ni
            nb = len(bool_names[s.name])
            booleans = inst.boolean_port(bool_names[s.name], self.ints[i_offset:i_offset + nb])
            i_offset += nb
            for name in in_names[s.name]:
                inst.variable(name, "input")
            inputs = inst.real_port(in_names[s.name])
            kind = fmu_spec(s.fmu).role
            if kind == "contact":   # every doStep it takes is logged for the replays (steplog.py)
                inst = LoggedContact(inst, inputs)
            self.nodes.append(Node(s, inst, outputs, integers, booleans, inputs, matrices[s.name], kind,
                                   y=self.y, plan=self.plan))
            self._in_names[s.name] = in_names[s.name]
            self._outputs[s.name] = (o, out_names[s.name])
        self.ground = [n for n in self.nodes if n.kind == "ground"]
        self.contacts = [n for n in self.nodes if n.kind == "contact"]
        self.buildings = [n for n in self.nodes if n.kind == "building"]

    def coupling_sources(self) -> list[str]:
        """The Real outputs some instance's inputs are computed from (columns of ``y``)."""
        used = np.zeros(self.y.size, dtype=bool)
        for n in self.nodes:
            if n.A.shape[0]:
                used |= np.any(n.A != 0.0, axis=0)
        return [self.columns[i] for i in np.flatnonzero(used)]

    def node(self, name: str) -> Node:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(name)

    @property
    def instances(self) -> dict[str, InstanceProtocol]:
        return {n.name: n.instance for n in self.nodes}

    # -- life cycle ------------------------------------------------------------------------------
    def initialize(self, t0: float = 0.0, stop_time: float | None = None, host: str | None = None) -> None:
        """setupExperiment, parameters, exit initialisation; read the outputs at t0.

        Sources and buildings leave initialisation first so that each contact
        instance starts from the buildings' initial floor states.  ``host``: the
        pounding.fmu parameter of that name for every contact whose scene does not
        set it (the coupling strategy's ``host``).
        """
        self.t0 = t0
        stop_time = self.scene.stop_time if stop_time is None else stop_time
        for n in self.nodes:
            n.instance.setup(t0, stop_time)
            n.instance.set(n.spec.parameters)
            if host is not None and n.kind == "contact" and "host" not in n.spec.parameters:
                n.instance.set({"host": host})
        self.y[:] = 0.0
        self.ints[:] = 0
        for n in self.ground + self.buildings + self.contacts:
            n.pull(self.y)
            n.instance.exit_initialization()
            n.push_all()
        for n in self.buildings:  # contact outputs at t0 (forces are zero unless overlapping)
            n.pull(self.y)
        self.initialized = True

    # -- what a run reads and sends --------------------------------------------------------------
    def watch(self, watched: "set[str] | None", recorded: "set[str] | None" = None) -> None:
        """Read only ``watched`` Real columns after every step, and ``watched | recorded`` after
        a recorded one (:class:`ReadPlan`), each node in one fmi2GetReal; None: every output,
        as before any plan."""
        for n in self.nodes:
            if watched is None:
                n.watched = n.watched_index = n.rows = n.rows_index = None
                continue
            # the node's own columns (y[offset:offset + len(names)], in order), not every column
            offset, names = self._outputs[n.name]
            mine = [(offset + j, v, column(n.name, v)) for j, v in enumerate(names)]
            w = [(i, v) for i, v, c in mine if c in watched]
            r = [(i, v) for i, v, c in mine if c in watched or (recorded is not None and c in recorded)]
            n.watched = n.instance.real_port([v for _, v in w])
            n.watched_index = np.array([i for i, _ in w], dtype=np.intp)
            n.rows = n.instance.real_port([v for _, v in r])
            n.rows_index = np.array([i for i, _ in r], dtype=np.intp)
        self.plan.rows = True

    def use_knots(self, capacity: int) -> None:
        """Give every building the ground motion's knots with its inputs (``capacity`` knots,
        interleaved ``t_knot[k], ag_knot[k]`` after the coupling inputs; :meth:`Node.pull_with_knots`);
        0: back to the held ``ag`` (``n_knots = 0``)."""
        for n in self.buildings:
            names = list(self._in_names[n.name])
            if capacity:
                names += [v for k in range(1, capacity + 1) for v in (f"t_knot[{k}]", f"ag_knot[{k}]")]
            n.inputs = n.instance.real_port(names)
            n.knot_offset = len(self._in_names[n.name])
            n.knot_ag = self._in_names[n.name].index("ag") if "ag" in self._in_names[n.name] else -1
            n.hold_mean = n.knot_ag >= 0 and storeys_are_linear(n.spec)
            if capacity:
                n.knot_count = n.instance.integer_port(["n_knots"])
                n.knots_set = -1
            elif n.knot_count is not None:
                n.knot_count.set([0])
                n.knot_count = None
        self.knots = capacity

    def reset(self, scene: "Scene | None" = None) -> None:
        """fmi2Reset every instance and apply the parameters of ``scene`` (default:
        the current one).  The new scene must have the same instances and
        connections (same buildings, storey counts and contact levels)."""
        if scene is not None:
            if [(s.name, s.fmu) for s in scene.instances()] != [(n.name, n.spec.fmu) for n in self.nodes] or \
                    scene.connections() != self.scene.connections() or \
                    [scene.n_storeys(b.name) for b in self.buildings] != [b.spec.parameters["n_storeys"] for b in self.buildings]:
                raise ValueError("System.reset: the new scene has other instances or connections; build a new System")
            for n, s in zip(self.nodes, scene.instances()):
                n.spec = s
            self.scene = scene
        for n in self.nodes:
            n.instance.reset()
        self.initialized = False

    def terminate(self) -> None:
        for n in self.nodes:
            n.instance.terminate()

    def close(self) -> None:
        for n in self.nodes:
            n.instance.free()
        self.nodes = []

    def __enter__(self) -> "System":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- counters --------------------------------------------------------------------------------
    def fmu_calls(self) -> int:
        return sum(n.instance.calls for n in self.nodes)

    def do_steps(self) -> dict[str, int]:
        return {n.name: n.instance.do_steps for n in self.nodes}
