"""How far from (y, x) a snippet reads its inputs, for given parameter values.

A stencil states its radius; the kernel generator reads the interior of the frame without
border rules on that promise, so a read beyond it would load memory outside the input.
``reach(tree, values, ports)`` walks the snippet with the parameters and sizes as
numbers, the element's values unknown and y and x as themselves: loops run (their bounds
are numbers), a choice on a number takes its branch, a choice on an element's value takes
both.  A read whose row is y plus a number and whose column is x plus a number is
bounded; one whose position depends on anything else (an element's value, a table, a
loop the walk cannot finish) is not, and the generator keeps the border rule for it.
Nothing is compiled or run: this reads the tree.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from . import syntax as S

MAX_STEPS = 200_000  # statements and expressions walked before giving up (unbounded)


@dataclass(frozen=True)
class Coord:
    """y or x plus a number: a position the snippet reads at."""
    axis: str
    offset: int


class _Unknown:
    def __repr__(self) -> str:
        return "?"


UNKNOWN = _Unknown()  # an element's value, or anything the walk does not follow


@dataclass
class Reach:
    """Per input port, the farthest read along y and x, and a read beyond any bound
    (None when every read is y + k, x + k)."""
    rows: dict[str, int]
    cols: dict[str, int]
    unbounded: S.Node | None = None
    farthest: dict[str, S.Node] | None = None  # per port, its farthest read


class _GiveUp(Exception):
    def __init__(self, node: S.Node) -> None:
        self.node = node


class _Return(Exception):
    pass


class _Jump(Exception):
    def __init__(self, word: str) -> None:
        self.word = word


def reach(tree: S.Node, values: Mapping[str, object], ports: list[str]) -> Reach:
    """The reads of the snippet at these parameter and size values (values: name ->
    int or float; a name missing there is unknown)."""
    walk = _Walk(values, ports)
    try:
        walk.block(tree.body if isinstance(tree, S.Snippet) else [tree], {})
    except _Return:
        pass
    except (_GiveUp, _Jump) as e:
        walk.result.unbounded = getattr(e, "node", tree)
    return walk.result


class _Walk:
    def __init__(self, values, ports) -> None:
        self.values, self.ports = values, set(ports)
        self.steps = 0
        self.result = Reach(dict.fromkeys(ports, 0), dict.fromkeys(ports, 0), None, {})
        self.far: dict[str, int] = {}  # per port, the farthest read's distance

    def tick(self, node) -> None:
        self.steps += 1
        if self.steps > MAX_STEPS:
            raise _GiveUp(node)

    # statements: env maps the locals to their values; raises _Return at a return
    def block(self, body, env: dict) -> None:
        for s in body:
            self.statement(s, env)

    def statement(self, s, env: dict) -> None:
        self.tick(s)
        if isinstance(s, S.Block):
            self.block(s.body, env)
        elif isinstance(s, S.Decl):
            for d in s.declarators:
                env[d.name] = UNKNOWN if d.size is not None or d.init is None \
                    else self.expr(d.init, env)
                if isinstance(d.init, S.InitList):
                    for item in d.init.items:
                        self.expr(item, env)
        elif isinstance(s, S.ExprStmt):
            if s.expr is not None:
                self.expr(s.expr, env)
        elif isinstance(s, S.Return):
            self.expr(s.value, env)
            raise _Return
        elif isinstance(s, S.If):
            cond = self.expr(s.cond, env)
            if isinstance(cond, (int, float)):
                chosen = s.then if cond else s.other
                if chosen is not None:
                    self.statement(chosen, env)
            else:
                self.both(s, [s.then, s.other], env)
        elif isinstance(s, S.For):
            self.loop(s, s.init, s.cond, s.step, s.body, env)
        elif isinstance(s, S.While):
            self.loop(s, None, s.cond, None, s.body, env)
        elif isinstance(s, S.DoWhile):
            self.loop(s, None, None, None, s.body, env, s.cond)
        elif isinstance(s, S.Jump):
            raise _Jump(s.word)

    def both(self, s, branches, env: dict) -> None:
        """Branches chosen by an element's value: each walked from the same locals; after
        them a local they leave different is unknown.  A branch that returns ends there;
        a break or continue in one leaves the loop's course unknown (given up)."""
        ends = []
        for b in branches:
            copy = dict(env)
            try:
                if b is not None:
                    self.statement(b, copy)
                ends.append(copy)
            except _Return:
                pass
            except _Jump:
                raise _GiveUp(s) from None
        if not ends:  # every branch returned
            raise _Return
        for name in env:
            first = ends[0][name]
            env[name] = first if all(e[name] == first for e in ends) else UNKNOWN

    def loop(self, s, init, cond, step, body, env: dict, after=None) -> None:
        if init is not None:
            self.statement(init, env)
        while True:
            if cond is not None:
                c = self.expr(cond, env)
                if not isinstance(c, (int, float)):
                    raise _GiveUp(s)
                if not c:
                    return
            try:
                self.statement(body, env)
            except _Jump as j:
                if j.word == "break":
                    return
            if after is not None:
                c = self.expr(after, env)
                if not isinstance(c, (int, float)):
                    raise _GiveUp(s)
                if not c:
                    return
            if step is not None:
                self.expr(step, env)

    # expressions: a number, a Coord, or UNKNOWN
    def expr(self, e, env: dict):
        self.tick(e)
        if isinstance(e, S.Number):
            return e.value
        if isinstance(e, S.Name):
            return self.name(e.name, env)
        if isinstance(e, S.Paren):
            return self.expr(e.inner, env)
        if isinstance(e, S.Member):
            self.expr(e.base, env)
            return UNKNOWN
        if isinstance(e, S.Conditional):
            c = self.expr(e.cond, env)
            if isinstance(c, (int, float)):
                return self.expr(e.then if c else e.other, env)
            a, b = self.expr(e.then, env), self.expr(e.other, env)
            return a if a == b and a is not UNKNOWN else UNKNOWN
        if isinstance(e, S.Call):
            return self.call(e, env)
        if isinstance(e, S.Cast):
            v = self.expr(e.operand, env)
            if isinstance(v, float) and e.type.name in ("int", "uint", "short", "ushort",
                                                          "char", "uchar", "long", "ulong"):
                return int(v)
            return v
        if isinstance(e, S.Unary):
            return self.unary(e, env)
        if isinstance(e, S.Postfix):
            old = self.expr(e.operand, env)
            self.assign(e.operand, _arith("+" if e.op == "++" else "-", old, 1), env)
            return old
        if isinstance(e, S.Binary):
            return self.binary(e, env)
        if isinstance(e, S.Assign):
            v = self.expr(e.value, env)
            if e.op != "=":
                v = _arith(e.op[:-1], self.expr(e.target, env), v)
            self.assign(e.target, v, env)
            return v
        if isinstance(e, S.Index):
            self.expr(e.base, env)
            self.expr(e.index, env)
            return UNKNOWN
        if isinstance(e, (S.VectorLiteral, S.InitList)):
            for a in (e.args if isinstance(e, S.VectorLiteral) else e.items):
                self.expr(a, env)
            return UNKNOWN
        return UNKNOWN

    def name(self, n: str, env: dict):
        if n in env:
            return env[n]
        if n in ("y", "x"):
            return Coord(n, 0)
        v = self.values.get(n, UNKNOWN)
        return v if isinstance(v, (int, float)) and not isinstance(v, bool) else \
            int(v) if isinstance(v, bool) else UNKNOWN

    def assign(self, target, value, env: dict) -> None:
        target = target.inner if isinstance(target, S.Paren) else target
        if isinstance(target, S.Name):
            env[target.name] = value
        elif isinstance(target, S.Index):
            self.expr(target.index, env)

    def unary(self, e: S.Unary, env: dict):
        if e.op in ("++", "--"):
            v = _arith("+" if e.op == "++" else "-", self.expr(e.operand, env), 1)
            self.assign(e.operand, v, env)
            return v
        v = self.expr(e.operand, env)
        if e.op == "+":
            return v
        if not isinstance(v, (int, float)):
            return UNKNOWN
        return {"-": lambda: -v, "!": lambda: int(not v),
                "~": lambda: ~v if isinstance(v, int) else UNKNOWN}[e.op]()

    def binary(self, e: S.Binary, env: dict):
        left = self.expr(e.left, env)
        if e.op in ("&&", "||") and isinstance(left, (int, float)):
            if (e.op == "&&") != bool(left):  # decided by the left operand
                return int(bool(left))
            right = self.expr(e.right, env)
            return int(bool(right)) if isinstance(right, (int, float)) else UNKNOWN
        return _arith(e.op, left, self.expr(e.right, env))

    def call(self, e: S.Call, env: dict):
        args = [self.expr(a, env) for a in e.args]
        if e.func in self.ports:
            self.read(e, args)
            return UNKNOWN
        if all(isinstance(a, (int, float)) for a in args):
            if e.func in ("min", "fmin") and len(args) == 2:
                return min(args)
            if e.func in ("max", "fmax") and len(args) == 2:
                return max(args)
            if e.func == "clamp" and len(args) == 3:
                return min(max(args[0], args[1]), args[2])
            if e.func in ("abs", "fabs") and len(args) == 1:
                return abs(args[0])
        return UNKNOWN

    def read(self, e: S.Call, args) -> None:
        row, col = args[0], args[1]
        if not (isinstance(row, Coord) and row.axis == "y"
                and isinstance(col, Coord) and col.axis == "x"):
            raise _GiveUp(e)
        r = self.result
        far = max(abs(row.offset), abs(col.offset))
        if far > self.far.get(e.func, -1):
            r.farthest[e.func], self.far[e.func] = e, far
        r.rows[e.func] = max(r.rows[e.func], abs(row.offset))
        r.cols[e.func] = max(r.cols[e.func], abs(col.offset))


def _arith(op: str, a, b):
    """a op b as C computes it on numbers; y or x plus or minus a whole number stays a
    position; anything else of a position, or of an unknown, is unknown."""
    if isinstance(a, Coord) or isinstance(b, Coord):
        if op == "+" and isinstance(a, Coord) and isinstance(b, int):
            return Coord(a.axis, a.offset + b)
        if op == "+" and isinstance(b, Coord) and isinstance(a, int):
            return Coord(b.axis, b.offset + a)
        if op == "-" and isinstance(a, Coord) and isinstance(b, int):
            return Coord(a.axis, a.offset - b)
        return UNKNOWN
    if not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
        return UNKNOWN
    both_int = isinstance(a, int) and isinstance(b, int)
    try:
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        if op == "/":
            if both_int:
                q = abs(a) // abs(b)
                return q if (a >= 0) == (b >= 0) else -q
            return a / b
        if op == "%" and both_int:
            return a - b * _arith("/", a, b)
        if op in ("<<", ">>", "&", "|", "^") and both_int:
            return {"<<": lambda: a << b, ">>": lambda: a >> b, "&": lambda: a & b,
                    "|": lambda: a | b, "^": lambda: a ^ b}[op]()
        if op in ("<", ">", "<=", ">=", "==", "!="):
            return int({"<": a < b, ">": a > b, "<=": a <= b, ">=": a >= b, "==": a == b,
                        "!=": a != b}[op])
        if op in ("&&", "||"):
            return int(bool(a) and bool(b)) if op == "&&" else int(bool(a) or bool(b))
    except (ZeroDivisionError, ValueError, OverflowError):
        return UNKNOWN
    return UNKNOWN
