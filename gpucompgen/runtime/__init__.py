"""The small runtime that generated programs import.

It holds what every generated program needs and nothing of the generator: device
selection, program building with readable errors, size checks, the command line of a
generated program.  It imports pyopencl and numpy only.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import os
import signal
import sys
import time
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple


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
        with quiet_compiler():
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


class Profile:
    """Where the time goes: each kernel and copy of every component and adapter.

    A generated program built with ``run(profile=True)`` (``--profile`` on its command
    line) hands every part this object; parts report the OpenCL event of each kernel
    launch and copy, and the bytes each copy moves between CPU and GPU; zero-copy
    adapters report their map and unmap commands, which move no bytes.  Event times are
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
        self.maps = 0  # zero-copy maps of device buffers for the host
        for obj in parts.values():
            if hasattr(obj, "profile"):
                obj.profile = self

    def kernel(self, owner: Any, event: Any) -> None:
        self._add((self.names.get(id(owner), "?"), "kernel"), event)

    def copy(self, owner: Any, direction: str, event: Any, nbytes: int) -> None:
        self.copies[direction] += 1
        self.bytes[direction] += nbytes
        self._add((self.names.get(id(owner), "?"), direction), event)

    def mapping(self, owner: Any, what: str, event: Any) -> None:
        """A zero-copy adapter's map or unmap: device time, but no bytes copied."""
        if what == "map":
            self.maps += 1
        self._add((self.names.get(id(owner), "?"), what), event)

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
        if self.maps:
            lines[-1] += f"; {self.maps / max(frames, 1):g} zero-copy maps"
        return "\n".join(lines)


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


def build_program(context, path: Path, component: str, options: tuple[str, ...] = ()):
    """Build one kernel file once; a failure names the component, file and build log."""
    import pyopencl as cl

    try:
        source = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise PipelineError(f"{component}: cannot read kernel file {path}: {exc.strerror}") \
            from None
    try:
        with quiet_compiler():
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


def load_module(path: Path, module_name: str, fresh: bool = True):
    """Import a Python file as a module: a generated program, or a user's component file.

    With fresh=False a module already imported from the same file is reused.
    """
    module = sys.modules.get(module_name)
    if not fresh and module is not None and getattr(module, "__file__", None) == str(path):
        return module
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise PipelineError(f"cannot load module {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module


def load_class(path: Path, name: str) -> type:
    """Load a user's standard component class from a file copied beside the program."""
    module = load_module(path, f"gpucompgen_user_{Path(path).stem}", fresh=False)
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


def component_failure(exc: BaseException, frame: int | None,
                      parts: dict[str, Any]) -> PipelineError:
    """Turn an exception raised by run() into a message naming who and when.

    frame is None while the components are being constructed, initialized and
    configured; parts maps every planned name to its object, None until constructed, so
    a constructor that raises is the first name still None.
    """
    who = failing_component(exc, parts)
    when = "while initializing" if frame is None else f"at frame {frame}"
    if who is None and frame is None:
        unbuilt = next((name for name, obj in parts.items() if obj is None), None)
        if unbuilt is not None:
            who, when = unbuilt, "while constructing"
    if isinstance(exc, PipelineError):
        text = str(exc)
        if who is None or text.startswith((f"{who}:", f"{who} ")):
            return exc
        return PipelineError(f"{who} failed {when}: {text}")
    return PipelineError(f"{who or 'a component'} failed {when}: {type(exc).__name__}: {exc}")


def free_all(parts: dict[str, Any]) -> None:
    """free_memory() on every part in reverse order; one failing does not stop the others.

    When run() is already failing, failures to free are printed as notes so the first
    error stays the one reported; otherwise they raise one PipelineError naming them all.
    """
    failed = []
    for name in reversed(list(parts)):
        if parts[name] is None:  # never constructed
            continue
        try:
            parts[name].free_memory()
        except Exception as exc:
            failed.append(f"{name}.free_memory() failed: {type(exc).__name__}: {exc}")
    if not failed:
        return
    if sys.exc_info()[1] is not None:
        for line in failed:
            print(f"note: {line}", file=sys.stderr)
        return
    raise PipelineError("; ".join(failed) + " (every other component was freed)")


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


class Stopped(BaseException):
    """SIGINT or SIGTERM arrived: run() frees everything and the program exits 128 + signal."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _ClearsProgress:
    """sys.stdout while a progress line is shown: whatever a component prints first clears
    the line (it is redrawn with the next frame), so the two never share a line."""

    def __init__(self, stdout, monitor: Monitor):
        self._stdout, self._monitor = stdout, monitor

    def write(self, text: str) -> int:
        self._monitor.clear_progress()
        return self._stdout.write(text)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stdout, name)


class Monitor:
    """What a run reports besides the components' own output, and the runtime options.

    - progress: frames and frames/s on one redrawn stderr line, only on a terminal (lines
      the components print to stdout clear it first);
    - stats: with stats_path, host wall time around every execute() and transfer(),
      written as JSON when the run ends (fields: see write_stats); without it the
      components are not wrapped and the stream loop pays one call per frame;
    - options: runtime options (e.g. {"decisions": "out.jsonl"}) handed to each component
      that declares them in RUNTIME_OPTIONS and takes them in runtime_options(options).
    """

    def __init__(self, *, progress: bool | None = None, stats_path: str | Path | None = None,
                 options: dict[str, Any] | None = None, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        if progress is None:
            progress = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.progress = progress
        self.stats_path = Path(stats_path) if stats_path else None
        self.options = dict(options or {})
        self.frames = 0
        self.parts: dict[str, Any] = {}
        self.calls: dict[str, list[float]] | None = None
        self.frame_seconds: list[float] = []
        self._started = time.perf_counter()
        self._frame_start: float | None = None
        self._drawn = 0.0  # when the progress line was last drawn
        self._shown = False  # whether it is on the screen now
        self._stdout = None  # the real sys.stdout while _ClearsProgress stands in

    def attach(self, parts: dict[str, Any]) -> None:
        """Called by run() once every component and adapter is constructed."""
        self.parts = parts
        self._give_options(parts)
        if self.progress and self._stdout is None:
            self._stdout = sys.stdout
            sys.stdout = _ClearsProgress(sys.stdout, self)
        if self.stats_path is not None:
            self.calls = {name: [] for name in parts}
            for name, obj in parts.items():
                for method in ("execute", "transfer"):
                    if hasattr(obj, method):
                        setattr(obj, method, self._timed(name, getattr(obj, method)))
        self._started = time.perf_counter()

    def _give_options(self, parts: dict[str, Any]) -> None:
        given = {k: v for k, v in self.options.items() if v not in (None, False, "")}
        taken = set()
        for obj in parts.values():
            wanted = set(getattr(obj, "RUNTIME_OPTIONS", ()))
            if wanted:
                obj.runtime_options({k: v for k, v in self.options.items() if k in wanted})
                taken |= wanted
        unused = sorted(set(given) - taken - {"quiet"})
        if unused:
            raise PipelineError(
                f"no component of this system takes --{unused[0].replace('_', '-')}")

    def _timed(self, name: str, method: Callable) -> Callable:
        record = self.calls[name]

        def timed(*args, **kwargs):
            start = time.perf_counter()
            if self._frame_start is None:
                self._frame_start = start
            try:
                return method(*args, **kwargs)
            finally:
                record.append(time.perf_counter() - start)

        return timed

    def frame_done(self, frames: int) -> None:
        """Called by run() after each frame with the number of frames processed so far."""
        self.frames = frames
        if self.calls is not None or self.progress:
            now = time.perf_counter()
            if self.calls is not None and self._frame_start is not None:
                self.frame_seconds.append(now - self._frame_start)
                self._frame_start = None
            if self.progress and now - self._drawn >= 0.5:
                self._drawn = now
                rate = frames / max(now - self._started, 1e-9)
                if self._stdout is not None:
                    self._stdout.flush()  # what components printed comes first
                self.stream.write(f"\r{frames} frames, {rate:.1f} frames/s \033[K")
                self.stream.flush()
                self._shown = True

    def clear_progress(self) -> None:
        """Take the progress line off the screen (it returns with the next frame)."""
        if self._shown:
            self._shown = False
            self._drawn = 0.0  # redraw at the next frame
            self.stream.write("\r\033[K")
            self.stream.flush()

    def close(self) -> None:
        """Called by run() after everything is freed, whether or not it failed."""
        if self._stdout is not None:
            sys.stdout, self._stdout = self._stdout, None
        self.clear_progress()
        if self.stats_path is not None:
            self.write_stats(self.stats_path)

    def stats(self) -> dict[str, Any]:
        """The --stats-json document. Times are host wall-clock seconds.

        frames: frames processed; wall_seconds: from the end of construction to the end of
        the run (initialize included); frames_per_second: frames / wall_seconds;
        frame_seconds: per frame, from the first execute() or transfer() of the frame to its
        end; components: per component and adapter, in run order, the calls made and the
        total, mean and max seconds spent in execute() or transfer(). For a GPU-aware
        component that is the time to enqueue its kernel: the kernel's own time shows in
        the next blocking transfer (or with the OpenCL profiling events, not here).
        """
        wall = time.perf_counter() - self._started
        components = {}
        for name, times in (self.calls or {}).items():
            components[name] = {
                "calls": len(times),
                "total_seconds": sum(times),
                "mean_seconds": sum(times) / len(times) if times else 0.0,
                "max_seconds": max(times, default=0.0),
            }
        return {
            "frames": self.frames,
            "wall_seconds": wall,
            "frames_per_second": self.frames / wall if wall > 0 else 0.0,
            "frame_seconds": list(self.frame_seconds),
            "components": components,
        }

    def write_stats(self, path: Path) -> None:
        try:
            path.write_text(json.dumps(self.stats(), indent=2) + "\n", encoding="utf-8")
        except OSError as exc:
            print(f"error: cannot write stats to {path}: {exc.strerror}", file=sys.stderr)


def _stop_on_signals() -> Callable[[], None]:
    """SIGINT and SIGTERM raise Stopped once (run() then frees everything); a second
    signal while stopping is ignored so freeing is not cut short. Returns the restorer."""
    stopping = []

    def handler(signum, frame):
        if not stopping:
            stopping.append(signum)
            raise Stopped(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

    def restore():
        for s, h in previous.items():
            signal.signal(s, h)

    return restore


def add_program_options(parser: argparse.ArgumentParser) -> None:
    """The generated program's options; 'gpucompgen run' offers the same and passes them on."""
    parser.add_argument("--frames", type=int, default=None, metavar="N",
                        help="stop after N frames (default: until a source ends its stream)")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="print nothing but errors (no progress, decisions or summary)")
    parser.add_argument("--stats-json", metavar="FILE",
                        help="time every execute() and transfer() and write frames, "
                             "per-frame and per-component timings to FILE as JSON")
    parser.add_argument("--decisions", metavar="FILE",
                        help="write the sinks' decisions to FILE: JSON lines if it ends in "
                             ".jsonl or .json, else one text line per frame")
    parser.add_argument("--save-images", metavar="DIR",
                        help="write the sinks' images (masks, annotated frames) as PNG to DIR")
    parser.add_argument("--profile", action="store_true",
                        help="time every kernel and copy with OpenCL profiling events and "
                             "count the bytes moved between CPU and GPU (printed at the end)")


def main(run: Callable[..., Result], description: str, argv: list[str] | None = None) -> int:
    """Command line of a generated program: run it, print errors without tracebacks.

    Exit codes: 0 done, 1 a component or the device failed, 2 usage, 130 SIGINT,
    143 SIGTERM (128 + the signal's number).
    """
    parser = argparse.ArgumentParser(
        description=description,
        epilog="Exit codes: 0 done, 1 a component or the device failed, 2 usage, "
               "130 on SIGINT, 143 on SIGTERM. Select the OpenCL device with PYOPENCL_CTX.")
    add_program_options(parser)
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    args = parser.parse_args(argv)
    if args.frames is not None and args.frames < 0:
        parser.error("--frames must be 0 or more")
    monitor = Monitor(progress=False if args.quiet else None, stats_path=args.stats_json,
                      options={"decisions": args.decisions, "save_images": args.save_images,
                               "quiet": args.quiet})
    restore = _stop_on_signals()
    try:
        result = run(frames=args.frames, monitor=monitor, profile=args.profile)
    except Stopped as exc:
        print(f"stopped by {exc} after {monitor.frames} frame(s); every component was freed",
              file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f"interrupted after {monitor.frames} frame(s)", file=sys.stderr)
        return 130
    except PipelineError as exc:
        if args.debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # a bug outside any component: still no traceback by default
        if args.debug:
            traceback.print_exc()
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        print("  (run with --debug for the traceback)", file=sys.stderr)
        return 1
    finally:
        restore()
    if result.profile is not None:
        print(result.profile.report(result.frames), file=sys.stderr)
    if not args.quiet:
        print(f"processed {result.frames} frame(s)", file=sys.stderr)
    return 0
