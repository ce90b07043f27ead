"""The OpenCL kernel of a fused group (passes/fuse.py): members' snippets composed.

One readable file per group: a header naming the members; GROUP_PARAMS / GROUP_ARGS, the
group kernel's parameter list (convention.group_parameters) as every member function
takes it; then, per member in run order, its snippet as a ``static inline`` function named
after the component, computing one element (y, x, c) of its output.  Around each function,
each input port's accessor ``<port>(y, x, c)`` is a macro: the producing member's function
when the producer is in the group (index maps compose back to front, values apply front
to back), else a load from the group's input buffer.

What makes it fast (it must cost about what one unfused component costs, whatever the
number of members):

- Every function is visible to the compiler and inlined, and every size is a constant:
  the system fixed the sizes when it was built, so the text states them.  A chain of
  index maps then folds to one index expression (a mirror of a mirror reads
  ``h - 1 - (h - 1 - y)``, which is ``y``), and nothing is computed per member.
- No clamp and no bounds test on an access that is in range by construction: pointwise
  members read the element they compute, index maps read in-range positions for every
  in-range output element (their contract, as for a kernel), and the kernel only
  computes output elements inside the frame.  The one clamp is where a stencil with
  ``border: clamp`` reads its input: a window reaches outside the frame at the edges.
- The grid covers whole rows (as the VerticalMirror kernel): a work-group computes
  ``tile`` rows, its block_y threads take them in turn and its block_x threads split
  each row into contiguous runs of pixels.  A work-item computes a pixel's channels
  together and stores them as one vector (vstore3 for three channels), which a CPU
  device turns into wide copies.
"""

from __future__ import annotations

from ...ir import GroupNode
from ...model import DTYPES, Endpoint
from .convention import group_parameters

VECTOR_WIDTHS = (2, 3, 4, 8, 16)  # OpenCL C vector types: a pixel stored at once


def group_kernel(group: GroupNode, header: str) -> str:
    params = group_parameters(group)
    decls = [p.declaration() for p in params if p.role != "tile"]
    args = [p.name for p in params if p.role != "tile"]
    root = group.root
    (out_name, out_port), = group.outputs.items()
    lines = [f"// {header}",
             f"// Fused group {group.name}: one kernel for "
             + ", ".join(f"{m.name} ({m.type.name}, {m.type.fusable.form})"
                         for m in group.members) + ".",
             (f"// It computes {root.name}.{out_name} from the group's inputs directly: no "
              "buffers between members."),
             "// Each member's snippet is a function of the element (y, x, c) it computes;",
             "// an input read <port>(y, x, c) calls the producing member, or loads from a",
             "// group input.  Sizes are constants: the system fixed them at build time.",
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
        lines += _member(m, feeds, producer)
    lines += _kernel(group, out_name, out_port)
    return "\n".join(lines)


def _member(m, feeds: dict[Endpoint, str], producer: dict[Endpoint, Endpoint]) -> list[str]:
    """A member's snippet as a function, between the macros of its input accessors."""
    decl = m.type.fusable
    ctype = DTYPES[next(iter(m.outputs.values())).dtype][1]
    lines = [f"// {m.name}: {m.type.name} ({decl.form}"
             + (f", radius {decl.radius}, border {decl.border}" if decl.form == "stencil"
                else "") + ")"]
    macros = []
    for pname, port in m.inputs.items():
        src = producer.get(Endpoint(m.name, pname))
        yy, xx = "(y_)", "(x_)"
        if decl.form == "stencil" and decl.border == "clamp":
            h, w = port.data.height, port.data.width
            yy, xx = f"clamp((y_), 0, {h - 1})", f"clamp((x_), 0, {w - 1})"
        if src is not None:
            body = f"{src.component}(GROUP_ARGS, {yy}, {xx}, (c_))"
        else:
            buf = feeds[Endpoint(m.name, pname)]
            body = f"{buf}[{port.channels} * ((size_t){yy} * {port.data.width} + {xx}) + (c_)]"
        macros.append(pname)
        lines.append(f"#define {pname}(y_, x_, c_) {body}")
    lines.append(f"static inline {ctype} {m.name}(GROUP_PARAMS, const int y, const int x, "
                 "const int c)")
    lines.append("{")
    for pname, port in {**m.inputs, **m.outputs}.items():
        lines.append(f"    const int {pname}_height = {port.data.height}, "
                     f"{pname}_width = {port.data.width};")
    for pname, pdecl in m.type.params.items():
        c = "float" if pdecl.type == "float" else "int"
        lines.append(f"    const {c} {pname} = {m.name}_{pname};")
    lines += [f"    {line}" for line in decl.lines()]  # printed from the parsed snippet
    lines.append("}")
    lines += [f"#undef {p}" for p in macros]
    lines.append("")
    return lines


def _kernel(group: GroupNode, out_name: str, out_port) -> list[str]:
    """The kernel: rows of the output, a run of pixels per work-item, a pixel at once."""
    root = group.root
    channels = out_port.channels
    out_c = DTYPES[out_port.dtype][1]
    out_buf = f"{root.name}_{out_name}"
    h, w = out_port.data.height, out_port.data.width
    call = f"{root.name}(GROUP_ARGS, y, x, {{c}})"
    if channels == 1:
        store = ["            row[x] = " + call.format(c=0) + ";"]
        what = "one channel"
    elif channels in VECTOR_WIDTHS:
        values = ", ".join(call.format(c=c) for c in range(channels))
        store = [f"            vstore{channels}(({out_c}{channels})(",
                 *_wrap(values, " " * 16), "                x, row);"]
        what = f"{channels} channels stored as one {out_c}{channels}"
    else:
        store = [f"            for (int c = 0; c < {channels}; c++)",
                 f"                row[{channels} * x + c] = " + call.format(c="c") + ";"]
        what = f"{channels} channels"
    return [
        f"// {h} rows of {w} pixels, {what} a pixel.  Work-group g computes the rows",
        "// [g * tile, g * tile + tile); its block_y threads take them in turn, its block_x",
        "// threads each a contiguous run of pixels of the row.",
        f"__kernel void {group.name}(GROUP_PARAMS, const int tile)",
        "{",
        "    const int y0 = get_group_id(1) * tile;",
        f"    const int y1 = min(y0 + tile, {h});",
        "    const int nx = get_local_size(0);",
        f"    const int per = ({w} + nx - 1) / nx;",
        f"    const int x0 = min((int)get_local_id(0) * per, {w});",
        f"    const int x1 = min(x0 + per, {w});",
        "    for (int y = y0 + get_local_id(1); y < y1; y += get_local_size(1)) {",
        f"        __global {out_c} *row = {out_buf} + (size_t)y * {w * channels};",
        "        for (int x = x0; x < x1; x++)",
        *store,
        "    }",
        "}",
        ""]


def _wrap(text: str, indent: str, width: int = 92) -> list[str]:
    """Comma-separated values over lines of at most width characters, each ending ','."""
    lines, line = [], ""
    for part in text.split(", "):
        if line and len(indent) + len(line) + len(part) + 2 > width:
            lines.append(f"{indent}{line},")
            line = part
        else:
            line = f"{line}, {part}" if line else part
    lines.append(f"{indent}{line}),")
    return lines
