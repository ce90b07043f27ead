"""What a parsed snippet means: every name resolved, constants folded, every path returns.

``analyse(text, form, inputs, outputs, params)`` reads a snippet once and gives either its
tree and the kind of every name it uses, or positioned problems (an offset into the
snippet's text each).  Nothing is left for the compiler to find that the snippet's author
could have been told here: an unknown name, an accessor's arity, a pointwise read away
from (y, x), an assignment to something the snippet is given, a division by a constant
zero, an array indexed outside its length, a path that falls off the end without
returning.
"""

from __future__ import annotations

import re
from collections.abc import Collection
from dataclasses import dataclass, field

from ..errors import did_you_mean
from .lexer import tokens
from .problems import Problem, SnippetError
from .syntax import (
    KEYWORDS,
    VECTORS,
    Assign,
    Binary,
    Block,
    Call,
    Cast,
    Conditional,
    Decl,
    DoWhile,
    ExprStmt,
    For,
    If,
    Index,
    InitList,
    Jump,
    Member,
    Name,
    Node,
    Number,
    Paren,
    Postfix,
    Return,
    Snippet,
    Unary,
    VectorLiteral,
    While,
    parse,
)

MAX_SNIPPET = 4000  # characters: a snippet is a few lines, not a program
MAX_ARRAY = 256  # elements of a local array (private memory of every work-item)
COORDINATES = ("y", "x", "c")
# words that would make the snippet write the kernel rather than one element of it
FORBIDDEN = frozenset({
    "__global", "global", "__local", "local", "__constant", "constant", "__private",
    "private", "__kernel", "kernel", "barrier", "mem_fence", "read_mem_fence",
    "write_mem_fence", "work_group_barrier", "goto", "static", "extern", "volatile",
    "restrict", "typedef", "struct", "union", "get_global_id", "get_local_id",
    "get_group_id", "get_global_size", "get_local_size", "get_num_groups", "get_work_dim",
    "get_global_offset", "printf", "atomic_add", "atomic_sub", "atomic_inc", "atomic_dec",
    "atomic_xchg", "atomic_cmpxchg", "atomic_min", "atomic_max", "atomic_and",
    "atomic_or", "atomic_xor", "async_work_group_copy", "wait_group_events", "prefetch",
    "vload", "vstore", "read_imagef", "write_imagef", "__attribute__"})
BUILTINS = frozenset({
    "clamp", "min", "max", "abs", "abs_diff", "mad", "mad24", "mul24", "mad_hi", "mul_hi",
    "select", "bitselect", "sqrt", "rsqrt", "cbrt", "floor", "ceil", "round", "rint",
    "trunc", "fabs", "fmin", "fmax", "fmod", "fma", "fdim", "exp", "exp2", "exp10",
    "expm1", "log", "log2", "log10", "log1p", "pow", "pown", "powr", "rootn", "sin", "cos",
    "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh", "acosh",
    "atanh", "sinpi", "cospi", "tanpi", "hypot", "copysign", "ldexp", "add_sat", "sub_sat",
    "mix", "step", "smoothstep", "sign", "degrees", "radians", "rotate", "hadd", "rhadd",
    "mad_sat", "upsample", "popcount", "clz", "isnan", "isinf", "isfinite", "signbit",
    "any", "all", "dot", "cross", "length", "distance", "normalize", "native_sqrt",
    "native_rsqrt", "native_exp", "native_log", "native_sin", "native_cos",
    "native_divide", "native_recip", "native_powr", "half_sqrt", "half_exp", "half_log"})
CONSTANTS = frozenset({
    "CHAR_BIT", "CHAR_MAX", "CHAR_MIN", "UCHAR_MAX", "SCHAR_MAX", "SCHAR_MIN", "SHRT_MAX",
    "SHRT_MIN", "USHRT_MAX", "INT_MAX", "INT_MIN", "UINT_MAX", "LONG_MAX", "LONG_MIN",
    "ULONG_MAX", "FLT_MAX", "FLT_MIN", "FLT_EPSILON", "MAXFLOAT", "HUGE_VALF", "INFINITY",
    "NAN", "M_PI_F", "M_E_F", "M_SQRT2_F", "M_LN2_F", "M_PI", "M_E"})
_TYPES = "|".join(("char", "uchar", "short", "ushort", "int", "uint", "long", "ulong",
                   "float", "half", "double", *VECTORS))
_CONVERT = re.compile(rf"(convert|as)_({_TYPES})(_sat)?(_rte|_rtz|_rtp|_rtn)?")


def is_builtin(name: str) -> bool:
    """An OpenCL C built-in function a snippet may call."""
    m = _CONVERT.fullmatch(name)
    return name in BUILTINS or (m is not None and (m.group(1) == "convert"
                                                   or not (m.group(3) or m.group(4))))


@dataclass
class Analysis:
    """A snippet read once: its tree (None when it does not parse), the kind of every name
    it uses ('coordinate', 'accessor', 'size', 'type' (<port>_t), 'limit' (<port>_min,
    <port>_max), 'param', 'local', 'builtin', 'constant') and its problems."""

    tree: Snippet | None
    names: dict[str, str] = field(default_factory=dict)  # and 'type': a port's <port>_t
    problems: list[Problem] = field(default_factory=list)


def port_names(inputs: list[str], outputs: list[str]) -> dict[str, str]:
    """The names a snippet gets for its ports beyond their accessors, each with what it
    names: <port>_height, <port>_width and <port>_channels (sizes), <port>_t (the port's element type,
    uchar, short or float as the model resolves it; not where <port>_t is already a word
    of OpenCL C, such as size_t), <port>_min and <port>_max (the least and the greatest
    value of that type: OpenCV's saturation bounds).  A type's parameters and ports must
    not take them."""
    names = {}
    for p in (*inputs, *outputs):
        names[f"{p}_height"] = f"the height of port '{p}'"
        names[f"{p}_width"] = f"the width of port '{p}'"
        names[f"{p}_channels"] = f"the channels of port '{p}'"
        names[f"{p}_min"] = f"the least value of port '{p}''s element type"
        names[f"{p}_max"] = f"the greatest value of port '{p}''s element type"
        if f"{p}_t" not in KEYWORDS:
            names[f"{p}_t"] = f"the element type of port '{p}'"
    return names


def port_types(inputs: list[str], outputs: list[str]) -> dict[str, str]:
    """'<port>_t' -> port, for the ports whose element type the snippet can name."""
    return {f"{p}_t": p for p in (*inputs, *outputs) if f"{p}_t" not in KEYWORDS}


def analyse(text: str, form: str, inputs: list[str], outputs: list[str],
            params: list[str], arrays: Collection[str] = ()) -> Analysis:
    """Read a snippet: arrays are the array parameters among params (read as
    table[i] or k[i][j], like local arrays)."""
    if len(text) > MAX_SNIPPET:
        return Analysis(None, problems=[Problem(0, f"the snippet has {len(text):,} characters, "
                                                f"more than {MAX_SNIPPET:,}",
                                                "a snippet is a few lines: keep the kernel "
                                                "for bigger work and drop 'fusable:'")])
    try:
        toks = tokens(text)
        forbidden = [Problem(t.offset, _forbidden(t.text)) for t in toks
                     if t.kind == "id" and t.text in FORBIDDEN]
        if forbidden:
            return Analysis(None, problems=forbidden)
        tree = parse(text, port_types(inputs, outputs))
    except SnippetError as exc:
        return Analysis(None, problems=[exc.problem])
    given = {n: "coordinate" for n in COORDINATES}
    given.update({f"{p}_{d}": "size" for p in inputs + outputs
                  for d in ("height", "width", "channels")})
    given.update({f"{p}_{d}": "limit" for p in inputs + outputs for d in ("min", "max")})
    given.update({p: "param" for p in params})
    resolver = _Resolver(form, given, set(inputs), set(outputs), frozenset(arrays),
                         port_types(inputs, outputs))
    resolver.block(tree.body)
    if not tree.expression and not returns(tree.body):
        last = tree.body[-1] if tree.body else tree
        resolver.problem(last, "a path through the statements ends without returning the "
                         "element", "end every path with 'return ...;'")
    return Analysis(tree, resolver.names, list(dict.fromkeys(resolver.problems)))


def _forbidden(word: str) -> str:
    return (f"'{word}' is not allowed in a snippet: the system writes the kernel, its "
            "memory accesses and its synchronisation")


@dataclass
class _Local:
    const: bool
    length: int | None  # an array's length; None: a scalar or a vector


class _Resolver:
    def __init__(self, form: str, given: dict[str, str], inputs: set[str],
                 outputs: set[str], arrays: frozenset[str] = frozenset(),
                 types: Collection[str] = ()) -> None:
        self.form = form
        self.types = types  # the ports' element types, <port>_t
        self.arrays = arrays  # array parameters: indexed as local arrays are
        self.given = given
        self.inputs = inputs
        self.outputs = outputs
        self.scopes: list[dict[str, _Local]] = [{}]
        self.loops = 0
        self.names: dict[str, str] = {}
        self.problems: list[Problem] = []

    def problem(self, node: Node, message: str, hint: str = "") -> None:
        self.problems.append(Problem(node.at, message, hint))

    def lookup(self, name: str) -> _Local | None:
        for scope in reversed(self.scopes):
            if name in scope:
                return scope[name]
        return None

    # statements
    def block(self, body) -> None:
        self.scopes.append({})
        for s in body:
            self.statement(s)
        self.scopes.pop()

    def statement(self, s: Node) -> None:
        if isinstance(s, Block):
            self.block(s.body)
        elif isinstance(s, Decl):
            self.declaration(s)
        elif isinstance(s, ExprStmt):
            if s.expr is not None:
                self.expr(s.expr)
        elif isinstance(s, If):
            self.expr(s.cond)
            self.block((s.then,))
            if s.other is not None:
                self.block((s.other,))
        elif isinstance(s, For):
            self.scopes.append({})
            self.statement(s.init)
            for e in (s.cond, s.step):
                if e is not None:
                    self.expr(e)
            self.loop(s.body)
            self.scopes.pop()
        elif isinstance(s, While):
            self.expr(s.cond)
            self.loop(s.body)
        elif isinstance(s, DoWhile):
            self.loop(s.body)
            self.expr(s.cond)
        elif isinstance(s, Return):
            self.expr(s.value)
        elif isinstance(s, Jump):
            if not self.loops:
                self.problem(s, f"'{s.word}' outside a loop", "use it inside for/while/do")
        else:  # pragma: no cover - the parser makes no other statement
            raise TypeError(f"not a statement: {s!r}")

    def loop(self, body: Node) -> None:
        self.loops += 1
        self.block((body,))
        self.loops -= 1

    def typename(self, t) -> None:
        if t.name in self.types:
            self.names[t.name] = "type"

    def declaration(self, d: Decl) -> None:
        self.typename(d.type)
        for v in d.declarators:
            length = None
            if v.size is not None:
                self.expr(v.size)
                n = constant(v.size)
                if not isinstance(n, int) or not 1 <= n <= MAX_ARRAY:
                    self.problem(v.size, f"the length of array '{v.name}' must be a number "
                                 f"from 1 to {MAX_ARRAY}", "write the length as a number")
                    n = None
                length = n or 0
            if isinstance(v.init, InitList):
                if v.size is None:
                    self.problem(v.init, f"'{{...}}' initializes an array; '{v.name}' is not "
                                 "one", f"declare it as {v.name}[N]")
                elif length and len(v.init.items) > length:
                    self.problem(v.init, f"{len(v.init.items)} values for array '{v.name}' "
                                 f"of length {length}")
                for item in v.init.items:
                    self.expr(item)
            elif v.init is not None:
                if v.size is not None:
                    self.problem(v.init, f"array '{v.name}' is initialized with '{{...}}'")
                self.expr(v.init)  # before the name exists: 'int a = a;' reads nothing
            elif d.type.const:
                self.problem(v, f"const local '{v.name}' needs a value",
                             f"const {d.type.name} {v.name} = ...;")
            self.declare(v, _Local(d.type.const, length))

    def declare(self, v, local: _Local) -> None:
        name = v.name
        kind = self.given.get(name)
        if kind is not None or name in self.inputs or name in self.outputs:
            self.problem(v, f"local '{name}' hides a name the snippet is given",
                         "choose another name")
        elif is_builtin(name) or name in CONSTANTS or name in FORBIDDEN:
            self.problem(v, f"local '{name}' hides an OpenCL C built-in",
                         "choose another name")
        elif name in self.scopes[-1]:
            self.problem(v, f"local '{name}' is declared twice", "choose another name")
        elif name.startswith("__"):
            self.problem(v, f"names starting with '__' are reserved: '{name}'",
                         "choose another name")
        self.scopes[-1][name] = local
        self.names.setdefault(name, "local")

    # expressions
    def expr(self, e: Node) -> None:
        if isinstance(e, Name):
            self.name(e)
        elif isinstance(e, Number):
            pass
        elif isinstance(e, Paren):
            self.expr(e.inner)
        elif isinstance(e, (Unary, Postfix)):
            self.expr(e.operand)
            if e.op in ("++", "--"):
                self.target(e.operand, e.op)
        elif isinstance(e, Binary):
            self.expr(e.left)
            self.expr(e.right)
            if e.op in ("/", "%"):
                self.divisor(e.right, e.op)
        elif isinstance(e, Assign):
            self.expr(e.target)
            self.expr(e.value)
            self.target(e.target, e.op)
            if e.op in ("/=", "%="):
                self.divisor(e.value, e.op[0])
        elif isinstance(e, Conditional):
            for part in (e.cond, e.then, e.other):
                self.expr(part)
        elif isinstance(e, Call):
            self.call(e)
        elif isinstance(e, Index):
            self.expr(e.base)
            self.expr(e.index)
            self.index(e)
        elif isinstance(e, Member):
            self.expr(e.base)
        elif isinstance(e, Cast):
            self.typename(e.type)
            self.expr(e.operand)
        elif isinstance(e, VectorLiteral):
            for a in e.args:
                self.expr(a)
        else:  # pragma: no cover - the parser makes no other expression
            raise TypeError(f"not an expression: {e!r}")

    def name(self, e: Name) -> None:
        n = e.name
        if self.lookup(n) is not None:
            return
        if n in self.given:
            self.names[n] = self.given[n]
        elif n in CONSTANTS:
            self.names[n] = "constant"
        elif n in self.inputs:
            self.problem(e, f"input '{n}' is read as {n}(y, x, c), with three arguments")
        elif n in self.outputs:
            self.problem(e, f"output '{n}' is what the snippet returns; it cannot be read")
        elif is_builtin(n):
            self.problem(e, f"'{n}' is a built-in function: call it", f"{n}(...)")
        else:
            choices = [*self.given, *(k for s in self.scopes for k in s)]
            self.problem(e, f"unknown name '{n}'", did_you_mean(n, choices) if choices else "")

    def call(self, e: Call) -> None:
        f = e.func
        for a in e.args:
            self.expr(a)
        if f in self.inputs:
            self.names[f] = "accessor"
            if len(e.args) == 4 and self.form == "pointwise":
                self.problem(e, f"a pointwise snippet reads {f}(y, x, c), which is always "
                             f"inside the frame: no fill value (a fourth argument)")
            elif len(e.args) not in (3, 4):
                self.problem(e, f"accessor {f}(...) takes 3 arguments (y, x, c), or 4 with "
                             f"the value outside the frame (y, x, c, fill), not "
                             f"{len(e.args)}")
            elif self.form == "pointwise" and not (_is(e.args[0], "y") and _is(e.args[1], "x")):
                from .printer import expression_text
                shown = ", ".join(expression_text(a) for a in e.args)
                self.problem(e, f"a pointwise snippet reads inputs at (y, x) only, but reads "
                             f"{f}({shown})", "declare the type 'index_map' or 'stencil'")
        elif f in self.outputs:
            self.problem(e, f"output '{f}' is what the snippet returns; it cannot be read")
        elif is_builtin(f):
            self.names[f] = "builtin"
        elif self.lookup(f) is not None or f in self.given:
            self.problem(e, f"'{f}' is not a function")
        else:
            close = did_you_mean(f, sorted(BUILTINS | self.inputs))
            self.problem(e, f"unknown function '{f}'", close if close.startswith("did you")
                         else "a snippet calls its accessors <port>(y, x, c) and OpenCL C "
                         "built-ins (docs/fusion.md lists them)")

    def target(self, e: Node, op: str) -> None:
        """The left of an assignment (or ++/--) is a local the snippet declared."""
        root = e
        while isinstance(root, (Index, Member, Paren)):
            root = root.inner if isinstance(root, Paren) else root.base
        if not isinstance(root, Name):
            self.problem(e, f"'{op}' needs a local on its left")
            return
        local = self.lookup(root.name)
        if local is None:
            if root.name in self.given:
                self.problem(e, f"'{root.name}' is given to the snippet; it cannot be "
                             "assigned", "copy it into a local first")
        elif local.const:
            self.problem(e, f"'{root.name}' is const; it cannot be assigned",
                         "drop 'const' from its declaration")

    def divisor(self, e: Node, op: str) -> None:
        if constant(e) == 0:
            what = "division" if op == "/" else "modulo"
            self.problem(e, f"{what} by zero", "a constant divisor must not be 0")

    def index(self, e: Index) -> None:
        base = e.base
        if isinstance(base, Name) and base.name in self.arrays:
            return  # an array parameter: its lengths are the instance's, not known here
        local = self.lookup(base.name) if isinstance(base, Name) else None
        if local is None or local.length is None:
            if local is not None or isinstance(base, Name) and base.name in self.given:
                self.problem(e, "only a local array can be indexed with [...]",
                             "vector components are read with .x, .s0, ...")
            return
        i = constant(e.index)
        if isinstance(i, int) and local.length and not 0 <= i < local.length:
            self.problem(e.index, f"index {i} is outside array '{base.name}' of length "
                         f"{local.length}", f"its indexes run from 0 to {local.length - 1}")


def _is(e: Node, name: str) -> bool:
    while isinstance(e, Paren):
        e = e.inner
    return isinstance(e, Name) and e.name == name


def constant(e: Node) -> int | float | None:
    """The value of a constant expression (literals and operators on them), else None."""
    if isinstance(e, Number):
        return e.value
    if isinstance(e, Paren):
        return constant(e.inner)
    if isinstance(e, Cast):
        v = constant(e.operand)
        if v is None:
            return None
        return float(v) if e.type.name in ("float", "half", "double") else int(v)
    if isinstance(e, Unary) and e.op in ("+", "-", "~", "!"):
        v = constant(e.operand)
        if v is None:
            return None
        return {"+": lambda: v, "-": lambda: -v, "~": lambda: ~v if isinstance(v, int) else None,
                "!": lambda: int(not v)}[e.op]()
    if isinstance(e, Conditional):
        c = constant(e.cond)
        return None if c is None else constant(e.then if c else e.other)
    if isinstance(e, Binary):
        a, b = constant(e.left), constant(e.right)
        if a is None or b is None:
            return None
        v = fold(e.op, a, b)
        return v if v is None or abs(v) <= 1 << 64 else None
    return None


def fold(op: str, a, b):
    """a op b on two numbers as C computes it (division truncated, shifts by 0 to 63), or
    None where C gives no number (a division by zero, a shift out of range, % or a bit
    operation on floats)."""
    ints = isinstance(a, int) and isinstance(b, int)
    if op in ("/", "%"):
        if b == 0:
            return None
        if not ints:
            return a / b if op == "/" else None
        q = abs(a) // abs(b) * (1 if (a < 0) == (b < 0) else -1)  # C truncates
        return q if op == "/" else a - b * q
    if op in ("<<", ">>", "&", "|", "^"):
        if not ints or (op in ("<<", ">>") and not 0 <= b < 64):
            return None
        return {"<<": a << b, ">>": a >> b, "&": a & b, "|": a | b, "^": a ^ b}[op]
    return {"+": lambda: a + b, "-": lambda: a - b, "*": lambda: a * b,
            "<": lambda: int(a < b), ">": lambda: int(a > b), "<=": lambda: int(a <= b),
            ">=": lambda: int(a >= b), "==": lambda: int(a == b), "!=": lambda: int(a != b),
            "&&": lambda: int(bool(a) and bool(b)),
            "||": lambda: int(bool(a) or bool(b))}[op]()


def returns(body) -> bool:
    """Every path through the statements ends in 'return' (loops are not counted on)."""
    for s in body:
        if _returns_one(s):
            return True
    return False


def _returns_one(s: Node) -> bool:
    if isinstance(s, Return):
        return True
    if isinstance(s, Block):
        return returns(s.body)
    if isinstance(s, If):
        return s.other is not None and _returns_one(s.then) and _returns_one(s.other)
    return False
