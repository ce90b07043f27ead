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
kernel language (c_convention.py: ``uchar``, ``int``...).  Nothing else
restates the order.
"""

from __future__ import annotations

from dataclasses import dataclass

# a parameter's value as a C literal: the generator writes a kernel's default constants
# with it, the runtime its -D build options, so both give the same float32
from .runtime.programs import c_literal  # noqa: F401  (re-exported for the backends)

# parameter type -> the element type the host passes (numpy's name)
HOST_TYPES = {"int": "int32", "bool": "int32", "float": "float32"}


@dataclass(frozen=True)
class Param:
    """One parameter of a kernel, as the convention requires it."""

    name: str  # the conventional name (the kernel may call it anything)
    kind: str  # "buffer" | "scalar" | "constant" (a build option: group_constants)
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
        if decl.shape:  # an array parameter: a constant table of the generated kernel
            continue
        params.append(Param(name, "scalar", HOST_TYPES[decl.type], "param", param=name))
    params.append(Param("tile", "scalar", "int32", "tile"))
    return params


def group_parameters(group) -> list[Param]:
    """The parameter list of a fused group's generated kernel (passes/fuse.py).

    1. one pointer per group input (named <member>_<port>, the member input it feeds),
       then the group's output (named <root>_<port>);
    2. ``tile``.

    No sizes and no parameters: the system fixed every port's size when it was built, and
    every member's parameter when the program starts (its model value, or --set's), so the
    generated kernel states sizes as constants and takes parameters as build options
    (group_constants): the compiler folds composed index maps (``h - 1 - (h - 1 - y)`` is
    ``y``), drops tests that cannot fail and picks a rule (Threshold's ``thresh_type``)
    once, not per element.
    """
    params: list[Param] = []
    for name, port in group.inputs.items():
        params.append(Param(name, "buffer", port.dtype, "input", port=name))
    for name, port in group.outputs.items():
        params.append(Param(f"{group.root.name}_{name}", "buffer", port.dtype, "output",
                            port=name))
    params.append(Param("tile", "scalar", "int32", "tile"))
    return params


def group_constants(group) -> list[Param]:
    """The members' parameters of a group's generated kernel, in member order then
    declaration order: constants of the kernel's build, set as build options (-D) when the
    program starts.  Each is the macro _m<i>_<parameter> for the group's i-th member (the
    generator's own namespace: model names start with a letter).  Not the parameters of a
    stencil's radius: the kernel writes its window as a literal (fixed at build time, like
    the sizes); nor array parameters, which the kernel's source holds as __constant tables."""
    return [Param(f"_m{i}_{pname}", "constant", HOST_TYPES[decl.type], "param",
                  param=f"{m.name}.{pname}")
            for i, m in enumerate(group.members) for pname, decl in m.type.params.items()
            if pname not in m.type.fusable.radius_names() and not decl.shape]
