"""schedule: a topological run order of the nodes, and each node's stage."""

from __future__ import annotations

import heapq

from ..ir import ComponentNode, System
from .base import Pass


def _rank(system: System, name: str) -> int:
    node = system.nodes[name]
    return node.order if isinstance(node, ComponentNode) else 1 << 30


class Schedule(Pass):
    """Ties follow the order of components in the model; a cycle is an error."""

    name = "schedule"
    runs_after_errors = True

    def apply(self, system, rep):
        nodes = system.nodes
        succ: dict[str, set[str]] = {n: set() for n in nodes}
        indeg = dict.fromkeys(nodes, 0)
        for e in system.edges:
            if e.target.component not in succ[e.source.component]:
                succ[e.source.component].add(e.target.component)
                indeg[e.target.component] += 1
        heap = [(_rank(system, n), n) for n, d in indeg.items() if d == 0]
        heapq.heapify(heap)
        order = []
        while heap:
            _, n = heapq.heappop(heap)
            order.append(n)
            for m in succ[n]:
                indeg[m] -= 1
                if indeg[m] == 0:
                    heapq.heappush(heap, (_rank(system, m), m))
        if len(order) != len(nodes):
            cycle = _find_cycle({n: s for n, s in succ.items() if indeg[n] > 0}, system)
            rep.error(nodes[cycle[0]].pos,
                      "the connections form a cycle: " + " -> ".join(cycle + cycle[:1]),
                      "pipe-and-filter systems are acyclic; remove one of these connections")
            return system
        system.order = order
        system.stages = stages(system)
        return system


def stages(system: System) -> dict[str, int]:
    """Longest path from a source: nodes of one stage never depend on each other.

    An adapter shares the stage of the node it serves (it moves that node's data)."""
    stage: dict[str, int] = {}
    for n in system.order:
        preds = system.predecessors(n)
        if system.nodes[n].kind == "adapter":
            stage[n] = max((stage[p] for p in preds), default=1)
        else:
            stage[n] = 1 + max((stage[p] for p in preds), default=0)
    return stage


def _find_cycle(succ: dict[str, set[str]], system: System) -> list[str]:
    start = min(succ, key=lambda n: _rank(system, n))
    path, seen = [start], {start: 0}
    while True:
        nxt = min((m for m in succ[path[-1]] if m in succ), key=lambda n: _rank(system, n))
        if nxt in seen:
            return path[seen[nxt]:]
        seen[nxt] = len(path)
        path.append(nxt)
