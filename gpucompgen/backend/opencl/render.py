"""The OpenCL backend's printer: a ProgramPlan into files (the program and its lib folder).

The program is templates/opencl/program.py.j2 (the common program on gpucompgen.runtime,
pyopencl) printed by gpucompgen.printing; kernel files are copied as checked, and each
fused group's kernel is written by the kernel generator (fused.py).
"""

from __future__ import annotations

from ... import printing
from ...output import OutputFile
from .fused import group_kernel

TEMPLATE = "opencl/program.py.j2"
KERNEL_SUFFIX = ".cl"


def render(system, source: str, model_dir: str = ".") -> list[OutputFile]:
    """All files of one system (printing.render).  Everything printed comes from the plan
    (system.plan), but the fused kernels: the kernel generator still reads the system's
    groups and device (fused.py)."""
    groups = {g.name: g for g in system.kernel_groups}

    def lib_text(src, header: str) -> str:
        if src.kind == "group":
            return group_kernel(groups[src.users[0]], header, system.device)
        return printing.lib_file_text(src, header)

    return printing.render(system.plan, system.name, source, model_dir, TEMPLATE, lib_text)
