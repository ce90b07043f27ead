"""A type's source files: the kernel, Python and CPU files it names, read once from
inside the type file's folder; a standard type's Python class and a flexible type's CPU
function, checked with ast (never imported)."""

from __future__ import annotations

import ast
import functools
from pathlib import Path
from typing import Any

from ..errors import Diagnostic, did_you_mean
from ..loader import MAX_SOURCE_BYTES, FileProblem, read_text
from ..names import name_problem
from .decls import ComponentType
from .fields import _expect_map, _unknown_keys

PYTHON_KEYS = ("file", "class")
CPU_KEYS = ("file", "function")


def _resolve_file(doc, rep, path, decl_dir: Path, value: Any, suffix: str,
                  what: str) -> tuple[Path, str] | None:
    """A kernel or Python file of a type and its text, or None after reporting why not.

    The file must be a regular file inside the folder of the type file, also after
    resolving symbolic links, at most MAX_SOURCE_BYTES long and UTF-8 text."""
    if not isinstance(value, str) or not value:
        rep.error(doc.pos(*path), f"expected a file name ending in {suffix}")
        return None
    rel = Path(value)
    if "\0" in value or rel.is_absolute() or ".." in rel.parts or rel.suffix != suffix:
        rep.error(doc.pos(*path), f"file {value!r} must be a relative path ending in {suffix}, "
                  "inside the folder of the type file", "move the file next to the type file")
        return None
    full = decl_dir / rel
    try:
        real = full.resolve()
        inside = real.is_relative_to(decl_dir.resolve())
    except (OSError, RuntimeError):  # a loop of links
        inside = False
    if not inside:
        rep.error(doc.pos(*path), f"file {value!r} is a link to a file outside the folder "
                  "of the type file", "copy the file next to the type file instead of "
                  "linking to it")
        return None
    shown = str(Path(doc.file).parent / rel)
    try:
        text = read_text(full, MAX_SOURCE_BYTES, f"{what} {value!r}")
    except FileProblem as exc:
        if exc.line:  # not UTF-8: say where in that file
            rep.diagnostics.append(Diagnostic(shown, exc.line, exc.col, "error", exc.message,
                                              exc.hint))
        elif exc.message.endswith("not found"):
            rep.error(doc.pos(*path), f"file {value!r} not found (looked in {decl_dir.name}/)",
                      "paths are relative to the component-type file")
        else:
            rep.error(doc.pos(*path), exc.message, exc.hint)
        return None
    return full, text


def _check_class(doc, rep, base, ctype: ComponentType, pspec: dict) -> None:
    """The Python file defines the class at module level: read with ast, never imported."""
    shown = str(Path(doc.file).parent / pspec["file"])
    try:
        module = ast.parse(ctype.python_text, shown)
    except SyntaxError as exc:
        rep.diagnostics.append(Diagnostic(shown, exc.lineno or 1, exc.offset or 1, "error",
                                          f"syntax error in Python file: {exc.msg}",
                                          "fix the module: the generated program imports it"))
        return
    except (ValueError, RecursionError, MemoryError) as exc:
        rep.error(doc.pos(*base, "python", "file"),
                  f"Python file {pspec['file']!r} cannot be read as Python: "
                  f"{type(exc).__name__}", "fix the module: the generated program imports it")
        return
    defined = module_names(module.body)
    if ctype.python_class not in defined:
        classes = [n for n, kind in defined.items() if kind == "class"]
        pos = doc.pos(*base, "python", "class") if "class" in pspec else \
            doc.key_pos(*base, "python")
        rep.error(pos, f"class '{ctype.python_class}' is not defined in {shown}",
                  did_you_mean(ctype.python_class, classes) if classes else
                  f"define 'class {ctype.python_class}:' at the top level of {pspec['file']}")


def module_names(body: list[ast.stmt]) -> dict[str, str]:
    """Names a module's top level binds: name -> "class" | "other" (also inside if/try/with
    blocks at module level, never inside functions or classes)."""
    names: dict[str, str] = {}
    for node in body:
        if isinstance(node, ast.ClassDef):
            names[node.name] = "class"
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            names.setdefault(node.name, "other")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            for alias in node.names:
                if alias.name != "*":
                    names.setdefault(alias.asname or alias.name.split(".")[0], "other")
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                for sub in ast.walk(target):
                    if isinstance(sub, ast.Name):
                        names.setdefault(sub.id, "other")
        elif isinstance(node, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
            blocks = [node.body, getattr(node, "orelse", []), getattr(node, "finalbody", [])]
            blocks += [h.body for h in getattr(node, "handlers", [])]
            for block in blocks:
                for name, kind in module_names(block).items():
                    if names.get(name) != "class":
                        names[name] = kind
    return names


def _load_python(doc, rep, base, ctype: ComponentType, spec) -> None:
    pspec = _expect_map(doc, rep, base + ("python",), spec.get("python"), "python")
    if not pspec:
        rep.error(ctype.pos, f"standard type '{ctype.name}' needs 'python: {{file, class}}'")
        return
    _unknown_keys(doc, rep, base + ("python",), pspec, PYTHON_KEYS, "python")
    found = _resolve_file(doc, rep, base + ("python", "file"), ctype.decl_file.parent,
                          pspec.get("file"), ".py", "Python file")
    if found is not None:
        ctype.python_file, ctype.python_text = found
    cls = pspec.get("class", ctype.name)
    problem = name_problem(cls, "class name", top_level=True)  # imported at module level
    if problem:
        rep.error(doc.pos(*base, "python", "class"), problem)
    else:
        ctype.python_class = cls
        if found is not None:
            _check_class(doc, rep, base, ctype, pspec)
    if ctype.python_file is not None and ctype.origin == "user":
        problem = name_problem(ctype.python_file.stem, "Python module name")
        if problem:
            rep.error(doc.pos(*base, "python", "file"), problem,
                      "rename the file to a valid module name")


@functools.lru_cache(maxsize=16)
def _parsed(text: str, filename: str) -> ast.Module:
    """A Python file's tree, parsed once: the library's sixty CPU forms live in a few
    modules (the tree is only read)."""
    return ast.parse(text, filename)


def _load_cpu(doc, rep, base, ctype: ComponentType, spec) -> None:
    """A flexible type's CPU side: ``cpu: {file: x.py, function: f}``.

    The function takes every input port (a numpy array) and every parameter as keywords
    and returns the output array (a tuple of them for several outputs, in the type's
    order).  Its file is parsed with ast, never imported: it must define the function at
    module level, and the function must accept those keywords.
    """
    path = base + ("cpu",)
    cspec = _expect_map(doc, rep, path, spec.get("cpu"), "cpu")
    if not cspec:
        if "cpu" not in spec:
            rep.error(ctype.pos, f"flexible type '{ctype.name}' needs "
                      "'cpu: {file, function}', its CPU implementation",
                      "write a numpy function taking the inputs and parameters as keywords "
                      "and returning the output(s)")
        return
    _unknown_keys(doc, rep, path, cspec, CPU_KEYS, "cpu")
    found = _resolve_file(doc, rep, path + ("file",), ctype.decl_file.parent,
                          cspec.get("file"), ".py", "Python file")
    cpu_text = ""
    if found is not None:
        ctype.cpu_file, cpu_text = found
        ctype.cpu_text = cpu_text
    function = cspec.get("function", ctype.snake)
    fpos = doc.pos(*path, "function") if "function" in cspec else doc.key_pos(*path)
    problem = name_problem(function, "function name")
    if problem:
        rep.error(fpos, problem)
        return
    ctype.cpu_function = function
    if ctype.cpu_file is None:
        return
    if ctype.origin == "user":
        problem = name_problem(ctype.cpu_file.stem, "Python module name")
        if problem:
            rep.error(doc.pos(*path, "file"), problem, "rename the file to a valid module name")
    try:
        tree = _parsed(cpu_text, str(ctype.cpu_file))
    except SyntaxError as exc:
        rep.error(doc.pos(*path, "file"), f"{ctype.cpu_file.name}:{exc.lineno}: {exc.msg}",
                  "fix the Python syntax of the CPU implementation")
        return
    found = next((n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
                  and n.name == function), None)
    if found is None:
        defined = [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]
        rep.error(fpos, f"{ctype.cpu_file.name} defines no function '{function}' at module "
                  "level", did_you_mean(function, defined) or
                  f"define 'def {function}({', '.join(ctype.inputs)}, ...)' there")
        return
    if isinstance(found, ast.AsyncFunctionDef):
        rep.error(fpos, f"'{function}' in {ctype.cpu_file.name} is async", "make it a plain def")
        return
    _check_cpu_arguments(rep, fpos, ctype, function, found.args)


def _check_cpu_arguments(rep, fpos, ctype: ComponentType, function: str,
                         a: ast.arguments) -> None:
    """The CPU function takes every input and parameter as a keyword, and needs nothing
    else."""
    named = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    wanted = list(ctype.inputs) + list(ctype.params)
    positional_only = {x.arg for x in a.posonlyargs}
    missing = [w for w in wanted if w not in named or w in positional_only]
    if missing and a.kwarg is None:
        rep.error(fpos, f"function '{function}' in {ctype.cpu_file.name} does not take "
                  + ", ".join(f"'{m}'" for m in missing) + " as keyword"
                  + ("s" if len(missing) > 1 else ""),
                  f"it is called as {function}("
                  + ", ".join(f"{w}=..." for w in wanted) + "): add the missing parameters")
    # parameters it has that the call never passes must have defaults
    n_pos = len(a.posonlyargs) + len(a.args)
    pos_defaults = n_pos - len(a.defaults)
    unfilled = [x.arg for i, x in enumerate(a.posonlyargs + a.args)
                if i < pos_defaults and x.arg not in wanted]
    unfilled += [x.arg for x, d in zip(a.kwonlyargs, a.kw_defaults)
                 if d is None and x.arg not in wanted]
    if unfilled:
        rep.error(fpos, f"function '{function}' in {ctype.cpu_file.name} needs "
                  + ", ".join(f"'{u}'" for u in unfilled) + f", which is no input or "
                  f"parameter of '{ctype.name}'",
                  "give it a default, or declare it as a parameter of the type")
