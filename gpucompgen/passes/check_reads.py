"""check-reads: a stencil reads within the radius it states; a pointwise component's
inputs are at least the size of its output (it reads them at the output's (y, x)).

The generated kernel runs a stencil's interior without border rules on the promise of its
radius (kernelgen/fused.py): a read farther away would load memory outside the input, and
a read whose position is not y and x plus numbers cannot be bounded at all.  For each
stencil component (and each of its stages) at its parameters and sizes, the snippet's
reads are followed through its loops and branches (snippet.reach: the tree is read,
nothing is compiled or run); a read beyond the radius, or one that cannot be bounded, is
an error at the component.
"""

from __future__ import annotations

from ..ir import ComponentNode
from ..snippet import expression_text
from ..snippet import syntax as S
from ..snippet.reach import MAX_STEPS
from .base import Pass


class CheckReads(Pass):
    name = "check-reads"

    def apply(self, system, rep):
        from ..kernelgen.fused import expand, group_of_one, member_reach

        for name in system.order:
            node = system.nodes[name]
            decl = getattr(node.type, "fusable", None) if isinstance(node, ComponentNode) \
                else None
            if decl is None or any(p.data is None for p in (*node.inputs.values(),
                                                             *node.outputs.values())):
                continue
            if decl.form == "pointwise":
                _pointwise(node, rep)
            if decl.form != "stencil":
                continue
            shapes = {p: (q.data.height, q.data.width)
                      for p, q in (*node.inputs.items(), *node.outputs.items())}
            group = group_of_one(node.type, node.params, shapes, name)
            for m in expand(group)[0].members:
                problem = _problem(m, member_reach(m))
                if problem:
                    rep.error(node.pos, f"'{name}' ({node.type.name}): {problem}",
                              "a stencil reads its inputs at y and x plus numbers within "
                              "its radius: declare the radius it reads (radius: in its "
                              "fusable form), or an index_map for positions it computes")
                    break
        return system


def _problem(m, found) -> str | None:
    what = "its stencil" if "." not in m.name else f"its stage '{m.name.split('.')[-1]}'"
    if found.unbounded is not None:
        at = found.unbounded
        if isinstance(at, S.Call):
            return (f"{what} reads {expression_text(at)}, at a position that is not y and "
                    f"x plus numbers: its reads cannot be bounded")
        return (f"{what} has a loop whose course depends on the element's values (or that "
                f"runs more than {MAX_STEPS:,} steps): its reads cannot be bounded")
    ry, rx = m.type.fusable.radii_of(m.params)
    for port in m.inputs:
        rows, cols = found.rows[port], found.cols[port]
        if rows > ry or cols > rx:
            read = expression_text(found.farthest[port])
            return (f"{what} reads {read}, {rows} row(s) and {cols} column(s) away, beyond "
                    f"its radius ({ry} rows, {rx} columns)")
    return None


def _pointwise(node, rep) -> None:
    """A pointwise snippet reads each input at its output's (y, x): an input smaller than
    the output would be read outside (a size given in the type's outputs, say)."""
    (out,) = node.outputs.values()
    h, w = out.data.height, out.data.width
    for pname, port in node.inputs.items():
        if port.data.height < h or port.data.width < w:
            rep.error(node.pos, f"'{node.name}' ({node.type.name}): its pointwise snippet "
                      f"reads {pname} at every (y, x) of its {h}x{w} output, but {pname} is "
                      f"{port.data.height}x{port.data.width}: it would read outside it",
                      "give the output its inputs' size (height: src.height, width: "
                      "src.width), or declare an index_map that computes where it reads")
