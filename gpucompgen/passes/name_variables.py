"""name-variables: the variable of every output port in generated code (as in Figure 8)."""

from __future__ import annotations

from ..ir import AdapterNode
from ..model import Endpoint
from .base import Pass


class NameVariables(Pass):
    """One variable per output port, unique among themselves and the nodes' names; the
    generated code also uses <variable>_size, so both must be free."""

    name = "name-variables"

    def apply(self, system, rep):
        taken = set(system.nodes)

        def claim(wanted: str) -> str:
            name, i = wanted, 2
            while name in taken or f"{name}_size" in taken:
                name, i = f"{wanted}_{i}", i + 1
            taken.update((name, f"{name}_size"))
            return name

        for n in system.order:
            node = system.nodes[n]
            for pname in node.outputs:
                if isinstance(node, AdapterNode):
                    side = "gpu" if node.direction == "cpu2gpu" else "cpu"
                    wanted = f"{node.source.component}_{node.source.port}_{side}"
                else:
                    wanted = f"{n}_{pname}"
                system.output_vars[Endpoint(n, pname)] = claim(wanted)
        return system
