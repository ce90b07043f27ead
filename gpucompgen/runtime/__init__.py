"""The small runtime that generated programs import.

It holds what every generated program needs and nothing of the generator: device
selection, program building with readable errors, size checks, the command line of a
generated program.  It imports pyopencl and numpy only.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import traceback
from pathlib import Path
from typing import Any, Callable, NamedTuple


class PipelineError(Exception):
    """A problem a user can act on, reported without a traceback."""


class Size(NamedTuple):
    """The size of the data on one port (the paper's SIZE_TYPE)."""

    height: int
    width: int
    channels: int = 1

    def nbytes(self, dtype: Any) -> int:
        import numpy as np

        return self.height * self.width * self.channels * np.dtype(dtype).itemsize

    @property
    def shape(self) -> tuple[int, ...]:
        """Host array shape: (height, width) for one channel, else (height, width, channels)."""
        if self.channels == 1:
            return (self.height, self.width)
        return (self.height, self.width, self.channels)


def create_context():
    """The OpenCL context PYOPENCL_CTX selects, else the first device found."""
    import pyopencl as cl

    try:
        return cl.create_some_context(interactive=False)
    except (cl.Error, RuntimeError, ValueError, IndexError) as exc:
        raise PipelineError(
            f"no usable OpenCL device ({exc}); install one, e.g. "
            "'pip install pyopencl[pocl]' for a CPU device, or set PYOPENCL_CTX") from None


def build_program(context, path: Path, component: str, options: tuple[str, ...] = ()):
    """Build one kernel file once; a failure names the component, file and build log."""
    import pyopencl as cl

    try:
        source = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise PipelineError(f"{component}: cannot read kernel file {path}: {exc.strerror}") \
            from None
    try:
        return cl.Program(context, source).build(options=list(options))
    except cl.RuntimeError as exc:
        log = str(exc).strip()
        raise PipelineError(f"{component}: kernel file {Path(path).name} failed to build:\n"
                            f"{log}") from None


class DeviceLimits(NamedTuple):
    """What the generated program needs to know about its OpenCL device, queried once."""

    name: str
    compute_units: int
    max_work_group_size: int
    max_work_item_sizes: tuple[int, ...]
    local_mem_size: int
    global_mem_size: int
    max_mem_alloc_size: int
    host_unified_memory: bool


class KernelLimits(NamedTuple):
    """Per kernel on a device: its work-group size limit and preferred multiple."""

    work_group_size: int
    preferred_multiple: int


_DEVICE_LIMITS: dict[Any, DeviceLimits] = {}


def device_limits(device) -> DeviceLimits:
    """The device's limits, queried from OpenCL once per device and remembered."""
    limits = _DEVICE_LIMITS.get(device.int_ptr)
    if limits is None:
        limits = DeviceLimits(
            device.name.strip(), device.max_compute_units, device.max_work_group_size,
            tuple(device.max_work_item_sizes), device.local_mem_size, device.global_mem_size,
            device.max_mem_alloc_size, bool(getattr(device, "host_unified_memory", False)))
        _DEVICE_LIMITS[device.int_ptr] = limits
    return limits


def kernel_limits(kernel, device) -> KernelLimits:
    import pyopencl as cl

    info = cl.kernel_work_group_info
    return KernelLimits(kernel.get_work_group_info(info.WORK_GROUP_SIZE, device),
                        kernel.get_work_group_info(info.PREFERRED_WORK_GROUP_SIZE_MULTIPLE,
                                                   device))


def check_work_group(kernel, device, local_size: tuple[int, ...], component: str
                     ) -> KernelLimits:
    """The system chose local_size for a described device; check it fits the real one."""
    threads = 1
    for v in local_size:
        threads *= v
    limits = kernel_limits(kernel, device)
    dims = device_limits(device).max_work_item_sizes
    if threads > limits.work_group_size or any(v > d for v, d in zip(local_size, dims)):
        raise PipelineError(
            f"{component}: GPU settings {local_size} ({threads} threads) do not fit device "
            f"'{device_limits(device).name}' (kernel limit {limits.work_group_size}, per "
            f"dimension {list(dims)}, preferred multiple {limits.preferred_multiple}); "
            "rebuild for this device with 'gpucompgen build --device auto'")
    return limits


def expect_size(component: str, got: Any, expected: Size) -> Size:
    """initialize() must give the size the system propagated at build time."""
    if tuple(got) != tuple(expected):
        raise PipelineError(f"{component}: initialize() gave size {tuple(got)}, but the system "
                            f"was built for {tuple(expected)} (height, width, channels)")
    return Size(*got)


def load_class(path: Path, name: str) -> type:
    """Load a user's standard component class from a file copied beside the program."""
    module_name = f"gpucompgen_user_{Path(path).stem}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise PipelineError(f"cannot load component module {path}")
    module = sys.modules.get(module_name)
    if module is None or getattr(module, "__file__", None) != str(path):
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        spec.loader.exec_module(module)
    try:
        return getattr(module, name)
    except AttributeError:
        raise PipelineError(f"{path.name} defines no class {name}") from None


class Result(NamedTuple):
    """What run() returns: frames processed and the (freed) components, for inspection."""

    frames: int
    components: dict[str, Any]


def failing_component(exc: BaseException, components: dict[str, Any]) -> str | None:
    """Name of the component whose method raised exc (innermost wins)."""
    by_id = {id(obj): name for name, obj in components.items()}
    found = None
    tb = exc.__traceback__
    while tb is not None:
        owner = tb.tb_frame.f_locals.get("self")
        if owner is not None and id(owner) in by_id:
            found = by_id[id(owner)]
        tb = tb.tb_next
    return found


def main(run: Callable[..., Result], description: str, argv: list[str] | None = None) -> int:
    """Command line of a generated program: run it, print errors without tracebacks."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--frames", type=int, default=None, metavar="N",
                        help="stop after N frames (default: until a source ends its stream)")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    args = parser.parse_args(argv)
    if args.frames is not None and args.frames < 0:
        parser.error("--frames must be 0 or more")
    try:
        result = run(frames=args.frames)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except PipelineError as exc:
        if args.debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # a component failed: say which, without a traceback
        if args.debug:
            traceback.print_exc()
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        print("  (run with --debug for the traceback)", file=sys.stderr)
        return 1
    print(f"processed {result.frames} frame(s)", file=sys.stderr)
    return 0


def component_failure(exc: BaseException, frame: int, parts: dict[str, Any]) -> PipelineError:
    """Turn an exception raised inside the stream loop into a message naming who and when."""
    if isinstance(exc, PipelineError):
        return exc
    who = failing_component(exc, parts) or "a component"
    return PipelineError(f"{who} failed at frame {frame}: {type(exc).__name__}: {exc}")
