"""Where a snippet reads its inputs, for given parameter values and sizes.

A stencil states its radius; the kernel generator reads the interior of the frame without
border rules on that promise, so a read beyond it would load memory outside the input
(passes/check_reads.py refuses it).  An index map computes its positions: a user's read
that cannot be shown inside its input gets the border rule (kernelgen/fused.py).
``reach(tree, values, ports, frame, sizes)`` walks the snippet with the parameters and
sizes as numbers, the element's values unknown and y and x as themselves: loops run (their
bounds are numbers), a choice on a number takes its branch, a choice on an element's value
takes both, and a choice on y or x against a number narrows its range in each branch
(``x < left_width ? left(y, x, c) : right(y, x - left_width, c)``).  A read whose row is
plus or minus y plus a number, and whose column the same of x, is bounded; one whose
position depends on anything else (an element's value, a loop the walk cannot finish) is
not.  A table's or an array parameter's entry at a known index is its number (a loop over
MedianBlur's exchange network runs its course).  Nothing is compiled or run: this reads
the tree.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from . import syntax as S
from .check import fold
from .query import unparen

MAX_STEPS = 200_000  # statements and expressions walked before giving up (unbounded)
_FLIP = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}  # a op b: b op' a
_NOT = {"<": ">=", "<=": ">", ">": "<=", ">=": "<", "==": "!=", "!=": "=="}


@dataclass(frozen=True)
class Coord:
    """sign * y (or x) plus a number: a position the snippet reads at."""
    axis: str
    offset: int
    sign: int = 1


class _Unknown:
    def __repr__(self) -> str:
        return "?"


UNKNOWN = _Unknown()  # an element's value, or anything the walk does not follow


@dataclass
class Reach:
    """Per input port, the farthest read along y and x (reads at y + k and x + k: a
    window), a read beyond any bound (None when every read is one of a window), and,
    given the frame's and the inputs' sizes, per port a read not shown inside it."""
    rows: dict[str, int]
    cols: dict[str, int]
    unbounded: S.Node | None = None
    farthest: dict[str, S.Node] = field(default_factory=dict)  # per port, its farthest
    outside: dict[str, S.Node] = field(default_factory=dict)


class _GiveUp(Exception):
    def __init__(self, node: S.Node) -> None:
        self.node = node


class _Return(Exception):
    pass


class _Jump(Exception):
    def __init__(self, word: str) -> None:
        self.word = word


def reach(tree: S.Node, values: Mapping[str, object], ports: list[str],
          frame: tuple[int, int] | None = None,
          sizes: Mapping[str, tuple[int, int]] | None = None) -> Reach:
    """The reads of the snippet at these parameter and size values (values: name ->
    int or float; a name missing there is unknown); with the output's (height, width)
    and each input's, which reads are not shown inside their input."""
    walk = _Walk(values, ports, frame, sizes or {})
    try:
        walk.block(tree.body if isinstance(tree, S.Snippet) else [tree], {})
    except _Return:
        pass
    except (_GiveUp, _Jump) as e:  # what it did not walk may read anywhere
        node = getattr(e, "node", tree)
        walk.result.unbounded = node
        for port in ports:
            walk.result.outside.setdefault(port, node)
    return walk.result


class _Walk:
    def __init__(self, values, ports, frame, sizes) -> None:
        self.values, self.ports, self.sizes = values, set(ports), sizes
        self.steps = 0
        self.result = Reach(dict.fromkeys(ports, 0), dict.fromkeys(ports, 0))
        self.far: dict[str, int] = {}  # per port, the farthest read's distance
        # the values y and x take where the walk is (narrowed by the choices it is in)
        self.ranges = {"y": (0, frame[0] - 1), "x": (0, frame[1] - 1)} if frame else None

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
                self.both(s, [(s.then, True), (s.other, False)], s.cond, env)
        elif isinstance(s, S.For):
            self.loop(s, s.init, s.cond, s.step, s.body, env)
        elif isinstance(s, S.While):
            self.loop(s, None, s.cond, None, s.body, env)
        elif isinstance(s, S.DoWhile):
            self.loop(s, None, None, None, s.body, env, s.cond)
        elif isinstance(s, S.Jump):
            raise _Jump(s.word)

    def both(self, s, branches, cond, env: dict) -> None:
        """Branches chosen by a value the walk does not know: each walked from the same
        locals, where the condition holds and where it does not; after them a local they
        leave different is unknown.  A branch that returns ends there; a break or
        continue in one leaves the loop's course unknown (given up)."""
        ends = []
        for b, truth in branches:
            copy = dict(env)
            saved = self.ranges
            try:
                self.ranges = self.narrowed(cond, env, truth)
                if b is not None:
                    self.statement(b, copy)
                ends.append(copy)
            except _Return:
                pass
            except _Jump:
                raise _GiveUp(s) from None
            finally:
                self.ranges = saved
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
            a, b = (self.where(e.cond, env, truth, side)
                    for truth, side in ((True, e.then), (False, e.other)))
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
            # an element of a table or an array parameter, at a known index: its number
            # (a loop bounded by a table's entry runs its course)
            base = unparen(e.base)
            table = self.values.get(base.name) if isinstance(base, S.Name) and \
                base.name not in env else None
            index = self.expr(e.index, env)
            if isinstance(table, tuple) and isinstance(index, int) and \
                    0 <= index < len(table) and _number(table[index]):
                return table[index]
            self.expr(e.base, env)
            return UNKNOWN
        if isinstance(e, (S.VectorLiteral, S.InitList)):
            for a in (e.args if isinstance(e, S.VectorLiteral) else e.items):
                self.expr(a, env)
            return UNKNOWN
        return UNKNOWN

    def where(self, cond, env: dict, truth: bool, e):
        """e's value, walked where cond is truth."""
        saved = self.ranges
        try:
            self.ranges = self.narrowed(cond, env, truth)
            return self.expr(e, env)
        finally:
            self.ranges = saved

    def narrowed(self, cond, env: dict, truth: bool):
        """The ranges of y and x where cond is truth: comparisons of y or x (plus or
        minus numbers) with numbers, and their '&&' (true) or '||' (false)."""
        ranges = self.ranges
        if ranges is None:
            return None
        c = unparen(cond)
        if isinstance(c, S.Unary) and c.op == "!":
            return self.narrowed(c.operand, env, not truth)
        if isinstance(c, S.Binary) and c.op in ("&&", "||") and truth == (c.op == "&&"):
            self.ranges = self.narrowed(c.left, env, truth)
            try:
                return self.narrowed(c.right, env, truth)
            finally:
                self.ranges = ranges
        if not (isinstance(c, S.Binary) and c.op in _FLIP):
            return ranges
        scratch = dict(env)  # walked again: an assignment in it must not count twice
        left, right, op = self.expr(c.left, scratch), self.expr(c.right, scratch), c.op
        if isinstance(right, Coord) and isinstance(left, int):
            left, right, op = right, left, _FLIP[op]
        if not (isinstance(left, Coord) and isinstance(right, int)):
            return ranges
        if not truth:
            op = _NOT[op]
        bound = right - left.offset  # sign * axis op bound
        if left.sign < 0:
            bound, op = -bound, _FLIP[op]
        lo, hi = ranges[left.axis]
        lo, hi = {"<": (lo, min(hi, bound - 1)), "<=": (lo, min(hi, bound)),
                  ">": (max(lo, bound + 1), hi), ">=": (max(lo, bound), hi),
                  "==": (max(lo, bound), min(hi, bound)), "!=": (lo, hi)}[op]
        return {**ranges, left.axis: (lo, hi)}

    def name(self, n: str, env: dict):
        if n in env:
            return env[n]
        if n in ("y", "x"):
            return Coord(n, 0)
        v = self.values.get(n, UNKNOWN)
        return v if isinstance(v, (int, float)) and not isinstance(v, bool) else \
            int(v) if isinstance(v, bool) else UNKNOWN

    def assign(self, target, value, env: dict) -> None:
        target = unparen(target)
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
        if e.op == "-" and isinstance(v, Coord):
            return Coord(v.axis, -v.offset, -v.sign)
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
        r = self.result
        if e.func not in r.outside and not self.inside(e.func, row, col):
            r.outside[e.func] = e
        if not (isinstance(row, Coord) and row.axis == "y" and row.sign == 1
                and isinstance(col, Coord) and col.axis == "x" and col.sign == 1):
            if r.unbounded is None:
                r.unbounded = e
            return
        far = max(abs(row.offset), abs(col.offset))
        if far > self.far.get(e.func, -1):
            r.farthest[e.func], self.far[e.func] = e, far
        r.rows[e.func] = max(r.rows[e.func], abs(row.offset))
        r.cols[e.func] = max(r.cols[e.func], abs(col.offset))

    def inside(self, port: str, row, col) -> bool:
        """Whether the read (row, col) lies inside the port's frame wherever the walk is
        (a branch no y or x reaches: vacuously)."""
        if self.ranges is None or port not in self.sizes:
            return False
        for at, axis, n in ((row, "y", self.sizes[port][0]), (col, "x", self.sizes[port][1])):
            if not (isinstance(at, Coord) and at.axis == axis):
                return False
            lo, hi = self.ranges[axis]
            if lo > hi:
                return True
            ends = (at.sign * lo + at.offset, at.sign * hi + at.offset)
            if min(ends) < 0 or max(ends) > n - 1:
                return False
        return True


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _arith(op: str, a, b):
    """a op b as C computes it on numbers; y or x plus or minus a whole number stays a
    position; anything else of a position, or of an unknown, is unknown."""
    if isinstance(a, Coord) or isinstance(b, Coord):
        if op == "+" and isinstance(a, Coord) and isinstance(b, int):
            return Coord(a.axis, a.offset + b, a.sign)
        if op == "+" and isinstance(b, Coord) and isinstance(a, int):
            return Coord(b.axis, b.offset + a, b.sign)
        if op == "-" and isinstance(a, Coord) and isinstance(b, int):
            return Coord(a.axis, a.offset - b, a.sign)
        if op == "-" and isinstance(b, Coord) and isinstance(a, int):
            return Coord(b.axis, a - b.offset, -b.sign)
        return UNKNOWN
    if not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
        return UNKNOWN
    result = fold(op, a, b)
    if result is None:
        return UNKNOWN
    # C's integers are 64 bits at most: a value beyond (a square taken in a loop) is
    # unknown, not a number Python would grow without bound
    if isinstance(result, int) and not -(1 << 63) <= result < (1 << 64):
        return UNKNOWN
    return result
