"""OpenCL device selection, queues, and the device's and kernels' limits."""

from __future__ import annotations

import os
from typing import Any, NamedTuple

from .errors import PipelineError
from .facts import DeviceFacts
from .facts import query as query_facts
from .programs import _captured_stderr, quiet_compiler

# A kernel every OpenCL C compiler must accept: whether a device can build it is whether
# the device is usable at all.
_PROBE_SOURCE = "__kernel void gpucompgen_probe(__global int *x) { x[0] = 1; }"


class DeviceStatus(NamedTuple):
    """One OpenCL device and whether it compiles OpenCL C (problem is None when it does)."""

    platform_index: int
    device_index: int
    device: Any
    problem: str | None

    @property
    def ctx(self) -> str:
        """The PYOPENCL_CTX value that selects this device."""
        return f"{self.platform_index}:{self.device_index}"


def _build_problem(exc: BaseException) -> str:
    """The line of a failed build a user can act on (the compiler's first error)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    for line in lines:
        if line.startswith("error:"):
            return line
    return lines[0] if lines else type(exc).__name__


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


NO_DEVICE_HINT = (
    "install an OpenCL driver for your GPU, or a CPU device: on Debian or Ubuntu "
    "'apt-get install pocl-opencl-icd', elsewhere 'pip install pyopencl[pocl]' "
    "(the PyPI PoCL cannot compile for CPUs its LLVM does not know: 'unknown target CPU')")


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


# What the program needs to know about its OpenCL device: the same facts the generator
# plans for (one declaration, in facts.py), queried once per device.
DeviceLimits = DeviceFacts


class KernelLimits(NamedTuple):
    """Per kernel on a device: its work-group size limit and preferred multiple."""

    work_group_size: int
    preferred_multiple: int


_DEVICE_LIMITS: dict[Any, DeviceLimits] = {}


def device_limits(device) -> DeviceLimits:
    """The device's limits, queried from OpenCL once per device and remembered."""
    limits = _DEVICE_LIMITS.get(device.int_ptr)
    if limits is None:
        limits = query_facts(device)
        _DEVICE_LIMITS[device.int_ptr] = limits
    return limits


def kernel_limits(kernel, device) -> KernelLimits:
    import pyopencl as cl

    info = cl.kernel_work_group_info
    return KernelLimits(kernel.get_work_group_info(info.WORK_GROUP_SIZE, device),
                        kernel.get_work_group_info(info.PREFERRED_WORK_GROUP_SIZE_MULTIPLE,
                                                   device))


def fitting_block(local_size: tuple[int, ...], work_group_size: int,
                  item_sizes: tuple[int, ...]) -> tuple[int, ...]:
    """local_size made to fit: each dimension within its limit, then the largest halved
    until the threads fit the kernel's work-group limit."""
    block = [max(1, min(v, d)) for v, d in zip(local_size, item_sizes)]
    block += [max(1, v) for v in local_size[len(block):]]
    while block and _product(block) > max(1, work_group_size):
        i = block.index(max(block))
        block[i] = max(1, block[i] // 2)
    return tuple(block)


def _product(values) -> int:
    threads = 1
    for v in values:
        threads *= v
    return threads


def check_work_group(kernel, device, local_size: tuple[int, ...], component: str,
                     settings_source: str = "") -> KernelLimits:
    """The system chose local_size for a described device; check it fits the real one.

    settings_source says where the settings came from: "model" for the model's
    platform.gpu_settings (the error then says to change them there, with values that
    fit); anything else, chosen at build time (the error says to rebuild for this device).
    """
    threads = _product(local_size)
    limits = kernel_limits(kernel, device)
    device_info = device_limits(device)
    dims = device_info.max_work_item_sizes
    if threads > limits.work_group_size or any(v > d for v, d in zip(local_size, dims)):
        fit = fitting_block(tuple(local_size), limits.work_group_size, tuple(dims))
        problem = (f"{component}: GPU settings {tuple(local_size)} ({threads:,} threads) do "
                   f"not fit device '{device_info.name}' (kernel limit "
                   f"{limits.work_group_size:,} threads, per dimension "
                   f"[{', '.join(f'{d:,}' for d in dims)}], preferred multiple "
                   f"{limits.preferred_multiple})")
        if settings_source == "model":
            if len(fit) == 3:
                values = f"block_x: {fit[0]}, block_y: {fit[1]}, block_z: {fit[2]}"
            else:
                values = f"a block of {fit}"
            raise PipelineError(
                f"{problem}; the settings come from the model: change "
                f"platform.gpu_settings.{component} there to fit, e.g. {values} "
                f"({_product(fit):,} threads)")
        raise PipelineError(
            f"{problem}; rebuild for this device with 'gpucompgen build --device auto'")
    return limits


def check_device_memory(device, buffers: dict[str, int]) -> None:
    """Before anything is allocated: every device buffer fits one allocation, all fit memory.

    buffers maps 'component.port' to bytes, as propagated at build time.
    """
    name = device.name.strip()
    limit = device.max_mem_alloc_size
    for what, nbytes in buffers.items():
        if nbytes > limit:
            raise PipelineError(
                f"{what} needs a device buffer of {nbytes:,} bytes, but device '{name}' "
                f"allows at most {limit:,} bytes in one allocation; build the system for "
                "smaller frames")
    total = sum(buffers.values())
    if total > device.global_mem_size:
        raise PipelineError(
            f"the system needs {total:,} bytes of device memory for its buffers, but device "
            f"'{name}' has {device.global_mem_size:,} bytes; build the system for smaller "
            "frames")
