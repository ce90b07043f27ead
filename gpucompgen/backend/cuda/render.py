"""The CUDA backend's printer: the same program as the OpenCL backend's, driving CUDA.

The generated program talks to the device only through ``runtime.*`` names; the CUDA
runtime module (gpucompgen.runtime.cuda) offers the same names, so the program is the
OpenCL printer's with its runtime import and kernel file names changed: every transfer,
launch setting (grid = global / local, block = local) and size stays a visible line.  Each
kernel file becomes a .cu file: the prelude (prelude.py), then the kernel as written.

Until the plan carries neutral kernel records (issue 23), this printer reuses the OpenCL
printer's output and rewrites those few lines; a test compares the two programs line by
line, so a template change that this misses fails there.
"""

from __future__ import annotations

import re
from pathlib import PurePosixPath

from ...errors import Diagnostic, GpucompgenError
from ...output import HEADER_PREFIX, OutputFile, source_path
from ..opencl.render import API_IMPORT
from ..opencl.render import render as render_opencl
from .prelude import PRELUDE, translate, unportable

__all__ = ["HEADER_PREFIX", "OutputFile", "render", "source_path"]

KERNEL_SUFFIX = ".cu"
# The lines of the OpenCL program that name OpenCL, and what the CUDA program says.
_PROGRAM_LINES = (
    # the runtime module, where an import sorter puts it (the program passes ruff's isort)
    ("from gpucompgen import runtime\n", ""),
    ("from gpucompgen.runtime import Size\n",
     "from gpucompgen.runtime import Size\nfrom gpucompgen.runtime import cuda as runtime\n"),
    ("select the OpenCL device with\nPYOPENCL_CTX.",
     "select the CUDA device with\nCUDA_DEVICE (default 0)."),
    ("OpenCL profiling events time every kernel and copy",
     "CUDA events time every kernel and copy"),
    (API_IMPORT, ""),  # its one use, below, is the runtime's
    ("cl.wait_for_events(", "runtime.wait_for_events("),
)


def check_portable(system) -> None:
    """Every GPU kernel the system uses is in the portable subset the prelude maps; an
    OpenCL-only construct is an error at its place in the kernel file, saying what to
    write instead."""
    problems = []
    launched = [(name, src) for src in system.plan.lib_sources if src.kind == "kernel"
                for name in src.users]
    for name, src in sorted(launched, key=lambda pair: pair[0]):  # by type, as they are used
        for u in unportable(src.text):
            problems.append(Diagnostic(
                src.origin or name, u.line, u.column, "error",
                f"component type {name}: '{u.text}' ({u.what}) is OpenCL-only; the CUDA "
                "backend cannot compile it",
                f"{u.hint}; docs/cuda.md lists the portable subset"))
    if problems:
        raise GpucompgenError(problems)


def cuda_kernel_file(text: str) -> str:
    """A .cu file: gpucompgen's header comment lines, the prelude, then the kernel."""
    header, sep, body = text.partition("\n\n")
    if not header.startswith("// ") or not sep:
        header, body = "", text
    return (f"{header}\n\n" if header else "") + PRELUDE + "#line 1\n" + translate(body)


def cuda_program(text: str, renames: dict[str, str]) -> str:
    for old, new in _PROGRAM_LINES:
        text = text.replace(old, new)
    for old, new in renames.items():
        text = re.sub(rf"(?<![\w.-]){re.escape(old)}(?!\w|-|\.\w)", new, text)
    return text


def render(system, source: str, model_dir: str = ".") -> list[OutputFile]:
    """All files of one system for CUDA: the program, then its lib folder (.cu kernels,
    user Python files as for OpenCL)."""
    check_portable(system)
    files = render_opencl(system, source, model_dir)
    renames = {f.path.name: f.path.with_suffix(KERNEL_SUFFIX).name
               for f in files[1:] if f.path.suffix == ".cl"}
    out = [OutputFile(files[0].path, cuda_program(files[0].text, renames))]
    for f in files[1:]:
        if f.path.suffix == ".cl":
            out.append(OutputFile(PurePosixPath(f.path.with_suffix(KERNEL_SUFFIX)),
                                  cuda_kernel_file(f.text)))
        else:
            out.append(f)
    return out
