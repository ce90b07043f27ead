"""SIGINT and SIGTERM stop a running program cleanly."""

from __future__ import annotations

import signal
from collections.abc import Callable

from .errors import Stopped


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
