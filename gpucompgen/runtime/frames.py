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
    (height, width, channels), as runtime.Size.shape gives.  A one-channel frame may also
    come as height x width x 1 (as many libraries give one-channel images): it is
    returned as the height x width view of the same memory, never copied.

    Called once a frame for every frame a CPU part hands on: the accepted case costs a
    type test, two comparisons and a read-only view (read_only); the message is composed
    only for a wrong frame.
    """
    if type(value) is _ndarray() and value.dtype == dtype:
        if value.shape == shape:
            return read_only(value)  # every reader gets the same frame: none may write it
        if len(shape) == 2 and value.shape == (*shape, 1):
            return read_only(value.reshape(shape))  # drops a length-1 axis: a view
    return _refuse(what, value, shape, dtype)


def _ndarray():
    """numpy.ndarray, imported on first use (the generator imports runtime without it)."""
    global _NDARRAY
    if _NDARRAY is None:
        import numpy as np

        _NDARRAY = np.ndarray
    return _NDARRAY


_NDARRAY = None


def _refuse(what: str, value: Any, shape: tuple[int, ...], dtype: Any) -> Any:
    """check_frame's slow path: a subclass of ndarray passes, anything else raises."""
    import numpy as np

    shape = tuple(shape)
    if isinstance(value, np.ndarray) and value.dtype == np.dtype(dtype):
        if value.shape == shape:
            return read_only(value)
        if len(shape) == 2 and value.shape == (*shape, 1):
            return read_only(value.reshape(shape))
    expected = f"{_shown(shape)} {np.dtype(dtype).name}"
    if len(shape) == 2:
        expected += " (or " + _shown((*shape, 1)) + ")"
    if value is None:
        raise FrameError(what,
            f"execute() returned None mid-stream where a {expected} frame was "
            "expected; only a source (a component without inputs) may end the stream by "
            "returning None")
    if not isinstance(value, np.ndarray):
        raise FrameError(what,
            f"execute() returned {type(value).__name__} where a numpy array "
            f"{expected} was expected")
    got = f"{_shown(value.shape)} {value.dtype.name}"
    hint = ""
    if value.shape != shape and sorted(value.shape) == sorted(shape):
        hint = " (transposed? arrays are height x width x channels)"
    elif value.shape in (shape, (*shape, 1)):
        hint = f" (convert with .astype(np.{np.dtype(dtype).name}))"
    raise FrameError(what, f"execute() returned a {got} frame where the system was "
                           f"built for {expected}{hint}")


def read_only(array: Any) -> Any:
    """A view of array that cannot be written: what every component gets as an input.

    Several readers of one producer get the same frame; one that wrote into it would
    change what the others read.  A write raises ValueError ('assignment destination is
    read-only'), reported as that component's failure with READ_ONLY_HINT.  The producer
    keeps its own (writable) array; the view costs no copy.  An array that is already
    read-only (the frame a component or the loop's check handed on) is returned as is:
    one view a frame, not one a reader."""
    if not array.flags.writeable:
        return array
    view = array.view()
    view.flags.writeable = False
    return view


READ_ONLY_HINT = ("inputs are read-only to components (another reader gets the same "
                  "frame): copy it first (image = image.copy()) or write into an array of "
                  "your own")
