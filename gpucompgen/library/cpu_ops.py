"""CPU forms of the operations of issue 26 (bitwise.yaml, convert.yaml, filters2.yaml,
morphology.yaml, features.yaml): OpenCV's own functions.

As in cpu_kernels.py, one function serves an operation over one or three channels (and its
deprecated one-channel 'Gray' name): the inputs as the ports declare them (height x width x channels; one
channel height x width or height x width x 1), the type's parameters as keywords, ``out=``
an array to write into (OpenCV's dst=), the output array returned.  Every function is the
OpenCV call docs/library.md names beside its type, so the CPU form equals OpenCV by
construction; tests/test_imgproc_ops.py compares each with the type's generated OpenCL
kernel on photographs and random frames, and with hand-computed values.  CPU_OPS maps each
type's name to its function (cpu_kernels.CPU_IMPLEMENTATIONS includes them).

It shares cpu_kernels' helpers (imported at the end: cpu_kernels imports this module at
its own end) and imports nothing of the generator.
"""

from __future__ import annotations

import cv2
import numpy as np

# OpenCV's border codes, as Blur's border_type takes them (cv2.BORDER_*)
BORDER_CONSTANT, BORDER_REPLICATE, BORDER_REFLECT, BORDER_REFLECT_101 = 0, 1, 2, 4
BORDERS = {BORDER_CONSTANT: "BORDER_CONSTANT (0 outside the frame)",
           BORDER_REPLICATE: "BORDER_REPLICATE (aaa|abc|ccc)",
           BORDER_REFLECT: "BORDER_REFLECT (cba|abc|cba)",
           BORDER_REFLECT_101: "BORDER_REFLECT_101 (cb|abc|ba)"}
MAX_KSIZE = 31  # Blur's and MorphologyEx's largest window side
INTEGER = (np.uint8, np.int16)  # the element types of the bitwise operations


# -- conversions --------------------------------------------------------------------------
COLOUR_DTYPES = (np.uint8, np.float32)  # what cv2.cvtColor takes of the library's types


def gray_to_rgb(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """GrayToRgb: cv2.cvtColor(src, cv2.COLOR_GRAY2RGB): the value in all three channels,
    uint8 or float32."""
    if _channels("GrayToRgb", "src", src, COLOUR_DTYPES) != 1:
        raise ValueError(f"GrayToRgb: 'src' must have one channel, not {src.shape}")
    return cv2.cvtColor(src, cv2.COLOR_GRAY2RGB,
                        dst=_output(out, src.shape[:2] + (3,), "GrayToRgb", "dst", src.dtype))


def swap_red_blue(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """RgbToBgr and BgrToRgb: cv2.cvtColor(src, cv2.COLOR_RGB2BGR), channels 0 and 2
    exchanged (the same operation both ways), uint8 or float32."""
    if _channels("RgbToBgr", "src", src, COLOUR_DTYPES) != 3:
        raise ValueError(f"RgbToBgr: 'src' must have three channels, not {src.shape}")
    return cv2.cvtColor(src, cv2.COLOR_RGB2BGR,
                        dst=_output(out, src.shape, "RgbToBgr", "dst", src.dtype))


def flip_vertical(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """FlipVertical / FlipVerticalGray: cv2.flip(src, 0): row y is row height - 1 - y,
    any element type."""
    _channels("FlipVertical", "src", src, ANY_DTYPE)
    return cv2.flip(src, 0, dst=_output(out, src.shape, "FlipVertical", "dst", src.dtype))


def lut(src: np.ndarray, *, lut, out: np.ndarray | None = None) -> np.ndarray:
    """Lut / LutGray: cv2.LUT(src, lut): each element replaced by lut[element], the 256
    values (0..255) of the array parameter, the same table for every channel."""
    _image("Lut", "src", src)
    table = np.asarray(lut, np.int64)
    if table.shape != (256,) or table.min() < 0 or table.max() > 255:
        raise ValueError(f"Lut: lut must be 256 values 0..255, not shape {table.shape}")
    return cv2.LUT(src, table.astype(np.uint8), dst=_output(out, src.shape, "Lut", "dst"))


# -- bitwise ------------------------------------------------------------------------------
def bitwise_and(src1: np.ndarray, src2: np.ndarray, *,
                out: np.ndarray | None = None) -> np.ndarray:
    """BitwiseAnd / BitwiseAndGray: cv2.bitwise_and(src1, src2)."""
    _pair("BitwiseAnd", src1, src2, INTEGER)
    dst = _output(out, src1.shape, "BitwiseAnd", "dst", src1.dtype)
    return cv2.bitwise_and(src1, src2, dst=dst)


def bitwise_or(src1: np.ndarray, src2: np.ndarray, *,
               out: np.ndarray | None = None) -> np.ndarray:
    """BitwiseOr / BitwiseOrGray: cv2.bitwise_or(src1, src2)."""
    _pair("BitwiseOr", src1, src2, INTEGER)
    dst = _output(out, src1.shape, "BitwiseOr", "dst", src1.dtype)
    return cv2.bitwise_or(src1, src2, dst=dst)


def bitwise_xor(src1: np.ndarray, src2: np.ndarray, *,
                out: np.ndarray | None = None) -> np.ndarray:
    """BitwiseXor / BitwiseXorGray: cv2.bitwise_xor(src1, src2)."""
    _pair("BitwiseXor", src1, src2, INTEGER)
    dst = _output(out, src1.shape, "BitwiseXor", "dst", src1.dtype)
    return cv2.bitwise_xor(src1, src2, dst=dst)


def bitwise_not(src: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """BitwiseNot / BitwiseNotGray: cv2.bitwise_not(src): ~p (255 - p for uint8)."""
    _channels("BitwiseNot", "src", src, INTEGER)
    return cv2.bitwise_not(src, dst=_output(out, src.shape, "BitwiseNot", "dst", src.dtype))


def bitwise_and_mask(src1: np.ndarray, src2: np.ndarray, mask: np.ndarray, *,
                     out: np.ndarray | None = None) -> np.ndarray:
    """BitwiseAndMask / BitwiseAndMaskGray: cv2.bitwise_and(src1, src2, mask=mask) into a
    zeroed frame: src1 & src2 where the mask is not 0, else 0 (every channel)."""
    _pair("BitwiseAndMask", src1, src2, INTEGER)
    if _image("BitwiseAndMask", "mask", mask) != 1 or mask.shape[:2] != src1.shape[:2]:
        raise ValueError(f"BitwiseAndMask: 'mask' must be one channel of the frames' size "
                         f"{src1.shape[:2]}, not {mask.shape}")
    dst = _output(out, src1.shape, "BitwiseAndMask", "dst", src1.dtype)
    dst[...] = 0  # OpenCV leaves dst as it was where the mask is 0
    return cv2.bitwise_and(src1, src2, dst=dst, mask=mask.reshape(mask.shape[:2]))


# -- filters -------------------------------------------------------------------------------
def blur(src: np.ndarray, *, ksize: int, border_type: int,
         out: np.ndarray | None = None) -> np.ndarray:
    """Blur / BlurGray: cv2.blur(src, (ksize, ksize), borderType=border_type): the mean of
    the ksize x ksize window (ksize odd, 1..31, so the mean is never a tie), rounded, with
    OpenCV's border rule of that code: 0 CONSTANT (zeros), 1 REPLICATE, 2 REFLECT,
    4 REFLECT_101.  uint8 and int16: OpenCV's (sums in int).  float32: the generated
    kernel's sums (OpenCV's are in double): each row's from the left, then the column's
    from the top, in float32, times 1 / ksize^2 (a float32 constant)."""
    _channels("Blur", "src", src, DTYPES3)
    ksize, border = _odd_ksize("Blur", ksize), int(border_type)
    if border not in BORDERS:
        raise ValueError(f"Blur: border_type must be one of {sorted(BORDERS)}, not {border}")
    dst = _output(out, src.shape, "Blur", "dst", src.dtype)
    if src.dtype != np.float32:
        return cv2.blur(src, (ksize, ksize), dst=dst, borderType=border)
    ones = (1.0,) * ksize  # each row's sum from the left, then the rows from the top
    total = _correlation(src.reshape(src.shape[0], src.shape[1], -1), ones, ones, border)
    dst[...] = (total * (np.float32(1) / np.float32(ksize * ksize))).reshape(dst.shape)
    return dst


FILTER_DEPTHS = {-1: np.uint8, 0: np.uint8, 3: np.int16, 5: np.float32}  # OpenCV's codes
CV_DEPTHS = {"uint8": cv2.CV_8U, "int16": cv2.CV_16S, "float32": cv2.CV_32F}


def filter_2d(src: np.ndarray, *, weights, delta: float = 0.0, border_type: int = 4,
              ddepth: int = -1, out: np.ndarray | None = None) -> np.ndarray:
    """Filter2D: cv2.filter2D(src, ddepth, np.float32(weights), delta=delta,
    borderType=border_type): the correlation with the kernel weights (rows x cols, 1..15
    each, anchored at (cols / 2, rows / 2)) plus delta, of a uint8, int16 or float32 frame,
    rounded and saturated to uint8 (ddepth 0) or int16 (3), or float32 (5), -1 the
    frame's own type (OpenCV's combinations: uint8 of uint8 frames, int16 of uint8 and
    int16 ones)."""
    _channels("Filter2D", "src", src, DTYPES3)
    weights = np.array(weights, np.float32)
    if weights.ndim != 2 or not (1 <= weights.shape[0] <= 15 and 1 <= weights.shape[1] <= 15):
        raise ValueError(f"Filter2D: weights must be rows x cols, 1..15 each, not "
                         f"{'x'.join(map(str, weights.shape))}")
    border = int(border_type)
    if border not in BORDERS:
        raise ValueError(f"Filter2D: border_type must be one of {sorted(BORDERS)}, "
                         f"not {border}")
    depth = int(ddepth)
    dtype = src.dtype if depth == -1 else FILTER_DEPTHS.get(depth)
    if dtype is None or np.dtype(dtype).itemsize < src.dtype.itemsize:
        raise ValueError(f"Filter2D: ddepth must be -1 (the input's), 0 (uint8, of uint8 "
                         f"frames), 3 (int16, of uint8 and int16 frames) or 5 (float32); "
                         f"not {depth} for {src.dtype.name} frames")
    return cv2.filter2D(src, depth, weights, delta=float(delta), borderType=border,
                        dst=_output(out, src.shape, "Filter2D", "dst", dtype))


# -- derivatives: Sobel, Scharr, Laplacian ---------------------------------------------------
def sobel(src: np.ndarray, *, dx: int, dy: int, ksize: int = 3, scale: float = 1.0,
          delta: float = 0.0, border_type: int = 4, ddepth: int = 3,
          out: np.ndarray | None = None) -> np.ndarray:
    """Sobel / SobelGray: cv2.Sobel(src, ddepth, dx, dy, ksize=ksize, scale=scale,
    delta=delta, borderType=border_type): OpenCV's separable derivative kernels
    (kernel_tables.sobel_taps; ksize 1, 3, 5, 7, or -1 for Scharr's), of uint8 or float32
    frames, as int16 (ddepth 3), uint8 (0), float32 (5) or the input's type (-1).  The
    generated kernel's bytes: OpenCV's own where they are exact (see _derivative)."""
    ksize, dx, dy = int(ksize), int(dx), int(dy)
    limit = max(ksize, 3)
    if not ((ksize == -1 and dx + dy == 1) or (ksize in (1, 3, 5, 7) and dx + dy >= 1
                                               and 0 <= dx < limit and 0 <= dy < limit)):
        raise ValueError(f"Sobel: give ksize 1, 3, 5 or 7 with orders dx, dy below it (at "
                         f"most 2 for ksize 1), at least one of them not 0, or ksize -1 "
                         f"with dx + dy = 1; not ksize={ksize}, dx={dx}, dy={dy}")
    terms = [(sobel_taps(ksize, dx), sobel_taps(ksize, dy))]
    return _derivative("Sobel", src, terms, scale, delta, border_type, ddepth, out,
                       lambda dst, depth: cv2.Sobel(src, depth, dx, dy, dst=dst, ksize=ksize,
                                                    scale=float(scale), delta=float(delta),
                                                    borderType=int(border_type)))


def scharr(src: np.ndarray, *, dx: int, dy: int, scale: float = 1.0, delta: float = 0.0,
           border_type: int = 4, ddepth: int = 3, out: np.ndarray | None = None) -> np.ndarray:
    """Scharr / ScharrGray: cv2.Scharr(src, ddepth, dx, dy, scale=scale, delta=delta,
    borderType=border_type): (-3 0 3; -10 0 10; -3 0 3) for dx=1, its transpose for dy=1;
    as Sobel for the element types and the exactness."""
    if (int(dx), int(dy)) not in ((1, 0), (0, 1)):
        raise ValueError(f"Scharr: give dx=1, dy=0 or dx=0, dy=1, not dx={dx}, dy={dy}")
    terms = [(scharr_taps(dx), scharr_taps(dy))]
    return _derivative("Scharr", src, terms, scale, delta, border_type, ddepth, out,
                       lambda dst, depth: cv2.Scharr(src, depth, int(dx), int(dy), dst=dst,
                                                     scale=float(scale), delta=float(delta),
                                                     borderType=int(border_type)))


def laplacian(src: np.ndarray, *, ksize: int, scale: float = 1.0, delta: float = 0.0,
              border_type: int = 4, ddepth: int = 3,
              out: np.ndarray | None = None) -> np.ndarray:
    """Laplacian / LaplacianGray: cv2.Laplacian(src, ddepth, ksize=ksize, scale=scale,
    delta=delta, borderType=border_type): d2/dx2 + d2/dy2 with Sobel's second-derivative
    kernels (ksize 1: [0 1 0; 1 -4 1; 0 1 0], 3: [2 0 2; 0 -8 0; 2 0 2], 5, 7); as Sobel
    for the element types and the exactness."""
    ksize = int(ksize)
    if ksize not in (1, 3, 5, 7):
        raise ValueError(f"Laplacian: ksize must be 1, 3, 5 or 7, not {ksize}")
    d2, smooth = sobel_taps(ksize, 2), sobel_taps(ksize, 0)
    return _derivative("Laplacian", src, [(d2, smooth), (smooth, d2)], scale, delta,
                       border_type, ddepth, out,
                       lambda dst, depth: cv2.Laplacian(src, depth, dst=dst, ksize=ksize,
                                                        scale=float(scale),
                                                        delta=float(delta),
                                                        borderType=int(border_type)))


def _derivative(name: str, src: np.ndarray, terms, scale, delta, border_type, ddepth,
                out, opencv) -> np.ndarray:
    """The sum of separable correlations terms [(along x, along y), ...] times scale plus
    delta, as the generated kernel computes it (the library's derivative snippets).  A
    uint8 frame's sums are exact integers; with a whole scale below 16 and a whole delta
    (as float32, the kernel's parameters) the result is exact, and OpenCV's: its call
    (opencv(dst, depth)).  Otherwise the sum times scale, then plus delta, each rounded
    to float32; a float32 frame's sums each row's products in order (zero weights
    skipped), then the rows; to uint8 and int16 rounded to nearest even, saturated."""
    _channels(name, "src", src, (np.uint8, np.float32))
    border, depth = int(border_type), int(ddepth)
    if border not in BORDERS:
        raise ValueError(f"{name}: border_type must be one of {sorted(BORDERS)}, not {border}")
    if depth not in FILTER_DEPTHS or (src.dtype == np.float32 and depth not in (-1, 5)):
        raise ValueError(f"{name}: ddepth must be 3 (int16), 5 (float32), -1 (the input's) "
                         f"or 0 (uint8), and 5 or -1 for a float32 frame; not {depth}")
    dtype = src.dtype if depth == -1 else FILTER_DEPTHS[depth]
    dst = _output(out, src.shape, name, "dst", dtype)
    scale32, delta32 = np.float32(scale), np.float32(delta)
    if src.dtype == np.uint8 and float(scale32).is_integer() and abs(scale32) < 16 \
            and float(delta32).is_integer():
        return opencv(dst, CV_DEPTHS[np.dtype(dtype).name])
    planes = src.reshape(src.shape[0], src.shape[1], -1)
    total = None
    for kx, ky in terms:
        part = _correlation(planes, kx, ky, border)
        total = part if total is None else total + part
    value = (total * scale32) + delta32
    if dtype == np.float32:
        dst[...] = value.reshape(dst.shape)
        return dst
    info = np.iinfo(dtype)
    dst[...] = np.clip(np.rint(value), info.min, info.max).reshape(dst.shape)
    return dst


def _correlation(planes: np.ndarray, kx, ky, border: int) -> np.ndarray:
    """planes (height x width x channels) correlated with kx along x and ky along y, in
    float32: a uint8 frame's exact integer sums (cv2.sepFilter2D: below 2^24, exact), a
    float32 frame's in the kernel's order (each row's products from the left, zero weights
    skipped, then the rows from the top, each operation rounded to float32)."""
    h, w = planes.shape[:2]
    if planes.dtype == np.uint8:
        found = cv2.sepFilter2D(planes, cv2.CV_32F, np.float32(kx), np.float32(ky),
                                borderType=border)
        return found.reshape(h, w, -1)
    rx, ry = len(kx) // 2, len(ky) // 2
    padded = cv2.copyMakeBorder(planes, ry, ry, rx, rx, border).reshape(
        h + 2 * ry, w + 2 * rx, -1)
    total = np.zeros(planes.shape, np.float32)
    for j, wy in enumerate(ky):
        if wy == 0:
            continue
        row = np.zeros((h, w, planes.shape[2]), np.float32)
        for i, wx in enumerate(kx):
            if wx:
                row = row + np.float32(wx) * padded[j:j + h, i:i + w]
        total = total + np.float32(wy) * row
    return total


# -- morphology ----------------------------------------------------------------------------
MORPH_OPS = range(7)  # ERODE, DILATE, OPEN, CLOSE, GRADIENT, TOPHAT, BLACKHAT
MORPH_SHAPES = range(3)  # RECT, CROSS, ELLIPSE
MAX_MORPH_KSIZE, MAX_ITERATIONS = 15, 4


def morphology_ex(src: np.ndarray, *, op: int, shape: int, ksize: int, iterations: int,
                  out: np.ndarray | None = None, name: str = "MorphologyEx") -> np.ndarray:
    """MorphologyEx / MorphologyExGray: cv2.morphologyEx(src, op,
    cv2.getStructuringElement(shape, (ksize, ksize)), iterations=iterations); op and shape
    are OpenCV's codes (MORPH_ERODE 0 .. MORPH_BLACKHAT 6; MORPH_RECT 0, MORPH_CROSS 1,
    MORPH_ELLIPSE 2), pixels outside the frame ignored (OpenCV's default); uint8, int16
    or float32.  name: the type's, in errors (Erode and Dilate are ops 0 and 1)."""
    _channels(name, "src", src, DTYPES3)
    op, shape, iterations = int(op), int(shape), int(iterations)
    ksize = int(ksize)
    if ksize < 1 or ksize > MAX_MORPH_KSIZE or ksize % 2 == 0:
        raise ValueError(f"{name}: ksize must be odd, 1..{MAX_MORPH_KSIZE}, not {ksize}")
    if op not in MORPH_OPS or shape not in MORPH_SHAPES:
        raise ValueError(f"{name}: op must be 0..6 and shape 0..2, not {op}, {shape}")
    if not 1 <= iterations <= MAX_ITERATIONS or (iterations > 1 and shape != 0):
        raise ValueError(f"{name}: iterations must be 1..{MAX_ITERATIONS}, above 1 "
                         f"for shape 0 (MORPH_RECT) only, not {iterations} (shape {shape})")
    element = cv2.getStructuringElement(shape, (ksize, ksize))
    return cv2.morphologyEx(src, op, element, iterations=iterations,
                            dst=_output(out, src.shape, name, "dst", src.dtype))


def erode(src: np.ndarray, *, ksize: int = 3, shape: int = 0, iterations: int = 1,
          out: np.ndarray | None = None) -> np.ndarray:
    """Erode / ErodeGray: cv2.erode(src, cv2.getStructuringElement(shape, (ksize, ksize)),
    iterations=iterations): the minimum over the element, pixels outside the frame ignored
    (OpenCV's default border for morphology, the same as repeating the edge)."""
    return morphology_ex(src, op=0, shape=shape, ksize=ksize, iterations=iterations,
                         out=out, name="Erode")


def dilate(src: np.ndarray, *, ksize: int = 3, shape: int = 0, iterations: int = 1,
           out: np.ndarray | None = None) -> np.ndarray:
    """Dilate / DilateGray: cv2.dilate(src, cv2.getStructuringElement(shape, (ksize,
    ksize)), iterations=iterations): the maximum over the element, pixels outside the
    frame ignored."""
    return morphology_ex(src, op=1, shape=shape, ksize=ksize, iterations=iterations,
                         out=out, name="Dilate")


# -- helpers -------------------------------------------------------------------------------
def _image(type_name: str, port: str, array, dtype=np.uint8) -> int:
    """The channels (1 or 3) of a frame of element type dtype; anything else raises."""
    if not isinstance(array, np.ndarray) or array.dtype != dtype:
        found = getattr(array, "dtype", type(array).__name__)
        raise TypeError(f"{type_name}: '{port}' must be a {np.dtype(dtype).name} numpy "
                        f"array, not {found}")
    if 0 in array.shape or not (array.ndim == 2 or (array.ndim == 3
                                                   and array.shape[2] in (1, 3))):
        raise ValueError(f"{type_name}: '{port}' must be height x width (x 1 or x 3) with "
                         f"height and width at least 1, not {array.shape}")
    return 3 if array.ndim == 3 and array.shape[2] == 3 else 1


def _odd_ksize(type_name: str, ksize) -> int:
    ksize = int(ksize)
    if ksize < 1 or ksize > MAX_KSIZE or ksize % 2 == 0:
        raise ValueError(f"{type_name}: ksize must be odd, 1..{MAX_KSIZE}, not {ksize}")
    return ksize


CPU_OPS = {
    "GrayToRgb": gray_to_rgb,
    "RgbToBgr": swap_red_blue,
    "BgrToRgb": swap_red_blue,
    **{f"{name}{suffix}": function for suffix in ("", "Gray") for name, function in (
        ("FlipVertical", flip_vertical),
        ("BitwiseAnd", bitwise_and), ("BitwiseOr", bitwise_or), ("BitwiseXor", bitwise_xor),
        ("BitwiseNot", bitwise_not), ("BitwiseAndMask", bitwise_and_mask),
        ("Blur", blur), ("Laplacian", laplacian), ("Scharr", scharr), ("Sobel", sobel),
        ("Lut", lut),
        ("MorphologyEx", morphology_ex), ("Erode", erode), ("Dilate", dilate))},
    "Filter2D": filter_2d,
}

# last, so that either module may be imported first: cpu_kernels imports CPU_OPS at its
# end, and these helpers are defined before that import runs
from .cpu_kernels import ANY_DTYPE, DTYPES3, _channels, _output
from .cpu_kernels import _same_shape as _pair
from .kernel_tables import scharr_taps, sobel_taps
