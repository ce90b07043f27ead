"""The device interface: what the runtime's neutral core asks of a device API.

One module per API implements it: ``runtime/opencl.py`` (OpenCL) and
``runtime/cuda.py`` (cuda-python; its generated programs' classes are built on the same
functions).  The adapters, kernel components, ``gpucompgen tune`` and ``gpucompgen
bench`` call only these functions, so they never import a device API's package
(tests/test_architecture.py checks it; tests/test_cuda_interface.py that both modules
declare every function with compatible parameters).  A module is picked by name, as
backends are (``get``), or by one of its contexts (``of``); contexts, queues, buffers,
programs, kernels and events are the API's own objects, which the core only passes back.
Kernel text handed to ``build_source`` is in the API's own language (CUDA C++ for CUDA:
gpucompgen.backend.kernel_text writes it from the portable subset).

Events: any object with ``wait()`` and ``profile.start`` / ``profile.end`` (nanoseconds,
on a queue made with profiling), which is what runtime.Profile and --trace read.
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol

DEFAULT = "opencl"
NAMES = ("opencl", "cuda")  # the device API modules, named as the backends that use them


class DeviceAPI(Protocol):
    """The functions a device API's module provides (module-level functions)."""

    # device facts and selection
    def select_device(self) -> Any: ...
    def create_context(self) -> Any: ...
    def context_device(self, context: Any) -> Any: ...
    def device_name(self, device: Any) -> str: ...
    def create_queue(self, context: Any, profile: bool = False) -> Any: ...
    def side_queue(self, queue: Any) -> Any: ...  # another queue on the queue's device
    def device_of(self, queue: Any) -> Any: ...
    def facts(self, device: Any) -> Any: ...  # runtime.facts.DeviceFacts
    def kernel_limits(self, kernel: Any, device: Any) -> Any: ...  # devices.KernelLimits
    def check_work_group(self, kernel: Any, device: Any, local_size: Any, component: str,
                         settings_source: str = "") -> Any: ...
    # memory: device, pinned (page-locked host, mapped once), host-visible
    def device_buffer(self, context: Any, nbytes: int, access: str = "read_write",
                      host_visible: bool = False) -> Any: ...
    def host_buffer(self, context: Any, array: Any, access: str = "read") -> Any: ...
    def pinned(self, context: Any, queue: Any, shape: Any, dtype: Any) -> tuple: ...
    def release_pinned(self, queue: Any, pinned_arrays: list) -> None: ...
    def release(self, buffer: Any) -> None: ...
    def nbytes(self, buffer: Any) -> int: ...
    def filled_buffer(self, context: Any, array: Any) -> Any: ...  # a copy of the array
    # copies both ways (host array <-> buffer, buffer -> buffer), map and unmap
    def copy(self, queue: Any, dst: Any, src: Any, blocking: bool = True,
             wait_for: Any = None) -> Any: ...
    def map(self, queue: Any, buffer: Any, shape: Any, dtype: Any, mode: str = "read",
            wait_for: Any = None) -> tuple: ...  # (view, event), blocking
    def unmap(self, queue: Any, view: Any) -> Any: ...  # event
    def fill(self, queue: Any, buffer: Any, byte: int, nbytes: int) -> Any: ...
    def finish(self, queue: Any) -> None: ...
    # programs and launches
    def build_program(self, context: Any, path: Any, component: str,
                      options: tuple[str, ...] = (), defines: Any = None) -> Any: ...
    def build_source(self, context: Any, source: str) -> Any: ...
    def kernel(self, program: Any, function: str) -> Any: ...
    def set_args(self, kernel: Any, *args: Any) -> None: ...
    def launch(self, queue: Any, kernel: Any, global_size: Any, local_size: Any,
               wait_for: Any = None) -> Any: ...  # event
    def launcher(self) -> Any: ...  # launch itself, looked up once for a hot loop
    # events
    def wait(self, events: Any) -> None: ...
    def event_seconds(self, event: Any) -> float: ...
    def is_running(self, event: Any) -> bool: ...
    # for messages and for other libraries in the process
    NAME: str  # the name of the binding it uses, in messages
    def api_frames(self, module: str) -> bool: ...  # a Python module of the binding
    def load(self) -> Any: ...
    def loader_library(self) -> str | None: ...


def get(name: str | None = None) -> Any:
    """The device API module `name` (default: OpenCL, what ``from gpucompgen import
    runtime`` programs use).  A missing binding (OpenCL's or cuda-python) is reported by
    its functions, not here: importing the module needs nothing but the core."""
    name = name or DEFAULT
    if name not in NAMES:
        raise ValueError(f"unknown device API {name!r} (one of {', '.join(NAMES)})")
    return importlib.import_module(f"{__package__}.{name}")


def of(context: Any) -> Any:
    """The device API module that made `context` (a CUDA context is the CUDA module's own
    class; anything else is the default API's)."""
    module = type(context).__module__
    for name in NAMES:
        if module == f"{__package__}.{name}":
            return get(name)
    return get()


def name_of(api: Any) -> str:
    """The name of a device API module ("opencl", "cuda")."""
    return api.__name__.rsplit(".", 1)[-1]
