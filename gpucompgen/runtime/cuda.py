"""The CUDA device API: the runtime of programs built with ``--backend cuda``.

It implements the device interface (runtime/device_api.py, ``device_api.get("cuda")``)
that ``gpucompgen tune``, ``gpucompgen bench`` and the neutral core call, and the
program's classes are the neutral ones on it (KernelComponent, the copying adapters, the
GPU-to-CPU zero-copy adapter).  A CUDA program imports ``from gpucompgen.runtime import
cuda as runtime`` and calls the names an OpenCL program calls (create_context,
create_queue, check_device_memory, build_program, KernelComponent, the adapters,
Profile...); what is not device-specific (sizes, parts, failures, the command line,
frames in flight) is the neutral runtime's, re-exported here.  It uses NVIDIA's
cuda-python (``cuda.bindings``: the driver API and NVRTC), installed with
``pip install gpucompgen[cuda]``.

How the OpenCL model maps:
- context: the device's primary CUDA context (CUDA_DEVICE selects the device, default 0);
- queue (one per lane): a non-blocking CUDA stream with a ring of events, one recorded
  after each command; an event of another lane's command is waited for with
  cuStreamWaitEvent, the host waits with cuEventSynchronize;
- a kernel file: NVRTC compiles it to a cubin for the device's exact architecture
  (sm_XY), cached on disk under the source's digest, the architecture and NVRTC's
  version (``$XDG_CACHE_HOME/gpucompgen/cuda``); no PTX is left for the driver to JIT;
- a kernel: its function and the arguments set_args packed (a buffer's device pointer,
  a scalar's bytes); a launch: grid = global size / local size, block = local size;
- buffers: cuMemAlloc once at initialize; pinned staging with cuMemHostAlloc;
  zero-copy (integrated GPUs, Jetson): mapped pinned host memory (cuMemHostAlloc with
  DEVICEMAP) that the kernel reads or writes through its device pointer; host memory is
  freed with the last numpy array over it.  Managed memory is not used (on Orin, host
  access while a kernel runs faults).
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import sys
import threading
from collections import deque
from pathlib import Path
from typing import Any

from . import adapters, components
from .cli import add_program_options, main
from .components import CpuFunctionComponent
from .devices import KernelLimits, check_device_memory, check_work_group_fits
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
from .session import Session
from .sizes import Size

__all__ = [
    "CpuFunctionComponent", "CpuToGpuAdapter", "FrameFailure", "GpuToCpuAdapter",
    "KernelComponent", "Monitor", "Param", "Parts", "PipelineError", "Profile", "Result",
    "Session", "Size", "Stopped", "ZeroCopyCpuToGpuAdapter", "ZeroCopyGpuToCpuAdapter",
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


NO_DRIVER = ("no NVIDIA driver (libcuda) found: the CUDA backend needs an NVIDIA GPU and "
             "its driver; 'gpucompgen devices' lists the devices there are")
NO_DEVICE = ("no CUDA device found: the NVIDIA driver sees no GPU; 'gpucompgen devices' "
             "lists the devices there are")
_NO_DEVICE_ERROR = 100  # CUDA_ERROR_NO_DEVICE


def _init():
    global _initialized
    cu = _driver()
    with _INIT:
        if not _initialized:
            try:
                result = cu.cuInit(0)
            except Exception:  # no libcuda: cuda-python raises its own error
                raise PipelineError(NO_DRIVER) from None
            err = result[0] if isinstance(result, tuple) else result
            if int(err) == _NO_DEVICE_ERROR:
                raise PipelineError(NO_DEVICE)
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


def select_device() -> CudaDevice:
    """The device CUDA_DEVICE selects (default 0); a one-line PipelineError says what is
    missing: cuda-python, the driver, a device."""
    cu = _init()
    count = int(_ok(cu.cuDeviceGetCount(), "device count"))
    ordinal = _ordinal()
    if count == 0:
        raise PipelineError(NO_DEVICE)
    if not 0 <= ordinal < count:
        raise PipelineError(f"CUDA_DEVICE={ordinal} selects no device (there are {count}); "
                            "'gpucompgen devices' lists them")
    return CudaDevice(ordinal)


def create_context() -> CudaContext:
    """The context of the device CUDA_DEVICE selects (default 0)."""
    return CudaContext(select_device())


def context_device(context: CudaContext) -> CudaDevice:
    return context.device


def device_name(device: CudaDevice) -> str:
    """The device and its architecture, for reports."""
    return f"{device.name} (CUDA, {device.arch})"


def facts(device: CudaDevice) -> DeviceFacts:
    return device.facts()


class CudaQueue:
    """One lane: a non-blocking stream (commands of other lanes only wait by events)."""

    def __init__(self, context: CudaContext, profile: bool = False):
        cu = _driver()
        context.current()
        self.context = context
        self.device = context.device
        self.profile = profile
        self.handle = _ok(cu.cuStreamCreate(1), "stream")  # CU_STREAM_NON_BLOCKING
        self.events = _Events(self, EVENT_RING)
        self.mapped: dict[int, tuple] = {}  # id(view) -> (buffer, mode, view) of map()

    def wait_for(self, events) -> None:
        cu = _driver()
        for event in events or ():
            if isinstance(event, CudaEvent):
                _ok(cu.cuStreamWaitEvent(self.handle, event.end, 0), "stream wait")

    def command(self, wait_for=None) -> CudaEvent:
        """Before a command: the other lanes' events it waits for, and its event (from
        this queue's ring), started; the caller enqueues, then calls .after()."""
        self.context.current()  # in the calling thread (stages run in threads)
        self.wait_for(wait_for)
        event = self.events.next()
        event.before()
        return event

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


def side_queue(queue: CudaQueue) -> CudaQueue:
    """Another stream on the same device."""
    return CudaQueue(queue.context, queue.profile)


def device_of(queue: CudaQueue) -> CudaDevice:
    return queue.device


def finish(queue: CudaQueue) -> None:
    queue.finish()


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
        self.keep = None  # a host array an asynchronous copy still reads or writes

    def before(self) -> None:
        if self.start is not None:
            _ok(_driver().cuEventRecord(self.start, self.queue.handle), "event record")

    def after(self) -> CudaEvent:
        _ok(_driver().cuEventRecord(self.end, self.queue.handle), "event record")
        return self

    def wait(self) -> None:
        self.queue.context.current()
        _ok(_driver().cuEventSynchronize(self.end), "event wait")
        self.keep = None

    @property
    def profile(self) -> _Times:
        cu = _driver()
        if self.start is None:
            raise PipelineError("a CUDA event of a queue made without profile=True has no "
                                "times")
        self.wait()
        elapsed = getattr(cu, "cuEventElapsedTime", None) or cu.cuEventElapsedTime_v2
        origin = self.queue.context.origin
        start = _ok(elapsed(origin, self.start), "event time")
        end = _ok(elapsed(origin, self.end), "event time")
        return _Times(int(start * 1e6), int(end * 1e6))


EVENT_RING = 256  # events a queue reuses in turn (a command's is reused 256 commands on)


class _Events:
    """A queue's ring of events: a command reuses the event of the command `size`
    commands before it on the same stream.  Reusing one is safe: a stream that waits for
    it captured it when it enqueued its wait, and a host that waits for it later waits for
    a later command of the same in-order stream, so also for the first.  An event whose
    copy still needed its host array (keep) is waited for before it is reused."""

    def __init__(self, queue: CudaQueue, size: int):
        self.queue, self.size = queue, max(size, 2)
        self.ring: deque[CudaEvent] = deque()

    def next(self) -> CudaEvent:
        if self.queue.profile or len(self.ring) < self.size:
            event = CudaEvent(self.queue)  # profiled events are read later: not reused
        else:
            event = self.ring.popleft()
            if event.keep is not None:
                event.wait()
        if not self.queue.profile:
            self.ring.append(event)
        return event


# --- memory --------------------------------------------------------------------------

class _HostMemory:
    """Page-locked host memory (cuMemHostAlloc), freed once nothing uses it: neither its
    owner (a DeviceBuffer, a PinnedArray, until released) nor a numpy array over it.  A
    consumer may keep a frame past free_memory() (FrameSink.last: the adapter's pinned
    array); freed at release, the array would read memory that is gone."""

    def __init__(self, nbytes: int, mapped: bool, what: str):
        cu = _driver()
        # CU_MEMHOSTALLOC_PORTABLE, | CU_MEMHOSTALLOC_DEVICEMAP for the device to reach it
        self.ptr = int(_ok(cu.cuMemHostAlloc(max(nbytes, 1), 1 | (2 if mapped else 0)),
                           f"{what} of {nbytes:,} bytes"))

    def array(self, shape, dtype):
        """A numpy array over the memory; it keeps the memory alive."""
        import numpy as np

        dtype = np.dtype(dtype)
        count = int(np.prod(shape))
        raw = (ctypes.c_ubyte * (count * dtype.itemsize)).from_address(self.ptr)
        raw.owner = self  # the array's base: the memory lives while the array does
        return np.frombuffer(raw, dtype=dtype, count=count).reshape(shape)

    def __del__(self):
        with contextlib.suppress(Exception):  # at exit the driver may be gone
            _driver().cuMemFreeHost(self.ptr)


class DeviceBuffer:
    """Device memory of `size` bytes at device address `ptr` (cuMemAlloc), or mapped
    pinned host memory (host is then its numpy view, the same bytes)."""

    def __init__(self, size: int, mapped: bool = False):
        cu = _driver()
        self.size = size
        self._host_ptr = 0
        self._memory: _HostMemory | None = None
        if mapped:
            self._memory = _HostMemory(size, True, "mapped host allocation")
            self._host_ptr = self._memory.ptr
            self.ptr = int(_ok(cu.cuMemHostGetDevicePointer(self._host_ptr, 0),
                               "device pointer of mapped memory"))
        else:
            self.ptr = int(_ok(cu.cuMemAlloc(max(size, 1)),
                               f"device allocation of {size:,} bytes"))

    def view(self, shape, dtype):
        """The mapped host memory as a numpy array (mapped buffers only)."""
        return self._memory.array(shape, dtype)

    def release(self) -> None:
        if self._memory is None and self.ptr:
            _driver().cuMemFree(self.ptr)
        self._memory = None  # mapped: freed with the last view of it
        self.ptr = self._host_ptr = 0


class PinnedArray:
    """A page-locked host array (cuMemHostAlloc): copies from and to it run at DMA speed.
    release() lets the memory go once no array over it is left."""

    def __init__(self, shape, dtype, mapped: bool = False):
        import numpy as np

        cu = _driver()
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        memory = _HostMemory(nbytes, mapped, "pinned host allocation")
        self.ptr = memory.ptr
        self.array = memory.array(shape, dtype)
        self.device_ptr = int(_ok(cu.cuMemHostGetDevicePointer(self.ptr, 0),
                                  "device pointer of mapped memory")) if mapped else 0

    def release(self) -> None:
        self.ptr, self.array = 0, None


def _address(array) -> int:
    return array.ctypes.data


class HostBuffer:
    """A host array the device reads and writes in place (cuMemHostRegister with
    DEVICEMAP: page-locked where it is, reached through its device pointer); the array
    must stay alive while it is registered (it is kept here)."""

    def __init__(self, array):
        import numpy as np

        cu = _driver()
        if not (isinstance(array, np.ndarray) and array.flags.c_contiguous):
            raise PipelineError("a host buffer needs a C-contiguous numpy array")
        self.host, self.size = array, array.nbytes
        self._host_ptr = _address(array)
        _ok(cu.cuMemHostRegister(self._host_ptr, max(self.size, 1), 1 | 2),
            f"registering {self.size:,} bytes of host memory")
        self.ptr = int(_ok(cu.cuMemHostGetDevicePointer(self._host_ptr, 0),
                           "device pointer of registered memory"))

    def view(self, shape, dtype):
        import numpy as np

        return self.host.view(np.dtype(dtype)).reshape(shape)

    def release(self) -> None:
        if self._host_ptr:
            _driver().cuMemHostUnregister(self._host_ptr)
        self.ptr = self._host_ptr = 0
        self.host = None


def device_buffer(context: CudaContext, nbytes: int, access: str = "read_write",
                  host_visible: bool = False) -> DeviceBuffer:
    """Device memory; host_visible: mapped pinned host memory (a zero-copy adapter reads
    it in place).  CUDA has no access flags: access is the interface's, unused."""
    context.current()
    return DeviceBuffer(nbytes, mapped=host_visible)


def host_buffer(context: CudaContext, array, access: str = "read") -> HostBuffer:
    context.current()
    return HostBuffer(array)


def filled_buffer(context: CudaContext, array) -> DeviceBuffer:
    """A device buffer holding a copy of a host array (copied before it returns)."""
    import numpy as np

    context.current()
    array = np.ascontiguousarray(array)
    buffer = DeviceBuffer(array.nbytes)
    _ok(_driver().cuMemcpyHtoD(buffer.ptr, _address(array), array.nbytes),
        "copy to the device")
    return buffer


def pinned(context: CudaContext, queue: CudaQueue, shape, dtype) -> tuple:
    """A pinned host array: (its PinnedArray, the numpy array)."""
    context.current()
    array = PinnedArray(shape, dtype)
    return array, array.array


def release_pinned(queue: CudaQueue, pinned_arrays) -> None:
    for array, _ in pinned_arrays:
        array.release()


def release(buffer) -> None:
    buffer.release()


def nbytes(buffer) -> int:
    return buffer.size


def _is_host(x) -> bool:
    import numpy as np

    return isinstance(x, np.ndarray)


def copy(queue: CudaQueue, dst, src, blocking: bool = True, wait_for=None) -> CudaEvent:
    """Host array to buffer, buffer to host array (blocking: done on return), or buffer to
    buffer (never blocking); returns its event.  A copy that is not waited for keeps its
    host array alive (the event's keep) until the queue's ring reuses the event, which
    waits for it first.  The host array must be C-contiguous; its bytes are copied."""
    cu = _driver()
    host = src if _is_host(src) else dst if _is_host(dst) else None
    if host is not None:
        if _is_host(src) and _is_host(dst):
            raise PipelineError("copy between two host arrays: use numpy")
        _check_copy(host, dst if host is src else src)
    event = queue.command(wait_for)
    if host is None:
        _ok(cu.cuMemcpyDtoDAsync(dst.ptr, src.ptr, min(src.size, dst.size), queue.handle),
            "copy between device buffers")
        blocking = False
    elif host is src:
        _ok(cu.cuMemcpyHtoDAsync(dst.ptr, _address(src), src.nbytes, queue.handle),
            "copy to the device")
    else:
        _ok(cu.cuMemcpyDtoHAsync(_address(dst), src.ptr, dst.nbytes, queue.handle),
            "copy to the host")
    event.after()
    if blocking:
        event.wait()
    else:
        event.keep = host
    return event


def _check_copy(host, buffer) -> None:
    if not host.flags.c_contiguous:
        raise PipelineError("a copy between host and device needs a C-contiguous array")
    if host.nbytes > buffer.size:
        raise PipelineError(f"a copy of {host.nbytes:,} bytes into or out of a buffer of "
                            f"{buffer.size:,}")


def fill(queue: CudaQueue, buffer, byte: int, nbytes: int) -> CudaEvent:
    event = queue.command()
    _ok(_driver().cuMemsetD8Async(buffer.ptr, byte, nbytes, queue.handle), "fill")
    return event.after()


def map(queue: CudaQueue, buffer, shape, dtype, mode: str = "read", wait_for=None) -> tuple:
    """The buffer for the host, once the queue's commands so far and wait_for are done:
    (view, event).  Host-visible memory (mapped pinned, registered) is the view itself;
    device memory is copied into a host array (not for mode "write", which discards the
    contents) and copied back at unmap()."""
    import numpy as np

    event = queue.command(wait_for).after()
    event.wait()  # a stream's commands run in order: everything before the map is done
    if getattr(buffer, "_host_ptr", 0):
        view = buffer.view(shape, dtype)
    else:
        view = np.empty(shape, dtype)
        if mode != "write":
            copy(queue, view, buffer)
    queue.mapped[id(view)] = (buffer, mode, view)
    return view, event


def unmap(queue: CudaQueue, view) -> CudaEvent:
    """Give a mapped view back: a copied one is copied back to the device unless it was
    mapped for reading only; returns the event after which the device sees it."""
    buffer, mode, _ = queue.mapped.pop(id(view), (None, "read", view))
    if buffer is not None and not getattr(buffer, "_host_ptr", 0) and mode != "read":
        return copy(queue, buffer, view, blocking=False)
    return queue.command().after()


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
        # --fmad=false: each statement rounded as OpenCL C rounds it (backend/cuda/nvrtc.py)
        opts = [f"--gpu-architecture={arch}".encode(), b"-std=c++17",
                b"--diag-suppress=177,161", b"--fmad=false", *(o.encode() for o in options)]
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
    path = Path(path)
    source = read_kernel_file(path, component)
    return _program(context, source, path, component, (*options, *define_options(defines)))


def build_source(context: CudaContext, source: str, options: tuple[str, ...] = ()) \
        -> CudaProgram:
    """Compile and load CUDA C++ source text (a .cu file's text, prelude included)."""
    return _program(context, source, Path("source.cu"), "kernel source", tuple(options))


def _program(context: CudaContext, source: str, path: Path, component: str,
             options: tuple[str, ...]) -> CudaProgram:
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


class CudaKernel:
    """One kernel function of a loaded program and the arguments set_args packed for it
    (cuLaunchKernel copies them at each launch, so they may change between launches)."""

    def __init__(self, program: CudaProgram, name: str):
        self.program, self.name = program, name
        self.function = program.function(name)
        self.arguments: _Launch | None = None


def kernel(program: CudaProgram, function: str) -> CudaKernel:
    return CudaKernel(program, function)


def set_args(kernel: CudaKernel, *args) -> None:
    """Buffers (anything with .ptr; None: a null pointer, filled in later) and numpy
    scalars, in the kernel's parameter order."""
    kernel.arguments = _Launch([_pointer(0 if a is None else a.ptr)
                                if a is None or hasattr(a, "ptr") else _scalar(a)
                                for a in args])


def launch(queue: CudaQueue, kernel: CudaKernel, global_size, local_size,
           wait_for=None) -> CudaEvent:
    """The kernel over global_size threads in blocks of local_size (grid = global size /
    local size, rounded up); returns its event."""
    if kernel.arguments is None:
        raise PipelineError(f"kernel {kernel.name}() launched before set_args()")
    block = (*local_size, 1, 1, 1)[:3]
    grid = tuple(-(-g // b) for g, b in zip((*global_size, 1, 1, 1)[:3], block))
    event = queue.command(wait_for)
    _ok(_driver().cuLaunchKernel(kernel.function, *grid, *block, 0, queue.handle,
                                 kernel.arguments.address, 0),
        f"launch of {kernel.name}()")
    return event.after()


def launcher():
    """launch() itself, looked up once: a kernel component calls it every frame."""
    return launch


def kernel_limits(kernel: CudaKernel, device: CudaDevice) -> KernelLimits:
    """The kernel's thread limit on the device (registers and shared memory decide it),
    and the warp size as its preferred multiple."""
    cu = _driver()
    limit = int(_ok(cu.cuFuncGetAttribute(
        cu.CUfunction_attribute.CU_FUNC_ATTRIBUTE_MAX_THREADS_PER_BLOCK, kernel.function),
        "kernel attribute"))
    return KernelLimits(limit, 32)


def check_work_group(kernel: CudaKernel, device: CudaDevice, local_size, component: str,
                     settings_source: str = "") -> KernelLimits:
    """The plan's block checked against the kernel's and the device's limits (the neutral
    check and message, devices.check_work_group_fits)."""
    return check_work_group_fits(kernel_limits(kernel, device), device.facts(),
                                 tuple(local_size), component, settings_source)


# --- events and the rest of the device interface ---------------------------------------

def wait(events) -> None:
    wait_for_events(events)


def event_seconds(event: CudaEvent) -> float:
    """A finished command's device time (its queue made with profiling)."""
    times = event.profile
    return (times.end - times.start) * 1e-9


def is_running(event: CudaEvent) -> bool:
    """Whether the command of this event is not done yet (CUDA does not tell queued from
    running: both are 'not ready')."""
    if not isinstance(event, CudaEvent):
        return False
    with contextlib.suppress(Exception):  # no driver, a foreign event: nothing to say
        err = _driver().cuEventQuery(event.end)
        err = err[0] if isinstance(err, tuple) else err
        return int(err) == 600  # CUDA_ERROR_NOT_READY
    return False


def api_frames(module: str) -> bool:
    """Whether a Python module is this API's binding (signals: where a thread waits)."""
    return module.split(".")[0] == "cuda"


def load():
    """Import cuda-python's driver API (a PipelineError saying what to install without)."""
    return _driver()


def loader_library() -> str | None:
    """No OpenCL loader comes with CUDA (OpenCV's OpenCL finds its own)."""
    return None


NAME = "cuda-python"  # the binding's name, in messages


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


class KernelComponent(components.KernelComponent):
    """The base class of generated GPU-aware component classes: the neutral one
    (components.py: allocates once, launches with the plan's settings, the standard
    form's copies) on this module's device interface."""

    api = sys.modules[__name__]


# --- adapters ------------------------------------------------------------------------
# The neutral adapters (adapters.py) on this module's device interface, but for the
# zero-copy CPU-to-GPU one: CUDA reads a frame in place from mapped pinned memory, which
# a frame is copied into on the host (registering each frame's memory would cost more).

_THIS = sys.modules[__name__]


class CpuToGpuAdapter(adapters.CpuToGpuAdapter):
    """One device buffer per buffer set, one copy a frame (cuMemcpyHtoDAsync); with
    staging="pinned" the frame is put in a pinned array first (a host copy), so the copy
    runs at DMA speed.  A copy that is not waited for (blocking=False) reads its source
    after transfer() returns: a set's pinned array is written again only once the set's
    last copy is done, and a pageable frame is kept alive by the copy's event."""

    api = _THIS

    def initialize(self, size, dtype):
        self.copied: list[CudaEvent | None] = [None] * self.buffer_sets
        return super().initialize(size, dtype)

    def transfer(self, host, wait_for=None):
        k = self._turn
        if self.copied[k] is not None:
            self.copied[k].wait()  # set k's last copy has read its pinned array
        buffer = super().transfer(host, wait_for)
        self.copied[k] = self.event
        return buffer

    def free_memory(self):
        for event in getattr(self, "copied", ()):
            if event is not None:
                event.wait()  # no copy still reads a pinned array being freed
        self.copied = [None] * self.buffer_sets
        super().free_memory()


class ZeroCopyCpuToGpuAdapter(adapters._Adapter):
    """The kernel reads the frame from mapped pinned host memory through its device
    pointer (integrated GPUs share the memory: no copy by the device).  The frame is put
    in the set's mapped array (a host copy); before a set is written again, the commands
    queued on this lane so far are waited for, so the device no longer reads it."""

    api = _THIS

    def __init__(self, context, queue, nbytes: int, buffer_sets: int = 1):
        super().__init__(context, queue, nbytes)
        self.buffer_sets = buffer_sets
        self.mapped: list[DeviceBuffer] = []
        self.buffer = None
        self.host = None
        self._turn = 0
        self._written: list[bool] = []

    def initialize(self, size, dtype):
        size = super().initialize(size, dtype)
        for _ in range(self.buffer_sets):
            self.mapped.append(device_buffer(self.context, self.nbytes, "read",
                                             host_visible=True))
            self._written.append(False)
        return size

    def transfer(self, host, wait_for=None):
        import numpy as np

        self._check(host)
        k = self._turn
        self._turn = (k + 1) % self.buffer_sets
        if self._written[k]:
            finish(self.queue)  # the kernels that read set k are done
        self.buffer = self.mapped[k]
        self.host = self.buffer.view(self.shape, self.dtype)
        np.copyto(self.host, np.reshape(host, self.host.shape), casting="no")
        self._written[k] = True
        return self.buffer

    def free_memory(self):
        for b in self.mapped:
            release(b)
        self.mapped, self.buffer, self.host = [], None, None


class GpuToCpuAdapter(adapters.GpuToCpuAdapter):
    """One host array per buffer set (pinned with staging="pinned"), one copy a frame,
    waited for: the host reads the frame next."""

    api = _THIS


class ZeroCopyGpuToCpuAdapter(adapters.ZeroCopyGpuToCpuAdapter):
    """The consumer reads the producer's output in place, mapped (map(): once the
    queue's commands so far and the events it is given are done): host-visible memory
    (mapped pinned, the producer made with host_visible) is read where it is, with no
    copy; unmap() only records where the device may write it again."""

    api = _THIS
