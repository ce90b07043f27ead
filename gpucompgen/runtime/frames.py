"""Frames checked where they cross components: shape and element type, named by producer.

A standard component returns numpy arrays the system cannot see at build time. Where such
an array enters another component or an adapter, the generated program checks it against
the size and element type propagated at build time, so that a transposed frame with the
right byte count, a float32 frame on a uint8 port, a narrower frame or a None returned
mid-stream is reported at once, naming the producing component and port, instead of
being copied as bytes or failing somewhere downstream.
"""

from __future__ import annotations

from typing import Any

from .errors import PipelineError


class FrameError(PipelineError):
    """A part returned a frame that does not match the system; component names the part."""

    def __init__(self, what: str, message: str):
        super().__init__(f"{what}: {message}")
        self.component = what.split(".", 1)[0]


def _shown(shape: tuple[int, ...]) -> str:
    return "x".join(str(v) for v in shape) if shape else "a scalar"


def check_frame(what: str, value: Any, shape: tuple[int, ...], dtype: Any) -> Any:
    """Return value when it is an array of exactly shape and dtype, else raise.

    what is 'component.port'; shape is (height, width) for one channel, else
    (height, width, channels), as runtime.Size.shape gives.
    """
    import numpy as np

    expected = f"{_shown(shape)} {np.dtype(dtype).name}"
    if value is None:
        raise FrameError(what,
            f"execute() returned None mid-stream where a {expected} frame was "
            "expected; only a source (a component without inputs) may end the stream by "
            "returning None")
    if not isinstance(value, np.ndarray):
        raise FrameError(what,
            f"execute() returned {type(value).__name__} where a numpy array "
            f"{expected} was expected")
    if value.shape != tuple(shape) or value.dtype != np.dtype(dtype):
        got = f"{_shown(value.shape)} {value.dtype.name}"
        hint = ""
        if value.shape != tuple(shape) and sorted(value.shape) == sorted(shape):
            hint = " (transposed? arrays are height x width x channels)"
        elif value.shape == tuple(shape):
            hint = f" (convert with .astype(np.{np.dtype(dtype).name}))"
        raise FrameError(what, f"execute() returned a {got} frame where the system was "
                               f"built for {expected}{hint}")
    return read_only(value)


def read_only(array: Any) -> Any:
    """A view of array that cannot be written: what every component gets as an input.

    Several readers of one producer get the same frame; one that wrote into it would
    change what the others read.  A write raises ValueError ('assignment destination is
    read-only'), reported as that component's failure with READ_ONLY_HINT.  The producer
    keeps its own (writable) array; the view costs no copy."""
    view = array.view()
    view.flags.writeable = False
    return view


READ_ONLY_HINT = ("inputs are read-only to components (another reader gets the same "
                  "frame): copy it first (image = image.copy()) or write into an array of "
                  "your own")
