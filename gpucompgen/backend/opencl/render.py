"""The OpenCL backend's printer: a ProgramPlan into files (the program and its lib folder).

The templates (the top-level templates/opencl/) print the plan's records with macros;
this module loads them, gives them filters that make model text safe (escaped literals and
comments) and one layout helper that fits a statement into the line length by breaking
only between its tokens, never inside a literal.
"""

from __future__ import annotations

import dataclasses
import os
import posixpath
import re
import textwrap
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import jinja2

from ... import output
from ...ir import ComponentNode, System
from ...output import HEADER, OutputFile
from ...plan import Argument, LibSource, ProgramPlan
from .fused import group_kernel

# the OpenCL program's import of its binding (the CUDA backend drops it: backend/cuda)
API_IMPORT = "import pyopencl as cl\n"
WIDTH = 100  # the project's line length; generated code fits it


def template_folder() -> Path:
    return output.template_folder("opencl")


def environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_folder())),
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


class ModelPath(str):
    """A path parameter relative to the model's folder, as seen from the program's folder:
    printed as a call that resolves it when the program runs, wherever it is started."""


class ParamRef(str):
    """A parameter --set may change: printed as its entry of run()'s `params`."""


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


URI = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")  # e.g. a camera's device:0, not a path


FILE_URI = re.compile(r"(file|mcap|rosbag)://(?!/)")  # a file URI with a relative path


def relative_to_program(value: str, model_dir: str):
    """A path (or a file URI's path) relative to the model, as seen from the program."""
    m = FILE_URI.match(value)
    if m:
        path, q, query = value[m.end():].partition("?")
        return ModelPath(f"{m.group(0)}{posixpath.normpath(posixpath.join(model_dir, path))}"
                         f"{q}{query}")
    if posixpath.isabs(value) or URI.match(value):
        return value
    return ModelPath(posixpath.normpath(posixpath.join(model_dir, value)))


def with_model_paths(system: System, plan: ProgramPlan, model_dir: str) -> ProgramPlan:
    """The plan with every relative 'path' parameter made relative to the program's folder
    (model_dir: the model's folder as seen from there), so that it names the same file
    whatever the working directory of the program."""
    parts = []
    for part in plan.parts:
        node = system.nodes.get(part.name)
        decls = getattr(getattr(node, "type", None), "params", {})
        params = tuple((k, relative_to_program(v, model_dir))
                       if decls.get(k) is not None and decls[k].type in ("path", "input")
                       and isinstance(v, str) and v else (k, v)
                       for k, v in part.params)
        parts.append(dataclasses.replace(part, params=params))
    return dataclasses.replace(plan, parts=parts)


@dataclass(frozen=True)
class Settable:
    """A parameter the program's --set may change when it starts: one that no size or
    requirement depends on (a generated kernel takes it as a build option)."""

    key: str  # 'component.param'
    type: str  # the declaration's type
    value: object  # the model's value (a literal, or a ModelPath)
    minimum: float | None = None
    maximum: float | None = None

    def arguments(self) -> list[str]:
        """runtime.Param's arguments: type, value, and the bounds the declaration has."""
        return [repr(self.type), py_literal(self.value)] + [
            f"{k}={v!r}" for k, v in (("minimum", self.minimum), ("maximum", self.maximum))
            if v is not None]


def size_names(t) -> set[str]:
    """The parameters a type's output sizes or requirements name, those that give a port
    its channels ('channels: n'), and a stencil's radius parameter (its generated kernel's
    window and interior are constants): fixed at build time."""
    import ast

    exprs = [e for d in t.outputs.values() for e in (d.height, d.width) if e is not None]
    exprs += [check for check, _ in t.requires]
    names = {n.id for e in exprs for n in ast.walk(e) if isinstance(n, ast.Name)}
    names |= {d.channels_param for d in (*t.inputs.values(), *t.outputs.values())
              if d.channels_param}
    decl = getattr(t, "fusable", None)
    if decl is not None:
        names |= decl.radius_names()
    return names


def with_settable_params(system: System, plan: ProgramPlan) -> tuple[ProgramPlan, list]:
    """The plan with every settable parameter printed as params['component.param'], and
    the declarations of those parameters (the program's PARAMS table)."""
    settable: dict[str, Settable] = {}

    def declare(key: str, t, pname: str, value) -> bool:
        decl = t.params.get(pname)
        if decl is None or pname in size_names(t) or decl.shape:
            return False  # arrays are tables compiled into a generated kernel
        settable[key] = Settable(key, decl.type, value, decl.minimum, decl.maximum)
        return True

    parts = []
    for part in plan.parts:
        t = getattr(system.nodes.get(part.name), "type", None)
        if t is None:
            parts.append(part)
            continue
        params = tuple((k, ParamRef(f"{part.name}.{k}"))
                       if declare(f"{part.name}.{k}", t, k, v) else (k, v)
                       for k, v in part.params)
        parts.append(dataclasses.replace(part, params=params))
    launches = []
    for la in plan.launches:
        node = system.nodes[la.part]
        args = []
        for a in la.arguments:
            if a.param:
                owner, pname = a.param.split(".", 1)
                # a group's parameters are its members' (a group of one: the component's)
                member = node.member(owner) if hasattr(node, "members") else node
                if declare(a.param, member.type, pname, a.value):
                    a = dataclasses.replace(a, value=ParamRef(a.param))  # noqa: PLW2901
            args.append(a)
        launches.append(dataclasses.replace(la, arguments=tuple(args)))
    members = {m.name: m for g in system.kernel_groups for m in g.members}
    programs = []
    for prog in plan.programs:
        defines = []
        for a in prog.defines:  # a group's constants: its members' parameters
            owner, pname = a.param.split(".", 1)
            if declare(a.param, members[owner].type, pname, a.value):
                a = dataclasses.replace(a, value=ParamRef(a.param))  # noqa: PLW2901
            defines.append(a)
        programs.append(dataclasses.replace(prog, defines=tuple(defines)))
    plan = dataclasses.replace(plan, parts=parts, launches=launches, programs=programs)
    return plan, sorted(settable.values(), key=lambda s: s.key)


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


def render(system: System, source: str, model_dir: str = ".") -> list[OutputFile]:
    """All files of one system, in a stable order: the program, then its lib folder (each
    kernel and user Python file once, whatever number of types use it).  model_dir: the
    model's folder relative to the output folder ('path' parameters start there)."""
    plan: ProgramPlan = with_model_paths(system, system.plan, model_dir)
    plan, settable = with_settable_params(system, plan)
    env = environment()
    model = system.model
    lib = plan.lib_dir
    header = HEADER.format(source=comment_text(source))
    files: list[OutputFile] = []
    groups = {g.name: g for g in system.kernel_groups}
    for src in plan.lib_sources:
        text = group_kernel(groups[src.users[0]], header, system.device) \
            if src.kind == "group" else lib_file_text(src, header)
        files.append(OutputFile(PurePosixPath(lib, src.file), text))
    from ...plan import plan_lines

    model_folder = model.file.resolve().parent
    inputs = sorted((comment_text(Path(os.path.relpath(p, model_folder)).as_posix()), digest)
                    for p, digest in model.inputs.items() if p != model.file.resolve())
    program = env.get_template("program.py.j2").render(
        header=header, sha256=model.text_sha256, inputs=inputs,
        description=model.description, lib=lib,
        plan=plan, plan_lines=plan_lines(plan), settable=settable,
        sources=[n for n in system.order if isinstance(system.nodes[n], ComponentNode)])
    files.insert(0, OutputFile(PurePosixPath(f"{system.name}.py"), program))
    return files
