"""InRange, Resize and Crop as one type each over 1 or 3 channels and the element types
OpenCV gives them (issue 26), the old one-channel names deprecated aliases; element types
for Blur, GaussianBlur and MorphologyEx; Filter2D's output depth (ddepth).

Every case runs as OpenCV's call, as the type's CPU form and as the OpenCL kernel the
generator writes from its fusable form (conftest.run_generated, on PoCL), on small crops of
photographs, equal bit for bit, or within the bound docs/library.md states where OpenCV
computes in floating point that one cannot follow bit for bit.  Few kernel builds: each
case is one build (sizes and parameters are constants of a generated kernel).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_opencl, run_generated

from gpucompgen.library import cpu_kernels

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")


@pytest.fixture(scope="module")
def photos():
    """{dtype: (RGB crop of one photograph, one-channel crop of another)}: uint8; int16
    over the whole range (p * 257 - 32768); float32 with fractions and negatives."""
    rgb = np.ascontiguousarray(skdata.chelsea()[60:101, 100:163])
    gray = np.ascontiguousarray(skdata.coffee()[150:187, 200:259, 1])
    out = {"uint8": (rgb, gray)}
    out["int16"] = tuple((a.astype(np.int32) * 257 - 32768).astype(np.int16)
                         for a in (rgb, gray))
    out["float32"] = tuple(a.astype(np.float32) * np.float32(0.73) - np.float32(41.5)
                           for a in (rgb, gray))
    return out


@pytest.fixture(scope="module")
def gpu(cl_context, cl_queue):
    require_opencl()
    from gpucompgen.model import library_types

    types = library_types()

    def run(type_name, arrays, params, shape):
        return run_generated(cl_context, cl_queue, types[type_name], params, arrays, shape)
    return run


def check(type_name: str, arrays: list, params: dict, reference: np.ndarray, gpu,
          what: str = "") -> None:
    """CPU form = GPU kernel = reference, bit for bit."""
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
    assert cpu.dtype == reference.dtype, what
    np.testing.assert_array_equal(cpu.reshape(reference.shape), reference,
                                  err_msg=f"CPU {type_name} {what} {params}")
    found = gpu(type_name, arrays, params, reference.shape)
    np.testing.assert_array_equal(found, reference, err_msg=f"GPU {type_name} {what} {params}")


# -- InRange, Resize, Crop ---------------------------------------------------------------
INRANGE = {  # bounds that are fractions, outside the type's range, empty (lower > upper)
    "uint8": {"lowerb_0": 40.5, "upperb_0": 200.5, "lowerb_1": -7, "upperb_1": 180,
              "lowerb_2": 60, "upperb_2": 300},
    "int16": {"lowerb_0": -20000.5, "upperb_0": 15000, "lowerb_1": -40000, "upperb_1": 9000.5,
              "lowerb_2": -9000, "upperb_2": 40000},
    "float32": {"lowerb_0": -10.25, "upperb_0": 95.125, "lowerb_1": 0.5, "upperb_1": 120.75,
                "lowerb_2": -50, "upperb_2": 60.5},
}


@pytest.mark.parametrize("dtype", sorted(INRANGE))
def test_in_range_per_channel_bounds_on_photographs(dtype, photos, gpu):
    bounds = INRANGE[dtype]
    rgb, gray = photos[dtype]
    lower = [float(np.float32(bounds[f"lowerb_{c}"])) for c in range(3)]
    upper = [float(np.float32(bounds[f"upperb_{c}"])) for c in range(3)]
    reference = cv2.inRange(rgb, np.array(lower), np.array(upper))
    assert 0 < (reference > 0).mean() < 1, "the bounds cut the photograph"
    check("InRange", [rgb], bounds, reference, gpu, dtype)
    reference = cv2.inRange(gray, lower[0], upper[0])
    assert 0 < (reference > 0).mean() < 1
    check("InRange", [gray], bounds, reference, gpu, dtype)  # channels 1, 2 unused


# (height, width) of the output: larger and smaller than the photograph's crops, ratios
# that are no whole factor, one channel and three
RESIZES = [((57, 97), 0), ((23, 40), 1)]  # (size, which photograph: 0 RGB, 1 one channel)


@pytest.mark.parametrize("dtype", ["uint8", "int16", "float32"])
def test_resize_nearest_every_element_type(dtype, photos, gpu):
    for (h, w), which in RESIZES:
        src = photos[dtype][which]
        params = {"width": w, "height": h, "interpolation": 0}
        reference = cv2.resize(src, (w, h), interpolation=cv2.INTER_NEAREST)
        check("Resize", [src], params, reference, gpu, dtype)


@pytest.mark.parametrize(("size", "which"), [
    ((29, 44), 0),  # shrinks by 1.41 and 1.43
    ((80, 100), 1),  # enlarges (the edges: weights moved along x, rows clamped along y)
    ((20, 31), 0),  # halves 41 x 63 to 20 x 31, no whole factor
    ((18, 29), 1),  # a whole factor 2 along y and x of a 36 x 58 frame (OpenCV: INTER_AREA)
])
def test_resize_bilinear_uint8_bit_exact(size, which, photos, gpu):
    src = photos["uint8"][which]
    if size == (18, 29):
        src = np.ascontiguousarray(src[:36, :58])
    h, w = size
    params = {"width": w, "height": h, "interpolation": 1}
    reference = cv2.resize(src, (w, h), interpolation=cv2.INTER_LINEAR)
    check("Resize", [src], params, reference, gpu, f"{src.shape} to {size}")


@pytest.mark.parametrize(("dtype", "which"), [("int16", 0), ("float32", 1), ("uint16", 0)])
def test_crop_any_element_type(dtype, which, photos, gpu):
    src = photos.get(dtype, photos["int16"])[which]
    if dtype == "uint16":
        src = src.view(np.uint16)
    params = {"left": 5, "top": 3, "width": 21, "height": 17}
    check("Crop", [src], params, np.ascontiguousarray(src[3:20, 5:26]), gpu, dtype)


# -- element types for Blur and MorphologyEx ---------------------------------------------
WIDE = ("int16", "float32")  # the element types new to these operations


@pytest.mark.parametrize("dtype", WIDE)
def test_blur_element_types_on_photographs(dtype, photos, gpu):
    """int16: sums in int, rounded to nearest (negative ones too), as OpenCV; float32:
    OpenCV's sum in double (exact for these frames) divided, which the kernel's exact
    two-float sum gives bit for bit."""
    for which, ksize, border in ((0, 3, 4), (1, 5, 0), (1, 7, 2)):
        src = photos[dtype][which]
        reference = cv2.blur(src, (ksize, ksize), borderType=border)
        check("Blur", [src], {"ksize": ksize, "border_type": border}, reference, gpu,
              f"{dtype} ksize {ksize} border {border}")


@pytest.mark.parametrize("dtype", WIDE)
def test_morphology_ex_element_types_on_photographs(dtype, photos, gpu):
    """The minimum and maximum of any element type; gradient, top hat and black hat
    saturated as OpenCV's subtract (int16: dilate - erode reaches 65535)."""
    for which, op, shape, ksize in ((0, 4, 0, 3), (1, 5, 2, 5), (0, 6, 1, 3)):
        src = photos[dtype][which]
        element = cv2.getStructuringElement(shape, (ksize, ksize))
        reference = cv2.morphologyEx(src, op, element)
        params = {"op": op, "shape": shape, "ksize": ksize, "iterations": 1}
        check("MorphologyEx", [src], params, reference, gpu, dtype)
        if dtype == "int16" and op == 4:  # the photograph's edges at the type's ends
            edges = np.where(src > 0, 32767, -32768).astype(np.int16)
            reference = cv2.morphologyEx(edges, op, element)
            assert (reference == 32767).any(), "a gradient that saturates"
            check("MorphologyEx", [edges], params, reference, gpu, "int16 edges")
