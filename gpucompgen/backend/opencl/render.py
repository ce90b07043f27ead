"""The OpenCL backend's printer: a ProgramPlan into files (the program and its lib folder).

The program is templates/opencl/program.py.j2 (the common program on gpucompgen.runtime,
pyopencl) printed by gpucompgen.printing; every kernel file, the fused groups' included
(their text written by the kernel generator when the plan was lowered), is the plan's
text under the generated-file header.
"""

from __future__ import annotations

from ... import printing
from ...output import OutputFile

TEMPLATE = "opencl/program.py.j2"
KERNEL_SUFFIX = ".cl"


def render(system, source: str, model_dir: str = ".") -> list[OutputFile]:
    """All files of one system (printing.render), from the plan alone (system.plan)."""
    return printing.render(system.plan, system.name, source, model_dir, TEMPLATE,
                           printing.lib_file_text)
