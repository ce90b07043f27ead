"""propagate-sizes: from the sources' parameters down the graph, every port gets its Data."""

from __future__ import annotations

import ast

from .. import sizeexpr
from ..ir import ComponentNode, Data, Size
from ..model import DTYPES, Endpoint
from .base import Pass


class PropagateSizes(Pass):
    name = "propagate-sizes"
    runs_after_errors = True

    def apply(self, system, rep):
        for name in system.order:
            node = system.nodes[name]
            in_sizes: dict[str, tuple[int, ...]] = {}  # height, width, channels, itemsize
            complete = True
            for pname, port in node.inputs.items():
                src = system.writer(Endpoint(name, pname))
                data = system.data(src) if src is not None else None
                if data is None:
                    complete = False
                    break
                port.data = Data(Size(data.height, data.width, port.channels), port.dtype)
                in_sizes[pname] = (data.height, data.width, port.channels,
                                   DTYPES[port.dtype][2])
            for edge in system.edges:
                if edge.target.component == name:
                    edge.data = system.data(edge.source)
            if not complete:
                continue
            if isinstance(node, ComponentNode):
                self._outputs(system, node, in_sizes, rep)
            else:  # an adapter: its output is its input, in the other memory
                for port in node.outputs.values():
                    port.data = next(iter(node.inputs.values())).data
        for end, data in system.sizes.items():
            node = system.nodes[end.component]
            # every port of a GPU component is a device buffer (its own or an adapter's)
            if isinstance(node, ComponentNode) and node.on_gpu and \
                    data.nbytes > system.device.max_mem_alloc_size:
                rep.error(node.pos, f"'{end}' needs {data.nbytes:,} bytes, more than the "
                          f"device's largest allocation ({system.device.max_mem_alloc_size:,} "
                          "bytes)", "use smaller frames or a device with more memory")
        return system

    @staticmethod
    def _outputs(system, node: ComponentNode, in_sizes, rep) -> None:
        ctype, name = node.type, node.name
        int_params = {k: v for k, v in node.params.items() if ctype.params[k].type == "int"}
        ok = True
        for tree, message in ctype.requires:
            try:
                if not sizeexpr.evaluate(tree, in_sizes, int_params):
                    rep.error(node.pos, *_unmet(name, ctype.name, message, tree, in_sizes))
                    ok = False
            except sizeexpr.SizeExprError as exc:
                rep.error(node.pos, f"'{name}': {exc}")
                ok = False
        if not ok:
            return
        for pname, port in node.outputs.items():
            decl = ctype.outputs[pname]
            if decl.height is None or decl.width is None:
                continue
            try:
                h = sizeexpr.evaluate(decl.height, in_sizes, int_params)
                w = sizeexpr.evaluate(decl.width, in_sizes, int_params)
            except sizeexpr.SizeExprError as exc:
                rep.error(node.pos, f"'{name}.{pname}': {exc}")
                continue
            if h < 1 or w < 1:
                rep.error(node.pos, f"output '{name}.{pname}' would be {h}x{w}",
                          "sizes must be positive; check parameters and inputs")
                continue
            # bounded in bytes as well as per side, CPU ports as GPU ports: a frame no
            # machine could hold is refused here, not by an allocation at run time
            problem = sizeexpr.frame_problem(h, w, port.channels, DTYPES[port.dtype][2])
            if problem:
                rep.error(node.pos, f"output '{name}.{pname}': {problem}",
                          "use smaller frames; check parameters and inputs")
                continue
            port.data = Data(Size(h, w, port.channels), port.dtype)


def _shown(port: str, size: tuple[int, int, int], tree) -> str:
    """'src is 7x10', with the channels where the requirement compares them."""
    h, w, channels, itemsize = size
    text = ast.unparse(tree.body)
    return f"{port} is {h}x{w}" + (f" with {channels} channel" + "s" * (channels != 1)
                                   if f"{port}.channels" in text else "") \
        + (f" of {itemsize}-byte elements" if f"{port}.itemsize" in text else "")


def _unmet(name: str, tname: str, message: str, tree, in_sizes) -> tuple[str, str]:
    """The message and hint of a requirement not met: the sizes it reads shown, and the
    hint naming what it depends on (parameters only, sizes only, or both)."""
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    ports = [p for p in in_sizes if p in names]
    if not ports:  # a requirement on the parameters alone
        return f"'{name}' ({tname}): {message}", "change the parameters"
    shown = ", ".join(_shown(p, in_sizes[p], tree) for p in ports)
    return (f"'{name}' ({tname}): {message} ({shown})",
            "change the parameters or what feeds it"
            if ".channels" in ast.unparse(tree.body) or names - set(ports)
            else "change the sizes of what feeds it")
