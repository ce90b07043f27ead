"""Erode and Dilate with OpenCV's structuring elements (issue 26: 'morphology is 3x3, one
iteration'): rectangles, crosses and ellipses of odd sides 1..15, a rectangle iterated up
to 4 times, over uint8, int16 and float32 frames of one and three channels; MedianBlur's
windows 3 and 5 over the three element types and up to 15 over uint8 (OpenCV's limits).

On crops of photographs (and a frame smaller than the window), cv2.erode / cv2.dilate, the
CPU form, the generated kernel and the numpy reference (imgproc_reference: the element
from its definition, the minimum or maximum over it with the edge repeated, applied
iterations times, not folded into one wider window; the median the middle of the sorted
window) are all equal, bit for bit.  The median network of 5 x 5 is checked on its own
over random and many-tied windows.
"""

from __future__ import annotations

import imgproc_reference
import numpy as np
import pytest

from gpucompgen.library import cpu_kernels, cpu_ops
from gpucompgen.library.kernel_tables import median_network

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

DTYPES = ("uint8", "int16", "float32")


@pytest.fixture(scope="module")
def crops():
    """Per element type, gray and RGB versions of two odd-sized crops and of a 5x7 one
    (smaller than the largest windows): int16 spread over negatives, float32 with
    fractions."""
    found = {d: {1: [], 3: []} for d in DTYPES}
    for load, (y, x, h, w) in ((skdata.chelsea, (60, 140, 45, 61)),
                               (skdata.coffee, (150, 220, 38, 53)),
                               (skdata.astronaut, (100, 200, 5, 7))):
        rgb = np.ascontiguousarray(load()[y:y + h, x:x + w])
        for channels, frame in ((3, rgb), (1, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))):
            found["uint8"][channels].append(frame)
            found["int16"][channels].append((frame.astype(np.int16) - 128) * 97)
            found["float32"][channels].append(
                (frame.astype(np.float32) - np.float32(100.3)) * np.float32(0.37))
    return found


@pytest.fixture(scope="module")
def gpu(run_alone):
    return run_alone


# (ksize, shape, iterations): the sides 1 and 15 (a rectangle and a cross; the ellipse to
# 11), every shape at 3, 5 and more, a rectangle iterated 2 and 4 times.  Windows of
# hundreds of elements take PoCL tens of seconds to compile (5 x 5 iterated 4 times: 35 s
# for three int16 channels); MorphologyEx's tests cover those.
ELEMENTS = [(1, 0, 1), (5, 0, 1), (3, 1, 1), (7, 1, 1), (3, 2, 1), (5, 2, 1), (9, 2, 1),
            (11, 2, 1), (15, 0, 1), (3, 0, 2), (3, 0, 4), (15, 1, 1)]
# each element over one element type, channel count and operation (a build each)
RUNS = [("Erode" if i % 2 == 0 else "Dilate", element, DTYPES[i % 3], 1 + 2 * ((i // 3) % 2))
        for i, element in enumerate(ELEMENTS)]


@pytest.mark.parametrize(("op", "element", "dtype", "channels"), RUNS,
                         ids=[f"{o}_k{e[0]}_s{e[1]}_i{e[2]}_{d}_{c}ch" for o, e, d, c in RUNS])
def test_erode_and_dilate_equal_opencv(op, element, dtype, channels, crops, gpu):
    ksize, shape, iterations = element
    params = {"ksize": ksize, "shape": shape, "iterations": iterations}
    opencv = cv2.erode if op == "Erode" else cv2.dilate
    reference = imgproc_reference.erode if op == "Erode" else imgproc_reference.dilate
    for i, src in enumerate(crops[dtype][channels]):
        what = f"{op} {params} on {dtype} crop {i}, {channels} channels"
        expected = opencv(src, cv2.getStructuringElement(shape, (ksize, ksize)),
                          iterations=iterations)
        np.testing.assert_array_equal(reference(src, **params), expected,
                                      err_msg=f"numpy reference {what}")
        np.testing.assert_array_equal(cpu_ops.CPU_OPS[op](src, **params), expected,
                                      err_msg=f"CPU form {what}")
        np.testing.assert_array_equal(gpu(op, src, params), expected, err_msg=f"GPU {what}")


def test_the_median_network_leaves_the_median_in_its_slot():
    count, slot, *flat = median_network(5)
    pairs = list(zip(flat[::2], flat[1::2], strict=True))
    assert count == len(pairs) == 113 and all(0 <= a < 25 and 0 <= b < 25 for a, b in pairs)
    rng = np.random.default_rng(26)
    for trial in range(3000):  # values from few (ties everywhere) to many
        values = list(rng.integers(0, (2, 6, 1000)[trial % 3], 25))
        expected = sorted(values)[12]
        for a, b in pairs:
            values[a], values[b] = min(values[a], values[b]), max(values[a], values[b])
        assert values[slot] == expected
    assert median_network(3) == median_network(7) == (0, 0)


# (ksize, element type, channels): 3 and 5 over every element type, then uint8's larger
# windows (OpenCV's medianBlur takes 7 and above for uint8 only), up to 15
# (three channels of 5x5 int16 took 35 s to compile: uint8's 12 s stand for them)
MEDIANS = [(5, "uint8", 3), (5, "int16", 1), (5, "float32", 1), (3, "float32", 3),
           (7, "uint8", 1), (9, "uint8", 1), (15, "uint8", 1)]


@pytest.mark.parametrize(("ksize", "dtype", "channels"), MEDIANS,
                         ids=[f"k{k}_{d}_{c}ch" for k, d, c in MEDIANS])
def test_median_blur_equals_opencv(ksize, dtype, channels, crops, gpu):
    # each frame size is a build: three channels of 5x5 (12 s each) on the first crop only
    frames = crops[dtype][channels][:1 if channels == 3 and ksize == 5 else None]
    for i, src in enumerate(frames):
        what = f"MedianBlur ksize {ksize} on {dtype} crop {i}, {channels} channels"
        expected = cv2.medianBlur(src, ksize)
        np.testing.assert_array_equal(imgproc_reference.median_blur(src, ksize=ksize),
                                      expected, err_msg=f"numpy reference {what}")
        np.testing.assert_array_equal(cpu_kernels.median_blur(src, ksize=ksize), expected,
                                      err_msg=f"CPU form {what}")
        np.testing.assert_array_equal(gpu("MedianBlur", src, {"ksize": ksize}), expected,
                                      err_msg=f"GPU {what}")
    with pytest.raises(ValueError, match="odd up to 15 for uint8 frames"):
        cpu_kernels.median_blur(crops["int16"][1][0], ksize=7)
