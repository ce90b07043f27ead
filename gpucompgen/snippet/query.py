"""Questions the fusion pass and the kernel generator ask of a parsed snippet: which
accessor calls it makes and with what arguments, and whether it uses a name elsewhere.
They read the tree, so comments, strings of tokens and layout cannot mislead them."""

from __future__ import annotations

from collections.abc import Iterator

from .syntax import Binary, Call, Name, Node, Paren


def _children(node) -> Iterator:
    if isinstance(node, Node):
        yield from vars(node).values()
    elif isinstance(node, tuple):
        yield from node


def accessor_calls(tree: Node, ports: list[str]) -> dict[str, list[tuple[Node, ...]]]:
    """Every call port(a, b, c) of the given accessors, its argument trees, per port, in
    the order they appear."""
    found: dict[str, list[tuple[Node, ...]]] = {p: [] for p in ports}

    def walk(node) -> None:
        if isinstance(node, Call) and node.func in found:
            found[node.func].append(node.args)
        for child in _children(node):
            walk(child)

    walk(tree)
    return found


def uses_outside_calls(tree: Node, funcs: list[str], names: set[str]) -> bool:
    """Whether the snippet uses any of names other than inside a call of funcs."""
    def walk(node) -> bool:
        if isinstance(node, Call) and node.func in funcs:
            return False
        if isinstance(node, Name) and node.name in names:
            return True
        return any(walk(child) for child in _children(node))

    return walk(tree)


def unparen(node: Node) -> Node:
    while isinstance(node, Paren):
        node = node.inner
    return node


def is_name(node: Node, name: str) -> bool:
    node = unparen(node)
    return isinstance(node, Name) and node.name == name


def is_shifted(node: Node, name: str) -> bool:
    """name, or name plus or minus an expression that does not use name."""
    node = unparen(node)
    if is_name(node, name):
        return True
    return (isinstance(node, Binary) and node.op in "+-" and is_name(node.left, name)
            and not uses_outside_calls(node.right, [], {name}))
