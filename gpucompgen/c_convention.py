"""The kernel calling convention in the portable C subset: the neutral order
(gpucompgen.convention) with its element types spelled as OpenCL C names, which the
CUDA prelude (backend/cuda/prelude.py) defines too.

A GPU-aware component's kernel takes ``__global`` pointers for its ports (inputs may be
``const``), each port's height and width as ``int``, its parameters (``float`` for float
parameters, ``int`` for int and bool ones) and ``int tile``, in the order
:func:`gpucompgen.convention.kernel_parameters` declares.  The ``check`` command compares
a user's kernel with it (backend/opencl/signature.py) and the kernel generator declares
its kernels with it (kernelgen/fused.py).
"""

from __future__ import annotations

from dataclasses import dataclass

from .convention import HOST_TYPES, Param
from .convention import group_constants as _group_constants
from .convention import group_parameters as _group_parameters
from .convention import kernel_parameters as _kernel_parameters

# element type -> OpenCL C type
C_TYPES = {
    "uint8": "uchar",
    "int8": "char",
    "uint16": "ushort",
    "int16": "short",
    "int32": "int",
    "uint32": "uint",
    "float32": "float",
}
# parameter type -> (OpenCL C scalar type, numpy conversion used by the host)
PARAM_C_TYPES = {t: (C_TYPES[h], f"np.{h}") for t, h in HOST_TYPES.items()}


@dataclass(frozen=True)
class KernelParam:
    """One parameter of a kernel, as the convention requires it."""

    name: str  # the conventional name (the kernel may call it anything)
    kind: str  # "buffer" | "scalar" | "constant" (a build option: group_constants)
    c_type: str  # element type of a buffer, or the scalar's type
    role: str  # "input" | "output" | "size" | "param" | "tile"
    port: str = ""  # the port a buffer or size belongs to
    dim: str = ""  # "height" | "width" for sizes
    param: str = ""  # the model parameter a scalar carries

    def declaration(self) -> str:
        """How the parameter would be written in a kernel."""
        if self.kind == "buffer":
            const = "const " if self.role == "input" else ""
            return f"__global {const}{self.c_type} *{self.name}"
        return f"const {self.c_type} {self.name}"


def _spelled(p: Param) -> KernelParam:
    return KernelParam(p.name, p.kind, C_TYPES[p.dtype], p.role, p.port, p.dim, p.param)


def kernel_parameters(ctype) -> list[KernelParam]:
    """The parameter list a GPU-aware component type's kernel must have."""
    return [_spelled(p) for p in _kernel_parameters(ctype)]


def signature_text(ctype, function: str | None = None) -> str:
    """The expected kernel signature, for messages and documentation."""
    args = ", ".join(p.declaration() for p in kernel_parameters(ctype))
    return f"__kernel void {function or ctype.kernel_function}({args})"


def group_parameters(group) -> list[KernelParam]:
    """The parameter list of a fused group's generated kernel (see
    gpucompgen.convention.group_parameters)."""
    return [_spelled(p) for p in _group_parameters(group)]


def group_constants(group) -> list[KernelParam]:
    """The members' parameters of a group's generated kernel, as build constants (see
    gpucompgen.convention.group_constants)."""
    return [_spelled(p) for p in _group_constants(group)]
