"""CPU forms of channels.yaml's and magnitude.yaml's types.

As in cpu_ops.py: the inputs as the ports declare them (one channel: height x width or
height x width x 1), the type's parameters as keywords, ``out=`` an array to write into,
the output returned.  ExtractChannel and MergeChannels2/3/4 are OpenCV's
cv2.extractChannel and cv2.merge; Magnitude is numpy's float32 arithmetic, the kernel's
(OpenCV's cv2.magnitude does not round its square root correctly: it differs by at most 2
units in the last place, docs/library.md).  tests/test_ops_channels.py compares each with
the generated kernel, OpenCV and hand-computed values.  CPU_CHANNELS maps each type's name
to its function (cpu_kernels.CPU_IMPLEMENTATIONS includes them).  Imports nothing of the
generator.
"""

from __future__ import annotations

import cv2
import numpy as np

DTYPES = (np.uint8, np.int16, np.float32)


def extract_channel(src: np.ndarray, *, channel: int,
                    out: np.ndarray | None = None) -> np.ndarray:
    """ExtractChannel: cv2.extractChannel(src, channel), height x width."""
    channels = _frame("ExtractChannel", "src", src)
    channel = int(channel)
    if not 0 <= channel < channels:
        raise ValueError(f"ExtractChannel: channel must be 0..{channels - 1} for a frame of "
                         f"{channels} channels, not {channel}")
    if channels == 1:  # OpenCV's extractChannel of one channel is the frame itself
        return _copy(src.reshape(src.shape[:2]), out, "ExtractChannel")
    return cv2.extractChannel(src, channel, dst=_output(out, src.shape[:2], "ExtractChannel",
                                                        "dst", src.dtype))


def merge_channels(src1: np.ndarray, src2: np.ndarray, src3: np.ndarray | None = None,
                   src4: np.ndarray | None = None, *,
                   out: np.ndarray | None = None) -> np.ndarray:
    """MergeChannels2/3/4: cv2.merge([src1, src2, ...]), height x width x n."""
    planes = [p for p in (src1, src2, src3, src4) if p is not None]
    name = f"MergeChannels{len(planes)}"
    for i, plane in enumerate(planes):
        if _frame(name, f"src{i + 1}", plane) != 1:
            raise ValueError(f"{name}: 'src{i + 1}' must have one channel, not {plane.shape}")
    flat = [p.reshape(p.shape[:2]) for p in planes]
    if len({(p.shape, p.dtype) for p in flat}) != 1:
        raise ValueError(f"{name}: the frames must have the same size and element type, "
                         f"not {[(p.shape, p.dtype.name) for p in flat]}")
    shape = flat[0].shape + (len(flat),)
    return cv2.merge(flat, dst=_output(out, shape, name, "dst", flat[0].dtype))


def magnitude(src1: np.ndarray, src2: np.ndarray, *,
              out: np.ndarray | None = None) -> np.ndarray:
    """Magnitude: sqrt(a * a + b * b) in float32 (each square and the sum rounded to
    float32, the square root correctly rounded: the kernel's bytes); cv2.magnitude of the
    same float32 frames differs by at most 2 units in the last place."""
    for port, array in (("src1", src1), ("src2", src2)):
        if getattr(array, "dtype", None) not in (np.int16, np.float32):
            raise TypeError(f"Magnitude: '{port}' must be an int16 or float32 numpy array, "
                            f"not {getattr(array, 'dtype', type(array).__name__)}")
        _frame("Magnitude", port, array)
    if src1.shape != src2.shape or src1.dtype != src2.dtype:
        raise ValueError(f"Magnitude: src1 and src2 must have the same size and element "
                         f"type, not {src1.shape} {src1.dtype} and {src2.shape} {src2.dtype}")
    a, b = src1.astype(np.float32), src2.astype(np.float32)
    target = _output(out, src1.shape, "Magnitude", "dst", np.float32)
    np.multiply(a, a, out=a)
    np.multiply(b, b, out=b)
    np.add(a, b, out=target)
    return np.sqrt(target, out=target)


def _frame(type_name: str, port: str, array) -> int:
    """The channels of a frame of one of DTYPES (height x width, or x channels)."""
    if not isinstance(array, np.ndarray) or array.dtype not in DTYPES:
        found = getattr(array, "dtype", type(array).__name__)
        raise TypeError(f"{type_name}: '{port}' must be a uint8, int16 or float32 numpy "
                        f"array, not {found}")
    if array.ndim not in (2, 3) or 0 in array.shape:
        raise ValueError(f"{type_name}: '{port}' must be height x width (x channels) with "
                         f"height and width at least 1, not {array.shape}")
    return array.shape[2] if array.ndim == 3 else 1


def _copy(values: np.ndarray, out: np.ndarray | None, type_name: str) -> np.ndarray:
    target = _output(out, values.shape, type_name, "dst", values.dtype)
    np.copyto(target, values)
    return target


CPU_CHANNELS = {
    "ExtractChannel": extract_channel,
    "MergeChannels2": merge_channels,
    "MergeChannels3": merge_channels,
    "MergeChannels4": merge_channels,
    "Magnitude": magnitude,
}

from .cpu_kernels import _output
