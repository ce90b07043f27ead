"""allocate-gpu: the system, not the component, decides each GPU component's settings."""

from __future__ import annotations

import math

from ..ir import ComponentNode, GpuSettings, GroupNode, System
from ..model import Endpoint
from ..runtime.facts import DeviceFacts
from .base import Pass


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
            inst = system.nodes[name]
            if not (isinstance(inst, (ComponentNode, GroupNode)) and inst.on_gpu):
                continue
            decl = inst.type.gpu
            # a group takes the settings the model gives its root, else another member's
            given = ([name] if isinstance(inst, ComponentNode) else
                     [m.name for m in reversed(inst.members)])
            given = [n for n in given if n in overrides]
            if given and system.mode == "gpu-aware":
                values, pos = overrides[given[0]]
                tile, bx, by, bz = (values.get(k, d) for k, d in zip(
                    ("tile", "block_x", "block_y", "block_z"), decl.prefer))
                problems = limit_problems(tile, bx, by, bz, decl, dev)
                for p in problems:
                    if "kernel" in p:
                        kernel = (f"the kernel of '{inst.type.name}'" if given[0] == name
                                  else f"the kernel of fused group {name}")
                        hint = f"{kernel} accepts {decl.accepts()}"
                    else:
                        hint = (f"device '{dev.name}' allows work-groups of at most "
                                f"{dev.max_work_group_size} threads, "
                                f"{list(dev.max_work_item_sizes)} per dimension")
                    owner = given[0] if given[0] == name else \
                        f"{given[0]}, which runs in fused group {name}"
                    rep.error(pos, f"gpu_settings of '{owner}': {p}", hint)
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
                rep.error(system.nodes[group[0]].pos,
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
    decl = system.gpu_node(name).type.gpu
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
    a pivot); pipelines are small, so enumerating them is usually cheap.
    Their number can grow exponentially with parallel branches (k branches of L
    components: L^k groups), so enumeration stops after MAX_CONCURRENT_GROUPS: then every
    GPU component is taken to run at the same time as every other, one group that
    over-approximates them all (settings may come out smaller than needed, never too large).
    """
    gpu = [n for n in system.order if n in system.settings]
    below = descendants(system)
    free = {n: {m for m in gpu if m != n and m not in below[n] and n not in below[m]}
            for n in gpu}
    groups: list[tuple[str, ...]] = []

    def expand(clique: set[str], cands: set[str], done: set[str]) -> None:
        if not cands and not done:
            groups.append(tuple(sorted(clique, key=system.order.index)))
            if len(groups) > MAX_CONCURRENT_GROUPS:
                raise _TooMany
            return
        pivot = max(cands | done, key=lambda n: (len(free[n] & cands), n))
        for n in sorted(cands - free[pivot]):
            expand(clique | {n}, cands & free[n], done & free[n])
            cands = cands - {n}
            done = done | {n}

    if gpu:
        try:
            expand(set(), set(gpu), set())
        except _TooMany:
            return [tuple(gpu)]
    return sorted(groups, key=lambda g: [system.order.index(n) for n in g])


MAX_CONCURRENT_GROUPS = 64


class _TooMany(Exception):
    """More groups of concurrent components than are worth listing."""


def descendants(system: System) -> dict[str, set[str]]:
    """Every node reachable from each node along edges."""
    succ: dict[str, set[str]] = {n: set() for n in system.nodes}
    for e in system.edges:
        succ[e.source.component].add(e.target.component)
    below: dict[str, set[str]] = {}
    for n in reversed(system.order):
        below[n] = set().union(*([{m} | below[m] for m in succ[n]] or [set()]))
    return below


def resident_threads(system: System, name: str) -> int:
    """Threads a component keeps resident at once: its work-groups, capped by the device."""
    return _resident(system, name, system.settings[name])


def _resident(system: System, name: str, s: GpuSettings, capped: bool = True) -> int:
    ctype = system.gpu_node(name).type
    grid = system.data(Endpoint(name, ctype.grid))
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
