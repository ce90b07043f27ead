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


def create_queue(context, profile: bool = False):
    """The program's command queue; with profile, one that records OpenCL event times."""
    import pyopencl as cl

    properties = cl.command_queue_properties.PROFILING_ENABLE if profile else 0
    return cl.CommandQueue(context, properties=properties)


class Profile:
    """Where the time goes: each kernel and copy of every component and adapter.

    A generated program built with ``run(profile=True)`` (``--profile`` on its command
    line) hands every part this object; parts report the OpenCL event of each kernel
    launch and copy, and the bytes each copy moves between CPU and GPU.  Event times are
    read in batches, so a long stream keeps little memory.  Without profiling a part's
    ``profile`` is None and nothing here runs.
    """

    BATCH = 4096  # events kept before their times are read

    def __init__(self, parts: dict[str, Any]):
        self.names = {id(obj): name for name, obj in parts.items()}
        self.order = list(parts)
        self.pending: list[tuple[tuple[str, str], Any]] = []
        self.seconds: dict[tuple[str, str], list[float]] = {}
        self.copies = {"cpu2gpu": 0, "gpu2cpu": 0}  # number of copies
        self.bytes = {"cpu2gpu": 0, "gpu2cpu": 0}
        for obj in parts.values():
            if hasattr(obj, "profile"):
                obj.profile = self

    def kernel(self, owner: Any, event: Any) -> None:
        self._add((self.names.get(id(owner), "?"), "kernel"), event)

    def copy(self, owner: Any, direction: str, event: Any, nbytes: int) -> None:
        self.copies[direction] += 1
        self.bytes[direction] += nbytes
        self._add((self.names.get(id(owner), "?"), direction), event)

    def _add(self, key: tuple[str, str], event: Any) -> None:
        self.pending.append((key, event))
        if len(self.pending) >= self.BATCH:
            self.collect()

    def collect(self) -> None:
        """Wait for the pending events and keep their durations."""
        for key, event in self.pending:
            event.wait()
            self.seconds.setdefault(key, []).append(
                (event.profile.end - event.profile.start) * 1e-9)
        self.pending = []

    def per_frame(self, frames: int) -> dict[str, float]:
        """Copies and bytes between CPU and GPU per frame, by direction."""
        n = max(frames, 1)
        return {f"{what}_{d}": count / n for what, table in (("copies", self.copies),
                                                            ("bytes", self.bytes))
                for d, count in table.items()}

    def report(self, frames: int) -> str:
        """A table: per part and kind, calls, median and total milliseconds."""
        import statistics

        self.collect()
        rank = {name: i for i, name in enumerate(self.order)}
        rows = [("part", "what", "calls", "median ms", "total ms")]
        total = 0.0
        for (name, what), secs in sorted(self.seconds.items(),
                                         key=lambda kv: (rank.get(kv[0][0], -1), kv[0][1])):
            total += sum(secs)
            rows.append((name, what, str(len(secs)), f"{statistics.median(secs) * 1e3:.3f}",
                         f"{sum(secs) * 1e3:.1f}"))
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        lines = ["  ".join(c.rjust(w) if i >= 2 else c.ljust(w)
                           for i, (c, w) in enumerate(zip(r, widths))).rstrip() for r in rows]
        pf = self.per_frame(frames)
        lines.append(f"device time {total * 1e3:.1f} ms over {frames} frame(s); per frame "
                     f"CPU->GPU {pf['copies_cpu2gpu']:g} copies {pf['bytes_cpu2gpu']:,.0f} "
                     f"bytes, GPU->CPU {pf['copies_gpu2cpu']:g} copies "
                     f"{pf['bytes_gpu2cpu']:,.0f} bytes")
        return "\n".join(lines)


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


def check_work_group(kernel, device, local_size: tuple[int, ...], component: str) -> None:
    """The system chose local_size for a described device; check it fits the real one."""
    import pyopencl as cl

    threads = 1
    for v in local_size:
        threads *= v
    limit = kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, device)
    dims = device.max_work_item_sizes
    if threads > limit or any(v > d for v, d in zip(local_size, dims)):
        raise PipelineError(
            f"{component}: GPU settings {local_size} ({threads} threads) do not fit device "
            f"'{device.name.strip()}' (kernel limit {limit}, per dimension {list(dims)}); "
            "rebuild for this device with 'gpucompgen build --device auto'")


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
    profile: Profile | None = None  # with run(profile=True)


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
    parser.add_argument("--profile", action="store_true",
                        help="time every kernel and copy with OpenCL profiling events and "
                             "count the bytes moved between CPU and GPU (printed at the end)")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    args = parser.parse_args(argv)
    if args.frames is not None and args.frames < 0:
        parser.error("--frames must be 0 or more")
    try:
        result = run(frames=args.frames, profile=True) if args.profile \
            else run(frames=args.frames)
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
    if result.profile is not None:
        print(result.profile.report(result.frames), file=sys.stderr)
    print(f"processed {result.frames} frame(s)", file=sys.stderr)
    return 0


def component_failure(exc: BaseException, frame: int, parts: dict[str, Any]) -> PipelineError:
    """Turn an exception raised inside the stream loop into a message naming who and when."""
    if isinstance(exc, PipelineError):
        return exc
    who = failing_component(exc, parts) or "a component"
    return PipelineError(f"{who} failed at frame {frame}: {type(exc).__name__}: {exc}")
