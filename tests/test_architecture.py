"""The layering of gpucompgen/, checked on its import graph (parsed with ast, never imported).

Every module belongs to one layer (LAYERS, first matching prefix wins); ALLOWED says which
layers a layer may import, EXTERNAL which layers may import a device API's package.  An
edge outside the table fails, unless it is listed in KNOWN_DEBT with why it is still there:
the debt list may only shrink (an entry no longer in the graph fails too, so that it is
removed when its edge is).  docs/development.md shows the same table and graph
(test_docs_show_the_layers; `python tests/test_architecture.py` prints them).

No function in gpucompgen/ is longer than MAX_FUNCTION_LINES, but those in KNOWN_LONG, a
list that may only shrink the same way.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "gpucompgen"

# (module prefix, layer): the first prefix that matches a module's dotted name wins
LAYERS = [
    ("gpucompgen.backend.opencl", "backend-opencl"),
    ("gpucompgen.backend.cuda", "backend-cuda"),
    ("gpucompgen.backend", "registry"),
    ("gpucompgen.plan", "records"),
    ("gpucompgen.convention", "records"),
    ("gpucompgen.dataflow", "records"),
    ("gpucompgen.errors", "records"),
    ("gpucompgen.output", "records"),
    ("gpucompgen.printing", "records"),
    ("gpucompgen.runtime.opencl", "runtime-opencl"),
    ("gpucompgen.runtime.cuda", "runtime-cuda"),
    ("gpucompgen.runtime.__init__", "runtime-facade"),
    ("gpucompgen.runtime", "runtime"),
    ("gpucompgen.io", "io"),
    ("gpucompgen.library", "library"),
    ("gpucompgen", "generic"),
]

# What each layer may import (besides itself).
ALLOWED = {
    # model, loader, ir, passes, lower, build, cli, tune, bench, ...: they reach a backend
    # only through the registry, and the runtime only through its neutral core, its facade
    # (the default device API of generated programs) and the device interface
    "generic": {"records", "registry", "runtime", "runtime-facade", "io", "library"},
    # the plan records, the values that flow (Endpoint, Data), the calling convention and
    # the error values: what lowering emits and a backend receives; the output files: what
    # a backend gives back; printing: the plan printed through a backend's template
    "records": {"runtime"},
    # picks a backend by name (importlib), so it imports none
    "registry": set(),
    # a backend receives the plan records, nothing else
    "backend-opencl": {"records"},
    "backend-cuda": {"records"},
    # the runtime's neutral core: no device API, nothing of the generator
    "runtime": set(),
    # ``from gpucompgen import runtime``: the core plus the OpenCL module, the device API of
    # generated OpenCL programs
    "runtime-facade": {"runtime", "runtime-opencl"},
    # a device API's module implements the interface over the core
    "runtime-opencl": {"runtime"},
    "runtime-cuda": {"runtime"},
    # sources and sinks; the library's components (what generated programs import)
    "io": {"runtime"},
    "library": {"io", "runtime", "runtime-facade"},
}

# Third-party packages of one device API: only these layers may import them.
EXTERNAL = {
    "pyopencl": {"runtime-opencl", "backend-opencl"},
    "cuda": {"runtime-cuda", "backend-cuda"},
}

# Edges that break the table today, each with why it is still there.  Remove an entry with
# its edge; never add one for new code.
KNOWN_DEBT = {
    # The kernel generator lives in the OpenCL backend: the CUDA printer asks it for the
    # fused groups' kernels (a sibling's import) until it moves out of the backend.
    ("gpucompgen.backend.cuda.render", "gpucompgen.backend.opencl.fused"):
        "the group kernels come from the kernel generator in the OpenCL backend",
    # The kernel generator works on the IR's groups and the model's types, and fusion asks
    # it what a group's kernel costs; a neutral record per fused kernel (member bodies,
    # accessors, borders, constant sizes) would cut these edges.
    ("gpucompgen.backend.opencl.fused", "gpucompgen.ir"): "group kernels from IR groups",
    ("gpucompgen.backend.opencl.fused", "gpucompgen.model"): "group kernels from model types",
    ("gpucompgen.backend.opencl.fused", "gpucompgen.passes.fuse"): "the group GPU settings",
    ("gpucompgen.backend.opencl.fused", "gpucompgen.device"): "the default device's facts",
    ("gpucompgen.backend.opencl.fused", "gpucompgen.snippet"): "snippets printed as C",
    ("gpucompgen.backend.opencl.fused", "gpucompgen.runtime.sizes"): "Size of constant sizes",
    ("gpucompgen.passes.fuse", "gpucompgen.backend.opencl.fused"):
        "fusion checks a group's generated kernel (the kernel generator is OpenCL's)",
    ("gpucompgen.bench", "gpucompgen.backend.opencl.fused"):
        "the hand-written reference runs the generator's VerticalMirror kernel",
    ("gpucompgen.tune", "gpucompgen.backend.opencl.fused"):
        "a fusable type's kernel is written by the generator to be measured",
}


def layer_of(module: str) -> str:
    for prefix, layer in LAYERS:
        if module == prefix or module.startswith(prefix + "."):
            return layer
    raise AssertionError(f"{module} is in no layer")


def modules() -> dict[str, Path]:
    """Dotted name -> file; a package's __init__ is '<package>.__init__'."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        found[".".join(path.relative_to(ROOT).with_suffix("").parts)] = path
    return found


def _target(known: dict[str, Path], name: str) -> str:
    """The module an imported dotted name is (a package: its __init__)."""
    if name in known:
        return name
    if f"{name}.__init__" in known:
        return f"{name}.__init__"
    return name


def import_graph() -> dict[str, set[str]]:
    """module -> the modules it imports (gpucompgen's by module, others by top package).
    `from package import name` counts the submodule when name is one."""
    known = modules()
    graph: dict[str, set[str]] = {}
    for module, path in known.items():
        package = module.split(".")[:-1]
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = package[:len(package) - node.level + 1]
                    base = ".".join(parent + ([base] if base else []))
                names = []
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    names.append(full if full in known or f"{full}.__init__" in known
                                 else base)
            else:
                continue
            for name in names:
                if name.split(".")[0] == "gpucompgen":
                    edges.add(_target(known, name))
                else:
                    edges.add(name.split(".")[0])
        edges.discard(module)
        graph[module] = edges
    return graph


def _short(module: str) -> str:
    return module.removesuffix(".__init__")


def violations() -> list[tuple[str, str, str]]:
    """(module, imported, why not allowed) for every edge outside the table."""
    found = []
    for module, edges in import_graph().items():
        layer = layer_of(module)
        for target in sorted(edges):
            if target.startswith("gpucompgen"):
                other = layer_of(target)
                if other != layer and other not in ALLOWED[layer]:
                    found.append((_short(module), _short(target),
                                  f"layer {layer} may not import layer {other}"))
            elif target in EXTERNAL and layer not in EXTERNAL[target]:
                found.append((_short(module), target, f"layer {layer} may not import {target}"))
    return found


def _debt_key(module: str, target: str) -> tuple[str, str] | None:
    """The KNOWN_DEBT entry covering an edge (an entry may name a package)."""
    for m, t in KNOWN_DEBT:
        if module == m and (target == t or target.startswith(t + ".")):
            return (m, t)
    return None


def test_every_module_has_a_layer():
    for module in modules():
        layer_of(module)
    assert set(ALLOWED) == {layer for _, layer in LAYERS}


def test_no_edge_outside_the_table():
    new = [f"{m} imports {t} ({why})" for m, t, why in violations() if not _debt_key(m, t)]
    assert not new, "imports that break the layering (docs/development.md):\n" + "\n".join(new)


def test_known_debt_is_still_owed():
    used = {_debt_key(m, t) for m, t, _ in violations()}
    paid = sorted(f"{m} -> {t}" for m, t in KNOWN_DEBT if (m, t) not in used)
    assert not paid, "KNOWN_DEBT entries whose edge is gone (remove them):\n" + "\n".join(paid)


def test_the_checker_sees_a_forbidden_edge(tmp_path, monkeypatch):
    """The graph is read from the files: a generic module importing a backend is caught."""
    fake = tmp_path / "gpucompgen"
    (fake / "backend" / "opencl").mkdir(parents=True)
    for name in ("__init__.py", "backend/__init__.py", "backend/opencl/__init__.py",
                 "backend/opencl/render.py"):
        (fake / name).write_text("")
    (fake / "names.py").write_text("from .backend.opencl import render\nimport pyopencl\n")
    (fake / "runtime").mkdir()
    (fake / "runtime" / "__init__.py").write_text("")
    (fake / "runtime" / "sizes.py").write_text("from pyopencl import Buffer\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", fake)
    assert sorted((m, t) for m, t, _ in violations()) == [
        ("gpucompgen.names", "gpucompgen.backend.opencl.render"),
        ("gpucompgen.names", "pyopencl"),
        ("gpucompgen.runtime.sizes", "pyopencl"),
    ]


def test_pyopencl_is_named_only_in_its_modules():
    """`grep -rl pyopencl gpucompgen`: the OpenCL backend and the runtime's OpenCL module."""
    named = sorted(str(p.relative_to(ROOT)) for p in PACKAGE.rglob("*")
                   if p.is_file() and p.suffix in (".py", ".j2", ".json", ".yaml", ".cl")
                   and "pyopencl" in p.read_text(encoding="utf-8", errors="replace"))
    allowed = [p for p in named if p.startswith(("gpucompgen/backend/opencl/",
                                                 "gpucompgen/runtime/opencl"))]
    assert named == allowed


# The runtime's core and what tests of it import, with pyopencl (and cuda) made impossible to
# import: a finder first on sys.meta_path raises ImportError for them.
_BLOCKED = """
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("pyopencl", "cuda"):
            raise ModuleNotFoundError(f"{name} is blocked")
        return None
sys.meta_path.insert(0, Block())
"""


def _runtime_core() -> list[str]:
    return sorted(_short(m) for m in modules() if layer_of(m) == "runtime")


def test_runtime_core_imports_without_pyopencl():
    code = _BLOCKED + "\n".join(f"import {m}" for m in _runtime_core()) + """
import gpucompgen.runtime as runtime
assert "pyopencl" not in sys.modules
from gpucompgen.runtime import Size, check_frame, Profile, Monitor, Parts
import numpy as np
assert Size(2, 3, 1).nbytes(np.uint8) == 6
try:
    runtime.create_context()
except ImportError as exc:
    print("no device API:", exc)
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "ok"


@pytest.mark.parametrize("test_file", ["test_runtime_messages.py", "test_lifecycle.py",
                                       "test_overrides.py", "test_frames_checked.py"])
def test_runtime_tests_run_without_pyopencl(test_file, tmp_path):
    """Tests of the runtime's core, run with pyopencl blocked: those that need a device
    skip, the rest pass."""
    conftest = tmp_path / "block_pyopencl.py"
    conftest.write_text(_BLOCKED)
    # no device pinned and not CI: the tests that need a device skip (conftest.py)
    env = {k: v for k, v in os.environ.items() if k not in ("PYOPENCL_CTX", "CI")}
    done = subprocess.run(
        [sys.executable, "-c", f"exec(open({str(conftest)!r}).read())\nimport pytest, sys\n"
         f"sys.exit(pytest.main(['-q', '-p', 'no:cacheprovider', '-n', '0', "
         f"{str(ROOT / 'tests' / test_file)!r}]))"],
        capture_output=True, text=True, cwd=ROOT, timeout=600, env=env)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert " passed" in done.stdout


def layer_table() -> str:
    """The table docs/development.md shows: each layer, what it may import, its modules."""
    members: dict[str, set[str]] = {layer: set() for layer in ALLOWED}
    for module in modules():
        name = _short(module).removeprefix("gpucompgen.")
        if layer_of(module) == "generic" and ("." in name or (
                module.endswith(".__init__") and name != "gpucompgen")):  # a package
            name = name.split(".")[0] + "/"
        members[layer_of(module)].add(name)
    rows = ["| layer | may import | modules (under gpucompgen/) |", "|---|---|---|"]
    for layer, allowed in ALLOWED.items():
        shown = ", ".join(f"`{n}`" for n in sorted(members[layer]) if n != "gpucompgen")
        rows.append(f"| {layer} | {', '.join(sorted(allowed)) or '(none)'} | {shown} |")
    return "\n".join(rows) + "\n"


def layer_graph() -> str:
    """The allowed edges between layers as a Mermaid flowchart (GitHub draws it)."""
    lines = ["```mermaid", "flowchart TD"]
    for layer, allowed in ALLOWED.items():
        lines += [f"  {layer} --> {other}" for other in sorted(allowed)]
    lines += ["```"]
    return "\n".join(lines) + "\n"


def test_docs_show_the_layers():
    """docs/development.md shows this test's table and graph; regenerate them with
    `python tests/test_architecture.py` and paste."""
    text = (ROOT / "docs" / "development.md").read_text(encoding="utf-8")
    assert layer_table() in text
    assert layer_graph() in text


def test_docs_list_the_passes_in_order():
    from gpucompgen.passes.pipeline import PIPELINE

    text = (ROOT / "docs" / "development.md").read_text(encoding="utf-8")
    rows = [line.split("|")[1].strip().strip("`") for line in text.splitlines()
            if line.startswith("| `") and line.count("|") == 4
            and line.split("|")[2].strip().endswith(".py`")]
    assert rows == [p.name for p in PIPELINE]


def test_the_opencl_module_implements_the_device_interface():
    """Every function and name the interface declares is the OpenCL module's (importing it
    needs no pyopencl: its functions import it)."""
    import inspect

    from gpucompgen.runtime import device_api, opencl

    declared = {name for name, _ in inspect.getmembers(device_api.DeviceAPI, inspect.isfunction)
                if not name.startswith("_")} | set(device_api.DeviceAPI.__annotations__)
    assert declared >= {"copy", "map", "unmap", "launch", "build_program", "event_seconds"}
    missing = sorted(name for name in declared if not hasattr(opencl, name))
    assert not missing
    assert device_api.get() is opencl



# --- function length --------------------------------------------------------------------

MAX_FUNCTION_LINES = 80  # def line to last line, decorators and docstring included
# Functions over the limit today, each with why it is still long.  Remove an entry when its
# function is split; never add one for new code.
KNOWN_LONG = {
    ("backend/opencl/fused.py", "_kernel"):
        "the fused-kernel printer; the kernel-generator work (issue 24) is rewriting it",
}


def long_functions(package: Path = PACKAGE) -> dict[tuple[str, str], int]:
    """(file under the package, function name) -> lines, for every function or method
    (nested ones too) longer than MAX_FUNCTION_LINES, found with ast (nothing imported)."""
    found = {}
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                lines = node.end_lineno - first + 1
                if lines > MAX_FUNCTION_LINES:
                    found[(path.relative_to(package).as_posix(), node.name)] = lines
    return found


def test_no_function_is_longer_than_the_limit():
    long = long_functions()
    new = sorted(f"gpucompgen/{f}: {name} ({n} lines): over {MAX_FUNCTION_LINES} lines, "
                 "split it by concern" for (f, name), n in long.items()
                 if (f, name) not in KNOWN_LONG)
    paid = sorted(f"gpucompgen/{f}: {name}: in KNOWN_LONG but no longer over the limit, "
                  "remove the entry" for f, name in KNOWN_LONG if (f, name) not in long)
    assert not new + paid, "\n".join(new + paid)


def test_the_length_check_sees_a_long_function(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    (tmp_path / "m.py").write_text(f"def short():\n    pass\n\n\n@staticmethod\n"
                                   f"def long():\n{body}\n")
    assert long_functions(tmp_path) == {("m.py", "long"): MAX_FUNCTION_LINES + 2}


if __name__ == "__main__":
    print(layer_graph())
    print(layer_table())
