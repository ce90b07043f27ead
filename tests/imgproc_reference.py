"""Independent numpy references for the library's OpenCV operations (tests only).

The library's CPU forms (gpucompgen/library/cpu_kernels.py) call OpenCV, so comparing
them with cv2 would compare OpenCV with itself. These functions compute each operation
from its definition in plain numpy, whole-array operations, following OpenCV's 8-bit
algorithms (fixed-point colour weights, division tables, binomial weights with
BORDER_REFLECT_101, round half to even after a float32 fma): tests/test_imgproc.py
compares the CPU forms and the OpenCL kernels with them on small frames and photographs.
They were the library's CPU forms before it called OpenCV (issue 24) and are slow: 5 to
300 times cv2.
"""

from __future__ import annotations

import numpy as np

# OpenCV's codes for Threshold's thresh_type and Resize's interpolation
THRESH_BINARY, THRESH_BINARY_INV, THRESH_TRUNC, THRESH_TOZERO, THRESH_TOZERO_INV = range(5)
INTER_NEAREST, INTER_LINEAR = 0, 1
# RGB2GRAY in fixed point, 16 fractional bits (OpenCV's 15-bit coefficients doubled)
GRAY_R, GRAY_G, GRAY_B, GRAY_SHIFT = 19596, 38470, 7470, 16
HSV_SHIFT = 12  # RGB2HSV's division tables: round(255 << 12 / v), round(180 << 12 / 6 diff)
WIDE = (np.uint8, np.int16, np.float32)  # the element types of the generic operations


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


def in_range(image: np.ndarray, *, lowerb_0: float = 0, lowerb_1: float = 0,
             lowerb_2: float = 0, upperb_0: float = 255, upperb_1: float = 255,
             upperb_2: float = 255, out: np.ndarray | None = None) -> np.ndarray:
    """InRange: cv2.inRange, bit-exact: 255 where every channel c has lowerb_c <= value
    <= upperb_c, else 0; the mask is height x width.  The bounds are float32; an integer
    frame compares with them rounded half to even (numpy's rint), a float32 frame with
    them as they are."""
    planes = _planes("InRange", "image", image, WIDE)
    n = planes.shape[2]
    lower = np.float32([lowerb_0, lowerb_1, lowerb_2][:n]).astype(np.float64)
    upper = np.float32([upperb_0, upperb_1, upperb_2][:n]).astype(np.float64)
    if image.dtype != np.float32:
        lower, upper = np.rint(lower), np.rint(upper)
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
    (p > thresh ? p : 0), 4 TOZERO_INV.

    thresh and maxval are float32.  uint8 and int16 (OpenCV's thresh_8u, thresh_16s): p is
    compared with floor(thresh); maxval is rounded half to even and saturated to the type;
    TRUNC writes floor(thresh) saturated, 0 where thresh is below the type's range (OpenCV
    fills the frame with 0).  float32: thresh and maxval as they are.
    """
    _planes("Threshold", "image", image, WIDE)
    thresh, maxval, kind = float(np.float32(thresh)), float(np.float32(maxval)), int(thresh_type)
    if kind not in range(5):
        raise ValueError(f"Threshold: thresh_type must be 0..4, not {kind}")
    if image.dtype == np.float32:
        cut, top = thresh, maxval
    else:
        info = np.iinfo(image.dtype)
        thresh = float(np.floor(thresh))
        top = int(np.clip(np.rint(maxval), info.min, info.max))
        cut = 0 if thresh < info.min else int(np.clip(thresh, info.min, info.max))
    above = image > thresh
    zero = np.zeros_like(image)
    top, cut = np.array(top, image.dtype), np.array(cut, image.dtype)
    values = {THRESH_BINARY: np.where(above, top, zero),
              THRESH_BINARY_INV: np.where(above, zero, top),
              THRESH_TRUNC: np.where(above, cut, image),
              THRESH_TOZERO: np.where(above, image, zero),
              THRESH_TOZERO_INV: np.where(above, zero, image)}[kind]
    return _store(values, out, "Threshold", "thresholded", image.dtype)


def convert_scale(image: np.ndarray, *, alpha: float, beta: float,
                  out: np.ndarray | None = None) -> np.ndarray:
    """ConvertScale / ConvertScaleGray: cv2.convertScaleAbs(image, alpha=, beta=).

    |fma(p, alpha, beta)| in float32 (one rounding, as OpenCV's vector code and the
    kernel's fma compute it), rounded half to even and saturated to 0..255.
    """
    _planes("ConvertScale", "image", image, (np.uint8, np.int16, np.float32))
    return _store(_saturate(np.abs(_fma32(image, alpha, beta))), out, "ConvertScale", "scaled")


def add_weighted(src1: np.ndarray, src2: np.ndarray, *, alpha: float, beta: float,
                 gamma: float, out: np.ndarray | None = None) -> np.ndarray:
    """AddWeighted / AddWeightedGray: cv2.addWeighted(src1, alpha, src2, beta, gamma).

    uint8 and int16: fma(src1, alpha, fma(src2, beta, gamma)) in float32 (as OpenCV's
    vector code and the kernel compute it), rounded half to even and saturated to the
    type.  float32: (src1 * alpha + src2 * beta) + gamma, each operation rounded to
    float32 (the kernel's; OpenCV computes in double).
    """
    _same_shape("AddWeighted", src1, src2, WIDE)
    if src1.dtype == np.float32:
        alpha, beta, gamma = (np.float32(v) for v in (alpha, beta, gamma))
        return _store((src1 * alpha + src2 * beta) + gamma, out, "AddWeighted", "blended",
                      np.float32)
    inner = _fma32(src2, beta, gamma)
    return _store(_saturate(_fma32(src1, alpha, inner), src1.dtype), out, "AddWeighted",
                  "blended", src1.dtype)


def _fma32(a: np.ndarray, b: float, c) -> np.ndarray:
    """fma(a, b, c) in float32 for uint8, int16 or float32 a, float32 b and c: the exact a
    * b + c rounded once to float32 (OpenCL's fma, correctly rounded).

    a * b is exact in float64 (at most 24 + 24 bits); the sum is rounded to float64 with "round to
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
    """AbsDiff / AbsDiffGray: cv2.absdiff(src1, src2), bit-exact: |src1 - src2|, int16
    saturated to 32767, float32 rounded once."""
    _same_shape("AbsDiff", src1, src2, WIDE)
    if src1.dtype == np.float32:
        return _store(np.abs(src1 - src2), out, "AbsDiff", "diff", np.float32)
    wide = np.abs(src1.astype(np.int64) - src2.astype(np.int64))
    return _store(np.minimum(wide, np.iinfo(src1.dtype).max), out, "AbsDiff", "diff",
                  src1.dtype)


def resize(image: np.ndarray, *, width: int, height: int, interpolation: int,
           out: np.ndarray | None = None) -> np.ndarray:
    """Resize / ResizeGray.  0 INTER_NEAREST: output column x reads column floor(x * (1 /
    (width / image width))) computed in double, as OpenCV does (the exact x * w / width
    differs where the double rounds an integer down), at most the last column; rows
    alike.  1 INTER_LINEAR of uint8: OpenCV's fixed point (_linear_weights), each row
    blended along x in int, then along y as OpenCV's vector code rounds:
    ((b0 (top >> 4)) >> 16 + (b1 (bottom >> 4)) >> 16 + 2) >> 2."""
    planes = _planes("Resize", "image", image, WIDE)
    height, width = int(height), int(width)
    if int(interpolation) == INTER_NEAREST:
        rows = _nearest(height, planes.shape[0])
        cols = _nearest(width, planes.shape[1])
        return _store(_unplanes(planes[rows][:, cols], image), out, "Resize", "resized",
                      image.dtype)
    assert image.dtype == np.uint8
    y0, y1, b0, b1 = _linear_weights(height, planes.shape[0], edge=False)
    x0, x1, a0, a1 = _linear_weights(width, planes.shape[1], edge=True)
    p = planes.astype(np.int64)
    top = p[y0][:, x0] * a0[None, :, None] + p[y0][:, x1] * a1[None, :, None]
    bottom = p[y1][:, x0] * a0[None, :, None] + p[y1][:, x1] * a1[None, :, None]
    values = (((b0[:, None, None] * (top >> 4)) >> 16)
              + ((b1[:, None, None] * (bottom >> 4)) >> 16) + 2) >> 2
    return _store(_unplanes(values, image), out, "Resize", "resized")


def _nearest(dst: int, src: int) -> np.ndarray:
    """OpenCV's INTER_NEAREST source index of each output index (double arithmetic)."""
    scale = 1.0 / (dst / src)
    return np.minimum(np.floor(np.arange(dst) * scale).astype(np.int64), src - 1)


def _linear_weights(dst: int, src: int, edge: bool):
    """OpenCV's INTER_LINEAR neighbours and weights of each output index: the position
    (d + 0.5) (1 / (dst / src)) - 0.5 in double rounded to float32, its floor s and
    fraction f; the weights round((1 - f) 2048) and round(f 2048) (half to even, each on
    its own); along x (edge) a position outside the frame moves to the edge pixel with
    weight 0, along y only the rows are clamped."""
    scale = 1.0 / (dst / src)
    f = ((np.arange(dst) + 0.5) * scale - 0.5).astype(np.float32)
    s = np.floor(f).astype(np.int64)
    f = (f - s.astype(np.float32)).astype(np.float32)
    if edge:
        outside = (s < 0) | (s >= src - 1)
        f[outside] = 0
        s = np.clip(s, 0, src - 1)
    w0 = np.rint((np.float32(1) - f) * np.float32(2048)).astype(np.int64)
    w1 = np.rint(f * np.float32(2048)).astype(np.int64)
    return np.clip(s, 0, src - 1), np.clip(s + 1, 0, src - 1), w0, w1


def flip_horizontal(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """FlipHorizontal / FlipHorizontalGray: cv2.flip(image, 1), bit-exact."""
    _planes("FlipHorizontal", "image", image, WIDE)
    return _store(image[:, ::-1], out, "FlipHorizontal", "flipped", image.dtype)


def rotate180(image: np.ndarray, *, out: np.ndarray | None = None) -> np.ndarray:
    """Rotate180 / Rotate180Gray: cv2.rotate(image, cv2.ROTATE_180), bit-exact."""
    _planes("Rotate180", "image", image, WIDE)
    return _store(image[::-1, ::-1], out, "Rotate180", "rotated", image.dtype)


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


def erode(image: np.ndarray, *, ksize: int = 3, shape: int = 0, iterations: int = 1,
          out: np.ndarray | None = None) -> np.ndarray:
    """Erode / ErodeGray: cv2.erode(image, cv2.getStructuringElement(shape, (ksize,
    ksize)), iterations=iterations), bit-exact: the minimum over the element, applied
    iterations times, pixels outside the frame ignored (OpenCV's default border for
    morphology), which is the same as repeating the edge."""
    return _window(image, "Erode", "eroded", np.min, out, element(shape, ksize), iterations)


def dilate(image: np.ndarray, *, ksize: int = 3, shape: int = 0, iterations: int = 1,
           out: np.ndarray | None = None) -> np.ndarray:
    """Dilate / DilateGray: cv2.dilate(image, cv2.getStructuringElement(shape, (ksize,
    ksize)), iterations=iterations), bit-exact: the maximum over the element."""
    return _window(image, "Dilate", "dilated", np.max, out, element(shape, ksize), iterations)


def element(shape: int, ksize: int) -> np.ndarray:
    """The structuring element from its definition: a rectangle; a cross (the middle row
    and column); an ellipse whose row dy spans round(sqrt(r^2 - dy^2)) each side."""
    r = ksize // 2
    found = np.zeros((ksize, ksize), bool)
    for dy in range(-r, r + 1):
        w = r if shape == 0 else (r if dy == 0 else 0) if shape == 1 else \
            round((r * r - dy * dy) ** 0.5)
        found[dy + r, r - w:r + w + 1] = True
    return found


def median_blur(image: np.ndarray, *, ksize: int = 3,
                out: np.ndarray | None = None) -> np.ndarray:
    """MedianBlur / MedianBlurGray: cv2.medianBlur(image, ksize), bit-exact: the middle
    of the ksize x ksize window's sorted values, edges repeated (BORDER_REPLICATE, as
    OpenCV's medianBlur)."""
    middle = ksize * ksize // 2
    return _window(image, "MedianBlur", "median",
                   lambda w, axis: np.sort(w, axis=axis).take(middle, axis=axis), out,
                   np.ones((ksize, ksize), bool))


def _window(image, type_name, port, reduce, out=None, mask=None,
            iterations: int = 1) -> np.ndarray:
    """reduce over the window of every pixel (mask: its elements; 3x3 by default), edges
    repeated, iterations times."""
    planes = _planes(type_name, "image", image, WIDE)
    mask = np.ones((3, 3), bool) if mask is None else mask
    r = mask.shape[0] // 2
    height, width = planes.shape[:2]
    for _ in range(iterations):
        padded = np.pad(planes, ((r, r), (r, r), (0, 0)), mode="edge")
        stack = np.stack([padded[dy:dy + height, dx:dx + width]
                          for dy in range(2 * r + 1) for dx in range(2 * r + 1)
                          if mask[dy, dx]])
        planes = reduce(stack, axis=0)
    return _store(_unplanes(planes, image), out, type_name, port, image.dtype)


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


def _saturate(values: np.ndarray, dtype=np.uint8) -> np.ndarray:
    """float32 -> uint8 (or int16) as OpenCV's saturate_cast: round half to even, clamp to
    the type's range."""
    info = np.iinfo(dtype)
    return np.clip(np.rint(values), info.min, info.max).astype(dtype)


def _planes(type_name: str, port: str, array: np.ndarray, dtypes=(np.uint8,)) -> np.ndarray:
    """A one-channel (height x width) or three-channel image as height x width x c."""
    if not isinstance(array, np.ndarray) or array.dtype not in dtypes:
        dtype = getattr(array, "dtype", type(array).__name__)
        names = " or ".join(np.dtype(d).name for d in dtypes)
        raise TypeError(f"{type_name}: '{port}' must be a {names} numpy array, not {dtype}")
    if array.ndim == 2 and 0 not in array.shape:
        return array[..., None]
    if array.ndim != 3 or array.shape[2] != 3 or 0 in array.shape:
        raise ValueError(f"{type_name}: '{port}' must be height x width x 3")
    return array


def _unplanes(values: np.ndarray, like: np.ndarray) -> np.ndarray:
    return values[..., 0] if like.ndim == 2 else values


def _same_shape(type_name: str, src1: np.ndarray, src2: np.ndarray,
                dtypes=(np.uint8,)) -> None:
    _planes(type_name, "src1", src1, dtypes)
    _planes(type_name, "src2", src2, dtypes)
    if src1.shape != src2.shape or src1.dtype != src2.dtype:
        raise ValueError(f"{type_name}: src1 and src2 must have the same size, not "
                         f"{src1.shape} and {src2.shape}")


# -- helpers --------------------------------------------------------------------------
def _check_image(type_name: str, port: str, array: np.ndarray, channels: int) -> None:
    if not isinstance(array, np.ndarray) or array.dtype != np.uint8:
        raise TypeError(f"{type_name}: '{port}' must be a uint8 numpy array")
    if array.ndim != 3 or array.shape[2] != channels or 0 in array.shape:
        raise ValueError(f"{type_name}: '{port}' must be height x width x {channels}")


def _output(out, shape, type_name, port):
    return np.empty(shape, np.uint8) if out is None else out


def _store(values, out, type_name, port, dtype=np.uint8):
    if out is None:
        return np.ascontiguousarray(values, dtype=dtype)
    np.copyto(out, values, casting="unsafe")
    return out


REFERENCES = {
    "RgbToGray": rgb_to_gray,
    "RgbToHsv": rgb_to_hsv,
    **{f"{name}{suffix}": function for suffix in ("", "Gray") for name, function in (
        ("InRange", in_range), ("Threshold", threshold), ("ConvertScale", convert_scale),
        ("Resize", resize), ("FlipHorizontal", flip_horizontal),
        ("Rotate180", rotate180), ("GaussianBlur", gaussian_blur), ("Sobel", sobel),
        ("Erode", erode), ("Dilate", dilate), ("MedianBlur", median_blur),
        ("AbsDiff", absdiff), ("AddWeighted", add_weighted),
        ("ConvertScaleAbs", convert_scale))},
}
