"""CPU implementations of the library's GPU-aware types, bit-exact with their kernels.

One plain numpy function per type, for the CPU side of flexible components (issue 15):
the input arrays in the shapes the ports declare (height x width x channels, uint8; one
channel is height x width), the type's parameters as keywords, the output array out.
Every function is vectorised (numpy whole-array operations, no loop over pixels) and
gives the same bytes as the type's OpenCL kernel in this folder for every size and
parameter the kernel accepts; tests/test_cpu_kernels.py runs both on PoCL and compares.

Each function also takes ``out=``, an array of the output's shape and dtype to write
into (a component allocates its outputs once, in initialize); without it, a new array.
CPU_IMPLEMENTATIONS maps each type's name to its function.
"""

from __future__ import annotations

import numpy as np


def vertical_mirror(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """VerticalMirror (vertical_mirror.cl): row y of the output is row height-1-y of image.

    The same as np.flipud and cv2.flip(image, 0), as a C-contiguous array.
    """
    _check_image("VerticalMirror", "image", image, 3)
    return _store(image[::-1], out, "VerticalMirror", "mirrored")


def image_merger(left: np.ndarray, right: np.ndarray, *,
                 out: np.ndarray | None = None) -> np.ndarray:
    """ImageMerger (image_merger.cl): left and right side by side, [left | right].

    Both frames must have the same height (the type's 'requires'); the output is
    height x (left width + right width) x 3, as np.hstack((left, right)).
    """
    _check_image("ImageMerger", "left", left, 3)
    _check_image("ImageMerger", "right", right, 3)
    if left.shape[0] != right.shape[0]:
        raise ValueError(f"ImageMerger: left and right frames must have the same height "
                         f"(left {left.shape[0]}, right {right.shape[0]} rows)")
    shape = (left.shape[0], left.shape[1] + right.shape[1], 3)
    merged = _output(out, shape, "ImageMerger", "merged")
    width = left.shape[1]
    merged[:, :width] = left
    merged[:, width:] = right
    return merged


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


def box_blur(image: np.ndarray, *, radius: int, out: np.ndarray | None = None) -> np.ndarray:
    """BoxBlur (box_blur.cl): each channel the mean of the (2 radius + 1)^2 window.

    Window coordinates are clamped to the frame (the edge pixels repeat, OpenCV's
    BORDER_REPLICATE), and the mean is rounded half up in integers:
    (sum + n // 2) // n for the n = (2 radius + 1)^2 pixels, as the kernel computes it.
    Any radius >= 0, also one larger than the frame.

    The window sums are separable: each pixel's sum along its row's window (one shifted
    copy added per column offset), then the sums of those along the column's window.
    They fit uint16: a window's sum is at most 15 * 15 * 255 = 57,375 at radius 7, the
    type's maximum (radii beyond it sum in int64).
    """
    _check_image("BoxBlur", "image", image, 3)
    radius = int(radius)
    if radius < 0:
        raise ValueError(f"BoxBlur: radius must be 0 or more, not {radius}")
    height, width = image.shape[:2]
    side = 2 * radius + 1
    n = side * side
    acc = np.uint16 if n * 255 + n // 2 < 2 ** 16 else np.int64
    # clamped coordinates: the edge pixels repeated radius times beyond each border
    padded = np.pad(image, ((radius, radius), (radius, radius), (0, 0)), mode="edge")
    rows = padded[:, :width].astype(acc)  # (height + 2 radius) x width x 3
    for dx in range(1, side):
        rows += padded[:, dx:dx + width]
    sums = rows[:height].copy()  # height x width x 3
    for dy in range(1, side):
        sums += rows[dy:dy + height]
    sums += n // 2
    sums //= n
    return _store(sums, out, "BoxBlur", "smooth")


# == imgproc.yaml: the OpenCV-like library ============================================
# Each function below serves the one-channel and the three-channel type of an operation
# (e.g. Threshold and ThresholdGray): a one-channel image is height x width, a
# three-channel one height x width x 3, as the ports declare them.  The integer rules are
# OpenCV's own 8-bit algorithms (tests/test_imgproc.py compares them with cv2 on
# photographs); the float ones (ConvertScale, AddWeighted) compute in float32 in the
# order the kernels do and round half to even, as OpenCV's saturate_cast does.

# OpenCV's codes for Threshold's thresh_type and Resize's interpolation
THRESH_BINARY, THRESH_BINARY_INV, THRESH_TRUNC, THRESH_TOZERO, THRESH_TOZERO_INV = range(5)
INTER_NEAREST, INTER_LINEAR = 0, 1
# RGB2GRAY in fixed point, 16 fractional bits (OpenCV's 15-bit coefficients doubled)
GRAY_R, GRAY_G, GRAY_B, GRAY_SHIFT = 19596, 38470, 7470, 16
HSV_SHIFT = 12  # RGB2HSV's division tables: round(255 << 12 / v), round(180 << 12 / 6 diff)
RESIZE_BITS = 11  # bilinear weights in 1/2048, as OpenCV's INTER_RESIZE_COEF_BITS


def rgb_to_gray(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """RgbToGray: cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), bit-exact.

    gray = (19596 r + 38470 g + 7470 b + 2^15) >> 16: OpenCV's fixed-point weights
    (0.299, 0.587, 0.114 in 1/65536), rounded half up.
    """
    _check_image("RgbToGray", "image", image, 3)
    r, g, b = (image[..., i].astype(np.uint32) for i in range(3))
    gray = (GRAY_R * r + GRAY_G * g + GRAY_B * b + (1 << (GRAY_SHIFT - 1))) >> GRAY_SHIFT
    return _store(gray, out, "RgbToGray", "gray")


def _div_table(numerator: int, per: int) -> np.ndarray:
    """round(numerator / (per * i)) for i = 0..255 (0 for i = 0), in integers.

    OpenCV rounds the double quotient half to even; for the two tables RGB2HSV uses no
    quotient is a tie (2 numerator / (per i) is never an odd integer), so rounding half
    up, as the kernel does, gives the same values.
    """
    i = np.arange(256, dtype=np.int64)
    table = (2 * numerator + per * i) // np.maximum(2 * per * i, 1)
    table[0] = 0
    return table


_SDIV = _div_table(255 << HSV_SHIFT, 1)  # saturation: diff * 255 / v
_HDIV = _div_table(180 << HSV_SHIFT, 6)  # hue: (hue sector offset) * 180 / (6 diff)


def rgb_to_hsv(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """RgbToHsv: cv2.cvtColor(image, cv2.COLOR_RGB2HSV), bit-exact (8-bit: hue 0..179).

    v = max(r, g, b), diff = v - min(r, g, b), s = (diff * round(255 * 4096 / v) + 2048)
    >> 12, and the hue from the channel that is the maximum (r first, then g), scaled by
    round(180 * 4096 / (6 diff)) and rounded the same way, 180 added when negative.
    """
    _check_image("RgbToHsv", "image", image, 3)
    r, g, b = (image[..., i].astype(np.int32) for i in range(3))
    v = np.maximum(np.maximum(r, g), b)
    diff = v - np.minimum(np.minimum(r, g), b)
    half = 1 << (HSV_SHIFT - 1)
    s = (diff * _SDIV[v] + half) >> HSV_SHIFT
    h = np.where(v == r, g - b, np.where(v == g, b - r + 2 * diff, r - g + 4 * diff))
    h = (h * _HDIV[diff] + half) >> HSV_SHIFT
    h += np.where(h < 0, 180, 0)
    hsv = _output(out, image.shape, "RgbToHsv", "hsv")
    hsv[..., 0], hsv[..., 1], hsv[..., 2] = h, s, v
    return hsv


def in_range(image: np.ndarray, *, out: np.ndarray | None = None, **bounds: int) -> np.ndarray:
    """InRange / InRangeGray: cv2.inRange, bit-exact: 255 where every channel c has
    lowerb_c <= value <= upperb_c, else 0; the mask is height x width.

    Bounds as keywords: lowerb_0, lowerb_1, lowerb_2, upperb_0, upperb_1, upperb_2 for
    three channels, lowerb and upperb for one.
    """
    planes = _planes("InRange", "image", image)
    n = planes.shape[2]
    names = ["lowerb", "upperb"] if n == 1 else [f"{w}_{c}" for w in ("lowerb", "upperb")
                                                 for c in range(3)]
    if sorted(bounds) != sorted(names):
        raise TypeError(f"InRange: give the bounds {', '.join(names)}, not {sorted(bounds)}")
    lower = [int(bounds[names[c]]) for c in range(n)]
    upper = [int(bounds[names[n + c]]) for c in range(n)]
    hit = np.ones(planes.shape[:2], bool)
    for c in range(n):
        hit &= (planes[..., c] >= lower[c]) & (planes[..., c] <= upper[c])
    mask = _output(out, planes.shape[:2], "InRange", "mask")
    return np.multiply(hit.view(np.uint8), 255, out=mask)


def threshold(image: np.ndarray, *, thresh: int, maxval: int, thresh_type: int,
              out: np.ndarray | None = None) -> np.ndarray:
    """Threshold / ThresholdGray: cv2.threshold(image, thresh, maxval, thresh_type)[1],
    bit-exact, every channel on its own; thresh_type is OpenCV's code: 0 BINARY
    (p > thresh ? maxval : 0), 1 BINARY_INV, 2 TRUNC (min(p, thresh)), 3 TOZERO
    (p > thresh ? p : 0), 4 TOZERO_INV."""
    _planes("Threshold", "image", image)
    thresh, maxval, kind = int(thresh), int(maxval), int(thresh_type)
    if kind not in range(5):
        raise ValueError(f"Threshold: thresh_type must be 0..4, not {kind}")
    above = image > thresh
    zero = np.zeros_like(image)
    values = {THRESH_BINARY: np.where(above, np.uint8(maxval), zero),
              THRESH_BINARY_INV: np.where(above, zero, np.uint8(maxval)),
              THRESH_TRUNC: np.where(above, np.uint8(max(thresh, 0)), image),
              THRESH_TOZERO: np.where(above, image, zero),
              THRESH_TOZERO_INV: np.where(above, zero, image)}[kind]
    return _store(values, out, "Threshold", "thresholded")


def convert_scale(image: np.ndarray, *, alpha: float, beta: float,
                  out: np.ndarray | None = None) -> np.ndarray:
    """ConvertScale / ConvertScaleGray: cv2.convertScaleAbs(image, alpha=, beta=).

    |fma(p, alpha, beta)| in float32 (one rounding, as OpenCV's vector code and the
    kernel's fma compute it), rounded half to even and saturated to 0..255.
    """
    _planes("ConvertScale", "image", image)
    return _store(_saturate(np.abs(_fma32(image, alpha, beta))), out, "ConvertScale", "scaled")


def add_weighted(src1: np.ndarray, src2: np.ndarray, *, alpha: float, beta: float,
                 gamma: float, out: np.ndarray | None = None) -> np.ndarray:
    """AddWeighted / AddWeightedGray: cv2.addWeighted(src1, alpha, src2, beta, gamma).

    fma(src1, alpha, fma(src2, beta, gamma)) in float32 (as OpenCV's vector code and the
    kernel compute it), rounded half to even and saturated to 0..255.
    """
    _same_shape("AddWeighted", src1, src2)
    inner = _fma32(src2, beta, gamma)
    return _store(_saturate(_fma32(src1, alpha, inner)), out, "AddWeighted", "blended")


def _fma32(a: np.ndarray, b: float, c) -> np.ndarray:
    """fma(a, b, c) in float32 for uint8 a, float32 b and c: the exact a * b + c rounded
    once to float32 (OpenCL's fma, correctly rounded).

    a * b is exact in float64 (8 + 24 bits); the sum is rounded to float64 with "round to
    odd" (a rounded sum that is not exact gets an odd last bit), after which rounding to
    float32 is the correct rounding of the exact value (Boldo and Melquiond, 2008).
    """
    product = a.astype(np.float64) * np.float64(np.float32(b))
    addend = np.asarray(c, np.float32).astype(np.float64)
    total = product + addend
    # the sum's rounding error (Knuth's TwoSum, exact in float64)
    back = total - product
    error = (product - (total - back)) + (addend - back)
    bits = total.view(np.int64)
    inexact_even = (error != 0) & (bits & 1 == 0)
    toward = np.where(error > 0, np.inf, -np.inf)
    total = np.where(inexact_even, np.nextafter(total, toward), total)
    return total.astype(np.float32)


def absdiff(src1: np.ndarray, src2: np.ndarray, *,
            out: np.ndarray | None = None) -> np.ndarray:
    """AbsDiff / AbsDiffGray: cv2.absdiff(src1, src2), bit-exact: |src1 - src2|."""
    _same_shape("AbsDiff", src1, src2)
    return _store(np.maximum(src1, src2) - np.minimum(src1, src2), out, "AbsDiff", "diff")


def resize(image: np.ndarray, *, width: int, height: int, interpolation: int,
           out: np.ndarray | None = None) -> np.ndarray:
    """Resize / ResizeGray: cv2.resize(image, (width, height), interpolation=).

    0 INTER_NEAREST, bit-exact: output column x reads column floor(x * (1 / (width /
    image width))) computed in double, as OpenCV does (the exact x * w / width differs
    where the double rounds an integer down), at most the last column; rows alike.
    1 INTER_LINEAR: the source position (x + 0.5) * w / width - 0.5 in exact integers,
    weights in 1/2048 rounded half up, neighbours clamped to the frame, the weighted sum
    rounded half up (differs from OpenCV's by at most 1: see docs/library.md).
    """
    planes = _planes("Resize", "image", image)
    width, height, mode = int(width), int(height), int(interpolation)
    if width < 1 or height < 1:
        raise ValueError(f"Resize: width and height must be 1 or more, not {width}x{height}")
    if mode == INTER_NEAREST:
        rows = _nearest(height, planes.shape[0])
        cols = _nearest(width, planes.shape[1])
        values = planes[rows][:, cols]
    elif mode == INTER_LINEAR:
        y0, y1, wy = _linear(height, planes.shape[0])
        x0, x1, wx = _linear(width, planes.shape[1])
        p = planes.astype(np.int64)
        wx0, wx1 = (1 << RESIZE_BITS) - wx[:, None], wx[:, None]
        top = p[y0][:, x0] * wx0 + p[y0][:, x1] * wx1
        bottom = p[y1][:, x0] * wx0 + p[y1][:, x1] * wx1
        wy0, wy1 = (1 << RESIZE_BITS) - wy[:, None, None], wy[:, None, None]
        values = (top * wy0 + bottom * wy1 + (1 << (2 * RESIZE_BITS - 1))) >> (2 * RESIZE_BITS)
    else:
        raise ValueError(f"Resize: interpolation must be 0 (nearest) or 1 (linear), not {mode}")
    return _store(_unplanes(values, image), out, "Resize", "resized")


def _nearest(dst: int, src: int) -> np.ndarray:
    """OpenCV's INTER_NEAREST source index of each output index (double arithmetic)."""
    scale = 1.0 / (dst / src)
    return np.minimum(np.floor(np.arange(dst) * scale).astype(np.int64), src - 1)


def _linear(dst: int, src: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear neighbours and the weight of the second, per output index.

    The source position of output d is ((2 d + 1) src - dst) / (2 dst): its floor s and
    the fraction in 1/2048, rounded half up; the neighbours s, s + 1 clamped to 0..src-1.
    """
    num = (2 * np.arange(dst, dtype=np.int64) + 1) * src - dst
    s = num // (2 * dst)
    frac = num - s * 2 * dst
    weight = (frac * (1 << RESIZE_BITS) + dst) // (2 * dst)
    return np.clip(s, 0, src - 1), np.clip(s + 1, 0, src - 1), weight


def crop(image: np.ndarray, *, x: int, y: int, width: int, height: int,
         out: np.ndarray | None = None) -> np.ndarray:
    """Crop / CropGray: image[y:y + height, x:x + width], the rectangle inside the frame."""
    planes = _planes("Crop", "image", image)
    x, y, width, height = int(x), int(y), int(width), int(height)
    if (min(x, y) < 0 or width < 1 or height < 1 or x + width > planes.shape[1]
            or y + height > planes.shape[0]):
        raise ValueError(f"Crop: the rectangle x={x} y={y} {width}x{height} must lie inside "
                         f"the {planes.shape[1]}x{planes.shape[0]} frame")
    return _store(image[y:y + height, x:x + width], out, "Crop", "cropped")


def flip_horizontal(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """FlipHorizontal / FlipHorizontalGray: cv2.flip(image, 1), bit-exact."""
    _planes("FlipHorizontal", "image", image)
    return _store(image[:, ::-1], out, "FlipHorizontal", "flipped")


def rotate180(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Rotate180 / Rotate180Gray: cv2.rotate(image, cv2.ROTATE_180), bit-exact."""
    _planes("Rotate180", "image", image)
    return _store(image[::-1, ::-1], out, "Rotate180", "rotated")


GAUSSIAN_WEIGHTS = {3: (1, 2, 1), 5: (1, 4, 6, 4, 1)}  # OpenCV's fixed kernels, sigma 0


def gaussian_blur(image: np.ndarray, *, ksize: int,
                  out: np.ndarray | None = None) -> np.ndarray:
    """GaussianBlur / GaussianBlurGray: cv2.GaussianBlur(image, (ksize, ksize), 0).

    ksize 3 or 5: the binomial weights (1 2 1)/4 or (1 4 6 4 1)/16 along both axes,
    borders BORDER_REFLECT_101 (OpenCV's default), the weighted sum rounded half up:
    (sum + 8) >> 4 or (sum + 128) >> 8 (OpenCV's bit-exact fixed-point blur gives the
    same).
    """
    planes = _planes("GaussianBlur", "image", image)
    ksize = int(ksize)
    if ksize not in GAUSSIAN_WEIGHTS:
        raise ValueError(f"GaussianBlur: ksize must be 3 or 5, not {ksize}")
    weights = GAUSSIAN_WEIGHTS[ksize]
    total = _separable(planes, weights, weights, reflect101=True)
    shift = 2 * (ksize - 1)  # the weights sum to 4 or 16 per axis
    return _store(_unplanes((total + (1 << (shift - 1))) >> shift, image), out,
                  "GaussianBlur", "blurred")


def sobel(image: np.ndarray, *, dx: int, dy: int, out: np.ndarray | None = None) -> np.ndarray:
    """Sobel / SobelGray: cv2.Sobel(image, cv2.CV_16S, dx, dy, ksize=3), bit-exact.

    dx=1, dy=0: (-1 0 1) along rows times (1 2 1) down columns; dx=0, dy=1 the transpose;
    borders BORDER_REFLECT_101.  Returns int16 (values -1020..1020).
    """
    planes = _planes("Sobel", "image", image)
    dx, dy = int(dx), int(dy)
    if (dx, dy) not in ((1, 0), (0, 1)):
        raise ValueError(f"Sobel: give dx=1, dy=0 or dx=0, dy=1, not dx={dx}, dy={dy}")
    derivative, smooth = (-1, 0, 1), (1, 2, 1)
    kx, ky = (derivative, smooth) if dx else (smooth, derivative)
    values = _unplanes(_separable(planes, kx, ky, reflect101=True), image)
    if out is None:
        return values.astype(np.int16)
    if out.shape != values.shape or out.dtype != np.int16:
        raise ValueError(f"Sobel: out= for 'gradient' must be int16 of shape "
                         f"{values.shape}, not {out.dtype} {out.shape}")
    np.copyto(out, values, casting="unsafe")
    return out


def erode(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Erode / ErodeGray: cv2.erode(image, np.ones((3, 3), np.uint8)), bit-exact: the
    minimum of the 3x3 window, pixels outside the frame ignored (OpenCV's default border
    for morphology), which is the same as repeating the edge."""
    return _window(image, "Erode", "eroded", np.min, out)


def dilate(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Dilate / DilateGray: cv2.dilate(image, np.ones((3, 3), np.uint8)), bit-exact: the
    maximum of the 3x3 window, pixels outside the frame ignored."""
    return _window(image, "Dilate", "dilated", np.max, out)


def median_blur(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """MedianBlur / MedianBlurGray: cv2.medianBlur(image, 3), bit-exact: the median of the
    3x3 window, edges repeated (BORDER_REPLICATE, as OpenCV's medianBlur)."""
    return _window(image, "MedianBlur", "median",
                   lambda w, axis: np.sort(w, axis=axis).take(4, axis=axis), out)


def _window(image, type_name, port, reduce, out=None) -> np.ndarray:
    """reduce over the 3x3 window of every pixel, edges repeated."""
    planes = _planes(type_name, "image", image)
    height, width = planes.shape[:2]
    padded = np.pad(planes, ((1, 1), (1, 1), (0, 0)), mode="edge")
    stack = np.stack([padded[dy:dy + height, dx:dx + width]
                      for dy in range(3) for dx in range(3)])
    return _store(_unplanes(reduce(stack, axis=0), image), out, type_name, port)


def _reflect101(index: np.ndarray, n: int) -> np.ndarray:
    """OpenCV's borderInterpolate for BORDER_REFLECT_101 (gfedcb|abcdefgh|gfedcba)."""
    if n == 1:
        return np.zeros_like(index)
    index = index.copy()
    while True:
        low, high = index < 0, index >= n
        if not (low.any() or high.any()):
            return index
        index[low] = -index[low]
        index[high] = 2 * (n - 1) - index[high]


def _separable(planes: np.ndarray, kx, ky, reflect101: bool) -> np.ndarray:
    """Sum of w_y * w_x * pixel over the window (int32), borders reflected (101)."""
    height, width = planes.shape[:2]
    r = len(kx) // 2
    rows = _reflect101(np.arange(-r, height + r), height)
    cols = _reflect101(np.arange(-r, width + r), width)
    padded = planes.astype(np.int32)[rows][:, cols]
    across = sum(w * padded[:, i:i + width] for i, w in enumerate(kx) if w)
    return sum(w * across[i:i + height] for i, w in enumerate(ky) if w)


def _saturate(values: np.ndarray) -> np.ndarray:
    """float32 -> uint8 as OpenCV's saturate_cast: round half to even, clamp to 0..255."""
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def _planes(type_name: str, port: str, array: np.ndarray) -> np.ndarray:
    """A one-channel (height x width) or three-channel image as height x width x c."""
    if not isinstance(array, np.ndarray) or array.dtype != np.uint8:
        dtype = getattr(array, "dtype", type(array).__name__)
        raise TypeError(f"{type_name}: '{port}' must be a uint8 numpy array, not {dtype}")
    if array.ndim == 2 and 0 not in array.shape:
        return array[..., None]
    _check_image(type_name, port, array, 3)
    return array


def _unplanes(values: np.ndarray, like: np.ndarray) -> np.ndarray:
    return values[..., 0] if like.ndim == 2 else values


def _same_shape(type_name: str, src1: np.ndarray, src2: np.ndarray) -> None:
    _planes(type_name, "src1", src1)
    _planes(type_name, "src2", src2)
    if src1.shape != src2.shape:
        raise ValueError(f"{type_name}: src1 and src2 must have the same size, not "
                         f"{src1.shape} and {src2.shape}")


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
        ("Rotate180", rotate180), ("GaussianBlur", gaussian_blur), ("Sobel", sobel),
        ("Erode", erode), ("Dilate", dilate), ("MedianBlur", median_blur),
        ("AbsDiff", absdiff), ("AddWeighted", add_weighted))},
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
            port: str) -> np.ndarray:
    if out is None:
        return np.empty(shape, np.uint8)
    if out.shape != tuple(shape) or out.dtype != np.uint8:
        raise ValueError(f"{type_name}: out= for '{port}' must be uint8 of shape "
                         f"{tuple(shape)}, not {out.dtype} {out.shape}")
    return out


def _store(values: np.ndarray, out: np.ndarray | None, type_name: str,
           port: str) -> np.ndarray:
    """values as a new C-contiguous uint8 array, or copied into out."""
    if out is None:
        return np.ascontiguousarray(values, dtype=np.uint8)
    target = _output(out, values.shape, type_name, port)
    np.copyto(target, values, casting="unsafe")  # the values are 0..255
    return target
