"""What `gpucompgen types` prints: the component types a model can use, as gst-inspect does.

Without a name, one line per type (name, kind, what it takes and gives, first sentence of
its description), the library's grouped by family, a model's own by the file that
declares it; with a name, the type in full: where it is declared, its description, ports,
parameters, requirements, forms (the ways it can run) and an example of its connections.

``forms`` lists each way a type can run as (label, detail) rows, so a new form (a fusable
snippet) is one more row.
"""

from __future__ import annotations

import ast
import textwrap
from collections.abc import Mapping

from .model import ComponentType, ParamDecl, PortDecl, py_yaml

WIDTH = 100  # columns of the listing
LABEL = 16  # width of the label column in the full view


def summary(ctype: ComponentType) -> str:
    """The description's first sentence (or the whole of a short one)."""
    text = " ".join(ctype.description.split())
    end = text.find(". ")
    return text if end < 0 else text[:end + 1]


FAMILY_TITLES = {"colour": "colour", "filters": "filters", "morphology": "morphology",
                 "geometry": "geometry", "arithmetic": "arithmetic and thresholds",
                 "features": "features", "io": "I/O: sources and sinks"}


MAX_PORTS_COLUMN = 22  # characters of the widest signature the column is sized for


def listing(types: Mapping[str, ComponentType]) -> list[str]:
    """Every type, one line each: the library's by family (colour, filters, ...; those
    without one by file), then the model's own by file.  Each line shows what the type
    takes and gives (element types, channels; 1|3 a choice, 'same' following the input),
    and a deprecated name says what it names."""
    groups: dict[tuple[int, int, str], list[tuple[str, ComponentType]]] = {}
    families = list(FAMILY_TITLES)
    for name, ctype in types.items():  # by the name a model writes (lib.Name: shadowed)
        if ctype.origin == "library" and ctype.family:
            key = (0, families.index(ctype.family), FAMILY_TITLES[ctype.family])
        else:
            key = (0 if ctype.origin == "library" else 1, len(families), _source(ctype))
        groups.setdefault(key, []).append((name, ctype))
    name_width = max((len(n) for n in types), default=0) + 2
    # the ports column fits the usual signatures; a longer one (Remap's three inputs) takes
    # room from its own description, not from every line's
    ports_width = min(max((len(signature(t)) for t in types.values()), default=0),
                      MAX_PORTS_COLUMN) + 2
    lines: list[str] = []
    for (_, _, title), members in sorted(groups.items()):
        lines.append(f"{title}:")
        for name, ctype in sorted(members, key=lambda m: (bool(m[1].alias_of), m[1].name)):
            ports = signature(ctype)
            ports += "  " if len(ports) + 2 > ports_width else ""
            head = f"  {name:<{name_width}}{ctype.kind:<11}{ports:<{ports_width}}"
            text = (f"deprecated: {ctype.alias_of} with {ctype.alias_channels} channel"
                    f"{'s' if ctype.alias_channels != 1 else ''}" if ctype.alias_of
                    else summary(ctype))
            room = WIDTH - len(head)
            if len(text) > room:
                text = text[:max(room - 3, 0)].rstrip() + "..."
            lines.append((head + text).rstrip())
        lines.append("")
    lines.append(f"{len(types)} component types; 'gpucompgen types NAME' shows one in full.")
    lines.append("Ports in OpenCV's notation: 8UC3 is uint8, 3 channels; 1|3 either, as fed;")
    lines.append("* any element type or channel count; an output without C has its input's")
    lines.append("channels, 'same' its input's element type and channels.")
    return lines


DEPTHS = {"uint8": "8U", "int8": "8S", "uint16": "16U", "int16": "16S", "int32": "32S",
          "uint32": "32U", "float32": "32F"}  # OpenCV's names of element types


def signature(ctype: ComponentType) -> str:
    """What a type takes and gives in OpenCV's notation: '8UC1|3 -> 16S' (8-bit, 1 or 3
    channels in; int16 out, with the input's channels), '8UC3, 8UC1 ->' (a sink), '->
    8UC3' (a source), '2 x 8UC1|3' (a second input like the first)."""
    def port(p: PortDecl) -> str:
        dtype = "" if p.dtype_of else "|".join(DEPTHS[d] for d in p.dtypes or (p.dtype,))
        if p.dtype_param:
            dtype = f"D({p.dtype_param})"
        if len(p.dtypes) == len(DEPTHS):  # 'dtype: any'
            dtype = "*"
        if p.channels_of:
            channels = ""
        elif p.channels_param:
            channels = f"C({p.channels_param})"
        elif p.any_channels:
            channels = "C*"
        else:
            channels = "C" + "|".join(map(str, p.channel_counts or (p.channels,)))
        if p.dtypes and channels:
            channels = " " + channels
        return f"{dtype}{channels}" or "same"

    ins = [port(p) for p in ctype.inputs.values() if not (p.dtype_of or p.channels_of)]
    if ins and len(ins) < len(ctype.inputs):
        ins[0] = f"{len(ctype.inputs) - len(ins) + 1} x {ins[0]}"
    outs = [port(p) for p in ctype.outputs.values()]
    return f"{', '.join(ins)} -> {', '.join(outs)}".strip()


def example(ctype: ComponentType, name: str | None = None) -> list[str]:
    """A component of the type and its connections, as a model writes them."""
    from .names import snake

    me = snake(ctype.alias_of or ctype.name) if name is None else name
    params = ", ".join(f"{p}: {py_yaml(d.default)}" for p, d in ctype.params.items()
                       if not d.required and d.type in ("int", "float", "bool"))
    required = ", ".join(f"{p}: ..." for p, d in ctype.params.items() if d.required)
    given = ", ".join(x for x in (params, required) if x)
    tname = ctype.alias_of or ctype.name
    one = f"  {me}: {{type: {tname}" + (f", params: {{{given}}}" if given else "") + "}"
    lines = ["components:"]
    if len(one) <= WIDTH - 2:
        lines.append(one)
    else:  # block style, the parameters wrapped
        lines += [f"  {me}:", f"    type: {tname}"]
        lines += textwrap.wrap(f"params: {{{given}}}", WIDTH - 2, initial_indent="    ",
                               subsequent_indent=" " * 13, break_on_hyphens=False)
    conns = []
    for pname, port in ctype.inputs.items():
        conns.append((f"  - <producer>.<port> -> {me}.{pname}",
                      f"{dtypes_text(port)}, {channels_text(port)}"))
    for pname, port in ctype.outputs.items():
        conns.append((f"  - {me}.{pname} -> <consumer>.<port>",
                      f"{dtypes_text(port)}, {channels_text(port)}"))
    if conns:
        width = max(len(c) for c, _ in conns) + 2
        lines.append("connections:")
        lines += [f"{c:<{width}}# {what}" for c, what in conns]
    return lines


def details(ctype: ComponentType) -> list[str]:
    """One type in full."""
    lines = [*_row("Name", ctype.name), *_row("Kind", _kind(ctype)),
             *_row("Declared in", f"{ctype.pos.file}:{ctype.pos.line}"
                                   + (" (library)" if ctype.origin == "library" else ""))]
    lines += _row("Description", " ".join(ctype.description.split()) or "(none)")
    if ctype.alias_of:
        lines += _row("Deprecated", f"a name of {ctype.alias_of}"
                      + (f" with {ctype.alias_channels} channel"
                         f"{'s' if ctype.alias_channels != 1 else ''}"
                         if ctype.alias_channels else "")
                      + f": write 'type: {ctype.alias_of}'")
    for title, ports in (("Inputs", ctype.inputs), ("Outputs", ctype.outputs)):
        lines += ["", f"{title}:"]
        for name, port in ports.items():
            lines += _row(f"  {name}", _port(port))
        if not ports:
            lines.append("  (none)")
    lines += ["", "Parameters:"]
    if not ctype.params:
        lines.append("  (none)")
    for name, decl in ctype.params.items():
        lines += _row(f"  {name}", _param(decl))
        if decl.description:
            lines += _row("", decl.description)
    if ctype.requires:
        lines += ["", "Requirements:"]
        for tree, message in ctype.requires:
            lines += _row("", f"{ast.unparse(tree.body)}: {message}")
    lines += ["", "Forms:"]
    for label, detail in forms(ctype):
        first, *code = detail.split("\n")
        lines += _row(f"  {label}", first)
        lines += _code(code)
    lines += ["", "Example:"] + [f"  {line}" for line in example(ctype)]
    return lines


def forms(ctype: ComponentType) -> list[tuple[str, str]]:
    """The ways the type can run, as (label, detail) rows."""
    rows: list[tuple[str, str]] = []
    if ctype.kernel_file is not None:
        gpu = ctype.gpu
        tile, bx, by, bz = gpu.prefer
        rows.append(("GPU kernel", f"{ctype.kernel_function}() in {ctype.kernel_file.name}; "
                                   f"tiles {', '.join(map(str, gpu.tiles))}; preferred tile "
                                   f"{tile}, block {bx}x{by}x{bz}"
                                   + ("; covers whole rows" if ctype.cover == "rows" else "")))
    elif ctype.gpu_aware and ctype.fusable is not None:
        rows.append(("GPU kernel", ("generated from the fusable form below, for a component "
                                    "alone as for a fused group; the system chooses its "
                                    "settings")))
    if ctype.cpu_file is not None:
        detail = (f"{ctype.cpu_function}() in {ctype.cpu_file.name}, called with the input "
                  "arrays and the parameters as keywords; runs where the model places the "
                  "component (placement: cpu, --place)")
        rows.append(("CPU function", detail))
    if ctype.python_file is not None:
        rows.append(("CPU (python)", f"class {ctype.python_class} in {ctype.python_file.name}"))
    if ctype.fusable is not None:
        f = ctype.fusable
        shape = (f"; window radius {f.radius}, border {f.border}" if f.form == "stencil"
                 else "")
        shape += "".join(f"; table {t} = {fn}({', '.join(args)})"
                         for t, (fn, args) in f.tables.items())
        code = f.value.strip().splitlines()
        head = f"{f.form.replace('_', ' ')}{shape}:"
        # a one-line snippet beside its form; statements one per line below it
        rows.append(("fusable", f"{head} {code[0]}" if len(code) == 1
                     else "\n".join([head, *code])))
    return rows


# -- helpers -----------------------------------------------------------------------------
def _source(ctype: ComponentType) -> str:
    return ctype.pos.file or str(ctype.decl_file)


def _kind(ctype: ComponentType) -> str:
    if ctype.flexible:
        return ("flexible (runs on the GPU or the CPU, as placed: 'placement:' in the model, "
                "--place, or auto; its ports live where it runs)")
    if ctype.gpu_aware:
        return "gpu-aware (runs on the GPU; its GPU ports stay in device memory)"
    return "standard (runs on the CPU)"


def _port(port: PortDecl) -> str:
    memory = "memory where placed" if port.memory == "any" else f"{port.memory.upper()} memory"
    text = f"{memory}, {dtypes_text(port)}, {channels_text(port)}"
    if port.direction == "in":
        text += ", any size"
    elif port.height is None or port.width is None:
        text += ", size: the input's"
    else:
        text += (f", height {ast.unparse(port.height.body)}, "
                 f"width {ast.unparse(port.width.body)}")
    if port.aliases:
        text += f" (old name{'s' if len(port.aliases) > 1 else ''}: {', '.join(port.aliases)})"
    return text


def _either(values) -> str:
    values = [str(v) for v in values]
    return values[0] if len(values) == 1 else ", ".join(values[:-1]) + " or " + values[-1]


def dtypes_text(port: PortDecl) -> str:
    """'uint8', 'uint8, int16 or float32', 'any dtype', 'the dtype of src', 'the dtype of
    parameter ddepth' (OpenCV's depth code)."""
    if port.dtype_of:
        return f"the dtype of {port.dtype_of}"
    if port.dtype_param:
        return f"the dtype of parameter {port.dtype_param}"
    if len(port.dtypes) == len(DEPTHS):
        return "any dtype"
    return _either(port.dtypes or [port.dtype])


def channels_text(port: PortDecl) -> str:
    """'3 channels', '1 or 3 channels', 'any channels', 'the channels of src'."""
    if port.channels_of:
        return f"the channels of {port.channels_of}"
    if port.channels_param:
        return f"channels: parameter {port.channels_param}"
    if port.any_channels:
        return "any channels"
    counts = port.channel_counts or (port.channels,)
    return f"{_either(counts)} channel{'s' if counts != (1,) else ''}"


def _param(decl: ParamDecl) -> str:
    parts = [decl.type]
    parts.append("required" if decl.required else f"default {py_yaml(decl.default)}")
    if decl.minimum is not None or decl.maximum is not None:
        low = "" if decl.minimum is None else _number(decl.minimum)
        high = "" if decl.maximum is None else _number(decl.maximum)
        parts.append(f"range {low}..{high}")
    if decl.aliases:
        parts.append(f"old name{'s' if len(decl.aliases) > 1 else ''}: "
                     + ", ".join(decl.aliases))
    return ", ".join(parts)


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else str(value)


def _code(code: list[str]) -> list[str]:
    """Lines of a snippet as written, indented under the text column; a line too long for
    the listing continues on the next, further indented."""
    lines = []
    for line in code:
        indent = " " * (LABEL + 2 + len(line) - len(line.lstrip()))
        lines += textwrap.wrap(line.strip(), WIDTH, initial_indent=indent,
                               subsequent_indent=indent + "    ",
                               break_on_hyphens=False) or [""]
    return lines


def _row(label: str, text: str) -> list[str]:
    """label in its column, text beside it, wrapped to the listing's width."""
    lines = textwrap.wrap(text, WIDTH - LABEL, break_on_hyphens=False) or [""]
    return [f"{label if i == 0 else '':<{LABEL}}{line}".rstrip()
            for i, line in enumerate(lines)]
