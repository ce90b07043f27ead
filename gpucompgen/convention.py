"""The kernel calling convention: the one declaration of a kernel's parameter list.

A GPU-aware component's kernel takes, in this order:

1. one pointer to global memory per input port, then one per output port, of the port's
   element type (inputs may be ``const``);
2. for every port in the same order, its height then its width, as 32-bit ints;
3. every parameter of the type in declaration order: float32 for float parameters,
   int32 for int and bool parameters;
4. ``tile`` (int32): the tile the system chose (pixels, or rows, one work-group covers).

The order and the element types are the same for every backend: lowering sets a launch's
arguments from this list (passes/lower.py), and each backend spells the types in its own
kernel language (backend/opencl/convention.py: ``uchar``, ``int``...).  Nothing else
restates the order.
"""

from __future__ import annotations

from dataclasses import dataclass

# parameter type -> the element type the host passes (numpy's name)
HOST_TYPES = {"int": "int32", "bool": "int32", "float": "float32"}


@dataclass(frozen=True)
class Param:
    """One parameter of a kernel, as the convention requires it."""

    name: str  # the conventional name (the kernel may call it anything)
    kind: str  # "buffer" | "scalar"
    dtype: str  # element type of a buffer, or the scalar's (numpy's name: "uint8", "int32")
    role: str  # "input" | "output" | "size" | "param" | "tile"
    port: str = ""  # the port a buffer or size belongs to
    dim: str = ""  # "height" | "width" for sizes
    param: str = ""  # the model parameter a scalar carries


def kernel_parameters(ctype) -> list[Param]:
    """The parameter list a GPU-aware component type's kernel must have."""
    params: list[Param] = []
    for role, ports in (("input", ctype.inputs), ("output", ctype.outputs)):
        for name, port in ports.items():
            params.append(Param(name, "buffer", port.dtype, role, port=name))
    for ports in (ctype.inputs, ctype.outputs):
        for name in ports:
            for dim in ("height", "width"):
                params.append(Param(f"{name}_{dim}", "scalar", "int32", "size",
                                    port=name, dim=dim))
    for name, decl in ctype.params.items():
        params.append(Param(name, "scalar", HOST_TYPES[decl.type], "param", param=name))
    params.append(Param("tile", "scalar", "int32", "tile"))
    return params


def group_parameters(group) -> list[Param]:
    """The parameter list of a fused group's generated kernel (passes/fuse.py).

    1. one pointer per group input (named <member>_<port>, the member input it feeds),
       then the group's output (named <root>_<port>);
    2. every member's parameters in declaration order, named <member>_<parameter>;
    3. ``tile``.

    No sizes: the system fixed every port's size when it was built, and the generated
    kernel states them as constants, so that the compiler folds composed index maps
    (``h - 1 - (h - 1 - y)`` is ``y``) and drops tests that cannot fail.
    """
    params: list[Param] = []
    for name, port in group.inputs.items():
        params.append(Param(name, "buffer", port.dtype, "input", port=name))
    for name, port in group.outputs.items():
        params.append(Param(f"{group.root.name}_{name}", "buffer", port.dtype, "output",
                            port=name))
    for m in group.members:
        for pname, decl in m.type.params.items():
            params.append(Param(f"{m.name}_{pname}", "scalar", HOST_TYPES[decl.type], "param",
                                param=f"{m.name}.{pname}"))
    params.append(Param("tile", "scalar", "int32", "tile"))
    return params
