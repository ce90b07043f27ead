"""The operations of issue 26 (bitwise.yaml, convert.yaml, filters2.yaml, ...) against OpenCV.

Each type runs as OpenCV's function, as its CPU form (cpu_ops.py, which calls OpenCV),
as an independent numpy reference written here from the operation's definition (so the
CPU form is not checked only against itself), and as the OpenCL kernel the generator writes
from its fusable form (conftest.run_generated: what a lone component runs), on PoCL. On
the photographs (scikit-image's chelsea, coffee and astronaut in RGB and gray: every type
over each channel count it takes, a threshold of them for masks) with every parameter set
of OPS, which reaches every parameter's limits: all four equal, bit for bit (ConvertScale,
also named ConvertScaleAbs, is tested with imgproc.yaml's types in test_imgproc.py). Hypothesis then draws small frames (odd sizes, one pixel high or wide,
where windows reach past two borders), parameters in their declared ranges and GPU
settings. Last, one generated program chains every new type (test_generated_program_*):
built on the GPU, on the CPU and alternating, each component's output equals the OpenCV
chain's; and with only the chain's ends kept it is built fused (every new type inside a
group), unfused and on the CPU, all equal to OpenCV (test_fused_*); tests/test_fusion.py's
property test also draws fused = unfused systems from every fusable library type.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field

import imgproc_reference
import numpy as np
import pytest
from conftest import (
    ROOT,
    keep_type_for,
    load_generated,
    require_opencl,
    run_generated,
    write_keep_types,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen.library import cpu_kernels, cpu_ops

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

NEW_FILES = ("bitwise.yaml", "convert.yaml", "filters2.yaml", "morphology.yaml")
PROPERTY = settings(max_examples=10, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


# -- independent numpy references ------------------------------------------------------------
def _pad(image: np.ndarray, r: int, border: int) -> np.ndarray:
    """image with r pixels added on every side by OpenCV's border rule of that code,
    following borderInterpolate's definition index by index (not cv2.copyMakeBorder)."""
    def index(p: int, n: int) -> int:
        if 0 <= p < n:
            return p
        if border == cpu_ops.BORDER_REPLICATE or n == 1:
            return min(max(p, 0), n - 1)
        delta = 1 if border == cpu_ops.BORDER_REFLECT_101 else 0
        while not 0 <= p < n:
            p = -p - 1 + delta if p < 0 else 2 * n - 1 - p - delta
        return p

    h, w = image.shape[:2]
    if border == cpu_ops.BORDER_CONSTANT:
        out = np.zeros((h + 2 * r, w + 2 * r) + image.shape[2:], image.dtype)
        out[r:r + h, r:r + w] = image
        return out
    rows = [index(p, h) for p in range(-r, h + r)]
    cols = [index(p, w) for p in range(-r, w + r)]
    return image[rows][:, cols]


def _correlate(image: np.ndarray, kernel: np.ndarray, border: int) -> np.ndarray:
    """sum over the window of kernel * pixel, in int64 (kernel odd x odd)."""
    r = kernel.shape[0] // 2
    padded = _pad(image, r, border).astype(np.int64)
    h, w = image.shape[:2]
    return sum(int(kernel[dy, dx]) * padded[dy:dy + h, dx:dx + w]
               for dy in range(kernel.shape[0]) for dx in range(kernel.shape[1])
               if kernel[dy, dx])


def _blur(src, ksize, border_type):
    n = ksize * ksize
    total = _correlate(src, np.ones((ksize, ksize), np.int64), border_type)
    return ((total + n // 2) // n).astype(np.uint8)


LAPLACE = {1: np.array([[0, 1, 0], [1, -4, 1], [0, 1, 0]]),
           3: np.array([[2, 0, 2], [0, -8, 0], [2, 0, 2]])}
SCHARR_X = np.array([[-3, 0, 3], [-10, 0, 10], [-3, 0, 3]])
CV_DEPTH = {-1: -1, 0: cv2.CV_8U, 3: cv2.CV_16S, 5: cv2.CV_32F}


def _laplace(ksize: int) -> np.ndarray:
    """The Laplacian's kernel: OpenCV's documented 3x3 ones for ksize 1 and 3; from 5, the
    second derivative along x smoothed along y plus its transpose, from OpenCV's own
    derivative kernels (cv2.getDerivKernels)."""
    if ksize in LAPLACE:
        return LAPLACE[ksize]
    d2, smooth = (k.ravel().astype(np.int64) for k in cv2.getDerivKernels(2, 0, ksize))
    return np.outer(smooth, d2) + np.outer(d2, smooth)


def _derivative(a, kernel, scale, delta, border_type, ddepth):
    """The correlation in integers, times a whole scale plus a whole delta (the cases
    here: exact), to OpenCV's output type (saturated)."""
    assert float(scale).is_integer() and float(delta).is_integer()
    total = _correlate(a, kernel, border_type) * int(scale) + int(delta)
    dtype = a.dtype if ddepth == -1 else {0: np.uint8, 3: np.int16, 5: np.float32}[ddepth]
    if dtype == np.float32:
        return total.astype(np.float32)
    return np.clip(total, np.iinfo(dtype).min, np.iinfo(dtype).max).astype(dtype)


_element = imgproc_reference.element


def _extreme(src, element, smallest: bool, iterations: int):
    """Erode (smallest) or dilate iterations times, pixels outside the frame ignored."""
    r = element.shape[0] // 2
    out = src.astype(np.int16)
    h, w = src.shape[:2]
    for _ in range(iterations):
        padded = _pad(out, r, cpu_ops.BORDER_CONSTANT) if r else out
        if r:  # outside the frame: a value that never wins
            border = np.ones(padded.shape[:2], bool)
            border[r:r + h, r:r + w] = False
            padded[border] = 256 if smallest else -1
        taps = [padded[dy:dy + h, dx:dx + w] for dy, dx in zip(*np.nonzero(element))]
        out = np.minimum.reduce(taps) if smallest else np.maximum.reduce(taps)
    return out


def _morphology(src, op, shape, ksize, iterations):
    e = _element(shape, ksize)
    def erode(a):
        return _extreme(a, e, True, iterations)

    def dilate(a):
        return _extreme(a, e, False, iterations)

    result = {0: lambda: erode(src), 1: lambda: dilate(src),
              2: lambda: dilate(erode(src)), 3: lambda: erode(dilate(src)),
              4: lambda: dilate(src) - erode(src),
              5: lambda: src.astype(np.int16) - dilate(erode(src)),
              6: lambda: erode(dilate(src)) - src.astype(np.int16)}[op]()
    return result.astype(np.uint8)


# op (OpenCV's code) with each shape, size and iteration count, then the size limits
MORPHOLOGY = [{"op": op, "shape": shape, "ksize": k, "iterations": it}
              for op, shape, k, it in ((0, 0, 3, 1), (1, 1, 5, 1), (2, 2, 5, 1), (3, 0, 3, 2),
                                       (4, 2, 7, 1), (5, 1, 3, 1), (6, 0, 5, 1), (0, 0, 1, 1),
                                       (2, 2, 15, 1), (1, 0, 3, 4))]


@dataclass
class Op:
    """How one new type compares with OpenCV and with numpy."""

    opencv: Callable  # (inputs..., **params) -> OpenCV's output
    numpy: Callable  # the same from the definition
    cases: list[dict] = field(default_factory=lambda: [{}])  # parameter sets on photos
    inputs: str = "u"  # one letter an input: u uint8 frame, m mask
    photos: int = 3  # how many photographs (each compiles the kernel anew)
    every_photo: int = 99  # the first cases run on every photograph, the rest on the first
    examples: int = 10  # Hypothesis examples


# a gamma curve of 0.5, rounded: the table a contrast pipeline would give Lut
GAMMA = tuple(round(255 * (i / 255) ** 0.5) for i in range(256))


def _masked_and(a, b, m):
    out = np.zeros_like(a)
    return cv2.bitwise_and(a, b, dst=out, mask=m)


OPS: dict[str, Op] = {
    "BitwiseAnd": Op(cv2.bitwise_and, np.bitwise_and, inputs="uu"),
    "BitwiseOr": Op(cv2.bitwise_or, np.bitwise_or, inputs="uu"),
    "BitwiseXor": Op(cv2.bitwise_xor, np.bitwise_xor, inputs="uu"),
    "BitwiseNot": Op(cv2.bitwise_not, lambda a: 255 - a),
    "BitwiseAndMask": Op(_masked_and,
                         lambda a, b, m: np.where((m != 0).reshape(m.shape[:2] + (1,) * (
                             a.ndim - 2)), a & b, 0).astype(np.uint8), inputs="uum"),
    "FlipVertical": Op(lambda a: cv2.flip(a, 0), lambda a: a[::-1]),
    "Blur": Op(
        lambda a, ksize, border_type: cv2.blur(a, (ksize, ksize), borderType=border_type),
        _blur,
        # OpenCV's default border at 3 and 5 on every photograph, then on the first every
        # other border rule and the window's limits 1 and 31 (each case is a build)
        [{"ksize": k, "border_type": b} for b in (4, 0, 1, 2) for k in (3, 5)]
        + [{"ksize": 1, "border_type": 4}, {"ksize": 31, "border_type": 2}], every_photo=2),
    "Laplacian": Op(
        lambda a, ksize, scale=1.0, delta=0.0, border_type=4, ddepth=3: cv2.Laplacian(
            a, CV_DEPTH[ddepth], ksize=ksize, scale=scale, delta=delta, borderType=border_type),
        lambda a, ksize, scale=1.0, delta=0.0, border_type=4, ddepth=3: _derivative(
            a, _laplace(ksize), scale, delta, border_type, ddepth),
        # the apertures, then the border rules and the output types, scaled and shifted by
        # whole numbers (bit-exact; fractions: tests/test_ops_derivatives.py)
        [{"ksize": 1}, {"ksize": 3}, {"ksize": 5}, {"ksize": 7},
         {"ksize": 3, "border_type": 0, "ddepth": 5, "scale": 2.0, "delta": -3.0},
         {"ksize": 5, "border_type": 1, "ddepth": 0, "delta": 128.0},
         {"ksize": 1, "border_type": 2, "ddepth": -1, "scale": -1.0}], every_photo=2),
    "Scharr": Op(
        lambda a, dx, dy, scale=1.0, delta=0.0, border_type=4, ddepth=3: cv2.Scharr(
            a, CV_DEPTH[ddepth], dx, dy, scale=scale, delta=delta, borderType=border_type),
        lambda a, dx, dy, scale=1.0, delta=0.0, border_type=4, ddepth=3: _derivative(
            a, SCHARR_X if dx else SCHARR_X.T, scale, delta, border_type, ddepth),
        [{"dx": 1, "dy": 0}, {"dx": 0, "dy": 1},
         {"dx": 1, "dy": 0, "border_type": 0, "ddepth": 5, "scale": 3.0, "delta": 5.0}],
        every_photo=2),
    "Lut": Op(lambda a, lut: cv2.LUT(a, np.array(lut, np.uint8)),
              lambda a, lut: np.array(lut, np.uint8)[a],
              [{"lut": tuple(range(256))}, {"lut": tuple(255 - i for i in range(256))},
               {"lut": GAMMA}, {"lut": (0,) * 255 + (255,)}]),
    # the kernel's op, shape, size and iterations are constants: each case compiles
    "MorphologyEx": Op(
        lambda a, op, shape, ksize, iterations: cv2.morphologyEx(
            a, op, cv2.getStructuringElement(shape, (ksize, ksize)), iterations=iterations),
        _morphology, MORPHOLOGY, photos=1, examples=4),
}
for _name in list(OPS):  # the deprecated one-channel names: the same operation
    OPS[_name + "Gray"] = OPS[_name]
OPS.update({
    "GrayToRgb": Op(lambda a: cv2.cvtColor(a, cv2.COLOR_GRAY2RGB),
                    lambda a: np.repeat(a.reshape(a.shape[:2] + (1,)), 3, axis=2)),
    "RgbToBgr": Op(lambda a: cv2.cvtColor(a, cv2.COLOR_RGB2BGR), lambda a: a[..., ::-1]),
    "BgrToRgb": Op(lambda a: cv2.cvtColor(a, cv2.COLOR_BGR2RGB), lambda a: a[..., ::-1]),
})


def new_types():
    from gpucompgen.model import library_types

    return {n: t for n, t in library_types().items() if t.decl_file.name in NEW_FILES}


def channel_counts(type_name: str) -> tuple[int, ...]:
    """The channel counts a type's first input takes: 1 and 3 for a generic one."""
    port = next(iter(new_types()[type_name].inputs.values()))
    return port.channel_counts or (port.channels,)


# every type over each channel count it takes; the deprecated 'Gray' names are the same
# operation with one channel, run under their old names in the generated programs below
VARIANTS = [(name, c) for name in sorted(OPS) if not new_types()[name].alias_of
            for c in channel_counts(name)]


def variant_id(value) -> str:
    return f"{value}ch" if isinstance(value, int) else str(value)


def test_every_new_type_is_compared_flexible_and_fusable():
    types = new_types()
    assert set(types) == set(OPS)
    assert set(OPS) <= set(cpu_kernels.CPU_IMPLEMENTATIONS)
    for name, t in types.items():
        assert t.flexible and t.fusable is not None, name
        assert t.family, name  # 'gpucompgen types' groups it with the library's others
        if t.alias_of:  # a deprecated 'Gray' name: the generic type with one channel
            assert (t.alias_of, t.alias_channels) == (name.removesuffix("Gray"), 1), name
        elif name not in ("GrayToRgb", "RgbToBgr", "BgrToRgb"):  # fixed by the operation
            assert channel_counts(name) == (1, 3), name
        # OpenCV's port names: src / dst, src1 and src2 for two frames, mask
        assert set(t.inputs) in ({"src"}, {"src1", "src2"}, {"src1", "src2", "mask"}), name
        assert set(t.outputs) == {"dst"}, name


def make_inputs(type_name: str, image: np.ndarray) -> list[np.ndarray]:
    """The inputs of a type from one frame of its channel count: a second frame unlike
    the first, or a mask (a threshold of the frame's first channel)."""
    found = []
    for kind in OPS[type_name].inputs:
        if kind == "u":
            found.append(image if not found else
                         np.ascontiguousarray(image[::-1, ::-1] // 2 + image // 3))
        else:
            first = image if image.ndim == 2 else image[..., 0]
            found.append(np.ascontiguousarray(np.where(first > 100, 255, 0).astype(np.uint8)))
    return found


@pytest.fixture(scope="module")
def photos():
    out = []
    for load in (skdata.chelsea, skdata.coffee, skdata.astronaut):
        rgb = np.ascontiguousarray(load())
        out.append({3: rgb, 1: cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)})
    return out


@pytest.fixture(scope="module")
def gpu(cl_context, cl_queue):
    require_opencl()

    def run(type_name, arrays, params, shape, setting=(16, 16, 16, 1)):
        return run_generated(cl_context, cl_queue, new_types()[type_name], params, arrays,
                             shape, setting)
    return run


def check_all(type_name: str, arrays: list[np.ndarray], params: dict, gpu, setting=None,
              what: str = "") -> None:
    op = OPS[type_name]
    reference = op.opencv(*arrays, **params)
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
    assert cpu.dtype == reference.dtype and cpu.shape == reference.shape, what
    np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU form {what} {params}")
    np.testing.assert_array_equal(op.numpy(*arrays, **params), reference,
                                  err_msg=f"numpy reference {what} {params}")
    found = gpu(type_name, arrays, params, reference.shape,
                *(() if setting is None else (setting,)))
    np.testing.assert_array_equal(found, reference, err_msg=f"GPU {what} {params}")


@pytest.mark.parametrize(("type_name", "channels"), VARIANTS, ids=variant_id)
def test_photographs_cpu_gpu_numpy_equal_opencv(type_name, channels, photos, gpu):
    for i, versions in enumerate(photos[:OPS[type_name].photos]):
        arrays = make_inputs(type_name, versions[channels])
        for k, params in enumerate(OPS[type_name].cases):
            if i and k >= OPS[type_name].every_photo:
                continue
            if channels == 3 and params.get("iterations", 1) > 2:
                continue  # many iterations: on one channel (the loop over iterations is
                # not the channels' concern; each is 15 s of compiling on three)
            some = arrays
            if params.get("ksize", 1) * params.get("iterations", 1) > 7:
                some = [np.ascontiguousarray(a[100:164, 200:280]) for a in arrays]  # a window
                # of windows of 15 x 15 costs 50,000 reads an element: a part of the photo
            check_all(type_name, some, params, gpu, what=f"photo {i}")


# -- random frames, parameters and GPU settings -------------------------------------------
sizes = st.integers(1, 20) | st.sampled_from([31, 33])
SETTINGS = [(8, 1, 1, 1), (16, 16, 16, 1), (32, 8, 3, 1)]


@st.composite
def cases(draw, type_name: str, channels: int):
    height, width = draw(sizes), draw(sizes)
    shape = (height, width) if channels == 1 else (height, width, channels)
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    image = rng.integers(0, 256, shape, dtype=np.uint8)
    arrays = make_inputs(type_name, image)
    params = {}
    t = new_types()[type_name]
    for name, decl in t.params.items():
        if decl.type == "float":
            params[name] = draw(st.floats(-4.0, 4.0, allow_nan=False, width=32)
                                | st.sampled_from([0.0, 0.5, 1.0, -1.0, 1e-30, 300.0]))
        elif not decl.shape:
            params[name] = draw(st.integers(int(decl.minimum), int(decl.maximum)))
        else:
            params[name] = decl.default
    if "lut" in params:
        params["lut"] = tuple(draw(st.lists(st.integers(0, 255), min_size=256, max_size=256)))
    if "dx" in params:
        params["dy"] = 1 - params["dx"]
    if "ksize" in params and type_name.startswith("Blur"):
        params["ksize"] = draw(st.sampled_from([1, 3, 5, 7, 9]))
        params["border_type"] = draw(st.sampled_from(sorted(cpu_ops.BORDERS)))
    if "ksize" in params and type_name.startswith("Laplacian"):
        params["ksize"] = draw(st.sampled_from([1, 3, 5, 7]))
    if "ddepth" in params:  # whole scales and deltas (exact); fractions: test_ops_derivatives
        params["ddepth"] = draw(st.sampled_from(sorted(CV_DEPTH)))
        params["border_type"] = draw(st.sampled_from(sorted(cpu_ops.BORDERS)))
        params["scale"] = draw(st.sampled_from([1.0, 2.0, -3.0, 0.0]))
        params["delta"] = draw(st.sampled_from([0.0, 7.0, -300.0]))
    if type_name.startswith("MorphologyEx"):
        params["ksize"] = draw(st.sampled_from([1, 3, 5]))
        if params["shape"]:
            params["iterations"] = 1
    return arrays, params, draw(st.sampled_from(SETTINGS))


@pytest.mark.parametrize(("type_name", "channels"), VARIANTS, ids=variant_id)
def test_random_frames_cpu_gpu_numpy_equal_opencv(type_name, channels, gpu):
    @settings(PROPERTY, max_examples=OPS[type_name].examples)
    @given(case=cases(type_name, channels))
    def check(case):
        arrays, params, setting = case
        check_all(type_name, arrays, params, gpu, setting, what=str(arrays[0].shape))

    check()


# -- the CPU forms' own checks ----------------------------------------------------------------
def test_cpu_forms_reject_bad_inputs():
    image = np.zeros((4, 5, 3), np.uint8)
    with pytest.raises(ValueError, match="same size"):
        cpu_ops.bitwise_and(image, image[:3])
    with pytest.raises(ValueError, match="mask"):
        cpu_ops.bitwise_and_mask(image, image, np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="odd"):
        cpu_ops.blur(image, ksize=4, border_type=4)
    with pytest.raises(ValueError, match="border_type"):
        cpu_ops.blur(image, ksize=3, border_type=3)
    with pytest.raises(ValueError, match="ksize"):
        cpu_ops.laplacian(image, ksize=9)
    with pytest.raises(ValueError, match="border_type"):
        cpu_ops.laplacian(image, ksize=3, border_type=3)
    with pytest.raises(ValueError, match="ddepth"):
        cpu_ops.scharr(image, dx=1, dy=0, ddepth=2)
    with pytest.raises(ValueError, match="dx=1"):
        cpu_ops.scharr(image, dx=1, dy=1)
    with pytest.raises(ValueError, match="one channel"):
        cpu_ops.gray_to_rgb(image)
    with pytest.raises(ValueError, match="out="):
        cpu_ops.flip_vertical(image, out=np.empty((4, 5), np.uint8))
    out = np.full((4, 5, 3), 7, np.uint8)
    assert cpu_ops.bitwise_and_mask(image, image, np.zeros((4, 5), np.uint8), out=out) is out
    assert not out.any()  # cleared where the mask is 0, as a new dst would be


def test_hand_computed_values():
    """A few pixels worked out on paper: the channel order, the rounding, the borders."""
    gray = np.array([[0b1100, 0b1010, 255, 0]], np.uint8)
    other = np.array([[0b1010, 0b0110, 15, 0]], np.uint8)
    assert cpu_ops.bitwise_and(gray, other).tolist() == [[0b1000, 0b0010, 15, 0]]
    assert cpu_ops.bitwise_or(gray, other).tolist() == [[0b1110, 0b1110, 255, 0]]
    assert cpu_ops.bitwise_xor(gray, other).tolist() == [[0b0110, 0b1100, 240, 0]]
    assert cpu_ops.bitwise_not(gray).tolist() == [[243, 245, 0, 255]]
    mask = np.array([[255, 0, 1, 0]], np.uint8)
    assert cpu_ops.bitwise_and_mask(gray, gray, mask).tolist() == [[12, 0, 255, 0]]
    # ConvertScale (also named ConvertScaleAbs) of int16: |-3 * 0.5| = 1.5 -> 2,
    # |5 * 0.5| = 2.5 -> 2 (half to even), -300 -> 255, 7 + 0.5 -> 8
    s = np.array([[-3, 5, -300, 7]], np.int16)
    convert = cpu_kernels.CPU_IMPLEMENTATIONS["ConvertScaleAbs"]
    assert convert(s, alpha=0.5, beta=0.0).tolist() == [[2, 2, 150, 4]]
    assert convert(s, alpha=1.0, beta=0.5).tolist() == [[2, 6, 255, 8]]
    rgb = np.array([[[1, 2, 3]]], np.uint8)
    assert cpu_ops.swap_red_blue(rgb).tolist() == [[[3, 2, 1]]]
    assert cpu_ops.gray_to_rgb(np.array([[9]], np.uint8)).tolist() == [[[9, 9, 9]]]
    assert cpu_ops.flip_vertical(np.array([[1], [2]], np.uint8)).tolist() == [[2], [1]]
    # a 1x3 row (10 20 30), 3x3 window: zeros outside (0 10 20 / 9 -> 3.3 -> 3, 60 / 9 ->
    # 6.7 -> 7, 50 / 9 -> 5.6 -> 6); replicated: rows three times (10 10 20 ...) / 9
    row = np.array([[10, 20, 30]], np.uint8)
    assert cpu_ops.blur(row, ksize=3, border_type=0).tolist() == [[3, 7, 6]]
    assert cpu_ops.blur(row, ksize=3, border_type=1).tolist() == [[13, 20, 27]]
    # reflect_101 (20 | 10 20 30 | 20): (20 + 10 + 20) / 3 = 16.7 -> 17, 20, 23.3 -> 23
    assert cpu_ops.blur(row, ksize=3, border_type=4).tolist() == [[17, 20, 23]]
    spot = np.zeros((5, 5), np.uint8)
    spot[2, 2] = 10
    assert cpu_ops.laplacian(spot, ksize=1)[1:4, 1:4].tolist() == [[0, 10, 0], [10, -40, 10],
                                                                    [0, 10, 0]]
    # ksize 3: the diagonal neighbours weigh 2, the centre -8
    assert cpu_ops.laplacian(spot, ksize=3)[1:4, 1:4].tolist() == [[20, 0, 20], [0, -80, 0],
                                                                    [20, 0, 20]]
    # at the border the frame is reflected (BORDER_REFLECT_101): row -1 is row 1
    edge = cpu_ops.laplacian(spot[1:4, 1:4].copy(), ksize=1)
    assert edge.tolist() == [[0, 20, 0], [20, -40, 20], [0, 20, 0]]
    # Scharr dx at (2, 1): the spot is to the right, weight 10: +100; at (1, 1): 3 * 10
    gradient = cpu_ops.scharr(spot, dx=1, dy=0)
    assert gradient.dtype == np.int16 and (gradient[2, 1], gradient[1, 1]) == (100, 30)
    assert (gradient[2, 3], cpu_ops.scharr(spot, dx=0, dy=1)[3, 2]) == (-100, -100)


# -- one generated program with every new type --------------------------------------------------
PHOTOS = ROOT / "models" / "photos"
FRAMES = 3
# name: (type, params, inputs in port order; "camera" is the source, 301x200 RGB)
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    "bgr": ("RgbToBgr", {}, ("camera",)),
    "rgb": ("BgrToRgb", {}, ("bgr",)),
    "flip": ("FlipVertical", {}, ("rgb",)),
    "blur": ("Blur", {"ksize": 5, "border_type": 0}, ("flip",)),
    "lap": ("Laplacian", {"ksize": 3}, ("blur",)),
    "lapabs": ("ConvertScaleAbs", {"alpha": 0.5, "beta": 3.0}, ("lap",)),
    "scharr": ("Scharr", {"dx": 1, "dy": 0}, ("camera",)),
    "scharrabs": ("ConvertScaleAbs", {"alpha": 0.25, "beta": 0.0}, ("scharr",)),
    "band": ("BitwiseAnd", {}, ("lapabs", "scharrabs")),
    "bor": ("BitwiseOr", {}, ("band", "flip")),
    "bxor": ("BitwiseXor", {}, ("bor", "camera")),
    "bnot": ("BitwiseNot", {}, ("bxor",)),
    "gray": ("RgbToGray", {}, ("camera",)),
    "gblur": ("BlurGray", {"ksize": 3, "border_type": 2}, ("gray",)),
    "gscharr": ("ScharrGray", {"dx": 0, "dy": 1}, ("gblur",)),
    "gabs": ("ConvertScaleAbsGray", {"alpha": 1.0, "beta": 0.0}, ("gscharr",)),
    "glap": ("LaplacianGray", {"ksize": 1}, ("gray",)),
    "glapabs": ("ConvertScaleAbsGray", {"alpha": 2.0, "beta": 0.0}, ("glap",)),
    "mask": ("ThresholdGray", {"thresh": 40, "maxval": 255, "thresh_type": 0}, ("gabs",)),
    "gflip": ("FlipVerticalGray", {}, ("mask",)),
    "gnot": ("BitwiseNotGray", {}, ("gflip",)),
    "gand": ("BitwiseAndGray", {}, ("gnot", "glapabs")),
    "gor": ("BitwiseOrGray", {}, ("gand", "gray")),
    "gxor": ("BitwiseXorGray", {}, ("gor", "gblur")),
    "gcut": ("BitwiseAndMaskGray", {}, ("gxor", "gxor", "mask")),
    "cut": ("BitwiseAndMask", {}, ("bnot", "camera", "mask")),
    "colour": ("GrayToRgb", {}, ("gcut",)),
    "curve": ("Lut", {"lut": GAMMA}, ("colour",)),
    "close": ("MorphologyEx", {"op": 3, "shape": 2, "ksize": 5, "iterations": 1}, ("curve",)),
    "gopen": ("MorphologyExGray", {"op": 2, "shape": 0, "ksize": 3, "iterations": 2},
              ("mask",)),
    "gcurve": ("LutGray", {"lut": tuple(255 - i for i in range(256))}, ("gcut",)),
    # a chain of one reader each, so that the fused build puts these in one group too
    "gsmooth": ("BlurGray", {"ksize": 5, "border_type": 1}, ("gray",)),
    "glut": ("LutGray", {"lut": GAMMA}, ("gsmooth",)),
    "gedge": ("MorphologyExGray", {"op": 4, "shape": 1, "ksize": 3, "iterations": 1},
              ("glut",)),
    # the generic names over one channel, beside the deprecated 'Gray' names above
    "g2blur": ("Blur", {"ksize": 3, "border_type": 4}, ("gray",)),
    "g2lut": ("Lut", {"lut": GAMMA}, ("g2blur",)),
    "g2open": ("MorphologyEx", {"op": 2, "shape": 2, "ksize": 5, "iterations": 1},
               ("g2lut",)),
    "gmask": ("BitwiseAndMask", {}, ("g2open", "gedge", "mask")),
    "gdown": ("FlipVertical", {}, ("gmask",)),
    "gsch": ("Scharr", {"dx": 1, "dy": 0}, ("gdown",)),
    "glap2": ("Laplacian", {"ksize": 3}, ("gdown",)),
    "gsabs": ("ConvertScaleAbs", {"alpha": 0.5, "beta": 0.0}, ("gsch",)),
    "glabs": ("ConvertScale", {"alpha": 0.25, "beta": 1.0}, ("glap2",)),
    "gbits": ("BitwiseXor", {}, ("gsabs", "glabs")),
    "gnot2": ("BitwiseNot", {}, ("gbits",)),
    "gor2": ("BitwiseOr", {}, ("gnot2", "gdown")),
    "gand2": ("BitwiseAnd", {}, ("gor2", "gsmooth")),
}


def _opencv(type_name: str) -> Callable:
    if type_name in OPS:
        return OPS[type_name].opencv
    from test_imgproc import SPECS

    return SPECS[type_name].opencv


def chain_model(system: str, chain: dict, placement: str | None = None,
                keep: Collection[str] | None = None) -> str:
    """A model of a camera over models/photos/ and the components of chain (name: (type,
    params, input components in port order)), each output (or those of keep) kept by a
    Keep sink."""
    from gpucompgen.model import library_types

    types = library_types()
    lines = [f"system: {system}", "types: [keep.yaml]"]
    if placement:
        lines.append(f"platform: {{device: portable, placement: {placement}}}")
    lines += ["components:", f'  camera: {{type: Camera, params: {{folder: '
              f'"{PHOTOS.as_posix()}", width: 301, height: 200}}}}']
    connections = []
    for name, (type_name, params, inputs) in chain.items():
        t = types[type_name]
        written = ", ".join(f"{k}: {_yaml_value(v)}" for k, v in params.items())
        lines.append(f"  {name}: {{type: {type_name}, params: {{{written}}}}}")
        (out_port, out_decl), = t.outputs.items()
        for port, source in zip(t.inputs, inputs, strict=True):
            out = "image" if source == "camera" else next(iter(types[chain[source][0]].outputs))
            connections.append(f"  - {source}.{out} -> {name}.{port}")
        if keep is None or name in keep:
            lines.append(f"  keep_{name}: {{type: {keep_type_for(out_decl)}}}")
            connections.append(f"  - {name}.{out_port} -> keep_{name}.image")
    return "\n".join(lines + ["connections:"] + connections) + "\n"


def _yaml_value(v) -> str:
    return str(list(v)) if isinstance(v, (list, tuple)) else \
        ("true" if v is True else "false" if v is False else str(v))


MIXED = {name: ("cpu" if i % 2 else "gpu") for i, name in enumerate(CHAIN)}


@pytest.fixture(scope="module")
def program_outputs(tmp_path_factory, cl_context):
    require_opencl()
    from gpucompgen.build import compile_model, write

    folder = tmp_path_factory.mktemp("ops_all")
    write_keep_types(folder)
    found = {}
    for variant, places, fusion in (("gpu", None, "auto"), ("cpu", None, "auto"),
                                    ("mixed", MIXED, "auto")):
        placement = "cpu" if variant == "cpu" else "gpu"
        model = folder / f"ops_{variant}.yaml"
        model.write_text(chain_model("ops_all", CHAIN, placement))
        out = folder / f"out_{variant}"
        built = compile_model(model, out, places=places, fusion=fusion)
        write(built, out)
        placed = {n: built.system.component(n).placement for n in CHAIN}
        assert placed == (places or dict.fromkeys(CHAIN, placement))
        program = load_generated(out / "ops_all.py", f"ops_all_{variant}")
        result = program.run(frames=FRAMES, context=cl_context)
        assert result.frames == FRAMES
        found[variant] = {n: result.components[f"keep_{n}"].frames for n in CHAIN}
    return found


# the chain's ends: what nobody else reads; only these are kept in the fused programs, so
# that every other output may live inside a group
ENDS = sorted(set(CHAIN) - {s for _, _, inputs in CHAIN.values() for s in inputs})


def fused_unfused_cpu(folder, context, system: str, chain: dict, ends) -> dict:
    """{variant: (build, {end: frames})}: chain with only its ends kept, built in folder
    fused (launches made so dear that every legal group forms), unfused and on the CPU,
    each run for FRAMES frames."""
    from gpucompgen.build import compile_model, write
    from gpucompgen.passes.fuse import FUSION_COSTS

    write_keep_types(folder)
    found = {}
    for variant, placement, fusion in (("fused", "gpu", "auto"), ("unfused", "gpu", "off"),
                                       ("cpu", "cpu", "auto")):
        model = folder / f"{system}_{variant}.yaml"
        model.write_text(chain_model(system, chain, placement, keep=ends))
        out = folder / f"out_{variant}"
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr("gpucompgen.passes.fuse.FUSION_COSTS",
                          {k: {**v, "launch_s": 1e6} for k, v in FUSION_COSTS.items()})
            built = compile_model(model, out, fusion=fusion)
        write(built, out)
        program = load_generated(out / f"{system}.py", f"{system}_{variant}")
        result = program.run(frames=FRAMES, context=context)
        found[variant] = (built, {n: result.components[f"keep_{n}"].frames for n in ends})
    return found


@pytest.fixture(scope="module")
def fused_outputs(tmp_path_factory, cl_context):
    """The chain fused, unfused and on the CPU (fused_unfused_cpu)."""
    require_opencl()
    return fused_unfused_cpu(tmp_path_factory.mktemp("ops_fused"), cl_context, "ops_fused",
                             CHAIN, ENDS)


def test_fused_equals_unfused_equals_cpu_equals_opencv(fused_outputs):
    built, _ = fused_outputs["fused"]
    grouped = {m.type.name for g in built.system.groups for m in g.members}
    fusable = {t for t, _, _ in CHAIN.values() if t in OPS}
    assert fusable <= grouped, sorted(fusable - grouped)  # every new type inside a group
    assert not fused_outputs["unfused"][0].system.groups
    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = _opencv(type_name)(*(values[s] for s in inputs), **params)
        for variant, (_, frames) in fused_outputs.items():
            for name in ENDS:
                np.testing.assert_array_equal(frames[name][i], values[name],
                                              err_msg=f"{variant}: {name}, frame {i}")


def test_the_chain_has_every_new_type():
    assert set(new_types()) <= {t for t, _, _ in CHAIN.values()}


def test_generated_program_equals_opencv_on_every_placement(program_outputs):
    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = _opencv(type_name)(*(values[s] for s in inputs), **params)
            for placement, components in program_outputs.items():
                np.testing.assert_array_equal(components[name][i], values[name],
                                              err_msg=f"{placement}: {name}, frame {i}")


# -- the CPU-side types (features.yaml, drawing.yaml) and the example models -----------------
ROI = [[0, 199], [110, 100], [190, 100], [300, 199]]
FEATURES = {  # name: (type, params, inputs); camera 301x200 RGB
    "gray": ("RgbToGray", {}, ("camera",)),
    "canny3": ("Canny", {"threshold1": 80.0, "threshold2": 160.0, "aperture_size": 3,
                         "l2_gradient": False}, ("camera",)),
    "canny": ("CannyGray", {"threshold1": 50.0, "threshold2": 150.0, "aperture_size": 5,
                            "l2_gradient": True}, ("gray",)),
    "canny7": ("CannyGray", {"threshold1": 500.0, "threshold2": 2000.0, "aperture_size": 7,
                             "l2_gradient": False}, ("gray",)),
    "roi": ("RoiMaskGray", {"points": ROI}, ("gray",)),
    "roi3": ("RoiMask", {"points": [[0, 0], [300, 0], [150, 199]]}, ("camera",)),
    # the generic names over one channel, beside the deprecated 'Gray' names above
    "canny1": ("Canny", {"threshold1": 60.0, "threshold2": 120.0, "aperture_size": 3,
                         "l2_gradient": False}, ("gray",)),
    "roi1": ("RoiMask", {"points": ROI}, ("canny1",)),
    "regions": ("ConnectedComponentsWithStats",
                {"connectivity": 8, "min_area": 5, "max_components": 16}, ("canny",)),
    "regions4": ("ConnectedComponentsWithStats",
                 {"connectivity": 4, "min_area": 1, "max_components": 4096}, ("roi",)),
    "contours": ("FindContours", {"max_contours": 24}, ("canny",)),
    "outlines": ("DrawBoxes", {"red": 255, "green": 0, "blue": 255, "thickness": 2},
                 ("camera", "contours")),
    "lines": ("HoughLinesP", {"rho": 1.0, "theta_degrees": 1.0, "threshold": 30,
                              "min_line_length": 20.0, "max_line_gap": 5.0, "max_lines": 8},
              ("canny",)),
    "boxes": ("DrawBoxes", {"red": 0, "green": 255, "blue": 0, "thickness": 1},
              ("camera", "regions")),
    "drawn": ("DrawLines", {"red": 255, "green": 0, "blue": 0, "thickness": 2},
              ("camera", "lines")),
}


def _features_reference(type_name: str, params: dict, *inputs):
    """OpenCV's calls for the CPU-side types, written out here."""
    p = params
    if type_name.startswith("Canny"):
        return cv2.Canny(inputs[0], p["threshold1"], p["threshold2"],
                         apertureSize=p["aperture_size"], L2gradient=p["l2_gradient"])
    if type_name.startswith("RoiMask"):
        return cv2.fillPoly(np.zeros(inputs[0].shape[:2], np.uint8),
                            [np.array(p["points"], np.int32)], 255)
    if type_name == "ConnectedComponentsWithStats":
        _, _, stats, _ = cv2.connectedComponentsWithStats((inputs[0] > 0).astype(np.uint8),
                                                          connectivity=p["connectivity"])
        kept = [tuple(r) for r in stats[1:] if r[4] >= p["min_area"]]
        kept.sort(key=lambda r: -r[4])  # stable: equal areas keep label order
        table = np.full((p["max_components"], 1, 5), -1, np.int32)
        for i, r in enumerate(kept[:p["max_components"]]):
            table[i, 0] = r
        return table
    if type_name == "FindContours":
        contours, _ = cv2.findContours((inputs[0] > 0).astype(np.uint8), cv2.RETR_EXTERNAL,
                                       cv2.CHAIN_APPROX_SIMPLE)
        table = np.full((p["max_contours"], 1, 5), -1, np.int32)
        for i, contour in enumerate(contours[:p["max_contours"]]):
            table[i, 0] = (*cv2.boundingRect(contour), len(contour))
        return table
    if type_name == "HoughLinesP":
        found = cv2.HoughLinesP(inputs[0], p["rho"], p["theta_degrees"] * np.pi / 180,
                                p["threshold"], minLineLength=p["min_line_length"],
                                maxLineGap=p["max_line_gap"])
        table = np.full((p["max_lines"], 1, 4), -1, np.int32)
        if found is not None:
            found = found.reshape(-1, 4)[:p["max_lines"]]
            table[:len(found), 0] = found
        return table
    image, table = inputs
    out = image.copy()
    for row in table.reshape(table.shape[0], -1):
        if row[0] == -1:
            continue
        colour = (p["red"], p["green"], p["blue"])
        if type_name == "DrawLines":
            cv2.line(out, (int(row[0]), int(row[1])), (int(row[2]), int(row[3])), colour,
                     p["thickness"])
        else:
            cv2.rectangle(out, (int(row[0]), int(row[1])),
                          (int(row[0] + row[2] - 1), int(row[1] + row[3] - 1)), colour,
                          p["thickness"])
    return out


def _camera_frames() -> list[np.ndarray]:
    Image = pytest.importorskip("PIL.Image")
    frames = []
    for path in sorted(PHOTOS.glob("*.jpg")):
        with Image.open(path) as im:
            frames.append(np.asarray(im.convert("RGB")))
    return frames


def test_cpu_side_types_in_a_generated_program_equal_opencv(tmp_path, cl_context):
    """Every type of features.yaml and drawing.yaml in one program over the photographs,
    each component's output against OpenCV's calls on OpenCV's results before it."""
    require_opencl()
    from gpucompgen.build import compile_model, write
    from gpucompgen.model import library_types

    types = library_types()
    assert {n for n, t in types.items() if t.decl_file.name in ("features.yaml", "drawing.yaml")
            } == {t for t, _, _ in FEATURES.values()} - {"RgbToGray"}
    write_keep_types(tmp_path)
    model = tmp_path / "features_all.yaml"
    model.write_text(chain_model("features_all", FEATURES))
    built = compile_model(model, tmp_path / "out")
    write(built, tmp_path / "out")
    program = load_generated(tmp_path / "out" / "features_all.py", "features_all")
    result = program.run(frames=FRAMES, context=cl_context)
    found_any = {"lines": 0, "regions": 0, "contours": 0}
    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in FEATURES.items():
            args = [values[s] for s in inputs]
            values[name] = (_opencv(type_name)(*args) if type_name == "RgbToGray"
                            else _features_reference(type_name, params, *args))
            ours = result.components[f"keep_{name}"].frames[i]
            np.testing.assert_array_equal(ours.reshape(values[name].shape), values[name],
                                          err_msg=f"{name}, frame {i}")
            if name in found_any:
                found_any[name] += int((values[name][:, 0, 0] != -1).sum())
    assert all(found_any.values()), found_any  # the tables were not all empty


@pytest.mark.parametrize("name", ["lanes", "edges"])
def test_example_models_equal_opencv(tmp_path, cl_context, name):
    """models/lanes.yaml and models/edges.yaml: the last photograph's picture equals the
    same pipeline written with OpenCV's functions."""
    require_opencl()
    from gpucompgen.build import compile_model, write

    built = compile_model(ROOT / "models" / f"{name}.yaml", tmp_path)
    write(built, tmp_path)
    program = load_generated(tmp_path / f"{name}.py", f"example_{name}")
    result = program.run(frames=FRAMES, context=cl_context)
    ours = result.components["sink"].last
    camera = _camera_frames()[-1]
    gray = cv2.cvtColor(camera, cv2.COLOR_RGB2GRAY)
    if name == "lanes":
        edges = cv2.threshold(cv2.convertScaleAbs(cv2.Sobel(cv2.GaussianBlur(
            gray, (5, 5), 0), cv2.CV_16S, 1, 0, ksize=3)), 60, 255, cv2.THRESH_BINARY)[1]
        roi = cv2.fillPoly(np.zeros(gray.shape, np.uint8), [np.array(ROI, np.int32)], 255)
        cut = cv2.bitwise_and(edges, edges, mask=roi)
        segments = cv2.HoughLinesP(cut, 1.0, np.pi / 180, 30, minLineLength=25.0,
                                   maxLineGap=5.0)
        expected = camera.copy()
        for x1, y1, x2, y2 in ([] if segments is None else segments.reshape(-1, 4)[:32]):
            cv2.line(expected, (int(x1), int(y1)), (int(x2), int(y2)), (255, 0, 0), 2)
        assert segments is not None  # the example finds lines
    else:
        blur = cv2.GaussianBlur(gray, (3, 3), 0)
        canny = cv2.Canny(blur, 50.0, 150.0)
        sobel = cv2.addWeighted(cv2.convertScaleAbs(cv2.Sobel(blur, cv2.CV_16S, 1, 0)), 0.5,
                                cv2.convertScaleAbs(cv2.Sobel(blur, cv2.CV_16S, 0, 1)), 0.5, 0)
        laplace = cv2.convertScaleAbs(cv2.Laplacian(blur, cv2.CV_16S, ksize=3))
        expected = cv2.hconcat([cv2.cvtColor(g, cv2.COLOR_GRAY2RGB)
                                for g in (canny, sobel, laplace)])
    np.testing.assert_array_equal(ours, expected)
