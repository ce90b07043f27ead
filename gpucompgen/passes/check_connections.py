"""check-connections: one writer per input, required inputs fed, nothing left dangling."""

from __future__ import annotations

from ..errors import Pos
from ..ir import ComponentNode, Edge
from ..model import Endpoint
from .base import Pass


class CheckConnections(Pass):
    """Who writes each input: a second writer of an input is reported and its edge dropped."""

    name = "check-connections"
    runs_after_errors = True

    def apply(self, system, rep):
        first: dict[Endpoint, Edge] = {}
        kept: list[Edge] = []
        for edge in system.edges:
            if edge.target in first:
                pos: Pos = first[edge.target].pos
                rep.error(edge.pos, f"input '{edge.target}' has two writers: "
                          f"'{first[edge.target].source}' and '{edge.source}'",
                          f"an input takes one connection (the first is at line "
                          f"{pos.line}); merge the data with a component")
                continue
            first[edge.target] = edge
            kept.append(edge)
        system.edges = kept
        fed = {e.source for e in kept}
        for node in system.nodes.values():
            if not isinstance(node, ComponentNode):
                continue
            connected = False
            for pname in node.inputs:
                end = Endpoint(node.name, pname)
                if end in first:
                    connected = True
                else:
                    rep.error(node.pos, f"input '{end}' is not connected",
                              f"add a connection '<producer>.<port> -> {end}'")
            for pname in node.outputs:
                end = Endpoint(node.name, pname)
                if end in fed:
                    connected = True
                else:
                    rep.warning(node.pos, f"output '{end}' is not connected",
                                "its data is computed every frame and dropped")
            if not connected and (node.inputs or node.outputs):
                rep.warning(node.pos, f"component '{node.name}' is connected to nothing",
                            "connect it or remove it")
        return system
