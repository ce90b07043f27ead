"""Size expressions: how an output's size follows from input sizes and parameters.

A component type writes, for example, ``width: left.width + right.width`` or
``height: height`` (a parameter).  Expressions are parsed with :mod:`ast` and only a
small arithmetic subset is accepted, so a model can never smuggle code through them;
the validated tree is what later gets printed into generated code.
"""

from __future__ import annotations

import ast
from collections.abc import Mapping

ALLOWED_FUNCS = {"min": min, "max": max}
DIMS = ("height", "width")


class SizeExprError(ValueError):
    pass


def parse(text: object, ports: set[str], params: set[str]) -> ast.Expression:
    """Parse and validate one size expression; raise SizeExprError with a message."""
    if isinstance(text, bool) or not isinstance(text, (str, int)):
        raise SizeExprError(f"a size expression must be an integer or a string, not {text!r}")
    source = str(text)
    if len(source) > 200:
        raise SizeExprError("size expression is longer than 200 characters")
    try:
        tree = ast.parse(source, mode="eval")
    except SyntaxError:
        raise SizeExprError(f"cannot parse size expression {source!r}") from None
    port_refs = {id(n.value) for n in ast.walk(tree)
                 if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)}
    for node in ast.walk(tree):
        if id(node) in port_refs and node.id in ports:
            continue
        if isinstance(node, (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Load,
                             ast.Add, ast.Sub, ast.Mult, ast.FloorDiv, ast.Mod, ast.USub,
                             ast.Compare, ast.Eq, ast.NotEq, ast.Lt, ast.LtE, ast.Gt, ast.GtE,
                             ast.BoolOp, ast.And, ast.Or)):
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, int) \
                and not isinstance(node.value, bool):
            continue
        if isinstance(node, ast.Call):
            if not (isinstance(node.func, ast.Name) and node.func.id in ALLOWED_FUNCS) \
                    or node.keywords or not node.args:
                raise SizeExprError(f"only min(...) and max(...) may be called in {source!r}")
            continue
        if isinstance(node, ast.Attribute):
            if not isinstance(node.value, ast.Name) or node.value.id not in ports:
                raise SizeExprError(f"'{ast.unparse(node)}' names no input port in {source!r}")
            if node.attr not in DIMS:
                raise SizeExprError(f"'{ast.unparse(node)}': a port has only .height and .width")
            continue
        if isinstance(node, ast.Name):
            if node.id in ALLOWED_FUNCS or node.id in params:
                continue
            if node.id in ports:
                raise SizeExprError(f"use '{node.id}.height' or '{node.id}.width', "
                                    f"not the port '{node.id}' itself")
            raise SizeExprError(f"unknown name '{node.id}' in {source!r}: "
                                "use an input port's .height/.width or an integer parameter")
        raise SizeExprError(f"'{source}' uses something a size expression cannot "
                            "(only + - * // %, comparisons, min, max)")
    return tree


class _PortSize:
    def __init__(self, height: int, width: int):
        self.height, self.width = height, width


def evaluate(tree: ast.Expression, sizes: Mapping[str, tuple[int, int]],
             params: Mapping[str, object]) -> int:
    """Evaluate a validated expression with concrete sizes (height, width) and params."""
    env: dict[str, object] = dict(ALLOWED_FUNCS)
    env.update({k: v for k, v in params.items()})
    env.update({name: _PortSize(*hw) for name, hw in sizes.items()})
    try:
        value = eval(compile(tree, "<size>", "eval"), {"__builtins__": {}}, env)
    except ZeroDivisionError:
        raise SizeExprError(f"division by zero in '{ast.unparse(tree)}'") from None
    if isinstance(value, bool):
        return value
    if not isinstance(value, int):
        raise SizeExprError(f"'{ast.unparse(tree)}' does not give an integer")
    return value


def to_python(tree: ast.Expression, port_prefix: str = "") -> str:
    """Print a validated expression as Python source (for generated code)."""
    return ast.unparse(tree.body)
