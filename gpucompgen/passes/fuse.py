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
  cost model says the group with it is cheaper than the group and it apart.
- Cost model (estimate()): inside a group a member is evaluated once for every read of
  its output: a stencil reading a producer at 9 taps evaluates it 9 times per output
  element, a gray conversion reading 3 channels evaluates its producer 3 times.  Reads
  are counted per snippet (its accessor calls, at least a stencil's window), so an index
  map reading its input 40 times costs 40 evaluations of its producer.  Fused, each
  member costs its evaluations times its arithmetic and its loads of group inputs; apart,
  each member costs one evaluation an element, plus storing its output, reading it back
  and a launch.  A producer joins only where the estimate with it is lower than without
  it, so no group chosen is estimated slower than its members apart; `plan` shows the
  estimate of every group and the figures of every refusal.  Where in doubt (a tie) the
  producer stays apart.
- A component of a fusable type that ends up in no group (fusion off, 'fuse: false', a
  producer the cost model refused, no fusable neighbour) becomes a group of one: it runs
  the kernel the generator writes from its form, as a group does (the library's fusable
  types have no hand-written kernel: each operation is declared once).  Such a group keeps
  the component's name, ports and, where it is the only one of its type, the type's name
  as its class; `plan` lists it as a generated kernel, not as a fusion.

Every GPU-to-GPU edge between components that ends up outside a group gets its reason in
system.unfused (shown by `plan`, `check` and --print-between-passes), and so does every
connection between two components with kernels that the placement put through the CPU.
A reason starts with its kind — "fusion off", "placed on the CPU", "fuse: false",
"opaque type", "read by several consumers", "cost model", "different groups" — then
says what, in the model's names.
"""

from __future__ import annotations

from dataclasses import replace

from ..ir import AdapterNode, ComponentNode, Edge, GroupNode, Port, System
from ..model import ComponentType, Endpoint, GpuDecl
from ..snippet import accessor_calls
from .base import Pass

# the generated kernel's settings: tile rows a work-group, 64 threads splitting them
# (measured on PoCL, as for VerticalMirror: long runs of pixels per work-item)
GROUP_GPU = GpuDecl((1, 2, 4, 8, 16, 32, 64, 128), (1,), (32, 8, 8, 1))
# on a GPU: a work-group of 128 threads along a row, 4 rows at a time, adjacent threads
# adjacent elements (backend/opencl/fused.py, schedule 'strided')
GROUP_GPU_STRIDED = GpuDecl((1, 2, 4, 8, 16, 32, 64, 128), (1,), (4, 128, 1, 1))


def group_gpu_decl(device) -> GpuDecl:
    """The generated kernel's settings for the device: fused.schedule() decides."""
    from ..backend.opencl.fused import schedule

    return GROUP_GPU if schedule(device) == "runs" else GROUP_GPU_STRIDED


class Fuse(Pass):
    name = "fuse"

    def apply(self, system, rep):
        gpu_edges = [e for e in system.edges if _gpu_component(system, e.source.component)
                     and _gpu_component(system, e.target.component)]
        _through_the_cpu(system)
        if system.fusion == "off" or not gpu_edges:
            for e in gpu_edges:
                system.unfused[str(e)] = f"fusion off ({system.fusion_reason})"
            _generate_singles(system)
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
                f"different groups: {a} and {b} each end a group of their own"
            system.unfused[str(e)] = why
        for names in groups:
            if len(names) > 1:
                text = estimate_text(system, set(names))
                make_group(system, names).estimate = text
        _generate_singles(system)
        return system


def _generate_singles(system: System) -> None:
    """Every GPU component of a fusable type left outside a group becomes a group of one:
    its kernel is generated from its form (backend/opencl/fused.py), like a group's."""
    singles = [n for n in system.order if isinstance(system.nodes[n], ComponentNode)
               and system.nodes[n].on_gpu and system.nodes[n].type.fusable is not None]
    for name in singles:
        make_group(system, [name])


def _through_the_cpu(system: System) -> None:
    """Connections between two components with kernels, one of them placed on the CPU
    (a flexible type): the data goes through the CPU, no fusion there."""
    for conn in system.model.connections:
        a, b = (system.nodes.get(end.component) for end in (conn.source, conn.target))
        if not (isinstance(a, ComponentNode) and isinstance(b, ComponentNode)
                and a.type.gpu_aware and b.type.gpu_aware) or (a.on_gpu and b.on_gpu):
            continue
        on_cpu = a if not a.on_gpu else b
        by = f" ({on_cpu.placed_by})" if on_cpu.placed_by else ""
        system.unfused[f"{conn.source} -> {conn.target}"] = (
            f"placed on the CPU: {on_cpu.name} runs its CPU function{by}")


def _gpu_component(system: System, name: str) -> bool:
    node = system.nodes.get(name)
    return isinstance(node, ComponentNode) and node.on_gpu


def _opaque(system: System, name: str) -> str:
    """Why a GPU component can never be in a group ('' when it can)."""
    node = system.nodes[name]
    if not isinstance(node, ComponentNode) or not node.on_gpu:
        return f"placed on the CPU: {name} does not run on the GPU"
    if node.type.fusable is None:
        return (f"opaque type: {name} ({node.type.name}) has no fusable form, its own kernel "
                "runs")
    if not node.fuse:
        return f"fuse: false: the model keeps {name} out of every group"
    return ""


def _why_not(system: System, src: Endpoint, members: set[str], consumer: str) -> str:
    """Why the producer src cannot join the group of members ('' when it can)."""
    why = _opaque(system, src.component)
    if why:
        return why
    outside = [_reader(system, r) for r in system.readers(src) if r.component not in members]
    if outside:
        return (f"read by several consumers: {src} is also read by {', '.join(outside)}, "
                "outside the group; its output must be materialized")
    grown = members | {src.component}
    fused, _ = estimate(system, grown)
    now, _ = estimate(system, members)
    alone = apart_cost(system, src.component) + LAUNCH
    if fused >= now + alone:
        r = evaluations(system, grown)[src.component]
        return (f"cost model: with {src.component} the group's kernel costs an estimated "
                f"{_ops(fused)} a frame, against {_ops(now + alone)} with {src.component} "
                f"apart (it would run {r} times per output element of the group)")
    return ""


def _ops(n: int) -> str:
    return f"{n:,} element operations"


def _reader(system: System, end: Endpoint) -> str:
    """A reader as a user knows it: the CPU reads through an adapter."""
    node = system.nodes[end.component]
    if isinstance(node, AdapterNode):
        ends = ", ".join(map(str, system.readers(Endpoint(node.name, "output"))))
        return f"the CPU ({ends}, through {node.name})"
    return str(end)


# The cost model, in element operations a frame (an element read, computed or stored
# costs about one; measured figures in docs/fusion.md).  A buffer between two kernels is
# written and read back from memory (MATERIALIZE a element more than a read of a value
# still in registers), and a kernel launch costs LAUNCH.
MATERIALIZE = 2
LAUNCH = 20_000


def reads(node, port: str) -> int:
    """Elements of input port one evaluation of node's snippet reads: its accessor calls
    on the port, at least the window for a stencil (whose reads may be in a loop)."""
    decl = node.type.fusable
    calls = len(accessor_calls(decl.tree, [port])[port])
    return max(calls, decl.taps(node.params) if decl.form == "stencil" else 1)


def arithmetic(node) -> int:
    """Operations one evaluation computes besides its reads: none for an index map (its
    work is the read), one a read for stencils and pointwise snippets."""
    if node.type.fusable.form == "index_map":
        return 0
    return max(1, sum(reads(node, p) for p in node.inputs))


def elements(node) -> int:
    (port,) = node.outputs.values()
    return port.data.height * port.data.width * port.channels if port.data else 1


def apart_cost(system: System, name: str) -> int:
    """A member run as its own kernel: its elements computed, its reads loaded, its output
    stored and read back from memory by its consumer."""
    node = system.nodes[name]
    per = arithmetic(node) + sum(reads(node, p) for p in node.inputs) + 1 + MATERIALIZE
    return elements(node) * per


def evaluations(system: System, members: set[str]) -> dict[str, int]:
    """How many times each member is evaluated per output element of the group: a read
    of a member inside the group is an evaluation of it (Inductor's recompute count)."""
    order = [n for n in system.order if n in members]
    count = dict.fromkeys(order, 0)
    count[order[-1]] = 1
    for m in reversed(order):
        node = system.nodes[m]
        for pname in node.inputs:
            src = system.writer(Endpoint(m, pname))
            if src is not None and src.component in members:
                count[src.component] += count[m] * reads(node, pname)
    return count


def estimate(system: System, members: set[str]) -> tuple[int, int]:
    """(the group as one kernel, its members apart), element operations a frame.  Fused,
    every member runs as often as evaluations() says, loading only the group's inputs;
    apart, each member runs once an element, and every buffer between them is stored,
    read back, and costs a launch."""
    count = evaluations(system, members)
    order = [n for n in system.order if n in members]
    root = system.nodes[order[-1]]
    per = 1  # the group's output stored
    for m in order:
        node = system.nodes[m]
        loads = sum(reads(node, p) for p in node.inputs
                    if (w := system.writer(Endpoint(m, p))) is None or w.component not in members)
        per += count[m] * (arithmetic(node) + loads)
    fused = elements(root) * per + LAUNCH
    apart = sum(apart_cost(system, m) for m in order) - elements(root) * MATERIALIZE \
        + LAUNCH * len(order)
    return fused, apart


def estimate_text(system: System, members: set[str]) -> str:
    fused, apart = estimate(system, members)
    return (f"estimate: {_ops(fused)} a frame as one kernel, {_ops(apart)} apart "
            f"({apart / fused:.1f}x)")


def group_name(system: System, names: list[str]) -> str:
    """Named after its members, never like a component of the model (one fused earlier
    has left the nodes, but users know it by that name: stats, profiles, plan)."""
    wanted = "_".join(names) if len(names) <= 3 else f"{names[0]}_to_{names[-1]}"
    name = system.unique_name(wanted)
    while name in system.model.components:
        name = system.unique_name(name + "_")
    return name


def make_group(system: System, names: list[str]) -> GroupNode:
    """Replace member components by one GroupNode, rewiring every edge.  A group of one
    is the component itself: its name and its ports' names."""
    members = [system.nodes[n] for n in names]
    root = members[-1]
    single = len(names) == 1
    name = names[0] if single else group_name(system, names)
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
            port_name = e.target.port if single else f"{e.target.component}_{e.target.port}"
            while port_name in inputs:  # member a_b's port c and member a's port b_c
                port_name += "_"
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
    if single:  # the component's place among the nodes, under its name
        system.nodes = {n: group if n == name else node for n, node in system.nodes.items()}
    else:
        for n in names:
            del system.nodes[n]
        system.add_node(group)
    system.edges = edges
    stage = system.stages[root.name]
    system.order = [n for n in system.order if n not in inside or n == root.name]
    system.order[system.order.index(root.name)] = name
    for n in names:
        system.stages.pop(n, None)
    system.stages[name] = stage
    return group


def entry_name(name: str, members: list[ComponentNode]) -> str:
    """The generated kernel's entry point: the group's (or lone component's) name, unless
    OpenCL C has a function or word of that name (a component called 'trunc') or a
    member's snippet uses it (a ThresholdGray called 'thresh', its parameter's name)."""
    from ..snippet import is_builtin
    from ..snippet.check import FORBIDDEN

    used = {n for m in members for n in (*m.type.fusable.names, *m.type.params,
                                         *m.inputs, *m.outputs)}
    taken = is_builtin(name) or name in FORBIDDEN or name in used
    return f"{name}_kernel" if taken else name


def group_type(system: System, name: str, members: list[ComponentNode],
               inputs: dict[str, Port]) -> ComponentType:
    """The stand-in type of a group: its class name in generated code, its ports, and the
    GPU preferences of the generated kernel (backend/opencl/fused.py: work-groups cover
    tile whole rows of the output, as the VerticalMirror kernel, and any tile)."""
    root = members[-1]
    rt = root.type
    camel = "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)
    taken = set(system.model.types) | set(system.nodes)
    if len(members) == 1:
        # the type's name where no other component of the type runs a generated kernel
        # (the type itself has no class in the program: its components run this kernel)
        others = [n for n in system.order if n != root.name
                  and isinstance(system.nodes.get(n), ComponentNode)
                  and system.nodes[n].on_gpu and system.nodes[n].type is rt]
        others += [g.name for g in system.kernel_groups if len(g.members) == 1
                   and g.root.type is rt]
        cls = rt.name if not others else rt.name + camel
        taken -= {rt.name}
        description = (f"Kernel of {root.name} ({rt.name}), generated from its "
                       f"{rt.fusable.form} form.")
    else:
        cls = "Fused" + camel
        description = ("Fuses " + ", ".join(f"{m.name} ({m.type.name})" for m in members)
                       + " into one kernel.")
    while cls in taken:
        cls += "_"
    from ..model import PortDecl

    ports = {p: PortDecl(p, "in", "gpu", port.dtype, port.channels)
             for p, port in inputs.items()}
    (out_name, out_decl), = rt.outputs.items()
    out = root.outputs[out_name]  # resolved: a generic type's declaration is not
    out_decl = out_decl.fixed(out.dtype, out.channels)
    return ComponentType(
        name=cls, kind="gpu-aware",
        description=description,
        params={}, inputs=ports, outputs={out_name: out_decl}, requires=[],
        decl_file=rt.decl_file, origin="group", pos=root.pos, kernel_function=entry_name(name, members),
        grid=out_name, cover="rows", gpu=group_gpu_decl(system.device))
