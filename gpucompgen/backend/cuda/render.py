"""The CUDA backend's printer: the plan's program on gpucompgen.runtime.cuda, .cu kernels.

The program is templates/cuda/program.py.j2 (the common program, which the OpenCL
backend's extends too) printed by gpucompgen.printing from the plan with its kernel files
named .cu (ProgramPlan.with_kernel_suffix): the runtime module offers the names the OpenCL
runtime does, so every transfer, launch setting (grid = global / local, block = local)
and size is the same visible line.  Each kernel file becomes a .cu file: the prelude
(prelude.py), then the kernel as written (in the portable subset, check_portable).
"""

from __future__ import annotations

from ... import printing
from ...errors import Diagnostic, GpucompgenError
from ...output import HEADER_PREFIX, OutputFile, source_path
from .prelude import PRELUDE, translate, unportable

__all__ = ["HEADER_PREFIX", "OutputFile", "render", "source_path"]

TEMPLATE = "cuda/program.py.j2"
KERNEL_SUFFIX = ".cu"


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


def render(system, source: str, model_dir: str = ".") -> list[OutputFile]:
    """All files of one system for CUDA, from the plan alone (system.plan): the program,
    then its lib folder (.cu kernels, user Python files as for OpenCL)."""
    check_portable(system)

    def lib_text(src, header: str) -> str:
        text = printing.lib_file_text(src, header)
        return cuda_kernel_file(text) if src.is_kernel else text

    plan = system.plan.with_kernel_suffix(KERNEL_SUFFIX)
    return printing.render(plan, system.name, source, model_dir, TEMPLATE, lib_text)
