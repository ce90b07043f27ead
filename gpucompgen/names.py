"""Names from a model become Python and OpenCL identifiers: validate them first."""

from __future__ import annotations

import builtins
import keyword
import re
import sys

# Kernel-language reserved words and the modules generated programs import live with
# each backend (backend/<name>/reserved.py); a model must build for every backend.
from .backend import module_names, reserved_words

KERNEL_RESERVED = reserved_words()

NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
MAX_NAME = 48

# Names the generated program itself uses at module level or in run().
GENERATED_RESERVED = frozenset({
    "np", "cl", "runtime", "run", "main", "args", "argv", "frame", "frames", "context", "queue",
    "sys", "Size", "components", "result", "KERNEL_DIR", "Path", "monitor", "profile",
    "profiler",
    # module level of the generated program (a local of the same name would shadow them)
    "LIB_DIR", "DESCRIPTION", "CpuToGpuAdapter", "GpuToCpuAdapter", "ZeroCopyCpuToGpuAdapter",
    "ZeroCopyGpuToCpuAdapter", "parts", "exc", "annotations", "PARAMS", "params",
})
# Families of names run() makes: its queues, built programs and adapters.
GENERATED_PATTERN = re.compile(r"(queue[0-9]+|[A-Za-z0-9_]+_program|"
                               r"adapter[0-9]+_(cpu2gpu|gpu2cpu))\Z")

# Members and locals of a generated GPU-aware component class other than those its ports
# and parameters make (see member_names).
CLASS_RESERVED = frozenset({
    "self", "context", "queue", "program", "kernel", "profile", "event", "local_size",
    "global_size", "scalar_args", "initialize", "config_gpu", "execute", "free_memory",
    "wait_for", "ran", "grid", "tile", "block_x", "block_y", "block_z",
    "np", "cl", "runtime", "Size",
    # runtime.KernelComponent's members
    "function", "inputs", "outputs", "output_sizes", "sizes", "buffers", "hosts",
    "arguments", "copies_own_data", "host_visible", "settings_source", "_inputs",
    "_outputs", "_slots", "_enqueue", "_results", "_copy_and_run",
})

# A system's name becomes <system>.py, whose folder comes first on sys.path when it runs:
# it must not hide a module that the program or its runtime imports.
MODULE_NAMES = frozenset(sys.stdlib_module_names) | {
    "numpy", "gpucompgen", "scipy", "PIL", "cv2", "yaml", "jinja2"} | module_names()


def member_names(name: str, role: str) -> list[str]:
    """What a GPU-aware component class makes of one of its parameter or port names.

    role: "param" (self.<p>), "in" (argument <i>, self.<i>_size, self.<i>_gpu and the
    local <i>_copied in standard mode) or "out" (self.<o>, self.<o>_size, self.<o>_gpu,
    <o>_copied).
    """
    if role == "param":
        return [name]
    return [name, f"{name}_size", f"{name}_gpu", f"{name}_copied"]

__all__ = ["KERNEL_RESERVED", "fold", "member_names", "name_hint", "name_problem", "snake"]

_RESERVED = (frozenset(keyword.kwlist) | frozenset(keyword.softkwlist) | frozenset(dir(builtins))
             | KERNEL_RESERVED | {"self"})


def name_problem(name: object, what: str, top_level: bool = False) -> str | None:
    """Why name is not a valid identifier for a model, or None when it is.

    top_level names (components, systems) become variables of the generated run()
    function, so they must also avoid the names generated code itself uses.
    """
    if name is None:
        return f"{what} is missing"
    if not isinstance(name, str):
        kind = {bool: "the boolean", int: "the integer", float: "the number"}.get(
            type(name), type(name).__name__)
        return (f"{what} must be a name, not {kind} {name!r} (YAML 1.1 reads no/yes/on/off "
                "as booleans and 010 as the integer 8: quote it if it is meant as a name)")
    if not NAME_RE.match(name):
        return (f"invalid {what} {name!r}: use letters, digits and '_' only, "
                "starting with a letter")
    if len(name) > MAX_NAME:
        return f"{what} {name!r} is longer than {MAX_NAME} characters"
    if name in _RESERVED or name.lower() in KERNEL_RESERVED or (
            top_level and (name in GENERATED_RESERVED or GENERATED_PATTERN.match(name))):
        return f"{what} {name!r} is a reserved word in Python, OpenCL or generated code"
    return None


def name_hint(name: object, default: str) -> str:
    """What to do about a name name_problem refused: shorten a long one, rename a reserved
    one; else default (what a good name looks like)."""
    if isinstance(name, str) and NAME_RE.match(name):
        if len(name) > MAX_NAME:
            return (f"shorten it to {MAX_NAME} characters or fewer, e.g. "
                    f"{name[:MAX_NAME].rstrip('_')!r}")
        for other in (f"my_{name}", f"{name}_1"):
            if name_problem(other, "name", top_level=True) is None:
                return f"rename it, e.g. {other!r}"
        return "rename it"
    return default


def fold(name: str) -> str:
    """Names that fold to the same string collide (case and underscores ignored)."""
    return name.replace("_", "").lower()


def snake(name: str) -> str:
    """CamelCase → snake_case (ImageMerger → image_merger)."""
    out = re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name)
    out = re.sub(r"(?<=[A-Z])([A-Z][a-z])", r"_\1", out)
    return out.lower()
