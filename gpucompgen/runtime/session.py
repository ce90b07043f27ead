"""Session: what every generated run() does around its own lines, written once.

A generated program keeps every transfer, launch setting and size a visible line of its
own; what is the same in every program lives here: the monitor and the checked parameter
values, the parts filled in as they are constructed, the profiler, the frame count, a
failure turned into a message naming the component and the frame, and freeing every part
that was initialized (in reverse order) and closing the monitor, whatever happened::

    session = runtime.Session(PARAMS, params, monitor, profile, ['source', 'blur', ...])
    ...  # context, queues, memory check, programs
    with session:  # a failure names its component and frame; every part is freed
        parts = session.parts
        source = parts['source'] = ...
        session.start()  # the monitor and the profiler see the parts
        ...  # initialize, config_gpu
        while frames is None or session.frame < frames:
            ...
            session.frame_done()
    return session.result()
"""

from __future__ import annotations

from .lifecycle import Parts, Result, component_failure, free_all
from .monitor import Monitor
from .overrides import param_values
from .profiling import Profile


class Session:
    """One run() of a generated program (see the module's docstring)."""

    def __init__(self, table: dict, params: dict | None, monitor: Monitor | None,
                 profile: bool, names: list[str]):
        self.monitor = monitor or Monitor(progress=False)
        self.params = param_values(table, params)  # checked against PARAMS' declarations
        self.parts = Parts(names)  # every planned name, None until constructed
        self.profile = profile
        self.profiler: Profile | None = None
        self.frame: int | None = None  # None while constructing and initializing

    def __enter__(self):
        return self

    def start(self) -> None:
        """Every part is constructed: the monitor and the profiler see them."""
        self.monitor.attach(self.parts)
        self.profiler = Profile(self.parts) if self.profile else None
        self.frame = None

    def frame_done(self) -> None:
        """One more frame processed (the monitor raises Stopped once a stop was asked)."""
        self.frame = (self.frame or 0) + 1
        self.monitor.frame_done(self.frame)

    def __exit__(self, kind, exc, traceback) -> bool:
        try:
            if isinstance(exc, Exception):
                raise component_failure(exc, self.frame, self.parts) from exc
        finally:
            free_all(self.parts)  # free_memory() on each initialized part, in reverse order
            self.monitor.close()
        return False

    def result(self) -> Result:
        """What run() returns: frames processed, the (freed) parts, the profile."""
        return Result(self.frame or 0, self.parts, self.profiler)


__all__ = ["Session"]
