"""Several frames in flight: the stages of a generated program, one thread each.

With ``platform.frames_in_flight: N`` (N >= 2) the generated ``run()`` cuts its stream loop
into stages (the plan's "frames in flight" table: sources, device work, sinks ...) and
hands them to ``stream_in_flight``.  Like GStreamer's ``queue`` element or OpenCV G-API's
streaming mode, each stage runs in its own thread and passes each frame's values to the
next through a bounded queue, so the cameras render frame f+2 while the device works on
frame f+1 and the sinks decide on frame f.

- Each stage is called by one thread, frame after frame, so every component instance is
  still called by one thread and in frame order (components need not be thread-safe);
  the last stage (the sinks) sees the frames in order.
- At most N frames are in the pipeline at once (a semaphore taken when the sources start
  a frame and given back when the last stage ends it).  The parts whose outputs cross a
  stage keep N sets of them and use set ``frame % N``, so a set is written again only once
  the frame that used it has left the pipeline.
- The first failure (an exception in any stage) stops that stage and the stages before it
  at their next step, while the stages after it finish the frames they were handed (which
  are all older than the failing one: they reach the sinks, as they would one frame at a
  time); a signal stops every stage at its next step.  The threads are joined before
  ``run()`` frees anything.  A failure is raised as
  ``FrameFailure`` carrying the frame it happened at, so ``component_failure`` names the
  component and the frame exactly as the one-frame-at-a-time loop does.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

_END = object()  # end of stream, passed down the stages
_POLL = 0.05  # seconds between looks at the stop flag while waiting


class FrameFailure(Exception):
    """A stage failed at a frame; ``component_failure`` unwraps it (the cause is the
    component's own exception, with its traceback)."""

    def __init__(self, exc: Exception, frame: int):
        super().__init__(str(exc))
        self.exc, self.frame = exc, frame


def stream_in_flight(stages: Sequence[Callable[..., Any]], frames_in_flight: int,
                     frames: int | None, monitor) -> int:
    """Run the stages over the stream; return the number of frames every stage finished.

    stages[0] takes nothing and returns the values the later stages need as a tuple, or
    None at the end of the stream; every later stage takes the values its predecessor
    returned and returns a tuple for its successor.  monitor.frame_done(n) is called in
    frame order after the last stage ends each frame, with the frame's latency (start of
    stages[0] to end of the last stage) given to monitor.frame_latency first.
    """
    return _Flight(stages, frames_in_flight, frames, monitor).run()


class _Flight:
    def __init__(self, stages, n: int, frames: int | None, monitor):
        if n < 1 or not stages:
            raise ValueError("at least one stage and one frame in flight")
        self.stages, self.n, self.frames, self.monitor = list(stages), n, frames, monitor
        self.tokens = threading.Semaphore(n)
        self.queues = [queue.Queue(maxsize=n) for _ in self.stages[1:]]
        self.stop = threading.Event()  # a signal: every stage stops
        # a failure in stage i: stages 0..i stop, the later ones drain what they were handed
        self.halted = [threading.Event() for _ in self.stages]
        self.lock = threading.Lock()
        self.failure: tuple[int, BaseException] | None = None
        self.done = 0
        if hasattr(monitor, "frames_in_flight"):
            monitor.frames_in_flight = n

    # --- waiting that gives way to a stop ------------------------------------------------
    def _stopped(self, i: int) -> bool:
        return self.stop.is_set() or self.halted[i].is_set()

    def _acquire(self) -> bool:
        while not self._stopped(0):
            if self.tokens.acquire(timeout=_POLL):
                return True
        return False

    def _get(self, i: int, q: queue.Queue):
        while not self._stopped(i):
            try:
                return q.get(timeout=_POLL)
            except queue.Empty:
                continue
        return _END

    def _put(self, i: int, q: queue.Queue, item) -> None:
        """Stage i hands item to stage i + 1 (the end of the stream even once stage i has
        stopped, unless stage i + 1 has stopped too)."""
        while (not self._stopped(i + 1)
               and (item is _END or not self.halted[i].is_set())):
            try:
                q.put(item, timeout=_POLL)
                return
            except queue.Full:
                continue

    def _fail(self, i: int, frame: int, exc: BaseException) -> None:
        """Stage i failed at frame: it and the stages before it stop; the later stages get
        the end of the stream after the frames already handed to them."""
        with self.lock:
            if self.failure is None:
                self.failure = (frame, exc)
        if not isinstance(exc, Exception):  # KeyboardInterrupt, SystemExit: stop at once
            self.stop.set()
        for j in range(i + 1):
            self.halted[j].set()
        if i < len(self.queues):
            self._put(i, self.queues[i], _END)

    # --- one thread a stage --------------------------------------------------------------
    def _source(self) -> None:
        stage, out = self.stages[0], self.queues[0] if self.queues else None
        frame = 0
        try:
            while not self.stop.is_set():
                if self.frames is not None and frame >= self.frames:
                    break
                if not self._acquire():
                    break
                start = time.perf_counter()
                values = stage()
                if values is None:  # end of stream
                    self.tokens.release()
                    break
                if out is None:
                    self._finish(frame, start)
                else:
                    self._put(0, out, (frame, start, values))
                frame += 1
            if out is not None and not self._stopped(0):
                self._put(0, out, _END)
        except BaseException as exc:
            self._fail(0, frame, exc)

    def _later(self, i: int) -> None:
        stage = self.stages[i]
        into = self.queues[i - 1]
        out = self.queues[i] if i < len(self.queues) else None
        frame = None
        try:
            while not self._stopped(i):
                item = self._get(i, into)
                if item is _END:
                    if out is not None and not self._stopped(i):
                        self._put(i, out, _END)
                    return
                frame, start, values = item
                values = stage(*values)
                if out is None:
                    self._finish(frame, start)
                else:
                    self._put(i, out, (frame, start, values))
        except BaseException as exc:
            self._fail(i, self.done if frame is None else frame, exc)

    def _finish(self, frame: int, start: float) -> None:
        """The last stage ended a frame: report it, in order, and let one more in."""
        self.done = frame + 1
        record = getattr(self.monitor, "frame_latency", None)
        if record is not None:
            record(time.perf_counter() - start)
        self.tokens.release()
        self.monitor.frame_done(self.done)

    # --- the calling thread waits, and stops everything on a signal ----------------------
    def run(self) -> int:
        threads = [threading.Thread(target=self._source, name="stage1", daemon=True)]
        threads += [threading.Thread(target=self._later, args=(i,), name=f"stage{i + 1}",
                                     daemon=True) for i in range(1, len(self.stages))]
        try:
            for t in threads:
                t.start()
            for t in threads:
                while t.is_alive():
                    t.join(_POLL)
        except BaseException:  # a signal (Stopped, KeyboardInterrupt) in this thread
            self.stop.set()
            for t in threads:
                while t.is_alive():
                    try:
                        t.join(_POLL)
                    except BaseException:  # noqa: S112 - a second signal: keep joining
                        continue
            raise
        if self.failure is not None:
            frame, exc = self.failure
            if isinstance(exc, Exception):
                raise FrameFailure(exc, frame) from exc
            raise exc
        return self.done
