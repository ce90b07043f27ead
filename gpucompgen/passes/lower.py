"""lower: the last pass turns the System into a ProgramPlan of plain records.

Every decision becomes concrete here: which part allocates which buffer of how many
bytes, each launch's arguments (in the calling convention's order, scalars with their
values), global and local sizes, each transfer, the queue variables and waits, the names
of programs and of files in the lib folder.  Backends print the plan; nothing decides
after this pass.
"""

from __future__ import annotations

import ast
import copy
import math
import re
from dataclasses import dataclass, field, replace

from ..convention import group_constants, group_parameters, kernel_parameters
from ..ir import AdapterNode, ComponentNode, GroupNode, System
from ..kernelgen.fused import group_kernel_body
from ..model import DTYPES, ComponentType, Endpoint
from ..plan import (
    Argument,
    Buffer,
    FlightStage,
    GroupPlan,
    KernelClass,
    Launch,
    LibSource,
    Part,
    Program,
    ProgramPlan,
    Step,
    Transfer,
    UserClass,
)
from .allocate_gpu import resident_threads
from .base import Pass
from .program_facts import with_program_facts


class Lower(Pass):
    name = "lower"

    def apply(self, system, rep):
        system.plan = with_program_facts(system, lower(system))
        check_device_memory(system, rep)
        return system


def check_device_memory(system: System, rep) -> None:
    """Every device buffer is allocated at start: all of them must fit the device's memory
    (each buffer's own limit, max_mem_alloc_size, is checked when sizes propagate)."""
    plan, device = system.plan, system.device
    if plan.device_bytes <= device.global_mem_size:
        return
    largest = sorted(plan.device_buffers(), key=lambda b: (-b.nbytes, b.what))[:3]
    shown = ", ".join(f"{b.what} {b.nbytes:,}" for b in largest)
    where = system.model.device_positions.get("global_mem_size", (None, None))[1] \
        or system.model.device_pos
    rep.error(where, f"the system needs {plan.device_bytes:,} bytes of device memory at peak "
              f"(largest buffers: {shown}), more than device '{device.name}' has "
              f"({device.global_mem_size:,} bytes)",
              "use smaller frames, zero-copy adapters on a device with unified memory, or a "
              "device (platform.device) with more memory")


def lib_dir_name(system_name: str) -> str:
    return f"{system_name}_lib"


def lib_files(system: System) -> dict[str, str]:
    """A unique file name in the lib folder for every kernel and user Python file used.

    Kernels are named after their type; a user's Python file keeps its name unless another
    file of the same name (from another folder) is used too: then it gets a numbered suffix,
    so neither replaces the other.  One entry per file, however many types use it.
    """
    names: dict[str, str] = {}  # source path -> lib file name
    taken: set[str] = set()
    for t in used_types(system):
        keys = []
        if t in gpu_used_types(system):
            keys.append((kernel_key(t), t.kernel_file.name))
        if t.flexible and t.origin == "user" and t in cpu_used_types(system):
            keys.append((cpu_lib_key(t), t.cpu_file.name))
        if not t.gpu_aware and t.origin == "user":
            keys.append((str(t.python_file.resolve()), t.python_file.name))
        for key, wanted in keys:
            _name_lib_file(names, taken, key, wanted)
    for t in checked_kernel_types(system):
        _name_lib_file(names, taken, kernel_key(t), t.kernel_file.name)
    for g in system.kernel_groups:  # a group of one: the component's kernel, from its form
        wanted = f"{g.name}.cl" if len(g.members) == 1 else f"group_{g.name}.cl"
        _name_lib_file(names, taken, lib_key(g.type), wanted)
    return names


def _name_lib_file(names: dict[str, str], taken: set[str], key: str, wanted: str) -> None:
    """names[key]: wanted, or wanted with a numbered suffix when another file took it."""
    if key in names:
        return
    name, stem, suffix, i = wanted, wanted.rsplit(".", 1)[0], wanted.rsplit(".", 1)[1], 2
    while name.lower() in taken:
        name, i = f"{stem}_{i}.{suffix}", i + 1
    taken.add(name.lower())
    names[key] = name


def kernel_key(t: ComponentType) -> str:
    """A kernel file in the lib folder: one per file, whatever number of types share it."""
    return f"kernel:{t.kernel_file.resolve()}"


def lib_key(t: ComponentType) -> str:
    if t.origin == "group":
        return f"group:{t.kernel_function}"
    return kernel_key(t) if t.gpu_aware else str(t.python_file.resolve())


def _type_key(t: ComponentType) -> tuple[str, str]:
    """A type in the program's tables: its kernel file and its name.  A user's fusable type
    run alone is a group of one that keeps the type's name, and its own kernel file is
    built only to check it: the two are different programs of one type name."""
    return lib_key(t), t.name


def cpu_lib_key(t: ComponentType) -> str:
    """A flexible type's CPU file in the lib folder (a user's; the library's is imported)."""
    return f"cpu:{t.cpu_file.resolve()}"


def used_types(system: System, side: str | None = None) -> list[ComponentType]:
    """The types of the system's components (those placed on side, when given)."""
    found: dict[str, ComponentType] = {}
    for node in system.nodes.values():
        if isinstance(node, ComponentNode) and side in (None, node.placement):
            found.setdefault(node.type.name, node.type)
    return [found[k] for k in sorted(found)]


def gpu_used_types(system: System) -> list[ComponentType]:
    """Types with a kernel that some component runs on the GPU."""
    return [t for t in used_types(system, "gpu") if t.gpu_aware]


def checked_kernel_types(system: System) -> list[ComponentType]:
    """The user's types with a kernel that no component launches: every component of the
    type runs the kernel generated from its fusable form (alone or fused into a group) or is
    placed on the CPU.

    The program still builds their kernel files at start-up, so that every kernel a model
    names is compiled on the device wherever it runs (a typo in a fused type's .cl file
    would otherwise pass until --fusion off).  The library's kernels are the test suite's
    to compile; they are left out.  A program with no part on the device (every flexible
    component on the CPU) opens no OpenCL context and builds none: it runs without one.
    """
    if not gpu_used_types(system) and not system.kernel_groups:
        return []
    launched = {kernel_key(t) for t in gpu_used_types(system) if t.kernel_file is not None}
    found: dict[str, ComponentType] = {}
    for inst in system.model.components.values():
        t = inst.type
        if t.gpu_aware and t.origin == "user" and t.kernel_file is not None \
                and kernel_key(t) not in launched:  # a fusable type may have no kernel
            found.setdefault(t.name, t)
    return [found[k] for k in sorted(found)]


def cpu_used_types(system: System) -> list[ComponentType]:
    """Flexible types that some component runs on the CPU (through its function)."""
    return [t for t in used_types(system, "cpu") if t.flexible]


def lib_sources(system: System, files: dict[str, str]) -> tuple[LibSource, ...]:
    """Every kernel and user Python file the lib folder holds, once each, with its checked
    text: per used type, its kernel (a GPU one), its CPU function file (a user's flexible
    type on the CPU), its class file (a user's standard type); then the kernels built only
    to check them; then each fused group's generated kernel (no text: the backend writes
    it)."""
    found: list[LibSource] = []
    written: set[str] = set()
    gpu, cpu, used = gpu_used_types(system), cpu_used_types(system), used_types(system)

    def add(key: str, kind: str, users: list[str], text: str, origin) -> None:
        name = files[key]
        if name not in written:  # a file several types share is copied once
            written.add(name)
            found.append(LibSource(name, kind, tuple(sorted(users)), text, str(origin)))

    for t in used:
        if t in gpu:
            add(kernel_key(t), "kernel", [u.name for u in gpu if kernel_key(u) == kernel_key(t)],
                t.kernel_text, t.kernel_file)
        if t.flexible and t.origin == "user" and t in cpu:
            add(cpu_lib_key(t), "cpu", [u.name for u in cpu if u.origin == "user"
                                        and cpu_lib_key(u) == cpu_lib_key(t)],
                t.cpu_text, t.cpu_file)
        if not t.gpu_aware and t.origin == "user":
            add(lib_key(t), "python", [u.name for u in used if not u.gpu_aware
                                       and u.origin == "user" and lib_key(u) == lib_key(t)],
                t.python_text, t.python_file)
    for t in checked_kernel_types(system):
        add(kernel_key(t), "checked_kernel", [t.name], t.kernel_text, t.kernel_file)
    for g in system.kernel_groups:  # the kernel generator writes their text
        found.append(LibSource(files[lib_key(g.type)], "group", (g.name,),
                               group_kernel_body(g, system.device)))
    return tuple(found)


def np_name(dtype: str) -> str:
    return DTYPES[dtype][0]


class _SelfParams(ast.NodeTransformer):
    """In a generated class, a parameter `p` in a size expression reads `self.p`."""

    def __init__(self, params):
        self.params = params

    def visit_Name(self, node):
        if node.id in self.params:
            return ast.Attribute(value=ast.Name("self", ast.Load()), attr=node.id, ctx=ast.Load())
        return node


def size_expr(tree: ast.Expression, ctype: ComponentType) -> str:
    body = _SelfParams(set(ctype.params)).visit(copy.deepcopy(tree.body))
    return ast.unparse(body)


def kernel_class(t: ComponentType, file: str, group: GroupNode | None = None) -> KernelClass:
    if group is not None:  # a group's output size was propagated at build time
        (out,) = group.outputs.values()
        return KernelClass(
            name=t.name, function=t.kernel_function, file=file, description=t.description,
            inputs=tuple((p, np_name(port.dtype)) for p, port in group.inputs.items()),
            outputs=((out.name, np_name(out.dtype)),),
            output_sizes=((str(out.data.height), str(out.data.width), out.data.channels),),
            grid=t.grid, rows=t.cover == "rows")
    return KernelClass(
        name=t.name, function=t.kernel_function, file=file, description=t.description,
        inputs=tuple((p, np_name(d.dtype)) for p, d in t.inputs.items()),
        outputs=tuple((p, np_name(d.dtype)) for p, d in t.outputs.items()),
        output_sizes=tuple((size_expr(d.height, t), size_expr(d.width, t), d.channels)
                           for d in t.outputs.values()),
        grid=t.grid, rows=t.cover == "rows")


def param_argument(node: ComponentNode, p) -> Argument:
    """A parameter's value as the kernel takes it: an argument of a hand kernel, a
    constant (build option) of a group's generated kernel (p.param 'member.param')."""
    group = isinstance(node, GroupNode)
    owner, pname = (node.member(p.param.split(".")[0]), p.param.split(".")[1]) \
        if group else (node, p.param)
    host = p.dtype
    value = owner.params[pname]
    value = float(value) if host == "float32" else int(value)
    return Argument(p.name, p.kind, host_type=host, value=value,
                    param=f"{owner.name}.{pname}")


def launch(system: System, node: ComponentNode, program: str) -> Launch:
    """The kernel launch of a GPU component: arguments in convention order, sizes decided."""
    s = system.settings[node.name]
    t = node.type
    args = []
    group = isinstance(node, GroupNode)
    for p in group_parameters(node) if group else kernel_parameters(t):
        if p.kind == "buffer":
            args.append(Argument(p.name, "buffer", port=p.port))
        elif p.role == "size":
            if group:
                member, port = p.port.split(".")
                data = node.member(member).port(port).data
            else:
                data = system.data(Endpoint(node.name, p.port))
            args.append(Argument(p.name, "scalar", port=p.port, host_type="int32",
                                 value=getattr(data, p.dim)))
        elif p.role == "param":
            args.append(param_argument(node, p))
        else:  # the tile
            args.append(Argument(p.name, "scalar", host_type="int32", value=s.tile))
    grid = system.data(Endpoint(node.name, t.grid))
    groups_y = math.ceil(grid.height / s.tile)
    groups_x = 1 if t.cover == "rows" else math.ceil(grid.width / s.tile)
    return Launch(node.name, t.kernel_function, tuple(args), s.tile,
                  (s.block_x, s.block_y, s.block_z),
                  (groups_x * s.block_x, groups_y * s.block_y, s.block_z), s.source,
                  resident_threads(system, node.name))


def _defines(group: GroupNode | None) -> tuple[Argument, ...]:
    """The build options of a group's generated kernel: its members' parameters."""
    if group is None:
        return ()
    return tuple(param_argument(group, p) for p in group_constants(group))


def lower(system: System) -> ProgramPlan:
    files = lib_files(system)
    types = used_types(system)
    gpu_types = gpu_used_types(system) + [g.type for g in system.kernel_groups]
    taken = set(system.nodes)
    functions = _function_vars(system, taken)
    sharing, programs = _program_vars(system, files, gpu_types, taken)
    queues, n_lanes = _queue_vars(system, gpu_types)
    n_sets = system.frames_in_flight
    sources = [n for n in system.order if isinstance(system.nodes[n], ComponentNode)
               and not system.nodes[n].inputs and not system.nodes[n].on_gpu]
    lo = _Lowering(system, queues, functions, programs, sources)
    for name in system.order:
        node = system.nodes[name]
        in_vars = tuple(f"{system.input_var(Endpoint(name, p))}_size" for p in node.inputs)
        outs = tuple((f"{system.output_vars[Endpoint(name, p)]}_size", p,
                      system.data(Endpoint(name, p)).size) for p in node.outputs)
        if isinstance(node, AdapterNode):
            _lower_adapter(lo, name, node, in_vars, outs)
        else:
            _lower_component(lo, name, node, in_vars, outs)
    steps = _stream_steps(lo)
    imports, user_classes = _imports(system, files, functions, types)
    users, why = _program_users(system, gpu_types)
    groups = {g.type.name: g for g in system.kernel_groups}
    groups_by_key = {_type_key(g.type): g for g in system.kernel_groups}
    return ProgramPlan(
        system=system.name, mode=system.mode, execution=system.execution,
        device_name=system.device.name, zero_copy=system.zero_copy,
        zero_copy_reason=system.zero_copy_reason, queues=queues if n_lanes or gpu_types else (),
        programs=tuple(Program(programs[_type_key(m[0])], files[lib_key(m[0])],
                               ", ".join(f"{users[_type_key(t)]} "
                                         f"({t.name}{why.get(_type_key(t), '')})"
                                         for t in m),
                               _defines(groups_by_key.get(_type_key(m[0]))))
                       for m in sharing.values()),
        imports=_grouped(imports), user_classes=tuple(user_classes),
        kernel_classes=tuple(kernel_class(t, files[lib_key(t)], groups.get(t.name))
                             for t in gpu_types),
        groups=tuple(GroupPlan(g.name, tuple((m.name, m.type.name, m.type.fusable.form)
                                             for m in g.members), files[lib_key(g.type)],
                               tuple((p, str(end)) for p, end in g.feeds.items()),
                               tuple((f"{m.name}.{p}", str(port.data), m is not g.root)
                                     for m in g.members for p, port in m.outputs.items()),
                               g.estimate)
                     for g in system.groups),
        generated=tuple((g.name, g.root.type.name, g.root.type.fusable.form,
                         files[lib_key(g.type)])
                        for g in system.kernel_groups if len(g.members) == 1),
        guarded=_guarded(system),
        unfused=tuple(system.unfused.items()), fusion=system.fusion,
        parts=tuple(lo.parts), buffers=tuple(lo.buffers), launches=tuple(lo.launches),
        transfers=tuple(lo.transfers), steps=tuple(steps),
        frame_end_waits=tuple(system.frame_end_waits),
        thread_budget=system.thread_budget, thread_budget_source=_budget_source(system),
        concurrent=tuple((g, sum(resident_threads(system, n) for n in g))
                         for g in system.concurrent),
        lib_files={v: k for k, v in files.items()},
        lib_dir=lib_dir_name(system.name), lib_sources=lib_sources(system, files),
        frames_in_flight=n_sets, stages=flight_stages(system, steps),
        flight_notes=tuple(system.flight_notes), buffer_sets=tuple(system.buffer_sets.items()),
        staging=system.staging, staging_reason=system.staging_reason,
        placement=tuple(system.placement.lines()) if system.placement else ())


def _function_vars(system: System, taken: set[str]) -> dict[str, str]:
    """The variable of each flexible type's CPU function (type name -> variable)."""
    functions: dict[str, str] = {}  # flexible type on the CPU -> its function's variable
    for t in cpu_used_types(system):
        var = f"{t.snake}_on_cpu"
        while var in taken:
            var += "_"
        functions[t.name] = var
        taken.add(var)
    return functions


def _program_vars(system: System, files: dict[str, str], gpu_types: list[ComponentType],
                  taken: set[str]) -> tuple[dict[str, list[ComponentType]],
                                            dict[tuple[str, str], str]]:
    """The types sharing each kernel file, and the program variable of each type."""
    # one OpenCL program per kernel file, however many of the types used share it
    # (color.cl, filter.cl, ...): the file is compiled once, and each component makes
    # its own kernel object from the program
    sharing: dict[str, list[ComponentType]] = {}
    for t in gpu_types + checked_kernel_types(system):
        sharing.setdefault(lib_key(t), []).append(t)
    programs: dict[tuple[str, str], str] = {}  # _type_key -> its program's variable
    for members in sharing.values():
        stem = files[lib_key(members[0])].rsplit(".", 1)[0]
        base = members[0].snake if len(members) == 1 else re.sub(r"\W", "_", stem).lower()
        var = f"{base}_program"
        while var in taken or not var.isidentifier():
            var = f"_{var}" if not var.isidentifier() else var + "_"
        for t in members:
            programs[_type_key(t)] = var
        taken.add(var)
    return sharing, programs


def _queue_vars(system: System, gpu_types: list[ComponentType]) -> tuple[tuple[str, ...], int]:
    """The queue variable of each lane, and the number of lanes."""
    n_lanes = max(system.lanes.values(), default=0) + 1 if system.lanes else 0
    queues = ("queue",) if n_lanes == 1 else tuple(f"queue{i}" for i in range(n_lanes))
    if system.lanes or gpu_types:
        queues = queues or ("queue",)
    return queues, n_lanes


@dataclass
class _Lowering:
    """What lower() decided before walking the nodes, and the records it collects."""

    system: System
    queues: tuple[str, ...]
    functions: dict[str, str]
    programs: dict[tuple[str, str], str]
    sources: list[str]
    parts: list[Part] = field(default_factory=list)
    buffers: list[Buffer] = field(default_factory=list)
    launches: list[Launch] = field(default_factory=list)
    transfers: list[Transfer] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)
    pending_checks: list[Step] = field(default_factory=list)
    head: list[Step] = field(default_factory=list)  # the sources' steps

    def queue_of(self, name: str) -> str:
        return self.queues[self.system.lanes.get(name, 0)]

    def sets(self, name: str) -> int:
        return self.system.frames_in_flight if name in self.system.buffer_sets else 1

    def sets_why(self, name: str) -> str:  # stage-frames: why a part's buffers have their sets
        return self.system.buffer_sets.get(name) or self.system.one_set.get(name, "")


def _lower_adapter(lo: _Lowering, name: str, node: AdapterNode, in_vars: tuple,
                   outs: tuple) -> None:
    """An adapter's transfer, buffers, part and step."""
    system, buffers, sets, sets_why = lo.system, lo.buffers, lo.sets, lo.sets_why
    parallel = system.execution == "parallel"
    pinned = system.staging == "pinned"
    data = node.outputs["output"].data
    consumers = tuple(system.readers(Endpoint(name, "output")))
    blocking = node.direction == "gpu2cpu" or not parallel
    lo.transfers.append(Transfer(name, node.direction, data, node.zero_copy, blocking,
                                 node.source, consumers))
    cls = ("CpuToGpuAdapter" if node.direction == "cpu2gpu" else "GpuToCpuAdapter")
    if node.zero_copy:
        cls = f"ZeroCopy{cls}"
        if node.direction == "cpu2gpu" and sets(name) > 1:
            buffers.append(Buffer(name, "output", f"{name} ({node.source}) kept",
                                  "host", data, sets(name), sets_why(name)))
    else:
        side = "device" if node.direction == "cpu2gpu" else "host"
        if side == "host" and pinned:
            side = "pinned host"
        buffers.append(Buffer(name, "output", f"{name} ({node.source})", side, data,
                              sets(name), sets_why(name)))
        if node.direction == "cpu2gpu" and pinned:
            buffers.append(Buffer(name, "staging", f"{name} staging", "pinned host",
                                  data, sets(name), sets_why(name)))
    runs = ("copy" if not node.zero_copy else
            "map" if node.direction == "gpu2cpu" else "in place")
    options = [("nbytes", data.nbytes)]
    if node.direction == "cpu2gpu" and not node.zero_copy:
        options.append(("blocking", blocking))
    if sets(name) > 1:
        options.append(("buffer_sets", sets(name)))
        if (node.zero_copy and node.direction == "gpu2cpu"
                and lo.queue_of(name) == lo.queue_of(
                    system.writer(Endpoint(name, "input")).component)):
            # the in-order queue puts the unmap before the writer's next kernel; a
            # host wait would also wait for later frames' kernels queued before it
            options.append(("wait_unmap", False))
    if pinned and not node.zero_copy:
        options.append(("staging", "pinned"))
    lo.parts.append(Part(name, "adapter", f"runtime.{cls}", runs=runs,
                         stage=system.stages[name], queue=lo.queue_of(name),
                         options=tuple(options),
                         note=f"{node.source} -> {', '.join(map(str, consumers))}",
                         init_inputs=in_vars, init_outputs=outs,
                         dtype=np_name(data.dtype)))
    lo.steps.append(Step("transfer", name, (system.input_var(Endpoint(name, "input")),),
                         (system.output_vars[Endpoint(name, "output")],),
                         tuple(system.waits.get(name, ()))))


def _lower_component(lo: _Lowering, name: str, node: ComponentNode | GroupNode,
                     in_vars: tuple, outs: tuple) -> None:
    """A component's (or group's) buffers, transfers (standard mode), launch, part, step,
    the checks of what it returns, and the unmaps after it."""
    system, buffers, sets, sets_why = lo.system, lo.buffers, lo.sets, lo.sets_why
    standard = system.mode == "standard"
    t = node.type
    params = tuple((k, node.params[k]) for k in t.params)
    group = isinstance(node, GroupNode)
    options: list[tuple[str, object]] = []
    if node.on_gpu:
        device_ports = ({**node.inputs, **node.outputs} if standard else node.outputs)
        for p, port in device_ports.items():
            buffers.append(Buffer(name, p, f"{name}.{p}", "device", port.data, sets(name),
                                  sets_why(name)))
        if standard:
            for p, port in node.outputs.items():
                buffers.append(Buffer(name, p, f"{name}.{p} (host)", "host", port.data,
                                      sets(name)))
            for p, port in node.inputs.items():
                lo.transfers.append(Transfer(name, "cpu2gpu", port.data))
            for p, port in node.outputs.items():
                lo.transfers.append(Transfer(name, "gpu2cpu", port.data))
            options.append(("copies_own_data", True))
        elif system.zero_copy:
            options.append(("host_visible", True))
        if sets(name) > 1:
            options.append(("buffer_sets", sets(name)))
        lo.launches.append(launch(system, node, lo.programs[_type_key(t)]))
    else:
        for p, port in node.outputs.items():
            buffers.append(Buffer(name, p, f"{name}.{p}", "host", port.data,
                                  sets_why=sets_why(name)))
    if t.flexible and not node.on_gpu:
        lo.parts.append(Part(name, "component", "runtime.CpuFunctionComponent", t.name, "CPU",
                             system.stages[name], params=params, init_inputs=in_vars,
                             init_outputs=outs, function=lo.functions[t.name],
                             ports=tuple(tuple((p, np_name(d.dtype)) for p, d in ports.items())
                                         for ports in (node.inputs, node.outputs))))
    else:
        what = t.name if not group else \
            node.root.type.name if len(node.members) == 1 else "fused group"
        lo.parts.append(Part(name, "component", t.name, what,
                             "GPU" if node.on_gpu else "CPU", system.stages[name],
                             lo.queue_of(name) if node.on_gpu else None,
                             lo.programs.get(_type_key(t)) if node.on_gpu else None, params,
                             tuple(options), init_inputs=in_vars, init_outputs=outs))
    # the sources run first, whatever the schedule: the end of the stream is known
    # before any part works on the frame (independent chains end together)
    (lo.head if name in lo.sources else lo.steps).append(Step(
        "execute", name, tuple(system.input_var(Endpoint(name, p)) for p in node.inputs),
        _execute_outputs(lo, name, node),
        tuple(system.waits.get(name, ())) if not standard else ()))
    # what a CPU component returns is checked where it enters another part (a
    # source's after the end-of-stream test: None ends the stream there)
    checks = [Step("check", name, (system.output_vars[Endpoint(name, p)],),
                   note=f"{name}.{p}", shape=port.data.size.shape,
                   dtype=np_name(port.data.dtype))
              for p, port in node.outputs.items()
              if not node.on_gpu and system.readers(Endpoint(name, p))]
    if name in lo.sources:
        lo.pending_checks += checks
    else:
        lo.steps += checks
    for a in system.unmap_after.get(name, []):
        lo.steps.append(Step("unmap", a, note=f"the device may write "
                             f"{system.nodes[a].source} again"))


def _execute_outputs(lo: _Lowering, name: str, node: ComponentNode | GroupNode) -> tuple:
    """The variables an execute step assigns: '_' for an output nobody reads (a source's
    outputs excepted: the end-of-stream test reads them), none when no output is read, so
    that the program assigns no variable it never uses."""
    system = lo.system
    outputs = tuple(system.output_vars[Endpoint(name, p)]
                    if name in lo.sources or system.readers(Endpoint(name, p)) else "_"
                    for p in node.outputs)
    return () if all(v == "_" for v in outputs) else outputs


def _stream_steps(lo: _Lowering) -> list[Step]:
    """The stream loop's steps: the sources', the end-of-stream test, the checks of what
    the sources returned, then the rest in order."""
    system = lo.system
    ends = tuple(system.output_vars[Endpoint(s, p)] for s in lo.sources
                 for p in system.nodes[s].outputs)
    return (lo.head + ([Step("end_of_stream", inputs=ends)] if ends else [])
            + lo.pending_checks + lo.steps)


def _grouped(imports) -> tuple[tuple[str, str, str], ...]:
    """(module, names, alias) import lines as an import sorter writes them: the plain names
    of one module on one line, sorted; each renamed one on a line of its own."""
    plain: dict[str, set[str]] = {}
    renamed = set()
    for module, name, alias in imports:
        if alias:
            renamed.add((module, name, alias))
        else:
            plain.setdefault(module, set()).add(name)
    lines = {(m, ", ".join(sorted(names)), "") for m, names in plain.items()}
    return tuple(sorted(lines | renamed))


def _imports(system: System, files: dict[str, str], functions: dict[str, str],
             types: list[ComponentType]) -> tuple[list, list[UserClass]]:
    """The library's imports the program needs, and the user's classes and CPU functions
    it loads from the lib folder."""
    imports, user_classes = [], []
    for t in cpu_used_types(system):
        if t.origin == "library":
            imports.append((f"gpucompgen.library.{t.cpu_file.stem}", t.cpu_function,
                            functions[t.name]))
        else:
            user_classes.append(UserClass(functions[t.name], files[cpu_lib_key(t)],
                                          t.cpu_function, "function"))
    for t in types:
        if t.gpu_aware:
            continue
        if t.origin == "library":
            imports.append((f"gpucompgen.library.{t.python_file.stem}", t.python_class,
                            "" if t.python_class == t.name else t.name))
        else:
            user_classes.append(UserClass(t.name, files[lib_key(t)], t.python_class))
    return imports, user_classes


def _program_users(system: System, gpu_types: list[ComponentType]) -> tuple[
        dict[tuple[str, str], str], dict[tuple[str, str], str]]:
    """The components each kernel's type serves (for the program's comment), and why a
    type's kernel is only built to check it."""
    users = {_type_key(t): _some([n for n in system.order
                            if isinstance(system.nodes[n], (ComponentNode, GroupNode))
                            and system.nodes[n].type is t and system.nodes[n].on_gpu])
             for t in gpu_types}
    why: dict[tuple[str, str], str] = {}  # a type whose kernel is only checked -> why
    for t in checked_kernel_types(system):
        fused = [m.name for g in system.groups for m in g.members if m.type is t]
        alone = [m.name for g in system.kernel_groups if len(g.members) == 1
                 for m in g.members if m.type is t]
        on_cpu = [n for n in system.order if isinstance(system.nodes[n], ComponentNode)
                  and system.nodes[n].type is t]
        users[_type_key(t)] = _some(fused + alone + on_cpu)
        why[_type_key(t)] = "; " + " and ".join(
            w for w, names in (("fused", fused), ("its generated kernel alone", alone),
                               ("on the CPU", on_cpu)) if names) + ": built only to check it"
    return users, why


def _budget_source(system: System) -> str:
    """Where the thread budget comes from, for the plan."""
    asked = system.model.thread_budget
    return ("platform.thread_budget" if asked and asked <= system.thread_budget else
            "device total" if not asked else
            f"device total; platform.thread_budget {asked:,} is more")


def flight_stages(system: System, steps: list[Step]) -> tuple[FlightStage, ...]:
    """The stream loop's steps cut into the stages of stage-frames, with the variables each
    takes from the stage before and hands to the stage after.

    A step waits only for commands of its own stage: a stage hands a frame on once its
    commands are complete.  The end of stream goes with the sources, in the first stage.
    """
    if not system.flight_stages:
        return ()
    where = {n: i for i, names in enumerate(system.flight_stages) for n in names}
    per_stage: list[list[Step]] = [[] for _ in system.flight_stages]
    reader = 0  # the stage of the last execute: an unmap follows its reader there
    for s in steps:
        i = 0 if s.kind == "end_of_stream" else reader if s.kind == "unmap" else where[s.part]
        if s.kind == "execute":
            reader = i
        per_stage[i].append(replace(s, waits=tuple(w for w in s.waits if where[w] == i)))
    made = [{v for s in st for v in s.outputs} for st in per_stage]
    used = [{v for s in st for v in s.inputs if s.kind != "end_of_stream"} for st in per_stage]
    order = [v for st in per_stage for s in st for v in s.outputs]  # first made first
    stages, carried = [], []
    for i, st in enumerate(per_stage):
        later = set().union(*used[i + 1:])
        inputs = tuple(carried)
        have = set(carried) | made[i]
        carried = [v for v in order if v in have and v in later]
        names = system.flight_stages[i]
        kinds = {"device" if (system.nodes[n].kind == "adapter" or system.nodes[n].on_gpu)
                 else "CPU" for n in names}
        runs = ("sources" if i == 0 and any(s.kind == "end_of_stream" for s in st) else
                "CPU and device" if len(kinds) > 1 else kinds.pop())
        stages.append(FlightStage(f"stage{i + 1}", tuple(names), tuple(st), inputs,
                                  tuple(carried), tuple(system.flight_end_waits[i]), runs))
    # what a stage takes from an earlier one is held in a set per frame in flight
    maker = {v: s.part for s in steps if s.kind in ("execute", "transfer") for v in s.outputs}
    for st in stages:
        unsafe = [v for v in st.inputs if maker[v] not in system.buffer_sets]
        if unsafe:
            raise AssertionError(f"{st.name} reads {', '.join(unsafe)} of an earlier stage, "
                                 "held in one buffer set (stage-frames)")
    return tuple(stages)


def _some(names: list[str], most: int = 3) -> str:
    """Names for a message: all of a few, else the first ones and how many more."""
    if len(names) <= most:
        return ", ".join(names)
    return f"{', '.join(names[:most])} and {len(names) - most} more"


def _guarded(system) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """Each kernel member whose reads of some inputs get the nearest pixel (a user's
    index map reading where it cannot be shown inside): (member, its ports)."""
    from ..kernelgen.fused import guarded_ports

    return tuple((m.name, tuple(sorted(ports))) for g in system.kernel_groups
                 for m in g.members if (ports := guarded_ports(m)))
