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
from conftest import opencv_fuses_multiply_adds, require_opencl, run_generated

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
        ctype, first = types[type_name], np.asarray(arrays[0])
        # the ports a component fed these arrays with these parameters gets (Filter2D's
        # ddepth gives its output's element type)
        ctype = ctype.specialized(first.dtype.name, first.shape[2] if first.ndim == 3 else 1,
                                  params)
        return run_generated(cl_context, cl_queue, ctype, params, arrays, shape)
    return run


def check(type_name: str, arrays: list, params: dict, reference: np.ndarray, gpu,
          what: str = "", within_one: float = 0.0) -> None:
    """CPU form = GPU kernel = reference, bit for bit; or the GPU within 1 of it on at
    most the fraction within_one of the elements (a stated bound)."""
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
    assert cpu.dtype == reference.dtype, what
    np.testing.assert_array_equal(cpu.reshape(reference.shape), reference,
                                  err_msg=f"CPU {type_name} {what} {params}")
    found = gpu(type_name, arrays, params, reference.shape)
    if within_one:
        differ = found != reference
        assert differ.mean() <= within_one, f"GPU {type_name} {what}: {differ.mean():.2%}"
        found = np.where(np.abs(found.astype(np.int64) - reference) <= 1, reference, found)
    np.testing.assert_array_equal(found, reference, err_msg=f"GPU {type_name} {what} {params}")


FMA = opencv_fuses_multiply_adds()


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
    # a whole factor 2 along y and x of a 36 x 58 frame (OpenCV: INTER_AREA; the kernel's
    # 2x2 means), one channel and three; along x only (the general rule)
    ((18, 29), 1),
    ((18, 29), 0),
    ((25, 29), 1),
])
def test_resize_bilinear_uint8_bit_exact(size, which, photos, gpu):
    src = photos["uint8"][which]
    if size[1] == 29:
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


# -- colour order and gray to three channels of float32 frames ----------------------------
@pytest.mark.parametrize(("type_name", "code", "which"), [
    ("GrayToRgb", cv2.COLOR_GRAY2RGB, 1), ("RgbToBgr", cv2.COLOR_RGB2BGR, 0),
    ("BgrToRgb", cv2.COLOR_BGR2RGB, 0)])
def test_channel_order_of_float32_frames(type_name, code, which, photos, gpu):
    """cv2.cvtColor takes float32 frames as uint8 ones (int16 it refuses): the same
    copies, bit-exact."""
    src = photos["float32"][which]
    check(type_name, [src], {}, cv2.cvtColor(src, code), gpu, "float32")
    with pytest.raises(TypeError, match="uint8 or float32"):
        cpu_kernels.CPU_IMPLEMENTATIONS[type_name](photos["int16"][which])


def test_gray_of_float32_frames(photos, gpu):
    """RgbToGray of float32: OpenCV's vector code, fma(b, 0.114, fma(r, 0.299, g 0.587)),
    bit-exact on a CPU with FMA, but for the last columns of a row, which its scalar code
    computes in another order (fewer than a vector's width: 32 covers AVX-512), and
    anywhere on a CPU without FMA: there within 2 ulp of the largest channel."""
    src = photos["float32"][0]
    reference = cv2.cvtColor(src, cv2.COLOR_RGB2GRAY)
    np.testing.assert_array_equal(cpu_kernels.CPU_IMPLEMENTATIONS["RgbToGray"](src),
                                  reference)
    found = gpu("RgbToGray", [src], {}, reference.shape)
    assert found.dtype == np.float32
    differ = found != reference
    if FMA:
        assert (np.nonzero(differ)[1] >= reference.shape[1] - 32).all()
    assert (np.abs(found - reference) <= 2 * np.spacing(np.abs(src).max(-1))).all()


# -- element types for Blur and MorphologyEx ---------------------------------------------
WIDE = ("int16", "float32")  # the element types new to these operations


@pytest.mark.parametrize("dtype", WIDE)
def test_blur_element_types_on_photographs(dtype, photos, gpu):
    """int16: sums in int, rounded to nearest (negative ones too), as OpenCV.  float32:
    OpenCV sums in double, the kernel in float32 (each row's sum, then the column's):
    the CPU form adds in the kernel's order (the same bytes, whatever the placement),
    within 2^-24 (2 ksize - 1) of the mean of |src| of OpenCV (docs/library.md); windows
    up to 31, wider than the crop (reflected more than once), every border code."""
    cases = ((0, 3, 4), (1, 5, 0), (1, 7, 2))
    if dtype == "float32":
        cases += ((0, 31, 1), (1, 13, 4))
    for which, ksize, border in cases:
        src = photos[dtype][which]
        what = f"{dtype} ksize {ksize} border {border}"
        params = {"ksize": ksize, "border_type": border}
        reference = cv2.blur(src, (ksize, ksize), borderType=border)
        if dtype == "int16":
            check("Blur", [src], params, reference, gpu, what)
            continue
        cpu = cpu_kernels.CPU_IMPLEMENTATIONS["Blur"](src, **params)
        np.testing.assert_array_equal(gpu("Blur", [src], params, reference.shape), cpu,
                                      err_msg=f"GPU against the CPU form, {what}")
        magnitude = cv2.blur(np.abs(src).astype(np.float64), (ksize, ksize),
                             borderType=border)
        off = np.abs(cpu.astype(np.float64) - reference)
        bound = 2.0 ** -24 * (2 * ksize - 1) * magnitude
        assert (off <= bound).all(), f"{what}: {(off / bound).max():.2f} of the bound"
        assert off.max() > 0 or ksize < 5, "a case where float32 and double sums differ"


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


# -- Filter2D's output depth ---------------------------------------------------------------
SHARPEN_3 = [[0, -1, 0], [-1, 5, -1], [0, -1, 0]]
FILTER_CASES = [  # (which photograph, weights, delta, border_type)
    (0, SHARPEN_3, 0.0, 4),
    (1, [[0.31, -1.7, 0.25], [2.5, -0.61, 0.0], [0.125, 1.1, -3.3], [0.7, 0.0, -0.2],
         [-0.9, 0.45, 1.3]], 3.25, 0),
]


@pytest.mark.parametrize("ddepth", [3, 5])
def test_filter2d_int16_and_float32_outputs(ddepth, photos, gpu):
    """int16 (CV_16S): OpenCV's fma sums rounded and saturated, as for uint8 (and, as
    for uint8, within 1 where OpenCV's code for the last elements of a row rounds a
    product first and the sum is within a rounding of a half: 1 element of 2,183 here);
    float32 (CV_32F): each product rounded, then added, as OpenCV's filter without
    vector code, bit-exact."""
    for which, weights, delta, border in FILTER_CASES:
        src = photos["uint8"][which]
        reference = cv2.filter2D(src, ddepth, np.float32(weights), delta=delta,
                                 borderType=border)
        assert reference.dtype == {3: np.int16, 5: np.float32}[ddepth]
        params = {"weights": tuple(tuple(r) for r in weights), "delta": delta,
                  "border_type": border, "ddepth": ddepth}
        check("Filter2D", [src], params, reference, gpu, f"ddepth {ddepth}",
              within_one=0.001 if ddepth == 3 else 0.0)
        if ddepth == 3:
            assert reference.min() < 0 and reference.max() > 255, "beyond uint8"


def test_filter2d_float32_from_130_elements_within_the_bound(photos, gpu):
    """From 130 weights OpenCV convolves by DFT: the direct sum is within 2^-22 * 255 *
    sum(|weights|) of it (docs/library.md; 1.2e-7 of that scale at most on photographs)."""
    weights = (np.random.default_rng(3).standard_normal((13, 11)) * 0.3).astype(np.float32)
    src = photos["uint8"][0]
    params = {"weights": tuple(map(tuple, weights.tolist())), "delta": 1.5,
              "border_type": 4, "ddepth": 5}
    opencv = cv2.filter2D(src, cv2.CV_32F, weights, delta=1.5, borderType=4)
    found = gpu("Filter2D", [src], params, opencv.shape)
    bound = 2.0 ** -22 * 255 * float(np.abs(weights).sum())
    assert np.abs(found - opencv).max() <= bound
    np.testing.assert_array_equal(cpu_kernels.CPU_IMPLEMENTATIONS["Filter2D"](src, **params),
                                  opencv)


# (which photograph, weights: a sharpening kernel, OpenCV's DFT sizes for an int16 frame
# (from 50) and for float32 to float32 (from 130) and below them, delta, border_type)
_RNG = np.random.default_rng(11)
WIDE_FILTERS = [
    (0, np.float32(SHARPEN_3), 0.5, 4),
    (1, (_RNG.standard_normal((7, 7)) * 0.3).astype(np.float32), -3.25, 0),  # 49: direct
    (1, (_RNG.standard_normal((8, 7)) * 0.3).astype(np.float32), 1.5, 2),  # 56: int16's DFT
    (0, (_RNG.standard_normal((13, 11)) * 0.3).astype(np.float32), 0.0, 1),  # 143: DFT
]


@pytest.mark.parametrize(("dtype", "ddepth"), [("int16", -1), ("int16", 5), ("float32", -1)])
def test_filter2d_of_int16_and_float32_frames(dtype, ddepth, photos, gpu):
    """int16 frames: OpenCV's direct sums below 50 weights (int16 out: fma, as for uint8;
    float32 out: each product rounded, no vector code), bit-exact; from 50 its DFT, within
    1 level (int16) or 2^-22 (sum |weight| |pixel| + |delta|) (float32).  float32 frames:
    OpenCV's vector fma but for the last elements of a row (its scalar code): within that
    bound at every size (docs/library.md)."""
    for which, weights, delta, border in WIDE_FILTERS:
        src = photos[dtype][which]
        what = f"{dtype} ddepth {ddepth} {weights.shape} border {border}"
        reference = cv2.filter2D(src, ddepth, weights, delta=delta, borderType=border)
        params = {"weights": tuple(map(tuple, weights.tolist())), "delta": delta,
                  "border_type": border, "ddepth": ddepth}
        cpu = cpu_kernels.CPU_IMPLEMENTATIONS["Filter2D"](src, **params)
        np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU {what}")
        found = gpu("Filter2D", [src], params, reference.shape)
        assert found.dtype == reference.dtype, what
        direct = dtype == "int16" and weights.size < 50
        if reference.dtype == np.int16:
            check("Filter2D", [src], params, reference, gpu, what,
                  within_one=0.0 if direct else 0.005)
            continue
        if direct:
            np.testing.assert_array_equal(found, reference, err_msg=f"GPU {what}")
            continue
        magnitude = cv2.filter2D(np.abs(src).astype(np.float64), -1,
                                 np.abs(weights).astype(np.float64), borderType=border)
        off = np.abs(found.astype(np.float64) - reference)
        assert (off <= 2.0 ** -22 * (magnitude + abs(delta))).all(), \
            f"{what}: {(off / (magnitude + abs(delta))).max() / 2.0 ** -22:.2f} x 2^-22"


@pytest.mark.parametrize(("dtype", "ddepth"), [("int16", 0), ("float32", 0), ("float32", 3)])
def test_filter2d_refuses_opencvs_refused_depths(dtype, ddepth, photos):
    """cv2.filter2D gives uint8 of uint8 frames only, float32 of float32 ones: the CPU
    form says so, as the model's check does (tests/test_bad_models.py)."""
    with pytest.raises(ValueError, match="ddepth must be"):
        cpu_kernels.CPU_IMPLEMENTATIONS["Filter2D"](photos[dtype][1], weights=[[1.0]],
                                                    ddepth=ddepth)


# -- one generated program: the types above over their element types and channel counts,
# and the old names with their old parameters, fused, unfused and on the CPU -----------------
SHARPEN = [[0, -1, 0], [-1, 5, -1], [0, -1, 0]]  # integer weights: every order sums alike
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    "small": ("Resize", {"width": 137, "height": 91, "interpolation": 1}, ("camera",)),
    "mask": ("InRange", {"lowerb_0": 60, "upperb_0": 230.5, "lowerb_1": 20, "upperb_1": 200,
                         "lowerb_2": 0, "upperb_2": 180}, ("small",)),
    "dx": ("Sobel", {"dx": 1, "dy": 0}, ("camera",)),
    "dx_near": ("Resize", {"width": 211, "height": 157, "interpolation": 0}, ("dx",)),
    "dx_crop": ("Crop", {"left": 7, "top": 5, "width": 190, "height": 140}, ("dx_near",)),
    "dx_blur": ("Blur", {"ksize": 5, "border_type": 1}, ("dx_crop",)),
    "dx_grad": ("MorphologyEx", {"op": 4, "shape": 0, "ksize": 3, "iterations": 1},
                ("dx_blur",)),
    "dx_in": ("InRange", {"lowerb_0": -200, "upperb_0": 150.5, "lowerb_1": -300,
                          "upperb_1": 0, "lowerb_2": 0, "upperb_2": 400}, ("dx_grad",)),
    "gray": ("RgbToGray", {}, ("camera",)),
    "sharp": ("Filter2D", {"weights": SHARPEN, "delta": 0.5, "border_type": 4, "ddepth": 5},
              ("gray",)),
    "sharp_blur": ("MorphologyEx", {"op": 1, "shape": 2, "ksize": 3, "iterations": 1},
                   ("sharp",)),
    "sharp_small": ("Resize", {"width": 160, "height": 100, "interpolation": 0},
                    ("sharp_blur",)),
    "sharp_in": ("InRange", {"lowerb_0": -20.25, "upperb_0": 120.75}, ("sharp_small",)),
    "edges": ("Filter2D", {"weights": SHARPEN, "ddepth": 3}, ("gray",)),
    "edges_min": ("MorphologyEx", {"op": 0, "shape": 1, "ksize": 3, "iterations": 1},
                  ("edges",)),
    # the one-channel names of before, with their old parameter names
    "old_crop": ("CropGray", {"x": 11, "y": 13, "width": 120, "height": 80}, ("gray",)),
    "old_resize": ("ResizeGray", {"width": 64, "height": 48, "interpolation": 1},
                   ("old_crop",)),
    "old_in": ("InRangeGray", {"lowerb": 50, "upperb": 170}, ("old_resize",)),
}


def _opencv(type_name: str, params: dict, src: np.ndarray) -> np.ndarray:
    """The chain's components as OpenCV's calls."""
    p = params
    if type_name in ("Resize", "ResizeGray"):
        return cv2.resize(src, (p["width"], p["height"]), interpolation=p["interpolation"])
    if type_name in ("InRange", "InRangeGray"):
        n = src.shape[2] if src.ndim == 3 else 1
        lower = [p.get(f"lowerb_{c}", p.get("lowerb")) for c in range(n)]
        upper = [p.get(f"upperb_{c}", p.get("upperb")) for c in range(n)]
        bounds = [np.float64(np.float32(b)) for b in (*lower, *upper)]
        return cv2.inRange(src, np.array(bounds[:n]), np.array(bounds[n:]))
    if type_name in ("Crop", "CropGray"):
        x, y = p.get("left", p.get("x")), p.get("top", p.get("y"))
        return np.ascontiguousarray(src[y:y + p["height"], x:x + p["width"]])
    if type_name == "Sobel":
        return cv2.Sobel(src, cv2.CV_16S, p["dx"], p["dy"], ksize=3)
    if type_name == "RgbToGray":
        return cv2.cvtColor(src, cv2.COLOR_RGB2GRAY)
    if type_name == "Blur":
        return cv2.blur(src, (p["ksize"], p["ksize"]), borderType=p["border_type"])
    if type_name == "MorphologyEx":
        element = cv2.getStructuringElement(p["shape"], (p["ksize"], p["ksize"]))
        return cv2.morphologyEx(src, p["op"], element, iterations=p["iterations"])
    assert type_name == "Filter2D"
    return cv2.filter2D(src, p["ddepth"], np.float32(p["weights"]), delta=p.get("delta", 0),
                        borderType=p.get("border_type", 4))


def test_generated_program_equals_opencv_fused_unfused_and_on_the_cpu(tmp_path, cl_context):
    """The chain's ends built fused (every legal group formed), unfused and on the CPU,
    each equal to OpenCV's calls on the camera's photographs (int16 and float32 frames
    through Resize, Crop, Blur, MorphologyEx and InRange; the old names and parameters
    run unchanged)."""
    require_opencl()
    from test_imgproc_ops import _camera_frames
    from test_ops_yuv import fused_builds

    found = fused_builds(tmp_path, "lib_ops", CHAIN, cl_context)
    grouped = {m.type.name for g in found["fused"][0].system.groups for m in g.members}
    assert {"Resize", "Crop", "InRange", "Blur", "MorphologyEx", "CropGray", "ResizeGray",
            "InRangeGray"} <= grouped, grouped
    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = _opencv(type_name, params, values[inputs[0]])
        for variant, (_, frames) in found.items():
            assert frames, variant
            for name, got in frames.items():
                np.testing.assert_array_equal(got[i].reshape(values[name].shape), values[name],
                                              err_msg=f"{variant}: {name}, frame {i}")
