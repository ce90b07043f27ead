"""Passes: each has one job, takes the System and returns it, reporting problems.

    check-connections → check-port-types → schedule → propagate-sizes → insert-adapters
    → allocate-gpu → name-variables → assign-queues

``gpucompgen build --print-between-passes`` dumps the System after each pass.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from . import sizeexpr
from .device import DeviceFacts
from .errors import GpucompgenError, Pos, Reporter
from .model import DTYPES, EXECUTIONS, ZERO_COPY, Endpoint, Instance, SystemModel

MODES = ("gpu-aware", "standard")


@dataclass(frozen=True)
class Size:
    height: int
    width: int
    channels: int
    dtype: str

    @property
    def nbytes(self) -> int:
        return self.height * self.width * self.channels * DTYPES[self.dtype][2]

    def __str__(self) -> str:
        return f"{self.height}x{self.width}x{self.channels} {self.dtype}"


@dataclass(frozen=True)
class GpuSettings:
    tile: int
    block_x: int
    block_y: int
    block_z: int
    source: str  # "model" | "preferred" | "reduced to fit the device" | "component's own"

    @property
    def threads_per_group(self) -> int:
        return self.block_x * self.block_y * self.block_z


@dataclass
class Adapter:
    name: str  # variable of the adapter object
    direction: str  # "cpu2gpu" | "gpu2cpu"
    source: Endpoint
    consumers: list[Endpoint]
    size: Size
    output_var: str = ""
    # zero-copy form (unified host memory): the device uses host memory, nothing is copied
    zero_copy: bool = False


@dataclass
class Step:
    """One line of the stream loop: a component's execute or an adapter's transfer."""

    kind: str  # "component" | "adapter"
    name: str


@dataclass
class System:
    model: SystemModel
    device: DeviceFacts
    mode: str = "gpu-aware"
    execution: str = "parallel"  # "parallel" | "sequential"
    zero_copy: bool = False
    zero_copy_reason: str = ""
    writers: dict[Endpoint, Endpoint] = field(default_factory=dict)  # input → producing output
    readers: dict[Endpoint, list[Endpoint]] = field(default_factory=dict)  # output → inputs
    order: list[str] = field(default_factory=list)
    sizes: dict[Endpoint, Size] = field(default_factory=dict)
    adapters: list[Adapter] = field(default_factory=list)
    settings: dict[str, GpuSettings] = field(default_factory=dict)
    stages: dict[str, int] = field(default_factory=dict)
    steps: list[Step] = field(default_factory=list)
    # thread budget: the cap, and the groups of GPU-aware components that can run at the
    # same time (maximal sets with no path between any two of them)
    thread_budget: int = 0
    concurrent: list[tuple[str, ...]] = field(default_factory=list)
    # parallel execution: the in-order queue ("lane") of every GPU command (GPU-aware
    # components and adapters), the other lanes' events each one waits for, and the lane
    # ends the host waits for at the end of a frame (those no host read already covers)
    lanes: dict[str, int] = field(default_factory=dict)
    waits: dict[str, list[str]] = field(default_factory=dict)
    frame_end_waits: list[str] = field(default_factory=list)
    # zero-copy GPU-to-CPU adapters unmap after the last consumer that reads their view
    unmap_after: dict[str, list[str]] = field(default_factory=dict)
    # where each consumer input reads its value from (a variable name in generated code)
    input_vars: dict[Endpoint, str] = field(default_factory=dict)
    output_vars: dict[Endpoint, str] = field(default_factory=dict)

    @property
    def components(self) -> dict[str, Instance]:
        return self.model.components

    def memory(self, end: Endpoint) -> str:
        """Where a port's data lives in this system (standard mode keeps it all on the CPU)."""
        port = self.components[end.component].type.port(end.port)
        return "cpu" if self.mode == "standard" else port.memory

    def dump(self) -> str:
        lines = [f"system {self.model.name} (mode {self.mode}, device {self.device.name})"]
        if self.order:
            lines.append("  order: " + ", ".join(self.order))
        for end, size in sorted(self.sizes.items(), key=lambda kv: str(kv[0])):
            lines.append(f"  size {end}: {size}")
        for a in self.adapters:
            lines.append(f"  adapter {a.name}: {a.direction} {a.source} -> "
                         + ", ".join(map(str, a.consumers))
                         + (" [zero-copy]" if a.zero_copy else ""))
        for name, s in sorted(self.settings.items()):
            lines.append(f"  config_gpu {name}: tile={s.tile} block=({s.block_x}, "
                         f"{s.block_y}, {s.block_z}) [{s.source}]")
        for group in self.concurrent:
            lines.append(f"  can run together: {', '.join(group)}")
        for step in self.steps:
            lane = self.lanes.get(step.name)
            lines.append(f"  step {step.kind} {step.name}"
                         + (f" [queue {lane}]" if lane is not None else "")
                         + "".join(f" waits {w}" for w in self.waits.get(step.name, [])))
        return "\n".join(lines)


class Pass:
    name = "pass"
    # A checking pass that still runs after an earlier pass found errors: it must cope with
    # a partly checked system (inputs without writers, no order after a cycle, missing
    # sizes), so one run reports as many independent problems as possible.
    runs_after_errors = False

    def apply(self, system: System, rep: Reporter) -> System:
        raise NotImplementedError


class CheckConnections(Pass):
    """Who writes each input: one writer, required inputs fed, nothing left dangling."""

    name = "check-connections"
    runs_after_errors = True

    def apply(self, system, rep):
        model = system.model
        first: dict[Endpoint, Pos] = {}
        for conn in model.connections:
            if conn.target in system.writers:
                rep.error(conn.pos, f"input '{conn.target}' has two writers: "
                          f"'{system.writers[conn.target]}' and '{conn.source}'",
                          f"an input takes one connection (the first is at line "
                          f"{first[conn.target].line}); merge the data with a component")
                continue
            system.writers[conn.target] = conn.source
            first[conn.target] = conn.pos
            system.readers.setdefault(conn.source, []).append(conn.target)
        for inst in model.components.values():
            connected = False
            for pname in inst.type.inputs:
                end = Endpoint(inst.name, pname)
                if end in system.writers:
                    connected = True
                else:
                    rep.error(inst.pos, f"input '{end}' is not connected",
                              f"add a connection '<producer>.<port> -> {end}'")
            for pname in inst.type.outputs:
                end = Endpoint(inst.name, pname)
                if end in system.readers:
                    connected = True
                else:
                    rep.warning(inst.pos, f"output '{end}' is not connected",
                                "its data is computed every frame and dropped")
            if not connected and (inst.type.inputs or inst.type.outputs):
                rep.warning(inst.pos, f"component '{inst.name}' is connected to nothing",
                            "connect it or remove it")
        return system


class CheckPortTypes(Pass):
    """Both ends of a connection carry the same element type and channels."""

    name = "check-port-types"
    runs_after_errors = True

    def apply(self, system, rep):
        for conn in system.model.connections:
            out = system.components[conn.source.component].type.port(conn.source.port)
            inp = system.components[conn.target.component].type.port(conn.target.port)
            if out.dtype != inp.dtype:
                rep.error(conn.pos, f"element type mismatch: '{conn.source}' gives {out.dtype}, "
                          f"'{conn.target}' takes {inp.dtype}",
                          "insert a component that converts, or change a port's dtype")
            if out.channels != inp.channels:
                rep.error(conn.pos, f"channel mismatch: '{conn.source}' gives {out.channels} "
                          f"channel(s), '{conn.target}' takes {inp.channels}",
                          "insert a component that converts, or connect another port")
        return system


class Schedule(Pass):
    """A topological order; ties follow the order of components in the model."""

    name = "schedule"
    runs_after_errors = True

    def apply(self, system, rep):
        comps = system.components
        succ: dict[str, set[str]] = {n: set() for n in comps}
        indeg = {n: 0 for n in comps}
        for target, source in system.writers.items():
            if target.component not in succ[source.component]:
                succ[source.component].add(target.component)
                indeg[target.component] += 1
        heap = [(comps[n].order, n) for n, d in indeg.items() if d == 0]
        heapq.heapify(heap)
        order = []
        while heap:
            _, n = heapq.heappop(heap)
            order.append(n)
            for m in succ[n]:
                indeg[m] -= 1
                if indeg[m] == 0:
                    heapq.heappush(heap, (comps[m].order, m))
        if len(order) != len(comps):
            cycle = _find_cycle({n: s for n, s in succ.items() if indeg[n] > 0}, comps)
            first = comps[cycle[0]]
            rep.error(first.pos, "the connections form a cycle: " + " -> ".join(cycle + cycle[:1]),
                      "pipe-and-filter systems are acyclic; remove one of these connections")
            return system
        system.order = order
        # stage = longest path from a source: components of one stage never depend on
        # each other, so they may run at the same time.
        stage: dict[str, int] = {}
        for n in order:
            preds = [s.component for t, s in system.writers.items() if t.component == n]
            stage[n] = 1 + max((stage[p] for p in preds), default=0)
        system.stages = stage
        return system


def _find_cycle(succ: dict[str, set[str]], comps) -> list[str]:
    start = min(succ, key=lambda n: comps[n].order)
    path, seen = [start], {start: 0}
    while True:
        nxt = min((m for m in succ[path[-1]] if m in succ), key=lambda n: comps[n].order)
        if nxt in seen:
            return path[seen[nxt]:]
        seen[nxt] = len(path)
        path.append(nxt)


class PropagateSizes(Pass):
    """From the sources' parameters down the graph: every port gets a concrete size."""

    name = "propagate-sizes"
    runs_after_errors = True

    def apply(self, system, rep):
        for name in system.order:
            inst = system.components[name]
            ctype = inst.type
            in_sizes: dict[str, tuple[int, int]] = {}
            for pname, port in ctype.inputs.items():
                end = Endpoint(name, pname)
                src = system.writers.get(end)
                if src is None or src not in system.sizes:
                    break
                size = system.sizes[src]
                system.sizes[end] = Size(size.height, size.width, port.channels, port.dtype)
                in_sizes[pname] = (size.height, size.width)
            else:
                int_params = {k: v for k, v in inst.params.items()
                              if ctype.params[k].type == "int"}
                ok = True
                for tree, message in ctype.requires:
                    try:
                        if not sizeexpr.evaluate(tree, in_sizes, int_params):
                            shown = ", ".join(f"{p} is {h}x{w}" for p, (h, w) in in_sizes.items())
                            rep.error(inst.pos, f"'{name}' ({ctype.name}): {message} ({shown})",
                                      "change the sizes of what feeds it")
                            ok = False
                    except sizeexpr.SizeExprError as exc:
                        rep.error(inst.pos, f"'{name}': {exc}")
                        ok = False
                if not ok:
                    continue
                for pname, port in ctype.outputs.items():
                    if port.height is None or port.width is None:
                        continue
                    try:
                        h = sizeexpr.evaluate(port.height, in_sizes, int_params)
                        w = sizeexpr.evaluate(port.width, in_sizes, int_params)
                    except sizeexpr.SizeExprError as exc:
                        rep.error(inst.pos, f"'{name}.{pname}': {exc}")
                        continue
                    if h < 1 or w < 1:
                        rep.error(inst.pos, f"output '{name}.{pname}' would be {h}x{w}",
                                  "sizes must be positive; check parameters and inputs")
                        continue
                    system.sizes[Endpoint(name, pname)] = Size(h, w, port.channels, port.dtype)
        for end, size in system.sizes.items():
            # every port of a GPU-aware component is a device buffer (its own or an adapter's)
            if system.components[end.component].type.gpu_aware and \
                    size.nbytes > system.device.max_mem_alloc_size:
                    rep.error(system.components[end.component].pos,
                              f"'{end}' needs {size.nbytes} bytes, more than the device's "
                              f"largest allocation ({system.device.max_mem_alloc_size} bytes)",
                              "use smaller frames or a device with more memory")
        return system


class InsertAdapters(Pass):
    """One adapter per producing port whose data must cross between CPU and GPU."""

    name = "insert-adapters"

    def apply(self, system, rep):
        count = 0
        for name in system.order:
            inst = system.components[name]
            for pname in inst.type.outputs:
                src = Endpoint(name, pname)
                consumers = system.readers.get(src, [])
                src_mem = system.memory(src)
                crossing = [c for c in consumers if system.memory(c) != src_mem]
                if not crossing or src not in system.sizes:
                    continue
                count += 1
                direction = "cpu2gpu" if src_mem == "cpu" else "gpu2cpu"
                name = f"adapter{count}_{direction}"
                while name in system.components:  # a component may have taken the name
                    name += "_"
                system.adapters.append(Adapter(
                    name=name, direction=direction, source=src,
                    consumers=crossing, size=system.sizes[src], zero_copy=system.zero_copy))
        return system


class AllocateGpu(Pass):
    """The system, not the component, decides each component's config_gpu values.

    Policy: start from the model's override, else the type's preference; a model override
    that breaks the device's limits or the type's constraints is an error; a preference
    that does not fit is halved (largest block dimension first) until it does.  Components
    of the same stage can run at the same time: their threads together must fit the
    thread budget (the device's total unless the model caps it).
    """

    name = "allocate-gpu"
    runs_after_errors = True

    def apply(self, system, rep):
        dev = system.device
        overrides = system.model.gpu_overrides
        for name in system.order:
            inst = system.components[name]
            if not inst.type.gpu_aware:
                continue
            decl = inst.type.gpu
            if name in overrides and system.mode == "gpu-aware":
                values, pos = overrides[name]
                tile, bx, by, bz = (values.get(k, d) for k, d in zip(
                    ("tile", "block_x", "block_y", "block_z"), decl.prefer))
                problems = limit_problems(tile, bx, by, bz, decl, dev)
                for p in problems:
                    if "kernel" in p:
                        hint = f"the kernel of '{inst.type.name}' accepts {decl.accepts()}"
                    else:
                        hint = (f"device '{dev.name}' allows work-groups of at most "
                                f"{dev.max_work_group_size} threads, "
                                f"{list(dev.max_work_item_sizes)} per dimension")
                    rep.error(pos, f"gpu_settings of '{name}': {p}", hint)
                if problems:
                    continue
                system.settings[name] = GpuSettings(tile, bx, by, bz, "model")
                continue
            tile, bx, by, bz = decl.prefer
            if tile not in decl.tiles:
                tile = min(decl.tiles, key=lambda t: (abs(t - tile), t))
            if bz not in decl.block_z:
                bz = min(decl.block_z)
            source = "preferred" if system.mode == "gpu-aware" else "component's own"
            threads = min(dev.max_work_group_size, decl.max_threads or dev.max_work_group_size)
            while bx * by * bz > threads or bx > dev.max_work_item_sizes[0] \
                    or by > dev.max_work_item_sizes[1] or by > tile \
                    or bx > tile and inst.type.cover == "squares":
                halved = _halve_block(bx, by, decl.square)
                if halved is None:
                    break
                bx, by = halved
                source = "reduced to fit the device"
            problems = limit_problems(tile, bx, by, bz, decl, dev)
            if problems:
                rep.error(inst.pos, f"no GPU settings of '{name}' fit device '{dev.name}': "
                          + "; ".join(problems), "choose a device profile with larger limits")
                continue
            system.settings[name] = GpuSettings(tile, bx, by, bz, source)
        self._distribute(system, rep)
        return system

    @staticmethod
    def _distribute(system, rep):
        """Shrink settings until every group that can run together fits the budget.

        Each round takes the first group over budget and shrinks, among its components
        whose settings the model does not fix, the one with the most resident threads: a
        larger accepted tile first (fewer work-groups, same shape), else half its block
        (largest dimension first).  When nothing in an over-budget group can shrink, the
        budget is impossible: the error names the group.
        """
        total = system.device.total_threads
        asked = system.model.thread_budget
        # the model's budget caps the device's total; it cannot raise it
        budget = min(asked, total) if asked else total
        if asked and asked > total:
            rep.warning(system.model.thread_budget_pos,
                        f"platform.thread_budget {asked:,} is more than device "
                        f"'{system.device.name}' can hold resident ({total:,} threads); "
                        f"using {total:,}", "lower thread_budget, or leave it out to use the "
                        "device's total")
        system.thread_budget = budget
        system.concurrent = concurrent_groups(system)
        reported: set[tuple[str, ...]] = set()
        while True:
            over = [g for g in system.concurrent if g not in reported
                    and sum(resident_threads(system, n) for n in g) > budget]
            if not over:
                return
            group = over[0]
            candidates = sorted((n for n in group if system.settings[n].source != "model"
                                 and _smaller(system, n) is not None),
                                key=lambda n: (-resident_threads(system, n), n))
            if not candidates:
                total = sum(resident_threads(system, n) for n in group)
                fixed = [n for n in group if system.settings[n].source == "model"]
                if len(group) > 1:
                    what = (f"components {', '.join(group)} can run at the same time and "
                            f"together need at least {total} resident threads")
                else:
                    what = f"component {group[0]} needs at least {total} resident threads"
                rep.error(system.components[group[0]].pos,
                          f"{what}, over the thread budget of {budget}"
                          + (f" (settings fixed by the model: {', '.join(fixed)})"
                             if fixed else ""),
                          "raise platform.thread_budget, set smaller gpu_settings, or use "
                          "a device with more threads")
                reported.add(group)
                continue
            name = candidates[0]
            system.settings[name] = _smaller(system, name)


def _smaller(system: System, name: str) -> GpuSettings | None:
    """The next smaller settings of a component (fewer resident threads), or None."""
    s = system.settings[name]
    decl = system.components[name].type.gpu
    # compared uncapped, so that each step makes progress even above the device's total
    now = _resident(system, name, s, capped=False)
    source = "shrunk to share the thread budget"
    for tile in (t for t in decl.tiles if t > s.tile):
        cand = GpuSettings(tile, s.block_x, s.block_y, s.block_z, source)
        if _resident(system, name, cand, capped=False) < now:
            return cand
    bx, by, bz = s.block_x, s.block_y, s.block_z
    while (halved := _halve_block(bx, by, decl.square)) is not None:
        bx, by = halved
        cand = GpuSettings(s.tile, bx, by, bz, source)
        if _resident(system, name, cand, capped=False) < now:
            return cand
    return None


def concurrent_groups(system: System) -> list[tuple[str, ...]]:
    """Maximal groups of GPU-aware components with no path between any two of them.

    These are the maximal cliques of the 'no path either way' graph (Bron-Kerbosch with
    a pivot); pipelines are small, so enumerating them is cheap.
    """
    gpu = [n for n in system.order if n in system.settings]
    below = descendants(system)
    free = {n: {m for m in gpu if m != n and m not in below[n] and n not in below[m]}
            for n in gpu}
    groups: list[tuple[str, ...]] = []

    def expand(clique: set[str], cands: set[str], done: set[str]) -> None:
        if not cands and not done:
            groups.append(tuple(sorted(clique, key=system.order.index)))
            return
        pivot = max(cands | done, key=lambda n: (len(free[n] & cands), n))
        for n in sorted(cands - free[pivot]):
            expand(clique | {n}, cands & free[n], done & free[n])
            cands = cands - {n}
            done = done | {n}

    if gpu:
        expand(set(), set(gpu), set())
    return sorted(groups, key=lambda g: [system.order.index(n) for n in g])


def descendants(system: System) -> dict[str, set[str]]:
    """Every component reachable from each component along connections."""
    succ: dict[str, set[str]] = {n: set() for n in system.components}
    for target, source in system.writers.items():
        succ[source.component].add(target.component)
    below: dict[str, set[str]] = {}
    for n in reversed(system.order):
        below[n] = set().union(*([{m} | below[m] for m in succ[n]] or [set()]))
    return below


def resident_threads(system: System, name: str) -> int:
    """Threads a component keeps resident at once: its work-groups, capped by the device."""
    return _resident(system, name, system.settings[name])


def _resident(system: System, name: str, s: GpuSettings, capped: bool = True) -> int:
    ctype = system.components[name].type
    grid = system.sizes.get(Endpoint(name, ctype.grid))
    if grid is None:
        return s.threads_per_group
    groups = math.ceil(grid.height / s.tile)
    if ctype.cover == "squares":
        groups *= math.ceil(grid.width / s.tile)
    threads = groups * s.threads_per_group
    return min(threads, system.device.total_threads) if capped else threads


def _halve_block(bx: int, by: int, square: bool) -> tuple[int, int] | None:
    """Half the block, largest dimension first (both at once for a square block), or None
    when it cannot shrink."""
    if square:
        return (bx // 2, by // 2) if min(bx, by) > 1 else None
    if bx >= by and bx > 1:
        return bx // 2, by
    if by > 1:
        return bx, by // 2
    return None


def limit_problems(tile, bx, by, bz, decl, dev: DeviceFacts) -> list[str]:
    problems = []
    if tile not in decl.tiles:
        problems.append(f"tile {tile} is not one the kernel accepts {list(decl.tiles)}")
    if bz not in decl.block_z:
        problems.append(f"block_z {bz} is not one the kernel accepts {list(decl.block_z)}")
    if decl.max_threads and bx * by * bz > decl.max_threads:
        problems.append(f"block {bx}x{by}x{bz} = {bx * by * bz} threads is over the "
                        f"{decl.max_threads} the kernel accepts")
    if decl.square and bx != by:
        problems.append(f"block {bx}x{by} is not square, and the kernel accepts only "
                        "block_x == block_y")
    for axis, v, limit in zip("xyz", (bx, by, bz), dev.max_work_item_sizes):
        if v > limit:
            problems.append(f"block_{axis} {v} is over the device's {limit}")
    if bx * by * bz > dev.max_work_group_size:
        problems.append(f"block {bx}x{by}x{bz} = {bx * by * bz} threads is over the device's "
                        f"work-group limit of {dev.max_work_group_size}")
    return problems


class NameVariables(Pass):
    """Variables of generated code: one per port (as in Figure 8) and per adapter, unique."""

    name = "name-variables"

    def apply(self, system, rep):
        taken = set(system.components)
        for adapter in system.adapters:
            taken.add(adapter.name)

        def claim(wanted: str) -> str:
            # the generated code also uses <name>_size: both must be free
            name, i = wanted, 2
            while name in taken or f"{name}_size" in taken:
                name, i = f"{wanted}_{i}", i + 1
            taken.update((name, f"{name}_size"))
            return name

        by_source = {a.source: a for a in system.adapters}
        for comp in system.order:
            inst = system.components[comp]
            for pname in inst.type.outputs:
                end = Endpoint(comp, pname)
                system.output_vars[end] = claim(f"{comp}_{pname}")
                adapter = by_source.get(end)
                if adapter is not None:
                    adapter.output_var = claim(f"{comp}_{pname}_"
                                               f"{'gpu' if adapter.direction == 'cpu2gpu' else 'cpu'}")
        for target, source in system.writers.items():
            adapter = by_source.get(source)
            if adapter is not None and target in adapter.consumers:
                system.input_vars[target] = adapter.output_var
            else:
                system.input_vars[target] = system.output_vars[source]
        # steps: each component in order, preceded by the adapters its inputs need
        done: set[str] = set()
        for comp in system.order:
            for pname in system.components[comp].type.inputs:
                end = Endpoint(comp, pname)
                adapter = by_source.get(system.writers.get(end))
                if adapter is not None and end in adapter.consumers and adapter.name not in done:
                    system.steps.append(Step("adapter", adapter.name))
                    done.add(adapter.name)
            system.steps.append(Step("component", comp))
        return system


class AssignQueues(Pass):
    """Which in-order queue ("lane") runs each GPU command, and what it must wait for.

    parallel: a command continues the lane of its first GPU input whose lane it ends;
    otherwise it takes a lane the host has already waited for, else a new lane.  It waits
    for the events of inputs made on other lanes (unless the host already waited for
    them).  The host waits where it reads a result (GPU-to-CPU adapters, which block) and,
    at the end of a frame, for lane ends no host read covers, so a frame is complete before
    the next one reuses any buffer.  sequential: one lane, every copy blocks.
    """

    name = "assign-queues"

    def apply(self, system, rep):
        adapters = {a.name: a for a in system.adapters}
        by_source = {a.source: a for a in system.adapters}
        producer: dict[str, list[str]] = {}  # GPU command -> GPU commands it reads from
        for step in system.steps:
            if step.kind == "adapter":
                a = adapters[step.name]
                producer[step.name] = [a.source.component] if a.direction == "gpu2cpu" else []
            elif system.components[step.name].type.gpu_aware:
                preds = []
                for pname in system.components[step.name].type.inputs:
                    src = system.writers[Endpoint(step.name, pname)]
                    a = by_source.get(src)
                    name = a.name if a is not None and Endpoint(step.name, pname) in \
                        a.consumers else src.component
                    if name in producer and name not in preds:  # a GPU command
                        preds.append(name)
                producer[step.name] = preds
        # zero-copy GPU-to-CPU adapters unmap after the last step that reads their view
        last_reader: dict[str, str] = {}
        for step in system.steps:
            if step.kind == "component":
                for pname in system.components[step.name].type.inputs:
                    a = by_source.get(system.writers[Endpoint(step.name, pname)])
                    if a is not None and a.zero_copy and a.direction == "gpu2cpu" and \
                            Endpoint(step.name, pname) in a.consumers:
                        last_reader[a.name] = step.name
        for a_name, reader in sorted(last_reader.items()):
            system.unmap_after.setdefault(reader, []).append(a_name)
        sequential = system.execution == "sequential"
        tails: list[str] = []  # last command of each lane
        synced: set[str] = set()  # commands the host knows to be complete
        ancestors: dict[str, set[str]] = {}
        for step in system.steps:
            if step.name not in producer:
                continue
            name, preds = step.name, producer[step.name]
            ancestors[name] = set(preds).union(*(ancestors[p] for p in preds))
            lane = 0 if sequential and tails else next(
                (system.lanes[p] for p in preds if tails[system.lanes[p]] == p), None)
            if lane is None:
                lane = next((i for i, t in enumerate(tails) if t in synced), len(tails))
                if lane == len(tails):
                    tails.append(name)
            tails[lane] = name
            system.lanes[name] = lane
            system.waits[name] = [p for p in preds if system.lanes[p] != lane
                                  and p not in synced]
            a = adapters.get(name)
            if system.mode == "standard" or (sequential and a is not None and not a.zero_copy):
                # a blocking copy on the one in-order queue: everything before it is done
                synced |= set(system.lanes)
            elif a is not None and (a.direction == "gpu2cpu" or a.zero_copy):
                # a host read blocks (and a zero-copy upload enqueues nothing)
                synced |= {name} | (ancestors[name] if a.direction == "gpu2cpu" else set())
        system.frame_end_waits = [t for t in tails if t not in synced]
        return system


PIPELINE: tuple[Pass, ...] = (CheckConnections(), CheckPortTypes(), Schedule(),
                             PropagateSizes(), InsertAdapters(), AllocateGpu(), NameVariables(),
                             AssignQueues())


def run_passes(model: SystemModel, device: DeviceFacts, mode: str = "gpu-aware",
               dump: Any = None, execution: str | None = None,
               zero_copy: str | None = None) -> tuple[System, list]:
    """Run every pass and return the system and its warnings, or raise with every problem.

    Once a pass has found errors, only the checking passes that cope with a partly checked
    system still run (Pass.runs_after_errors); the others are skipped.
    execution ("parallel" | "sequential") and zero_copy ("auto" | "on" | "off") override
    the model's platform settings (the command line's --execution and --zero-copy).
    """
    execution = execution or model.execution
    zero_copy = zero_copy or model.zero_copy
    if execution not in EXECUTIONS or zero_copy not in ZERO_COPY:
        raise ValueError(f"execution {execution!r}, zero_copy {zero_copy!r}")
    system = System(model, device, mode, "sequential" if mode == "standard" else execution)
    if mode == "standard":
        system.zero_copy_reason = "standard mode: components copy their own data"
    elif zero_copy == "auto":
        system.zero_copy = device.host_unified_memory
        system.zero_copy_reason = (f"auto: device {'has' if system.zero_copy else 'has no'} "
                                   "unified host memory")
    else:
        system.zero_copy = zero_copy == "on"
        system.zero_copy_reason = "forced by the model or the command line"
    rep = Reporter()
    for p in PIPELINE:
        if rep.has_errors and not p.runs_after_errors:
            continue
        system = p.apply(system, rep)
        if dump is not None:
            dump(f"// after {p.name}\n{system.dump()}\n")
    if rep.has_errors:
        raise GpucompgenError(_unique(rep.diagnostics))
    return system, rep.warnings


def _unique(diagnostics: list) -> list:
    return sorted(set(diagnostics))


def passes_names() -> Iterable[str]:
    return [p.name for p in PIPELINE]
