"""NVRTC through ctypes: compile CUDA C++ for an architecture without a driver or a GPU.

Used to check at build and test time that every .cu file the build writes compiles for
the architectures the boards have (sm_72 Xavier, sm_87 Orin, sm_90 H100...).  ctypes
loads one libnvrtc per path, so one process can compile with the CUDA 12 NVRTC that
JetPack 6 boards have and with the current one side by side (cuda.bindings binds a single
version).  The PyPI wheels put the libraries at nvidia/cuda_nvrtc/lib/libnvrtc.so.12
(``nvidia-cuda-nvrtc-cu12``) and nvidia/cu13/lib/libnvrtc.so.13 (``nvidia-cuda-nvrtc``).
"""

from __future__ import annotations

import ctypes
import glob
import os
import sys
from dataclasses import dataclass
from functools import cache

# Warnings that say nothing about generated kernels: old architectures deprecated (sm_72),
# variables a size line declares but a snippet does not use, OpenCL's fp64 pragma.
QUIET = (b"--diag-suppress=177,161",)
# OpenCL C contracts a * b + c into one fma only within an expression; the snippets that
# must round each operation (Filter2D's float32 output, the derivatives' float sums, which
# the CPU forms compute the same way in numpy) write them as separate statements.  NVRTC's
# default (--fmad=true) contracts across statements too: false keeps each statement's
# rounding, so that the CUDA kernel gives the OpenCL kernel's and the CPU form's bytes
# (an explicit fma() stays one).
ROUNDING = (b"--fmad=false",)


@dataclass(frozen=True)
class Compiled:
    ok: bool
    log: str
    cubin: bytes = b""


class Nvrtc:
    """One libnvrtc shared library."""

    def __init__(self, path: str):
        self.path = path
        self.lib = ctypes.CDLL(path)
        major, minor = ctypes.c_int(), ctypes.c_int()
        self.lib.nvrtcVersion(ctypes.byref(major), ctypes.byref(minor))
        self.version = (major.value, minor.value)
        self.lib.nvrtcGetErrorString.restype = ctypes.c_char_p

    def __repr__(self) -> str:
        return f"NVRTC {self.version[0]}.{self.version[1]} ({self.path})"

    def architectures(self) -> list[int]:
        """The sm_XY numbers this NVRTC can compile for (XY as an integer)."""
        n = ctypes.c_int()
        if self.lib.nvrtcGetNumSupportedArchs(ctypes.byref(n)) != 0:
            return []
        archs = (ctypes.c_int * n.value)()
        self.lib.nvrtcGetSupportedArchs(archs)
        return list(archs)

    def compile(self, source: str, name: str, arch: int,
                options: tuple[str, ...] = ()) -> Compiled:
        """source compiled to a cubin for sm_<arch> (or the log of why not)."""
        lib = self.lib
        prog = ctypes.c_void_p()
        rc = lib.nvrtcCreateProgram(ctypes.byref(prog), source.encode(), name.encode(), 0,
                                    None, None)
        if rc:
            return Compiled(False, lib.nvrtcGetErrorString(rc).decode())
        try:
            opts = [f"--gpu-architecture=sm_{arch}".encode(), b"-std=c++17", *QUIET, *ROUNDING,
                    *(o.encode() for o in options)]
            array = (ctypes.c_char_p * len(opts))(*opts)
            rc = lib.nvrtcCompileProgram(prog, len(opts), array)
            size = ctypes.c_size_t()
            lib.nvrtcGetProgramLogSize(prog, ctypes.byref(size))
            buf = ctypes.create_string_buffer(size.value)
            lib.nvrtcGetProgramLog(prog, buf)
            log = buf.value.decode("utf-8", "replace").strip()
            if rc:
                return Compiled(False, log or lib.nvrtcGetErrorString(rc).decode())
            lib.nvrtcGetCUBINSize(prog, ctypes.byref(size))
            cubin = ctypes.create_string_buffer(size.value)
            lib.nvrtcGetCUBIN(prog, cubin)
            return Compiled(True, log, cubin.raw)
        finally:
            lib.nvrtcDestroyProgram(ctypes.byref(prog))


def _candidates() -> list[str]:
    """libnvrtc shared libraries installed by the PyPI wheels, then the CUDA toolkit's."""
    found = []
    for base in sys.path:
        found += glob.glob(os.path.join(base, "nvidia", "cuda_nvrtc", "lib", "libnvrtc.so.*"))
        found += glob.glob(os.path.join(base, "nvidia", "cu*", "lib", "libnvrtc.so.*"))
    for home in (os.environ.get("CUDA_HOME", ""), "/usr/local/cuda"):
        if home:
            found += glob.glob(os.path.join(home, "lib64", "libnvrtc.so.*"))
    return [p for p in dict.fromkeys(found) if "alt" not in os.path.basename(p)
            and "builtins" not in os.path.basename(p)]


@cache
def available() -> dict[int, Nvrtc]:
    """The NVRTC libraries that load, by major version (one each, the first found)."""
    libraries: dict[int, Nvrtc] = {}
    for path in _candidates():
        try:
            lib = Nvrtc(path)
        except OSError:
            continue
        libraries.setdefault(lib.version[0], lib)
    return libraries
