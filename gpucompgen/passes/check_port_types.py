"""check-port-types: both ends of an edge carry the same element type and channels."""

from __future__ import annotations

from .base import Pass


class CheckPortTypes(Pass):
    name = "check-port-types"
    runs_after_errors = True

    def apply(self, system, rep):
        for edge in system.edges:
            out = system.nodes[edge.source.component].port(edge.source.port)
            inp = system.nodes[edge.target.component].port(edge.target.port)
            if out.dtype != inp.dtype:
                rep.error(edge.pos, f"element type mismatch: '{edge.source}' gives "
                          f"{out.dtype}, '{edge.target}' takes {inp.dtype}",
                          "insert a component that converts, or change a port's dtype")
            if out.channels != inp.channels:
                rep.error(edge.pos, f"channel mismatch: '{edge.source}' gives "
                          f"{out.channels} channel(s), '{edge.target}' takes {inp.channels}",
                          "insert a component that converts, or connect another port")
        return system
