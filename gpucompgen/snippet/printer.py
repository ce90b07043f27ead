"""Print a parsed snippet as OpenCL C: what reaches a kernel, never the text as written.

Comments, line splices and the author's layout stay behind; the tree is printed one
statement a line, 4 spaces an indentation level, with the parentheses the author wrote
and any that the operators' precedence needs.  Identifiers can be renamed on the way
(``rename``), so a kernel generator can give a snippet's locals, parameters and accessors
names that cannot collide with its own.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from .syntax import (
    BINARY_PREC,
    KEYWORDS,
    TYPE_WORDS,
    Assign,
    Binary,
    Block,
    Call,
    Cast,
    Conditional,
    Decl,
    Declarator,
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
    TypeName,
    Unary,
    VectorLiteral,
    While,
)

INDENT = "    "
WIDTH = 88  # a statement longer than this is laid out on several lines
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
# precedence of what an expression node prints as (higher binds tighter)
_ASSIGN, _COND, _UNARY, _POSTFIX, _PRIMARY = 1, 2, 13, 14, 15


def print_lines(tree: Snippet, rename: Mapping[str, str] | None = None,
                fills: Mapping[str, str] | None = None) -> list[str]:
    """The snippet as C statements, one a line (nested ones indented by 4 spaces).

    rename maps identifiers the snippet uses (locals, parameters, sizes, coordinates,
    accessors) to the names to print.  Renaming must keep names apart and give
    identifiers that are not reserved words; a built-in function cannot be renamed.
    fills maps an accessor to the name its reads with a fill value (four arguments:
    port(y, x, c, fill)) print as, a macro of the kernel generator's.
    """
    return _Printer(_checked(tree, rename or {}), fills or {}).block(tree.body, 0)


def print_text(tree: Snippet, rename: Mapping[str, str] | None = None) -> str:
    return "\n".join(print_lines(tree, rename)) + "\n"


def expression_text(e: Node, rename: Mapping[str, str] | None = None) -> str:
    """One expression, as C (for messages, and for generators that inline an
    expression snippet)."""
    return _Printer(rename or {}).expr(e, 0)


def names_in(tree: Node) -> set[str]:
    """Every identifier the tree uses or declares (built-in calls included)."""
    found: set[str] = set()

    def walk(node) -> None:
        if isinstance(node, Name):
            found.add(node.name)
        elif isinstance(node, Call):
            found.add(node.func)
        elif isinstance(node, Declarator) or isinstance(node, TypeName) and node.name not in TYPE_WORDS \
                and " " not in node.name:
            found.add(node.name)
        if isinstance(node, Node):
            for value in vars(node).values():
                walk(value)
        elif isinstance(node, tuple):
            for item in node:
                walk(item)

    walk(tree)
    return found


def _checked(tree: Snippet, rename: Mapping[str, str]) -> Mapping[str, str]:
    from .check import CONSTANTS, is_builtin

    used = names_in(tree)
    printed: dict[str, str] = {}
    for name in sorted(used):
        new = rename.get(name, name)
        if new != name and (is_builtin(name) or name in CONSTANTS):
            raise ValueError(f"built-in '{name}' cannot be renamed")
        if not _IDENT.match(new) or new in KEYWORDS:
            raise ValueError(f"'{name}' renamed to {new!r}, which is not a C name")
        if new in printed:
            raise ValueError(f"renaming gives '{printed[new]}' and '{name}' the same name "
                             f"'{new}'")
        printed[new] = name
    return rename


class _Printer:
    def __init__(self, rename: Mapping[str, str], fills: Mapping[str, str] | None = None) -> None:
        self.rename = rename
        self.fills = fills or {}

    def n(self, name: str) -> str:
        return self.rename.get(name, name)

    def func(self, e: Call) -> str:
        if len(e.args) == 4 and e.func in self.fills:  # a read with a fill value
            return self.fills[e.func]
        return self.n(e.func)

    # statements
    def block(self, body, level: int) -> list[str]:
        return [line for s in body for line in self.statement(s, level)]

    def statement(self, s: Node, level: int) -> list[str]:
        pad = INDENT * level
        if isinstance(s, Block):
            return [pad + "{", *self.block(s.body, level + 1), pad + "}"]
        if isinstance(s, Decl):
            return [pad + self.decl(s) + ";"]
        if isinstance(s, ExprStmt):
            if s.expr is None:
                return [pad + ";"]
            return self.laid(pad, s.expr, ";")
        if isinstance(s, Return):
            return self.laid(pad + "return ", s.value, ";")
        if isinstance(s, Jump):
            return [f"{pad}{s.word};"]
        if isinstance(s, If):
            then = s.then
            if s.other is not None and _open_if(then):
                then = Block((then,))  # the else belongs to this if, not to the inner one
            lines = self.headed(f"if ({self.expr(s.cond, 0)})", then, level)
            if s.other is not None:
                if isinstance(s.other, If):
                    inner = self.statement(s.other, level)
                    lines.append(f"{pad}else {inner[0].lstrip()}")
                    lines += inner[1:]
                else:
                    lines += self.headed("else", s.other, level)
            return lines
        if isinstance(s, For):
            init = (self.decl(s.init) if isinstance(s.init, Decl)
                    else self.expr(s.init.expr, 0) if s.init.expr is not None else "")
            cond = "" if s.cond is None else " " + self.expr(s.cond, 0)
            step = "" if s.step is None else " " + self.expr(s.step, 0)
            return self.headed(f"for ({init};{cond};{step})", s.body, level)
        if isinstance(s, While):
            return self.headed(f"while ({self.expr(s.cond, 0)})", s.body, level)
        if isinstance(s, DoWhile):
            lines = self.headed("do", s.body, level)
            tail = f"while ({self.expr(s.cond, 0)});"
            if lines[-1].strip() == "}":
                lines[-1] += " " + tail
            else:
                lines.append(pad + tail)
            return lines
        raise TypeError(f"not a statement: {s!r}")

    def laid(self, head: str, e: Node, tail: str) -> list[str]:
        """head + e + tail, on several lines when one would be longer than WIDTH: a
        long '?:' chain one alternative a line, a long && or || chain broken before its
        operators, continuation lines aligned under the expression's start."""
        lines = self.layout(e, 0, len(head))
        return [head + lines[0], *lines[1:-1], lines[-1] + tail] if len(lines) > 1 \
            else [head + lines[0] + tail]

    def layout(self, e: Node, context: int, col: int) -> list[str]:
        """e printed from column col: the first line without indentation, continuation
        lines with theirs (whitespace only differs from expr(): the same tokens)."""
        flat = self.expr(e, context)
        if col + len(flat) + 1 <= WIDTH:
            return [flat]
        if self._expr(e)[1] < context:  # the printer's own parentheses
            return _join(["("], self.layout(e, 0, col + 1), [")"])
        pad = " " * col
        if isinstance(e, Paren):
            return _join(["("], self.layout(e.inner, 0, col + 1), [")"])
        if isinstance(e, Conditional):  # a chain 'a ? b : c ? d : e', an alternative a line
            lines: list[str] = []
            chained = False
            while True:
                cond = self.layout(e.cond, _COND + 1, col + 2 * bool(lines))
                alt = _join(cond, [f" ? {self.expr(e.then, 0)}"])
                lines += alt if not lines else [pad + ": " + alt[0], *alt[1:]]
                e = e.other
                if not isinstance(e, Conditional):
                    last = self.layout(e, _COND, col + 2)
                    used = (col if len(lines) == 1 else 0) + len(lines[-1])
                    if len(last) == 1 and not chained and used + len(last[0]) + 4 <= WIDTH:
                        return [*lines[:-1], f"{lines[-1]} : {last[0]}"]  # 'a ? b : c'
                    return [*lines, pad + ": " + last[0], *last[1:]]
                chained = True
        if isinstance(e, Assign):
            head = f"{self.expr(e.target, _UNARY)} {e.op} "
            return _join([head], self.layout(e.value, _ASSIGN, col + len(head)))
        if isinstance(e, Cast):
            head = f"({self.n(e.type.name)})"
            return _join([head], self.layout(e.operand, _UNARY, col + len(head)))
        if isinstance(e, Call):  # arguments broken after a comma, aligned after '('
            head = f"{self.func(e)}("
            start = col + len(head)
            lines = [""]
            for i, a in enumerate(e.args):
                sep = ", " if i else ""
                used = (start if len(lines) == 1 else 0) + len(lines[-1])
                arg = self.layout(a, _ASSIGN, used + len(sep))
                if i and (len(arg) > 1 or used + len(sep) + len(arg[0]) + 2 > WIDTH):
                    lines[-1] += ","
                    arg = self.layout(a, _ASSIGN, start)
                    lines += [" " * start + arg[0], *arg[1:]]
                else:
                    lines = _join(lines, [sep + arg[0], *arg[1:]])
            return _join([head], lines, [")"])
        if isinstance(e, Binary) and e.op in ("&&", "||"):  # broken before the operators
            op, operands = e.op, []
            while isinstance(e, Binary) and e.op == op:
                operands.append(e.right)
                e = e.left
            p = BINARY_PREC[op]
            parts = [self.expr(e, p)] + [self.expr(o, p + 1) for o in reversed(operands)]
            lines = [parts[0]]
            for part in parts[1:]:
                used = (col if len(lines) == 1 else 0) + len(lines[-1])
                if used + len(op) + len(part) + 2 <= WIDTH:
                    lines[-1] += f" {op} {part}"
                else:
                    lines.append(f"{pad}{op} {part}")
            return lines
        return [flat]

    def headed(self, head: str, body: Node, level: int) -> list[str]:
        pad = INDENT * level
        if isinstance(body, Block):
            return [f"{pad}{head} {{", *self.block(body.body, level + 1), pad + "}"]
        return [pad + head, *self.statement(body, level + 1)]

    def decl(self, d: Decl) -> str:
        return f"{self.type(d.type)} " + ", ".join(self.declarator(v) for v in d.declarators)

    def type(self, t: TypeName) -> str:
        name = self.n(t.name)  # OpenCL C's types are never renamed; a port's may be
        return f"const {name}" if t.const else name

    def declarator(self, v: Declarator) -> str:
        text = self.n(v.name)
        if v.size is not None:
            text += f"[{self.expr(v.size, 0)}]"
        if isinstance(v.init, InitList):
            text += " = {" + ", ".join(self.expr(i, _ASSIGN) for i in v.init.items) + "}"
        elif v.init is not None:
            text += f" = {self.expr(v.init, _ASSIGN)}"
        return text

    # expressions
    def expr(self, e: Node, context: int) -> str:
        text, prec = self._expr(e)
        return f"({text})" if prec < context else text

    def _expr(self, e: Node) -> tuple[str, int]:
        if isinstance(e, Name):
            return self.n(e.name), _PRIMARY
        if isinstance(e, Number):
            return e.text, _PRIMARY
        if isinstance(e, Paren):
            return f"({self.expr(e.inner, 0)})", _PRIMARY
        if isinstance(e, Call):
            return f"{self.func(e)}({self.args(e.args)})", _POSTFIX
        if isinstance(e, Index):
            return f"{self.expr(e.base, _POSTFIX)}[{self.expr(e.index, 0)}]", _POSTFIX
        if isinstance(e, Member):
            base = self.expr(e.base, _POSTFIX)
            if isinstance(e.base, Number):
                base = f"({base})"
            return f"{base}.{e.field}", _POSTFIX
        if isinstance(e, Postfix):
            return f"{self.expr(e.operand, _POSTFIX)}{e.op}", _POSTFIX
        if isinstance(e, Unary):
            operand = self.expr(e.operand, _UNARY)
            sep = " " if operand[:1] in "+-" and e.op[-1] in "+-" else ""
            return f"{e.op}{sep}{operand}", _UNARY
        if isinstance(e, Cast):
            return f"({self.n(e.type.name)}){self.expr(e.operand, _UNARY)}", _UNARY
        if isinstance(e, VectorLiteral):
            return f"({e.type.name})({self.args(e.args)})", _UNARY
        if isinstance(e, Binary):
            p = BINARY_PREC[e.op]
            return f"{self.expr(e.left, p)} {e.op} {self.expr(e.right, p + 1)}", p
        if isinstance(e, Conditional):
            return (f"{self.expr(e.cond, _COND + 1)} ? {self.expr(e.then, 0)} : "
                    f"{self.expr(e.other, _COND)}"), _COND
        if isinstance(e, Assign):
            return f"{self.expr(e.target, _UNARY)} {e.op} {self.expr(e.value, _ASSIGN)}", _ASSIGN
        raise TypeError(f"not an expression: {e!r}")

    def args(self, args) -> str:
        return ", ".join(self.expr(a, _ASSIGN) for a in args)


def _join(*parts: list[str]) -> list[str]:
    """Line lists written one after the other: each list's first line continues the
    previous list's last line."""
    lines: list[str] = []
    for part in parts:
        if lines:
            lines[-1] += part[0]
            lines += part[1:]
        else:
            lines = list(part)
    return lines


def _open_if(s: Node) -> bool:
    """The statement ends with an 'if' without 'else' (which would take a following else)."""
    while True:
        if isinstance(s, If):
            if s.other is None:
                return True
            s = s.other
        elif isinstance(s, (For, While)):
            s = s.body
        else:
            return False
