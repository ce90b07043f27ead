"""The OpenCL device API (pyopencl): the runtime's one OpenCL module.

It implements the device interface (runtime/device_api.py) that the neutral core (the
adapters, kernel components, profiling) and ``gpucompgen tune`` / ``bench`` call, and holds
everything else that speaks OpenCL: device selection (PYOPENCL_CTX, else the first device
that compiles OpenCL C), the device facts queried from a device, and building kernel files
with readable errors.  pyopencl is imported when a function needs it, so importing this
module (and ``from gpucompgen import runtime``) works without it.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from pathlib import Path
from typing import Any

from .devices import DeviceStatus, KernelLimits, _build_problem, check_work_group_fits
from .errors import PipelineError
from .facts import DeviceFacts, kind_of
from .programs import (
    _captured_stderr,
    _log_from_error,
    _name_unnamed_source,
    _split_header,
    clean_build_log,
    define_options,
    read_kernel_file,
)

# PoCL's CPU device runs kernels on one worker thread a core; unpinned, Linux at times
# put two of them on one core for dozens of frames (the pointwise chain at 1280x720: runs
# of 1.4 ms frames among 0.75 ms ones, the kernel at one core's speed; 14 to 30 frames of
# 115 slower than 1.1 ms against 3 pinned).  Pinned unless the user says otherwise
# (POCL_AFFINITY=0); other drivers ignore it, and PoCL reads it when its platform is
# first loaded, so it is set when the runtime is imported.
os.environ.setdefault("POCL_AFFINITY", "1")


def load():
    """Import pyopencl: it points the ICD loader at the PoCL shipped in its wheel, which
    another library in the same process (OpenCV's OpenCL) then finds too."""
    import pyopencl

    return pyopencl


# ---------------------------------------------------------------- devices and their facts

# A kernel every OpenCL C compiler must accept: whether a device can build it is whether
# the device is usable at all.
_PROBE_SOURCE = "__kernel void gpucompgen_probe(__global int *x) { x[0] = 1; }"

NO_DEVICE_HINT = (
    "install an OpenCL driver for your GPU, or a CPU device: on Debian or Ubuntu "
    "'apt-get install pocl-opencl-icd', elsewhere 'pip install pyopencl[pocl]' "
    "(the PyPI PoCL cannot compile for CPUs its LLVM does not know: 'unknown target CPU')")


@contextlib.contextmanager
def quiet_compiler():
    """Keep a successful build's compiler chatter off the user's terminal.

    NVIDIA's OpenCL compiler returns a non-empty log for kernels that build fine, which
    pyopencl turns into a CompilerWarning on stderr every run. As in pyopencl, setting
    PYOPENCL_COMPILER_OUTPUT=1 shows it; a failed build always shows its log.
    """
    import pyopencl as cl

    with warnings.catch_warnings():
        if os.environ.get("PYOPENCL_COMPILER_OUTPUT") != "1":
            warnings.simplefilter("ignore", cl.CompilerWarning)
        yield


def probe_device(device) -> str | None:
    """None if DEVICE builds a trivial kernel, else what went wrong."""
    import pyopencl as cl

    try:
        context = cl.Context([device])
        with _captured_stderr(), quiet_compiler():  # no stray '1 error generated.'
            cl.Program(context, _PROBE_SOURCE).build()
    except Exception as exc:  # any failure means: not usable
        return _build_problem(exc)
    return None


def survey_devices(stop_at_first_usable: bool = False) -> list[DeviceStatus]:
    """Every OpenCL device in platform order, each probed with a trivial kernel build."""
    try:
        import pyopencl as cl

        platforms = cl.get_platforms()
    except Exception:  # no pyopencl, no ICD loader, or no platform at all
        return []
    found = []
    for p, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except Exception:  # a platform with no devices raises DEVICE_NOT_FOUND
            devices = []
        for d, device in enumerate(devices):
            status = DeviceStatus(p, d, device, probe_device(device))
            found.append(status)
            if stop_at_first_usable and status.problem is None:
                return found
    return found


def unusable_message(statuses: list[DeviceStatus]) -> str:
    """Why none of these devices can be used, and what to install."""
    if not statuses:
        return f"no OpenCL device found; {NO_DEVICE_HINT}"
    tried = "; ".join(f"{s.ctx} {s.device.name.strip()}: {s.problem}" for s in statuses)
    return f"no OpenCL device can compile kernels ({tried}); {NO_DEVICE_HINT}"


def select_device(statuses: list[DeviceStatus] | None = None):
    """The device PYOPENCL_CTX selects, else the first device that compiles OpenCL C.

    pyopencl's own default takes the first device, even one whose compiler cannot build
    anything (a PoCL whose LLVM does not know the host CPU); skipping such a device keeps
    ``python generated/x.py`` working wherever some OpenCL device works.  statuses, from
    survey_devices(), saves probing the devices again.
    """
    import pyopencl as cl

    if os.environ.get("PYOPENCL_CTX"):
        try:
            return cl.create_some_context(interactive=False).devices[0]
        except Exception as exc:
            raise PipelineError(
                f"PYOPENCL_CTX={os.environ['PYOPENCL_CTX']!r} selects no usable OpenCL "
                f"device ({exc}); 'gpucompgen devices' lists the devices") from None
    if statuses is None:
        statuses = survey_devices(stop_at_first_usable=True)
    for status in statuses:
        if status.problem is None:
            return status.device
    raise PipelineError(unusable_message(statuses))


def create_context():
    """A context on the device select_device() chooses (PYOPENCL_CTX, else the first usable)."""
    import pyopencl as cl

    return cl.Context([select_device()])


def create_queue(context, profile: bool = False):
    """The program's command queue; with profile, one that records OpenCL event times."""
    import pyopencl as cl

    properties = cl.command_queue_properties.PROFILING_ENABLE if profile else 0
    return cl.CommandQueue(context, properties=properties)


def side_queue(queue):
    """Another in-order queue on the same device (a zero-copy adapter maps on its own)."""
    import pyopencl as cl

    return cl.CommandQueue(queue.context, device=queue.device)


def device_of(queue):
    return queue.device


def context_device(context):
    """The device a context (made by create_context) runs on."""
    return context.devices[0]


def device_name(device) -> str:
    """The device and its platform, for reports."""
    return f"{device.name.strip()} ({device.platform.name.strip()})"


def loader_library() -> str | None:
    """The OpenCL loader library shipped inside pyopencl's wheel (with PoCL), for another
    library in a child process (OpenCV) to reach the same devices; None without one."""
    try:
        import pyopencl
    except ImportError:
        return None
    libs = sorted((Path(pyopencl.__file__).parent / ".libs").glob("libOpenCL*.so*"))
    return str(libs[0]) if libs else None


def facts(device: Any) -> DeviceFacts:
    """The facts of an OpenCL device (the OpenCL queries, made in this one place)."""
    import pyopencl as cl

    unified = bool(getattr(device, "host_unified_memory", False))
    sizes = tuple(device.max_work_item_sizes)[:3]
    sizes = tuple(sizes) + (1,) * (3 - len(sizes))
    return DeviceFacts(
        name=device.name.strip(),
        compute_units=device.max_compute_units,
        max_work_group_size=device.max_work_group_size,
        max_work_item_sizes=sizes,
        local_mem_size=device.local_mem_size,
        global_mem_size=device.global_mem_size,
        max_mem_alloc_size=device.max_mem_alloc_size,
        host_unified_memory=unified,
        threads_per_compute_unit=2048 if device.type & cl.device_type.GPU else
        device.max_work_group_size,
        kind=kind_of(bool(device.type & cl.device_type.CPU),
                     bool(device.type & cl.device_type.GPU), unified),
    )


_DEVICE_LIMITS: dict[Any, DeviceFacts] = {}


def device_limits(device) -> DeviceFacts:
    """The device's limits, queried from OpenCL once per device and remembered."""
    limits = _DEVICE_LIMITS.get(device.int_ptr)
    if limits is None:
        limits = facts(device)
        _DEVICE_LIMITS[device.int_ptr] = limits
    return limits


def kernel_limits(kernel, device) -> KernelLimits:
    import pyopencl as cl

    info = cl.kernel_work_group_info
    return KernelLimits(kernel.get_work_group_info(info.WORK_GROUP_SIZE, device),
                        kernel.get_work_group_info(info.PREFERRED_WORK_GROUP_SIZE_MULTIPLE,
                                                   device))


def check_work_group(kernel, device, local_size: tuple[int, ...], component: str,
                     settings_source: str = "") -> KernelLimits:
    """The system chose local_size for a described device; check it fits the real one
    (devices.check_work_group_fits says how a misfit is reported)."""
    return check_work_group_fits(kernel_limits(kernel, device), device_limits(device),
                                 local_size, component, settings_source)


# ---------------------------------------------------------------- memory, copies, mapping

_ACCESS = {"read": "READ_ONLY", "write": "WRITE_ONLY", "read_write": "READ_WRITE"}


def device_buffer(context, nbytes: int, access: str = "read_write",
                  host_visible: bool = False):
    """A device buffer; host_visible: in memory the host can map without a copy
    (ALLOC_HOST_PTR), for a zero-copy adapter to map."""
    import pyopencl as cl

    flags = getattr(cl.mem_flags, _ACCESS[access])
    if host_visible:
        flags |= cl.mem_flags.ALLOC_HOST_PTR
    return cl.Buffer(context, flags, nbytes)


def host_buffer(context, array, access: str = "read"):
    """A buffer over a host array, used in place (USE_HOST_PTR: zero-copy on unified
    memory); the array must stay alive and unchanged while the device reads it."""
    import pyopencl as cl

    flags = getattr(cl.mem_flags, _ACCESS[access]) | cl.mem_flags.USE_HOST_PTR
    return cl.Buffer(context, flags, hostbuf=array)


def filled_buffer(context, array):
    """A read-only device buffer holding a copy of a host array."""
    import pyopencl as cl

    return cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=array)


def pinned(context, queue, shape, dtype):
    """A pinned host array: a buffer the implementation allocates in page-locked host
    memory (ALLOC_HOST_PTR), mapped once for the host.  Copies to and from it run at the
    device's DMA speed; a pageable array is staged through such memory by the driver on
    every copy.  Returns (buffer, mapped array)."""
    import numpy as np
    import pyopencl as cl

    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    buffer = cl.Buffer(context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, nbytes)
    view, _ = cl.enqueue_map_buffer(queue, buffer, cl.map_flags.READ | cl.map_flags.WRITE, 0,
                                    shape, np.dtype(dtype), is_blocking=True)
    return buffer, view


def release_pinned(queue, pinned_arrays) -> None:
    """Unmap and release pinned staging buffers without waiting: the unmap is queued behind
    whatever the device still runs (a kernel that never ends must not keep free_all from
    returning), and OpenCL releases the memory once its commands are done."""
    for buffer, view in pinned_arrays:
        view.base.release(queue)
        buffer.release()


def release(buffer) -> None:
    buffer.release()


def nbytes(buffer) -> int:
    return buffer.size


def copy(queue, dst, src, blocking: bool = True, wait_for=None):
    """Host array to buffer, buffer to host array (blocking: done on return), or buffer to
    buffer (never blocking); returns its event."""
    import pyopencl as cl

    if isinstance(dst, cl.MemoryObjectHolder) and isinstance(src, cl.MemoryObjectHolder):
        return cl.enqueue_copy(queue, dst, src, wait_for=wait_for)
    return cl.enqueue_copy(queue, dst, src, is_blocking=blocking, wait_for=wait_for)


def fill(queue, buffer, byte: int, nbytes: int):
    import numpy as np
    import pyopencl as cl

    return cl.enqueue_fill_buffer(queue, buffer, np.uint8(byte), 0, nbytes)


_MAP = {"read": ("READ",), "write": ("WRITE_INVALIDATE_REGION",),
        "read_write": ("READ", "WRITE")}


def map(queue, buffer, shape, dtype, mode: str = "read", wait_for=None):
    """Map a buffer for the host (blocking): (array view, event).  mode "write" discards
    the buffer's contents (the host overwrites all of it)."""
    import numpy as np
    import pyopencl as cl

    flags = 0
    for name in _MAP[mode]:
        flags |= getattr(cl.map_flags, name)
    return cl.enqueue_map_buffer(queue, buffer, flags, 0, shape, np.dtype(dtype),
                                 is_blocking=True, wait_for=wait_for)


def unmap(queue, view):
    """Give a mapped view back to the device; returns the unmap's event."""
    return view.base.release(queue)


def finish(queue) -> None:
    queue.finish()


# ---------------------------------------------------------------- programs and launches

def build_source(context, source: str, options: tuple[str, ...] = ()):
    """Build kernel source text (the compiler's chatter kept quiet)."""
    import pyopencl as cl

    with quiet_compiler():
        return cl.Program(context, source).build(options=list(options))


def build_program(context, path: Path, component: str, options: tuple[str, ...] = (),
                  defines: dict | None = None):
    """Build one kernel file once; a failure names the component and file and gives the
    compiler's messages once, as file:line:col (a #line directive makes the compiler
    name the kernel file and its own line numbers).  defines: the kernel's constants
    (programs.define_options), set as build options."""
    import pyopencl as cl

    options = (*options, *define_options(defines))
    path = Path(path)
    source = read_kernel_file(path, component)
    header, body = _split_header(source)
    name = path.name.replace("\\", "\\\\").replace('"', '\\"')
    program = cl.Program(context, f'{header}#line 1 "{name}"\n{body}')
    with _captured_stderr() as captured:
        try:
            with quiet_compiler():
                return program.build(options=list(options))
        except cl.RuntimeError as exc:
            error = exc
    log = ""
    raw = getattr(program, "_prg", None)
    if raw is not None:
        with contextlib.suppress(Exception):
            log = "\n".join(str(raw.get_build_info(d, cl.program_build_info.LOG))
                            for d in context.devices)
    if not log.strip():
        log = _log_from_error(str(error))
    lines = clean_build_log(log + "\n" + "".join(captured))
    lines = _name_unnamed_source(lines, path.name, header.count("\n") + 1)
    if not lines:
        lines = [str(error).strip().splitlines()[0] if str(error).strip() else
                 type(error).__name__]
    text = "\n".join(f"  {line}" for line in lines)
    raise PipelineError(f"{component}: kernel file {path.name} failed to build:\n{text}")


def kernel(program, function: str):
    import pyopencl as cl

    return cl.Kernel(program, function)


def set_args(kernel, *args) -> None:
    kernel.set_args(*args)


def launch(queue, kernel, global_size, local_size, wait_for=None):
    """Enqueue a kernel over global_size work-items in work-groups of local_size (the
    plan's grid times block, and block); returns its event."""
    import pyopencl as cl

    return cl.enqueue_nd_range_kernel(queue, kernel, global_size, local_size,
                                      wait_for=wait_for)


def launcher():
    """launch() itself, looked up once: a kernel component calls it every frame."""
    import pyopencl as cl

    return cl.enqueue_nd_range_kernel


# ---------------------------------------------------------------- events

def wait(events) -> None:
    for event in events:
        event.wait()


def event_seconds(event) -> float:
    """A finished command's device time (its queue made with profiling)."""
    return (event.profile.end - event.profile.start) * 1e-9


def is_running(event) -> bool:
    """Whether the command of this event runs on the device now."""
    import pyopencl as cl

    state = None
    with contextlib.suppress(Exception):  # a released or foreign event: nothing to say
        state = event.command_execution_status
    return state == cl.command_execution_status.RUNNING


def api_frames(module: str) -> bool:
    """Whether a Python module is this API's binding (signals: where a thread waits)."""
    return module.split(".")[0] == "pyopencl"


NAME = "pyopencl"  # the binding's name, in messages
