"""Errors a generated program reports to its user, and the signal stop."""

from __future__ import annotations

import signal


class PipelineError(Exception):
    """A problem a user can act on, reported without a traceback."""


class Stopped(BaseException):
    """SIGINT or SIGTERM arrived: run() frees everything and the program exits 128 + signal."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
