"""The snippet language: its syntax tree and a recursive-descent parser for it.

A whitelist of OpenCL C, the part a per-element snippet needs (every library snippet is
written in it).  Anything else is a positioned error, never passed on to the compiler::

    snippet     := expression | statement+          (statements end by returning)
    statement   := declaration | '{' statement* '}' | 'if' '(' expr ')' statement
                   ['else' statement] | 'for' '(' (declaration | [expr] ';') [expr] ';'
                   [expr] ')' statement | 'while' '(' expr ')' statement
                   | 'do' statement 'while' '(' expr ')' ';' | 'return' expr ';'
                   | 'break' ';' | 'continue' ';' | [expr] ';'
    declaration := ['const'] type declarator (',' declarator)* ';'
    declarator  := name ['[' expr ']'] ['=' (expr | '{' expr (',' expr)* [','] '}')]
    type        := a scalar type (bool, char, uchar, short, ushort, int, uint, long, ulong,
                   float, half, double, size_t, 'unsigned int', ...), a vector type
                   (char2 ... double16) or a port's element type <port>_t (src_t: the
                   element type of port src, uchar, short or float as the model resolves
                   it; parse's 'types')
    expr        := C's expressions without the comma operator, pointers (unary '*' and
                   '&', '->'), 'sizeof', strings and compound literals other than vector
                   literals '(float4)(a, b, c, d)'; calls name a function (an accessor
                   or a built-in); '.' selects vector components

Nesting (parentheses, operators, statements) is limited to MAX_NESTING levels, so a
snippet can neither exhaust the parser nor the compiler's bracket depth.

The tree keeps each node's offset in the snippet (not compared: two trees are equal when
they mean the same code) and every parenthesis the author wrote (``Paren``), so printing
it gives back the author's grouping.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from .lexer import Token, tokens
from .problems import SnippetError

MAX_NESTING = 32  # brackets, prefix operators and statements inside each other
MAX_DEPTH = 100  # levels of the tree (a chain 'a + b + c' is a level an operator)

SCALARS = ("bool", "char", "uchar", "short", "ushort", "int", "uint", "long", "ulong",
           "float", "half", "double", "size_t")
VECTOR_BASES = ("char", "uchar", "short", "ushort", "int", "uint", "long", "ulong", "float",
                "half", "double")
VECTORS = tuple(f"{b}{n}" for b in VECTOR_BASES for n in (2, 3, 4, 8, 16))
SIGNS = ("unsigned", "signed")
TYPE_WORDS = frozenset(SCALARS + VECTORS + SIGNS)
STATEMENT_WORDS = frozenset({"if", "else", "for", "while", "do", "return", "break",
                             "continue", "const"})
# C and OpenCL C keywords a snippet cannot use as names (most it cannot use at all)
KEYWORDS = TYPE_WORDS | STATEMENT_WORDS | frozenset({
    "true", "false", "void", "switch", "case", "default", "goto", "sizeof", "struct",
    "union", "enum", "typedef", "static", "extern", "auto", "register", "inline",
    "volatile", "restrict", "__global", "global", "__local", "local", "__constant",
    "constant", "__private", "private", "__kernel", "kernel", "__attribute__", "_Bool",
    "__read_only", "read_only", "__write_only", "write_only", "image2d_t", "sampler_t",
    "event_t", "vec_step", "__generic", "generic", "ptrdiff_t", "intptr_t", "uintptr_t"})
ASSIGN_OPS = ("=", "+=", "-=", "*=", "/=", "%=", "<<=", ">>=", "&=", "^=", "|=")
BINARY_PREC = {"||": 3, "&&": 4, "|": 5, "^": 6, "&": 7, "==": 8, "!=": 8, "<": 9, ">": 9,
               "<=": 9, ">=": 9, "<<": 10, ">>": 10, "+": 11, "-": 11, "*": 12, "/": 12,
               "%": 12}
PREFIX_OPS = ("+", "-", "!", "~", "++", "--")
COMPONENTS = re.compile(r"[xyzw]{1,4}|[sS][0-9a-fA-F]{1,16}|lo|hi|even|odd\Z")
_INT = re.compile(r"(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)([uU](ll|LL|l|L)?|(ll|LL|l|L)[uU]?)?")
_FLOAT = re.compile(r"((\d+\.\d*|\.\d+)([eE][+-]?\d+)?|\d+[eE][+-]?\d+)[fFhH]?")
MAX_LITERAL = (1 << 64) - 1


# -- the tree --------------------------------------------------------------------------
@dataclass(frozen=True)
class Node:
    at: int = field(default=0, compare=False, kw_only=True)  # offset in the snippet


@dataclass(frozen=True)
class TypeName(Node):
    name: str  # 'int', 'unsigned int', 'float4'
    const: bool = False


@dataclass(frozen=True)
class Name(Node):
    name: str


@dataclass(frozen=True)
class Number(Node):
    text: str  # as written: 255, 32768u, 0x1F, 0.5f, true, false

    @property
    def value(self) -> int | float:
        if self.text in ("true", "false"):
            return int(self.text == "true")
        m = _INT.fullmatch(self.text)
        if m:
            digits = m.group(1)
            base = 16 if digits[:2] in ("0x", "0X") else 8 if len(digits) > 1 and \
                digits[0] == "0" else 10
            return int(digits, base)
        return float(self.text.rstrip("fFhH"))

    @property
    def is_float(self) -> bool:
        return _INT.fullmatch(self.text) is None and self.text not in ("true", "false")


@dataclass(frozen=True)
class Paren(Node):
    inner: Node


@dataclass(frozen=True)
class Unary(Node):
    op: str  # + - ! ~ ++ -- (prefix)
    operand: Node


@dataclass(frozen=True)
class Postfix(Node):
    op: str  # ++ --
    operand: Node


@dataclass(frozen=True)
class Binary(Node):
    op: str
    left: Node
    right: Node


@dataclass(frozen=True)
class Assign(Node):
    op: str  # one of ASSIGN_OPS
    target: Node
    value: Node


@dataclass(frozen=True)
class Conditional(Node):
    cond: Node
    then: Node
    other: Node


@dataclass(frozen=True)
class Call(Node):
    func: str  # an accessor (input port) or a built-in function
    args: tuple[Node, ...]


@dataclass(frozen=True)
class Index(Node):
    base: Node
    index: Node


@dataclass(frozen=True)
class Member(Node):
    base: Node
    field: str  # vector components: x, xy, s0, lo, ...


@dataclass(frozen=True)
class Cast(Node):
    type: TypeName
    operand: Node


@dataclass(frozen=True)
class VectorLiteral(Node):
    type: TypeName
    args: tuple[Node, ...]


@dataclass(frozen=True)
class InitList(Node):
    items: tuple[Node, ...]


@dataclass(frozen=True)
class Declarator(Node):
    name: str
    size: Node | None = None  # an array's length
    init: Node | None = None


@dataclass(frozen=True)
class Decl(Node):
    type: TypeName
    declarators: tuple[Declarator, ...]


@dataclass(frozen=True)
class ExprStmt(Node):
    expr: Node | None  # None: the empty statement ';'


@dataclass(frozen=True)
class Block(Node):
    body: tuple[Node, ...]


@dataclass(frozen=True)
class If(Node):
    cond: Node
    then: Node
    other: Node | None = None


@dataclass(frozen=True)
class For(Node):
    init: Node  # Decl or ExprStmt
    cond: Node | None
    step: Node | None
    body: Node


@dataclass(frozen=True)
class While(Node):
    cond: Node
    body: Node


@dataclass(frozen=True)
class DoWhile(Node):
    body: Node
    cond: Node


@dataclass(frozen=True)
class Return(Node):
    value: Node


@dataclass(frozen=True)
class Jump(Node):
    word: str  # break | continue


@dataclass(frozen=True)
class Snippet(Node):
    """A parsed snippet: statements; an expression snippet is one Return (expression)."""

    body: tuple[Node, ...]
    expression: bool = field(default=False, compare=False)  # written as an expression


# -- the parser ------------------------------------------------------------------------
def parse(text: str, types: Mapping[str, str] | None = None) -> Snippet:
    """The snippet's tree, or SnippetError at the first thing outside the language.  types
    are the type names the snippet is given beyond OpenCL C's ('src_t' -> port 'src',
    whose element type it names): written where a type may be, never as values."""
    tree = _Parser(tokens(text), types or {}).snippet()
    _check_depth(tree)
    return tree


def _check_depth(tree: Snippet) -> None:
    """Refuse a tree deeper than MAX_DEPTH (a long chain 'a + b + c + ...' or
    'v[0][0]...' nests without brackets), measured without recursion: whatever reads
    the tree afterwards (names, printing) may recurse."""
    stack = [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise SnippetError(node.at, f"the snippet nests deeper than {MAX_DEPTH} levels "
                               "(a chain of operators counts a level each)",
                               "split it into steps with locals")
        for value in vars(node).values():
            children = value if isinstance(value, tuple) else (value,)
            stack += [(c, depth + 1) for c in children if isinstance(c, Node)]


class _Parser:
    def __init__(self, toks: list[Token], types: Mapping[str, str]) -> None:
        self.toks = toks
        self.port_types = types  # 'src_t' -> 'src'
        self.types = TYPE_WORDS | frozenset(types)
        self.i = 0
        self.depth = 0

    # tokens
    @property
    def tok(self) -> Token:
        return self.toks[self.i]

    def peek(self, k: int = 1) -> Token:
        return self.toks[min(self.i + k, len(self.toks) - 1)]

    def at(self, *texts: str) -> bool:
        return self.tok.kind in ("op", "id") and self.tok.text in texts

    def take(self) -> Token:
        t = self.tok
        if t.kind != "end":
            self.i += 1
        return t

    def expect(self, text: str, what: str = "", opener: Token | None = None) -> Token:
        if opener is not None and self.tok.kind == "end":
            raise self.error(f"'{opener.text}' is never closed", f"close it with '{text}'",
                             token=opener)
        if not self.at(text):
            raise self.error(f"expected '{text}'{what}, found {self.shown(self.tok)}")
        return self.take()

    def error(self, message: str, hint: str = "", token: Token | None = None) -> SnippetError:
        return SnippetError((token or self.tok).offset, message, hint)

    @staticmethod
    def shown(t: Token) -> str:
        return "the end of the snippet" if t.kind == "end" else f"'{t.text}'"

    def enter(self) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise self.error(f"the snippet nests deeper than {MAX_NESTING} levels "
                             "(parentheses, operators and statements)",
                             "split it into steps with const locals")

    def leave(self) -> None:
        self.depth -= 1

    # snippet and statements
    def snippet(self) -> Snippet:
        statements = any((t.kind == "op" and t.text in (";", "{"))
                         or (t.kind == "id" and t.text == "return") for t in self.toks)
        if not statements:
            expr = self.expression()
            if self.tok.kind != "end":
                raise self.error(f"unexpected {self.shown(self.tok)} after the expression")
            return Snippet((Return(expr, at=expr.at),), expression=True, at=0)
        body = []
        while self.tok.kind != "end":
            body.append(self.statement(top=True))
        return Snippet(tuple(body), at=0)

    def statement(self, top: bool = False, block: bool = False) -> Node:
        """A statement; a declaration only where block says one may be (in a block or at
        the top, not as the body of if, else, for, while or do, where C refuses it)."""
        self.enter()
        try:
            return self._statement(top, block or top)
        finally:
            self.leave()

    def _statement(self, top: bool, block: bool) -> Node:
        t = self.tok
        if t.kind == "end":
            raise self.error("expected a statement, found the end of the snippet",
                             "a snippet's statements end by returning: 'return ...;'")
        if self.at("{"):
            self.take()
            body = []
            while not self.at("}"):
                if self.tok.kind == "end":
                    self.expect("}", opener=t)
                body.append(self.statement(block=True))
            self.take()
            return Block(tuple(body), at=t.offset)
        if self.is_type_start():
            if not block:
                raise self.error("a declaration cannot be the body of if, else, for, while "
                                 "or do", "put it in braces: { ... }")
            return self.declaration()
        if t.kind == "id" and t.text in ("if", "while", "do", "for", "return", "break",
                                         "continue"):
            return getattr(self, f"stmt_{t.text}")()
        if self.at(";"):
            self.take()
            return ExprStmt(None, at=t.offset)
        expr = self.expression()
        if top and self.tok.kind == "end":
            raise self.error("statements must end by returning the element: 'return ...;'",
                             "write the last value as 'return ...;'")
        self.expect(";", " after the expression")
        return ExprStmt(expr, at=t.offset)

    def stmt_if(self) -> Node:
        t = self.take()
        cond = self.condition()
        then = self.statement()
        other = None
        if self.at("else"):
            self.take()
            other = self.statement()
        return If(cond, then, other, at=t.offset)

    def stmt_while(self) -> Node:
        t = self.take()
        cond = self.condition()
        return While(cond, self.statement(), at=t.offset)

    def stmt_do(self) -> Node:
        t = self.take()
        body = self.statement()
        self.expect("while", " after the body of 'do'")
        cond = self.condition()
        self.expect(";", " after 'do ... while (...)'")
        return DoWhile(body, cond, at=t.offset)

    def stmt_for(self) -> Node:
        t = self.take()
        self.expect("(", " after 'for'")
        if self.is_type_start():
            init: Node = self.declaration()
        else:
            start = self.tok.offset
            init = ExprStmt(None if self.at(";") else self.expression(), at=start)
            self.expect(";", " in 'for (...)'")
        cond = None if self.at(";") else self.expression()
        self.expect(";", " in 'for (...)'")
        step = None if self.at(")") else self.expression()
        self.expect(")", " to close 'for (...)'")
        return For(init, cond, step, self.statement(), at=t.offset)

    def stmt_return(self) -> Node:
        t = self.take()
        if self.at(";"):
            raise self.error("'return' needs the element's value", "return ...;")
        value = self.expression()
        self.expect(";", " after the returned value")
        return Return(value, at=t.offset)

    def stmt_break(self) -> Node:
        t = self.take()
        self.expect(";", f" after '{t.text}'")
        return Jump(t.text, at=t.offset)

    stmt_continue = stmt_break

    def condition(self) -> Node:
        self.expect("(", " before the condition")
        cond = self.expression()
        self.expect(")", " after the condition")
        return cond

    # declarations
    def is_type_start(self) -> bool:
        return self.tok.kind == "id" and (self.tok.text in self.types or self.tok.text == "const")

    def type_name(self) -> TypeName:
        t = self.tok
        const = False
        if self.at("const"):
            self.take()
            const = True
        if self.at(*SIGNS):
            sign = self.take().text
            if self.at("char", "short", "int", "long"):
                name = f"{sign} {self.take().text}"
            else:
                name = sign
        elif self.tok.kind == "id" and self.tok.text in self.types:
            name = self.take().text
        else:
            ports = ", ".join(self.port_types) or "none here"
            raise self.error(f"expected a type, found {self.shown(self.tok)}",
                             "types: bool, char, uchar, short, ushort, int, uint, long, "
                             "ulong, float, half, double, size_t, vectors like uchar4 and "
                             f"the ports' element types <port>_t ({ports})")
        if self.at("const"):
            raise self.error("write 'const' before the type", f"const {name}")
        return TypeName(name, const, at=t.offset)

    def declaration(self) -> Node:
        t = self.tok
        ty = self.type_name()
        declarators = [self.declarator()]
        while self.at(","):
            self.take()
            declarators.append(self.declarator())
        self.expect(";", " after the declaration")
        return Decl(ty, tuple(declarators), at=t.offset)

    def declarator(self) -> Declarator:
        if self.at("*"):
            raise self.error("pointers are not part of the snippet language",
                             "read inputs with their accessors: <port>(y, x, c)")
        t = self.name("a name for the local")
        size = init = None
        if self.at("["):
            self.take()
            size = self.expression()
            self.expect("]", " after the array's length")
        if self.at("="):
            self.take()
            if self.at("{"):
                start = self.take()
                items = [self.assignment()]
                while self.at(","):
                    self.take()
                    if self.at("}"):
                        break
                    items.append(self.assignment())
                self.expect("}", " to close the initializer list")
                init = InitList(tuple(items), at=start.offset)
            else:
                init = self.assignment()
        return Declarator(t.text, size, init, at=t.offset)

    def name(self, what: str) -> Token:
        t = self.tok
        if t.kind != "id":
            raise self.error(f"expected {what}, found {self.shown(t)}")
        if t.text in KEYWORDS:
            raise self.error(f"'{t.text}' is a reserved word of OpenCL C, not a name",
                             "choose another name")
        if t.text in self.port_types:
            raise self.error(f"'{t.text}' names the element type of port "
                             f"'{self.port_types[t.text]}', not a local",
                             "choose another name")
        return self.take()

    # expressions
    def expression(self) -> Node:
        expr = self.assignment()
        if self.at(","):
            raise self.error("the comma operator is not part of the snippet language",
                             "write two statements")
        return expr

    def assignment(self) -> Node:
        start = self.tok
        left = self.conditional()
        if not self.at(*ASSIGN_OPS):
            return left
        op = self.take()
        self.enter()
        try:
            return Assign(op.text, left, self.assignment(), at=start.offset)
        finally:
            self.leave()

    def conditional(self) -> Node:
        start = self.tok
        cond = self.binary(3)
        if not self.at("?"):
            return cond
        self.take()
        self.enter()
        try:
            then = self.expression()
            self.expect(":", " in 'a ? b : c'")
            other = self.conditional()
        finally:
            self.leave()
        return Conditional(cond, then, other, at=start.offset)

    def binary(self, min_prec: int) -> Node:
        start = self.tok
        left = self.unary()
        while self.tok.kind == "op" and BINARY_PREC.get(self.tok.text, 0) >= min_prec:
            op = self.take().text
            right = self.binary(BINARY_PREC[op] + 1)
            left = Binary(op, left, right, at=start.offset)
        return left

    def unary(self) -> Node:
        t = self.tok
        if t.kind == "op" and t.text in PREFIX_OPS:
            self.take()
            self.enter()
            try:
                return Unary(t.text, self.unary(), at=t.offset)
            finally:
                self.leave()
        if t.kind == "op" and t.text in ("*", "&"):
            raise self.error(f"unary '{t.text}' (pointers) is not part of the snippet language",
                             "read inputs with their accessors: <port>(y, x, c)")
        if t.kind == "id" and t.text == "sizeof":
            raise self.error("'sizeof' is not part of the snippet language",
                             "write the size as a number")
        if self.at("(") and self.peek().kind == "id" and (self.peek().text in self.types
                                                           or self.peek().text == "const"):
            self.take()
            ty = self.type_name()
            self.expect(")", " after the type of a cast")
            self.enter()
            try:
                if ty.name in VECTORS and self.at("("):
                    args = self.arguments(self.take())
                    if self.at("(", "[", ".", "++", "--", "->"):
                        raise self.error(f"'{self.tok.text}' after a vector literal: C "
                                         "compilers read this differently",
                                         f"put the literal in parentheses: (({ty.name})"
                                         "(...))" + self.tok.text)
                    return VectorLiteral(ty, args, at=t.offset)
                return Cast(ty, self.unary(), at=t.offset)
            finally:
                self.leave()
        return self.postfix()

    def postfix(self) -> Node:
        start = self.tok
        expr = self.primary()
        while True:
            if self.at("("):
                if not isinstance(expr, Name):
                    raise self.error("only a named function can be called",
                                     "call an accessor <port>(y, x, c) or a built-in")
                opener = self.take()
                self.enter()
                try:
                    expr = Call(expr.name, self.arguments(opener), at=start.offset)
                finally:
                    self.leave()
            elif self.at("["):
                self.take()
                self.enter()
                try:
                    index = self.expression()
                finally:
                    self.leave()
                self.expect("]", " after the index")
                expr = Index(expr, index, at=start.offset)
            elif self.at("."):
                self.take()
                f = self.tok
                if f.kind != "id" or not COMPONENTS.fullmatch(f.text):
                    raise self.error(f"'.{f.text}' is not a vector component",
                                     "components: .x .y .z .w, .s0 ... .sf, .lo .hi "
                                     ".even .odd")
                self.take()
                expr = Member(expr, f.text, at=start.offset)
            elif self.at("++", "--"):
                expr = Postfix(self.take().text, expr, at=start.offset)
            elif self.at("->"):
                raise self.error("'->' (pointers) is not part of the snippet language")
            else:
                return expr

    def arguments(self, opener: Token | None = None) -> tuple[Node, ...]:
        """Comma-separated expressions up to and including ')'."""
        args = []
        if not self.at(")"):
            args.append(self.assignment())
            while self.at(","):
                self.take()
                args.append(self.assignment())
        self.expect(")", " after the arguments", opener)
        return tuple(args)

    def primary(self) -> Node:
        t = self.tok
        if t.kind == "num":
            self.take()
            return Number(_number(t), at=t.offset)
        if t.kind == "id" and t.text in ("true", "false"):
            self.take()
            return Number(t.text, at=t.offset)
        if t.kind == "id":
            if t.text in KEYWORDS:
                raise self.error(f"'{t.text}' is not allowed here", _keyword_hint(t.text))
            if t.text in self.port_types:
                raise self.error(f"'{t.text}' is a type (the element type of port "
                                 f"'{self.port_types[t.text]}'), not a value",
                                 f"declare a local of it ({t.text} v = ...;) or cast to it "
                                 f"(({t.text})(...))")
            self.take()
            return Name(t.text, at=t.offset)
        if self.at("("):
            self.enter()
            self.take()
            try:
                inner = self.expression()
            finally:
                self.leave()
            self.expect(")", " to close '('", opener=t)
            return Paren(inner, at=t.offset)
        raise self.error(f"expected a value, found {self.shown(t)}")


def _number(t: Token) -> str:
    text = t.text
    m = _INT.fullmatch(text)
    if m:
        if Number(text).value > MAX_LITERAL:
            raise SnippetError(t.offset, f"the number {text} does not fit in 64 bits",
                               "the largest is 18446744073709551615ul (ULONG_MAX)")
        return text
    if _FLOAT.fullmatch(text):
        return text
    raise SnippetError(t.offset, f"'{text}' is not an OpenCL C number",
                       "numbers: 255, 255u, 0xff, 0.5f, 1e-3f")


def _keyword_hint(word: str) -> str:
    if word in ("switch", "case", "default", "goto"):
        return "write it with if/else"
    return "a snippet computes one element: a few locals, loops and 'return ...;'"
