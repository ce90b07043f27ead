"""Sobel, Scharr and Laplacian with OpenCV's parameters (issue 26): apertures 1, 3, 5, 7
(and Sobel's -1, the Scharr kernel), orders up to the aperture's, scale, delta, every
border rule, int16, uint8 and float32 outputs, of uint8 and float32 frames.

The derivative kernels (library/kernel_tables.py) equal cv2.getDerivKernels' for every
aperture and order.  On crops of photographs (one and three channels, and a frame smaller
than the largest window) the generated kernel and the CPU form give the same bytes, every
case; against OpenCV:

- a uint8 frame with a whole scale below 16 and a whole delta: bit for bit, and equal to
  an independent numpy reference (OpenCV's kernels, borderInterpolate index by index,
  int64 sums);
- otherwise (a fractional scale or delta, a float32 frame) within the bound
  docs/library.md states: 1 level for uint8 and int16 outputs, and for float32
  2^-20 (|scale| sum |weight| |pixel| + |delta|), the sum over the window: OpenCV adds in
  its own order (and its vector code rounds its own way), the type in a fixed one.

A program of the three, fused, unfused and on the CPU, gives OpenCV's frames; bad
parameters are refused with positioned errors (tests/bad_models).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_imgproc_ops import _pad

from gpucompgen.library import cpu_ops
from gpucompgen.library.kernel_tables import scharr_taps, sobel_taps

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

CV_DEPTH = {-1: -1, 0: cv2.CV_8U, 3: cv2.CV_16S, 5: cv2.CV_32F}
FLOAT_BOUND = 2.0 ** -20


def test_taps_equal_opencvs_derivative_kernels():
    for ksize in (1, 3, 5, 7):
        for order in range(3 if ksize == 1 else ksize):
            # getDerivKernels wants a derivative along one axis: ask along y for order 0
            kx, _ = cv2.getDerivKernels(order, int(order == 0), ksize)
            assert sobel_taps(ksize, order) == tuple(int(v) for v in kx.ravel()), (ksize, order)
    kx, ky = cv2.getDerivKernels(1, 0, cv2.FILTER_SCHARR)
    assert scharr_taps(1) == tuple(int(v) for v in kx.ravel()) == sobel_taps(-1, 1)
    assert scharr_taps(0) == tuple(int(v) for v in ky.ravel()) == (3, 10, 3)
    for ksize, order in ((3, 3), (9, 1), (4, 1), (-1, 2), (1, 3)):
        with pytest.raises(ValueError):
            sobel_taps(ksize, order)


# -- crops of photographs ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def crops():
    """uint8 and float32 (scaled and shifted: fractions and negatives) versions of two
    crops of odd sizes and of a 7x5 one, smaller than the largest windows (reads reflected
    more than once), gray and RGB."""
    found = []
    for load, (y, x, h, w) in ((skdata.chelsea, (60, 140, 45, 61)),
                               (skdata.coffee, (150, 220, 38, 53)),
                               (skdata.astronaut, (100, 200, 7, 5))):
        rgb = np.ascontiguousarray(load()[y:y + h, x:x + w])
        for frame in (rgb, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)):
            found.append(frame)
            found.append((frame.astype(np.float32) - np.float32(100.3)) * np.float32(0.37))
    return found


@pytest.fixture(scope="module")
def gpu(run_alone):
    return run_alone


def _opencv(type_name, src, p):
    depth = CV_DEPTH[p["ddepth"]]
    keys = {"scale": p["scale"], "delta": p["delta"], "borderType": p["border_type"]}
    if type_name == "Sobel":
        return cv2.Sobel(src, depth, p["dx"], p["dy"], ksize=p["ksize"], **keys)
    if type_name == "Scharr":
        return cv2.Scharr(src, depth, p["dx"], p["dy"], **keys)
    return cv2.Laplacian(src, depth, ksize=p["ksize"], **keys)


def _terms(type_name, p) -> list[tuple[np.ndarray, np.ndarray]]:
    """The (along x, along y) kernel pairs summed, from OpenCV's own getDerivKernels."""
    if type_name == "Laplacian":
        d2, smooth = (k.ravel() for k in cv2.getDerivKernels(2, 0, p["ksize"]))
        return [(d2, smooth), (smooth, d2)]
    ksize = cv2.FILTER_SCHARR if type_name == "Scharr" else p["ksize"]
    kx, ky = cv2.getDerivKernels(p["dx"], p["dy"], ksize)
    return [(kx.ravel(), ky.ravel())]


def _window_sums(src, terms, border, absolute: bool) -> np.ndarray:
    """sum over the window of weight * pixel (or |weight| |pixel|), float64 (int64 for
    integers: exact), the frame padded by borderInterpolate's rule index by index."""
    r = max(len(k) for pair in terms for k in pair) // 2
    padded = _pad(src, r, border)
    padded = np.abs(padded.astype(np.float64)) if absolute else \
        padded.astype(np.int64 if src.dtype == np.uint8 else np.float64)
    h, w = src.shape[:2]
    total = 0
    for kx, ky in terms:
        for j, wy in enumerate(ky):
            for i, wx in enumerate(kx):
                weight = abs(wy * wx) if absolute else int(wy * wx)
                if weight:
                    y0, x0 = r - len(ky) // 2 + j, r - len(kx) // 2 + i
                    total = total + weight * padded[y0:y0 + h, x0:x0 + w]
    return total


def _exact(src, p) -> bool:
    scale, delta = np.float32(p["scale"]), np.float32(p["delta"])
    return src.dtype == np.uint8 and float(scale).is_integer() and abs(scale) < 16 \
        and float(delta).is_integer()


DEFAULTS = {"scale": 1.0, "delta": 0.0, "border_type": 4, "ddepth": 3}
# (type, parameters, channels, float32 frames): every aperture, orders up to the
# aperture's (Sobel's 6th at ksize 7, saturating int16), every border rule and output
# type, whole and fractional scales and deltas (0.5 with ties), scales from 16 (float
# sums), float32 frames
CASES = [
    ("Sobel", {"dx": 2, "dy": 0, "ksize": 3}, 3, False),
    ("Sobel", {"dx": 1, "dy": 1, "ksize": 5, "border_type": 0}, 1, False),
    ("Sobel", {"dx": 0, "dy": 3, "ksize": 7, "border_type": 1, "ddepth": 5}, 1, False),
    ("Sobel", {"dx": 1, "dy": 0, "ksize": 1, "border_type": 2}, 3, False),
    ("Sobel", {"dx": 0, "dy": 2, "ksize": 1, "ddepth": 0, "scale": 0.5, "delta": 100.0},
     1, False),
    ("Sobel", {"dx": 1, "dy": 0, "ksize": -1, "scale": 2.0, "delta": -7.0}, 1, False),
    ("Sobel", {"dx": 2, "dy": 2, "ksize": 5, "ddepth": 5, "scale": 1 / 256, "delta": 0.25},
     3, False),
    ("Sobel", {"dx": 6, "dy": 0, "ksize": 7}, 1, False),
    ("Sobel", {"dx": 1, "dy": 0, "ksize": 3, "scale": 20.0, "delta": -5.0}, 1, False),
    ("Sobel", {"dx": 1, "dy": 0, "ksize": 3, "ddepth": -1}, 1, True),
    ("Sobel", {"dx": 2, "dy": 1, "ksize": 5, "ddepth": 5, "border_type": 0, "scale": 0.3,
               "delta": -1.5}, 3, True),
    ("Laplacian", {"ksize": 7, "ddepth": 5, "border_type": 2}, 1, True),
    ("Laplacian", {"ksize": 5, "ddepth": 0, "scale": 0.25, "delta": 128.0}, 1, False),
    ("Laplacian", {"ksize": 3, "scale": 0.5, "delta": 0.5}, 3, False),
    ("Scharr", {"dx": 0, "dy": 1, "ddepth": -1, "scale": 2.0, "border_type": 1}, 3, True),
    ("Scharr", {"dx": 1, "dy": 0, "ddepth": 5, "scale": 1 / 32}, 1, False),
]


def _case_id(case) -> str:
    name, params, channels, floats = case
    return name + "_" + "_".join(f"{k}{v:g}" for k, v in params.items()) + \
        f"_{channels}ch" + "_f32" * floats


@pytest.mark.parametrize("case", CASES, ids=[_case_id(c) for c in CASES])
def test_derivatives_against_opencv(case, crops, gpu):
    type_name, given, channels, floats = case
    p = {**DEFAULTS, **given}
    frames = [f for f in crops if (f.ndim == 3) == (channels == 3)
              and (f.dtype == np.float32) == floats]
    worst = 0.0
    for i, src in enumerate(frames):
        what = f"{type_name} {given} on crop {i}"
        expected = _opencv(type_name, src, p)
        cpu = cpu_ops.CPU_OPS[type_name](src, **p)
        found = gpu(type_name, src, p)
        assert cpu.dtype == expected.dtype and cpu.shape == expected.shape, what
        np.testing.assert_array_equal(found, cpu, err_msg=f"GPU against the CPU form, {what}")
        if _exact(src, p):
            np.testing.assert_array_equal(cpu, expected, err_msg=f"CPU form {what}")
            sums = _window_sums(src, _terms(type_name, p), p["border_type"], False)
            value = sums * int(p["scale"]) + int(p["delta"])
            if expected.dtype != np.float32:
                value = np.clip(value, np.iinfo(expected.dtype).min,
                                np.iinfo(expected.dtype).max)
            np.testing.assert_array_equal(value.astype(expected.dtype), expected,
                                          err_msg=f"numpy reference {what}")
            continue
        off = np.abs(cpu.astype(np.float64) - expected)
        if expected.dtype != np.float32:
            assert off.max() <= 1, what
            continue
        magnitude = abs(p["scale"]) * _window_sums(src, _terms(type_name, p),
                                                   p["border_type"], True) + abs(p["delta"])
        assert (off <= FLOAT_BOUND * magnitude.reshape(off.shape)).all(), what
        worst = max(worst, float((off / np.maximum(magnitude.reshape(off.shape), 1e-30))
                                 .max()))
    print(f"{_case_id(case)}: largest |ours - OpenCV| / bound's sum = {worst:.3g} "
          f"(2^-20 = {FLOAT_BOUND:.3g})")
