"""Fusable forms: a component type's per-element work, as a snippet the system can fuse.

A GPU-aware type may declare, beside its kernel, what it computes for one output element
(y, x, channel c) of its single output, in one of three forms (after TVM's pattern kinds
and PyTorch Inductor's ``Pointwise(inner_fn)``, whose loads are index expressions)::

    fusable:
      form: index_map                                # pointwise | index_map | stencil
      value: "image(image_height - 1 - y, x, c)"     # OpenCL C: an expression, or
                                                     # statements ending in 'return ...;'
      # stencil only: radius: 2 (or an int parameter, or an expression of them such
      # as 'ksize // 2'), border: clamp (or reflect101, reflect, constant, or an int
      # parameter holding OpenCV's border code)

pointwise   reads every input only at (y, x) (any channel)
index_map   reads each input at one position computed from y, x, c, sizes and parameters
            (a mirror, a crop, side-by-side merging of two inputs)
stencil     reads a window of 'radius' around (y, x); reads outside the input follow
            'border', applied by the accessor: clamp (the nearest edge pixel, OpenCV's
            BORDER_REPLICATE), reflect101, reflect, constant (0), or the name of an int
            parameter whose value is OpenCV's code for one of them (OPENCV_BORDERS),
            fixed at build time like the radius

The snippet is read once, at check time, by the snippet language (gpucompgen/snippet/:
a C lexer, a whitelist grammar, name resolution), and kept parsed in the type; kernels
get it printed from the tree (``FusableDecl.lines``), never pasted.  The tests compile
every library type's snippet.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping
from dataclasses import dataclass, field

from . import sizeexpr
from .errors import Pos
from .snippet import MAX_SNIPPET, Snippet, analyse, port_names, print_lines

FORMS = ("pointwise", "index_map", "stencil")
# the nearest edge pixel (BORDER_REPLICATE); OpenCV's BORDER_REFLECT_101 (gfedcb|abcdefgh),
# BORDER_REFLECT (fedcba|abcdefgh) and BORDER_CONSTANT with 0 (000000|abcdefgh)
BORDERS = ("clamp", "reflect101", "reflect", "constant")
# OpenCV's border codes, for a border chosen by a parameter ('border: border_type')
OPENCV_BORDERS = {0: "constant", 1: "clamp", 2: "reflect", 4: "reflect101"}
__all__ = ["BORDERS", "FORMS", "MAX_SNIPPET", "OPENCV_BORDERS", "FusableDecl", "analyse",
           "port_names", "snippet_position"]


@dataclass(frozen=True)
class FusableDecl:
    form: str  # one of FORMS
    value: str  # the snippet as written (for people: 'types NAME' shows it)
    tree: Snippet  # the snippet as parsed: what kernels are printed from
    names: Mapping[str, str] = field(default_factory=dict, compare=False)
    # every name the snippet uses -> 'coordinate' (y, x, c), 'accessor' (an input port
    # read as port(y, x, c)), 'size' (port_height, port_width), 'type' (port_t, the
    # port's element type), 'param', 'local', 'builtin' or 'constant' (built-ins are
    # never renamed)
    radius: int | str = 0  # stencil: a number, or an int parameter or an expression of
    # int parameters ('ksize // 2', 'iterations * (ksize - 1)'): fixed at build time
    border: str = "clamp"  # stencil: one of BORDERS, or an int parameter holding
    # OpenCV's code of one (OPENCV_BORDERS): fixed at build time, like the radius

    def radius_of(self, params: Mapping[str, object]) -> int:
        """The stencil's radius for these parameter values (0 for another form)."""
        if self.form != "stencil":
            return 0
        if isinstance(self.radius, int):
            return self.radius
        tree = ast.parse(self.radius.strip(), mode="eval")
        return max(0, int(sizeexpr.evaluate(tree, {}, params)))

    def border_of(self, params: Mapping[str, object]) -> str:
        """The stencil's border rule (one of BORDERS) for these parameter values."""
        if self.border in BORDERS:
            return self.border
        code = int(params[self.border])
        if code not in OPENCV_BORDERS:
            raise ValueError(f"{self.border}={code} is not one of OpenCV's border codes "
                             f"{sorted(OPENCV_BORDERS)}")
        return OPENCV_BORDERS[code]

    def radius_names(self) -> set[str]:
        """The parameters that fix the window: those the radius depends on, and the one
        that picks the border rule (constants of a generated kernel, fixed at build time:
        its interior and its accessors are written for them)."""
        if self.form != "stencil":
            return set()
        names = set() if self.border in BORDERS else {self.border}
        if isinstance(self.radius, int):
            return names
        tree = ast.parse(self.radius.strip(), mode="eval")
        calls = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}  # min, max
        return names | {n.id for n in ast.walk(tree)
                        if isinstance(n, ast.Name) and id(n) not in calls}

    def lines(self, rename: Mapping[str, str] | None = None) -> list[str]:
        """The snippet as C statements ending by returning the element, one a line
        (nested ones indented by 4 spaces), printed from the tree with the names in
        rename (any name of ``names`` but a built-in's; unnamed ones print as written).
        Raises ValueError if renaming would merge two names or give a reserved word."""
        return print_lines(self.tree, rename)

    @property
    def body(self) -> str:
        """The snippet as C statements, printed from the tree (no renaming)."""
        return "\n".join(self.lines())

    def taps(self, params: dict) -> int:
        """Input elements one output element reads per input: (2 radius + 1)^2 for a
        stencil, 1 otherwise."""
        if self.form != "stencil":
            return 1
        return (2 * self.radius_of(params) + 1) ** 2


def snippet_position(start: Pos, raw: str | None, style: str | None, value: str,
                     offset: int) -> Pos | None:
    """Where offset (into a YAML string's value) is in the YAML file, given where the
    scalar starts and its source text as written (quotes, escapes, indentation); None
    when the source cannot be followed (then the caller points at the scalar)."""
    if raw is None:
        return None
    at = _align(raw, style, value[:offset + 1])
    if at is None:
        return None
    k = at[offset] if offset < len(at) else (at[-1] + 1 if at else 0)
    line_start = raw.rfind("\n", 0, k)
    line = start.line + raw.count("\n", 0, k)
    col = start.col + k if line_start < 0 else k - line_start
    return Pos(start.file, line, col)


_ESCAPES = {"0": "\0", "a": "\a", "b": "\b", "t": "\t", "\t": "\t", "n": "\n", "v": "\v",
            "f": "\f", "r": "\r", "e": "\x1b", " ": " ", '"': '"', "/": "/", "\\": "\\",
            "N": "\x85", "_": "\xa0", "L": "\u2028", "P": "\u2029"}


def _align(raw: str, style: str | None, value: str) -> list[int] | None:
    """For each character of value, its index in raw (the scalar as written), following
    quotes, escapes, block indentation and line folding; None if they do not match."""
    p = 1 if style in ('"', "'") else 0
    if style in ("|", ">"):
        p = raw.find("\n") + 1
        if p == 0:
            return None
    found = []
    for v in value:
        while True:
            if p >= len(raw):
                return None
            r = raw[p]
            if style == '"' and r == "\\":
                decoded, length = _escape(raw, p)
                if decoded == v:
                    found.append(p)
                    p += length
                    break
                if decoded == "":  # an escaped line break
                    p += length
                    continue
                return None
            if style == "'" and raw.startswith("''", p) and v == "'":
                found.append(p)
                p += 2
                break
            if r == v:
                found.append(p)
                p += 1
                break
            if r in " \t\n\r":  # indentation, or a line break folded into a space
                p += 1
                continue
            return None
    return found


def _escape(raw: str, p: int) -> tuple[str | None, int]:
    """The character a double-quoted YAML escape at p stands for, and its length."""
    ch = raw[p + 1:p + 2]
    if ch in _ESCAPES:
        return _ESCAPES[ch], 2
    if ch in ("\n", "\r"):
        return "", 2
    digits = {"x": 2, "u": 4, "U": 8}.get(ch)
    if digits:
        try:
            return chr(int(raw[p + 2:p + 2 + digits], 16)), 2 + digits
        except ValueError:
            return None, 2
    return None, 2
