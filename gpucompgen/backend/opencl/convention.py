"""The kernel calling convention: the one declaration of a kernel's parameter list.

A GPU-aware component's kernel takes, in this order:

1. one ``__global`` pointer per input port, then one per output port, of the port's
   element type (inputs may be ``const``);
2. for every port in the same order, its height then its width, as ``int``;
3. every parameter of the type in declaration order: ``float`` for float parameters,
   ``int`` for int and bool parameters;
4. ``int tile``: the tile the system chose (pixels, or rows, one work-group covers).

The generated program sets its arguments from this list, the ``check`` command compares a
user's kernel with it, and the benchmark's hand-written variant follows it: nothing else
restates the order.
"""

from __future__ import annotations

from dataclasses import dataclass

# element type -> (OpenCL C type, numpy scalar type)
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
PARAM_C_TYPES = {"int": ("int", "np.int32"), "bool": ("int", "np.int32"),
                 "float": ("float", "np.float32")}


@dataclass(frozen=True)
class KernelParam:
    """One parameter of a kernel, as the convention requires it."""

    name: str  # the conventional name (the kernel may call it anything)
    kind: str  # "buffer" | "scalar"
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


def kernel_parameters(ctype) -> list[KernelParam]:
    """The parameter list a GPU-aware component type's kernel must have."""
    params: list[KernelParam] = []
    for role, ports in (("input", ctype.inputs), ("output", ctype.outputs)):
        for name, port in ports.items():
            params.append(KernelParam(name, "buffer", C_TYPES[port.dtype], role, port=name))
    for ports in (ctype.inputs, ctype.outputs):
        for name in ports:
            for dim in ("height", "width"):
                params.append(KernelParam(f"{name}_{dim}", "scalar", "int", "size",
                                          port=name, dim=dim))
    for name, decl in ctype.params.items():
        if decl.shape:  # an array parameter: a constant table of the generated kernel
            continue
        params.append(KernelParam(name, "scalar", PARAM_C_TYPES[decl.type][0], "param",
                                  param=name))
    params.append(KernelParam("tile", "scalar", "int", "tile"))
    return params


def signature_text(ctype, function: str | None = None) -> str:
    """The expected kernel signature, for messages and documentation."""
    args = ", ".join(p.declaration() for p in kernel_parameters(ctype))
    return f"__kernel void {function or ctype.kernel_function}({args})"


def group_parameters(group) -> list[KernelParam]:
    """The parameter list of a fused group's generated kernel (passes/fuse.py).

    1. one ``__global`` pointer per group input (named <member>_<port>, the member input
       it feeds), then the group's output (named <root>_<port>);
    2. every member's parameters in declaration order, named <member>_<parameter>, but
       array parameters, which the kernel's source holds as ``__constant`` tables;
    3. ``int tile``.

    No sizes: the system fixed every port's size when it was built, and the generated
    kernel states them as constants, so that the compiler folds composed index maps
    (``h - 1 - (h - 1 - y)`` is ``y``) and drops tests that cannot fail.
    """
    params: list[KernelParam] = []
    for name, port in group.inputs.items():
        params.append(KernelParam(name, "buffer", C_TYPES[port.dtype], "input", port=name))
    for name, port in group.outputs.items():
        params.append(KernelParam(f"{group.root.name}_{name}", "buffer", C_TYPES[port.dtype],
                                  "output", port=name))
    for m in group.members:
        for pname, decl in m.type.params.items():
            if decl.shape:  # an array: a __constant table in the kernel's source
                continue
            params.append(KernelParam(f"{m.name}_{pname}", "scalar",
                                      PARAM_C_TYPES[decl.type][0], "param",
                                      param=f"{m.name}.{pname}"))
    params.append(KernelParam("tile", "scalar", "int", "tile"))
    return params
