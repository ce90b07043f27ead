"""resolve-types: every port of every component gets one element type and channel count.

A type's generic ports (``channels: [1, 3]``, ``dtype: [uint8, int16, float32]``,
``channels: src.channels``, ``channels: n``: docs/component-types.md#generic-ports) are
resolved for each component from what feeds it, in the order data flows, as
propagate-sizes does for sizes; afterwards the IR's ports are concrete, so adapters,
generated kernels, buffers and CPU forms see one dtype and channel count per port.  A
frame a generic port does not take is reported on its connection; fixed ports are
check-port-types' to compare.
"""

from __future__ import annotations

from collections import deque

from ..ir import ComponentNode
from ..model import Endpoint
from ..typeresolve import accepts_channels, accepts_dtype, choices_text, resolve_ports
from .base import Pass


class ResolveTypes(Pass):
    name = "resolve-types"
    runs_after_errors = True

    def apply(self, system, rep):
        edges = {e.target: e for e in system.edges}  # check-connections left one each
        for name in _flow_order(system):
            node = system.nodes[name]
            if not isinstance(node, ComponentNode) or not node.type.generic:
                continue
            ctype = node.type
            given = {}
            for pname in node.inputs:
                edge = edges.get(Endpoint(name, pname))
                if edge is not None:
                    port = system.nodes[edge.source.component].port(edge.source.port)
                    given[pname] = (port.dtype, port.channels)
            ports = resolve_ports(ctype, given, node.params)
            for pname, resolved in ports.items():
                decl = ctype.port(pname)
                if pname in given and decl.generic:  # what feeds it, reported if not taken
                    node.port(pname).dtype, node.port(pname).channels = _checked(
                        rep, edges[Endpoint(name, pname)], decl, given[pname], ports,
                        ctype.name)
                else:
                    node.port(pname).dtype, node.port(pname).channels = resolved
            for pname, decl in ctype.outputs.items():
                if decl.channels_param and ports[pname][1] != node.params.get(
                        decl.channels_param):
                    rep.error(node.pos, f"'{name}' ({ctype.name}): parameter "
                              f"'{decl.channels_param}' gives output '{pname}' its channels: "
                              f"it must be 1 or more, not {node.params.get(decl.channels_param)!r}",
                              f"set '{decl.channels_param}' to a channel count")
        return system


def _checked(rep, edge, decl, fed: tuple[str, int], ports, type_name: str) -> tuple[str, int]:
    """What an input of a generic port carries: what feeds it, reported where the port
    does not take it (then the port takes it anyway, so check-port-types, which compares
    the ends of every edge, does not report the same edge again)."""
    dtype, channels = fed
    for i, (kind, value, shown, followed, accepts, convert) in enumerate((
            ("element type", dtype, dtype, decl.dtype_of, accepts_dtype,
             "ConvertScale gives uint8"),
            ("channels", channels, f"{channels} channel(s)", decl.channels_of,
             accepts_channels, "RgbToGray gives 1"))):
        head = (f"{'channel' if i else kind} mismatch: '{edge.source}' gives {shown}, "
                f"'{edge.target}' takes ")
        if followed and value != ports[followed][i]:
            rep.error(edge.pos, head + f"{ports[followed][i]}, the {kind} of "
                      f"'{edge.target.component}.{followed}'",
                      f"{type_name} takes {followed} and {decl.name} with the same {kind}: "
                      f"convert one of them ({convert})")
        elif i and decl.channels_param and value != ports[decl.name][1]:
            rep.error(edge.pos, head + f"{ports[decl.name][1]} (parameter "
                      f"'{decl.channels_param}')", f"set '{decl.channels_param}: {value}', or "
                      "connect another port")
        elif not accepts(decl, value):
            rep.error(edge.pos, head + choices_text(decl, "channels" if i else "dtype"),
                      f"insert a component that converts ({convert}), or connect another "
                      "port")
    return dtype, channels


def _flow_order(system) -> list[str]:
    """The nodes, producers before consumers (Kahn's order, ties in the model's order);
    the nodes of a cycle (schedule reports it) last, in the model's order."""
    succ: dict[str, list[str]] = {n: [] for n in system.nodes}
    indeg = dict.fromkeys(system.nodes, 0)
    for e in system.edges:
        succ[e.source.component].append(e.target.component)
        indeg[e.target.component] += 1
    ready = deque(n for n, d in indeg.items() if d == 0)
    order = []
    while ready:
        n = ready.popleft()
        order.append(n)
        for m in succ[n]:
            indeg[m] -= 1
            if indeg[m] == 0:
                ready.append(m)
    done = set(order)
    return order + [n for n in system.nodes if n not in done]
