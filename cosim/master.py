"""System assembly and the run loop.

:class:`Catalog` loads each FMU file once (model description read, archive
extracted once).  :class:`System` instantiates exactly the instances a
:class:`~cosim.scene.Scene` calls for, sets every parameter as an FMU
variable, and wires the scene's connections as one linear map per instance:
``u_i = A_i @ y`` where ``y`` is the vector of every Real output of every
instance (each instance's outputs are a view into ``y``, filled in place by
``fmi2GetReal``).  :func:`simulate` advances a system with a coupling strategy
(:mod:`cosim.coupling`) and records every output in preallocated arrays.

Reuse (parameter studies): build the ``System`` once, then for each case
``system.reset(scene)`` (fmi2Reset + parameters of the new scene, same
instances and connections) and ``simulate(system, ...)`` again.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .fmi import FMU, BooleanPort, Instance, IntegerPort, RealPort
from .scene import BUILDING, GROUND, POUNDING, InstanceSpec, Scene, _element


class Catalog(Mapping[str, FMU]):
    """The package's FMUs in one folder, each loaded (extracted) once."""

    def __init__(self, fmu_dir: str | Path, names: Sequence[str] = (POUNDING, BUILDING, GROUND)):
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


@dataclass
class Node:
    """One instance in the system: its ports and its input map.

    ``outputs.values`` is a view of ``System.y``; ``inputs`` are set from
    ``A @ y`` by :meth:`pull`.  ``integers`` and ``booleans`` hold the Integer
    (impacts) and Boolean (in_contact) outputs, views of ``System.ints``.
    """

    spec: InstanceSpec
    instance: Instance
    outputs: RealPort
    integers: IntegerPort
    booleans: BooleanPort
    inputs: RealPort
    A: np.ndarray
    kind: str

    @property
    def name(self) -> str:
        return self.spec.name

    def pull(self, y: np.ndarray) -> None:
        """Set the inputs from the current outputs of the system."""
        if self.A.shape[0]:
            np.dot(self.A, y, out=self.inputs.values)
            self.inputs.set()

    def push(self) -> None:
        """Read the outputs (into the system's ``y``)."""
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

    def __init__(self, scene: Scene, catalog: Catalog):
        self.scene = scene
        self.catalog = catalog
        self.nodes: list[Node] = []
        self.t0 = 0.0
        created: list[Instance] = []
        try:
            self._build(scene, created)
        except Exception:
            for inst in created:
                inst.free()
            raise
        self.initialized = False

    # -- assembly --------------------------------------------------------------------------------
    def _output_names(self, spec: InstanceSpec, fmu: FMU, type: str) -> list[str]:
        names = fmu.names("output", type)
        if spec.fmu == BUILDING:  # only the floors the building uses
            n = int(spec.parameters["n_storeys"])
            names = [x for x in names if (_element(x)[1] or 0) <= n]
        return names

    def _build(self, scene: Scene, created: list[Instance]) -> None:
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
        self.columns = [f"{s.name}.{v}" for s in specs for v in out_names[s.name]] + \
                       [f"{s.name}.{v}" for s in specs for v in int_names[s.name] + bool_names[s.name]]
        index = {c: i for i, c in enumerate(self.columns[:n_y])}

        # inputs each instance receives, in a fixed order, and the map A from y
        in_names: dict[str, list[str]] = {s.name: [] for s in specs}
        for c in scene.connections():
            if c.input not in in_names[c.target]:
                in_names[c.target].append(c.input)
        matrices = {s.name: np.zeros((len(in_names[s.name]), n_y)) for s in specs}
        for c in scene.connections():
            matrices[c.target][in_names[c.target].index(c.input), index[f"{c.source}.{c.output}"]] += c.factor

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
            kind = {GROUND: "ground", POUNDING: "contact", BUILDING: "building"}[s.fmu]
            self.nodes.append(Node(s, inst, outputs, integers, booleans, inputs, matrices[s.name], kind))
        self.ground = [n for n in self.nodes if n.kind == "ground"]
        self.contacts = [n for n in self.nodes if n.kind == "contact"]
        self.buildings = [n for n in self.nodes if n.kind == "building"]

    def node(self, name: str) -> Node:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(name)

    @property
    def instances(self) -> dict[str, Instance]:
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
            n.push()
        for n in self.buildings:  # contact outputs at t0 (forces are zero unless overlapping)
            n.pull(self.y)
        self.initialized = True

    def reset(self, scene: Scene | None = None) -> None:
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


@dataclass
class SimulationResult:
    """Every recorded output of a run, plus the cost counters.

    ``time`` (s), ``values[k, j]`` = column ``columns[j]`` at ``time[k]``.
    """

    scene: Scene
    strategy: str
    time: np.ndarray
    columns: list[str]
    values: np.ndarray
    communication_steps: int
    rollbacks: int
    fmu_calls: int
    do_steps: dict[str, int]
    wall_time_s: float
    instances: list[str] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)   # strategy-specific counters (adaptive)

    @property
    def energy_residual_J(self) -> float:
        """Energy balance residual at the end (J), see :mod:`cosim.results`."""
        from .results import energy_history

        return float(energy_history(self)["residual"][-1])

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(column)]
        except ValueError:
            raise KeyError(f"no column {column!r}") from None

    def has(self, column: str) -> bool:
        return column in self.columns


class Recorder:
    """Preallocated history of (t, y, ints), grown by doubling for variable steps."""

    def __init__(self, system: System, capacity: int):
        self.system = system
        self.n_y = system.y.size
        self.time = np.empty(max(capacity, 2))
        self.values = np.empty((max(capacity, 2), self.n_y + system.ints.size))
        self.count = 0

    def record(self, t: float) -> None:
        if self.count == self.time.size:
            self.time = np.resize(self.time, 2 * self.time.size)
            self.values = np.resize(self.values, (2 * self.values.shape[0], self.values.shape[1]))
        k = self.count
        self.time[k] = t
        row = self.values[k]
        row[:self.n_y] = self.system.y
        row[self.n_y:] = self.system.ints
        self.count += 1


def simulate(system: System, strategy: str | type | None = None, stop_time: float | None = None,
             step: float | None = None, progress: bool | None = None,
             callback: Callable[[float], None] | None = None, check_stability: bool = True,
             **options: Any) -> SimulationResult:
    """Initialise ``system`` and run it from t0 = 0 to ``stop_time`` with a coupling strategy.

    ``strategy``: a name from :data:`cosim.coupling.STRATEGIES` or a
    :class:`~cosim.coupling.CouplingStrategy` subclass (default: the scene's
    ``coupling``); ``step``: communication step (s, default: the scene's);
    ``progress``: tqdm bar (None = shown if the run lasts over 2 s).
    ``options`` go to the strategy's constructor.  ``check_stability``: after every
    step, :class:`cosim.adaptive.StabilityGuard` raises
    :class:`cosim.adaptive.InstabilityError` (saying what to change) when the run has
    produced non-finite values, a penetration beyond physical sense or created energy.
    """
    from .coupling import get_strategy

    scene = system.scene
    stop_time = scene.stop_time if stop_time is None else float(stop_time)
    step = scene.step if step is None else float(step)
    cls = get_strategy(strategy or scene.coupling)
    if system.initialized:
        system.reset()
    calls_before = system.fmu_calls()
    steps_before = system.do_steps()
    wall = time.perf_counter()
    system.initialize(0.0, stop_time, host=cls.host)
    solver = cls(system, 0.0, stop_time, step, **options)
    guard = None
    if check_stability:
        from .adaptive import StabilityGuard

        guard = StabilityGuard(system)
    recorder = Recorder(system, int(np.ceil(stop_time / step)) + 2)
    recorder.record(0.0)
    bar = None
    if progress is not False:
        from tqdm import tqdm

        bar = tqdm(total=stop_time, unit="s", delay=0.0 if progress else 2.0, leave=False,
                   desc=scene.name, bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.2f}/{total:g} s "
                                               "[{elapsed}<{remaining}]")
    shown = 0.0
    try:
        while solver.status == "running":
            solver.step()
            if guard is not None:
                guard.check(solver.t, getattr(solver, "h_last", solver.h))
            recorder.record(solver.t)
            if callback is not None:
                callback(solver.t)
            if bar is not None and solver.t - shown >= 0.01 * stop_time:
                bar.update(solver.t - shown)
                shown = solver.t
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall
    stats = dict(getattr(solver, "stats", {}))
    if guard is not None and guard.step_over_time_scale:
        stats["step_over_time_scale"] = dict(guard.step_over_time_scale)
    k = recorder.count
    return SimulationResult(
        scene=scene, strategy=cls.name, time=recorder.time[:k].copy(), columns=list(system.columns),
        values=recorder.values[:k].copy(), communication_steps=solver.communication_steps,
        rollbacks=solver.rollbacks, fmu_calls=system.fmu_calls() - calls_before,
        do_steps={n: v - steps_before.get(n, 0) for n, v in system.do_steps().items()},
        wall_time_s=wall, instances=[n.name for n in system.nodes], stats=stats)
