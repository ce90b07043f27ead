"""A snippet with the choices its build's constants decide already made.

A library snippet serves every element type and parameter value of its type: Sobel's sums
integers for uint8 frames and floats for float32 ones (``if ((src_t)0.5f == (src_t)0)``),
MedianBlur chooses its method by ``ksize``.  The kernel of one component is written for
one element type and one set of fixed parameters: ``prune(tree, values, types)`` keeps
only the branches those choose, so that the generated code reads as if written for it,
and so that what the kernel generator counts (the reads it unrolls) is what the compiler
gets.  values: the names whose values are fixed at build time (the parameters that fix
the window, the ports' sizes and limits); types: the ports' element types (src_t ->
'uchar').  An ``if`` whose condition they decide becomes the branch taken (its block's
statements in place where no name would clash; the statements after one that always
returns dropped); a ``const`` local whose initializer they decide is known below it, and
dropped where nothing reads it any more.  Nothing else changes: a condition on a
parameter --set may change, or on an element's value, stays as written.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import replace

from . import syntax as S
from .check import fold, returns
from .query import nodes, unparen

_INT_TYPES = {"char": (8, True), "uchar": (8, False), "short": (16, True),
              "ushort": (16, False), "int": (32, True), "uint": (32, False),
              "unsigned int": (32, False), "long": (64, True), "ulong": (64, False),
              "bool": (1, False)}


def prune(tree: S.Snippet, values: Mapping[str, object],
          types: Mapping[str, str]) -> S.Snippet:
    """The snippet with the branches values and types decide taken (see the module)."""
    body = _Pruner(values, types).block(tree.body, {})
    return replace(tree, body=_drop_unused(body))


class _Pruner:
    def __init__(self, values: Mapping[str, object], types: Mapping[str, str]) -> None:
        self.values = {k: v for k, v in values.items()
                       if isinstance(v, (int, float)) and not isinstance(v, bool)}
        self.types = types

    # -- statements ---------------------------------------------------------------------
    def block(self, body: tuple, env: dict) -> tuple:
        out: list = []
        for i, s in enumerate(body):
            kept = self.statement(s, env)
            if kept is None:
                continue
            taken = kept[1] if isinstance(kept, tuple) else None
            if taken is not None:  # an if decided: its branch's statements
                inner = taken.body if isinstance(taken, S.Block) else (taken,)
                clash = _declared(inner) & (_declared(body[:i]) | _declared(body[i + 1:]))
                if clash:
                    out.append(taken if isinstance(taken, S.Block)
                               else S.Block(inner, at=taken.at))
                else:
                    out.extend(inner)
                if returns(inner):
                    break
                continue
            out.append(kept)
            if returns((kept,)):
                break
        return tuple(out)

    def statement(self, s, env: dict):
        if isinstance(s, S.Decl):
            for d in s.declarators:
                env.pop(d.name, None)
                if s.type.const and d.size is None and d.init is not None:
                    v = self.expr(d.init, env)
                    if v is not None:
                        env[d.name] = _cast(v, self.resolve(s.type.name))
            return s
        if isinstance(s, S.If):
            v = self.expr(s.cond, env)
            if v is None:
                then = self.nested(s.then, env)
                other = None if s.other is None else self.nested(s.other, env)
                return replace(s, then=then, other=other)
            chosen = s.then if v else s.other
            if chosen is None:
                return None
            chosen = self.nested(chosen, env)
            return ("taken", chosen)
        if isinstance(s, S.Block):
            return replace(s, body=self.block(s.body, dict(env)))
        if isinstance(s, S.For):
            inner = dict(env)
            self.statement(s.init, inner)
            return replace(s, body=self.nested(s.body, inner))
        if isinstance(s, (S.While, S.DoWhile)):
            return replace(s, body=self.nested(s.body, dict(env)))
        return s

    def nested(self, s, env: dict):
        """A branch or loop body, pruned in a scope of its own."""
        if isinstance(s, S.Block):
            return replace(s, body=self.block(s.body, dict(env)))
        kept = self.statement(s, dict(env))
        if isinstance(kept, tuple):
            return kept[1]
        return kept if kept is not None else S.Block((), at=s.at)

    # -- expressions ----------------------------------------------------------------------
    def resolve(self, name: str) -> str:
        return self.types.get(name, name)

    def expr(self, e, env: dict):
        """The value of e where the constants decide it, else None."""
        e = unparen(e)
        if isinstance(e, S.Number):
            return e.value
        if isinstance(e, S.Name):
            return env[e.name] if e.name in env else self.values.get(e.name)
        if isinstance(e, S.Cast):
            v = self.expr(e.operand, env)
            return None if v is None else _cast(v, self.resolve(e.type.name))
        if isinstance(e, S.Unary):
            v = self.expr(e.operand, env)
            if v is None or e.op not in ("!", "-", "+"):
                return None
            return int(not v) if e.op == "!" else -v if e.op == "-" else v
        if isinstance(e, S.Binary):
            return self.binary(e, env)
        if isinstance(e, S.Conditional):
            c = self.expr(e.cond, env)
            return None if c is None else self.expr(e.then if c else e.other, env)
        if isinstance(e, S.Call) and e.func in ("min", "max") and len(e.args) == 2:
            a, b = (self.expr(x, env) for x in e.args)
            return None if a is None or b is None else (min if e.func == "min" else max)(a, b)
        return None

    def binary(self, e: S.Binary, env: dict):
        a = self.expr(e.left, env)
        if e.op in ("&&", "||"):
            if a is not None and (not a if e.op == "&&" else a):
                return int(bool(a))
            b = self.expr(e.right, env)
            if b is not None and (not b if e.op == "&&" else b):
                return int(bool(b))
            return None if a is None or b is None else int(bool(b))
        b = self.expr(e.right, env)
        if a is None or b is None:
            return None
        v = fold(e.op, a, b)  # as C computes it; None where C gives no number
        return None if v is None or isinstance(v, int) and abs(v) > 1 << 64 else v


def _cast(v, ctype: str):
    """v converted to a scalar C type as C converts it (None: a type not known here)."""
    if ctype in ("float", "half", "double"):
        return struct.unpack("f", struct.pack("f", float(v)))[0] if ctype == "float" \
            else float(v)
    if ctype not in _INT_TYPES:
        return None
    bits, signed = _INT_TYPES[ctype]
    if ctype == "bool":
        return int(bool(v))
    n = int(v)  # toward zero, as C converts a float
    n &= (1 << bits) - 1
    return n - (1 << bits) if signed and n >= 1 << (bits - 1) else n


def _declared(body) -> set[str]:
    """The names declared at the top level of these statements."""
    return {d.name for s in body if isinstance(s, S.Decl) for d in s.declarators}


def _drop_unused(body: tuple) -> tuple:
    """The statements without const locals nothing reads (their initializers have no
    effect), repeated until none is left."""
    while True:
        used = _names_read(body)
        kept = tuple(_without(body, used))
        if kept == body:
            return body
        body = kept


def _without(body, used: set[str]):
    for s in body:
        if isinstance(s, S.Decl) and s.type.const and all(
                d.name not in used and d.size is None and _pure(d.init)
                for d in s.declarators):
            continue
        if isinstance(s, S.Block):
            yield replace(s, body=tuple(_without(s.body, used)))
        elif isinstance(s, S.If):
            yield replace(s, then=_one(s.then, used),
                          other=None if s.other is None else _one(s.other, used))
        elif isinstance(s, (S.For, S.While, S.DoWhile)):
            yield replace(s, body=_one(s.body, used))
        else:
            yield s


def _one(s, used: set[str]):
    if isinstance(s, S.Block):
        return replace(s, body=tuple(_without(s.body, used)))
    return s


def _pure(e) -> bool:
    """An initializer without effects: no assignment, increment or call of anything but a
    built-in on pure arguments (an accessor's read is pure too: it only loads)."""
    if e is None:
        return True
    if isinstance(e, (S.Assign, S.Postfix)) or isinstance(e, S.Unary) and e.op in ("++", "--"):
        return False
    if isinstance(e, S.Node):
        return all(_pure(v) for v in vars(e).values() if isinstance(v, (S.Node, tuple)))
    if isinstance(e, tuple):
        return all(_pure(v) for v in e)
    return True


def _names_read(tree) -> set[str]:
    """Every name the statements read (a declaration's own name is not a read)."""
    return {n.name for n in nodes(tree) if isinstance(n, S.Name)}
