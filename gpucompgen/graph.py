"""The architecture of a checked system as a Graphviz drawing (the paper's Figures 1-3).

gpu-aware mode draws Figure 3: GPU-aware components (double border, green) with their GPU
ports marked, and every generated adapter as a node of its own between the ports it joins.
standard mode draws Figure 1/2: every component standard, no adapters (each GPU-aware
component copies its own data). Edges carry the element type and size of what flows.
A fused group (passes/fuse.py) is a cluster around its members, labelled as the one
kernel it runs; the edges between members are drawn inside it, dashed: no buffer.

The DOT text is written here, deterministically (system order, no timestamps); `dot`
renders .svg and .png.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from .errors import OutputError
from .ir import AdapterNode, ComponentNode, GroupNode, System
from .model import Endpoint

FORMATS = (".dot", ".svg", ".png")


class GraphvizMissing(Exception):
    """`dot` is needed for svg/png and is not on PATH."""


def quote(text: str) -> str:
    """A DOT double-quoted string: backslashes, quotes and line breaks escaped."""
    escaped = str(text).replace("\\", "\\\\").replace('"', '\\"')
    escaped = escaped.replace("\r", "").replace("\n", "\\n")
    return f'"{escaped}"'


def _port(system: System, end: Endpoint) -> str:
    port = system.component(end.component).port(end.port)
    return f"{end.port} [GPU]" if port.memory == "gpu" else end.port


def _drawn(system: System, end: Endpoint, side: str) -> Endpoint:
    """Where an edge's end is drawn: a group's port is its member's (the root's output,
    the member an input feeds)."""
    node = system.nodes[end.component]
    if not isinstance(node, GroupNode):
        return end
    return Endpoint(node.root.name, end.port) if side == "source" else node.feeds[end.port]


def _component_line(name: str, node: ComponentNode, gpu_aware_mode: bool) -> str:
    t = node.type
    if node.on_gpu and gpu_aware_mode:
        label = f"{name}\n{t.name}\nGPU-aware"
        return f"{quote(name)} [label={quote(label)}, peripheries=2, fillcolor=\"#d9f2d9\"];"
    if node.on_gpu:
        label = f"{name}\n{t.name}\nstandard: copies its own GPU data"
        return f"{quote(name)} [label={quote(label)}];"
    label = f"{name}\n{t.name}"
    return f"{quote(name)} [label={quote(label)}];"


def dot_text(system: System) -> str:
    """The DOT source of the system's architecture: its IR's nodes and edges."""
    gpu_aware_mode = system.mode == "gpu-aware"
    figure = "Figure 3" if gpu_aware_mode else "Figures 1 and 2"
    title = f"{system.name} ({system.mode} mode, as in the paper's {figure})"
    lines = [
        f"digraph {quote(system.name)} {{",
        f"  label={quote(title)};",
        "  labelloc=t;",
        "  rankdir=LR;",
        "  ranksep=1.1;",
        "  nodesep=0.5;",
        "  fontname=\"Helvetica\";",
        '  node [shape=box, style="rounded,filled", fillcolor="#f2f2f2", fontname="Helvetica"];',
        ('  edge [fontname="Helvetica", fontsize=10, labelfontsize=9, labeldistance=2.5, '
         'labelangle=20];'),
    ]
    for name in system.order:
        node = system.nodes[name]
        if isinstance(node, AdapterNode):
            arrow = "CPU to GPU" if node.direction == "cpu2gpu" else "GPU to CPU"
            how = "zero-copy" if node.zero_copy else "copy"
            label = f"{name}\ngenerated adapter\n{arrow} {how}"
            lines.append(f"  {quote(name)} [label={quote(label)}, shape=cds, "
                         'style="filled,dashed", fillcolor="#fff2cc"];')
            continue
        if isinstance(node, GroupNode) and len(node.members) == 1:  # a component alone
            lines.append(f"  {_component_line(name, node.root, gpu_aware_mode)}")
            continue
        if isinstance(node, GroupNode):
            label = (f"fused group {name}: one kernel, one launch\n"
                     + " -> ".join(m.name for m in node.members))
            lines += [f"  subgraph {quote('cluster_' + name)} {{",
                      f"    label={quote(label)};",
                      '    style="rounded,dashed";',
                      '    color="#2f7d32";']
            lines += [f"    {_component_line(m.name, m, gpu_aware_mode)}" for m in node.members]
            for e in node.internal:
                lines.append(f"    {quote(e.source.component)} -> {quote(e.target.component)} "
                             f"[style=dashed, label={quote('fused')}, "
                             f"taillabel={quote(_port(system, e.source))}, "
                             f"headlabel={quote(_port(system, e.target))}];")
            lines.append("  }")
            continue
        lines.append(f"  {_component_line(name, node, gpu_aware_mode)}")
    for e in system.edges:
        label = quote(str(e.data) if e.data else "")
        attrs = [f"label={label}"]
        source, target = _drawn(system, e.source, "source"), _drawn(system, e.target, "target")
        if not isinstance(system.nodes[e.source.component], AdapterNode):
            attrs.append(f"taillabel={quote(_port(system, source))}")
        if not isinstance(system.nodes[e.target.component], AdapterNode):
            attrs.append(f"headlabel={quote(_port(system, target))}")
        lines.append(f"  {quote(source.component)} -> {quote(target.component)} "
                     f"[{', '.join(attrs)}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def write_graph(system: System, path: Path) -> None:
    """Write .dot text, or render .svg/.png with Graphviz's dot."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"unknown graph format '{path.suffix}'; use one of {', '.join(FORMATS)}")
    text = dot_text(system)
    if not path.parent.is_dir():
        raise OutputError(f"cannot write {path}: folder {path.parent} does not exist")
    if suffix == ".dot":
        try:
            path.write_text(text, encoding="utf-8")
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror}") from None
        return
    dot = shutil.which("dot")
    if dot is None:
        raise GraphvizMissing(
            f"drawing {suffix} needs Graphviz's 'dot' program, which is not on PATH; install "
            "Graphviz (apt-get install graphviz, brew install graphviz) or write a .dot file")
    proc = subprocess.run([dot, f"-T{suffix[1:]}", "-o", str(path)], input=text.encode(),
                          capture_output=True, check=False)
    if proc.returncode != 0:
        raise OutputError(f"Graphviz's dot could not write {path}: "
                          f"{proc.stderr.decode(errors='replace').strip()}")
