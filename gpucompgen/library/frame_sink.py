"""FrameSink: a standard sink that keeps the last frame and when each frame arrived."""

from __future__ import annotations

import time

import numpy as np

from gpucompgen.runtime import Size


class FrameSink:
    def __init__(self):
        self.last: np.ndarray | None = None
        self.arrivals: list[float] = []  # time.perf_counter() at each execute

    def initialize(self, image: Size) -> None:
        self.size = image

    def execute(self, image: np.ndarray) -> None:
        self.arrivals.append(time.perf_counter())
        self.last = image

    def frame_times(self) -> np.ndarray:
        """Seconds between consecutive frames: the steady-state time per frame."""
        return np.diff(np.asarray(self.arrivals, dtype=np.float64))

    def free_memory(self) -> None:
        pass
