"""--drop: a source read in its own thread, keeping only the newest frame.

A live camera does not wait for the pipeline: when the pipeline falls behind, frames are
lost, and it should process the newest one, not a queue of old ones.  DropFrames reads
the source as fast as it delivers and hands out the newest frame not handed out yet;
those overwritten before anyone took them are counted in ``dropped``.  The end of the
stream and errors are handed on after the frames read before them.
"""

from __future__ import annotations

import threading

import numpy as np

from .sources import Source


class DropFrames(Source):
    def __init__(self, source: Source):
        super().__init__(source.uri)
        self.source = source
        self.dropped = 0
        self.cond = threading.Condition()
        self.latest: np.ndarray | None = None
        self.ended = False
        self.error: BaseException | None = None
        self.closing = False
        self.thread: threading.Thread | None = None

    def open(self) -> tuple[int, int] | None:
        size = self.source.open()
        self.thread = threading.Thread(target=self._reader, name="drop-frames", daemon=True)
        self.thread.start()
        return size

    def _reader(self) -> None:
        try:
            while not self.closing:
                frame = self.source.read()
                with self.cond:
                    if frame is None:
                        self.ended = True
                    else:
                        if self.latest is not None:
                            self.dropped += 1
                        self.latest = frame
                    self.cond.notify_all()
                if frame is None:
                    return
        except BaseException as exc:
            with self.cond:
                self.error, self.ended = exc, True
                self.cond.notify_all()

    def read(self) -> np.ndarray | None:
        with self.cond:
            while self.latest is None and not self.ended:
                self.cond.wait(0.1)
            if self.latest is not None:
                frame, self.latest = self.latest, None
                self.frames += 1
                return frame
            if self.error is not None:
                raise self.error
            return None

    def close(self) -> None:
        self.closing = True
        if self.thread is not None:
            self.thread.join(2.0)  # a read blocked in a driver is left to end on its own
        self.source.close()
