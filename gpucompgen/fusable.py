"""Fusable forms: a component type's per-element work, as a snippet the system can fuse.

A GPU-aware type may declare, beside its kernel, what it computes for one output element
(y, x, channel c) of its single output, in one of three forms (after TVM's pattern kinds
and PyTorch Inductor's ``Pointwise(inner_fn)``, whose loads are index expressions)::

    fusable:
      form: index_map                                # pointwise | index_map | stencil
      value: "image(image_height - 1 - y, x, c)"     # OpenCL C: an expression, or
                                                     # statements ending in 'return ...;'
      # stencil only: radius: 2 (or an int parameter's name), border: clamp

pointwise   reads every input only at (y, x) (any channel)
index_map   reads each input at one position computed from y, x, c, sizes and parameters
            (a mirror, a crop, side-by-side merging of two inputs)
stencil     reads a window of 'radius' around (y, x); reads outside the input follow
            'border' (clamp: the nearest edge pixel), applied by the accessor

The snippet reads input element (y', x', c') as ``<port>(y', x', c')`` and may use y, x, c,
``<port>_height`` / ``<port>_width`` of every port, the parameters, locals it declares, and
OpenCL C built-in functions.  It is checked here, without a device: the form is known,
every name is one of those, accessors take three arguments, pointwise accessors read at
(y, x), no address-space qualifiers, barriers, preprocessor lines or kernel definitions,
braces and parentheses balance, and it is small.  The tests compile every library type's
snippet.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

FORMS = ("pointwise", "index_map", "stencil")
BORDERS = ("clamp", "reflect101")  # the nearest edge pixel; OpenCV's BORDER_REFLECT_101
MAX_SNIPPET = 4000  # characters: a snippet is a few lines, not a program

_TOKEN = re.compile(r"\s+|//[^\n]*|/\*.*?\*/|(?P<id>[A-Za-z_][A-Za-z0-9_]*)"
                    r"|(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?[uUlLfF]*|0[xX][0-9a-fA-F]+[uUlL]*)"
                    r"|(?P<op><<=|>>=|\+\+|--|&&|\|\||<<|>>|[<>=!+\-*/%&|^]=|->|[-+*/%<>=!&|^~?:;,.(){}\[\]])",
                    re.DOTALL)
C_TYPES_WORDS = {"char", "uchar", "short", "ushort", "int", "uint", "long", "ulong", "float",
                 "double", "half", "bool", "size_t", "unsigned", "signed", "void"}
C_KEYWORDS = C_TYPES_WORDS | {"const", "return", "if", "else", "for", "while", "do",
                              "break", "continue", "switch", "case", "default", "sizeof",
                              "true", "false"}
FORBIDDEN = {"__global", "global", "__local", "local", "__constant", "constant",
             "__private", "private", "__kernel", "kernel", "barrier", "mem_fence",
             "read_mem_fence", "write_mem_fence", "work_group_barrier", "goto", "static",
             "extern", "volatile", "restrict", "typedef", "struct", "union",
             "get_global_id", "get_local_id", "get_group_id", "get_global_size",
             "get_local_size", "get_num_groups", "printf", "atomic_add", "atomic_inc",
             "atomic_xchg"}
BUILTINS = {"clamp", "min", "max", "abs", "abs_diff", "mad", "mad24", "mul24", "select",
            "sqrt", "rsqrt", "floor", "ceil", "round", "rint", "trunc", "fabs", "fmin", "fmax",
            "fmod", "fma", "exp", "exp2", "log", "log2", "pow", "pown", "sin", "cos", "tan", "atan",
            "atan2", "hypot", "add_sat", "sub_sat", "mix", "step", "sign", "rotate",
            "hadd", "rhadd", "mad_sat", "isnan", "isinf"}


@dataclass(frozen=True)
class FusableDecl:
    form: str  # one of FORMS
    value: str  # the snippet as written
    body: str  # the snippet as C statements (an expression becomes 'return (...);')
    radius: int | str = 0  # stencil: a number or the name of an int parameter
    border: str = "clamp"  # stencil

    def taps(self, params: dict) -> int:
        """Input elements one output element reads per input: (2 radius + 1)^2 for a
        stencil, 1 otherwise."""
        if self.form != "stencil":
            return 1
        r = params.get(self.radius, 0) if isinstance(self.radius, str) else self.radius
        return (2 * int(r) + 1) ** 2


def tokens(text: str) -> list[tuple[str, str]]:
    """(kind, text) of every token: 'id', 'num', 'op', or 'bad' for a character C lacks."""
    found, i = [], 0
    while i < len(text):
        m = _TOKEN.match(text, i)
        if m is None:
            found.append(("bad", text[i]))
            i += 1
            continue
        kind = m.lastgroup
        if kind:
            found.append((kind, m.group(kind)))
        i = m.end()
    return found


def snippet_problems(value: str, form: str, inputs: list[str], outputs: list[str],
                     params: list[str]) -> list[str]:
    """What is wrong with a snippet, as far as can be told without compiling it."""
    if len(value) > MAX_SNIPPET:
        return [f"the snippet has {len(value):,} characters, more than {MAX_SNIPPET:,}"]
    if "#" in value:
        return ["preprocessor lines ('#') are not allowed in a snippet"]
    toks = tokens(value)
    problems: list[str] = []
    bad = sorted({t for k, t in toks if k == "bad"})
    if bad:
        problems.append(f"characters {', '.join(map(repr, bad))} are not OpenCL C")
    depth = {"(": 0, "{": 0, "[": 0}
    closing = {")": "(", "}": "{", "]": "["}
    for k, t in toks:
        if k == "op" and t in depth:
            depth[t] += 1
        elif k == "op" and t in closing:
            depth[closing[t]] -= 1
            if depth[closing[t]] < 0:
                problems.append(f"unbalanced '{t}'")
                depth[closing[t]] = 0
    for opening, n in depth.items():
        if n:
            problems.append(f"unbalanced '{opening}': {n} not closed")
    known = ({"x", "y", "c"} | set(params)
             | {f"{p}_{d}" for p in inputs + outputs for d in ("height", "width")})
    declared: set[str] = set()
    for i, (k, t) in enumerate(toks):
        if k != "id":
            continue
        prev = toks[i - 1][1] if i else ""
        nxt = toks[i + 1][1] if i + 1 < len(toks) else ""
        if t in FORBIDDEN:
            problems.append(f"'{t}' is not allowed in a snippet: the system writes the "
                            "kernel, its memory accesses and its synchronisation")
        elif t in C_KEYWORDS:
            continue
        elif prev in C_TYPES_WORDS or (prev in (",", "*") and _in_declaration(toks, i)):
            if t in known or t in inputs:
                problems.append(f"local '{t}' hides a name the snippet is given")
            declared.add(t)
        elif t in inputs:
            if nxt != "(":
                problems.append(f"input '{t}' is read as {t}(y, x, c), with three arguments")
                continue
            args = _call_args(toks, i + 1)
            if len(args) != 3:
                problems.append(f"accessor {t}(...) takes 3 arguments (y, x, c), "
                                f"not {len(args)}")
            elif form == "pointwise" and [a.strip() for a in args[:2]] != ["y", "x"]:
                problems.append(f"a pointwise snippet reads inputs at (y, x) only, but "
                                f"reads {t}({', '.join(a.strip() for a in args)})")
        elif t in outputs:
            problems.append(f"output '{t}' is what the snippet returns; it cannot be read")
        elif nxt == "(" and (t in BUILTINS or t.startswith("convert_")):
            continue
        elif t not in known and t not in declared:
            problems.append(f"unknown name '{t}'")
    if "return" not in {t for _, t in toks} and any(t == ";" for _, t in toks):
        problems.append("statements must end by returning the element: 'return ...;'")
    return list(dict.fromkeys(problems))


def _in_declaration(toks, i: int) -> bool:
    """Token i follows a comma of a declaration statement ('int a = 0, b = 1;')."""
    j = i - 1
    depth = 0
    while j >= 0:
        k, t = toks[j]
        if t in (")", "]"):
            depth += 1
        elif t in ("(", "["):
            if depth == 0:
                return False
            depth -= 1
        elif t in (";", "{", "}") and depth == 0:
            return False
        elif k == "id" and t in C_TYPES_WORDS and depth == 0:
            return True
        j -= 1
    return False


def _call_args(toks, open_index: int) -> list[str]:
    """The top-level arguments of the call whose '(' is at open_index, as text."""
    args, current, depth = [], [], 0
    for _, t in toks[open_index + 1:]:
        if t in ("(", "[", "{"):
            depth += 1
        elif t in (")", "]", "}"):
            if depth == 0:
                break
            depth -= 1
        if t == "," and depth == 0:
            args.append(" ".join(current))
            current = []
            continue
        current.append(t)
    if current or args:
        args.append(" ".join(current))
    return args


def as_body(value: str) -> str:
    """The snippet as statements: an expression becomes one return statement."""
    if any(t == "return" for _, t in tokens(value)):
        return value.strip()
    return f"return ({value.strip()});"
