"""Backends: everything specific to one way of running kernels, picked by name.

    opencl/  Python host code over OpenCL, OpenCL C kernels (the default)
    cuda/    cuda-python host code, the same kernels as CUDA C++ under a prelude

Each backend package has a ``render`` module with ``render(system, source, model_dir)``
and may have a ``reserved`` module (``WORDS``: its kernel language's reserved words, which
no model name may take; ``MODULES``: the modules its generated programs import, which no
system may be named after).  The functions here import the backend asked for by name, so
nothing generic imports a backend (tests/test_architecture.py checks it).
"""

from __future__ import annotations

import functools
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


# The runtime module a backend's generated programs import
RUNTIMES = {"opencl": "gpucompgen.runtime", "cuda": "gpucompgen.runtime.cuda"}


def runtime_module(name: str | None):
    """The runtime module of backend `name` (ImportError without its device API)."""
    return importlib.import_module(RUNTIMES[name or DEFAULT])


def kernel_text(name: str | None, text: str) -> tuple[str, str]:
    """(suffix, text) of the kernel file backend `name` writes for a kernel file's text
    (OpenCL C in the portable subset): as it is for OpenCL, under the prelude for CUDA;
    what `tune` and `bench` build through the device interface."""
    if (name or DEFAULT) == "cuda":
        module = importlib.import_module(f"{__name__}.cuda.render")
        return module.KERNEL_SUFFIX, module.cuda_kernel_file(text)
    return ".cl", text


def device_query(name: str | None) -> Callable | None:
    """What ``--device auto`` asks for backend `name`: a function returning DeviceFacts
    (None: the OpenCL device, gpucompgen.device's default)."""
    if (name or DEFAULT) == "cuda":
        return runtime_module("cuda").device_facts
    return None


@functools.cache
def _reserved(attribute: str) -> frozenset[str]:
    names: set[str] = set()
    for name in BACKENDS:
        try:
            module = importlib.import_module(f"{__name__}.{name}.reserved")
        except ModuleNotFoundError:
            continue
        names |= getattr(module, attribute, frozenset())
    return frozenset(names)


def reserved_words() -> frozenset[str]:
    """Every backend's kernel-language reserved words: a model builds for any backend."""
    return _reserved("WORDS")


def module_names() -> frozenset[str]:
    """The modules every backend's generated programs (and their runtime) import."""
    return _reserved("MODULES")


def signature_checker(language: str = "opencl"):
    """(check, SignatureError) of the kernel language that type files' kernel files are
    written in: check(ctype, text, function) raises SignatureError where the kernel's
    definition does not take what the calling convention passes."""
    module = importlib.import_module(f"{__name__}.{language}.signature")
    return module.check, module.SignatureError
