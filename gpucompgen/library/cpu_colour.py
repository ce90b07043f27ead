"""CPU forms of yuv.yaml's types: OpenCV's cv2.cvtColor with the camera formats' codes.

As in cpu_ops.py: the inputs as the ports declare them (NV12 and NV21: a one-channel frame
of height * 3/2 rows, height x width or height x width x 1; YUYV and UYVY: height x width
x 2; RGB: height x width x 3), ``out=`` an array to write into, the output returned.  Each
function is the cvtColor call docs/library.md names beside its type, so the CPU form is
OpenCV's result by construction; tests/test_ops_yuv.py compares each with the type's
generated kernel and with a numpy reference of the fixed-point rules in yuv.yaml.
CPU_COLOUR maps each type's name to its function (cpu_kernels.CPU_IMPLEMENTATIONS
includes them).  Imports nothing of the generator.
"""

from __future__ import annotations

import cv2
import numpy as np


def nv12_to_rgb(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Nv12ToRgb: cv2.cvtColor(src, cv2.COLOR_YUV2RGB_NV12)."""
    return _semi_planar("Nv12ToRgb", cv2.COLOR_YUV2RGB_NV12, src, out, 3)


def nv12_to_bgr(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Nv12ToBgr: cv2.cvtColor(src, cv2.COLOR_YUV2BGR_NV12)."""
    return _semi_planar("Nv12ToBgr", cv2.COLOR_YUV2BGR_NV12, src, out, 3)


def nv21_to_rgb(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Nv21ToRgb: cv2.cvtColor(src, cv2.COLOR_YUV2RGB_NV21)."""
    return _semi_planar("Nv21ToRgb", cv2.COLOR_YUV2RGB_NV21, src, out, 3)


def nv21_to_bgr(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Nv21ToBgr: cv2.cvtColor(src, cv2.COLOR_YUV2BGR_NV21)."""
    return _semi_planar("Nv21ToBgr", cv2.COLOR_YUV2BGR_NV21, src, out, 3)


def nv12_to_gray(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Nv12ToGray: cv2.cvtColor(src, cv2.COLOR_YUV2GRAY_NV12): the Y plane, the first 2/3
    of the rows (NV21's is the same)."""
    return _semi_planar("Nv12ToGray", cv2.COLOR_YUV2GRAY_NV12, src, out, 1)


def yuyv_to_rgb(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """YuyvToRgb: cv2.cvtColor(src, cv2.COLOR_YUV2RGB_YUYV)."""
    return _packed("YuyvToRgb", cv2.COLOR_YUV2RGB_YUYV, src, out, 3)


def yuyv_to_bgr(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """YuyvToBgr: cv2.cvtColor(src, cv2.COLOR_YUV2BGR_YUYV)."""
    return _packed("YuyvToBgr", cv2.COLOR_YUV2BGR_YUYV, src, out, 3)


def uyvy_to_rgb(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """UyvyToRgb: cv2.cvtColor(src, cv2.COLOR_YUV2RGB_UYVY)."""
    return _packed("UyvyToRgb", cv2.COLOR_YUV2RGB_UYVY, src, out, 3)


def uyvy_to_bgr(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """UyvyToBgr: cv2.cvtColor(src, cv2.COLOR_YUV2BGR_UYVY)."""
    return _packed("UyvyToBgr", cv2.COLOR_YUV2BGR_UYVY, src, out, 3)


def yuyv_to_gray(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """YuyvToGray: cv2.cvtColor(src, cv2.COLOR_YUV2GRAY_YUYV): the Y of each pixel."""
    return _packed("YuyvToGray", cv2.COLOR_YUV2GRAY_YUYV, src, out, 1)


def uyvy_to_gray(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """UyvyToGray: cv2.cvtColor(src, cv2.COLOR_YUV2GRAY_UYVY): the Y of each pixel."""
    return _packed("UyvyToGray", cv2.COLOR_YUV2GRAY_UYVY, src, out, 1)


def rgb_to_yuv(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """RgbToYuv: cv2.cvtColor(src, cv2.COLOR_RGB2YUV)."""
    return _to_yuv("RgbToYuv", cv2.COLOR_RGB2YUV, src, out)


def bgr_to_yuv(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """BgrToYuv: cv2.cvtColor(src, cv2.COLOR_BGR2YUV)."""
    return _to_yuv("BgrToYuv", cv2.COLOR_BGR2YUV, src, out)


# -- helpers -------------------------------------------------------------------------------
def _semi_planar(type_name: str, code: int, src, out, channels: int) -> np.ndarray:
    """cvtColor of an NV12/NV21 frame: one channel of height * 3/2 rows (a multiple of 3)
    and an even width, in; height x width (x 3), out."""
    _uint8(type_name, src)
    if src.ndim == 3 and src.shape[2] == 1:
        src = src.reshape(src.shape[:2])
    if src.ndim != 2 or src.shape[0] % 3 or src.shape[1] % 2 or 0 in src.shape:
        raise ValueError(f"{type_name}: 'src' must be one channel of height * 3/2 rows (a "
                         f"multiple of 3) and an even width, not {src.shape}")
    shape = (src.shape[0] * 2 // 3, src.shape[1]) + ((3,) if channels == 3 else ())
    return cv2.cvtColor(src, code, dst=_output(out, shape, type_name, "dst"))


def _packed(type_name: str, code: int, src, out, channels: int) -> np.ndarray:
    """cvtColor of a YUYV/UYVY frame: height x width x 2 of an even width, in."""
    _uint8(type_name, src)
    if src.ndim != 3 or src.shape[2] != 2 or src.shape[1] % 2 or 0 in src.shape:
        raise ValueError(f"{type_name}: 'src' must be height x width x 2 of an even width, "
                         f"not {src.shape}")
    shape = src.shape[:2] + ((3,) if channels == 3 else ())
    return cv2.cvtColor(src, code, dst=_output(out, shape, type_name, "dst"))


def _to_yuv(type_name: str, code: int, src, out) -> np.ndarray:
    _uint8(type_name, src)
    if src.ndim != 3 or src.shape[2] != 3 or 0 in src.shape:
        raise ValueError(f"{type_name}: 'src' must be height x width x 3, not {src.shape}")
    return cv2.cvtColor(src, code, dst=_output(out, src.shape, type_name, "dst"))


def _uint8(type_name: str, array) -> None:
    if not isinstance(array, np.ndarray) or array.dtype != np.uint8:
        found = getattr(array, "dtype", type(array).__name__)
        raise TypeError(f"{type_name}: 'src' must be a uint8 numpy array, not {found}")


CPU_COLOUR = {
    "Nv12ToRgb": nv12_to_rgb, "Nv12ToBgr": nv12_to_bgr, "Nv21ToRgb": nv21_to_rgb,
    "Nv21ToBgr": nv21_to_bgr, "Nv12ToGray": nv12_to_gray,
    "YuyvToRgb": yuyv_to_rgb, "YuyvToBgr": yuyv_to_bgr, "UyvyToRgb": uyvy_to_rgb,
    "UyvyToBgr": uyvy_to_bgr, "YuyvToGray": yuyv_to_gray, "UyvyToGray": uyvy_to_gray,
    "RgbToYuv": rgb_to_yuv, "BgrToYuv": bgr_to_yuv,
}

from .cpu_kernels import _output
