"""The program plan: a lowered system as plain, backend-neutral records.

The lower pass makes every decision concrete here — buffers and their bytes, each kernel
launch with its arguments in calling-convention order and its global and local sizes,
each transfer, the lanes (queues) and waits, the variable names.  The backend's templates
only print these records; ``plan``, ``check``'s summary, the program's start-up memory
check and ``--profile``'s byte counts read the same ones.
"""

from __future__ import annotations

import posixpath
import re
import textwrap
from dataclasses import dataclass, field, replace
from pathlib import PurePosixPath
from typing import Any

from .dataflow import Data, Endpoint
from .runtime.sizes import Size


class ModelPath(str):
    """A path parameter relative to the model's folder, as seen from the program's folder:
    printed as a call that resolves it when the program runs, wherever it is started."""


class ParamRef(str):
    """A parameter --set may change: printed as its entry of run()'s `params`."""


@dataclass(frozen=True)
class Settable:
    """A parameter the program's --set may change when it starts: one that no size or
    requirement depends on (a generated kernel takes it as a build option)."""

    key: str  # 'component.param'
    type: str  # the declaration's type
    value: object  # the model's value
    minimum: float | None = None
    maximum: float | None = None


@dataclass(frozen=True)
class Buffer:
    owner: str  # the part that allocates it
    port: str
    what: str  # as shown in messages: 'merger.merged', 'adapter1_cpu2gpu (camera1.image)'
    memory: str  # "device" | "host" | "pinned host"
    data: Data
    sets: int = 1  # one per frame in flight where another stage reads it (stage-frames)
    sets_why: str = ""  # with frames in flight: why it has that many sets

    @property
    def nbytes(self) -> int:
        """Its bytes, all sets together."""
        return self.data.nbytes * self.sets

    @property
    def on_host(self) -> bool:
        return self.memory != "device"


@dataclass(frozen=True)
class Argument:
    """One kernel argument, in the calling convention's order."""

    name: str  # the convention's name of the parameter
    kind: str  # "buffer" | "scalar"
    port: str = ""  # a buffer: the port it belongs to
    host_type: str = ""  # a scalar: the numpy type it is passed as
    value: Any = None  # a scalar's value, decided at build time
    param: str = ""  # a parameter's scalar: the model's 'component.param' it passes


@dataclass(frozen=True)
class Launch:
    part: str
    function: str
    arguments: tuple[Argument, ...]
    tile: int
    local_size: tuple[int, int, int]
    global_size: tuple[int, int, int]
    settings_source: str  # who chose the settings: "model", "preferred", ...
    threads: int  # resident threads

    @property
    def settings_from_model(self) -> bool:
        return self.settings_source == "model"


@dataclass(frozen=True)
class Transfer:
    """Bytes moved between CPU and GPU each frame: by an adapter, or by a component that
    copies its own data (standard mode)."""

    part: str
    direction: str  # "cpu2gpu" | "gpu2cpu"
    data: Data
    zero_copy: bool = False  # nothing copied: the other side maps the memory in place
    blocking: bool = True  # the host waits for the copy
    source: Endpoint | None = None  # an adapter's producing port
    consumers: tuple[Endpoint, ...] = ()

    @property
    def nbytes(self) -> int:
        return self.data.nbytes

    @property
    def copied(self) -> int:
        return 0 if self.zero_copy else self.nbytes


@dataclass(frozen=True)
class Part:
    """An object of the program: a component or an adapter, constructed in run order."""

    name: str
    kind: str  # "component" | "adapter"
    cls: str  # its class in generated code
    type_name: str = ""  # a component's type
    runs: str = "CPU"  # "CPU" | "GPU" | "copy" | "map" | "in place"
    stage: int = 0
    queue: str | None = None  # the queue variable of a GPU command
    program: str | None = None  # the program variable of a kernel component
    params: tuple[tuple[str, Any], ...] = ()  # constructor arguments (model parameters)
    options: tuple[tuple[str, Any], ...] = ()  # constructor settings the system chose
    note: str = ""  # e.g. what an adapter joins
    # initialize(): the size variables it takes, what it gives (variable, port, Size) and,
    # for an adapter, the element type
    init_inputs: tuple[str, ...] = ()
    init_outputs: tuple[tuple[str, str, Size], ...] = ()
    dtype: str = ""
    # a flexible component placed on the CPU: the variable of its type's CPU function, and
    # its ports: (input names, ((output name, element type), ...))
    function: str = ""
    ports: tuple = ()


@dataclass(frozen=True)
class Step:
    """One statement of the stream loop."""

    kind: str  # "execute" | "transfer" | "unmap" | "end_of_stream" | "check"
    part: str = ""
    inputs: tuple[str, ...] = ()  # variables
    outputs: tuple[str, ...] = ()  # variables
    waits: tuple[str, ...] = ()  # parts whose last event it waits for
    note: str = ""
    # "check": a CPU component's output entering another part must have this host shape
    # and numpy element type (note names the port)
    shape: tuple[int, ...] = ()
    dtype: str = ""


@dataclass(frozen=True)
class FlightStage:
    """With frames in flight: a stage of the stream, run by its own thread, frame after
    frame; it takes the values earlier stages made that it or later stages need, and
    returns those later stages need (the first stage returns None at the end of the
    stream)."""

    name: str  # its function in generated code: "stage1"
    parts: tuple[str, ...]
    steps: tuple[Step, ...]
    inputs: tuple[str, ...]  # variables from the stage before
    outputs: tuple[str, ...]  # variables for the stage after
    end_waits: tuple[str, ...] = ()  # parts whose last event it waits for at frame end
    runs: str = ""  # "sources" | "CPU" | "device" | "CPU and device"


@dataclass(frozen=True)
class Program:
    var: str
    file: str
    users: str
    # a generated kernel's constants, set as build options -D NAME=VALUE: its members'
    # parameters (kind "constant"; name the macro, param the model's 'component.param')
    defines: tuple[Argument, ...] = ()


@dataclass(frozen=True)
class KernelClass:
    """A kernel component type as the program declares it (what differs per type)."""

    name: str
    function: str
    file: str
    description: str
    inputs: tuple[tuple[str, str], ...]  # (port, element type)
    outputs: tuple[tuple[str, str], ...]
    output_sizes: tuple[tuple[str, str, int], ...]  # (height expr, width expr, channels)
    grid: str
    rows: bool


@dataclass(frozen=True)
class UserClass:
    name: str
    file: str  # in the lib folder
    cls: str
    kind: str = "class"  # "class" (a standard type) | "function" (a flexible type's CPU side)


@dataclass(frozen=True)
class GroupPlan:
    """A fused group: its part, its members (name, type, fusable form) in run order, and
    the generated kernel's file in the lib folder."""

    part: str
    members: tuple[tuple[str, str, str], ...]
    file: str
    # the group's ports as the model names them: input port -> "member.port" it feeds,
    # and every member's output -> its size ("" for the group's output: a buffer)
    feeds: tuple[tuple[str, str], ...] = ()
    outputs: tuple[tuple[str, str, bool], ...] = ()  # ("member.port", data, fused away)
    estimate: str = ""  # the fuse pass's estimate: fused against apart


@dataclass(frozen=True)
class LibSource:
    """A source file the program's lib folder holds, with the text that was checked (a
    backend prints it under its header; nothing is read from disk again)."""

    file: str  # in the lib folder
    kind: str  # "kernel" | "checked_kernel" (built only to check it) | "cpu" | "python"
    #          | "group" (a fused group's kernel, as the kernel generator wrote it)
    users: tuple[str, ...]  # the types that use it, sorted (a group: the group's part)
    text: str
    origin: str = ""  # the file it was read from, for messages

    @property
    def is_kernel(self) -> bool:
        """Whether the file is device code (a backend names and translates it so)."""
        return self.kind in ("kernel", "checked_kernel", "group")


@dataclass
class ProgramPlan:
    system: str
    mode: str
    execution: str
    device_name: str
    zero_copy: bool
    zero_copy_reason: str
    queues: tuple[str, ...] = ()
    programs: tuple[Program, ...] = ()
    imports: tuple[tuple[str, str, str], ...] = ()  # (module, name, alias)
    user_classes: tuple[UserClass, ...] = ()
    kernel_classes: tuple[KernelClass, ...] = ()
    parts: tuple[Part, ...] = ()
    buffers: tuple[Buffer, ...] = ()
    launches: tuple[Launch, ...] = ()
    transfers: tuple[Transfer, ...] = ()
    steps: tuple[Step, ...] = ()
    frame_end_waits: tuple[str, ...] = ()
    thread_budget: int = 0
    thread_budget_source: str = ""
    concurrent: tuple[tuple[tuple[str, ...], int], ...] = ()  # (group, resident threads)
    lib_files: dict[str, str] = field(default_factory=dict)  # lib file -> what it is
    lib_dir: str = ""  # the lib folder, beside the program
    lib_sources: tuple[LibSource, ...] = ()  # the kernel and Python files it holds
    fusion: str = "off"
    groups: tuple[GroupPlan, ...] = ()
    # components of fusable types alone, each running the kernel generated from its form:
    # (part, type, form, file in the lib folder)
    generated: tuple[tuple[str, str, str, str], ...] = ()
    # a user's index map whose reads of these inputs are not shown inside them: the
    # kernel reads the nearest pixel there (kernelgen/fused.py guarded_ports)
    guarded: tuple[tuple[str, tuple[str, ...]], ...] = ()
    unfused: tuple[tuple[str, str], ...] = ()  # (GPU-to-GPU edge, why it was not fused)
    placement: tuple[str, ...] = ()  # where each flexible component runs, who decided, costs
    # frames in flight (stage-frames): N, the stages, why stages were merged, the parts
    # that keep N sets of their outputs and why; staging of copying adapters
    frames_in_flight: int = 1
    stages: tuple[FlightStage, ...] = ()
    flight_notes: tuple[str, ...] = ()
    buffer_sets: tuple[tuple[str, str], ...] = ()  # (part, why)
    staging: str = "pageable"  # "pinned" | "pageable"
    staging_reason: str = ""
    # what the program says of its model and lets its user change
    description: str = ""
    model_sha256: str = ""  # of the model file's text
    model_inputs: tuple[tuple[str, str], ...] = ()  # (file relative to the model, sha256)
    sources: tuple[str, ...] = ()  # the components, in run order
    settable: tuple[Settable, ...] = ()  # by key
    path_params: tuple[str, ...] = ()  # 'part.param' keys whose values are model paths

    def for_program(self, model_dir: str) -> ProgramPlan:
        """The plan as its program prints it: every settable parameter's value a ParamRef
        (run()'s `params` entry), every relative path parameter a ModelPath from the
        program's folder (model_dir: the model's folder as seen from there)."""
        keys = {s.key for s in self.settable}
        paths = set(self.path_params)

        def value(key: str, v):
            if key in keys:
                return ParamRef(key)
            if key in paths and isinstance(v, str) and v:
                return relative_to_program(v, model_dir)
            return v

        def arguments(args: tuple[Argument, ...]) -> tuple[Argument, ...]:
            return tuple(replace(a, value=value(a.param, a.value)) if a.param else a
                         for a in args)

        return replace(
            self,
            settable=tuple(replace(s, value=relative_to_program(s.value, model_dir))
                           if s.key in paths and isinstance(s.value, str) and s.value else s
                           for s in self.settable),
            parts=tuple(replace(p, params=tuple((k, value(f"{p.name}.{k}", v))
                                                for k, v in p.params))
                        for p in self.parts),
            launches=tuple(replace(la, arguments=arguments(la.arguments))
                           for la in self.launches),
            programs=tuple(replace(pr, defines=arguments(pr.defines))
                           for pr in self.programs))

    def with_kernel_suffix(self, suffix: str) -> ProgramPlan:
        """The plan with its kernel files named as a backend writes them (``.cu`` for CUDA,
        which compiles the same portable kernels under its prelude): every record that
        names a kernel file in the lib folder, and nothing else."""
        kernels = {s.file for s in self.lib_sources if s.is_kernel}

        def name(file: str) -> str:
            return str(PurePosixPath(file).with_suffix(suffix)) if file in kernels else file

        return replace(
            self,
            programs=tuple(replace(p, file=name(p.file)) for p in self.programs),
            kernel_classes=tuple(replace(k, file=name(k.file)) for k in self.kernel_classes),
            groups=tuple(replace(g, file=name(g.file)) for g in self.groups),
            generated=tuple((part, t, form, name(file)) for part, t, form, file in self.generated),
            lib_files={name(f): what for f, what in self.lib_files.items()},
            lib_sources=tuple(replace(s, file=name(s.file)) for s in self.lib_sources))

    # --- the facts everything reads --------------------------------------------------------
    def device_buffers(self) -> list[Buffer]:
        return [b for b in self.buffers if b.memory == "device"]

    @property
    def device_bytes(self) -> int:
        return sum(b.nbytes for b in self.buffers if b.memory == "device")

    @property
    def host_bytes(self) -> int:
        return sum(b.nbytes for b in self.buffers if b.on_host)

    def extra_set_bytes(self, memory: str) -> int:
        """What the frames in flight cost: the bytes of the sets beyond the first."""
        return sum(b.data.nbytes * (b.sets - 1) for b in self.buffers
                   if (b.memory == "device") == (memory == "device"))

    @property
    def copied_bytes(self) -> int:
        return sum(t.copied for t in self.transfers)

    def lib_files_of(self, key: str) -> str:
        """The lib folder's file of a source (see lower.lib_files)."""
        return next(f for f, k in self.lib_files.items() if k == key)

    def launch(self, part: str) -> Launch | None:
        return next((la for la in self.launches if la.part == part), None)

    def adapter_transfer(self, part: str) -> Transfer | None:
        return next((t for t in self.transfers if t.part == part and t.source), None)

    def uses_gpu(self) -> bool:
        return bool(self.queues)

    def dump_lines(self) -> list[str]:
        lines = [f"plan: queues {', '.join(self.queues) or '-'}"]
        for b in self.buffers:
            lines.append(f"  buffer {b.what}: {b.memory} {b.data} ({b.nbytes:,} bytes)"
                         + (f" x{b.sets} sets" if b.sets > 1 else ""))
        for la in self.launches:
            lines.append(f"  launch {la.part}: {la.function} global {la.global_size} local "
                         f"{la.local_size} args ({', '.join(_arg(a) for a in la.arguments)})")
        for t in self.transfers:
            lines.append(f"  transfer {t.part}: {t.direction} {t.nbytes:,} bytes"
                         + (" zero-copy" if t.zero_copy else ""))
        for st in self.stages:
            lines.append(f"  {st.name}: {', '.join(st.parts)} (in: {', '.join(st.inputs) or '-'};"
                         f" out: {', '.join(st.outputs) or '-'})")
        return lines


def _arg(a: Argument) -> str:
    return a.port if a.kind == "buffer" else f"{a.name}={a.value}"


def plan_lines(plan: ProgramPlan) -> list[str]:
    """The system plan, as printed by `gpucompgen plan` and atop the generated program.

    One row per part in the order they run: the stage (parts of one stage never depend on
    each other), the queue of a GPU command, where it runs, the GPU settings and resident
    threads the system chose, and every buffer with its bytes.  Then the totals: peak device
    and host memory (all allocated once, at start), bytes copied between CPU and GPU per
    frame, and the thread budget.
    """
    parallel = plan.execution == "parallel" and len(plan.queues) > 1
    rows = [("step", "name", "stage", "queue", "runs", "GPU settings", "threads")]
    for i, part in enumerate(plan.parts, 1):
        queue = part.queue.removeprefix("queue") if parallel and part.queue else "-"
        la = plan.launch(part.name)
        setting = (f"tile {la.tile}, block {la.local_size[0]}x{la.local_size[1]}x"
                   f"{la.local_size[2]}" if la else "-")
        name = part.name if part.kind == "adapter" else f"{part.name} ({part.type_name})"
        rows.append((str(i), name, str(part.stage), queue, part.runs, setting,
                     f"{la.threads:,}" if la else "-"))
    lines = _table(rows)
    lines.append("")
    flight = plan.frames_in_flight > 1
    rows = [("buffer", "memory", "size", "bytes") + (("sets",) if flight else ())]
    for b in plan.buffers:
        rows.append((b.what, b.memory, str(b.data), f"{b.nbytes:,}")
                    + ((str(b.sets),) if flight else ()))
    for t in plan.transfers:
        if t.zero_copy:
            view = "mapped device" if t.direction == "gpu2cpu" else "host"
            rows.append((f"{t.part} ({t.source})", f"{view} view", str(t.data), "0")
                        + (("-",) if flight else ()))
    lines += _table(rows, right=(3,))
    lines.append("")
    if plan.placement:
        lines.append("placement of flexible components:")
        lines += [f"  {line}" for line in plan.placement]
        lines.append("")
    lines.append(f"device: {plan.device_name}")
    lines.append(f"peak device memory: {plan.device_bytes:,} bytes; peak host memory: "
                 f"{plan.host_bytes:,} bytes")
    lines.append("(every buffer is allocated once, at start)")
    lines.append(f"bytes copied between CPU and GPU per frame: {plan.copied_bytes:,}")
    lines.append(f"zero-copy adapters: {'on' if plan.zero_copy else 'off'} "
                 f"({plan.zero_copy_reason})")
    if any(p.kind == "adapter" for p in plan.parts) and not plan.zero_copy:
        lines.append(f"staging of copying adapters: {plan.staging} ({plan.staging_reason})")
    n = len(plan.queues)
    lines.append(f"execution: {plan.execution}" + (
        f", {n} queue{'s' if n != 1 else ''}" if plan.execution == "parallel" and n else ""))
    if plan.concurrent:
        lines.append(f"thread budget: {plan.thread_budget:,} ({plan.thread_budget_source}); "
                     "GPU components that can run at the same time:")
        for group, threads in plan.concurrent:
            lines += textwrap.wrap(f"{', '.join(group)}: {threads:,} threads", 88,
                                   initial_indent="  ", subsequent_indent="    ",
                                   break_on_hyphens=False)
    lines += fusion_lines(plan)
    if flight:
        lines += flight_lines(plan)
    return lines


def fusion_lines(plan: ProgramPlan) -> list[str]:
    """Each fused group and, for every GPU-to-GPU edge left unfused, why."""
    lines = []
    if plan.generated:  # a component of a fusable type alone: the kernel of its form
        lines += textwrap.wrap(
            "kernels generated from fusable forms, one component each: " + ", ".join(
                f"{part} ({t}, {form}: {file})" for part, t, form, file in plan.generated),
            88, subsequent_indent="  ", break_on_hyphens=False)
    if plan.guarded:
        lines += textwrap.wrap(
            "index-map reads not shown inside their input, given the nearest pixel there "
            "(BORDER_REPLICATE): " + ", ".join(f"{m}.{p}" for m, ports in plan.guarded
                                               for p in ports),
            88, subsequent_indent="  ", break_on_hyphens=False)
    if plan.fusion == "off" and not plan.unfused:
        return lines
    lines += [f"fusion: {plan.fusion}, {len(plan.groups)} "
              f"group{'s' if len(plan.groups) != 1 else ''}" + (":" if plan.groups else "")]
    for g in plan.groups:
        lines.append(f"  {g.part}: one kernel ({g.file}) for")
        lines += [f"    {'-> ' if i else ''}{m} ({t}, {form})"
                  for i, (m, t, form) in enumerate(g.members)]
        if g.estimate:
            lines += textwrap.wrap(g.estimate, 88, initial_indent="    ",
                                   subsequent_indent="    ")
    for edge, why in plan.unfused:
        lines.append(f"  not fused: {edge}:")
        # wrapped: the generated program's header quotes these lines (100 columns)
        lines += textwrap.wrap(why, 88, initial_indent="    ", subsequent_indent="    ",
                               break_on_hyphens=False)
    return lines


def flight_lines(plan: ProgramPlan) -> list[str]:
    """The frames in flight: the stages, one thread each, and what N costs."""
    n = plan.frames_in_flight
    lines = [f"frames in flight: {n} (at most {n} in the pipeline); each stage runs in its own",
             "thread, frame after frame, and hands frames on through a queue:"]
    for st in plan.stages:
        lines.append(f"  {st.name} ({st.runs}): {', '.join(st.parts)}")
    for note in plan.flight_notes:
        lines.append(f"  merged: {note}")
    lines.append(f"buffer sets ({n}, one a frame in flight, used in turn, where one stage "
                 "writes what")
    lines.append("another reads; else 1):")
    for b in plan.buffers:
        lines += textwrap.wrap(f"{b.what}: {b.sets} ({b.sets_why})", 88, initial_indent="  ",
                               subsequent_indent="    ", break_on_hyphens=False)
    lines.append(f"memory {n} frames in flight cost beyond one frame: "
                 f"{plan.extra_set_bytes('device'):,} device bytes, "
                 f"{plan.extra_set_bytes('host'):,} host bytes")
    return lines


def _table(rows: list[tuple[str, ...]], right: tuple[int, ...] = ()) -> list[str]:
    widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
    return ["  ".join(cell.rjust(w) if c in right else cell.ljust(w)
                      for c, (cell, w) in enumerate(zip(r, widths))).rstrip() for r in rows]


def summary_lines(plan: ProgramPlan) -> list[str]:
    """What `gpucompgen check` prints about a checked system: components, adapters, sizes."""
    comps = [p for p in plan.parts if p.kind == "component"]
    groups = {g.part: g for g in plan.groups}
    named = {f"{g.part}.{port}": end for g in plan.groups for port, end in g.feeds}

    def listed(p) -> str:
        side = "GPU" if p.runs == "GPU" else "CPU"
        g = groups.get(p.name)
        if g is None:
            return f"{p.name} ({p.type_name}, {side})"
        return ", ".join(f"{m} ({t}, {side}, fused in {g.part})" for m, t, _ in g.members)

    count = sum(len(groups[p.name].members) if p.name in groups else 1 for p in comps)
    lines = [f"{count} component{'s' if count != 1 else ''}, in order: "
             + ", ".join(listed(p) for p in comps)]
    adapters = [t for t in plan.transfers if t.source is not None]
    n = len(adapters)
    lines.append(f"{n} adapter{'s' if n != 1 else ''} will be inserted" + (":" if n else ""))
    for t in adapters:
        lines.append(f"  {t.part}: {t.source} -> "
                     f"{', '.join(named.get(str(c), str(c)) for c in t.consumers)} "
                     f"({t.data}, {t.nbytes:,} bytes a frame)")
    lines.append("sizes:")
    for p in comps:
        if p.name in groups:
            lines += [f"  {end}: {data}" + (" (fused: no buffer)" if gone else "")
                      for end, data, gone in groups[p.name].outputs]
            continue
        for _, port, size in sorted(p.init_outputs, key=lambda o: o[1]):
            data = next(b.data for b in plan.buffers if b.owner == p.name and b.port == port)
            lines.append(f"  {p.name}.{port}: {data}")
    for p in comps:
        la = plan.launch(p.name)
        if la is not None:
            bx, by, bz = la.local_size
            lines.append(f"GPU settings of {p.name}: tile {la.tile}, block {bx}x{by}x{bz} "
                         f"({la.settings_source})")
    if plan.placement:
        lines.append("placement of flexible components:")
        lines += [f"  {line}" for line in plan.placement]
    lines += fusion_lines(plan)
    lines.append("device: " + plan.device_name.encode("unicode_escape").decode("ascii"))
    return lines


URI = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")  # e.g. a camera's device:0, not a path
FILE_URI = re.compile(r"(file|mcap|rosbag)://(?!/)")  # a file URI with a relative path


def relative_to_program(value: str, model_dir: str):
    """A path (or a file URI's path) relative to the model, as seen from the program."""
    m = FILE_URI.match(value)
    if m:
        path, q, query = value[m.end():].partition("?")
        return ModelPath(f"{m.group(0)}{posixpath.normpath(posixpath.join(model_dir, path))}"
                         f"{q}{query}")
    if posixpath.isabs(value) or URI.match(value):
        return value
    return ModelPath(posixpath.normpath(posixpath.join(model_dir, value)))
