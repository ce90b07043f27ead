"""place: where each flexible component runs, the GPU or the CPU.

A flexible type has a kernel and a CPU function (``kind: flexible``).  Each of its
components runs where it is asked — ``--place NAME=SIDE`` on the command line, its own
``placement:``, ``platform.placement`` — and those asked ``auto`` are placed together,
minimising the estimated time of one frame.  A component nobody asked is placed **for the
device's class** (``DeviceFacts.kind``: the model's ``platform.device``, ``--device``):
as ``auto`` where the class is known, on the GPU where it is not (the 'portable' profile,
the checked-in examples: the paper's default).  The frame time:

    frame time = sum over auto components of compute(component, side)
               + sum over producing ports whose data crosses memories of transfer(bytes)

A producing port crosses when a reader sits on the other side (one adapter serves every
reader there, as insert-adapters makes it); in standard mode a GPU component copies each
of its inputs and outputs itself.  transfer(bytes) = latency + bytes / bandwidth per copy
(latency only with zero-copy adapters: nothing is copied).  compute() comes from the
model's profile (``platform.profile``, written by ``gpucompgen tune``), else from the
estimate of the device's class below (PLACEMENT_COSTS).  Up to EXHAUSTIVE_LIMIT auto components every combination is
tried; beyond, a greedy start (all on the GPU and all on the CPU) improved by moving one
component at a time while that lowers the estimate, the better of the two kept.  Ties go
to the GPU (the default placement).

The pass runs after propagate-sizes (the costs need the bytes) and before
insert-adapters (which puts adapters wherever neighbours are now on different sides).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import Diagnostic, GpucompgenError, Reporter
from ..ir import ComponentNode, System
from ..loader import MAX_FILE_BYTES, FileProblem, load_text, read_text
from ..model import Endpoint
from .base import Pass
from .fuse import load_measured

EXHAUSTIVE_LIMIT = 16
# the largest time (µs) or bandwidth (MB/s) a profile may give: 1e12 µs is 11 days a frame
MAX_PROFILE_NUMBER = 1e12
# The estimate used without a profile, one row per device class (DeviceFacts.kind; the
# table and its measurements are in docs/placement.md).  A component reads its inputs and
# writes its outputs once, at the side's bytes a second; a CPU form also costs the
# generated loop's call of it (cpu_call_s: the call, the check of the frame it returns);
# a kernel costs a launch (enqueue to done, as the generated loop waits for it); a copy
# between memories costs its latency plus its bytes at the transfer's rate (zero-copy
# adapters: the latency only).
# - "cpu": a CPU OpenCL device (PoCL) runs on the cores the CPU forms (OpenCV) use.  The
#   CPU forms move 8 to 58 GB/s through these 2 cores, median 14 GB/s
#   (benchmarks/cpu_forms.py, 640x360: bytes read and written over the call's time), and
#   the loop pays about 6 µs a CPU form (benchmarks/frame_cost.py: N mirrors on the CPU,
#   8x8 frames, 5.8 µs a component).  The kernels' rate and launch are fitted to
#   benchmarks/pipelines.py's ten cells (device fusion off less all CPU, against the
#   kernels' count and bytes: 52 µs a kernel, 23 GB/s), with PoCL's threads pinned
#   (POCL_AFFINITY, runtime/opencl.py); unpinned, kernels ran at one core's speed for
#   long stretches and the row said 45 µs and 3.5 GB/s.  The fit misses a cell by 17%
#   (root mean square, 0% to 31%): "error", the margin a placement putting a chain's
#   components on the device must win by (weigh_chains);
# - "integrated-gpu": a Jetson-class board: slower cores, a GPU sharing their memory;
# - "discrete-gpu": a GPU behind PCIe: fast kernels, every crossing a copy;
# - "": no class known (`placement: auto` on the 'portable' profile): the first static
#   estimate, numpy-speed CPU forms.
# Recalibrate with `gpucompgen tune` on the device (its profile replaces these figures
# for one model) or benchmarks/pipelines.py (all CPU against the device's variants).
PLACEMENT_COSTS: dict[str, dict[str, float]] = {
    "cpu": {"cpu_bytes_per_s": 14e9, "cpu_call_s": 6e-6, "gpu_bytes_per_s": 23e9,
            "gpu_launch_s": 52e-6, "transfer_bytes_per_s": 5e9, "transfer_latency_s": 10e-6,
            "error": 0.17},
    # the GPU rows: not measured, so no fitted error to state (0)
    "integrated-gpu": {"cpu_bytes_per_s": 2e9, "cpu_call_s": 6e-6, "gpu_bytes_per_s": 20e9,
                       "gpu_launch_s": 20e-6, "transfer_bytes_per_s": 10e9,
                       "transfer_latency_s": 10e-6, "error": 0.0},
    "discrete-gpu": {"cpu_bytes_per_s": 5e9, "cpu_call_s": 6e-6, "gpu_bytes_per_s": 200e9,
                     "gpu_launch_s": 10e-6, "transfer_bytes_per_s": 12e9,
                     "transfer_latency_s": 10e-6, "error": 0.0},
    "": {"cpu_bytes_per_s": 1e9, "cpu_call_s": 0.0, "gpu_bytes_per_s": 20e9,
         "gpu_launch_s": 20e-6, "transfer_bytes_per_s": 6e9, "transfer_latency_s": 10e-6,
         "error": 0.0},
}
STATIC = PLACEMENT_COSTS[""]


def a_device(kind: str) -> str:
    """'a cpu device', 'an integrated-gpu device': how plan names a device class."""
    return f"{'an' if kind[:1] in 'aeiou' else 'a'} {kind} device"


def estimate_source(kind: str) -> str:
    """How plan names the estimate of a device class."""
    return f"estimate for {a_device(kind)}" if kind else "static estimate"


@dataclass(frozen=True)
class Cost:
    """Estimated time per frame of one component on each side, in seconds."""

    cpu_s: float
    gpu_s: float
    source: str  # "profile" | "estimate for a cpu device" | ... | "static estimate"


@dataclass
class Chain:
    """A chain of flexible fusable components weighed whole (weigh_chains): on the CPU,
    each its CPU form; on the device, the groups the fuse pass would make of them."""

    members: tuple[str, ...]
    side: str  # where the chain was placed: "gpu" | "cpu" | "mixed" (per component)
    cpu_s: float  # the frame's estimate with the chain on the CPU
    gpu_s: float  # ... with the chain on the device, as its groups
    chosen_s: float  # ... as placed
    # on the device: each group of two or more members: (members, whether chosen (all its
    # members placed on the device), what its one kernel
    # saves a frame over its members' kernels apart, fused_s, apart_s of the group's
    # kernel and its members' as estimated or measured, where those come from)
    groups: tuple[tuple[tuple[str, ...], bool, float, float, float, str], ...] = ()
    # a placement with members on the device was taken at (1 + margin) its estimate: the
    # estimate's error (PLACEMENT_COSTS "error"; 0 where tune measured every member)
    margin: float = 0.0

    def why(self, name: str, side: str) -> str:
        """Why one member runs on side, as the plan says it."""
        why = f"its chain weighed whole: {self.where}"
        if side == "cpu":
            return why + ("" if self.side == "cpu" else ", this one on the CPU")
        group = next((g for g in self.groups if name in g[0] and g[1]), None)
        return why + (f", one kernel with {', '.join(m for m in group[0] if m != name)}"
                      if group else ", its own kernel")

    @property
    def where(self) -> str:
        return {"gpu": "on the device", "cpu": "on the CPU", "mixed": "split"}[self.side]

    def lines(self) -> list[str]:
        """The chain's decision with its figures, and every group it weighed."""
        inside = {m for g in self.groups for m in g[0] if m in self.members}
        kernels = len(self.groups) + len(self.members) - len(inside)
        out = [(f"chain {', '.join(self.members)}: {self.where}; frame est. "
                f"{_ms(self.chosen_s)} (with the chain on the CPU {_ms(self.cpu_s)}, on the "
                f"device {_ms(self.gpu_s)} as {kernels} kernel{'s' * (kernels != 1)}"
                + (f"; the device must win by the estimate's error, {self.margin:.0%}"
                   if self.margin else "") + ")")]
        for members, chosen, saved, fused, apart, source in self.groups:
            verdict = "chosen" if chosen else "refused"
            out.append(f"  group {'+'.join(members)} {verdict}: one kernel saves {_ms(saved)} "
                       f"a frame over its members apart ({apart / fused:.2f}x: fused "
                       f"{_ms(fused)}, apart {_ms(apart)}; {source})")
        return out


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3f} ms"


@dataclass
class Placement:
    """How the flexible components were placed, for the plan."""

    decided: dict[str, tuple[str, str]] = field(default_factory=dict)  # name -> (side, by)
    costs: dict[str, Cost] = field(default_factory=dict)
    transfer: tuple[float, float, str] = (0.0, 0.0, "")  # latency s, bytes/s, source
    # auto only: the estimated frame time of the choice and of the alternatives
    estimate_s: float | None = None
    all_gpu_s: float | None = None
    all_cpu_s: float | None = None
    search: str = ""  # "exhaustive over 2^n" | "greedy + local improvement"
    # auto only: each chain of fusable components weighed whole (weigh_chains)
    chains: list[Chain] = field(default_factory=list)

    def lines(self) -> list[str]:
        out = []
        chain_of = {m: c for c in self.chains for m in c.members}
        for name, (side, by) in self.decided.items():
            c = self.costs.get(name)
            est = (f"; est. CPU {c.cpu_s * 1e3:.3f} ms, GPU {c.gpu_s * 1e3:.3f} ms "
                   f"({c.source})" if c else "")
            chain = chain_of.get(name)
            if chain is not None:
                est += f"; {chain.why(name, side)}"
            out.append(f"{name}: {side.upper()} (by {by}{est})")
        for chain in self.chains:
            out += chain.lines()
        if self.estimate_s is not None:
            lat, bw, src = self.transfer
            out.append(f"auto ({self.search}): est. {self.estimate_s * 1e3:.3f} ms a frame "
                       f"(all on GPU {self.all_gpu_s * 1e3:.3f} ms, all on CPU "
                       f"{self.all_cpu_s * 1e3:.3f} ms); transfers {lat * 1e6:.1f} µs + "
                       f"{bw / 1e6:,.0f} MB/s per copy ({src})")
        return out


class Place(Pass):
    name = "place"

    def apply(self, system, rep):
        flexible = [n for n in system.components.values() if n.type.flexible]
        placement = Placement()
        kind = system.device.kind
        for node in flexible:
            if node.asked in ("gpu", "cpu"):
                node.place(node.asked, system.mode)
            elif node.asked == "default" and not kind:  # no class known: the paper's GPU
                node.place("gpu", system.mode)
        # asked auto, or nobody asked and the device's class is known: placed together
        auto = [n for n in flexible if n.asked == "auto" or n.asked == "default" and kind]
        if auto:
            profile = read_profile(system, rep)
            load_measured(system, rep)  # tune's groups: weigh_chains prices them so
            model = CostModel(system, profile)
            for node in flexible:
                placement.costs[node.name] = model.compute(node)
            placement.transfer = model.transfer_facts()
            sides, search = choose(model, [n.name for n in auto])
            # priced with its groups, all on one side may beat the search's choice: start
            # from the least of the three, then weigh each chain whole
            start = min((sides, dict.fromkeys(sides, "gpu"), dict.fromkeys(sides, "cpu")),
                        key=lambda o: round(model.frame_fused(o), 12))
            if start is not sides:
                search += (f"; all on the {next(iter(start.values())).upper()}, priced with "
                           "the groups the fuse pass makes, cheaper than its choice")
            sides, placement.chains = weigh_chains(model, start)
            for node in auto:
                node.place(sides[node.name], system.mode)
            placement.estimate_s = model.frame_fused(sides)
            placement.all_gpu_s = model.frame_fused(dict.fromkeys(sides, "gpu"))
            placement.all_cpu_s = model.frame_fused(dict.fromkeys(sides, "cpu"))
            placement.search = search
        for node in flexible:
            by = node.placed_by
            if node.asked == "auto":
                by = "auto"
            elif node.asked == "default" and kind:
                by = node.placed_by = f"default for {a_device(kind)}"
            placement.decided[node.name] = (node.placement, by)
        system.placement = placement
        return system


# --------------------------------------------------------------------------- cost model

class CostModel:
    """Estimated frame time of a placement of a system's auto components."""

    def __init__(self, system: System, profile: dict | None = None):
        self.system = system
        self.profile = profile or {}
        kind = system.device.kind if system.device is not None else ""
        self.costs = PLACEMENT_COSTS.get(kind, STATIC)
        self.source = estimate_source(kind)
        t = self.profile.get("transfer")
        if t:
            self.latency, self.bandwidth, self.transfer_source = t[0], t[1], "profile"
        else:
            self.latency = self.costs["transfer_latency_s"]
            self.bandwidth = self.costs["transfer_bytes_per_s"]
            self.transfer_source = self.source
        self._compute = {n.name: self.compute(n) for n in system.components.values()
                         if n.type.flexible}
        self._groups: dict[tuple, list[list[str]]] = {}

    def transfer_facts(self) -> tuple[float, float, str]:
        return self.latency, self.bandwidth, self.transfer_source

    def transfer_s(self, nbytes: int) -> float:
        if self.system.zero_copy and self.system.mode != "standard":
            return self.latency
        return self.latency + nbytes / self.bandwidth

    def compute(self, node: ComponentNode) -> Cost:
        measured = self.profile.get("components", {}).get(node.name)
        if measured is not None:
            return Cost(measured[0], measured[1], "profile")
        nbytes = sum(p.data.nbytes for p in node.ports if p.data is not None)
        k = self.costs
        return Cost(k["cpu_call_s"] + nbytes / k["cpu_bytes_per_s"],
                    k["gpu_launch_s"] + nbytes / k["gpu_bytes_per_s"], self.source)

    def side(self, name: str, sides: dict[str, str]) -> str:
        if name in sides:
            return sides[name]
        node = self.system.nodes[name]
        return node.placement if isinstance(node, ComponentNode) else "cpu"

    def frame(self, sides: dict[str, str]) -> float:
        """Compute of the placed components + transfers the placement causes."""
        total = sum(getattr(self._compute[n], f"{s}_s") for n, s in sides.items())
        system = self.system
        if system.mode == "standard":  # a GPU component copies its own data both ways
            for name, node in system.components.items():
                if self.side(name, sides) == "gpu":
                    total += sum(self.transfer_s(p.data.nbytes) for p in node.ports
                                 if p.data is not None)
            return total
        for name, node in system.components.items():
            here = self.side(name, sides)
            for pname, port in node.outputs.items():
                readers = system.readers(Endpoint(name, pname))
                if port.data is not None and any(self.side(r.component, sides) != here
                                                 for r in readers):
                    total += self.transfer_s(port.data.nbytes)
        return total

    # ---- fused groups: what the fuse pass makes of the components placed on the GPU

    def groups(self, sides: dict[str, str]) -> list[list[str]]:
        """The groups of two or more members the fuse pass would make with sides taken
        (fuse.choose_groups, asked with these sides; none when fusion is off)."""
        from .fuse import choose_groups

        system = self.system
        if system.fusion == "off" or system.mode == "standard":
            return []
        key = tuple(sorted(sides.items()))
        if key not in self._groups:
            def on_gpu(name):
                node = system.nodes.get(name)
                return isinstance(node, ComponentNode) and self.side(name, sides) == "gpu"
            found, _ = choose_groups(system, on_gpu)
            self._groups[key] = [g for g in found if len(g) > 1]
        return self._groups[key]

    def saving(self, members: list[str]) -> tuple[float, float, float, str]:
        """(seconds a frame the group's one kernel saves over its members' kernels apart,
        fused_s, apart_s, where the figures come from).  Where tune timed the group and its
        members (the profile), the group's kernel is its measured time.  Else the group
        takes fused_s / apart_s of its members' GPU times (compute()): the ratio tune
        measured where the profile has the group, else the fusion cost
        model's (passes/fuse.py FUSION_COSTS: the intermediate frames neither stored nor
        loaded, launches saved, less what the group computes again) with its fused time
        taken at the model's median error more (its row's 'error'): a gain the estimate
        claims counts only beyond what the estimate is known to miss by."""
        from .fuse import _measured, estimate, fusion_costs

        measured = _measured(self.system, set(members))
        if measured is not None:
            (fused, apart), source, error = measured, "measured by tune", 0.0
        else:
            (fused, apart) = estimate(self.system, set(members))
            error = fusion_costs(self.system).get("error", 0.0)
            source = (f"fusion estimate for {a_device(self.system.device.kind or 'cpu')}, "
                      f"fused taken {1 + error:.2f}x")
        members_s = sum(self._compute[m].gpu_s if m in self._compute else 0.0
                        for m in members)
        if measured is not None and all(
                m in self._compute and self._compute[m].source == "profile" for m in members):
            # the group's own time, timed with its members: not its ratio times theirs,
            # which would carry a burst of load one member's timing caught
            return members_s - fused, fused, apart, source
        ratio = min(1.0, fused * (1 + error) / apart) if apart > 0 else 1.0
        return members_s * (1 - ratio), fused, apart, source

    def margin(self, members) -> float:
        """How much a placement putting members on the device must win by: the device
        class's estimate error, none where tune measured every member."""
        if all(self._compute[m].source == "profile" for m in members if m in self._compute):
            return 0.0
        return self.costs["error"]

    def frame_fused(self, sides: dict[str, str]) -> float:
        """frame(), each group the fuse pass would make on the GPU counted as one kernel:
        its members' GPU times less what the group saves (saving())."""
        return self.frame(sides) - sum(self.saving(g)[0] for g in self.groups(sides))


def chains(model: CostModel, names: list[str]) -> list[list[str]]:
    """The maximal chains among names: components of a fusable type that the model lets
    fuse, connected by their connections (a DAG: a fan-in or fan-out stays one chain) or
    through a fusable component that runs on the GPU whoever placed it (a merger asked
    for the GPU, with the detector it feeds: one kernel with it), each in run order, its
    members the components of names: those with a fusable neighbour."""
    system = model.system

    def fusable(n):
        node = system.nodes[n]
        return isinstance(node, ComponentNode) and node.type.fusable is not None and \
            node.fuse and (n in names or node.on_gpu)
    movable = set(names)
    link: dict[str, set[str]] = {}
    for e in system.edges:
        a, b = e.source.component, e.target.component
        if (a in movable or b in movable) and fusable(a) and fusable(b):
            link.setdefault(a, set()).add(b)
            link.setdefault(b, set()).add(a)
    at = {n: i for i, n in enumerate(system.order)}
    found, seen = [], set()
    for n in sorted(link, key=at.get):
        if n in seen or n not in movable:
            continue
        chain, todo = set(), [n]
        while todo:
            m = todo.pop()
            if m not in chain:
                chain.add(m)
                todo += link.get(m, ()) if m in movable else ()
        seen |= chain
        found.append(sorted(chain & movable, key=at.get))
    return found


def weigh_chains(model: CostModel, sides: dict[str, str]) -> tuple[dict[str, str], list]:
    """Placement priced component by component never sees that components placed together
    on the device become one kernel.  So each maximal chain of fusable components is
    weighed whole: as placed, all on the CPU (each its CPU form), all on the device (the
    groups the fuse pass would make of it, each one kernel: frame_fused()), and each of
    those groups alone on the device; the least estimated frame is kept (ties: as placed).
    Returns the sides and a Chain record for each chain weighed, for the plan."""
    if model.system.fusion == "off" or model.system.mode == "standard":
        return sides, []
    records = []
    for chain in chains(model, list(sides)):
        on_cpu = {**sides, **dict.fromkeys(chain, "cpu")}
        on_gpu = {**sides, **dict.fromkeys(chain, "gpu")}
        mine = [g for g in model.groups(on_gpu) if set(g) & set(chain)]
        margin = model.margin(chain)
        options = [(model.frame_fused(sides), 0, sides), (model.frame_fused(on_gpu), 1, on_gpu),
                   (model.frame_fused(on_cpu), 2, on_cpu)]
        options += [(model.frame_fused(alone), 3 + i, alone) for i, alone in enumerate(
            {**on_cpu, **{m: "gpu" for m in g if m in sides}} for g in mine
            if not set(chain) <= set(g))]
        best_s, _, best = min(options, key=lambda o: (
            round(_weighed(o[0], o[2], chain, margin), 12), o[1]))
        placed = {best[m] for m in chain}
        side = placed.pop() if len(placed) == 1 else "mixed"
        groups = tuple((tuple(g), all(model.side(m, best) == "gpu" for m in g),
                        *model.saving(g)) for g in mine)
        records.append(Chain(tuple(chain), side, options[2][0], options[1][0], best_s,
                             groups, margin))
        sides = best
    return sides, records


def _weighed(option_s: float, sides: dict[str, str], chain: list[str], margin: float) -> float:
    """A placement's estimate as weigh_chains compares it: with any of the chain on the
    device, taken at (1 + margin): the device must win by the estimate's error."""
    return option_s * (1 + margin) if any(sides[m] == "gpu" for m in chain) else option_s


def choose(model: CostModel, names: list[str]) -> tuple[dict[str, str], str]:
    """The sides of names with the lowest estimated frame time (ties: more on the GPU)."""
    def key(sides):
        return (round(model.frame(sides), 12), sum(s == "cpu" for s in sides.values()))

    if len(names) <= EXHAUSTIVE_LIMIT:
        return (min(_near_best(model, names), key=key),
                f"exhaustive over {2 ** len(names):,} placements")
    results = []
    for start in ("gpu", "cpu"):
        sides = dict.fromkeys(names, start)
        improved = True
        while improved:
            improved = False
            for n in names:
                trial = {**sides, n: "cpu" if sides[n] == "gpu" else "gpu"}
                if key(trial) < key(sides):
                    sides, improved = trial, True
        results.append(sides)
    return min(results, key=key), "greedy + local improvement"


# Placements whose frame time, summed over all placements at once, is within this of the
# best are compared again exactly (key() rounds to 1e-12 s; numpy's sums differ from
# frame()'s by far less than this).
NEAR_BEST_S = 1e-9


def _near_best(model: CostModel, names: list[str]) -> list[dict[str, str]]:
    """The placements of names, in itertools.product(("gpu", "cpu")) order, whose frame
    time is within NEAR_BEST_S of the best: the only ones min(key) can pick.

    Each placement's frame time is model.frame()'s sum, computed for all 2^n placements at
    once, one column of numpy booleans (on the CPU) per component, with every producing
    port's readers looked up once: 2^16 placements take milliseconds, where calling
    frame() for each (rescanning components and edges) took minutes.
    """
    import numpy as np

    n = len(names)
    index = np.arange(2 ** n, dtype=np.int64)
    on_cpu = {name: (index >> (n - 1 - i)) & 1 == 1 for i, name in enumerate(names)}

    def cpu(name: str):
        return on_cpu[name] if name in on_cpu else model.side(name, {}) == "cpu"

    total = np.zeros(2 ** n)
    for name in names:
        c = model._compute[name]
        total += np.where(on_cpu[name], c.cpu_s, c.gpu_s)
    system = model.system
    for name, node in system.components.items():
        here = cpu(name)
        if system.mode == "standard":  # a GPU component copies its own data both ways
            cost = sum(model.transfer_s(p.data.nbytes) for p in node.ports
                       if p.data is not None)
            total += np.where(here, 0.0, cost)
            continue
        for pname, port in node.outputs.items():
            readers = system.readers(Endpoint(name, pname))
            if port.data is None or not readers:
                continue
            crosses = np.zeros(2 ** n, dtype=bool)
            for r in readers:
                crosses |= cpu(r.component) != here
            total += np.where(crosses, model.transfer_s(port.data.nbytes), 0.0)
    near = np.flatnonzero(total <= total.min() + NEAR_BEST_S)
    return [{name: "cpu" if on_cpu[name][i] else "gpu" for name in names} for i in near]


# --------------------------------------------------------------------------- profiles

def default_profile(model) -> Path:
    """Where `gpucompgen tune` writes a model's profile when the model names none."""
    return model.file.parent / "tune" / f"{model.name}.yaml"


def profile_path(model) -> Path | None:
    """The profile placement: auto reads: the model's platform.profile, else the file
    `gpucompgen tune` writes for it (tune/<system>.yaml beside the model) when it exists,
    else None (the static estimate)."""
    if model.profile is not None:
        return model.profile
    default = default_profile(model)
    return default if default.is_file() else None


def read_profile(system: System, rep: Reporter) -> dict | None:
    """The profile profile_path() finds, for placement (an error where the model names one
    that is missing); the build's output records it (--check sees a new one)."""
    profile = load_profile(system, rep, required=True)
    if profile is not None:
        record_profile(system, profile)
    return profile


def record_profile(system: System, profile: dict) -> None:
    """The build used the profile: its output records the file's digest."""
    path, text = profile["file"]
    system.model.add_input(path, text)


def load_profile(system: System, rep: Reporter, required: bool) -> dict | None:
    """The profile profile_path() finds as {"components": {name: (cpu_s, gpu_s)},
    "transfer": (latency_s, bytes_per_s), "groups": {frozenset(members): (fused_s, apart_s,
    sizes)}, "file": (path, text)}, read once a build (the place and fuse passes share it);
    problems are reported at their position.  A missing file is an error where required
    (placement asks for it), else no profile."""
    cached = system.profile_cache
    if cached is not None:
        return cached or None
    result = _read_profile(system, rep, required)
    if result is not None or required:
        system.profile_cache = result or {}
    return result


def _measured_elsewhere(system: System, rep: Reporter, doc, data: dict) -> bool:
    """A profile times one device: built for another device that was queried (--device
    auto, `gpucompgen run`), its figures would place for the wrong machine, so the build
    warns and decides by the estimate of the device's class instead.  Built for a named
    device profile (the checked-in default), the model's profile is taken as the user's
    statement of the target."""
    from ..device import PROFILES

    device = system.device
    measured_on = data.get("device")
    if device is None or not isinstance(measured_on, str) or \
            device.name in {p.name for p in PROFILES.values()} or \
            measured_on.strip() == device.name.strip():
        return False
    rep.warning(doc.pos("device"), f"this profile was measured on {measured_on!r}, not on "
                f"the device this build is for ({device.name.strip()!r}): its figures are "
                f"left out and the {estimate_source(device.kind)} decides instead",
                f"rerun 'gpucompgen tune {system.model.display}' on this device")
    return True


def _read_profile(system: System, rep: Reporter, required: bool) -> dict | None:
    model = system.model
    path: Path | None = profile_path(model)
    if path is None:
        return None
    if not path.is_file():
        if not required:
            return None
        rel = os.path.relpath(path, model.file.parent)
        rep.error(model.profile_pos, f"profile {rel!r} not found (paths are relative to the "
                  "model)", f"write it with 'gpucompgen tune {model.display}'")
        return None
    shown = str(Path(model.display).parent / os.path.relpath(path, model.file.parent))
    try:
        text = read_text(path, MAX_FILE_BYTES, "profile")
    except FileProblem as exc:
        raise GpucompgenError([Diagnostic(shown, exc.line, exc.col, "error", exc.message,
                                          exc.hint)]) from None
    doc = load_text(text, shown)
    data = doc.data
    if not isinstance(data, dict):
        rep.error(doc.pos(), "a profile is a mapping written by 'gpucompgen tune'",
                  f"rewrite it with 'gpucompgen tune {model.display}'")
        return None
    if _measured_elsewhere(system, rep, doc, data):
        return None
    result: dict = {"components": {}, "groups": {}, "file": (path, text)}

    def number(path_, value, what) -> float | None:
        # an int of any length is compared as an int: float() of a 400-digit one overflows
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                (isinstance(value, float) and not math.isfinite(value)) or \
                not 0 <= value <= MAX_PROFILE_NUMBER:
            said = "a number over 1e+20" if isinstance(value, int) and \
                abs(value) >= 10 ** 20 else repr(value)
            rep.error(doc.pos(*path_), f"{what} must be a number from 0 to "
                      f"{MAX_PROFILE_NUMBER:.0e}, not {said}",
                      f"rewrite the profile with 'gpucompgen tune {model.display}'")
            return None
        return float(value)

    groups = data.get("groups")
    if isinstance(groups, dict):
        _read_groups(system, rep, doc, groups, result, number)
    elif groups is not None:
        rep.error(doc.pos("groups"), "groups must be a mapping of group names to their "
                  "members, fused_us and apart_us",
                  f"rewrite the profile with 'gpucompgen tune {model.display}'")
    t = data.get("transfer")
    if isinstance(t, dict):
        lat = number(("transfer", "latency_us"), t.get("latency_us"), "transfer.latency_us")
        bw = number(("transfer", "bandwidth_mb_s"), t.get("bandwidth_mb_s"),
                    "transfer.bandwidth_mb_s")
        if lat is not None and bw:
            result["transfer"] = (lat * 1e-6, bw * 1e6)
    elif t is not None:
        rep.error(doc.pos("transfer"), "transfer must be a mapping of latency_us and "
                  "bandwidth_mb_s")
    comps = data.get("components")
    if not isinstance(comps, dict):
        rep.error(doc.pos("components") if "components" in data else doc.pos(),
                  "the profile lists no components",
                  f"rewrite it with 'gpucompgen tune {model.display}'")
        return result
    _read_components(system, rep, doc, comps, result, number)
    return result


def _read_components(system: System, rep: Reporter, doc, comps: dict, result: dict,
                     number) -> None:
    """Each flexible component's CPU and kernel times, where measured at today's sizes."""
    for name, entry in comps.items():
        node = system.nodes.get(name) if isinstance(name, str) else None
        if not isinstance(node, ComponentNode) or not node.type.flexible:
            rep.warning(doc.key_pos("components", name),
                        f"the profile times '{name}', which is no flexible component of "
                        f"'{system.name}'", "rerun 'gpucompgen tune' after changing the model")
            continue
        if not isinstance(entry, dict):
            rep.error(doc.pos("components", name), f"profile entry of '{name}' must be a "
                      "mapping of cpu_us and gpu_us")
            continue
        cpu = number(("components", name, "cpu_us"), entry.get("cpu_us"), "cpu_us")
        gpu = number(("components", name, "gpu_us"), entry.get("gpu_us"), "gpu_us")
        sizes = entry.get("sizes")
        now = sizes_text(system, node)
        if sizes is not None and sizes != now:
            rep.warning(doc.pos("components", name, "sizes"),
                        f"'{name}' was timed at {sizes}, the model now gives {now}: its "
                        "static estimate is used", "rerun 'gpucompgen tune'")
            continue
        if cpu is not None and gpu is not None:
            result["components"][name] = (cpu * 1e-6, gpu * 1e-6)


def _read_groups(system: System, rep: Reporter, doc, groups: dict, result: dict,
                 number) -> None:
    """The groups tune measured against their members apart: {frozenset(members):
    (fused_s, apart_s, sizes)}; a group naming a component the system lacks is skipped
    with a warning (the model changed), one whose sizes changed is kept with its sizes,
    for the fuse pass to compare."""
    for name, entry in groups.items():
        members = entry.get("members") if isinstance(entry, dict) else None
        if not isinstance(members, list) or not members or \
                not all(isinstance(m, str) for m in members):
            rep.error(doc.pos("groups", name), f"profile group '{name}' must be a mapping "
                      "of members (a list of component names), fused_us and apart_us",
                      f"rewrite the profile with 'gpucompgen tune {system.model.display}'")
            continue
        missing = [m for m in members if not isinstance(system.nodes.get(m), ComponentNode)]
        if missing:
            rep.warning(doc.pos("groups", name, "members"),
                        f"the profile's group '{name}' has {', '.join(missing)}, no "
                        f"component of '{system.name}'", "rerun 'gpucompgen tune' after "
                        "changing the model")
            continue
        fused = number(("groups", name, "fused_us"), entry.get("fused_us"), "fused_us")
        apart = number(("groups", name, "apart_us"), entry.get("apart_us"), "apart_us")
        sizes = entry.get("sizes")
        if fused is not None and apart is not None:
            result["groups"][frozenset(members)] = (fused * 1e-6, apart * 1e-6,
                                                     sizes if isinstance(sizes, str) else None)


def sizes_text(system: System, node: ComponentNode) -> str:
    """A component's port sizes as a profile records them: 'in 480x640x3 -> out 480x...'."""
    def side(ports):
        return ", ".join(f"{p.data.height}x{p.data.width}x{p.data.channels}"
                         for p in ports.values() if p.data is not None)
    return f"{side(node.inputs)} -> {side(node.outputs)}"
