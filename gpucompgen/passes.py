"""Passes: each has one job, takes the System and returns it, reporting problems.

    check-connections → check-port-types → schedule → propagate-sizes → insert-adapters
    → allocate-gpu → name-variables

``gpucompgen build --print-between-passes`` dumps the System after each pass.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Any, Iterable

from . import sizeexpr
from .device import DeviceFacts
from .errors import GpucompgenError, Pos, Reporter
from .model import DTYPES, Endpoint, Instance, SystemModel

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
    writers: dict[Endpoint, Endpoint] = field(default_factory=dict)  # input → producing output
    readers: dict[Endpoint, list[Endpoint]] = field(default_factory=dict)  # output → inputs
    order: list[str] = field(default_factory=list)
    sizes: dict[Endpoint, Size] = field(default_factory=dict)
    adapters: list[Adapter] = field(default_factory=list)
    settings: dict[str, GpuSettings] = field(default_factory=dict)
    stages: dict[str, int] = field(default_factory=dict)
    steps: list[Step] = field(default_factory=list)
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
                         + ", ".join(map(str, a.consumers)))
        for name, s in sorted(self.settings.items()):
            lines.append(f"  config_gpu {name}: tile={s.tile} block=({s.block_x}, "
                         f"{s.block_y}, {s.block_z}) [{s.source}]")
        for step in self.steps:
            lines.append(f"  step {step.kind} {step.name}")
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
            if end in system.writers or system.components[end.component].type.port(
                    end.port).direction == "out":
                if size.nbytes > system.device.max_mem_alloc_size and \
                        system.components[end.component].type.gpu_aware:
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
                    consumers=crossing, size=system.sizes[src]))
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
                    if "kernel accepts" in p:
                        hint = (f"the kernel of '{inst.type.name}' accepts tile "
                                f"{' or '.join(map(str, decl.tiles))} and block_z "
                                f"{' or '.join(map(str, decl.block_z))}")
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
            while bx * by * bz > dev.max_work_group_size or bx > dev.max_work_item_sizes[0] \
                    or by > dev.max_work_item_sizes[1] or by > tile \
                    or bx > tile and inst.type.cover == "squares":
                if bx >= by and bx > 1:
                    bx //= 2
                elif by > 1:
                    by //= 2
                else:
                    break
                source = "reduced to fit the device"
            problems = limit_problems(tile, bx, by, bz, decl, dev)
            if problems:
                rep.error(inst.pos, f"no GPU settings of '{name}' fit device '{dev.name}': "
                          + "; ".join(problems), "choose a device profile with larger limits")
                continue
            system.settings[name] = GpuSettings(tile, bx, by, bz, source)
        self._check_budget(system, rep)
        return system

    @staticmethod
    def _check_budget(system, rep):
        budget = system.model.thread_budget or system.device.total_threads
        by_stage: dict[int, list[str]] = {}
        for name, s in system.settings.items():
            by_stage.setdefault(system.stages.get(name, 0), []).append(name)
        for stage, names in sorted(by_stage.items()):
            total = sum(resident_threads(system, n) for n in names)
            if total > budget and len(names) > 1:
                rep.error(system.components[sorted(names)[0]].pos,
                          f"components {', '.join(sorted(names))} can run at the same time "
                          f"and together need {total} resident threads, over the thread "
                          f"budget of {budget}",
                          "raise platform.thread_budget or set smaller gpu_settings")


def resident_threads(system: System, name: str) -> int:
    """Threads a component keeps resident at once: its work-groups, capped by the device."""
    s = system.settings[name]
    ctype = system.components[name].type
    grid = system.sizes.get(Endpoint(name, ctype.grid))
    if grid is None:
        return s.threads_per_group
    groups = math.ceil(grid.height / s.tile)
    if ctype.cover == "squares":
        groups *= math.ceil(grid.width / s.tile)
    return min(groups * s.threads_per_group, system.device.total_threads)


def limit_problems(tile, bx, by, bz, decl, dev: DeviceFacts) -> list[str]:
    problems = []
    if tile not in decl.tiles:
        problems.append(f"tile {tile} is not one the kernel accepts {list(decl.tiles)}")
    if bz not in decl.block_z:
        problems.append(f"block_z {bz} is not one the kernel accepts {list(decl.block_z)}")
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


PIPELINE: tuple[Pass, ...] = (CheckConnections(), CheckPortTypes(), Schedule(),
                             PropagateSizes(), InsertAdapters(), AllocateGpu(), NameVariables())


def run_passes(model: SystemModel, device: DeviceFacts, mode: str = "gpu-aware",
               dump: Any = None) -> tuple[System, list]:
    """Run every pass and return the system and its warnings, or raise with every problem.

    Once a pass has found errors, only the checking passes that cope with a partly checked
    system still run (Pass.runs_after_errors); the others are skipped.
    """
    system = System(model, device, mode)
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
