"""FrameSink: a standard sink that keeps the last frame and when each frame arrived, and
with ``output`` (a gpucompgen.io sink URI: ``display://``, ``out.mp4``, ``frames/``,
``mcap://out.mcap``) also writes every frame there."""

from __future__ import annotations

import time

import numpy as np

from gpucompgen.runtime import Size


class FrameSink:
    def __init__(self, *, output: str = ""):
        self.last: np.ndarray | None = None
        self.arrivals: list[float] = []  # time.perf_counter() at each execute
        self.output = output
        self.sink = None

    def initialize(self, image: Size) -> None:
        self.size = image
        if self.output:
            from gpucompgen import io

            self.sink = io.open_sink(self.output)
            self.sink.open()

    def execute(self, image: np.ndarray) -> None:
        self.arrivals.append(time.perf_counter())
        self.last = image
        if self.sink is not None:
            self.sink.write(image, "image")

    def frame_times(self) -> np.ndarray:
        """Seconds between consecutive frames: the steady-state time per frame."""
        return np.diff(np.asarray(self.arrivals, dtype=np.float64))

    def free_memory(self) -> None:
        if self.sink is not None:
            sink, self.sink = self.sink, None
            sink.close()
