"""Devices and kernels' limits, in neutral terms: a device's status, the limits a kernel
has on it, and the checks of the system's plan against them (the work-group, the memory).
The OpenCL module (opencl.py) selects devices and queries these facts."""

from __future__ import annotations

from typing import Any, NamedTuple

from .errors import PipelineError
from .facts import DeviceFacts


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


# What the program needs to know about its OpenCL device: the same facts the generator
# plans for (one declaration, in facts.py), queried once per device.
DeviceLimits = DeviceFacts


class KernelLimits(NamedTuple):
    """Per kernel on a device: its work-group size limit and preferred multiple."""

    work_group_size: int
    preferred_multiple: int


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


def check_work_group_fits(limits: KernelLimits, device_info: DeviceFacts,
                          local_size: tuple[int, ...], component: str,
                          settings_source: str = "") -> KernelLimits:
    """The system chose local_size for a described device; check it fits the real one
    (limits: the kernel's on it; device_info: its facts).

    settings_source says where the settings came from: "model" for the model's
    platform.gpu_settings (the error then says to change them there, with values that
    fit); anything else, chosen at build time (the error says to rebuild for this device).
    """
    threads = _product(local_size)
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
