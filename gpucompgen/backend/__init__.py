"""Backends: everything specific to one way of running kernels, picked by name.

    opencl/  pyopencl host code, OpenCL C kernels (the default)
    cuda/    cuda-python host code, the same kernels as CUDA C++ under a prelude

Each backend package has a ``render`` module with ``render(system, source, model_dir)``;
``renderer(name)`` imports the one asked for, so nothing generic imports a backend.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

BACKENDS = ("opencl", "cuda")
DEFAULT = "opencl"


def renderer(name: str | None) -> Callable:
    """The render function of backend `name` (None: the default)."""
    name = name or DEFAULT
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r} (one of {', '.join(BACKENDS)})")
    return importlib.import_module(f"{__name__}.{name}.render").render


def device_query(name: str | None) -> Callable | None:
    """What ``--device auto`` asks for backend `name`: a function returning DeviceFacts
    (None: the OpenCL device, gpucompgen.device's default)."""
    if (name or DEFAULT) == "cuda":
        return importlib.import_module("gpucompgen.runtime.cuda").device_facts
    return None
