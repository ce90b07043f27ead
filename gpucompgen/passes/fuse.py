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
- Cost model (estimate(), in seconds a frame, constants per device class in
  FUSION_COSTS): inside a group a member is evaluated once for every read of its output:
  a stencil reading a producer at 9 taps evaluates it 9 times per output element, a gray
  conversion reading 3 channels evaluates its producer 3 times.  Reads are counted per
  snippet (its accessor calls, at least a stencil's window), so an index map reading its
  input 40 times costs 40 evaluations of its producer.  Fused, each member costs its
  evaluations times its arithmetic and its loads of group inputs, and a stencil's taps
  on a producer inside the group are calls, not vectorized loads; apart, each member is
  its own kernel: one evaluation an element, its output stored and loaded back, a
  launch.  A producer joins only where the estimate with it is lower than without it,
  and the group grown that way is checked whole, so no group chosen is estimated slower
  than its members apart; `plan` shows the estimate of every group and the figures of
  every refusal.  Where in doubt (a tie) the producer stays apart.
- Measured: `gpucompgen tune` times the groups chosen against their members apart and
  writes them in the profile (passes/place.py load_profile); a group measured no faster
  is refused, whatever the estimate says.
- The choice is choose_groups(): this pass calls it with each component where it was
  placed; the place pass calls it first, with the sides it weighs, to price a chain of
  components on the device as the groups they would become (passes/place.py
  weigh_chains), so both see the same groups, refusals and measurements.
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
"opaque type", "read by several consumers", "cost model", "measured", "different
groups" — then
says what, in the model's names.
"""

from __future__ import annotations

from dataclasses import replace

from ..ir import AdapterNode, ComponentNode, Edge, GroupNode, Port, System
from ..model import ComponentType, Endpoint, GpuDecl
from ..snippet import accessor_calls, operations
from .base import Pass

# the generated kernel's settings: tile rows a work-group, 64 threads splitting them
# (measured on PoCL, as for VerticalMirror: long runs of pixels per work-item)
GROUP_GPU = GpuDecl((1, 2, 4, 8, 16, 32, 64, 128), (1,), (32, 8, 8, 1))
# on a GPU: a work-group of 128 threads along a row, 4 rows at a time, adjacent threads
# adjacent elements (kernelgen/fused.py, schedule 'strided')
GROUP_GPU_STRIDED = GpuDecl((1, 2, 4, 8, 16, 32, 64, 128), (1,), (4, 128, 1, 1))


def group_gpu_decl(device) -> GpuDecl:
    """The generated kernel's settings for the device: fused.schedule() decides."""
    from ..kernelgen.fused import schedule

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
        load_measured(system, rep)
        groups, reasons = choose_groups(system)
        assigned = {m: names[-1] for names in groups for m in names}
        for e in gpu_edges:
            a, b = e.source.component, e.target.component
            if assigned.get(a) is not None and assigned.get(a) == assigned.get(b):
                continue
            why = _opaque(system, b) or _opaque(system, a) or reasons.get(str(e)) or \
                f"different groups: {a} and {b} each end a group of their own"
            system.unfused[str(e)] = why
        for names in groups:
            if len(names) > 1:
                text, figures = estimate_text(system, set(names)), estimate(system, set(names))
                group = make_group(system, names)
                group.estimate, group.estimate_s = text, figures
        _generate_singles(system)
        return system


def choose_groups(system: System, on_gpu=None) -> tuple[list[list[str]], dict[str, str]]:
    """The groups the fuse pass makes (each a list of members in run order; a component
    alone is a group of one) and why each edge inside no group was not fused.

    on_gpu(name) says whether a component runs on the GPU; by default where it is placed.
    The place pass asks with the sides it weighs (passes/place.py), before they are
    taken, so that it prices a chain on the device as the groups it would become."""
    if on_gpu is None:
        def on_gpu(name):
            return _gpu_component(system, name)
    at = {n: i for i, n in enumerate(system.order)}
    assigned: dict[str, str] = {}  # member -> the root of its group
    reasons: dict[str, str] = {}
    groups: list[list[str]] = []
    for root in reversed(system.order):
        if root in assigned or _opaque(system, root, on_gpu):
            continue
        members = {root}
        changed = True
        while changed:
            changed = False
            for m in sorted(members, key=at.get, reverse=True):
                for pname in system.nodes[m].inputs:
                    src = system.writer(Endpoint(m, pname))
                    if src is None or src.component in members or \
                            not on_gpu(src.component):
                        continue
                    why = _why_not(system, src, members, m, on_gpu)
                    if why:
                        reasons.setdefault(f"{src} -> {m}.{pname}", why)
                        continue
                    members.add(src.component)
                    changed = True
        why = _group_loses(system, members)
        if why:  # grown one producer at a time, it may still lose as a whole
            for e in system.edges:
                if e.source.component in members and e.target.component in members:
                    reasons[str(e)] = why
            members = {root}
        for m in members:
            assigned[m] = root
        groups.append(sorted(members, key=at.get))
    return groups, reasons


def _generate_singles(system: System) -> None:
    """Every GPU component of a fusable type left outside a group becomes a group of one:
    its kernel is generated from its form (kernelgen/fused.py), like a group's."""
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


def _opaque(system: System, name: str, on_gpu=None) -> str:
    """Why a GPU component can never be in a group ('' when it can); on_gpu as for
    choose_groups."""
    node = system.nodes[name]
    gpu = on_gpu(name) if on_gpu is not None else _gpu_component(system, name)
    if not isinstance(node, ComponentNode) or not gpu:
        return f"placed on the CPU: {name} does not run on the GPU"
    if node.type.fusable is None:
        return (f"opaque type: {name} ({node.type.name}) has no fusable form, its own kernel "
                "runs")
    if not node.fuse:
        return f"fuse: false: the model keeps {name} out of every group"
    return ""


def _why_not(system: System, src: Endpoint, members: set[str], consumer: str,
             on_gpu=None) -> str:
    """Why the producer src cannot join the group of members ('' when it can)."""
    why = _opaque(system, src.component, on_gpu)
    if why:
        return why
    outside = [_reader(system, r) for r in system.readers(src) if r.component not in members]
    if outside:
        return (f"read by several consumers: {src} is also read by {', '.join(outside)}, "
                "outside the group; its output must be materialized")
    grown = members | {src.component}
    measured = _measured(system, grown)
    if measured is not None and measured[0] >= measured[1]:
        return (f"measured: with {src.component} the group's kernel took "
                f"{_ms(measured[0])} a frame, its members apart {_ms(measured[1])} "
                "(the profile 'gpucompgen tune' wrote)")
    fused, _ = estimate(system, grown)
    now, _ = estimate(system, members)
    alone = kernel_s(system, [src.component])
    if fused >= now + alone:
        r = evaluations(system, grown)[src.component]
        return (f"cost model: with {src.component} the group's kernel takes an estimated "
                f"{_ms(fused)} a frame, against {_ms(now + alone)} with {src.component} "
                f"apart (it would run {r} times per output element of the group; "
                f"{_constants(system)})")
    return ""


def _group_loses(system: System, members: set[str]) -> str:
    """Why the group of members as a whole is no faster than its members apart: measured
    by tune, or estimated ('' when it wins, or is one component)."""
    if len(members) < 2:
        return ""
    names = ", ".join(n for n in system.order if n in members)
    measured = _measured(system, members)
    if measured is not None and measured[0] >= measured[1]:
        return (f"measured: the group of {names} took {_ms(measured[0])} a frame, its "
                f"members apart {_ms(measured[1])} (the profile 'gpucompgen tune' wrote)")
    fused, apart = estimate(system, members)
    if fused >= apart:
        return (f"cost model: the group of {names} takes an estimated {_ms(fused)} a frame, "
                f"its members apart {_ms(apart)} ({_constants(system)})")
    return ""


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3f} ms"


def _constants(system: System) -> str:
    from .place import a_device

    return f"constants for {a_device(device_kind(system) or 'cpu')}"


def _reader(system: System, end: Endpoint) -> str:
    """A reader as a user knows it: the CPU reads through an adapter."""
    node = system.nodes[end.component]
    if isinstance(node, AdapterNode):
        ends = ", ".join(map(str, system.readers(Endpoint(node.name, "output"))))
        return f"the CPU ({ends}, through {node.name})"
    return str(end)


# The cost model's constants, one row per device class (DeviceFacts.kind; the device the
# build plans for: platform.device, --device), in seconds: an element operation computed
# (a snippet's arithmetic), an element loaded from a buffer in memory, an element stored,
# a kernel's launch (enqueue to done), and a stencil's tap that calls a producer inside
# the group (PoCL vectorizes a stencil's row of loads, not a row of calls).  A kernel's
# time is
#     launch_s + ops * op_s + loads * load_s + stores * store_s + taps * tap_s
# over what it does for a frame (kernel_features()).  "cpu" is fitted to the generated
# kernels on PoCL (2 cores): each kernel of benchmarks/pipelines.py's pipelines alone and
# each group the fuse pass chose, device time, by `python benchmarks/fusion_costs.py`
# (it prints the row, and for every group its measurement beside the estimate;
# docs/fusion.md has the figures), refitted after the kernels took their members'
# parameters as build constants.  The fit cannot tell loads from operations (it put
# 1.4e-11 on op_s, 0 on load_s when a snippet's arithmetic was one operation a read; with
# pointwise arithmetic counted from the snippet's tree (arithmetic()) it puts 0 on both
# and the launch and store carry every kernel, agreeing with fewer measured groups: 22 of
# 44 against 33 of 44 for the row below); they are split evenly, deciding every measured
# group alike, so that an index map's reads, which are loads only, still cost (40 reads
# of 40 reads... is refused).  tap_s is set from the
# groups of a stencil behind a producer that computes (0.08 to 0.15 ns a tap measured:
# InRange under an erosion, a gray conversion under a blur); every value from 0 to 0.5 ns
# decides the measured groups alike.  "error" is the fit's median error a kernel (65%:
# fusion_costs.py prints it): this pass compares fused with apart under the same constants
# and does not use it; placement, which sets a group's kernel against the CPU forms, takes
# the estimated fused time at that much more.  The GPU rows are not fitted on a device yet:
# memory-bound element costs at an integrated GPU's (~100 GB/s) and a discrete GPU's
# (~1 TB/s) bandwidth, and their launch costs.  "" (the 'portable' profile)
# is scheduled as a CPU device is (kernelgen/fused.py), so it takes the CPU row.
# To recalibrate: `python benchmarks/fusion_costs.py` on the device (PYOPENCL_CTX), paste
# the row it prints under the device's class.
FEATURES = {"launches": "launch_s", "ops": "op_s", "loads": "load_s", "stores": "store_s",
            "taps": "tap_s"}  # kernel_features() -> its constant
FUSION_COSTS: dict[str, dict[str, float]] = {
    "cpu": {"launch_s": 20e-6, "op_s": 0.7e-11, "load_s": 0.7e-11, "store_s": 4.3e-11,
            "tap_s": 1e-10, "error": 0.65},
    "integrated-gpu": {"launch_s": 20e-6, "op_s": 2e-12, "load_s": 1e-11, "store_s": 1e-11,
                       "tap_s": 4e-12, "error": 0.65},
    "discrete-gpu": {"launch_s": 10e-6, "op_s": 2e-13, "load_s": 1e-12, "store_s": 1e-12,
                     "tap_s": 4e-13, "error": 0.65},
}


def device_kind(system: System) -> str:
    return system.device.kind if system.device is not None else ""


def fusion_costs(system: System) -> dict[str, float]:
    return FUSION_COSTS.get(device_kind(system)) or FUSION_COSTS["cpu"]


def reads(node, port: str) -> int:
    """Elements of input port one evaluation of node's snippet reads: its accessor calls
    on the port, at least the window for a stencil (whose reads may be in a loop), and
    for a stencil of one input that states its reads, those (a window of windows:
    MorphologyEx's 5x5 opening reads 626 elements, not the 81 of its window).  Not the
    count of calls in unrolled loops the kernel generator bounds itself by: it adds up
    every branch of the snippet, an upper bound, not a cost."""
    decl = node.type.fusable
    calls = len(accessor_calls(decl.tree, [port])[port])
    if decl.form != "stencil":
        return max(calls, 1)
    stated = staged_reads(decl, node.params) if (decl.reads is not None or decl.stages) \
        and len(node.inputs) == 1 else 0
    return max(calls, decl.taps(node.params), stated)


def staged_reads(decl, params) -> int:
    """Input elements the generated kernel reads an output element of a stencil with
    stages: each stage the generator stages (kernelgen/fused.py staged_pieces: read
    more than MIN_STAGED_READS times through, reading more than one element) computed
    once an element, plus the value's own reads of it; a stage inline, at every read of
    it.  (A 5x5 opening: 25 + 25, not 25 x 25; its halo, about a tenth more, not
    counted.)"""
    from ..kernelgen.fused import MIN_STAGED_READS

    own = decl.reads_of(params)
    if not decl.stages:
        return own
    inner = {n: s.decl.total_reads_of(params) for n, s in decl.stages.items()}
    staged = {n for n, r in inner.items() if r > 1 and own * r > MIN_STAGED_READS}
    inline = max((r for n, r in inner.items() if n not in staged), default=1)
    return own * inline + sum(inner[n] for n in staged)


def arithmetic(node) -> int:
    """Operations one evaluation computes besides its reads: none for an index map (its
    work is the read); a pointwise snippet's operations on the element's values (those of
    parameters alone are computed once: snippet.operations), at least one; one a read for
    a stencil (its loops walk a window: priced by its reads)."""
    decl = node.type.fusable
    if decl.form == "index_map":
        return 0
    if decl.form == "pointwise":
        return max(1, operations(decl.tree, decl.names))
    return max(1, sum(reads(node, p) for p in node.inputs))


def elements(node) -> int:
    port = _output(node)
    return port.data.height * port.data.width * port.channels if port.data else 1


def _output(node) -> Port:
    """A fusable member's one output port."""
    (port,) = node.outputs.values()
    return port


def kernel_features(system: System, members: list[str] | set[str]) -> dict[str, int]:
    """What the kernel of members (one, or a group) does for a frame: element operations
    computed, elements loaded from memory (the group's inputs, once a read of each
    evaluation), elements stored (its output), launches (one), and taps: a stencil's
    reads of a producer inside the group that computes, each a call of that producer's
    function where the stencil alone would load a row it can vectorize."""
    count = evaluations(system, set(members))
    order = [n for n in system.order if n in members]
    root = system.nodes[order[-1]]
    ops = loads = taps = 0
    for m in order:
        node = system.nodes[m]
        outside = sum(reads(node, p) for p in node.inputs
                      if (w := system.writer(Endpoint(m, p))) is None or
                      w.component not in members)
        ops += count[m] * arithmetic(node)
        loads += count[m] * outside
        if node.type.fusable.form == "stencil":
            taps += count[m] * sum(reads(node, p) for p in node.inputs
                                   if (w := system.writer(Endpoint(m, p))) is not None
                                   and w.component in members
                                   and _computes(system, w.component, members))
    n = elements(root)
    return {"ops": n * ops, "loads": n * loads, "stores": n, "launches": 1, "taps": n * taps}


def _computes(system: System, name: str, members) -> bool:
    """Whether evaluating member name computes anything (arithmetic of its own or of a
    member it reads): an index map over the group's inputs is only a load at another
    address, which stays a load in a stencil's row."""
    node = system.nodes[name]
    if arithmetic(node):
        return True
    return any(w is not None and w.component in members and
               _computes(system, w.component, members)
               for w in (system.writer(Endpoint(name, p)) for p in node.inputs))


def kernel_s(system: System, members: list[str] | set[str]) -> float:
    """The estimated time of the kernel of members, a frame (FUSION_COSTS)."""
    f, k = kernel_features(system, members), fusion_costs(system)
    return sum(f[feature] * k[constant] for feature, constant in FEATURES.items())


def evaluations(system: System, members: set[str]) -> dict[str, int]:
    """How many times each member is evaluated per output element of the group: a read
    of a member inside the group is an evaluation of it (Inductor's recompute count),
    except that a member read only through pointwise members is computed once a channel
    of the root's pixel however many of them read it."""
    order = [n for n in system.order if n in members]
    count = dict.fromkeys(order, 0)
    count[order[-1]] = 1
    at_pixel = {order[-1]: True}  # evaluated only at the root element's pixel
    for m in reversed(order):
        node = system.nodes[m]
        if at_pixel.get(m, True):
            # pointwise all the way to the root: evaluated at one pixel, each of its
            # channels at most once (the kernel inlines the members, and the compiler
            # computes a call with the same arguments once: a conversion read by two
            # consumers is not computed twice)
            count[m] = min(count[m], _output(node).channels)
        pointwise = node.type.fusable.form == "pointwise" and at_pixel.get(m, True)
        for pname in node.inputs:
            src = system.writer(Endpoint(m, pname))
            if src is not None and src.component in members:
                count[src.component] += count[m] * reads(node, pname)
                at_pixel[src.component] = at_pixel.get(src.component, True) and pointwise
    return count


def estimate(system: System, members: set[str]) -> tuple[float, float]:
    """(the group as one kernel, its members apart), seconds a frame.  Fused, every member
    runs as often as evaluations() says, loading only the group's inputs; apart, each
    member is its own kernel: it runs once an element, stores its output, its consumer
    loads it back, and each costs a launch."""
    return kernel_s(system, members), sum(kernel_s(system, [m]) for m in members)


def _measured(system: System, members: set[str]) -> tuple[float, float] | None:
    """(fused_s, apart_s) that `gpucompgen tune` measured for exactly these members at
    these sizes (the profile's groups), else None."""
    return (system.measured_groups or {}).get(frozenset(members))


def load_measured(system: System, rep) -> None:
    """system.measured_groups from the profile's groups whose members are components of
    the system at the sizes measured (unless tune set them itself, measuring)."""
    from .place import load_profile, record_profile

    if system.measured_groups is not None:
        return
    profile = load_profile(system, rep, required=False)
    groups = system.measured_groups = {}
    for key, (fused, apart, sizes) in (profile or {}).get("groups", {}).items():
        if all(isinstance(system.nodes.get(m), ComponentNode) and system.nodes[m].on_gpu
               for m in key) and sizes in (None, group_sizes_text(system, key)):
            groups[key] = (fused, apart)
    if groups:  # the build used the profile: its output records it
        record_profile(system, profile)


def group_sizes_text(system: System, members) -> str:
    """A group's sizes as a profile records them: its inputs from outside, then its
    output ('360x640x3 -> 360x640x1'), as place.sizes_text writes a component's."""
    order = [n for n in system.order if n in members]
    ins = []
    for m in order:
        node = system.nodes[m]
        for p, port in node.inputs.items():
            w = system.writer(Endpoint(m, p))
            if (w is None or w.component not in members) and port.data is not None:
                ins.append(f"{port.data.height}x{port.data.width}x{port.data.channels}")
    (out,) = system.nodes[order[-1]].outputs.values()
    tail = f"{out.data.height}x{out.data.width}x{out.data.channels}" if out.data else ""
    return f"{', '.join(ins)} -> {tail}"


def estimate_text(system: System, members: set[str]) -> str:
    fused, apart = estimate(system, members)
    text = (f"estimate: {_ms(fused)} a frame as one kernel, {_ms(apart)} apart "
            f"({apart / fused:.1f}x; {_constants(system)})")
    measured = _measured(system, members)
    if measured is not None:
        text += (f"; measured: {_ms(measured[0])} as one kernel, {_ms(measured[1])} apart "
                 "(profile)")
    return text


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
    GPU preferences of the generated kernel (kernelgen/fused.py: work-groups cover
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
