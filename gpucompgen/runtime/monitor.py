"""Progress, --stats-json timings and runtime options of a running program."""

from __future__ import annotations

import errno
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .errors import PipelineError, Stopped


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
                 options: dict[str, Any] | None = None, stream=None,
                 trace_path: str | Path | None = None):
        self.stream = stream if stream is not None else sys.stderr
        if progress is None:
            progress = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.progress = progress
        self.stats_path = Path(stats_path) if stats_path else None
        self.stats_failed = False  # --stats-json could not be written: exit 1
        self.options = dict(options or {})
        self.frames = 0
        self.parts: dict[str, Any] = {}
        self.calls: dict[str, list[float]] | None = None
        self.frame_seconds: list[float] = []
        self.frames_in_flight = 1  # set by the stages' runner (runtime.pipeline)
        self._latency_given = False  # frame_latency() measures frames, not the wrappers
        self._started = time.perf_counter()
        self._frame_start: float | None = None
        self._drawn = 0.0  # when the progress line was last drawn
        self._shown = False  # whether it is on the screen now
        self._stdout = None  # the real sys.stdout while _ClearsProgress stands in
        self.stop_signal: int | None = None  # set by request_stop (SIGINT, SIGTERM)
        self._closed = False
        self.tracer = None  # --trace FILE (runtime.trace)
        if trace_path:
            from .trace import Tracer

            self.tracer = Tracer(trace_path)
        self.digests = None  # a DigestRecorder with the 'digests' option (--digests FILE)

    def attach(self, parts: dict[str, Any]) -> None:
        """Called by run() once every component and adapter is constructed."""
        self.parts = parts
        self._give_options(parts)
        if self.options.get("digests"):
            from .digests import DigestRecorder

            self.digests = DigestRecorder(self.options["digests"])
            try:
                self.digests.open()
            except OSError as exc:
                self.digests = None
                raise PipelineError(f"cannot write digests to {self.options['digests']}: "
                                    f"{exc.strerror}") from None
            self.digests.wrap(parts)
        if self.progress and self._stdout is None:
            self._stdout = sys.stdout
            sys.stdout = _ClearsProgress(sys.stdout, self)
        if self.stats_path is not None:
            self.calls = {name: [] for name in parts}
            for name, obj in parts.items():
                for method in ("execute", "transfer"):
                    if hasattr(obj, method):
                        setattr(obj, method, self._timed(name, getattr(obj, method)))
        if self.tracer is not None:
            self.tracer.attach(parts)
        self._started = time.perf_counter()

    def _give_options(self, parts: dict[str, Any]) -> None:
        given = {k: v for k, v in self.options.items() if v not in (None, False, "")}
        taken = set()
        for obj in parts.values():
            wanted = set(getattr(obj, "RUNTIME_OPTIONS", ()))
            if wanted:
                obj.runtime_options({k: v for k, v in self.options.items() if k in wanted})
                taken |= wanted
        unused = sorted(set(given) - taken - {"quiet", "digests"})  # the runtime's own
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

    def frame_latency(self, seconds: float) -> None:
        """With frames in flight: the latency of the frame about to be reported done (start
        of its sources to end of its last sink), measured by the stages' runner; frames
        overlap, so the wrappers' first-call-of-the-frame clock cannot measure it."""
        self._latency_given = True
        if self.calls is not None:
            self.frame_seconds.append(seconds)

    def request_stop(self, signum: int) -> None:
        """Ask the run to stop: the next frame_done() raises Stopped (runtime.main calls
        this on SIGINT and SIGTERM)."""
        self.stop_signal = signum

    def frame_done(self, frames: int) -> None:
        """Called by run() after each frame with the number of frames processed so far.

        Raises Stopped once a stop was requested, which ends the stream loop; run() then
        frees everything.
        """
        self.frames = frames
        if self.stop_signal is not None:
            raise Stopped(self.stop_signal)
        if self.calls is not None or self.progress:
            now = time.perf_counter()
            if self._latency_given:
                self._frame_start = None
            elif self.calls is not None and self._frame_start is not None:
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
        """Called by run() after everything is freed, whether or not it failed; once (the
        main thread giving up on a blocked run calls it too)."""
        if self._closed:
            return
        self._closed = True
        if self._stdout is not None:
            sys.stdout, self._stdout = self._stdout, None
        self.clear_progress()
        if self.digests is not None:
            self.digests.close()
        if self.stats_path is not None:
            self.write_stats(self.stats_path)
        if self.tracer is not None:
            self.tracer.frames_in_flight = self.frames_in_flight
            try:
                self.tracer.write()
            except OSError as exc:
                self.stats_failed = True
                print(f"error: cannot write the trace to {self.tracer.path}: "
                      f"{exc.strerror}", file=sys.stderr)

    def stats(self) -> dict[str, Any]:
        """The --stats-json document. Times are host wall-clock seconds.

        frames: frames processed; wall_seconds: from the end of construction to the end of
        the run (initialize included); frames_per_second: frames / wall_seconds;
        frame_seconds: per frame, its latency: from the first execute() or transfer() of the
        frame (its sources) to its end (its last sink); latency_seconds: their median, 95th
        percentile, mean and max; frames_in_flight: frames the program worked on at the same
        time (with 2 or more, frames overlap: frames/s rises, and so may latency); components: per component and adapter, in run order, the calls made and the
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
            "frames_in_flight": self.frames_in_flight,
            "latency_seconds": latency_summary(self.frame_seconds),
            "frame_seconds": list(self.frame_seconds),
            "components": components,
            "dropped_frames": self.dropped_frames(),
        }

    def dropped_frames(self) -> dict[str, int]:
        """Frames each source dropped because the pipeline fell behind (--drop)."""
        return {name: obj.dropped_frames for name, obj in self.parts.items()
                if isinstance(getattr(obj, "dropped_frames", None), int)}

    def write_stats(self, path: Path) -> None:
        """Write the --stats-json document.  Opened without blocking: a FIFO that no
        process reads is an error here, not a run that never ends."""
        text = json.dumps(self.stats(), indent=2) + "\n"
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NONBLOCK, 0o666)
        except OSError as exc:
            self.stats_failed = True  # the run's exit code says so
            why = ("it is a FIFO that no process reads" if exc.errno == errno.ENXIO
                   else exc.strerror)
            print(f"error: cannot write stats to {path}: {why}", file=sys.stderr)
            return
        try:
            os.set_blocking(fd, True)  # a reader is there: it takes the document
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
        except OSError as exc:
            self.stats_failed = True
            print(f"error: cannot write stats to {path}: {exc.strerror}", file=sys.stderr)


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0..100) of values, linearly interpolated (numpy's default)."""
    if not values:
        return 0.0
    ordered = sorted(values)
    pos = (len(ordered) - 1) * q / 100
    low = int(pos)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (pos - low)


def latency_summary(seconds: list[float]) -> dict[str, float]:
    """Median, 95th percentile, mean and max of per-frame latencies, in seconds."""
    return {
        "median": percentile(seconds, 50),
        "p95": percentile(seconds, 95),
        "mean": sum(seconds) / len(seconds) if seconds else 0.0,
        "max": max(seconds, default=0.0),
    }
