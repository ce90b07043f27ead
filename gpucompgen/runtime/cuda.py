"""The runtime of programs built with ``--backend cuda``: the same names, driving CUDA.

A CUDA program imports ``from gpucompgen.runtime import cuda as runtime`` and calls the
names an OpenCL program calls (create_context, create_queue, check_device_memory,
build_program, KernelComponent, the adapters, Profile...); what is not device-specific
(sizes, parts, failures, the command line, frames in flight) is the neutral runtime's,
re-exported here.  It uses NVIDIA's cuda-python (``cuda.bindings``: the driver API and
NVRTC), installed with ``pip install gpucompgen[cuda]``.

How the OpenCL model maps:
- context: the device's primary CUDA context (CUDA_DEVICE selects the device, default 0);
- queue (one per lane): a non-blocking CUDA stream; an event of another lane's command
  is waited for with cuStreamWaitEvent, the host waits with cuEventSynchronize;
- a kernel file: NVRTC compiles it to a cubin for the device's exact architecture
  (sm_XY), cached on disk under the source's digest, the architecture and NVRTC's
  version (``$XDG_CACHE_HOME/gpucompgen/cuda``); no PTX is left for the driver to JIT;
- a launch: grid = global size / local size, block = local size (the plan's numbers);
  arguments are packed once per buffer set, only changed input pointers are rewritten;
- buffers: cuMemAlloc once at initialize; pinned staging with cuMemHostAlloc;
  zero-copy (integrated GPUs, Jetson): mapped pinned host memory (cuMemHostAlloc with
  DEVICEMAP) that the kernel reads or writes through its device pointer.  Managed memory
  is not used (on Orin, host access while a kernel runs faults).
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import threading
from collections import deque
from pathlib import Path
from typing import Any

from . import adapters
from .cli import add_program_options, main
from .components import CpuFunctionComponent
from .devices import check_device_memory
from .errors import PipelineError, Stopped
from .facts import DeviceFacts
from .frames import check_frame
from .lifecycle import (
    Parts,
    Result,
    component_failure,
    expect_size,
    failing_component,
    free_all,
    load_class,
    load_function,
    load_module,
    model_path,
)
from .monitor import Monitor
from .overrides import Param, param_values
from .pipeline import FrameFailure, stream_in_flight
from .profiling import Profile
from .programs import clean_build_log, define_options, read_kernel_file
from .sizes import Size

__all__ = [
    "CpuFunctionComponent", "CpuToGpuAdapter", "FrameFailure", "GpuToCpuAdapter",
    "KernelComponent", "Monitor", "Param", "Parts", "PipelineError", "Profile", "Result",
    "Size", "Stopped", "ZeroCopyCpuToGpuAdapter", "ZeroCopyGpuToCpuAdapter",
    "add_program_options", "build_program", "check_device_memory", "check_frame",
    "component_failure", "create_context", "create_queue", "device_facts", "expect_size",
    "failing_component", "free_all", "load_class", "load_function", "load_module", "main",
    "model_path", "param_values", "stream_in_flight", "survey_devices", "wait_for_events",
]

MISSING = ("the CUDA backend needs NVIDIA's cuda-python: pip install 'gpucompgen[cuda]' "
           "(cuda-bindings matching the driver's CUDA major, and an NVRTC: on x86 "
           "nvidia-cuda-nvrtc, on Jetson the JetPack CUDA toolkit); see docs/cuda.md")


def _driver():
    try:
        from cuda.bindings import driver
    except ImportError:
        try:
            from cuda import cuda as driver  # cuda-python 11.x / 12.0-12.5
        except ImportError:
            raise PipelineError(MISSING) from None
    return driver


def _nvrtc():
    try:
        from cuda.bindings import nvrtc
    except ImportError:
        try:
            from cuda import nvrtc
        except ImportError:
            raise PipelineError(MISSING) from None
    return nvrtc


def _ok(result, what: str):
    """A cuda-python call's (error, values...) as its values, or a PipelineError."""
    cu = _driver()
    err, *values = result if isinstance(result, tuple) else (result,)
    if int(err) != 0:
        name = getattr(err, "name", str(err))
        with_text = ""
        with contextlib.suppress(Exception):  # the name alone is still a message
            e2, text = cu.cuGetErrorString(err)
            if int(e2) == 0 and text:
                with_text = f": {text.decode() if isinstance(text, bytes) else text}"
        raise PipelineError(f"CUDA {what} failed ({name}{with_text})")
    if not values:
        return None
    return values[0] if len(values) == 1 else tuple(values)


# --- devices -------------------------------------------------------------------------

_INIT = threading.Lock()
_initialized = False


def _init():
    global _initialized
    cu = _driver()
    with _INIT:
        if not _initialized:
            try:
                result = cu.cuInit(0)
            except Exception as exc:  # no libcuda: cuda-python raises its own error
                raise PipelineError(f"no NVIDIA driver ({type(exc).__name__}: {exc}); the "
                                    "CUDA backend needs an NVIDIA GPU and its driver") \
                    from None
            _ok(result, "initialization (is an NVIDIA driver installed?)")
            _initialized = True
    return cu


def _attribute(device, name: str) -> int:
    cu = _driver()
    return int(_ok(cu.cuDeviceGetAttribute(getattr(cu.CUdevice_attribute,
                                                   f"CU_DEVICE_ATTRIBUTE_{name}"), device),
                   f"query {name}"))


class CudaDevice:
    """One CUDA device: its facts, under the attribute names the neutral checks read."""

    def __init__(self, ordinal: int):
        cu = _init()
        self.ordinal = ordinal
        self.handle = _ok(cu.cuDeviceGet(ordinal), f"device {ordinal}")
        raw = _ok(cu.cuDeviceGetName(256, self.handle), "device name")
        self.name = (raw.split(b"\0", 1)[0].decode() if isinstance(raw, bytes)
                     else str(raw)).strip()
        a = lambda n: _attribute(self.handle, n)
        self.compute_capability = (a("COMPUTE_CAPABILITY_MAJOR"), a("COMPUTE_CAPABILITY_MINOR"))
        self.arch = f"sm_{self.compute_capability[0]}{self.compute_capability[1]}"
        self.multiprocessors = a("MULTIPROCESSOR_COUNT")
        self.max_threads_per_block = a("MAX_THREADS_PER_BLOCK")
        self.max_block = (a("MAX_BLOCK_DIM_X"), a("MAX_BLOCK_DIM_Y"), a("MAX_BLOCK_DIM_Z"))
        self.max_threads_per_multiprocessor = a("MAX_THREADS_PER_MULTIPROCESSOR")
        self.shared_memory_per_block = a("MAX_SHARED_MEMORY_PER_BLOCK")
        self.integrated = bool(a("INTEGRATED"))
        self.can_map_host_memory = bool(a("CAN_MAP_HOST_MEMORY"))
        self.global_mem_size = int(_ok(cu.cuDeviceTotalMem(self.handle), "memory size"))
        # CUDA has no per-allocation limit below the device's memory
        self.max_mem_alloc_size = self.global_mem_size

    def facts(self) -> DeviceFacts:
        """The facts the generator plans for (an integrated GPU shares host memory)."""
        return DeviceFacts(
            name=self.name, compute_units=self.multiprocessors,
            max_work_group_size=self.max_threads_per_block,
            max_work_item_sizes=self.max_block,
            local_mem_size=self.shared_memory_per_block,
            global_mem_size=self.global_mem_size,
            max_mem_alloc_size=self.max_mem_alloc_size,
            host_unified_memory=self.integrated,
            threads_per_compute_unit=self.max_threads_per_multiprocessor,
            kind="integrated-gpu" if self.integrated else "discrete-gpu")

    def __repr__(self) -> str:
        return f"<CUDA device {self.ordinal}: {self.name} ({self.arch})>"


def device_facts(ordinal: int | None = None) -> DeviceFacts:
    """The facts of the CUDA device CUDA_DEVICE selects (default 0)."""
    return CudaDevice(_ordinal() if ordinal is None else ordinal).facts()


def survey_devices() -> list[tuple[int, str, str | None]]:
    """(ordinal, description, problem) for each CUDA device; [] without cuda-python or a
    driver.  A device is usable when its context opens."""
    try:
        cu = _init()
        count = int(_ok(cu.cuDeviceGetCount(), "device count"))
    except PipelineError:
        return []
    found = []
    for i in range(count):
        try:
            d = CudaDevice(i)
            text = (f"{d.name} ({d.arch}, {d.multiprocessors} SMs, "
                    f"{d.global_mem_size / 2**30:.1f} GiB"
                    f"{', integrated' if d.integrated else ''})")
            found.append((i, text, None))
        except PipelineError as exc:
            found.append((i, f"device {i}", str(exc)))
    return found


def _ordinal() -> int:
    text = os.environ.get("CUDA_DEVICE", "0")
    try:
        return int(text)
    except ValueError:
        raise PipelineError(f"CUDA_DEVICE={text!r} is not a device number; "
                            "'gpucompgen devices' lists the CUDA devices") from None


class CudaContext:
    """The device's primary context; .devices as an OpenCL context has them."""

    def __init__(self, device: CudaDevice):
        cu = _driver()
        self.device = device
        self.devices = [device]
        self.handle = _ok(cu.cuDevicePrimaryCtxRetain(device.handle), "context")
        self.current()
        # the time origin of profiled events (their start and end are read against it)
        self.origin = _ok(cu.cuEventCreate(0), "event")
        _ok(cu.cuEventRecord(self.origin, 0), "event record")
        _ok(cu.cuEventSynchronize(self.origin), "event wait")

    def current(self) -> None:
        """Make this context current in the calling thread (stages run in threads)."""
        _ok(_driver().cuCtxSetCurrent(self.handle), "context")


def create_context() -> CudaContext:
    """The context of the device CUDA_DEVICE selects (default 0)."""
    cu = _init()
    count = int(_ok(cu.cuDeviceGetCount(), "device count"))
    ordinal = _ordinal()
    if count == 0:
        raise PipelineError("no CUDA device found; " + MISSING)
    if not 0 <= ordinal < count:
        raise PipelineError(f"CUDA_DEVICE={ordinal} selects no device (there are {count}); "
                            "'gpucompgen devices' lists them")
    return CudaContext(CudaDevice(ordinal))


class CudaQueue:
    """One lane: a non-blocking stream (commands of other lanes only wait by events)."""

    def __init__(self, context: CudaContext, profile: bool = False):
        cu = _driver()
        context.current()
        self.context = context
        self.device = context.device
        self.profile = profile
        self.handle = _ok(cu.cuStreamCreate(1), "stream")  # CU_STREAM_NON_BLOCKING

    def wait_for(self, events) -> None:
        cu = _driver()
        for event in events or ():
            if isinstance(event, CudaEvent):
                _ok(cu.cuStreamWaitEvent(self.handle, event.end, 0), "stream wait")

    def finish(self) -> None:
        self.context.current()
        _ok(_driver().cuStreamSynchronize(self.handle), "stream synchronize")


def wait_for_events(events) -> None:
    """The host waits until these commands are done (the OpenCL runtime's wait_for_events)."""
    for event in events:
        if event is not None:
            event.wait()


def create_queue(context: CudaContext, profile: bool = False) -> CudaQueue:
    """A lane's stream; with profile, its commands are timed by event pairs."""
    return CudaQueue(context, profile)


class _Times:
    def __init__(self, start: int, end: int):
        self.start, self.end = start, end


class CudaEvent:
    """What a command left behind: an event recorded after it on its stream (and one
    before it when profiling).  .wait() and .profile.start/.end (ns), the device interface's events."""

    def __init__(self, queue: CudaQueue):
        cu = _driver()
        self.queue = queue
        self.command_queue = queue
        flags = 0 if queue.profile else 2  # CU_EVENT_DISABLE_TIMING: cheaper
        self.start = _ok(cu.cuEventCreate(flags), "event") if queue.profile else None
        self.end = _ok(cu.cuEventCreate(flags), "event")

    def before(self) -> None:
        if self.start is not None:
            _ok(_driver().cuEventRecord(self.start, self.queue.handle), "event record")

    def after(self) -> CudaEvent:
        _ok(_driver().cuEventRecord(self.end, self.queue.handle), "event record")
        return self

    def wait(self) -> None:
        self.queue.context.current()
        _ok(_driver().cuEventSynchronize(self.end), "event wait")

    @property
    def profile(self) -> _Times:
        cu = _driver()
        self.wait()
        elapsed = getattr(cu, "cuEventElapsedTime", None) or cu.cuEventElapsedTime_v2
        origin = self.queue.context.origin
        start = _ok(elapsed(origin, self.start), "event time")
        end = _ok(elapsed(origin, self.end), "event time")
        return _Times(int(start * 1e6), int(end * 1e6))

    def release(self) -> None:
        cu = _driver()
        for e in (self.start, self.end):
            if e is not None:
                cu.cuEventDestroy(e)
        self.start = self.end = None


class _Events:
    """A ring of events for one part on one queue: a command reuses the event of the
    command `size` commands before it, long done (its waiters captured it when they
    enqueued their waits)."""

    def __init__(self, queue: CudaQueue, size: int):
        self.queue, self.size = queue, max(size, 2)
        self.ring: deque[CudaEvent] = deque()

    def next(self) -> CudaEvent:
        if self.queue.profile or len(self.ring) < self.size:
            event = CudaEvent(self.queue)  # profiled events are read later: not reused
        else:
            event = self.ring.popleft()
        if not self.queue.profile:
            self.ring.append(event)
        return event

    def release(self) -> None:
        while self.ring:
            self.ring.popleft().release()


# --- memory --------------------------------------------------------------------------

class DeviceBuffer:
    """Device memory of `size` bytes at device address `ptr` (cuMemAlloc), or mapped
    pinned host memory (host is then its numpy view, the same bytes)."""

    def __init__(self, size: int, mapped: bool = False):
        cu = _driver()
        self.size = size
        self.host = None
        self._host_ptr = 0
        if mapped:
            # CU_MEMHOSTALLOC_PORTABLE | CU_MEMHOSTALLOC_DEVICEMAP
            self._host_ptr = int(_ok(cu.cuMemHostAlloc(max(size, 1), 1 | 2),
                                     f"mapped host allocation of {size:,} bytes"))
            self.ptr = int(_ok(cu.cuMemHostGetDevicePointer(self._host_ptr, 0),
                               "device pointer of mapped memory"))
        else:
            self.ptr = int(_ok(cu.cuMemAlloc(max(size, 1)),
                               f"device allocation of {size:,} bytes"))

    def view(self, shape, dtype):
        """The mapped host memory as a numpy array (mapped buffers only)."""
        return _host_array(self._host_ptr, shape, dtype)

    def release(self) -> None:
        cu = _driver()
        if self._host_ptr:
            cu.cuMemFreeHost(self._host_ptr)
        elif self.ptr:
            cu.cuMemFree(self.ptr)
        self.ptr = self._host_ptr = 0


def _host_array(address: int, shape, dtype):
    import numpy as np

    dtype = np.dtype(dtype)
    count = int(np.prod(shape))
    raw = (ctypes.c_ubyte * (count * dtype.itemsize)).from_address(address)
    return np.frombuffer(raw, dtype=dtype, count=count).reshape(shape)


class PinnedArray:
    """A page-locked host array (cuMemHostAlloc): copies from and to it run at DMA speed."""

    def __init__(self, shape, dtype, mapped: bool = False):
        import numpy as np

        cu = _driver()
        nbytes = max(int(np.prod(shape)) * np.dtype(dtype).itemsize, 1)
        self.ptr = int(_ok(cu.cuMemHostAlloc(nbytes, 1 | (2 if mapped else 0)),
                           f"pinned host allocation of {nbytes:,} bytes"))
        self.array = _host_array(self.ptr, shape, dtype)
        self.device_ptr = int(_ok(cu.cuMemHostGetDevicePointer(self.ptr, 0),
                                  "device pointer of mapped memory")) if mapped else 0

    def release(self) -> None:
        if self.ptr:
            _driver().cuMemFreeHost(self.ptr)
        self.ptr, self.array = 0, None


def _address(array) -> int:
    return array.ctypes.data


# --- programs ------------------------------------------------------------------------

def cache_folder() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "gpucompgen" / "cuda"


def nvrtc_version() -> tuple[int, int]:
    nv = _nvrtc()
    return tuple(int(v) for v in _nvrtc_ok(nv.nvrtcVersion(), "version"))


def _nvrtc_ok(result, what: str):
    err, *values = result
    if int(err) != 0:
        raise PipelineError(f"NVRTC {what} failed ({getattr(err, 'name', err)})")
    return values[0] if len(values) == 1 else tuple(values)


def compile_cubin(source: str, name: str, arch: str,
                  options: tuple[str, ...] = ()) -> tuple[bytes | None, str]:
    """(cubin, log) of source compiled by NVRTC for arch ('sm_87'); cubin None on failure.
    A cubin is machine code for that architecture: the driver loads it as is."""
    nv = _nvrtc()
    prog = _nvrtc_ok(nv.nvrtcCreateProgram(source.encode(), name.encode(), 0, [], []),
                     "program")
    try:
        opts = [f"--gpu-architecture={arch}".encode(), b"-std=c++17",
                b"--diag-suppress=177,161", *(o.encode() for o in options)]
        err, = nv.nvrtcCompileProgram(prog, len(opts), opts)
        # NVRTC writes into the buffer it is given: a bytearray, never bytes.  cuda-python's
        # examples pass b" " * size, which for an empty log (size 1) IS the interpreter's
        # shared one-byte b" ": NVRTC's NUL then turns every b" " of the process into
        # b"\0" (on the H100 a .npz written afterwards by the same process was corrupt)
        size = _nvrtc_ok(nv.nvrtcGetProgramLogSize(prog), "log")
        log = bytearray(size)
        nv.nvrtcGetProgramLog(prog, log)
        log_text = bytes(log).rstrip(b"\0 ").decode("utf-8", "replace")
        if int(err) != 0:
            return None, log_text
        size = _nvrtc_ok(nv.nvrtcGetCUBINSize(prog), "cubin size")
        cubin = bytearray(size)
        nv.nvrtcGetCUBIN(prog, cubin)
        return bytes(cubin), log_text
    finally:
        nv.nvrtcDestroyProgram(prog)


class CudaProgram:
    """A loaded module (one kernel file) and its kernels by name."""

    def __init__(self, context: CudaContext, module, path: Path):
        self.context, self.module, self.path = context, module, path
        self._functions: dict[str, Any] = {}

    def function(self, name: str):
        found = self._functions.get(name)
        if found is None:
            found = _ok(_driver().cuModuleGetFunction(self.module, name.encode()),
                        f"kernel {name}() in {self.path.name}")
            self._functions[name] = found
        return found


def build_program(context: CudaContext, path: Path, component: str,
                  options: tuple[str, ...] = (), defines: dict | None = None) -> CudaProgram:
    """Compile one .cu file for the device's architecture (cached on disk) and load it;
    a failure names the component and file and gives NVRTC's messages.  defines: the
    kernel's constants as -D options, as for OpenCL (programs.define_options)."""
    options = (*options, *define_options(defines))
    path = Path(path)
    source = read_kernel_file(path, component)
    arch = context.device.arch
    version = nvrtc_version()
    key = hashlib.sha256("\0".join([source, arch, f"{version[0]}.{version[1]}",
                                    *options]).encode()).hexdigest()
    cached = cache_folder() / f"{key}.cubin"
    cubin = None
    if cached.is_file():
        cubin = cached.read_bytes()
    else:
        cubin, log = compile_cubin(source, path.name, arch, options)
        if cubin is None:
            lines = clean_build_log(log)
            text = "\n".join(f"  {line}" for line in lines) or "  (no log)"
            raise PipelineError(f"{component}: kernel file {path.name} failed to build "
                                f"for {arch} with NVRTC {version[0]}.{version[1]}:\n{text}")
        try:
            cached.parent.mkdir(parents=True, exist_ok=True)
            partial = cached.with_suffix(f".{os.getpid()}.tmp")
            partial.write_bytes(cubin)
            os.replace(partial, cached)
        except OSError:  # a read-only cache: compile again next time
            pass
    context.current()
    module = _ok(_driver().cuModuleLoadData(cubin),
                 f"loading {path.name} for {arch} (a driver older than NVRTC "
                 f"{version[0]}.{version[1]}? install the NVRTC of the driver's CUDA version)")
    return CudaProgram(context, module, path)


# --- components ----------------------------------------------------------------------

class _Launch:
    """One kernel's packed arguments: each a 0-d numpy array, and the array of their
    addresses that cuLaunchKernel reads (void **kernelParams)."""

    def __init__(self, values):
        import numpy as np

        self.values = values
        self.pointers = np.array([v.ctypes.data for v in values], dtype=np.uint64)

    @property
    def address(self) -> int:
        return self.pointers.ctypes.data


def _scalar(value):
    import numpy as np

    return np.array(value, dtype=np.asarray(value).dtype)


def _pointer(ptr: int):
    import numpy as np

    return np.array(ptr, dtype=np.uint64)


class KernelComponent:
    """The base class of generated GPU-aware component classes (see components.py for
    the OpenCL one it mirrors): allocates once, launches with the plan's settings."""

    function = ""
    inputs: tuple = ()
    outputs: tuple = ()

    def __init__(self, context: CudaContext, queue: CudaQueue, program: CudaProgram, *,
                 copies_own_data: bool = False, host_visible: bool = False,
                 buffer_sets: int = 1, **params: Any):
        self.context, self.queue, self.program = context, queue, program
        self.kernel = program.function(self.function)
        self.copies_own_data, self.host_visible = copies_own_data, host_visible
        self.buffer_sets = buffer_sets
        self.profile = None
        self.event = None
        for name, value in params.items():
            setattr(self, name, value)
        self._inputs, self._outputs = dict(self.inputs), dict(self.outputs)
        self.sizes: dict[str, Size] = {}
        self.sets: list[dict[str, Any]] = []
        self.host_sets: list[dict[str, Any]] = []
        self._results: list = []
        self._turn = 0
        self._events = _Events(queue, 2 * buffer_sets + 2)

    @property
    def buffers(self) -> dict[str, Any]:
        return self.sets[0] if self.sets else {}

    def output_sizes(self, *inputs: Size) -> list[Size]:
        raise NotImplementedError

    def initialize(self, *inputs: Size):

        self.context.current()
        for port, size in zip(self._inputs, inputs):
            self.sizes[port] = Size(*size)
        out_sizes = list(self.output_sizes(*inputs))
        for port, size in zip(self._outputs, out_sizes):
            self.sizes[port] = size
        for _ in range(self.buffer_sets):
            buffers, hosts = {}, {}
            if self.copies_own_data:
                for port, dtype in self._inputs.items():
                    buffers[port] = DeviceBuffer(self.sizes[port].nbytes(dtype))
                for port, dtype in self._outputs.items():
                    buffers[port] = DeviceBuffer(self.sizes[port].nbytes(dtype))
                    hosts[port] = PinnedArray(self.sizes[port].shape, dtype)
            else:
                for port, dtype in self._outputs.items():
                    buffers[port] = DeviceBuffer(self.sizes[port].nbytes(dtype),
                                                 mapped=self.host_visible)
            self.sets.append(buffers)
            self.host_sets.append(hosts)
            given = [(hosts[port].array if self.copies_own_data else buffers[port])
                     for port in self._outputs]
            self._results.append(given[0] if len(given) == 1 else tuple(given))
        return out_sizes[0] if len(out_sizes) == 1 else tuple(out_sizes)

    def config_gpu(self, tile: int, local_size, global_size, arguments,
                   settings_source: str = ""):
        """The plan's settings: block = local size, grid = global size / local size."""
        cu = _driver()
        self.tile, self.local_size, self.global_size = tile, tuple(local_size), \
            tuple(global_size)
        limit = int(_ok(cu.cuFuncGetAttribute(
            cu.CUfunction_attribute.CU_FUNC_ATTRIBUTE_MAX_THREADS_PER_BLOCK, self.kernel),
            "kernel attribute"))
        threads = self.local_size[0] * self.local_size[1] * self.local_size[2]
        dims = self.context.device.max_block
        if threads > limit or any(b > d for b, d in zip(self.local_size, dims)):
            where = (f"change platform.gpu_settings.{type(self).__name__} in the model"
                     if settings_source == "model" else
                     "rebuild for this device with 'gpucompgen build --backend cuda "
                     "--device auto'")
            raise PipelineError(
                f"{type(self).__name__}: a block of {self.local_size} ({threads:,} threads) "
                f"does not fit device '{self.context.device.name}' (kernel limit "
                f"{limit:,} threads, per dimension {list(dims)}); {where}")
        self.grid = tuple(-(-g // b) for g, b in zip(self.global_size, self.local_size))
        inputs = [port for port, _ in self.inputs]
        self._slots = [(i, inputs.index(arg)) for i, arg in enumerate(arguments)
                       if isinstance(arg, str) and arg not in self.buffers]
        self._launches = []
        for buffers in self.sets:
            values = []
            for arg in arguments:
                if isinstance(arg, str):
                    buffer = buffers.get(arg)
                    values.append(_pointer(buffer.ptr if buffer is not None else 0))
                else:
                    values.append(_scalar(arg))
            self._launches.append(_Launch(values))

    def _launch(self, k: int, inputs, wait_for) -> CudaEvent:
        cu = _driver()
        launch = self._launches[k]
        for i, j in self._slots:
            launch.values[i][()] = inputs[j].ptr
        self.queue.wait_for(wait_for)
        event = self._events.next()
        event.before()
        g, b = self.grid, self.local_size
        _ok(cu.cuLaunchKernel(self.kernel, g[0], g[1], g[2], b[0], b[1], b[2], 0,
                              self.queue.handle, launch.address, 0),
            f"launch of {self.function}()")
        return event.after()

    def execute(self, *inputs, wait_for=None):
        self.context.current()
        k = self._turn
        if self.buffer_sets > 1:
            self._turn = (k + 1) % self.buffer_sets
        if self.copies_own_data:
            self._copy_and_run(k, inputs)
        else:
            self.event = self._launch(k, inputs, wait_for)
            if self.profile is not None:
                self.profile.kernel(self, self.event)
        return self._results[k]

    def _copy_and_run(self, k: int, inputs) -> None:
        import numpy as np

        cu = _driver()
        buffers, hosts = self.sets[k], self.host_sets[k]
        stream = self.queue.handle
        copied_in = []
        kept = []
        for port, given in zip(self._inputs, inputs):
            x = np.ascontiguousarray(given)
            kept.append(x)
            event = self._events.next()
            event.before()
            _ok(cu.cuMemcpyHtoDAsync(buffers[port].ptr, _address(x), buffers[port].size,
                                     stream), "copy to the device")
            copied_in.append(event.after())
        ran = self._launch(k, [], None)
        copied_out = []
        for port in self._outputs:
            event = self._events.next()
            event.before()
            _ok(cu.cuMemcpyDtoHAsync(hosts[port].ptr, buffers[port].ptr, buffers[port].size,
                                     stream), "copy to the host")
            copied_out.append(event.after())
        copied_out[-1].wait()
        self.event = copied_out[-1]
        if self.profile is not None:
            for port, event in zip(self._inputs, copied_in):
                self.profile.copy(self, "cpu2gpu", event, buffers[port].size)
            self.profile.kernel(self, ran)
            for port, event in zip(self._outputs, copied_out):
                self.profile.copy(self, "gpu2cpu", event, buffers[port].size)

    def free_memory(self):
        for hosts in self.host_sets:
            for pinned in hosts.values():
                pinned.release()
        for buffers in self.sets:
            for buffer in buffers.values():
                buffer.release()
        self.sets, self.host_sets, self._results, self._launches = [], [], [], []
        self._events.release()


# --- adapters ------------------------------------------------------------------------

class _Adapter(adapters._Adapter):
    """The OpenCL adapters' checks of frame sizes, on the CUDA context."""

    def initialize(self, size, dtype):
        size = super().initialize(size, dtype)
        self.context.current()
        return size


class CpuToGpuAdapter(_Adapter):
    """One device buffer per buffer set, one copy a frame (cuMemcpyHtoDAsync); with
    staging="pinned" the frame is put in a pinned array first (a host copy), so the copy
    runs at DMA speed and does not wait for the driver to stage pageable memory."""

    def __init__(self, context, queue, nbytes: int, blocking: bool = True,
                 buffer_sets: int = 1, staging: str = "pageable"):
        super().__init__(context, queue, nbytes)
        self.blocking, self.buffer_sets, self.staging = blocking, buffer_sets, staging
        self.buffers: list[DeviceBuffer] = []
        self.pinned: list[PinnedArray] = []
        self.copied: list[CudaEvent | None] = []
        self.buffer = None
        self._turn = 0
        self._events = _Events(queue, 2 * buffer_sets + 2)
        self._kept: list = []

    def initialize(self, size, dtype):
        size = super().initialize(size, dtype)
        for _ in range(self.buffer_sets):
            self.buffers.append(DeviceBuffer(self.nbytes))
            if self.staging == "pinned":
                self.pinned.append(PinnedArray(size.shape, dtype))
            self.copied.append(None)
            self._kept.append(None)
        self.buffer = self.buffers[0]
        return size

    def transfer(self, host, wait_for=None):
        import numpy as np

        cu = _driver()
        self.context.current()
        self._check(host)
        k = self._turn
        self._turn = (k + 1) % self.buffer_sets
        self.buffer = self.buffers[k]
        if self.copied[k] is not None:
            self.copied[k].wait()  # set k's last copy has read its source
        if self.pinned:
            source = self.pinned[k].array
            np.copyto(source, np.reshape(host, source.shape), casting="no")
        else:
            source = np.ascontiguousarray(host)
            self._kept[k] = source  # alive until the copy has read it
        self.queue.wait_for(wait_for)
        event = self._events.next()
        event.before()
        _ok(cu.cuMemcpyHtoDAsync(self.buffer.ptr, _address(source), self.nbytes,
                                 self.queue.handle), "copy to the device")
        self.event = self.copied[k] = event.after()
        if self.blocking:
            self.event.wait()
        if self.profile is not None:
            self.profile.copy(self, "cpu2gpu", self.event, self.nbytes)
        return self.buffer

    def free_memory(self):
        for p in self.pinned:
            p.release()
        for b in self.buffers:
            b.release()
        self.pinned, self.buffers, self.buffer, self._kept = [], [], None, []
        self._events.release()


class ZeroCopyCpuToGpuAdapter(_Adapter):
    """The kernel reads the frame from mapped pinned host memory through its device
    pointer (integrated GPUs share the memory: no copy by the device).  The frame is put
    in the set's mapped array (a host copy); before a set is written again, the commands
    queued on this lane so far are waited for, so the device no longer reads it."""

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1):
        super().__init__(context, queue, nbytes)
        self.buffer_sets = buffer_sets
        self.mapped: list[DeviceBuffer] = []
        self.buffer = None
        self.host = None
        self._turn = 0
        self._written: list[CudaEvent | None] = []
        self._events = _Events(queue, 2 * buffer_sets + 2)

    def initialize(self, size, dtype):
        size = super().initialize(size, dtype)
        for _ in range(self.buffer_sets):
            self.mapped.append(DeviceBuffer(self.nbytes, mapped=True))
            self._written.append(None)
        return size

    def transfer(self, host, wait_for=None):
        import numpy as np

        self.context.current()
        self._check(host)
        k = self._turn
        self._turn = (k + 1) % self.buffer_sets
        if self._written[k] is not None:
            self.queue.finish()  # the kernels that read set k are done
        self.buffer = self.mapped[k]
        self.host = self.buffer.view(self.shape, self.dtype)
        np.copyto(self.host, np.reshape(host, self.host.shape), casting="no")
        self._written[k] = self._events.next().after()
        return self.buffer

    def free_memory(self):
        for b in self.mapped:
            b.release()
        self.mapped, self.buffer, self.host = [], None, None
        self._events.release()


class GpuToCpuAdapter(_Adapter):
    """One host array per buffer set (pinned with staging="pinned"), one copy a frame,
    waited for: the host reads the frame next."""

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1,
                 staging: str = "pageable"):
        super().__init__(context, queue, nbytes)
        self.buffer_sets, self.staging = buffer_sets, staging
        self.hosts: list = []
        self.pinned: list[PinnedArray] = []
        self.host = None
        self._turn = 0
        self._events = _Events(queue, 2 * buffer_sets + 2)

    def initialize(self, size, dtype):
        import numpy as np

        size = super().initialize(size, dtype)
        for _ in range(self.buffer_sets):
            if self.staging == "pinned":
                self.pinned.append(PinnedArray(size.shape, dtype))
                self.hosts.append(self.pinned[-1].array)
            else:
                self.hosts.append(np.empty(size.shape, dtype))
        self.host = self.hosts[0]
        return size

    def transfer(self, buffer, wait_for=None):
        cu = _driver()
        self.context.current()
        k = self._turn
        self._turn = (k + 1) % self.buffer_sets
        self.host = self.hosts[k]
        self.queue.wait_for(wait_for)
        event = self._events.next()
        event.before()
        _ok(cu.cuMemcpyDtoHAsync(_address(self.host), buffer.ptr, self.nbytes,
                                 self.queue.handle), "copy to the host")
        self.event = event.after()
        self.event.wait()
        if self.profile is not None:
            self.profile.copy(self, "gpu2cpu", self.event, self.nbytes)
        return self.host

    def free_memory(self):
        for p in self.pinned:
            p.release()
        self.hosts, self.pinned, self.host = [], [], None
        self._events.release()


class ZeroCopyGpuToCpuAdapter(_Adapter):
    """The consumer reads the producer's mapped pinned output in place, once the kernel
    that wrote it is done (its event, or this lane's commands so far); unmap() is
    bookkeeping only: CUDA needs no unmap before the device writes again, but the
    program's order (a consumer done before the producer's next frame) is kept."""

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1,
                 wait_unmap: bool = True):
        super().__init__(context, queue, nbytes)
        self.buffer_sets, self.wait_unmap = buffer_sets, wait_unmap
        self.views: deque = deque()

    @property
    def view(self):
        return self.views[-1] if self.views else None

    def transfer(self, buffer, wait_for=None):
        self.context.current()
        if len(self.views) >= self.buffer_sets:
            raise PipelineError("buffer mapped twice: unmap() was not called")
        waited = False
        for event in wait_for or ():
            if isinstance(event, CudaEvent):
                event.wait()
                waited = True
        if not waited:
            self.queue.finish()
        if buffer.host is None and buffer._host_ptr:
            buffer.host = buffer.view(self.shape, self.dtype)
        if buffer.host is None:
            raise PipelineError("zero-copy adapter given a buffer that is not host-visible "
                                "(rebuild with --zero-copy off)")
        self.views.append(buffer.host)
        return buffer.host

    def unmap(self):
        if self.views:
            self.views.popleft()

    def free_memory(self):
        self.views.clear()
