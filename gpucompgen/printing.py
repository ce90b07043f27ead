"""Printing a ProgramPlan as Python: what every backend's printer shares.

A backend's printer (backend/<name>/render.py) gives ``render`` its template (templates/
<name>/program.py.j2, which extends templates/common/program.py.j2), the suffix of its
kernel files and the text of each lib file; everything else is here: the one Jinja
environment, filters that make model text safe (escaped literals and comments) and one
layout helper that fits a statement into the line length by breaking only between its
tokens, never inside a literal.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from pathlib import Path, PurePosixPath

import jinja2

from . import output
from .output import HEADER, OutputFile
from .plan import (
    Argument,
    LibSource,
    ModelPath,
    ParamRef,
    ProgramPlan,
    Settable,
    plan_lines,
)

WIDTH = 100  # the project's line length; generated code fits it


def template_root() -> Path:
    """templates/: common/ and one folder per backend (output.template_folder)."""
    return output.template_folder("common").parent


def environment() -> jinja2.Environment:
    """The one Jinja environment of every backend's program template."""
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_root())),
        undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
        keep_trailing_newline=True, autoescape=False)
    env.filters["py"] = py_literal
    env.filters["comment"] = comment_text
    env.filters["number"] = lambda n: f"{n:_}"
    env.filters["kwargs"] = keyword_arguments
    env.filters["py_text"] = py_text
    env.filters["pairs"] = lambda ports: [f"({p!r}, np.{dtype})" for p, dtype in ports]
    env.globals["fit"] = fit
    env.globals["comment_lines"] = comment_lines
    env.globals["argument_groups"] = argument_groups
    env.globals["settable_arguments"] = settable_arguments
    return env


def fit(head: str, items: list, indent: int, comment: str = "", tail: str = "",
        opening: str = "(", closing: str = ")", sep: str = ", ") -> str:
    """`head(item, item, ...)tail  # comment` within WIDTH columns.

    Items are whole tokens (literals, names, keyword arguments): a statement that does not
    fit breaks after the opening bracket and between items, never inside one; a comment
    that does not fit goes on its own line above.
    """
    items = [str(i) for i in items]
    code = f"{head}{opening}{sep.join(items)}{closing}{tail}"
    note = f"  # {comment_text(comment)}" if comment else ""
    if indent + len(code) + len(note) <= WIDTH:
        return code + note
    above = "".join(line + "\n" + " " * indent
                    for line in comment_lines(comment, indent)) if comment else ""
    if indent + len(code) <= WIDTH or not items:
        return above + code
    bare = not head and not opening  # a continuation line of items: pack at indent
    inner = indent if bare else indent + 4
    lines, current = [], ""
    for i, item in enumerate(items):
        piece = item + (sep.rstrip() if i < len(items) - 1 else closing + tail)
        if current and inner + len(current) + 1 + len(piece) > WIDTH:
            lines.append(current)
            current = piece
        else:
            current = f"{current} {piece}" if current else piece
    lines.append(current)
    if bare:
        return above + f"\n{' ' * indent}".join(lines)
    return above + f"{head}{opening}\n" + "\n".join(" " * inner + line for line in lines)


def keyword_arguments(pairs) -> list[str]:
    """`name=literal` for each (name, value): large integers with '_' separators."""
    return [f"{k}={v:_}" if isinstance(v, int) and not isinstance(v, bool) and v > 9999
            else f"{k}={py_literal(v)}" for k, v in pairs]


def comment_text(text: str) -> str:
    """Free text made safe for one comment line: no line breaks or control characters."""
    return str(text).encode("unicode_escape").decode("ascii")


def comment_lines(text: str, indent: int) -> list[str]:
    """Free text as comment lines that fit WIDTH (broken between words only)."""
    width = max(WIDTH - indent - 2, 20)
    return ["# " + line for line in textwrap.wrap(comment_text(text), width,
                                                   break_long_words=False,
                                                   break_on_hyphens=False)] or ["#"]


def py_literal(value) -> str:
    """A Python literal for a model value (escaped: no model text becomes code)."""
    if isinstance(value, ParamRef):
        return f"params[{str(value)!r}]"
    if isinstance(value, ModelPath):
        return f"runtime.model_path(__file__, {str(value)!r})"
    if isinstance(value, (bool, int, float, str)) or value is None:
        return repr(value)
    if isinstance(value, tuple) and all(type(v) is int for v in value):
        return repr(value)  # a shape, or an int array parameter
    if isinstance(value, tuple):  # an array parameter: nested tuples of numbers
        return "(" + ", ".join(py_literal(v) for v in value) + ("," if len(value) == 1 else "") + ")"
    raise TypeError(f"no literal for {type(value).__name__}")


def py_text(text: str, indent: int) -> str:
    """A string literal that fits WIDTH: a long one becomes adjacent literals in
    parentheses, split between words, each piece a complete literal of its own."""
    one = py_literal(text)
    if indent + len(one) <= WIDTH:
        return one
    words = str(text).split(" ")
    pieces, current = [], ""
    for i, word in enumerate(words):
        piece = word + (" " if i < len(words) - 1 else "")
        if current and 4 + len(py_literal(current + piece)) > WIDTH:
            pieces.append(current)
            current = piece
        else:
            current += piece
    pieces.append(current)
    return "(\n" + "\n".join("    " + py_literal(p) for p in pieces) + "\n)"


def argument_groups(arguments: tuple[Argument, ...]) -> list[tuple[list[Argument], str]]:
    """Kernel arguments in convention order, grouped for one commented line each: the
    buffers, each port's height and width, each parameter, the tile."""
    groups: list[tuple[list[Argument], str]] = []
    for a in arguments:
        if a.kind == "buffer":
            key = "buffers: inputs, then outputs"
        elif a.port:
            key = f"{a.port}: height, width"
        else:
            key = a.name
        if groups and groups[-1][1] == key:
            groups[-1][0].append(a)
        else:
            groups.append(([a], key))
    return groups


def settable_arguments(s: Settable) -> list[str]:
    """runtime.Param's arguments: type, value, and the bounds the declaration has."""
    return [repr(s.type), py_literal(s.value)] + [
        f"{k}={v!r}" for k, v in (("minimum", s.minimum), ("maximum", s.maximum))
        if v is not None]


def lib_file_text(src: LibSource, header: str) -> str:
    """A lib folder's copy of a checked source, under the generated header saying what it
    is."""
    users = ", ".join(src.users)
    if src.kind == "kernel":
        return (f"// {header}\n// Kernel of component type{'s' if len(src.users) > 1 else ''} "
                f"{users}.\n\n{src.text}")
    if src.kind == "checked_kernel":
        return (f"// {header}\n// Kernel of component type {users}, not launched (its "
                "components are fused or on the CPU):\n// built at start-up to check it.\n\n"
                + src.text)
    if src.kind == "cpu":
        return (f"# {header}\n# CPU implementation of {users}, copied from its type file."
                f"\n\n{src.text}")
    return f"# {header}\n# Copied from the component type file of {users}.\n\n{src.text}"


def render(plan: ProgramPlan, system_name: str, source: str, model_dir: str, template: str,
           lib_text: Callable[[LibSource, str], str]) -> list[OutputFile]:
    """All files of one system, in a stable order: the program (the backend's template),
    then its lib folder (each kernel and user Python file once, whatever number of types
    use it; lib_text(source, header): a file's text as the backend writes it).  model_dir:
    the model's folder relative to the output folder ('path' parameters start there)."""
    plan = plan.for_program(model_dir)
    lib = plan.lib_dir
    header = HEADER.format(source=comment_text(source))
    files = [OutputFile(PurePosixPath(lib, src.file), lib_text(src, header))
             for src in plan.lib_sources]
    inputs = sorted((comment_text(path), digest) for path, digest in plan.model_inputs)
    program = environment().get_template(template).render(
        header=header, sha256=plan.model_sha256, inputs=inputs,
        description=plan.description, lib=lib,
        plan=plan, plan_lines=plan_lines(plan), settable=plan.settable,
        sources=list(plan.sources))
    files.insert(0, OutputFile(PurePosixPath(f"{system_name}.py"), program))
    return files
