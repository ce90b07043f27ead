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


CPU_IMPLEMENTATIONS = {
    "VerticalMirror": vertical_mirror,
    "ImageMerger": image_merger,
    "ObjectDetector": object_detector,
    "BoxBlur": box_blur,
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
