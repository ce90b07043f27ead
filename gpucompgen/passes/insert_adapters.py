"""insert-adapters: a node that moves data between CPU and GPU on every edge that crosses.

One adapter per producing port whose data must cross (its consumers on the other side
share it); the edges to those consumers now leave the adapter.  In the run order the
adapter comes just before its first consumer.
"""

from __future__ import annotations

from ..ir import AdapterNode, ComponentNode, Edge, Port
from ..model import Endpoint
from .base import Pass


class InsertAdapters(Pass):
    name = "insert-adapters"

    def apply(self, system, rep):
        count = 0
        for comp in list(system.order):
            node = system.nodes[comp]
            if not isinstance(node, ComponentNode):
                continue
            for pname, port in node.outputs.items():
                src = Endpoint(comp, pname)
                crossing = [e for e in system.edges if e.source == src and
                            system.nodes[e.target.component].port(e.target.port).memory
                            != port.memory]
                if not crossing or port.data is None:
                    continue
                count += 1
                direction = "cpu2gpu" if port.memory == "cpu" else "gpu2cpu"
                adapter = insert_adapter(system, src, crossing,
                                         system.unique_name(f"adapter{count}_{direction}"))
                adapter.zero_copy = system.zero_copy
        return system


def insert_adapter(system, src: Endpoint, crossing: list[Edge], name: str) -> AdapterNode:
    """Put an adapter between src and the consumers of these edges (a transform of the IR)."""
    port = system.nodes[src.component].port(src.port)
    other = "gpu" if port.memory == "cpu" else "cpu"
    adapter = AdapterNode(
        name, system.nodes[src.component].pos,
        {"input": Port("input", "in", port.memory, port.dtype, port.channels, port.data)},
        {"output": Port("output", "out", other, port.dtype, port.channels, port.data)},
        direction="cpu2gpu" if port.memory == "cpu" else "gpu2cpu", source=src)
    system.add_node(adapter)
    for edge in crossing:
        edge.source = Endpoint(name, "output")
    at = system.edges.index(crossing[0])
    system.edges.insert(at, Edge(src, Endpoint(name, "input"), crossing[0].pos, port.data))
    if system.order:
        first = min(system.order.index(e.target.component) for e in crossing)
        system.order.insert(first, name)
    if src.component in system.stages:
        system.stages[name] = system.stages[src.component]
    return adapter
