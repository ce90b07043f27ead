"""The OpenCL kernel of a fused group (passes/fuse.py): members' snippets composed.

One readable file per group: a header naming the members; GROUP_PARAMS / GROUP_ARGS, the
group kernel's parameter list (convention.group_parameters) as every member function
takes it; then, per member in run order, its snippet as a ``static inline`` function named
after the component, computing one element (y, x, c) of its output.  Around each function,
each input port's accessor ``<port>(y, x, c)`` is a macro: the producing member's function
when the producer is in the group (index maps compose back to front, values apply front
to back), else a load from the group's input buffer (clamped to the input's edges for a
stencil with border: clamp).  The kernel covers the group's output with the usual
scheme: one work-group a tile x tile square, its threads striding through it, and within
a row the work-items take consecutive bytes (x and channel together), so that a CPU device
vectorizes the stores.
"""

from __future__ import annotations

from ...ir import GroupNode
from ...model import DTYPES
from .convention import group_parameters


def group_kernel(group: GroupNode, header: str) -> str:
    params = group_parameters(group)
    decls = [p.declaration() for p in params if p.role != "tile"]
    args = [p.name for p in params if p.role != "tile"]
    root = group.root
    (out_name, out_port), = group.outputs.items()
    out_c = DTYPES[out_port.dtype][1]
    lines = [f"// {header}",
             f"// Fused group {group.name}: one kernel for "
             + ", ".join(f"{m.name} ({m.type.name}, {m.type.fusable.form})"
                         for m in group.members) + ".",
             (f"// It computes {root.name}.{out_name} from the group's inputs directly: no "
              "buffers between members."),
             "// Each member's snippet is a function of the element (y, x, c) it computes;",
             "// an input read <port>(y, x, c) calls the producing member, or loads from a",
             "// group input.",
             "",
             "#define GROUP_PARAMS \\",
             *(f"    {d}, \\" if i < len(decls) - 1 else f"    {d}" for i, d in enumerate(decls)),
             "",
             "#define GROUP_ARGS \\",
             *(f"    {a}, \\" if i < len(args) - 1 else f"    {a}" for i, a in enumerate(args)),
             ""]
    feeds = {end: port for port, end in group.feeds.items()}
    producer = {e.target: e.source for e in group.internal}
    for m in group.members:
        decl = m.type.fusable
        ctype = DTYPES[next(iter(m.outputs.values())).dtype][1]
        lines.append(f"// {m.name}: {m.type.name} ({decl.form}"
                     + (f", radius {decl.radius}, border {decl.border}" if decl.form == "stencil"
                        else "") + ")")
        macros = []
        for pname, port in m.inputs.items():
            src = producer.get(_end(m.name, pname))
            if src is not None:
                body = f"{src.component}(GROUP_ARGS, (y_), (x_), (c_))"
            else:
                buf = feeds[_end(m.name, pname)]
                h, w = f"{m.name}_{pname}_height", f"{m.name}_{pname}_width"
                yy, xx = "(y_)", "(x_)"
                if decl.form == "stencil" and decl.border == "clamp":
                    yy, xx = f"clamp((y_), 0, {h} - 1)", f"clamp((x_), 0, {w} - 1)"
                body = f"{buf}[{port.channels} * ((size_t){yy} * {w} + {xx}) + (c_)]"
            macros.append(pname)
            lines.append(f"#define {pname}(y_, x_, c_) {body}")
        lines.append(f"static inline {ctype} {m.name}(GROUP_PARAMS, const int y, const int x, "
                     "const int c)")
        lines.append("{")
        for pname in list(m.inputs) + list(m.outputs):
            lines.append(f"    const int {pname}_height = {m.name}_{pname}_height, "
                         f"{pname}_width = {m.name}_{pname}_width;")
        for pname, pdecl in m.type.params.items():
            c = "float" if pdecl.type == "float" else "int"
            lines.append(f"    const {c} {pname} = {m.name}_{pname};")
        for line in decl.body.splitlines():
            lines.append(f"    {line}".rstrip())
        lines.append("}")
        lines += [f"#undef {p}" for p in macros]
        lines.append("")
    channels = out_port.channels
    out_buf = f"{root.name}_{out_name}"
    h, w = f"{root.name}_{out_name}_height", f"{root.name}_{out_name}_width"
    lines += [
        f"__kernel void {group.name}(GROUP_PARAMS, const int tile)",
        "{",
        "    const int x0 = get_group_id(0) * tile;",
        "    const int y0 = get_group_id(1) * tile;",
        f"    const int x_end = min(x0 + tile, {w});",
        f"    const int y_end = min(y0 + tile, {h});",
        f"    // the bytes of a tile's row, x and channel together: {channels} a pixel",
        f"    const int i_end = (x_end - x0) * {channels};",
        "    const int threads = get_local_size(0) * get_local_size(1);",
        "    const int lid = get_local_id(1) * get_local_size(0) + get_local_id(0);",
        "    for (int y = y0; y < y_end; y++) {",
        f"        __global {out_c} *row = {out_buf} + ((size_t)y * {w} + x0) * {channels};",
        "        for (int i = lid; i < i_end; i += threads)",
        f"            row[i] = {root.name}(GROUP_ARGS, y, x0 + i / {channels}, i % {channels});",
        "    }",
        "}",
        ""]
    return "\n".join(lines)


def _end(component: str, port: str):
    from ...model import Endpoint

    return Endpoint(component, port)
