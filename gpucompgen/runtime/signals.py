"""SIGINT and SIGTERM stop a running program cleanly, even one blocked in OpenCL.

A Python signal handler runs only in the main thread and only between Python
instructions, so a program whose host waits on a kernel that never ends (a blocking
enqueue_copy, wait_for_events, queue.finish) never sees the signal.  Therefore main()
runs run() in a worker thread and the main thread only waits and handles signals
(StopOnSignals.run):

- the first SIGINT or SIGTERM asks the run to stop: monitor.frame_done() raises Stopped
  at the end of the frame in flight, where every component and adapter is in a
  consistent state; a run that has not got there INTERRUPT_SECONDS later (a component
  looping in Python, a slow initialize) gets Stopped raised in the worker at its next
  Python instruction, as a handler in the main thread would raise it. run() then frees
  every component (free_all) and the program reports "stopped by SIGINT after N
  frame(s); every component was freed". (Raising at once would land right after the
  blocking OpenCL call the host was waiting in, in the middle of an adapter's
  bookkeeping: an unmapped buffer still recorded as mapped, unmapped again when freed.)
- a second signal while stopping is ignored (a terminal's Ctrl-C reaches both
  'gpucompgen run' and the program, which forwards it too), and so is one arriving while
  free_all() runs: freeing is never cut short;
- if the worker has not ended GRACE_SECONDS after the signal, it is blocked outside
  Python: the main thread frees what it can (each free_memory() within a short time),
  says where the run is blocked, which kernels are still running and what could not be
  freed, and ends the process with os._exit(128 + signal).

run() called directly (tests, 'gpucompgen bench') runs in the caller's thread as before.
"""

from __future__ import annotations

import contextlib
import ctypes
import linecache
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import device_api
from .errors import Stopped

SIGNALS = (signal.SIGINT, signal.SIGTERM)
GRACE_SECONDS = 1.5  # from the signal until the program gives up on a blocked run
INTERRUPT_SECONDS = 0.5  # from the signal until a run not yet at frame_done is interrupted
FREE_SECONDS = 0.4  # then, the time the main thread spends freeing what it can

# Threads that may receive Stopped asynchronously now: a worker inside run(), not yet
# freeing. Guarded by _LOCK (reentrant: a handler may run while the main thread holds it).
_LOCK = threading.RLock()
_INTERRUPTIBLE: set[int] = set()
_STOPPED_CLASSES: dict[int, type[Stopped]] = {}


def _stopped_class(signum: int) -> type[Stopped]:
    """PyThreadState_SetAsyncExc raises a class, not an instance: one class per signal."""
    cls = _STOPPED_CLASSES.get(signum)
    if cls is None:
        def __init__(self, *args):
            Stopped.__init__(self, signum)

        cls = type("Stopped", (Stopped,), {"__init__": __init__, "__module__": __name__})
        _STOPPED_CLASSES[signum] = cls
    return cls


def _set_async(ident: int, exc: type[BaseException] | None) -> None:
    """Raise exc in thread ident at its next Python instruction (None: cancel a pending one)."""
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident),
                                               ctypes.py_object(exc) if exc else None)


def freeing() -> None:
    """Called by free_all(): from now on this thread's run is ending; a stop requested while
    it frees must not cut freeing short (the request is still reported)."""
    ident = threading.get_ident()
    with _LOCK:
        if ident in _INTERRUPTIBLE:
            _INTERRUPTIBLE.discard(ident)
            _set_async(ident, None)


def _stop_on_signals() -> Callable[[], None]:
    """In the calling (main) thread: SIGINT and SIGTERM raise Stopped once; a second
    signal while stopping is ignored. Returns the restorer. (For a run() in the main
    thread; main() uses StopOnSignals, which also stops a run blocked in OpenCL.)"""
    stopping = []

    def handler(signum, frame):
        if not stopping:
            stopping.append(signum)
            raise Stopped(signum)

    previous = {s: signal.signal(s, handler) for s in SIGNALS}

    def restore():
        for s, h in previous.items():
            signal.signal(s, h)

    return restore


class _Outcome:
    result: Any = None
    error: BaseException | None = None


class StopOnSignals:
    """Run a program's run() in a worker thread, stopping it on SIGINT and SIGTERM.

    monitor: the run's Monitor (its parts are what the main thread frees when the worker
    is blocked; its frame_done() raises Stopped once a stop is requested). exit: how the
    program ends when the run cannot be stopped (os._exit; tests pass their own).
    """

    def __init__(self, monitor, *, grace: float = GRACE_SECONDS,
                 free_seconds: float = FREE_SECONDS, exit: Callable[[int], Any] = os._exit,
                 stream=None, interrupt: float = INTERRUPT_SECONDS):
        self.monitor = monitor
        self.grace, self.free_seconds, self.exit = grace, free_seconds, exit
        self.interrupt = interrupt
        self._interrupted = False
        self.stream = stream
        self.signum: int | None = None
        self._when = 0.0
        self._worker: threading.Thread | None = None
        self._previous: dict[int, Any] = {}

    # -- signals, in the main thread ------------------------------------------------------

    def install(self) -> None:
        self._previous = {s: signal.signal(s, self._handler) for s in SIGNALS}

    def restore(self) -> None:
        """Put the previous handlers back, unless a signal came: then both signals are
        ignored from now on, so duplicates arriving while the process exits (a terminal's
        Ctrl-C forwarded by 'gpucompgen run') cannot kill it. (SIG_IGN, not a Python
        handler: Python puts the default action back for those as it finalizes.)"""
        for s, h in self._previous.items():
            signal.signal(s, h if self.signum is None else signal.SIG_IGN)

    def _handler(self, signum, frame) -> None:
        self.request_stop(signum)

    def request_stop(self, signum: int) -> None:
        """The first request counts; later ones are ignored while stopping."""
        if self.signum is not None:
            return
        self.signum, self._when = signum, time.monotonic()
        request = getattr(self.monitor, "request_stop", None)
        if request is not None:
            request(signum)

    def _interrupt(self) -> None:
        """Raise Stopped in the worker at its next Python instruction, unless it is freeing."""
        self._interrupted = True
        worker = self._worker
        if worker is not None and worker.ident is not None:
            with _LOCK:
                if worker.ident in _INTERRUPTIBLE:
                    _set_async(worker.ident, _stopped_class(self.signum))

    # -- the run ----------------------------------------------------------------------------

    def run(self, call: Callable[[], Any]) -> Any:
        """call() in a worker thread: its result, or its exception raised here.

        A run that ended normally after a stop was requested (the signal came while it
        was freeing) raises Stopped too. A run still blocked GRACE_SECONDS after the signal
        never returns from here: see _give_up.
        """
        outcome = _Outcome()
        worker = threading.Thread(target=self._work, args=(call, outcome),
                                  name="gpucompgen-run", daemon=True)
        self._worker = worker
        worker.start()
        while worker.is_alive():
            if self.signum is None:
                worker.join(0.2)  # a signal's handler runs during the wait
                continue
            now = time.monotonic()
            if not self._interrupted and now >= self._when + self.interrupt:
                self._interrupt()
            left = self._when + self.grace - now
            if left <= 0:
                self._give_up(worker)
                return None  # only where exit() returned (tests)
            worker.join(min(left, 0.05))
        error = outcome.error
        if self.signum is not None and not isinstance(error, Stopped):
            # the run ended after the signal: normally (the signal came while it was
            # freeing), or failing, where an OpenCL call the signal interrupted may fail
            raise Stopped(self.signum) from error
        if error is not None:
            raise error.with_traceback(error.__traceback__)
        return outcome.result

    def _work(self, call: Callable[[], Any], outcome: _Outcome) -> None:
        ident = threading.get_ident()
        try:
            try:
                with _LOCK:
                    _INTERRUPTIBLE.add(ident)
                    if self.signum is not None:  # a signal came before the thread ran
                        raise Stopped(self.signum)
                outcome.result = call()
            finally:
                with _LOCK:
                    _INTERRUPTIBLE.discard(ident)
                    _set_async(ident, None)
        except BaseException as exc:  # handed to the main thread, which reports it
            outcome.error = exc

    # -- a run that cannot be stopped -------------------------------------------------------

    def _give_up(self, worker: threading.Thread) -> None:
        with _LOCK:
            _INTERRUPTIBLE.discard(worker.ident)
        parts = getattr(self.monitor, "parts", None) or {}
        where = blocked_at(worker, parts)
        running = running_kernels(parts)
        freed, not_freed = free_what_can_be_freed(parts, self.free_seconds)
        try:
            self.monitor.close()  # progress line off, stdout back, --stats-json written
        except Exception as exc:  # reported, but the program still exits
            not_freed.append(f"the monitor ({type(exc).__name__}: {exc})")
        name = signal.Signals(self.signum).name
        frames = getattr(self.monitor, "frames", 0)
        lines = [(f"stopped by {name} after {frames} frame(s), but the run did not stop "
                  f"within {self.grace:g} s: it is blocked {where}")]
        if running:
            lines.append("  still running on the device: the last command of "
                         + ", ".join(running) + " (a kernel that never ends?)")
        lines.append("  freed: " + (", ".join(freed) if freed else "nothing"))
        not_freed.append("the OpenCL context and queue(s), and the memory of commands "
                         "still on the device")
        lines.append("  not freed: " + "; ".join(not_freed)
                     + " (the operating system reclaims them as the program exits)")
        stream = self.stream or sys.stderr
        with contextlib.suppress(Exception):  # a closed stream must not keep it alive
            sys.stdout.flush()
            stream.write("\n".join(lines) + "\n")
            stream.flush()
        self.exit(128 + self.signum)


def blocked_at(worker: threading.Thread, parts: dict[str, Any]) -> str:
    """Where the worker thread is now, in words: the component and the OpenCL call."""
    frame = sys._current_frames().get(worker.ident)
    if frame is None:
        return "outside Python"
    by_id = {id(obj): name for name, obj in parts.items() if obj is not None}
    api = _api_of(parts)
    innermost = frame
    component = opencl = None
    program_line = None
    while frame is not None:
        module = frame.f_globals.get("__name__", "")
        binding = api.api_frames(module)
        if binding:
            opencl = frame.f_code.co_name  # keeps the outermost frame of the API's binding
        elif component is None:
            owner = frame.f_locals.get("self")
            if owner is not None and id(owner) in by_id:
                component = f"{by_id[id(owner)]}.{frame.f_code.co_name}()"
        # the line of the generated program (or a user's module), not of the runtime's
        # adapters and kernel components that it called
        if program_line is None and not binding and module.split(".")[0] != "numpy" \
                and not module.startswith("gpucompgen.runtime"):
            program_line = frame
        frame = frame.f_back
    spot = program_line or innermost
    source = linecache.getline(spot.f_code.co_filename, spot.f_lineno).strip()
    if source.count("(") != source.count(")"):  # a statement on several lines
        source = source.split("(", 1)[0].strip() + "(...)"
    text = f"at {Path(spot.f_code.co_filename).name}:{spot.f_lineno}"
    if component:
        text += f" in {component}"
    if source:
        text += f" ({source})"
    if opencl:
        text += f", waiting in {api.NAME}'s {opencl}()"
    elif _looks_like_opencl(source):
        text += ", waiting in OpenCL"
    return text


def _api_of(parts: dict[str, Any]) -> Any:
    """The device API the run's parts use (a CUDA program's adapters and kernel components
    hold the CUDA module), else the default one."""
    for part in parts.values():
        api = getattr(part, "_api", None)
        if api is not None:
            return api
    return device_api.get()


def _looks_like_opencl(source: str) -> bool:
    return any(word in source for word in ("finish()", "wait()", "wait_for_events",
                                           "enqueue_", "cl."))


def running_kernels(parts: dict[str, Any]) -> list[str]:
    """Parts whose last device command (their .event) is running on the device now."""
    api = _api_of(parts)
    found = []
    for name, part in parts.items():
        event = getattr(part, "event", None)
        if event is None:
            continue
        try:
            running = api.is_running(event)
        except ImportError:  # no device API installed: no command can be running
            return []
        if running:
            found.append(name)
    return found


def free_what_can_be_freed(parts: dict[str, Any], seconds: float
                           ) -> tuple[list[str], list[str]]:
    """free_memory() on each part in reverse order, each in a thread of its own, all within
    about `seconds` (an equal share each, so one that hangs does not keep the others from
    being freed): (freed, not freed with why).  Only parts not freed yet (by the run's own
    free_all) and, with a Parts, initialized."""
    from .lifecycle import claim  # lifecycle imports this module

    freed, not_freed = [], []
    built = [name for name in reversed(list(parts)) if claim(parts, name)]
    share = max(seconds / max(len(built), 1), 0.02)
    for name in built:
        part = parts[name]
        errors: list[BaseException] = []

        def free(part=part, errors=errors):
            try:
                part.free_memory()
            except BaseException as exc:
                errors.append(exc)

        helper = threading.Thread(target=free, name=f"gpucompgen-free-{name}", daemon=True)
        helper.start()
        helper.join(share)
        if helper.is_alive():
            not_freed.append(f"{name} (free_memory() did not return)")
        elif errors:
            not_freed.append(f"{name} (free_memory() failed: {type(errors[0]).__name__}: "
                             f"{errors[0]})")
        else:
            freed.append(name)
    return freed, not_freed
