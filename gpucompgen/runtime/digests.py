"""--digests FILE: what every sink received and decided, frame by frame, as JSON lines.

A sink is a component whose execute() returns nothing. For each of its calls one line is
written (and flushed, so a run that fails or is stopped keeps the frames before it):

    {"part": "manager", "frame": 0, "inputs": ["480x1280x1 uint8 blake2b:9f2c..."],
     "report": {"action": "forward", ...}}

- inputs: per argument, its shape, dtype and a BLAKE2b digest of its bytes (C order), so
  two runs that gave a sink the same frames give the same lines;
- report: what the sink decided, where it says so: a component may define report(),
  called after each execute(), returning a JSON-serialisable value (VisionManager returns
  its decision); absent otherwise.

`gpucompgen replay` reads these lines to compare a changed pipeline with a baseline. The
digests cost one pass over each sink input (about 1 ms a megabyte); without --digests no
component is wrapped.
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import numpy as np

DIGEST_BYTES = 16


def frame_digest(value: Any) -> str:
    """'HxWxC dtype blake2b:HEX' for an array; a JSON text's digest for anything else."""
    if isinstance(value, np.ndarray):
        if value.ndim == 3 and value.shape[2] == 1:  # (H, W, 1) is the same frame as (H, W)
            value = value[:, :, 0]
        shape = "x".join(str(n) for n in value.shape) or "scalar"
        data = np.ascontiguousarray(value)
        digest = hashlib.blake2b(memoryview(data).cast("B"), digest_size=DIGEST_BYTES)
        return f"{shape} {value.dtype} blake2b:{digest.hexdigest()}"
    text = json.dumps(value, sort_keys=True, default=repr)
    digest = hashlib.blake2b(text.encode("utf-8"), digest_size=DIGEST_BYTES)
    return f"{type(value).__name__} blake2b:{digest.hexdigest()}"


class DigestRecorder:
    """Wraps the execute() of every part; writes a line for each call that returns None."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._out: TextIO | None = None
        self._lock = threading.Lock()  # with frames in flight, sinks run in several threads
        self._frames: dict[str, int] = {}

    def open(self) -> None:
        self._out = open(self.path, "w", encoding="utf-8")  # noqa: SIM115  (closed by close())

    def wrap(self, parts: dict[str, Any]) -> None:
        for name, obj in parts.items():
            if hasattr(obj, "execute") and not hasattr(obj, "transfer"):
                obj.execute = self._recording(name, obj, obj.execute)

    def _recording(self, name: str, obj: Any, method: Callable) -> Callable:
        report = getattr(obj, "report", None)

        def recording(*args, **kwargs):
            result = method(*args, **kwargs)
            if result is None:
                self._write(name, [*args, *kwargs.values()],
                            report() if callable(report) else None, callable(report))
            return result

        return recording

    def _write(self, name: str, inputs: list, report: Any, reports: bool) -> None:
        line: dict[str, Any] = {"part": name, "inputs": [frame_digest(v) for v in inputs]}
        if reports:
            line["report"] = report
        with self._lock:
            line["frame"] = self._frames.get(name, 0)
            self._frames[name] = line["frame"] + 1
            text = json.dumps(line, sort_keys=True, default=repr)
            if self._out is not None:
                self._out.write(text + "\n")
                self._out.flush()

    def close(self) -> None:
        with self._lock:
            out, self._out = self._out, None
        if out is not None:
            out.close()
