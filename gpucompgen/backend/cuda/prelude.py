"""The CUDA prelude: OpenCL C's neutral names for CUDA C++, and the kernel text's check.

The kernels gpucompgen writes (library kernels, single-operation and fused-group kernels)
and the kernels of user types are written in a portable subset of OpenCL C: scalar code,
``__kernel``/``__global`` qualifiers, work-item functions, OpenCV-style saturating
conversions.  A small prelude maps those names to CUDA (as each of Halide's device
printers writes one in ``init_module()``), so one kernel source serves both backends; the
few OpenCL-only idioms that have no such mapping are reported with what to write instead.

What the prelude maps:
- ``__kernel`` -> ``extern "C" __global__`` (C names, so a launch finds the function by
  the name the program gives); ``__global``, ``__constant`` on pointers -> nothing;
  ``inline`` functions (after the prelude) -> ``__device__ inline``; ``restrict`` -> ``__restrict__``.
- ``uchar``, ``ushort``, ``uint``, ``ulong`` -> the unsigned C types.
- ``get_global_id(d)``, ``get_local_id``, ``get_group_id``, ``get_local_size``,
  ``get_num_groups``, ``get_global_size`` -> blockIdx, blockDim, threadIdx, gridDim
  (a launch's grid is OpenCL's global size / local size, its block the local size).
- ``clamp``, ``mad24``, ``mul24``, ``as_int``, ``as_float`` (of float and int),
  ``convert_uchar_sat``, ``convert_uchar_sat_rte``,
  ``vstore2/3/4`` and ``vload2/3/4`` -> ``__device__`` functions with OpenCL's results.
- Vector literals ``(uchar3)(a, b, c)`` and ``(int2)(v)`` -> ``make_uchar3(a, b, c)``,
  ``make_int2(v)`` (a textual rewrite of the literal's opening, see ``translate``; the
  one-value forms are overloads defined here).
- ``cl_khr_fp64`` is defined (CUDA devices have doubles).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_VECTOR_SCALARS = ("char", "uchar", "short", "ushort", "int", "uint", "float")
_CUDA_SCALAR = {"uchar": "unsigned char", "ushort": "unsigned short", "uint": "unsigned int",
                "ulong": "unsigned long"}


def _vector_helpers() -> list[str]:
    """One-value vector constructors (OpenCL's splat) and vloadN / vstoreN."""
    fields = "xyzw"
    lines = []
    for t in _VECTOR_SCALARS:
        for n in (2, 3, 4):
            splat = ", ".join(["v"] * n)
            lines.append(f"__device__ inline {t}{n} make_{t}{n}(const {t} v) "
                         f"{{ return make_{t}{n}({splat}); }}")
            stores = " ".join(f"p[{n} * i + {k}] = v.{fields[k]};" for k in range(n))
            lines.append(f"__device__ inline void vstore{n}(const {t}{n} v, const size_t i, "
                         f"{t} *p) {{ {stores} }}")
            loads = ", ".join(f"p[{n} * i + {k}]" for k in range(n))
            lines.append(f"__device__ inline {t}{n} vload{n}(const size_t i, const {t} *p) "
                         f"{{ return make_{t}{n}({loads}); }}")
    return lines


def _work_item(name: str, expr: str) -> str:
    return (f"__device__ inline size_t {name}(const unsigned d) "
            f"{{ return d == 0 ? {expr.format(c='x')} : d == 1 ? {expr.format(c='y')} : "
            f"d == 2 ? {expr.format(c='z')} : 0; }}")


def _saturating() -> list[str]:
    lines = []
    for t in ("int", "unsigned int", "long", "float", "double"):
        low = "v < 0" if t != "unsigned int" else "false"
        lines.append(f"__device__ inline uchar convert_uchar_sat(const {t} v) "
                     f"{{ return {low} ? 0 : v > 255 ? 255 : (uchar)v; }}")
    lines += [
        # round to nearest even, then saturate; NaN converts to 0 (as OpenCL's sat)
        "__device__ inline uchar convert_uchar_sat_rte(float v)",
        "{ v = v >= 0.0f ? v : 0.0f; return (uchar)rintf(v <= 255.0f ? v : 255.0f); }",
        "__device__ inline uchar convert_uchar_sat_rte(double v)",
        "{ v = v >= 0.0 ? v : 0.0; return (uchar)rint(v <= 255.0 ? v : 255.0); }",
    ]
    return lines


def _clamps() -> list[str]:
    return [f"__device__ inline {t} clamp(const {t} v, const {t} lo, const {t} hi) "
            "{ return v < lo ? lo : v > hi ? hi : v; }"
            for t in ("int", "unsigned int", "long", "float", "double")]


PRELUDE_LINES = [
    "// gpucompgen's CUDA prelude: the portable subset of OpenCL C the kernels are",
    "// written in, mapped to CUDA C++ (see gpucompgen/backend/cuda/prelude.py).",
    "#define __kernel extern \"C\" __global__",
    "#define __global",
    "#define __constant",
    "#define restrict __restrict__",
    "#define overloadable",  # OpenCL C's overloading attribute: C++ overloads anyway
    "#define cl_khr_fp64 1",
    *[f"typedef {c} {t};" for t, c in _CUDA_SCALAR.items()],
    _work_item("get_local_id", "threadIdx.{c}"),
    _work_item("get_group_id", "blockIdx.{c}"),
    _work_item("get_local_size", "blockDim.{c}"),
    _work_item("get_num_groups", "gridDim.{c}"),
    _work_item("get_global_id", "(size_t)blockIdx.{c} * blockDim.{c} + threadIdx.{c}"),
    _work_item("get_global_size", "(size_t)gridDim.{c} * blockDim.{c}"),
    "__device__ inline int mad24(const int a, const int b, const int c) { return a * b + c; }",
    ("__device__ inline unsigned int mad24(const unsigned int a, const unsigned int b, "
    "const unsigned int c) { return a * b + c; }"),
    "__device__ inline int mul24(const int a, const int b) { return a * b; }",
    # a float's bits as an int and back (a snippet may call them: Blur's float32 mean)
    "__device__ inline int as_int(const float v) { return __float_as_int(v); }",
    "__device__ inline float as_float(const int v) { return __int_as_float(v); }",
    *_clamps(),
    *_saturating(),
    *_vector_helpers(),
    "#define inline __device__ inline",
    "// end of the prelude; the kernel follows as written",
]
PRELUDE = "\n".join(PRELUDE_LINES) + "\n"

_FILE_CONSTANT = re.compile(r"^__constant\b", re.MULTILINE)
_VECTOR_LITERAL = re.compile(
    r"\(\s*(" + "|".join(_VECTOR_SCALARS) + r")([234])\s*\)\s*\(")
# Constructs of OpenCL C with no CUDA mapping in the prelude, and what to write instead.
_UNPORTABLE = [
    (re.compile(r"\b(__local|local)\b(?=\s+\w)"),
     "local (shared) memory", ("keep per-thread values in registers, or leave the type on "
     "the OpenCL backend")),
    (re.compile(r"\b(barrier|mem_fence|work_group_barrier)\s*\("),
     "work-group barriers", "write kernels whose threads do not wait for each other"),
    (re.compile(r"\b(image[123]d\w*_t|sampler_t|read_image\w*|write_image\w*)\b"),
     "OpenCL images and samplers", "read and write __global buffers with computed indices"),
    (re.compile(r"\b(atomic_\w+|atom_\w+)\s*\("), "OpenCL atomics",
     "write each output element from one thread"),
    (re.compile(r"\b(vload|vstore)(8|16)\b"), "8- and 16-wide vector loads and stores",
     "store the elements one by one, or with vstore2/3/4"),
    (re.compile(r"\b(convert_\w+)\s*\("), "OpenCL conversion functions",
     "use a cast, or convert_uchar_sat / convert_uchar_sat_rte"),
    (re.compile(r"\.(s[0-9a-fA-F]{1,16}|lo|hi|even|odd|[xyzw]{2,4})\b"),
     "vector swizzles", "read the components one by one (.x, .y, .z, .w)"),
    (re.compile(r"#\s*pragma\s+OPENCL\s+EXTENSION\s+(?!cl_khr_fp64)"),
     "OpenCL extensions", "write the kernel without the extension"),
]
_ALLOWED_CONVERSIONS = {"convert_uchar_sat", "convert_uchar_sat_rte"}
_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.DOTALL)


@dataclass(frozen=True)
class Unportable:
    """An OpenCL-only construct in a kernel: where (1-based line and column), what, and
    what to write instead."""

    line: int
    column: int
    what: str
    hint: str
    text: str


def _blank_comments(source: str) -> str:
    """The source with comments blanked out (same length and line breaks)."""
    return _COMMENT.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), source)


def unportable(source: str) -> list[Unportable]:
    """Every OpenCL-only construct of the kernel text, in order (comments ignored)."""
    code = _blank_comments(source)
    found = []
    for pattern, what, hint in _UNPORTABLE:
        for m in pattern.finditer(code):
            if what.startswith("OpenCL conversion") and m.group(1) in _ALLOWED_CONVERSIONS:
                continue
            line = code.count("\n", 0, m.start()) + 1
            column = m.start() - (code.rfind("\n", 0, m.start()) + 1) + 1
            found.append(Unportable(line, column, what, hint, m.group(0).strip()))
    return sorted(found, key=lambda u: (u.line, u.column))


def translate(source: str) -> str:
    """The kernel text as CUDA C++ under the prelude: vector literals, each ``(T n)(``
    opening becoming ``make_Tn(`` (the parentheses stay balanced), and tables declared
    ``__constant`` at file scope (a line's first word) becoming ``__constant__`` (CUDA's
    constant memory; elsewhere ``__constant`` qualifies a pointer and means nothing).
    Lines keep their numbers, so compiler messages point at the kernel as written."""
    source = _FILE_CONSTANT.sub("__constant__", source)
    return _VECTOR_LITERAL.sub(lambda m: f"make_{m.group(1)}{m.group(2)}(", source)


def cuda_source(kernel_text: str) -> str:
    """A .cu file's text: the prelude, a #line directive, then the translated kernel."""
    return PRELUDE + "#line 1\n" + translate(kernel_text)
