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
      # parameter holding OpenCV's border code); reads: how many input elements an
      # output element reads with the snippet's loops unrolled, where a stencil's
      # snippet nests windows (a number, an int parameter or an expression of them);
      # tables: {kx: 'gaussian_q8(ksize, sigma)'} (tables the snippet reads, computed
      # from parameters); stages: {rows: {dtype: int32, radius: r, value: ...}} (see
      # below); axis: x (or y) where the window is a row (a column)

pointwise   reads every input only at (y, x) (any channel)
index_map   reads each input at one position computed from y, x, c, sizes and parameters
            (a mirror, a crop, side-by-side merging of two inputs)
stencil     reads a window of 'radius' around (y, x); reads outside the input follow
            'border', applied by the accessor: clamp (the nearest edge pixel, OpenCV's
            BORDER_REPLICATE), reflect101, reflect, constant (0), or the name of an int
            parameter whose value is OpenCV's code for one of them (OPENCV_BORDERS),
            fixed at build time like the radius; 'tables' name arrays the snippet reads
            (kx[i]) that one of gpucompgen's table functions (library/kernel_tables.py:
            an OpenCV kernel's fixed-point weights) computes from parameters when the
            kernel is generated: those parameters are fixed at build time too
An array parameter's lengths are names of the snippet and of the radius: <name>_length
(one dimension), <name>_rows and <name>_cols (two or three), fixed at build time.

A stencil whose work is a window of something computed over a window (a box filter's
row sums, then the sums of ksize of them down a column; an opening's erosion, then the
dilation of it) may say so with ``stages``: each a named stencil of its own (an element
type, a radius, its reads, a value reading the inputs and the stages before it, the
type's border), and the type's value reads them as ``name(y, x, c)``, like inputs; the
type's own radius and reads are then the value's own, over the stages.  The kernel
generator decides how a stage is computed (kernelgen/fused.py): inline, at every
read of it (what the type would be without stages), or once a frame strip into local
memory that the value then reads; the results are the same.

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
from .library.kernel_tables import TABLES
from .snippet import MAX_SNIPPET, Snippet, analyse, is_builtin, port_names, print_lines
from .snippet.syntax import Call, DoWhile, For, Node, While

FORMS = ("pointwise", "index_map", "stencil")
# a stencil's window along one axis: a row ('x': it reads (y, x + d) only) or a column
AXES = ("x", "y")
# the nearest edge pixel (BORDER_REPLICATE); OpenCV's BORDER_REFLECT_101 (gfedcb|abcdefgh),
# BORDER_REFLECT (fedcba|abcdefgh) and BORDER_CONSTANT with 0 (000000|abcdefgh)
BORDERS = ("clamp", "reflect101", "reflect", "constant")
# OpenCV's border codes, for a border chosen by a parameter ('border: border_type')
OPENCV_BORDERS = {0: "constant", 1: "clamp", 2: "reflect", 4: "reflect101"}
__all__ = ["AXES", "BORDERS", "FORMS", "MAX_SNIPPET", "OPENCV_BORDERS", "TABLES", "FusableDecl", "Stage",
           "analyse", "array_lengths", "length_names", "port_names", "snippet_position",
           "table_call"]


def length_names(name: str, dims: int) -> tuple[str, ...]:
    """The names of an array parameter's lengths: <name>_length for one dimension,
    <name>_rows and <name>_cols for two or more."""
    return (f"{name}_length",) if dims == 1 else (f"{name}_rows", f"{name}_cols")


def array_lengths(params: Mapping[str, object]) -> dict[str, int]:
    """The lengths of the array values among params, by length_names."""
    found = {}
    for name, value in params.items():
        if not isinstance(value, (tuple, list)):
            continue
        if value and isinstance(value[0], (tuple, list)):
            found[f"{name}_rows"], found[f"{name}_cols"] = len(value), len(value[0])
        else:
            found[f"{name}_length"] = len(value)
    return found


def table_call(text: object, params: Mapping[str, str]) -> tuple[str, tuple[str, ...]] | str:
    """A 'tables:' entry ('gaussian_q8(ksize, sigma)') as its function and argument
    names, or why it cannot be: the function one of TABLES, each argument an int or float
    parameter (params: name -> type)."""
    known = ", ".join(TABLES)
    try:
        call = ast.parse(str(text).strip(), mode="eval").body if isinstance(text, str) \
            else None
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        call = None
    if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name)) or call.keywords:
        return f"a table is a call of a table function ({known}) on parameters, not {text!r}"
    if call.func.id not in TABLES:
        return f"{call.func.id!r} is no table function: there are {known}"
    _, least, most = TABLES[call.func.id]
    if not least <= len(call.args) <= most:
        return f"{call.func.id}() takes {least} to {most} parameters, not {len(call.args)}"
    names = []
    for arg in call.args:
        if not isinstance(arg, ast.Name) or params.get(arg.id) not in ("int", "float"):
            return (f"argument {ast.unparse(arg)!r} of {call.func.id}() is not an int or "
                    "float parameter")
        names.append(arg.id)
    return call.func.id, tuple(names)


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
    reads: int | str | None = None  # stencil: input elements an output element reads
    # with the loops unrolled, where the window count (reads_of) would be wrong: a
    # snippet that nests windows (MorphologyEx's opening: a window of windows)
    # stencil: arrays the snippet reads, each a table function of TABLES and the
    # parameters it is called with ('kx': ('gaussian_q8', ('ksize', 'sigma'))): computed
    # when the kernel is generated, so those parameters are fixed at build time
    tables: Mapping[str, tuple[str, tuple[str, ...]]] = field(default_factory=dict)
    # stencil: what the value reads besides the inputs, in order (each may read the
    # inputs and the stages before it): name -> Stage
    stages: Mapping[str, Stage] = field(default_factory=dict)
    # stencil: 'x' where the window is a row (it reads (y, x + d) only), 'y' where it is a
    # column; None: both (a square of 2 radius + 1)
    axis: str | None = None

    def radii_of(self, params: Mapping[str, object]) -> tuple[int, int]:
        """The window's radius along y and along x (axis: one of them 0)."""
        r = self.radius_of(params)
        return (0 if self.axis == "x" else r, 0 if self.axis == "y" else r)

    def radius_of(self, params: Mapping[str, object]) -> int:
        """The stencil's radius for these parameter values (0 for another form)."""
        if self.form != "stencil":
            return 0
        return _int_of(self.radius, params)

    def border_of(self, params: Mapping[str, object]) -> str:
        """The stencil's border rule (one of BORDERS) for these parameter values."""
        if self.border in BORDERS:
            return self.border
        code = int(params[self.border])
        if code not in OPENCV_BORDERS:
            raise ValueError(f"{self.border}={code} is not one of OpenCV's border codes "
                             f"{sorted(OPENCV_BORDERS)}")
        return OPENCV_BORDERS[code]

    @staticmethod
    def lengths_of(params: Mapping[str, object]) -> dict[str, int]:
        """The lengths of the array parameters (array_lengths): constants of a kernel."""
        return array_lengths(params)

    def tables_of(self, params: Mapping[str, object]) -> dict[str, tuple]:
        """The tables the snippet reads, computed for these parameter values."""
        return {name: TABLES[function][0](*(params[a] for a in args))
                for name, (function, args) in self.tables.items()}

    def radius_names(self) -> set[str]:
        """The parameters that fix the window: those the radius depends on, the one
        that picks the border rule and those the tables are computed from (constants of a
        generated kernel, fixed at build time: its interior, its accessors and its tables
        are written for them)."""
        if self.form != "stencil":
            return set()
        names = set() if self.border in BORDERS else {self.border}
        names |= {a for _, args in self.tables.values() for a in args}
        for stage in self.stages.values():
            names |= stage.decl.radius_names()
        if isinstance(self.radius, int):
            return names
        tree = ast.parse(self.radius.strip(), mode="eval")
        calls = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}  # min, max
        return names | {n.id for n in ast.walk(tree)
                        if isinstance(n, ast.Name) and id(n) not in calls}

    def reach_of(self, params: Mapping[str, object]) -> int:
        """How far from (y, x) an output element reads the inputs: the radius, plus the
        farthest reach of the stages where it has any (a stage read at the value's
        radius reads its own window around there)."""
        return self.radius_of(params) + max(
            (s.decl.reach_of(params) for s in self.stages.values()), default=0)

    def total_reads_of(self, params: Mapping[str, object]) -> int:
        """Input elements an output element reads with every stage computed at every read
        of it (inline) and the loops unrolled: reads_of, a stage's read counted as the
        most any stage reads (an upper bound)."""
        inner = max((s.decl.total_reads_of(params) for s in self.stages.values()),
                    default=1)
        return self.reads_of(params) * inner

    def lines(self, rename: Mapping[str, str] | None = None,
              fills: Mapping[str, str] | None = None) -> list[str]:
        """The snippet as C statements ending by returning the element, one a line
        (nested ones indented by 4 spaces), printed from the tree with the names in
        rename (any name of ``names`` but a built-in's; unnamed ones print as written)
        and an accessor's reads with a fill value under the name fills gives it.
        Raises ValueError if renaming would merge two names or give a reserved word."""
        return print_lines(self.tree, rename, fills)

    @property
    def body(self) -> str:
        """The snippet as C statements, printed from the tree (no renaming)."""
        return "\n".join(self.lines())

    def taps(self, params: dict) -> int:
        """Input elements one output element reads per input: (2 radius + 1)^2 for a
        stencil (of the stages where it has any: its own window over them), 1
        otherwise."""
        if self.form != "stencil":
            return 1
        ry, rx = self.radii_of(params)
        return (2 * ry + 1) * (2 * rx + 1)

    def reads_of(self, params: Mapping[str, object]) -> int:
        """Input elements one evaluation of the snippet reads with its loops unrolled
        (what a kernel that inlines it repeats, and what its compile time follows): the
        declared 'reads' where the type states it, else its accessor calls, a call inside
        n loops counted (2 radius + 1)^n times for a stencil (a loop walks the window's
        side), once for other forms."""
        if self.reads is not None:
            return max(1, _int_of(self.reads, params))
        side = 2 * self.radius_of(params) + 1 if self.form == "stencil" else 1
        return max(1, unrolled_calls(self.tree, side))


@dataclass(frozen=True)
class Stage:
    """A stage of a stencil (FusableDecl.stages): its element type (one of DTYPES;
    '<input>.dtype': a generic type's input's; '<input>.sum_dtype': the type a sum of
    that input's elements is kept in) and its own form, a stencil with the
    type's border."""

    name: str
    dtype: str
    decl: FusableDecl

    def dtype_for(self, inputs: dict) -> str:
        """The stage's element type for a component whose input ports are inputs (name ->
        a port with .dtype): '<input>.dtype' is that input's, '<input>.sum_dtype' the
        type its sums are kept in."""
        port, _, of = self.dtype.partition(".")
        if of == "sum_dtype":  # int32 for integer types (exact for uint8 and int16
            # windows), float32 for float32 (OpenCV's is double: docs/library.md's bounds)
            return "float32" if inputs[port].dtype == "float32" else "int32"
        return inputs[port].dtype if of == "dtype" else self.dtype


_LOOPS = (For, While, DoWhile)


def unrolled_calls(tree, side: int) -> int:
    """Accessor calls (calls of anything but a built-in) in the snippet, each inside n
    loops counted side^n times."""
    def walk(node, weight: int) -> int:
        found = weight if isinstance(node, Call) and not is_builtin(node.func) else 0
        if isinstance(node, _LOOPS):
            weight *= side
        if isinstance(node, Node):
            children = vars(node).values()
        elif isinstance(node, tuple):
            children = node
        else:
            return found
        return found + sum(walk(child, weight) for child in children)

    return walk(tree, 1)


def _int_of(value: int | str, params: Mapping[str, object]) -> int:
    """A number, an int parameter or an expression of them, for these values (0 at
    least)."""
    if isinstance(value, int):
        return value
    tree = ast.parse(value.strip(), mode="eval")
    try:
        return max(0, int(sizeexpr.evaluate(tree, {}, {**params, **array_lengths(params)})))
    except sizeexpr.SizeExprError:  # beyond any size: a count beyond every bound
        return sizeexpr.MAX_SIDE + 1


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
