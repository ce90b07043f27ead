"""fuse: chains of fusable GPU components become one group: one kernel, one launch.

Runs after insert-adapters (so every edge that crosses memories has its adapter, and
what the CPU reads is known) and before allocate-gpu (so a group gets one config_gpu and
the thread budget counts it once).

How groups are chosen (after TVM's fusion of injective operators into their consumers
and Inductor's scheduler, which records why two nodes were not fused):

- Candidates are GPU components whose type declares a fusable form (fusable.py) and that
  the model does not mark 'fuse: false'.  Everything else is opaque: its own kernel.
- Walking the run order backwards, each candidate not yet in a group roots a new group
  and absorbs its producers, upstream, as long as a producer is a candidate, every reader
  of its output is already in the group (an output read by a component outside the group,
  or by the CPU through an adapter, must be materialized: it ends the group), and the
  recomputation stays within the cost cap.
- Cost cap: inside a group a member is evaluated once for every read of its output, so a
  stencil of (2r + 1)^2 taps evaluates each producer (2r + 1)^2 times per output element.
  A member evaluated R > 1 times per output element, reading T input elements each time
  (T = 1 for pointwise and index maps, (2r + 1)^2 for a stencil), costs R x T loads; the
  group is refused where any such member would exceed FUSE_COST_CAP (64): e.g. a 5x5
  blur may absorb mirrors and detectors, but not another blur (25 x 25 = 625).
- A group of one component is no group: the component keeps its own, hand-written kernel.

Every GPU-to-GPU edge between components that ends up outside a group gets its reason in
system.unfused (shown by `plan`, `check` and --print-between-passes).
"""

from __future__ import annotations

from dataclasses import replace

from ..ir import AdapterNode, ComponentNode, Edge, GroupNode, Port, System
from ..model import ComponentType, Endpoint, GpuDecl
from .base import Pass

FUSE_COST_CAP = 64
GROUP_PREFER = GpuDecl((8, 16, 32, 64), (1,), (32, 16, 16, 1))


class Fuse(Pass):
    name = "fuse"

    def apply(self, system, rep):
        gpu_edges = [e for e in system.edges if _gpu_component(system, e.source.component)
                     and _gpu_component(system, e.target.component)]
        if system.fusion == "off" or not gpu_edges:
            for e in gpu_edges:
                system.unfused[str(e)] = f"fusion is off ({system.fusion_reason})"
            return system
        at = {n: i for i, n in enumerate(system.order)}
        assigned: dict[str, str] = {}  # member -> the root of its group
        reasons: dict[str, str] = {}
        groups: list[list[str]] = []
        for root in reversed(system.order):
            if root in assigned or _opaque(system, root):
                continue
            members = {root}
            changed = True
            while changed:
                changed = False
                for m in sorted(members, key=at.get, reverse=True):
                    for pname in system.nodes[m].inputs:
                        src = system.writer(Endpoint(m, pname))
                        if src is None or src.component in members or \
                                not _gpu_component(system, src.component):
                            continue
                        why = _why_not(system, src, members, m)
                        if why:
                            reasons.setdefault(f"{src} -> {m}.{pname}", why)
                            continue
                        members.add(src.component)
                        changed = True
            for m in members:
                assigned[m] = root
            groups.append(sorted(members, key=at.get))
        for e in gpu_edges:
            a, b = e.source.component, e.target.component
            if assigned.get(a) is not None and assigned.get(a) == assigned.get(b):
                continue
            why = _opaque(system, b) or _opaque(system, a) or reasons.get(str(e)) or \
                f"{a} and {b} are in different groups"
            system.unfused[str(e)] = why
        for names in groups:
            if len(names) > 1:
                make_group(system, names)
        return system


def _gpu_component(system: System, name: str) -> bool:
    node = system.nodes.get(name)
    return isinstance(node, ComponentNode) and node.on_gpu


def _opaque(system: System, name: str) -> str:
    """Why a GPU component can never be in a group ('' when it can)."""
    node = system.nodes[name]
    if not isinstance(node, ComponentNode) or not node.on_gpu:
        return f"{name} does not run on the GPU"
    if node.type.fusable is None:
        return f"{name} ({node.type.name}) has no fusable form: its own kernel runs"
    if not node.fuse:
        return f"the model sets 'fuse: false' on {name}"
    return ""


def _why_not(system: System, src: Endpoint, members: set[str], consumer: str) -> str:
    """Why the producer src cannot join the group of members ('' when it can)."""
    why = _opaque(system, src.component)
    if why:
        return why
    outside = [_reader(system, r) for r in system.readers(src) if r.component not in members]
    if outside:
        return (f"{src} is also read by {', '.join(outside)}, outside the group: "
                "its output must be materialized")
    cost = _worst_recompute(system, members | {src.component})
    if cost is not None:
        member, r, taps = cost
        return (f"recomputing {member} {r} times per output element of the group "
                f"(reading {taps} input element{'s' if taps != 1 else ''} each time) "
                f"costs {r * taps} loads, over the cap of {FUSE_COST_CAP}")
    return ""


def _reader(system: System, end: Endpoint) -> str:
    """A reader as a user knows it: the CPU reads through an adapter."""
    node = system.nodes[end.component]
    if isinstance(node, AdapterNode):
        ends = ", ".join(map(str, system.readers(Endpoint(node.name, "output"))))
        return f"the CPU ({ends}, through {node.name})"
    return str(end)


def evaluations(system: System, members: set[str]) -> dict[str, int]:
    """How many times each member is evaluated per output element of the group."""
    order = [n for n in system.order if n in members]
    count = dict.fromkeys(order, 0)
    count[order[-1]] = 1
    for m in reversed(order):
        node = system.nodes[m]
        taps = node.type.fusable.taps(node.params)
        for pname in node.inputs:
            src = system.writer(Endpoint(m, pname))
            if src is not None and src.component in members:
                count[src.component] += count[m] * taps
    return count


def _worst_recompute(system: System, members: set[str]) -> tuple[str, int, int] | None:
    """The first member whose recomputation costs more than the cap, or None."""
    for m, r in evaluations(system, members).items():
        node = system.nodes[m]
        taps = node.type.fusable.taps(node.params)
        if r > 1 and r * taps > FUSE_COST_CAP:
            return m, r, taps
    return None


def group_name(system: System, names: list[str]) -> str:
    wanted = "_".join(names) if len(names) <= 3 else f"{names[0]}_to_{names[-1]}"
    return system.unique_name(wanted)


def make_group(system: System, names: list[str]) -> GroupNode:
    """Replace member components by one GroupNode, rewiring every edge."""
    members = [system.nodes[n] for n in names]
    root = members[-1]
    name = group_name(system, names)
    inside = set(names)
    inputs: dict[str, Port] = {}
    feeds: dict[str, Endpoint] = {}
    internal: list[Edge] = []
    edges: list[Edge] = []
    (out_name, out_port), = root.outputs.items()
    for e in system.edges:
        a, b = e.source.component in inside, e.target.component in inside
        if a and b:
            internal.append(e)
        elif b:
            port_name = f"{e.target.component}_{e.target.port}"
            inputs[port_name] = replace(system.nodes[e.target.component].inputs[e.target.port],
                                        name=port_name)
            feeds[port_name] = e.target
            edges.append(Edge(e.source, Endpoint(name, port_name), e.pos, e.data))
        elif a:
            edges.append(Edge(Endpoint(name, e.source.port), e.target, e.pos, e.data))
        else:
            edges.append(e)
    group = GroupNode(name, root.pos, inputs, {out_name: replace(out_port)}, members=members,
                      feeds=feeds, internal=internal,
                      type=group_type(system, name, members, inputs))
    position = system.order.index(root.name)
    for n in names:
        del system.nodes[n]
    system.add_node(group)
    system.edges = edges
    system.order[position] = name
    system.order = [n for n in system.order if n not in inside]
    system.stages[name] = system.stages[root.name]
    for n in names:
        system.stages.pop(n, None)
    return group


def group_type(system: System, name: str, members: list[ComponentNode],
               inputs: dict[str, Port]) -> ComponentType:
    """The stand-in type of a group: its class name in generated code, its ports, and
    the GPU preferences of its root (a generated group kernel covers tile x tile squares
    and accepts these tiles)."""
    cls = "Fused" + "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)
    taken = set(system.model.types) | set(system.nodes)
    while cls in taken:
        cls += "_"
    root = members[-1]
    rt = root.type
    decl = rt.gpu if rt.cover == "squares" else GROUP_PREFER
    decl = GpuDecl(decl.tiles, (1,), decl.prefer[:3] + (1,))
    from ..model import PortDecl

    ports = {p: PortDecl(p, "in", "gpu", port.dtype, port.channels)
             for p, port in inputs.items()}
    (out_name, out_decl), = rt.outputs.items()
    return ComponentType(
        name=cls, kind="gpu-aware",
        description="Fuses " + ", ".join(f"{m.name} ({m.type.name})" for m in members)
        + " into one kernel.",
        params={}, inputs=ports, outputs={out_name: out_decl}, requires=[],
        decl_file=rt.decl_file, origin="group", pos=root.pos, kernel_function=name,
        grid=out_name, cover="squares", gpu=decl)
