"""The system IR: the system's own graph of nodes and edges, which passes transform.

Built from the parsed model (``build_system``) and independent of it afterwards: passes
add, replace and remove nodes (an adapter between memories; later a fused group, a
component placed on the CPU) and rewire edges.  ``verify()`` checks the invariants after a
pass; ``dump()`` prints the whole IR, deterministically (``--print-between-passes``).

    node        a component instance (where it runs, its type, parameters, position),
                an adapter (a copy or mapping between CPU and GPU memory), or a group of
                member nodes (room for fusion: one node, one launch)
    port        a node's input or output: element type, channels, the memory its data lives
                in and, once sizes are propagated, its Data (size and element type)
    edge        producer node.port -> consumer node.port, with the Data that flows
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from .dataflow import Data, Endpoint
from .errors import Pos
from .model import ComponentType, SystemModel
from .runtime.facts import DeviceFacts
from .runtime.sizes import Size  # noqa: F401  (the passes take it from here)

MODES = ("gpu-aware", "standard")


@dataclass(frozen=True)
class GpuSettings:
    tile: int
    block_x: int
    block_y: int
    block_z: int
    source: str  # "model" | "preferred" | "reduced to fit the device" | "component's own" ...

    @property
    def threads_per_group(self) -> int:
        return self.block_x * self.block_y * self.block_z


@dataclass
class Port:
    name: str
    direction: str  # "in" | "out"
    memory: str  # "gpu" | "cpu": where its data lives in this system
    dtype: str
    channels: int
    data: Data | None = None  # set by propagate-sizes


@dataclass
class Node:
    name: str
    pos: Pos
    inputs: dict[str, Port]
    outputs: dict[str, Port]
    kind: ClassVar[str] = "node"

    def port(self, name: str) -> Port | None:
        return self.inputs.get(name) or self.outputs.get(name)

    @property
    def ports(self) -> list[Port]:
        return list(self.inputs.values()) + list(self.outputs.values())


@dataclass
class ComponentNode(Node):
    """An instance of a component type; placement says where its work runs."""

    type: ComponentType = None  # type: ignore[assignment]
    params: dict[str, Any] = field(default_factory=dict)
    placement: str = "cpu"  # "gpu" | "cpu"
    order: int = 0  # position in the model: ties in the run order follow it
    fuse: bool = True  # the model's 'fuse: false' keeps it out of every group
    # a flexible component: what was asked ("gpu" | "cpu" | "auto") and by whom ("model",
    # "platform.placement", "command line", "default"); the place pass decides "auto"
    asked: str = ""
    placed_by: str = ""
    kind: ClassVar[str] = "component"

    @property
    def on_gpu(self) -> bool:
        return self.placement == "gpu"

    def place(self, side: str, mode: str) -> None:
        """Run on side ("gpu" | "cpu"): a flexible component's ports live there too."""
        self.placement = side
        for port in self.ports:
            port.memory = port_memory(mode, side)


@dataclass
class AdapterNode(Node):
    """Moves one producing port's data between memories: input 'input', output 'output'."""

    direction: str = "cpu2gpu"  # "cpu2gpu" | "gpu2cpu"
    zero_copy: bool = False  # unified host memory: the device uses host memory in place
    source: Endpoint = None  # type: ignore[assignment]  # the producing port it serves
    kind: ClassVar[str] = "adapter"


@dataclass
class GroupNode(Node):
    """Member components that run as one kernel: one launch, one config_gpu, one lane.

    Made by the fuse pass (passes/fuse.py).  members are in run order and the last one,
    the root, makes the group's only output (named as the root's output port).  The
    group's inputs are named <member>_<port>, one per member input fed from outside
    (`feeds` says which); `internal` holds the edges between members.  `type` is a
    stand-in type (GPU preferences of the root, work-groups covering tile x tile squares
    of the output) so that passes that read a GPU node's type treat the group as one.
    """

    members: list[ComponentNode] = field(default_factory=list)
    placement: str = "gpu"
    feeds: dict[str, Endpoint] = field(default_factory=dict)  # input port -> member port
    internal: list[Edge] = field(default_factory=list)
    type: ComponentType = None  # type: ignore[assignment]
    params: dict[str, Any] = field(default_factory=dict)  # none: members keep theirs
    fuse: bool = False
    estimate: str = ""  # the fuse pass's cost estimate, fused against apart
    kind: ClassVar[str] = "group"

    @property
    def on_gpu(self) -> bool:
        return True

    @property
    def root(self) -> ComponentNode:
        return self.members[-1]

    def member(self, name: str) -> ComponentNode:
        return next(m for m in self.members if m.name == name)


@dataclass
class Edge:
    source: Endpoint  # producer node.port
    target: Endpoint  # consumer node.port
    pos: Pos = Pos("")
    data: Data | None = None  # set by propagate-sizes

    def __str__(self) -> str:
        return f"{self.source} -> {self.target}"


class VerifyError(Exception):
    """The IR breaks an invariant: a bug in a pass (or a hand-built IR), never the user's."""


@dataclass
class System:
    name: str
    model: SystemModel  # platform settings and positions for messages; passes read nodes
    device: DeviceFacts
    mode: str = "gpu-aware"
    execution: str = "parallel"  # "parallel" | "sequential"
    zero_copy: bool = False
    zero_copy_reason: str = ""
    frames_in_flight: int = 1  # frames worked on at the same time (stage-frames)
    staging: str = "pageable"  # copying adapters' host side: "pinned" | "pageable"
    staging_reason: str = ""
    fusion: str = "auto"  # "auto" | "off" (platform.fusion or --fusion)
    fusion_reason: str = ""
    nodes: dict[str, Node] = field(default_factory=dict)
    edges: list[Edge] = field(default_factory=list)
    done: list[str] = field(default_factory=list)  # names of the passes applied so far
    # schedule: the run order of every node (adapters placed where first needed) and the
    # stage of each (longest path from a source: one stage's nodes never depend on each
    # other)
    order: list[str] = field(default_factory=list)
    stages: dict[str, int] = field(default_factory=dict)
    # fuse: why each GPU-to-GPU edge between components was left unfused ("a.p -> b.q")
    unfused: dict[str, str] = field(default_factory=dict)
    # allocate-gpu: each GPU node's settings, the thread budget, the groups that can run
    # at the same time
    settings: dict[str, GpuSettings] = field(default_factory=dict)
    thread_budget: int = 0
    concurrent: list[tuple[str, ...]] = field(default_factory=list)
    # name-variables: the variable of every output port in generated code
    output_vars: dict[Endpoint, str] = field(default_factory=dict)
    # assign-queues: lane of every GPU command, the events it waits for, the lanes the host
    # waits for at the end of a frame, and zero-copy adapters unmapped after a reader
    lanes: dict[str, int] = field(default_factory=dict)
    waits: dict[str, list[str]] = field(default_factory=dict)
    frame_end_waits: list[str] = field(default_factory=list)
    unmap_after: dict[str, list[str]] = field(default_factory=dict)
    # stage-frames (frames in flight >= 2): the nodes of each stage, each run by one
    # thread in frame order, why the stages are cut where they are, the commands a stage
    # waits for before it hands a frame on, and the parts that keep one set of their
    # outputs per frame in flight (part -> why)
    flight_stages: list[list[str]] = field(default_factory=list)
    flight_notes: list[str] = field(default_factory=list)
    flight_end_waits: list[list[str]] = field(default_factory=list)
    buffer_sets: dict[str, str] = field(default_factory=dict)
    one_set: dict[str, str] = field(default_factory=dict)  # part -> why one set is enough
    plan: Any = None  # lower: the ProgramPlan
    # place: how the flexible components were placed (passes/place.py's Placement)
    placement: Any = None

    # --- queries -----------------------------------------------------------------------
    @property
    def components(self) -> dict[str, ComponentNode]:
        """The components that are nodes, and those running a generated kernel alone (a
        group of one is its component under the component's name)."""
        return {n: node.root if isinstance(node, GroupNode) else node
                for n, node in self.nodes.items()
                if isinstance(node, ComponentNode)
                or isinstance(node, GroupNode) and len(node.members) == 1}

    def component(self, name: str) -> ComponentNode:
        """A component by name, also when a fused group holds it."""
        node = self.nodes.get(name)
        if isinstance(node, ComponentNode):
            return node
        return next(m for g in self.kernel_groups for m in g.members if m.name == name)

    @property
    def kernel_groups(self) -> list[GroupNode]:
        """Every node whose kernel is generated from fusable forms: the fused groups and
        the groups of one (a component of a fusable type alone, passes/fuse.py)."""
        names = self.order or list(self.nodes)
        return [self.nodes[n] for n in names if isinstance(self.nodes.get(n), GroupNode)]

    @property
    def groups(self) -> list[GroupNode]:
        """The fused groups: several components as one kernel."""
        return [g for g in self.kernel_groups if len(g.members) > 1]

    def gpu_node(self, name: str) -> ComponentNode | GroupNode:
        """A component placed on the GPU or a group: a node with a type and GPU settings."""
        node = self.nodes[name]
        assert isinstance(node, (ComponentNode, GroupNode)) and node.on_gpu, name
        return node

    @property
    def adapters(self) -> list[AdapterNode]:
        names = self.order or list(self.nodes)
        return [self.nodes[n] for n in names if isinstance(self.nodes.get(n), AdapterNode)]

    def writer(self, target: Endpoint) -> Endpoint | None:
        """The output that feeds an input (None when unconnected)."""
        for e in self.edges:
            if e.target == target:
                return e.source
        return None

    def readers(self, source: Endpoint) -> list[Endpoint]:
        return [e.target for e in self.edges if e.source == source]

    def writers(self) -> dict[Endpoint, Endpoint]:
        """Input -> the output that feeds it, for every edge."""
        return {e.target: e.source for e in self.edges}

    def predecessors(self, name: str) -> list[str]:
        """Nodes feeding a node, in the order of its inputs (each once)."""
        found: list[str] = []
        for pname in self.nodes[name].inputs:
            src = self.writer(Endpoint(name, pname))
            if src is not None and src.component not in found:
                found.append(src.component)
        return found

    def data(self, end: Endpoint) -> Data | None:
        port = self.nodes[end.component].port(end.port)
        return port.data if port is not None else None

    @property
    def sizes(self) -> dict[Endpoint, Data]:
        """Every port's Data, once propagated."""
        return {Endpoint(n, p.name): p.data for n, node in self.nodes.items()
                for p in node.ports if p.data is not None}

    def input_var(self, target: Endpoint) -> str:
        return self.output_vars[self.writer(target)]

    # --- transforms ---------------------------------------------------------------------
    def add_node(self, node: Node) -> Node:
        if node.name in self.nodes:
            raise VerifyError(f"node '{node.name}' exists")
        self.nodes[node.name] = node
        return node

    def remove_node(self, name: str) -> None:
        del self.nodes[name]
        self.edges = [e for e in self.edges
                      if e.source.component != name and e.target.component != name]
        self.order = [n for n in self.order if n != name]

    def unique_name(self, wanted: str) -> str:
        name = wanted
        while name in self.nodes:  # a component may have taken the name
            name += "_"
        return name

    # --- invariants ---------------------------------------------------------------------
    def verify(self) -> None:
        """Raise VerifyError naming every broken invariant."""
        problems = verify_problems(self)
        if problems:
            raise VerifyError(f"IR of '{self.name}' after {self.done[-1] if self.done else 'build'}: "
                              + "; ".join(problems))

    def dump(self) -> str:
        return dump(self)


def verify_problems(system: System) -> list[str]:
    problems: list[str] = []
    done = set(system.done)
    for key, node in system.nodes.items():
        if key != node.name:
            problems.append(f"node '{node.name}' is filed as '{key}'")
        if not node.name.isidentifier():
            problems.append(f"node name '{node.name}' is not an identifier")
        for pname, port in {**node.inputs, **node.outputs}.items():
            if pname != port.name:
                problems.append(f"port '{node.name}.{port.name}' is filed as '{pname}'")
        if isinstance(node, GroupNode):
            for m in node.members:
                # a group of one is its member under the member's name
                if m.name in system.nodes and system.nodes[m.name] is not node:
                    problems.append(f"'{m.name}' is a member of group '{node.name}' and a node")
    seen: dict[Endpoint, int] = {}
    for e in system.edges:
        for end, direction in ((e.source, "out"), (e.target, "in")):
            node = system.nodes.get(end.component)
            port = None
            if node is not None:
                port = (node.outputs if direction == "out" else node.inputs).get(end.port)
            if port is None:
                problems.append(f"edge {e}: no {'output' if direction == 'out' else 'input'} "
                                f"'{end}'")
        seen[e.target] = seen.get(e.target, 0) + 1
    if "check-connections" in done:
        for node in system.nodes.values():
            for pname in node.inputs:
                n = seen.get(Endpoint(node.name, pname), 0)
                if n != 1:
                    problems.append(f"input '{node.name}.{pname}' has {n} writers")
    if "check-port-types" in done:
        for e in system.edges:
            a, b = _port(system, e.source), _port(system, e.target)
            if a and b and (a.dtype, a.channels) != (b.dtype, b.channels):
                problems.append(f"edge {e} joins {a.dtype}x{a.channels} to "
                                f"{b.dtype}x{b.channels}")
    if "insert-adapters" in done:
        for e in system.edges:
            a, b = _port(system, e.source), _port(system, e.target)
            if a and b and a.memory != b.memory:
                problems.append(f"edge {e} crosses from {a.memory.upper()} to "
                                f"{b.memory.upper()} memory without an adapter")
    if "propagate-sizes" in done:
        for node in system.nodes.values():
            for port in node.ports:
                if port.data is None:
                    problems.append(f"port '{node.name}.{port.name}' has no size")
        for e in system.edges:
            a, b = _port(system, e.source), _port(system, e.target)
            if a and b and not (e.data == a.data == b.data):
                problems.append(f"edge {e} carries {e.data}, its ports {a.data} and {b.data}")
    if "schedule" in done:
        if sorted(system.order) != sorted(system.nodes) or \
                len(set(system.order)) != len(system.order):
            problems.append("the order does not hold every node exactly once")
        else:
            at = {n: i for i, n in enumerate(system.order)}
            for e in system.edges:
                if e.source.component in at and e.target.component in at and \
                        at[e.source.component] >= at[e.target.component]:
                    problems.append(f"the order runs '{e.target.component}' before "
                                    f"'{e.source.component}', which feeds it")
    if "name-variables" in done:
        names = list(system.output_vars.values())
        if len(set(names)) != len(names):
            problems.append("two ports share a variable")
        for node in system.nodes.values():
            for pname in node.outputs:
                if Endpoint(node.name, pname) not in system.output_vars:
                    problems.append(f"output '{node.name}.{pname}' has no variable")
    for name in list(system.settings) + list(system.lanes):
        if name not in system.nodes:
            problems.append(f"settings or lane of '{name}', which is no node")
    return problems


def _port(system: System, end: Endpoint) -> Port | None:
    node = system.nodes.get(end.component)
    return node.port(end.port) if node is not None else None


def port_memory(mode: str, decl_memory: str) -> str:
    """Where a port's data lives: standard mode keeps all data on the CPU."""
    return "cpu" if mode == "standard" else decl_memory


def component_node(name: str, ctype: ComponentType, params: dict[str, Any], pos: Pos,
                   order: int, mode: str = "gpu-aware", asked: str = "",
                   placed_by: str = "", fuse: bool = True) -> ComponentNode:
    """A node of one instance; a flexible one starts where it is asked to run (on the GPU
    when asked "auto", until the place pass decides)."""
    side = "gpu" if ctype.gpu_aware else "cpu"
    if ctype.flexible and asked == "cpu":
        side = "cpu"

    def ports(decls):
        return {p: Port(p, d.direction, port_memory(mode, side if d.memory == "any" else d.memory),
                        d.dtype, d.channels)
                for p, d in decls.items()}

    return ComponentNode(name, pos, ports(ctype.inputs), ports(ctype.outputs), type=ctype,
                         params=dict(params), placement=side, order=order,
                         asked=asked if ctype.flexible else "",
                         placed_by=placed_by if ctype.flexible else "", fuse=fuse)


def asked_placement(model: SystemModel, name: str,
                    places: dict[str, str] | None = None) -> tuple[str, str]:
    """Where a flexible component is asked to run, and by whom: the command line
    (--place), its own 'placement:', platform.placement, else the GPU (the default)."""
    inst = model.components[name]
    if places and name in places:
        return places[name], "command line"
    if inst.placement:
        return inst.placement, "model"
    if model.placement != "gpu":
        return model.placement, "platform.placement"
    return "gpu", "default"


def build_system(model: SystemModel, device: DeviceFacts, mode: str = "gpu-aware",
                 execution: str = "parallel", places: dict[str, str] | None = None) -> System:
    """The IR of a parsed model: one node per instance, one edge per connection (duplicates
    included: check-connections reports and drops them).  places: --place COMPONENT=SIDE."""
    system = System(model.name, model, device, mode, execution)
    for inst in sorted(model.components.values(), key=lambda i: i.order):
        asked, by = asked_placement(model, inst.name, places)
        system.add_node(component_node(inst.name, inst.type, inst.params, inst.pos, inst.order,
                                       mode, asked, by, inst.fuse))
    for conn in model.connections:
        system.edges.append(Edge(conn.source, conn.target, conn.pos))
    return system


def dump(system: System) -> str:
    """The whole IR as text: every node with its ports, every edge, every decision."""
    lines = [(f"system {system.name} (mode {system.mode}, execution {system.execution}, "
              f"zero-copy {'on' if system.zero_copy else 'off'}, fusion {system.fusion}, "
              f"device {system.device.name})")]
    if system.done:
        lines.append(f"  after: {', '.join(system.done)}")
    names = system.order or list(system.nodes)
    for n in names:
        lines += ["  " + line for line in _node_lines(system, system.nodes[n])]
    for e in system.edges:
        lines.append(f"  edge {e}" + (f" : {e.data}" if e.data else ""))
    if system.placement is not None:  # place: each flexible component's side, and why
        lines += [f"  placed {line}" for line in system.placement.lines()]
    for edge, why in system.unfused.items():
        lines.append(f"  not fused {edge}: {why}")
    if system.concurrent:
        lines.append(f"  thread budget {system.thread_budget:,}")
        for group in system.concurrent:
            lines.append(f"  can run together: {', '.join(group)}")
    if system.frame_end_waits:
        lines.append(f"  frame end waits: {', '.join(system.frame_end_waits)}")
    for i, names in enumerate(system.flight_stages, 1):
        lines.append(f"  stage {i} of {system.frames_in_flight} frames in flight: "
                     f"{', '.join(names)}")
    for part, why in system.buffer_sets.items():
        lines.append(f"  {system.frames_in_flight} buffer sets: {part} ({why})")
    if system.plan is not None:
        lines += ["  " + line for line in system.plan.dump_lines()]
    return "\n".join(lines)


def _node_lines(system: System, node: Node) -> list[str]:
    if isinstance(node, ComponentNode):
        params = ", ".join(f"{k}={v!r}" for k, v in node.params.items())
        head = (f"component {node.name}: {node.type.name} on {node.placement.upper()}"
                + (f" [asked {node.asked} by {node.placed_by}]"
                   if node.placed_by not in ("", "default") else "")
                + (f" ({params})" if params else ""))
    elif isinstance(node, AdapterNode):
        head = (f"adapter {node.name}: {node.direction} of {node.source}"
                + (" [zero-copy]" if node.zero_copy else ""))
    elif isinstance(node, GroupNode):
        head = (f"group {node.name} on {node.placement.upper()}: "
                + ", ".join(f"{m.name} ({m.type.name})" for m in node.members))
    else:
        head = f"{node.kind} {node.name}"
    if node.name in system.stages:
        head += f" [stage {system.stages[node.name]}]"
    lines = [head]
    for port in node.ports:
        var = system.output_vars.get(Endpoint(node.name, port.name))
        lines.append(f"  {port.direction} {port.name}: {port.memory.upper()} {port.dtype}"
                     f"x{port.channels}" + (f" = {port.data}" if port.data else "")
                     + (f" -> var {var}" if var else ""))
    s = system.settings.get(node.name)
    if s is not None:
        lines.append(f"  config_gpu: tile={s.tile} block=({s.block_x}, {s.block_y}, "
                     f"{s.block_z}) [{s.source}]")
    if node.name in system.lanes:
        lines.append(f"  queue {system.lanes[node.name]}"
                     + "".join(f", waits {w}" for w in system.waits.get(node.name, [])))
    for a in system.unmap_after.get(node.name, []):
        lines.append(f"  then unmaps {a}")
    if isinstance(node, GroupNode):
        for port, end in node.feeds.items():
            lines.append(f"  feeds {port} -> {end}")
        for e in node.internal:
            lines.append(f"  fused edge {e}")
    return lines
