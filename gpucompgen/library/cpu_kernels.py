"""CPU implementations of the library's GPU-aware types: OpenCV's own functions.

One function per type, for the CPU side of flexible components (issue 15): the input
arrays in the shapes the ports declare (height x width x channels, uint8; one channel is
height x width, or height x width x 1), the type's parameters as keywords, the output
array out.  The library's operations are OpenCV's, so wherever OpenCV has the operation
the function calls cv2 (as RGB: the library's frames are RGB, and cv2's colour codes
say so, COLOR_RGB2GRAY and COLOR_RGB2HSV); the CPU form is then OpenCV's result by
construction and as fast as OpenCV on these cores.  numpy remains only where OpenCV has
no equal: ObjectDetector's rule, Crop (a slice).  Every function gives the
same bytes as the type's OpenCL kernel in this folder for every size and parameter the
kernel accepts: tests/test_cpu_kernels.py and tests/test_imgproc.py run both on PoCL and
compare, and compare the CPU functions with independent numpy references
(tests/imgproc_reference.py) and hand-computed values.

Each function also takes ``out=``, an array of the output's shape and dtype to write
into (OpenCV writes into it, dst=); without it, a new array.  CPU_IMPLEMENTATIONS maps
each type's name to its function.
"""

from __future__ import annotations

import cv2
import numpy as np

# the element types of the library's generic operations (docs/library.md): OpenCV's
# uint8, int16 and float32 frames; an index map (a flip) moves elements of any type
DTYPES3 = (np.uint8, np.int16, np.float32)
ANY_DTYPE = (np.uint8, np.int8, np.uint16, np.int16, np.int32, np.uint32, np.float32)


def vertical_mirror(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """VerticalMirror (vertical_mirror.cl): row y of the output is row height-1-y of image:
    cv2.flip(src, 0), any element type."""
    _channels("VerticalMirror", "src", src, ANY_DTYPE)
    return cv2.flip(src, 0, dst=_output(out, src.shape, "VerticalMirror", "dst", src.dtype))


def image_merger(left: np.ndarray, right: np.ndarray, *,
                 out: np.ndarray | None = None) -> np.ndarray:
    """ImageMerger (image_merger.cl): left and right side by side, [left | right].

    Both frames must have the same height (the type's 'requires'); the output is
    height x (left width + right width) x 3: cv2.hconcat((left, right)).
    """
    _check_image("ImageMerger", "left", left, 3)
    _check_image("ImageMerger", "right", right, 3)
    if left.shape[0] != right.shape[0]:
        raise ValueError(f"ImageMerger: left and right frames must have the same height "
                         f"(left {left.shape[0]}, right {right.shape[0]} rows)")
    shape = (left.shape[0], left.shape[1] + right.shape[1], 3)
    return cv2.hconcat((left, right), dst=_output(out, shape, "ImageMerger", "merged"))


def object_detector(frame: np.ndarray, *, red_min: int, margin: int,
                    out: np.ndarray | None = None) -> np.ndarray:
    """ObjectDetector (object_detector.cl): 255 where a pixel is red enough, else 0.

    A pixel (r, g, b) is red enough when r >= red_min, r - g >= margin and
    r - b >= margin, in integers as the kernel compares them (so a negative margin admits
    pixels whose red is below their green or blue). Returns the height x width mask.
    """
    _check_image("ObjectDetector", "frame", frame, 3)
    # r is 0..255 and r - g, r - b are -255..255: clamping the thresholds to one past
    # those ranges keeps every comparison's result and lets them run in int16
    red_min = min(max(int(red_min), 0), 256)
    margin = min(max(int(margin), -256), 256)
    red = frame[..., 0].astype(np.int16)
    hit = red >= red_min
    hit &= red - frame[..., 1] >= margin
    hit &= red - frame[..., 2] >= margin
    mask = _output(out, frame.shape[:2], "ObjectDetector", "mask")
    return np.multiply(hit.view(np.uint8), 255, out=mask)


def box_blur(src: np.ndarray, *, radius: int, out: np.ndarray | None = None) -> np.ndarray:
    """BoxBlur (box_blur.cl): each channel the mean of the (2 radius + 1)^2 window:
    cv2.blur(src, (side, side), borderType=cv2.BORDER_REPLICATE).

    Window coordinates are clamped to the frame (the edge pixels repeat, BORDER_REPLICATE;
    OpenCV's default border, BORDER_REFLECT_101, differs), and the mean is rounded half
    up: (sum + n // 2) // n for the n = (2 radius + 1)^2 pixels, as the kernel computes it
    (n is odd, so OpenCV's rounding of sum / n never meets a tie).  Any radius >= 0, also
    one larger than the frame.
    """
    _channels("BoxBlur", "src", src)
    radius = int(radius)
    if radius < 0:
        raise ValueError(f"BoxBlur: radius must be 0 or more, not {radius}")
    side = 2 * radius + 1
    return cv2.blur(src, (side, side), dst=_output(out, src.shape, "BoxBlur", "dst"),
                    borderType=cv2.BORDER_REPLICATE)


# == imgproc.yaml: the OpenCV-like library ============================================
# Each function below serves the one-channel and the three-channel type of an operation
# (e.g. Threshold and ThresholdGray): a one-channel image is height x width (or height x
# width x 1), a three-channel one height x width x 3, as the ports declare them.

# OpenCV's codes for Threshold's thresh_type and Resize's interpolation
THRESH_BINARY, THRESH_BINARY_INV, THRESH_TRUNC, THRESH_TOZERO, THRESH_TOZERO_INV = range(5)
INTER_NEAREST, INTER_LINEAR = 0, 1


def rgb_to_gray(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """RgbToGray: cv2.cvtColor(image, cv2.COLOR_RGB2GRAY): uint8 (19596 r + 38470 g + 7470
    b + 2^15) >> 16, OpenCV's fixed-point weights (0.299, 0.587, 0.114 in 1/65536);
    float32 fma(b, 0.114, fma(r, 0.299, g 0.587)) in float32 (OpenCV's vector code)."""
    if _channels("RgbToGray", "src", src, (np.uint8, np.float32)) != 3:
        raise ValueError(f"RgbToGray: 'src' must be height x width x 3, not {src.shape}")
    return cv2.cvtColor(src, cv2.COLOR_RGB2GRAY,
                        dst=_output(out, src.shape[:2], "RgbToGray", "dst", src.dtype))


def rgb_to_hsv(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """RgbToHsv: cv2.cvtColor(image, cv2.COLOR_RGB2HSV) (8-bit: hue 0..179)."""
    _check_image("RgbToHsv", "src", src, 3)
    return cv2.cvtColor(src, cv2.COLOR_RGB2HSV,
                        dst=_output(out, src.shape, "RgbToHsv", "dst"))


def in_range(src: np.ndarray, *, lowerb_0: float = 0, lowerb_1: float = 0,
             lowerb_2: float = 0, upperb_0: float = 255, upperb_1: float = 255,
             upperb_2: float = 255, out: np.ndarray | None = None) -> np.ndarray:
    """InRange: cv2.inRange(src, lowerb, upperb): 255 where every channel c has lowerb_c
    <= value <= upperb_c, else 0; the mask is height x width.  uint8, int16 or float32
    frames of one channel (lowerb_0, upperb_0) or three; the bounds are float32, as the
    kernel's parameters, which OpenCV rounds (half to even) for an integer frame."""
    n = _channels("InRange", "src", src, DTYPES3)
    mask = _output(out, src.shape[:2], "InRange", "dst")
    lower = np.float32([lowerb_0, lowerb_1, lowerb_2][:n]).astype(np.float64)
    upper = np.float32([upperb_0, upperb_1, upperb_2][:n]).astype(np.float64)
    if n == 1:
        return cv2.inRange(src, float(lower[0]), float(upper[0]), dst=mask)
    return cv2.inRange(src, lower, upper, dst=mask)


def threshold(src: np.ndarray, *, thresh: int, maxval: int, thresh_type: int,
              out: np.ndarray | None = None) -> np.ndarray:
    """Threshold / ThresholdGray: cv2.threshold(image, thresh, maxval, thresh_type)[1],
    every channel on its own; thresh_type is OpenCV's code: 0 BINARY (p > thresh ?
    maxval : 0), 1 BINARY_INV, 2 TRUNC (min(p, thresh)), 3 TOZERO (p > thresh ? p : 0),
    4 TOZERO_INV.  uint8, int16 or float32 frames, OpenCV's rules for each (an integer
    frame compares with floor(thresh), maxval rounded and saturated); thresh and maxval
    are float32, as the kernel's parameters."""
    _channels("Threshold", "src", src, DTYPES3)
    kind = int(thresh_type)
    if kind not in range(5):
        raise ValueError(f"Threshold: thresh_type must be 0..4, not {kind}")
    return cv2.threshold(src, float(np.float32(thresh)), float(np.float32(maxval)), kind,
                         dst=_output(out, src.shape, "Threshold", "dst", src.dtype))[1]


def convert_scale(src: np.ndarray, *, alpha: float, beta: float,
                  out: np.ndarray | None = None) -> np.ndarray:
    """ConvertScale: cv2.convertScaleAbs(src, alpha=, beta=) of a uint8, int16 or float32
    frame: |p * alpha + beta| in float32 (one fma in OpenCV's vector code, as in the
    kernel), rounded half to even and saturated to 0..255 (uint8)."""
    _channels("ConvertScale", "src", src, (np.uint8, np.int16, np.float32))
    return cv2.convertScaleAbs(src, dst=_output(out, src.shape, "ConvertScale", "dst"),
                               alpha=float(np.float32(alpha)), beta=float(np.float32(beta)))


def add_weighted(src1: np.ndarray, src2: np.ndarray, *, alpha: float, beta: float,
                 gamma: float, out: np.ndarray | None = None) -> np.ndarray:
    """AddWeighted / AddWeightedGray: cv2.addWeighted(src1, alpha, src2, beta, gamma):
    for uint8 and int16 fma(src1, alpha, fma(src2, beta, gamma)) in float32, rounded half
    to even and saturated.  float32 frames: OpenCV computes in double; this gives the
    kernel's bytes, (src1 * alpha + src2 * beta) + gamma each operation rounded to
    float32, within 2^-22 (|src1 alpha| + |src2 beta| + |gamma|) of OpenCV's."""
    _same_shape("AddWeighted", src1, src2, DTYPES3)
    dst = _output(out, src1.shape, "AddWeighted", "dst", src1.dtype)
    if src1.dtype == np.float32:
        alpha, beta, gamma = (np.float32(v) for v in (alpha, beta, gamma))
        np.multiply(src1, alpha, out=dst)
        dst += src2 * beta
        dst += gamma
        return dst
    alpha, beta, gamma = (float(np.float32(v)) for v in (alpha, beta, gamma))
    return cv2.addWeighted(src1, alpha, src2, beta, gamma, dst=dst)


def absdiff(src1: np.ndarray, src2: np.ndarray, *,
            out: np.ndarray | None = None) -> np.ndarray:
    """AbsDiff / AbsDiffGray: cv2.absdiff(src1, src2): |src1 - src2| (int16 saturated)."""
    _same_shape("AbsDiff", src1, src2, DTYPES3)
    return cv2.absdiff(src1, src2, dst=_output(out, src1.shape, "AbsDiff", "dst", src1.dtype))


def resize(src: np.ndarray, *, width: int, height: int, interpolation: int,
           out: np.ndarray | None = None) -> np.ndarray:
    """Resize: cv2.resize(src, (width, height), interpolation=interpolation): 0
    INTER_NEAREST of uint8, int16 or float32 frames, 1 INTER_LINEAR of uint8 ones (OpenCV's
    fixed point; the type's requirement refuses others)."""
    _channels("Resize", "src", src, DTYPES3)
    width, height, mode = int(width), int(height), int(interpolation)
    if width < 1 or height < 1:
        raise ValueError(f"Resize: width and height must be 1 or more, not {width}x{height}")
    if mode not in (INTER_NEAREST, INTER_LINEAR):
        raise ValueError(f"Resize: interpolation must be 0 (nearest) or 1 (linear), not {mode}")
    if mode == INTER_LINEAR and src.dtype != np.uint8:
        raise TypeError(f"Resize: INTER_LINEAR takes uint8 frames, not {src.dtype}")
    shape = (height, width) + src.shape[2:]
    return cv2.resize(src, (width, height), dst=_output(out, shape, "Resize", "dst", src.dtype),
                      interpolation=mode)


def crop(src: np.ndarray, *, left: int, top: int, width: int, height: int,
         out: np.ndarray | None = None) -> np.ndarray:
    """Crop: src[top:top + height, left:left + width], the rectangle inside the frame, of
    any element type."""
    _channels("Crop", "src", src, ANY_DTYPE)
    x, y, width, height = int(left), int(top), int(width), int(height)
    if (min(x, y) < 0 or width < 1 or height < 1 or x + width > src.shape[1]
            or y + height > src.shape[0]):
        raise ValueError(f"Crop: the rectangle left={x} top={y} {width}x{height} must lie "
                         f"inside the {src.shape[1]}x{src.shape[0]} frame")
    values = src[y:y + height, x:x + width]
    if out is None:
        return np.ascontiguousarray(values)
    target = _output(out, values.shape, "Crop", "dst", src.dtype)
    np.copyto(target, values)
    return target


def flip_horizontal(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """FlipHorizontal / FlipHorizontalGray: cv2.flip(image, 1), any element type."""
    _channels("FlipHorizontal", "src", src, ANY_DTYPE)
    return cv2.flip(src, 1, dst=_output(out, src.shape, "FlipHorizontal", "dst", src.dtype))


def rotate180(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Rotate180 / Rotate180Gray: cv2.rotate(image, cv2.ROTATE_180), any element type."""
    _channels("Rotate180", "src", src, ANY_DTYPE)
    return cv2.rotate(src, cv2.ROTATE_180,
                      dst=_output(out, src.shape, "Rotate180", "dst", src.dtype))


def gaussian_blur(src: np.ndarray, *, ksize: int, ksize_y: int = 0, sigma: float = 0.0,
                  sigma_y: float = 0.0, border_type: int = 4,
                  out: np.ndarray | None = None) -> np.ndarray:
    """GaussianBlur / GaussianBlurGray: cv2.GaussianBlur(src, (ksize, ksize_y or ksize),
    sigma, sigmaY=sigma_y, borderType=border_type).

    Window sides odd, 1..31 (ksize_y 0: ksize); sigma 0 from the side, sigma_y 0 sigma;
    border 0 CONSTANT, 1 REPLICATE, 2 REFLECT, 4 REFLECT_101 (OpenCV's default).  OpenCV
    computes 8-bit images in fixed point (weights in 1/256), bit-exact: its call.  int16
    and float32 frames: the generated kernel's bytes (OpenCV's float32 weights, each row's
    products in order, then the rows, each operation rounded to float32; int16 rounded to
    nearest even and saturated), within docs/library.md's bound of OpenCV's.
    """
    _channels("GaussianBlur", "src", src, DTYPES3)
    width, height = int(ksize), int(ksize_y) or int(ksize)
    for name, side in (("ksize", width), ("ksize_y", height)):
        if side < 1 or side > 31 or side % 2 == 0:
            raise ValueError(f"GaussianBlur: {name} must be odd, 1..31, not {side}")
    if not (0 <= sigma <= 1000 and 0 <= sigma_y <= 1000):
        raise ValueError(f"GaussianBlur: sigma and sigma_y must be 0..1000, not {sigma} "
                         f"and {sigma_y}")
    if int(border_type) not in (0, 1, 2, 4):
        raise ValueError(f"GaussianBlur: border_type must be 0, 1, 2 or 4, not {border_type}")
    dst = _output(out, src.shape, "GaussianBlur", "dst", src.dtype)
    if src.dtype == np.uint8:
        return cv2.GaussianBlur(src, (width, height), float(sigma), sigmaY=float(sigma_y),
                                borderType=int(border_type), dst=dst)
    from .cpu_ops import _correlation
    from .kernel_tables import gaussian_f32

    planes = src.astype(np.float32).reshape(src.shape[0], src.shape[1], -1)
    total = _correlation(planes, gaussian_f32(width, sigma),
                         gaussian_f32(height, sigma_y, width, sigma), int(border_type))
    if src.dtype == np.int16:
        total = np.clip(np.rint(total), -32768, 32767)
    dst[...] = total.reshape(dst.shape)
    return dst


MAX_MEDIAN_KSIZE = 15


def median_blur(src: np.ndarray, *, ksize: int = 3,
                out: np.ndarray | None = None) -> np.ndarray:
    """MedianBlur / MedianBlurGray: cv2.medianBlur(image, ksize): the median of the
    ksize x ksize window (3 or 5; up to 15 for uint8), edges repeated (BORDER_REPLICATE,
    as OpenCV's medianBlur)."""
    _channels("MedianBlur", "src", src, DTYPES3)
    ksize = int(ksize)
    if ksize < 3 or ksize % 2 == 0 or ksize > MAX_MEDIAN_KSIZE or \
            (ksize > 5 and src.dtype != np.uint8):
        raise ValueError(f"MedianBlur: ksize must be 3 or 5, or odd up to "
                         f"{MAX_MEDIAN_KSIZE} for uint8 frames (OpenCV's), not {ksize} "
                         f"for {src.dtype}")
    return cv2.medianBlur(src, ksize,
                          dst=_output(out, src.shape, "MedianBlur", "dst", src.dtype))


def _channels(type_name: str, port: str, array: np.ndarray, dtypes=(np.uint8,)) -> int:
    """The channels of a one-channel (height x width or height x width x 1) or
    three-channel image of one of dtypes; anything else raises."""
    if not isinstance(array, np.ndarray) or array.dtype not in dtypes:
        dtype = getattr(array, "dtype", type(array).__name__)
        names = [np.dtype(d).name for d in dtypes]
        names = " or ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)
        raise TypeError(f"{type_name}: '{port}' must be a {names} numpy array, not {dtype}")
    if array.ndim == 2 and 0 not in array.shape:
        return 1
    if array.ndim == 3 and array.shape[2] == 1 and 0 not in array.shape:
        return 1
    if array.ndim != 3 or array.shape[2] != 3 or 0 in array.shape:
        raise ValueError(f"{type_name}: '{port}' must be height x width x 3 (or one "
                         f"channel) with height and width at least 1, not {array.shape}")
    return 3


def _same_shape(type_name: str, src1: np.ndarray, src2: np.ndarray,
                dtypes=(np.uint8,)) -> None:
    _channels(type_name, "src1", src1, dtypes)
    _channels(type_name, "src2", src2, dtypes)
    if src1.shape != src2.shape or src1.dtype != src2.dtype:
        raise ValueError(f"{type_name}: src1 and src2 must have the same size and element "
                         f"type, not {src1.shape} {src1.dtype} and {src2.shape} {src2.dtype}")


CPU_IMPLEMENTATIONS = {
    "VerticalMirror": vertical_mirror,
    "ImageMerger": image_merger,
    "ObjectDetector": object_detector,
    "BoxBlur": box_blur,
    # imgproc.yaml: one function for the one- and the three-channel type
    "RgbToGray": rgb_to_gray,
    "RgbToHsv": rgb_to_hsv,
    **{f"{name}{suffix}": function for suffix in ("", "Gray") for name, function in (
        ("InRange", in_range), ("Threshold", threshold), ("ConvertScale", convert_scale),
        ("Resize", resize), ("Crop", crop), ("FlipHorizontal", flip_horizontal),
        ("Rotate180", rotate180), ("GaussianBlur", gaussian_blur),
        ("MedianBlur", median_blur),
        ("AbsDiff", absdiff), ("AddWeighted", add_weighted), ("ConvertScaleAbs", convert_scale))},
}


# -- helpers --------------------------------------------------------------------------
def _check_image(type_name: str, port: str, array: np.ndarray, channels: int) -> None:
    if not isinstance(array, np.ndarray) or array.dtype != np.uint8:
        dtype = getattr(array, "dtype", type(array).__name__)
        raise TypeError(f"{type_name}: '{port}' must be a uint8 numpy array, not {dtype}")
    if array.ndim != 3 or array.shape[2] != channels or 0 in array.shape:
        raise ValueError(f"{type_name}: '{port}' must be height x width x {channels} "
                         f"with height and width at least 1, not {array.shape}")


def _output(out: np.ndarray | None, shape: tuple[int, ...], type_name: str,
            port: str, dtype=np.uint8) -> np.ndarray:
    """out, checked: OpenCV would silently allocate a new array for a dst of another
    shape or type (or not contiguous) and leave out as it was."""
    if out is None:
        return np.empty(shape, dtype)
    if (not isinstance(out, np.ndarray) or out.shape != tuple(shape) or out.dtype != dtype
            or not out.flags.c_contiguous):
        raise ValueError(f"{type_name}: out= for '{port}' must be a C-contiguous "
                         f"{np.dtype(dtype).name} array of shape {tuple(shape)}, not "
                         f"{getattr(out, 'dtype', type(out).__name__)} "
                         f"{getattr(out, 'shape', '')}")
    return out


# the operations of issue 26 (bitwise.yaml, convert.yaml, filters2.yaml, ...): their CPU
# forms live in cpu_ops.py; the registry has them all
from .cpu_ops import CPU_OPS

CPU_IMPLEMENTATIONS.update(CPU_OPS)

# the camera formats of yuv.yaml (cpu_colour.py), channels.yaml and magnitude.yaml
# (cpu_channels.py), the warps of warp.yaml (warp_ops.py)
from .cpu_channels import CPU_CHANNELS
from .cpu_colour import CPU_COLOUR
from .warp_ops import WARP_OPS

CPU_IMPLEMENTATIONS.update(CPU_COLOUR)
CPU_IMPLEMENTATIONS.update(CPU_CHANNELS)
CPU_IMPLEMENTATIONS.update(WARP_OPS)
