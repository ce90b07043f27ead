"""--trace FILE: a Chrome trace-event JSON of a run, for Perfetto (ui.perfetto.dev) or
chrome://tracing.

- process "host": a track per component and adapter; a slice per execute() or
  transfer() call, named by the part, with the frame number in its args;
- process "device": a track per OpenCL queue; a slice per kernel, copy, map and unmap,
  from the OpenCL profiling events, moved onto the host clock (below);
- each frame is followable: flow events join its slices in time order (Perfetto draws
  the arrows; clicking one follows the frame), and every slice's args name the frame;
- counters: frames in flight, and bytes copied between CPU and GPU (cumulative);
- warm-up frames (the first frames_in_flight frames, which fill the pipeline and build
  caches) are marked: their slices' args say ``"warmup": true`` and their names end in
  ``(warm-up)``.

The clocks: host times are ``time.perf_counter()``; a device event's times are the
device's.  Each event is reported while the call that enqueued it runs, so its host
enqueue time is at least that call's start: the offset is the largest
``call start - event queued`` over all events.  Device slices then start no earlier than
the call that enqueued them, and end no later than they really did (so within the frame
that waits for them).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HOST_PID, DEVICE_PID, COUNTER_PID = 1, 2, 3


class Tracer:
    """Records a run's host calls and device commands; write() makes the JSON."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.parts: dict[str, Any] = {}
        self.tids: dict[str, int] = {}
        self.calls: list[tuple] = []  # part, frame, start, end, method
        self.current: dict[str, tuple[int, float]] = {}  # part -> (frame, call start)
        self.counts: dict[tuple[str, str], int] = {}  # calls so far per part and method
        self.device: list[tuple[str, str, int, float, Any, int]] = []
        self.frames_in_flight = 1
        self.lock = threading.Lock()
        self.t0 = time.perf_counter()
        self.hooked: set[int] = set()

    # -- recording -------------------------------------------------------------------------
    def attach(self, parts: dict[str, Any]) -> None:
        self.parts = parts
        self.names = {id(obj): name for name, obj in parts.items()}
        self.tids = {name: i + 1 for i, name in enumerate(parts)}
        for name, obj in parts.items():
            # a zero-copy adapter's unmap() releases the oldest frame's view: its n-th call
            # belongs to frame n, as the n-th transfer() does
            for method in ("execute", "transfer", "unmap"):
                if hasattr(obj, method):
                    setattr(obj, method, self._traced(name, obj, getattr(obj, method),
                                                      method))

    def _traced(self, name: str, obj: Any, method: Callable, kind: str) -> Callable:
        def traced(*args, **kwargs):
            profile = getattr(obj, "profile", None)
            if profile is not None and id(profile) not in self.hooked:
                self.hooked.add(id(profile))
                profile.on_event = self.event
            frame = self.counts.get((name, kind), 0)
            self.counts[(name, kind)] = frame + 1
            start = time.perf_counter()
            before = self.current.get(name)
            self.current[name] = (frame, start)
            try:
                return method(*args, **kwargs)
            finally:
                end = time.perf_counter()
                with self.lock:
                    self.calls.append((name, frame, start, end, kind))
                if kind == "unmap" and before is not None:
                    self.current[name] = before

        return traced

    def event(self, owner: Any, what: str, event: Any, nbytes: int = 0) -> None:
        """Profile's hook: a device command of `owner`, enqueued during its current call."""
        name = self.names.get(id(owner), "?")
        frame, start = self.current.get(name, (0, time.perf_counter()))
        with self.lock:
            self.device.append((name, what, frame, start, event, nbytes))

    # -- writing ---------------------------------------------------------------------------
    def events(self) -> list[dict]:
        """The trace events (Chrome's JSON format), host and device, in time order."""
        us = 1e6
        warm = self.frames_in_flight
        out: list[dict] = [
            {"ph": "M", "name": "process_name", "pid": HOST_PID, "tid": 0,
             "args": {"name": "host (components and adapters)"}},
            {"ph": "M", "name": "process_name", "pid": DEVICE_PID, "tid": 0,
             "args": {"name": "device (OpenCL queues)"}},
            {"ph": "M", "name": "process_name", "pid": COUNTER_PID, "tid": 0,
             "args": {"name": "counters"}},
        ]
        for name, tid in self.tids.items():
            out.append({"ph": "M", "name": "thread_name", "pid": HOST_PID, "tid": tid,
                        "args": {"name": name}})
            out.append({"ph": "M", "name": "thread_sort_index", "pid": HOST_PID, "tid": tid,
                        "args": {"sort_index": tid}})

        def label(name: str, frame: int) -> str:
            return f"{name} #{frame}" + (" (warm-up)" if frame < warm else "")

        slices = []  # (ts, pid, tid, frame): every slice, for the flows
        for name, frame, start, end, kind in sorted(self.calls, key=lambda c: c[2]):
            ts = (start - self.t0) * us
            shown = name if kind != "unmap" else f"{name} unmap"
            out.append({"ph": "X", "name": label(shown, frame), "cat": "host",
                        "pid": HOST_PID, "tid": self.tids[name], "ts": ts,
                        "dur": max((end - start) * us, 0.0),
                        "args": {"frame": frame, "part": name, "warmup": frame < warm}})
            slices.append((ts, HOST_PID, self.tids[name], frame))
        # device events onto the host clock
        times = []
        for name, what, frame, start, event, nbytes in self.device:
            try:
                event.wait()
                p = event.profile
                queue = event.command_queue.int_ptr
                times.append((name, what, frame, start, p.queued, p.start, p.end, queue,
                              nbytes))
            except Exception:  # noqa: S112  (an event without profiling info: left out)
                continue
        queues: dict[int, int] = {}
        if times:
            offset = max(start - queued * 1e-9 for _, _, _, start, queued, *_ in times)
            for name, what, frame, _start, _queued, dstart, dend, queue, nbytes in times:
                tid = queues.setdefault(queue, len(queues) + 1)
                ts = (dstart * 1e-9 + offset - self.t0) * us
                args = {"frame": frame, "part": name, "warmup": frame < warm}
                if nbytes:
                    args["bytes"] = nbytes
                out.append({"ph": "X", "name": label(f"{name} {what}", frame),
                            "cat": "device", "pid": DEVICE_PID, "tid": tid, "ts": ts,
                            "dur": max((dend - dstart) * 1e-3, 0.0), "args": args})
                slices.append((ts, DEVICE_PID, tid, frame))
        for queue, tid in queues.items():
            out.append({"ph": "M", "name": "thread_name", "pid": DEVICE_PID, "tid": tid,
                        "args": {"name": f"queue {tid}"}})
        # each frame's slices joined by a flow, in time order
        by_frame: dict[int, list] = {}
        for s in sorted(slices):
            by_frame.setdefault(s[3], []).append(s)
        for frame, chain in by_frame.items():
            for i, (ts, pid, tid, _) in enumerate(chain):
                ph = "s" if i == 0 else "f" if i == len(chain) - 1 else "t"
                if len(chain) == 1:
                    break
                flow = {"ph": ph, "name": "frame", "cat": "frame", "id": frame, "pid": pid,
                        "tid": tid, "ts": ts}
                if ph != "s":
                    flow["bp"] = "e"
                out.append(flow)
        out += self._counters(times)
        return out

    def _counters(self, times: list) -> list[dict]:
        us = 1e6
        spans: dict[int, list[float]] = {}
        for _, frame, start, end, _ in self.calls:
            span = spans.setdefault(frame, [start, end])
            span[0], span[1] = min(span[0], start), max(span[1], end)
        changes = sorted([(s, 1) for s, _ in spans.values()] + [(e, -1) for _, e in
                                                                spans.values()])
        out, level = [], 0
        for t, step in changes:
            level += step
            out.append({"ph": "C", "name": "frames in flight", "pid": COUNTER_PID, "tid": 0,
                        "ts": (t - self.t0) * us, "args": {"frames": level}})
        copied = {"cpu2gpu": 0, "gpu2cpu": 0}
        for _, what, _, start, *_rest, nbytes in sorted(times, key=lambda t: t[3]):
            if what in copied and nbytes:
                copied[what] += nbytes
                out.append({"ph": "C", "name": "bytes copied", "pid": COUNTER_PID, "tid": 0,
                            "ts": (start - self.t0) * us, "args": dict(copied)})
        return out

    def write(self) -> None:
        document = {"traceEvents": self.events(), "displayTimeUnit": "ms",
                    "otherData": {"generator": "gpucompgen", "frames_in_flight":
                                  self.frames_in_flight,
                                  "warmup_frames": self.frames_in_flight}}
        self.path.write_text(json.dumps(document) + "\n", encoding="utf-8")
