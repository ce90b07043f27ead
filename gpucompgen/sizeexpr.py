"""Size expressions: how an output's size follows from input sizes and parameters.

A component type writes, for example, ``width: left.width + right.width`` or
``height: height`` (a parameter), and requirements such as ``left.height ==
right.height``.  Expressions are parsed with :mod:`ast` and only a small integer
arithmetic subset is accepted, so a model can never smuggle code through them; the
validated tree is what later gets printed into generated code.

Evaluation never runs Python's ``eval``: a small interpreter walks the validated tree and
bounds every intermediate value, so no parameter or product can grow without limit.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping

DIMS = ("height", "width")
# a requirement may also compare an input's channels ('channel < src.channels') and the
# bytes of its element type ('src.itemsize == 1': uint8 among uint8, int16 and float32);
# sizes never follow them
CONDITION_ATTRS = DIMS + ("channels", "itemsize")
FUNCS = ("min", "max")
MAX_SOURCE = 200  # characters of one expression
MAX_VALUE = 1 << 62  # bound on every value while evaluating (an int64 with room to spare)
MAX_SIDE = 1 << 20  # the largest height or width of any port, CPU or GPU: 1,048,576
# the most bytes one frame of a port may have (checked where sizes and element types meet)
MAX_FRAME_BYTES = 1 << 32
ARITH_OPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.FloorDiv: "//", ast.Mod: "%"}
COMPARE_OPS = (ast.Eq, ast.NotEq, ast.Lt, ast.LtE, ast.Gt, ast.GtE)
WHAT = "only integers, + - * // %, min(a, b, ...), max(a, b, ...), parameters and " \
       "<input>.height/.width"


class SizeExprError(ValueError):
    pass


def parse(text: object, ports: set[str], params: set[str],
          condition: bool = False) -> ast.Expression:
    """Parse and validate one size expression (condition: a requirement, i.e. one or more
    comparisons joined by 'and'/'or'); raise SizeExprError with a message."""
    if isinstance(text, bool) or not isinstance(text, (str, int)):
        raise SizeExprError(f"a size expression must be an integer or a string, not {text!r}")
    if isinstance(text, int) and abs(text) > MAX_VALUE:
        raise SizeExprError(f"{text:,} is larger than any size ({MAX_SIDE:,} at most)")
    source = str(text)
    if len(source) > MAX_SOURCE:
        raise SizeExprError(f"size expression is longer than {MAX_SOURCE} characters")
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise SizeExprError(f"cannot parse size expression {source!r}") from None
    checker = _Checker(source, ports, params, condition)
    if condition:
        checker.condition(tree.body)
    else:
        checker.arith(tree.body)
    return tree


class _Checker:
    def __init__(self, source: str, ports: set[str], params: set[str],
                 condition: bool = False):
        self.source, self.ports, self.params = source, ports, params
        self.attrs = CONDITION_ATTRS if condition else DIMS

    def fail(self, message: str) -> SizeExprError:
        return SizeExprError(message)

    def condition(self, node: ast.AST) -> None:
        if isinstance(node, ast.BoolOp) and isinstance(node.op, (ast.And, ast.Or)):
            for value in node.values:
                self.condition(value)
        elif isinstance(node, ast.Compare) and all(isinstance(op, COMPARE_OPS)
                                                   for op in node.ops):
            for operand in (node.left, *node.comparators):
                self.arith(operand)
        else:
            raise self.fail(f"a requirement must compare sizes, e.g. 'a.height == "
                            f"b.height', not {self.source!r}")

    def arith(self, node: ast.AST) -> None:
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, int) or isinstance(node.value, bool):
                raise self.fail(f"{ast.unparse(node)} in {self.source!r} is not an integer")
            if node.value > MAX_VALUE:
                raise self.fail(f"{node.value:,} in {self.source!r} is larger than any size "
                                f"({MAX_SIDE:,} at most)")
        elif isinstance(node, ast.BinOp) and type(node.op) in ARITH_OPS:
            self.arith(node.left)
            self.arith(node.right)
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            self.arith(node.operand)
        elif isinstance(node, ast.Call):
            if not (isinstance(node.func, ast.Name) and node.func.id in FUNCS) \
                    or node.keywords:
                raise self.fail(f"only min(...) and max(...) may be called in {self.source!r}")
            if len(node.args) < 2 or any(isinstance(a, ast.Starred) for a in node.args):
                raise self.fail(f"{node.func.id}() takes two or more sizes, in "
                                f"{self.source!r}")
            for arg in node.args:
                self.arith(arg)
        elif isinstance(node, ast.Attribute):
            if not isinstance(node.value, ast.Name) or node.value.id not in self.ports:
                raise self.fail(f"'{ast.unparse(node)}' names no input port in "
                                f"{self.source!r}")
            if node.attr not in self.attrs:
                raise self.fail(f"'{ast.unparse(node)}': a port has only .height and .width"
                                + (" (and .channels and .itemsize, in a requirement)"
                                   if node.attr in CONDITION_ATTRS[2:] else ""))
        elif isinstance(node, ast.Name):
            if node.id in self.params:
                return
            if node.id in self.ports:
                raise self.fail(f"use '{node.id}.height' or '{node.id}.width', "
                                f"not the port '{node.id}' itself")
            if node.id in FUNCS:
                raise self.fail(f"'{node.id}' must be called: {node.id}(a, b)")
            raise self.fail(f"unknown name '{node.id}' in {self.source!r}: "
                            "use an input port's .height/.width or an integer parameter")
        elif isinstance(node, (ast.Compare, ast.BoolOp)) or (
                isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not)):
            raise self.fail(f"a size must be a number, not a comparison: {self.source!r}")
        else:
            raise self.fail(f"'{self.source}' uses something a size expression cannot "
                            f"({WHAT})")


def evaluate(tree: ast.Expression, sizes: Mapping[str, tuple[int, ...]],
             params: Mapping[str, object]) -> int | bool:
    """Evaluate a validated expression with concrete sizes (height, width) and params;
    a requirement that compares an input's channels or element size needs them: (height,
    width, channels, itemsize).

    A requirement gives True or False; a size gives an integer of at most MAX_SIDE (it
    may be zero or negative: the caller says which port would get it)."""
    shown = ast.unparse(tree.body)
    value = _Evaluator(shown, sizes, params).value(tree.body)
    if isinstance(value, bool):
        return value
    if value > MAX_SIDE:
        raise SizeExprError(f"'{shown}' gives {value:,}, larger than any size "
                            f"({MAX_SIDE:,} at most)")
    return value


class _Evaluator:
    def __init__(self, shown: str, sizes: Mapping[str, tuple[int, ...]],
                 params: Mapping[str, object]):
        self.shown, self.sizes, self.params = shown, sizes, params

    def bounded(self, value: int, what: str) -> int:
        if abs(value) > MAX_VALUE:
            raise SizeExprError(f"{what} in '{self.shown}' is beyond any size (more than "
                                f"{MAX_VALUE:,})")
        return value

    def value(self, node: ast.AST) -> int | bool:
        if isinstance(node, ast.BoolOp):
            results = (self.value(v) for v in node.values)
            return all(results) if isinstance(node.op, ast.And) else any(results)
        if isinstance(node, ast.Compare):
            left = self.number(node.left)
            for op, right_node in zip(node.ops, node.comparators):
                right = self.number(right_node)
                if not _compare(op, left, right):
                    return False
                left = right
            return True
        return self.number(node)

    def number(self, node: ast.AST) -> int:
        if isinstance(node, ast.Constant):
            return self.bounded(node.value, f"{node.value:,}")
        if isinstance(node, ast.Name):
            value = self.params.get(node.id)
            if isinstance(value, bool) or not isinstance(value, int):
                raise SizeExprError(f"parameter '{node.id}' in '{self.shown}' has no integer "
                                    f"value (it is {value!r})")
            return self.bounded(value, f"parameter '{node.id}' ({value:,})")
        if isinstance(node, ast.Attribute):
            known = self.sizes[node.value.id]
            index = CONDITION_ATTRS.index(node.attr)
            if index >= len(known):
                raise SizeExprError(f"'{ast.unparse(node)}' in '{self.shown}' is not known "
                                    "here")
            return self.bounded(known[index], ast.unparse(node))
        if isinstance(node, ast.UnaryOp):
            operand = self.number(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.Call):
            args = [self.number(a) for a in node.args]
            return min(args) if node.func.id == "min" else max(args)
        if isinstance(node, ast.BinOp):
            left, right = self.number(node.left), self.number(node.right)
            op = type(node.op)
            if op in (ast.FloorDiv, ast.Mod) and right == 0:
                raise SizeExprError(f"division by zero in '{self.shown}'")
            result = {ast.Add: lambda: left + right, ast.Sub: lambda: left - right,
                      ast.Mult: lambda: left * right, ast.FloorDiv: lambda: left // right,
                      ast.Mod: lambda: left % right}[op]()
            return self.bounded(result, f"'{ast.unparse(node)}'")
        raise SizeExprError(f"cannot evaluate '{self.shown}'")  # pragma: no cover - parse refused it


def _compare(op: ast.cmpop, left: int, right: int) -> bool:
    return {ast.Eq: left == right, ast.NotEq: left != right, ast.Lt: left < right,
            ast.LtE: left <= right, ast.Gt: left > right, ast.GtE: left >= right}[type(op)]


def frame_problem(height: int, width: int, channels: int, itemsize: int) -> str:
    """Why a frame of this shape cannot be (for any port, CPU or GPU), or ''."""
    if not (0 < height <= MAX_SIDE and 0 < width <= MAX_SIDE):
        return f"a frame of {height:,}x{width:,} pixels is outside 1..{MAX_SIDE:,} per side"
    nbytes = height * width * channels * itemsize
    if nbytes > MAX_FRAME_BYTES:
        return (f"a frame of {height:,}x{width:,}x{channels} needs {nbytes:,} bytes, more "
                f"than any frame may have ({MAX_FRAME_BYTES:,} bytes)")
    return ""


def to_python(tree: ast.Expression, port_prefix: str = "") -> str:
    """Print a validated expression as Python source (for generated code)."""
    return ast.unparse(tree.body)
