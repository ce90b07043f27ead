"""CPU forms of the warps (warp.yaml): OpenCV's own functions.

As in cpu_ops.py, one function serves a type over one or three channels: the inputs as the
ports declare them (height x width x channels; one channel height x width or height x
width x 1), the type's parameters as keywords (matrices as nested tuples, as an array
parameter arrives), ``out=`` an array to write into, the output array returned.  Each is
the OpenCV call docs/library.md names beside its type; tests/test_warps.py compares each
with the type's generated OpenCL kernel on photographs and random frames.  WARP_OPS maps
each type's name to its function (cpu_kernels.CPU_IMPLEMENTATIONS includes them).
"""

from __future__ import annotations

import cv2
import numpy as np

WARP_INVERSE_MAP = 16  # cv2.WARP_INVERSE_MAP
FRAME_DTYPES = (np.uint8, np.float32)  # int16: OpenCV's fixed point of before, not taken
BORDER_MODES = (0, 1)  # cv2.BORDER_CONSTANT, cv2.BORDER_REPLICATE


def _matrix(type_name: str, m, shape: tuple[int, int]) -> np.ndarray:
    """The matrix as float64 holding the float32 values the kernel reads."""
    matrix = np.asarray(m, np.float32)
    if matrix.shape != shape or not np.isfinite(matrix).all():
        raise ValueError(f"{type_name}: m must be {shape[0]}x{shape[1]} finite numbers, "
                         f"not shape {matrix.shape}")
    return matrix.astype(np.float64)


def _checked(type_name: str, flags: int, border_mode: int, border_value: float) -> tuple:
    if int(flags) not in (0, 1, 16, 17):
        raise ValueError(f"{type_name}: flags must be 0 or 1, plus 16, not {flags}")
    if int(border_mode) not in BORDER_MODES:
        raise ValueError(f"{type_name}: border_mode must be 0 or 1, not {border_mode}")
    # the kernel's parameter is a float32: OpenCV's saturate_cast of it, as there
    return int(flags), int(border_mode), (float(np.float32(border_value)),) * 4


def _finish(result: np.ndarray, src: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """OpenCV's result shaped as the input (a height x width x 1 input gives x 1), copied
    into out when given."""
    result = result.reshape(result.shape[:2] + src.shape[2:])
    if out is None:
        return result
    if out.shape != result.shape or out.dtype != result.dtype:
        raise ValueError(f"out= must be a {result.dtype} array of shape {result.shape}, not "
                         f"{out.dtype} {out.shape}")
    np.copyto(out, result)
    return out


def warp_affine(src: np.ndarray, *, m, width: int, height: int, flags: int,
                border_mode: int, border_value: float,
                out: np.ndarray | None = None) -> np.ndarray:
    """WarpAffine: cv2.warpAffine(src, m, (width, height), flags=, borderMode=,
    borderValue=)."""
    return _warp(cv2.warpAffine, "WarpAffine", (2, 3), src, m, width, height, flags,
                 border_mode, border_value, out)


def warp_perspective(src: np.ndarray, *, m, width: int, height: int, flags: int,
                     border_mode: int, border_value: float,
                     out: np.ndarray | None = None) -> np.ndarray:
    """WarpPerspective: cv2.warpPerspective(src, m, (width, height), flags=, borderMode=,
    borderValue=)."""
    return _warp(cv2.warpPerspective, "WarpPerspective", (3, 3), src, m, width, height,
                 flags, border_mode, border_value, out)


def _warp(call, type_name: str, shape: tuple[int, int], src, m, width, height, flags,
          border_mode, border_value, out) -> np.ndarray:
    _channels(type_name, "src", src, FRAME_DTYPES)
    flags, border_mode, value = _checked(type_name, flags, border_mode, border_value)
    return _finish(call(src, _matrix(type_name, m, shape), (int(width), int(height)),
                        flags=flags, borderMode=border_mode, borderValue=value), src, out)


def remap(src: np.ndarray, map1: np.ndarray, map2: np.ndarray, *, interpolation: int,
          border_mode: int, border_value: float, out: np.ndarray | None = None) -> np.ndarray:
    """Remap: cv2.remap(src, map1, map2, interpolation, borderMode=, borderValue=), map1
    and map2 the float32 x and y positions (height x width, or x 1)."""
    _channels("Remap", "src", src, FRAME_DTYPES)
    maps = []
    for name, a in (("map1", map1), ("map2", map2)):
        _image("Remap", name, a, np.float32)
        maps.append(np.ascontiguousarray(a.reshape(a.shape[:2])))
    if maps[0].shape != maps[1].shape:
        raise ValueError(f"Remap: map1 and map2 must have the same size, not "
                         f"{maps[0].shape} and {maps[1].shape}")
    flags, border_mode, value = _checked("Remap", interpolation, border_mode, border_value)
    if flags > 1:
        raise ValueError(f"Remap: interpolation must be 0 or 1, not {interpolation}")
    if np.shares_memory(maps[0], maps[1]):
        # one frame feeding both ports: OpenCV 5.0's remap misreads two maps that are one
        # array (positions one pixel off; a copy gives its own right answer)
        maps[1] = maps[1].copy()
    return _finish(cv2.remap(src, maps[0], maps[1], flags, borderMode=border_mode,
                             borderValue=value), src, out)


def undistort(src: np.ndarray, *, camera_matrix, dist_coeffs,
              out: np.ndarray | None = None) -> np.ndarray:
    """Undistort: cv2.undistort(src, camera_matrix, dist_coeffs) (a remap with fixed-point
    maps: positions in 1/32 pixel, zeros outside), uint8 or float32."""
    _channels("Undistort", "src", src, FRAME_DTYPES)
    k = _matrix("Undistort", camera_matrix, (3, 3))
    d = np.asarray(dist_coeffs, np.float32).astype(np.float64)
    if d.shape != (5,):
        raise ValueError(f"Undistort: dist_coeffs must be 5 numbers, not shape {d.shape}")
    return _finish(cv2.undistort(src, k, d), src, out)


WARP_OPS = {"WarpAffine": warp_affine, "WarpPerspective": warp_perspective,
            "Remap": remap, "Undistort": undistort}

# last, as in cpu_ops.py, so that any of the library's CPU modules may be imported first (a
# generated program whose only CPU-placed library type is a warp imports this one first):
# cpu_ops imports cpu_kernels, which imports WARP_OPS from here
from .cpu_kernels import _channels
from .cpu_ops import _image
