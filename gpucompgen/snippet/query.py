"""Questions the fusion pass and the kernel generator ask of a parsed snippet: which
accessor calls it makes and with what arguments, whether it uses a name elsewhere, and
what an element's evaluation computes (operations).  They read the tree, so comments,
strings of tokens and layout cannot mislead them."""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from . import syntax as S
from .check import returns


def _children(node) -> Iterator:
    if isinstance(node, S.Node):
        yield from vars(node).values()
    elif isinstance(node, tuple):
        yield from node


def accessor_calls(tree: S.Node, ports: list[str]) -> dict[str, list[tuple[S.Node, ...]]]:
    """Every call port(a, b, c) of the given accessors, its argument trees, per port, in
    the order they appear."""
    found: dict[str, list[tuple[S.Node, ...]]] = {p: [] for p in ports}

    def walk(node) -> None:
        if isinstance(node, S.Call) and node.func in found:
            found[node.func].append(node.args)
        for child in _children(node):
            walk(child)

    walk(tree)
    return found


def uses_outside_calls(tree: S.Node, funcs: list[str], names: set[str]) -> bool:
    """Whether the snippet uses any of names other than inside a call of funcs."""
    def walk(node) -> bool:
        if isinstance(node, S.Call) and node.func in funcs:
            return False
        if isinstance(node, S.Name) and node.name in names:
            return True
        return any(walk(child) for child in _children(node))

    return walk(tree)


def unparen(node: S.Node) -> S.Node:
    while isinstance(node, S.Paren):
        node = node.inner
    return node


def is_name(node: S.Node, name: str) -> bool:
    node = unparen(node)
    return isinstance(node, S.Name) and node.name == name


def is_shifted(node: S.Node, name: str) -> bool:
    """name, or name plus or minus an expression that does not use name."""
    node = unparen(node)
    if is_name(node, name):
        return True
    return (isinstance(node, S.Binary) and node.op in "+-" and is_name(node.left, name)
            and not uses_outside_calls(node.right, [], {name}))


# what operations() counts as one operation where a value the element depends on is
# computed (a value of constants, parameters and sizes only is folded or hoisted out of
# the element loop by the compiler: free)
_STATIC_KINDS = frozenset({"param", "size", "limit", "constant", "type", "builtin"})


def operations(tree: S.Node, names: Mapping[str, str]) -> int:
    """Operations one evaluation of a loop-free snippet computes: each operator, cast and
    built-in call on a value that depends on the element (a coordinate, an input read, a
    local computed from one); none for a value of parameters and constants, which the
    kernel computes once.  A choice whose condition is such a value (a rule picked by a
    parameter) costs its dearest branch, one taken everywhere; a choice on an element's
    value costs both branches and a select, as vector code computes them.  A loop counts
    its body once (stencils, whose loops walk a window, are priced by their reads).
    names: the snippet's names and their kinds (FusableDecl.names)."""
    static = {n for n, kind in names.items() if kind in _STATIC_KINDS}
    assigned = set()
    for a in nodes(tree):
        target = a.target if isinstance(a, S.Assign) else \
            a.operand if isinstance(a, (S.Unary, S.Postfix)) and a.op in ("++", "--") else None
        if target is not None and isinstance(unparen(target), S.Name):
            assigned.add(unparen(target).name)
    return _Counter(static, assigned).statement(tree)


def nodes(node) -> Iterator:
    """node and every node below it, depth first (the tree's values that are nodes)."""
    yield node
    for child in _children(node):
        yield from nodes(child)


class _Counter:
    def __init__(self, static: set[str], assigned: set[str]):
        self.static, self.assigned = set(static), assigned

    def statement(self, s) -> int:
        if isinstance(s, (S.Snippet, S.Block)):
            return self.block(s.body)
        if isinstance(s, S.Decl):
            total = 0
            for d in s.declarators:
                if d.init is None:
                    continue
                ops, fixed = self.expr(d.init)
                total += ops
                if fixed and d.name not in self.assigned and d.size is None:
                    self.static.add(d.name)
            return total
        if isinstance(s, S.ExprStmt):
            return self.expr(s.expr)[0] if s.expr is not None else 0
        if isinstance(s, S.Return):
            return self.expr(s.value)[0]
        if isinstance(s, S.If):
            ops, fixed = self.expr(s.cond)
            then = self.statement(s.then)
            other = self.statement(s.other) if s.other is not None else 0
            return max(then, other) if fixed else ops + then + other + 1
        if isinstance(s, (S.For, S.While, S.DoWhile)):
            parts = [s.body] + [p for p in (getattr(s, "init", None), s.cond,
                                            getattr(s, "step", None)) if p is not None]
            return sum(self.statement(p) if not _is_expr(p) else self.expr(p)[0]
                       for p in parts)
        return 0  # break, continue

    def block(self, body: tuple) -> int:
        """A block's statements; an 'if' without 'else' whose body always returns makes
        the statements after it its other branch (one or the other runs, as for an
        if-else: 'if (float type) { ... return; } <the integer code>')."""
        total = 0
        for i, s in enumerate(body):
            if isinstance(s, S.If) and s.other is None and returns([s.then]):
                ops, fixed = self.expr(s.cond)
                then, rest = self.statement(s.then), self.block(body[i + 1:])
                return total + (max(then, rest) if fixed else ops + then + rest + 1)
            total += self.statement(s)
        return total

    def expr(self, e) -> tuple[int, bool]:
        """(operations, whether the value is the same for every element)."""
        if isinstance(e, S.Number):
            return 0, True
        if isinstance(e, S.Name):
            return 0, e.name in self.static
        if isinstance(e, S.TypeName):
            return 0, True
        if isinstance(e, (S.Paren, S.Member)):
            return self.expr(e.inner if isinstance(e, S.Paren) else e.base)
        if isinstance(e, S.Conditional):
            ops, fixed = self.expr(e.cond)
            (a, fa), (b, fb) = self.expr(e.then), self.expr(e.other)
            if fixed:
                return max(a, b), fa and fb
            return ops + a + b + 1, False
        if isinstance(e, S.Call):
            if e.func not in self.static:  # an input's accessor: a load, counted apart
                return sum(self.expr(a)[0] for a in e.args), False
            return self._op(e.args)
        if isinstance(e, (S.Unary, S.Postfix, S.Cast)):
            return self._op([e.operand])
        if isinstance(e, S.Binary):
            return self._op([e.left, e.right])
        if isinstance(e, S.Assign):
            ops, fixed = self.expr(e.value)
            return (ops + (e.op != "=" and not fixed), fixed)
        if isinstance(e, S.Index):
            (a, fa), (b, fb) = self.expr(e.base), self.expr(e.index)
            return a + b, fa and fb
        if isinstance(e, (S.VectorLiteral, S.InitList)):
            items = e.args if isinstance(e, S.VectorLiteral) else e.items
            parts = [self.expr(a) for a in items]
            return sum(p[0] for p in parts), all(p[1] for p in parts)
        return 0, False

    def _op(self, operands) -> tuple[int, bool]:
        parts = [self.expr(a) for a in operands]
        fixed = all(p[1] for p in parts)
        return sum(p[0] for p in parts) + (not fixed), fixed


def _is_expr(node) -> bool:
    return not isinstance(node, (S.Decl, S.ExprStmt, S.Block, S.If, S.For, S.While,
                                 S.DoWhile, S.Return, S.Jump, S.Snippet))
