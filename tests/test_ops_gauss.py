"""GaussianBlur with OpenCV's parameters and Filter2D against OpenCV (issue 26).

GaussianBlur: OpenCV computes 8-bit images in fixed point (weights in 1/256, error
diffused from its double kernel, rows then columns, rounded half up); the library's
weights are computed in Python when the kernel is generated (library/kernel_tables.py).
Checked here: those weights against the ones made from cv2.getGaussianKernel's doubles
over thousands of (ksize, sigma) pairs; then on crops of photographs (one and three
channels, every border rule, fixed-table, derived and given sigmas, non-square windows,
the window's limits 1 and 31), cv2.GaussianBlur, the CPU form, the generated kernel and
an independent numpy reference (OpenCV's doubles, borderInterpolate index by index,
integer sums): all equal, bit for bit.

Filter2D: OpenCV sums kernels of fewer than 130 elements directly in float (from delta,
fused multiply-adds in row order on a CPU with FMA) and convolves larger ones by DFT: the
generated kernel equals cv2.filter2D bit for bit below 130 elements (within 1 level on a
CPU without FMA, where OpenCV rounds each product), and within 1 level on at most 1% of
the elements from 130.  Then a generated program chaining both types, fused, unfused and
on the CPU, against OpenCV on the model photographs; last, bad parameters give
positioned errors.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, opencv_fuses_multiply_adds, require_opencl
from test_imgproc_ops import FRAMES, _camera_frames, _pad, fused_unfused_cpu

from gpucompgen.library import cpu_kernels
from gpucompgen.library.kernel_tables import gaussian_q8

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")


# -- the fixed-point weights -----------------------------------------------------------------
def _diffused(kernel: np.ndarray) -> tuple[int, ...]:
    """OpenCV's double kernel to 8 fraction bits by error diffusion, the centre taking the
    rest (written from the definition, on cv2's own doubles)."""
    n = len(kernel)
    side, err = [], 0.0
    for v in kernel[:n // 2]:
        adjusted = float(v) * 256.0 + err
        q = int(np.rint(adjusted))  # half to even
        err = adjusted - q
        side.append(q)
    return (*side, 256 - 2 * sum(side), *side[::-1])


def test_weights_equal_those_of_opencvs_doubles():
    rng = np.random.default_rng(26)
    sigmas = [0.0, 1e-3, 0.05, 100.0, 1000.0, *np.arange(0.1, 8.0, 0.05),
              *rng.uniform(0.01, 12.0, 150)]
    for n in range(1, 32, 2):
        for sigma in sigmas:
            ours = gaussian_q8(n, float(sigma))
            theirs = _diffused(cv2.getGaussianKernel(n, float(sigma), ktype=cv2.CV_64F)
                               .ravel())
            assert ours == theirs, (n, sigma)
            assert sum(ours) == 256 and min(ours) >= 0
    # sigma 0 with 3 and 5 taps: the binomial weights of before, in 1/256
    assert gaussian_q8(3, 0) == (64, 128, 64)
    assert gaussian_q8(5, 0) == (16, 64, 96, 64, 16)
    # ksize_y 0 takes ksize, sigma_y 0 takes sigma (GaussianBlur's 'ky' table)
    assert gaussian_q8(0, 0, 7, 1.5) == gaussian_q8(7, 1.5)
    with pytest.raises(ValueError, match="odd"):
        gaussian_q8(4, 1.0)


# -- GaussianBlur on photographs -----------------------------------------------------------
def _gaussian_reference(src, ksize, ksize_y, sigma, sigma_y, border_type):
    """The fixed-point blur from its definition: OpenCV's double kernels diffused to 1/256,
    the frame padded by borderInterpolate's rule, integer sums along rows then columns,
    rounded half up from 16 fraction bits."""
    height = ksize_y or ksize
    kx = _diffused(cv2.getGaussianKernel(ksize, sigma, ktype=cv2.CV_64F).ravel())
    ky = _diffused(cv2.getGaussianKernel(height, sigma_y or sigma, ktype=cv2.CV_64F).ravel())
    r = max(ksize, height) // 2
    padded = _pad(src, r, border_type).astype(np.int64)
    h, w = src.shape[:2]
    rows = sum(k * padded[:, r - ksize // 2 + j:r - ksize // 2 + j + w]
               for j, k in enumerate(kx))
    total = sum(k * rows[r - height // 2 + i:r - height // 2 + i + h] for i, k in enumerate(ky))
    return ((total + (1 << 15)) >> 16).astype(np.uint8)


# (ksize, ksize_y, sigma, sigma_y, border_type): the binomial 3 and 5 of before, OpenCV's
# fixed tables 7 and 9, sigma from the size, given sigmas (tiny, huge), non-square
# windows with their own sigma_y, the limits 1 and 31, every border rule
GAUSS = [(3, 0, 0.0, 0.0, 4), (5, 0, 0.0, 0.0, 0), (7, 0, 0.0, 0.0, 1), (9, 0, 0.0, 0.0, 2),
         (11, 0, 0.0, 0.0, 4), (5, 0, 1.1, 0.0, 1), (15, 0, 3.0, 0.0, 0),
         (9, 3, 2.0, 0.7, 2), (1, 31, 0.0, 5.0, 1), (31, 0, 6.0, 0.0, 4),
         (3, 0, 0.1, 0.0, 4), (13, 7, 100.0, 0.0, 0)]
KEYS = ("ksize", "ksize_y", "sigma", "sigma_y", "border_type")


@pytest.fixture(scope="module")
def crops():
    """Crops of two photographs, odd sizes, gray and RGB; and a frame smaller than the
    largest windows (reads reflected more than once)."""
    found = []
    for load, (y, x) in ((skdata.chelsea, (60, 140)), (skdata.coffee, (150, 220))):
        rgb = np.ascontiguousarray(load()[y:y + 45, x:x + 61])
        found.append({3: rgb, 1: cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)})
    tiny = np.ascontiguousarray(skdata.astronaut()[100:107, 200:205])
    found.append({3: tiny, 1: cv2.cvtColor(tiny, cv2.COLOR_RGB2GRAY)})
    return found


@pytest.fixture(scope="module")
def gpu(run_alone):
    return run_alone


# each case over one channel count, the largest windows also over the small frame: sizes
# are constants of a kernel, so each (case, channels, frame size) compiles one (the 3 and
# 5 of before run over both channel counts in test_imgproc.py)
GAUSS_RUNS = [(case, 1 + 2 * (i % 2)) for i, case in enumerate(GAUSS)]


def _frames(crops, channels: int, largest_window: bool) -> list[np.ndarray]:
    return [versions[channels] for versions in crops[:3 if largest_window else 2]]


@pytest.mark.parametrize(("case", "channels"), GAUSS_RUNS,
                         ids=["k{}x{}_s{}_{}_b{}".format(*c) + f"_{n}ch" for c, n in GAUSS_RUNS])
def test_gaussian_blur_equals_opencv(case, channels, crops, gpu):
    params = dict(zip(KEYS, case, strict=True))
    ksize, ksize_y, sigma, sigma_y, border = case
    for i, src in enumerate(_frames(crops, channels, max(ksize, ksize_y) > 15)):
        what = f"{params} on crop {i}, {channels} channels"
        expected = cv2.GaussianBlur(src, (ksize, ksize_y or ksize), sigma, sigmaY=sigma_y,
                                    borderType=border)
        np.testing.assert_array_equal(_gaussian_reference(src, **params), expected,
                                      err_msg=f"numpy reference {what}")
        np.testing.assert_array_equal(cpu_kernels.gaussian_blur(src, **params), expected,
                                      err_msg=f"CPU form {what}")
        np.testing.assert_array_equal(gpu("GaussianBlur", src, params), expected,
                                      err_msg=f"GPU {what}")


# int16 and float32 frames: OpenCV's float32 weights; the kernel and the CPU form give the
# same bytes, within 1 level (int16) or 2^-20 sum |weight| |pixel| (float32) of OpenCV
WIDE_GAUSS = [((5, 0, 0.0, 0.0, 4), "float32", 1), ((7, 0, 1.3, 0.0, 0), "int16", 3),
              ((31, 0, 0.5, 0.0, 1), "float32", 1), ((3, 9, 0.0, 2.0, 2), "float32", 3),
              ((9, 0, 0.0, 0.0, 2), "int16", 1)]


@pytest.mark.parametrize(("case", "dtype", "channels"), WIDE_GAUSS,
                         ids=["k{}x{}_s{}_{}_b{}".format(*c) + f"_{d}_{n}ch"
                              for c, d, n in WIDE_GAUSS])
def test_gaussian_blur_of_int16_and_float32_frames(case, dtype, channels, crops, gpu):
    params = dict(zip(KEYS, case, strict=True))
    ksize, ksize_y, sigma, sigma_y, border = case
    for i, versions in enumerate(crops):
        src = versions[channels]
        src = (src.astype(np.int16) - 128) * 97 if dtype == "int16" else \
            (src.astype(np.float32) - np.float32(100.3)) * np.float32(0.37)
        what = f"{params} on {dtype} crop {i}, {channels} channels"
        expected = cv2.GaussianBlur(src, (ksize, ksize_y or ksize), sigma, sigmaY=sigma_y,
                                    borderType=border)
        cpu = cpu_kernels.gaussian_blur(src, **params)
        np.testing.assert_array_equal(gpu("GaussianBlur", src, params), cpu,
                                      err_msg=f"GPU against the CPU form, {what}")
        off = np.abs(cpu.astype(np.float64) - expected)
        if dtype == "int16":
            assert off.max() <= 1, what
            continue
        # the weights are positive and sum to 1: sum |weight| |pixel| is the blur of |src|
        magnitude = cv2.GaussianBlur(np.abs(src).astype(np.float64), (ksize, ksize_y or ksize),
                                     sigma, sigmaY=sigma_y, borderType=border)
        assert (off <= 2.0 ** -20 * magnitude + 1e-30).all(), what


# -- Filter2D ---------------------------------------------------------------------------------
def _kernels():
    rng = np.random.default_rng(5)

    def normal(rows, cols):
        k = rng.normal(0.0, 1.0, (rows, cols)).astype(np.float32)
        return k / max(float(k.sum()), 0.5)

    sharpen = np.array([[0, -1, 0], [-1, 5, -1], [0, -1, 0]], np.float32)
    # (weights, delta, border_type): a sharpening kernel, a row, even sizes (anchored at
    # cols / 2, rows / 2), integer weights with a half delta (sums on ties), random ones up
    # to OpenCV's direct sum's largest (11 x 11 = 121 < 130), then its DFT's (13 x 11, 15 x 15)
    return [(sharpen, 0.0, 4), (normal(1, 5), 3.5, 0), (normal(2, 4), -1.25, 2),
            (np.round(rng.normal(0, 2, (5, 5))).astype(np.float32), 0.5, 1),
            (normal(7, 3), 0.0, 4), (normal(11, 11), 0.0, 0), (normal(13, 11), 0.0, 4),
            (normal(15, 15), 2.0, 2)]


FILTERS = _kernels()
FMA = opencv_fuses_multiply_adds()


@pytest.mark.parametrize("index", range(len(FILTERS)),
                         ids=[f"{k.shape[0]}x{k.shape[1]}" for k, _, _ in FILTERS])
def test_filter2d_equals_opencv(index, crops, gpu):
    weights, delta, border = FILTERS[index]
    params = {"weights": tuple(tuple(float(v) for v in row) for row in weights),
              "delta": delta, "border_type": border}
    direct = weights.size < 130  # OpenCV's direct sum; from 130 elements its DFT
    channels = 1 + 2 * (index % 2)
    for i, src in enumerate(_frames(crops, channels, weights.size == 225)):
        what = f"{weights.shape} on crop {i}, {channels} channels"
        expected = cv2.filter2D(src, -1, weights, delta=delta, borderType=border)
        np.testing.assert_array_equal(cpu_kernels.CPU_IMPLEMENTATIONS["Filter2D"](
            src, **params), expected, err_msg=f"CPU form {what}")
        found = gpu("Filter2D", src, params)
        if direct and FMA:
            np.testing.assert_array_equal(found, expected, err_msg=f"GPU {what}")
            continue
        off = np.abs(found.astype(int) - expected)
        assert off.max() <= 1, what
        assert np.count_nonzero(off) <= max(1, off.size // 100), what


# -- a program: fused, unfused, on the CPU -------------------------------------------------
SHARPEN = [[0.0, -1.0, 0.0], [-1.0, 5.0, -1.0], [0.0, -1.0, 0.0]]
EMBOSS = [[-2.0, -1.0, 0.0, 0.5], [-1.0, 1.0, 1.0, 0.25], [0.0, 1.0, 2.0, 0.0]]
CHAIN = {  # name: (type, params, inputs); the camera gives 301x200 RGB photographs
    # fused: a stencil after a stencil (recomputed at each of its 9 taps: windows kept
    # small, compile time grows with the product), a stencil after a pointwise type, a
    # pointwise type after a stencil
    "blur": ("GaussianBlur", {"ksize": 5, "ksize_y": 3, "sigma": 1.5, "sigma_y": 0.0,
                              "border_type": 0}, ("camera",)),
    "sharp": ("Filter2D", {"weights": SHARPEN, "delta": 0.0, "border_type": 1}, ("blur",)),
    "gray": ("RgbToGray", {}, ("camera",)),
    "edges": ("Filter2D", {"weights": EMBOSS, "delta": 64.5, "border_type": 4}, ("gray",)),
    "gblur": ("GaussianBlurGray", {"ksize": 7, "ksize_y": 3, "sigma": 0.0, "sigma_y": 2.0,
                                   "border_type": 2}, ("gray",)),
    "mask": ("Threshold", {"thresh": 100, "maxval": 255, "thresh_type": 0}, ("gblur",)),
}
ENDS = ("sharp", "edges", "mask")


def _opencv(type_name, src, params):
    p = params
    if type_name.startswith("GaussianBlur"):
        return cv2.GaussianBlur(src, (p["ksize"], p["ksize_y"] or p["ksize"]), p["sigma"],
                                sigmaY=p["sigma_y"], borderType=p["border_type"])
    if type_name == "Filter2D":
        return cv2.filter2D(src, -1, np.array(p["weights"], np.float32), delta=p["delta"],
                            borderType=p["border_type"])
    if type_name == "RgbToGray":
        return cv2.cvtColor(src, cv2.COLOR_RGB2GRAY)
    return cv2.threshold(src, p["thresh"], p["maxval"], p["thresh_type"])[1]


@pytest.fixture(scope="module")
def chain_outputs(tmp_path_factory, cl_context):
    require_opencl()
    return fused_unfused_cpu(tmp_path_factory.mktemp("gauss_chain"), cl_context,
                             "gauss_chain", CHAIN, ENDS)


def test_chain_fused_unfused_cpu_equal_opencv(chain_outputs):
    built, _ = chain_outputs["fused"]
    grouped = {m.type.name for g in built.system.groups for m in g.members}
    assert {"GaussianBlur", "Filter2D"} <= grouped, grouped
    assert not chain_outputs["unfused"][0].system.groups
    for i, camera in enumerate(_camera_frames()[:FRAMES]):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = _opencv(type_name, values[inputs[0]], params)
        for variant, (_, frames) in chain_outputs.items():
            for name in ENDS:
                np.testing.assert_array_equal(frames[name][i], values[name],
                                              err_msg=f"{variant}: {name}, frame {i}")


# -- bad parameters ------------------------------------------------------------------------
# component: (type, params, the error's message); a value outside its declaration stops the
# model at loading, a requirement is checked after: two models
BAD_VALUES = {
    "large": ("GaussianBlur", "{ksize: 33}",
              "parameter 'ksize' of 'GaussianBlur' is 33, outside [1, 31]"),
    "negative": ("GaussianBlur", "{sigma: -1.5}",
                 "parameter 'sigma' of 'GaussianBlur' is -1.5, outside [0, 1000]"),
    "big": ("Filter2D", "{weights: [[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]]}",
            "parameter 'weights' of 'Filter2D' element [0] has 16 values where "
            "float[1..15][1..15] takes 1 to 15"),
    "ragged": ("Filter2D", "{weights: [[1, 2], [3]]}", "parameter 'weights' of 'Filter2D' "
               "has rows of 1 and 2 values: all must have one length"),
    "huge": ("Filter2D", "{weights: [[5000.0]]}",
             "element [0][0] is 5000.0, outside [-1000, 1000]"),
}
BAD_REQUIREMENTS = {
    "even": ("GaussianBlur", "{ksize: 4}", "ksize must be odd"),
    "even_y": ("GaussianBlur", "{ksize: 3, ksize_y: 6}", "ksize_y must be odd"),
    "wrap": ("GaussianBlur", "{border_type: 3}",
             "border_type 3 (BORDER_WRAP) is not supported by cv2.GaussianBlur"),
    "fwrap": ("Filter2D", "{border_type: 3}",
              "border_type 3 (BORDER_WRAP) is not supported by cv2.filter2D"),
}


@pytest.mark.parametrize("bad", [BAD_VALUES, BAD_REQUIREMENTS], ids=["values", "requirements"])
def test_bad_parameters_get_positioned_errors(tmp_path, bad):
    lines = ["system: bad", "components:",
             "  camera: {type: Camera, params: {width: 64, height: 48}}"]
    connections = []
    for name, (type_name, params, _) in bad.items():
        lines.append(f"  {name}: {{type: {type_name}, params: {params}}}")
        connections.append(f"  - camera.image -> {name}.src")
    model = tmp_path / "bad.yaml"
    model.write_text("\n".join(lines + ["connections:", *connections]) + "\n")
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "check", str(model)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    errors = [e for e in proc.stderr.splitlines() if ": error: " in e]
    assert len(errors) == len(bad), proc.stderr
    for line, (name, (_, _, message)) in enumerate(bad.items(), start=4):
        found = [e for e in errors if e.startswith(f"{model}:{line}:")]
        assert found and message in found[0], (name, proc.stderr)
    assert proc.stderr.count("  hint: ") >= len(bad), proc.stderr
