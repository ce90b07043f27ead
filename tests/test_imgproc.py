"""The image-processing library (gpucompgen/library/imgproc.yaml) against OpenCV.

Every type runs four ways: OpenCV's function, the CPU form (cpu_kernels.py, which calls
OpenCV wherever OpenCV has the operation), an independent numpy reference written from
the operation's definition (imgproc_reference.py: the CPU form must not be checked only
against itself) and the OpenCL kernel a lone component runs, launched directly with
pyopencl on the pinned device (PoCL in CI): the kernel the generator writes from the
type's fusable form. On real
photographs (scikit-image's bundled chelsea 300x451, coffee 400x600 and astronaut
512x512; their gray versions for the one-channel types) the CPU and GPU outputs must be
byte for byte the same (the GPU's on every parameter set of the first photograph, and on
the first two of the others: each set is a build), equal to the numpy reference, and within
MAX_DIFF of OpenCV's: 0, bit-exact, for every type. Hypothesis then
draws small frames (odd sizes, one pixel high or wide), parameters and GPU settings: GPU
equals CPU equals the numpy reference everywhere. RgbToGray and RgbToHsv are also
compared with the reference on all 2^24 colours, and every operation with values
computed by hand (which also pins RGB, not BGR, channel order).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from imgproc_reference import REFERENCES

from gpucompgen.library import cpu_kernels, cpu_ops

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

LIBRARY = ROOT / "gpucompgen" / "library"
PROPERTY = settings(max_examples=12, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


@dataclass
class Spec:
    """How one library type compares with OpenCV."""

    opencv: Callable  # (inputs..., **params) -> OpenCV's output
    cases: list[dict] = field(default_factory=lambda: [{}])  # parameters tried on photos
    max_diff: int = 0  # largest |ours - OpenCV| allowed (and documented in docs/library.md)
    inputs: int = 1  # two for AbsDiff and AddWeighted


SPECS: dict[str, Spec] = {
    "RgbToGray": Spec(lambda im: cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)),
    "RgbToHsv": Spec(lambda im: cv2.cvtColor(im, cv2.COLOR_RGB2HSV)),
    "InRange": Spec(  # one channel: channel 0's bounds
        lambda im, **b: cv2.inRange(im, *(np.array([b[f"{w}_{c}"] for c in range(
            im.shape[2] if im.ndim == 3 else 1)], np.float64) for w in ("lowerb", "upperb"))),
        [{"lowerb_0": 100, "lowerb_1": 0, "lowerb_2": 50,
          "upperb_0": 255, "upperb_1": 120, "upperb_2": 200},
         {"lowerb_0": 60, "lowerb_1": 0, "lowerb_2": 0,
          "upperb_0": 180, "upperb_1": 255, "upperb_2": 255},
         {"lowerb_0": 200, "lowerb_1": 0, "lowerb_2": 0,
          "upperb_0": 100, "upperb_1": 255, "upperb_2": 255}]),
    "Threshold": Spec(
        lambda im, thresh, maxval, thresh_type: cv2.threshold(im, thresh, maxval,
                                                              thresh_type)[1],
        [{"thresh": t, "maxval": m, "thresh_type": k}
         for k in range(5) for t, m in ((100, 200), (0, 255), (255, 7))]),
    "ConvertScale": Spec(
        lambda im, alpha, beta: cv2.convertScaleAbs(im, alpha=alpha, beta=beta),
        [{"alpha": a, "beta": b} for a, b in ((1.7, -30.2), (-0.8, 10.5), (0.37, 0.25),
                                              (1.0, 0.0), (3.3, -400.1))]),
    "AbsDiff": Spec(lambda a, b: cv2.absdiff(a, b), inputs=2),
    "AddWeighted": Spec(
        lambda a, b, alpha, beta, gamma: add_weighted_opencv(a, b, alpha, beta, gamma),
        [{"alpha": a, "beta": b, "gamma": g}
         for a, b, g in ((0.3, 0.7, 0.0), (0.5, 0.5, 0.5), (1.3, -0.4, 12.7), (2.1, 0.9, -99.9))],
        inputs=2),
    "Resize": Spec(
        lambda im, width, height, interpolation: cv2.resize(im, (width, height),
                                                            interpolation=interpolation),
        [{"width": w, "height": h, "interpolation": i}
         for i in (0, 1) for w, h in ((123, 77), (777, 501), (301, 199), (640, 480))]),
    "Crop": Spec(lambda im, left, top, width, height: im[top:top + height, left:left + width],
                 [{"left": 17, "top": 5, "width": 201, "height": 99},
                  {"left": 0, "top": 0, "width": 1, "height": 1}]),
    "FlipHorizontal": Spec(lambda im: cv2.flip(im, 1)),
    "Rotate180": Spec(lambda im: cv2.rotate(im, cv2.ROTATE_180)),
    "GaussianBlur": Spec(lambda im, ksize: cv2.GaussianBlur(im, (ksize, ksize), 0),
                         [{"ksize": 3}, {"ksize": 5}]),
    "Sobel": Spec(lambda im, dx, dy: cv2.Sobel(im, cv2.CV_16S, dx, dy, ksize=3),
                  [{"dx": 1, "dy": 0}, {"dx": 0, "dy": 1}]),
    # the 3x3 rectangle of before, and an ellipse (more sizes, shapes and iterations:
    # tests/test_ops_windows.py)
    "Erode": Spec(lambda im, ksize=3, shape=0, iterations=1: cv2.erode(
        im, cv2.getStructuringElement(shape, (ksize, ksize)), iterations=iterations),
        [{}, {"ksize": 5, "shape": 2}]),
    "Dilate": Spec(lambda im, ksize=3, shape=0, iterations=1: cv2.dilate(
        im, cv2.getStructuringElement(shape, (ksize, ksize)), iterations=iterations),
        [{}, {"ksize": 5, "shape": 2}]),
    # 3x3 here; 5x5 and up (a kernel of its own, 12 s to 35 s to compile for three
    # channels): tests/test_ops_windows.py
    "MedianBlur": Spec(lambda im, ksize=3: cv2.medianBlur(im, ksize)),
}
def add_weighted_opencv(a, b, alpha, beta, gamma):
    """cv2.addWeighted; of float32 frames, which OpenCV computes in double, the bound
    docs/library.md states is asserted, and the kernel's bytes (each operation rounded to
    float32: imgproc_reference.add_weighted) are what the test compares exactly."""
    opencv = cv2.addWeighted(a, alpha, b, beta, gamma)
    if a.dtype != np.float32:
        return opencv
    alpha, beta, gamma = (np.float32(v) for v in (alpha, beta, gamma))
    ours = (a * alpha + b * beta) + gamma
    bound = 2.0 ** -22 * (np.abs(a * alpha) + np.abs(b * beta) + abs(gamma))
    assert (np.abs(ours.astype(np.float64) - opencv) <= bound).all()
    return ours


for _name in ("InRange", "Threshold", "ConvertScale", "AbsDiff", "AddWeighted", "Resize", "Crop",
              "FlipHorizontal", "Rotate180", "GaussianBlur", "Sobel", "Erode", "Dilate",
              "MedianBlur"):
    SPECS[_name + "Gray"] = SPECS[_name]
# OpenCV's name for ConvertScale, and the int16-only types of before (deprecated names)
SPECS["ConvertScaleAbs"] = SPECS["ConvertScaleAbsGray"] = SPECS["ConvertScale"]
TYPES = sorted(SPECS)


def imgproc_types():
    from gpucompgen.model import library_types

    return {n: t for n, t in library_types().items() if t.decl_file.name == "imgproc.yaml"}


def test_every_imgproc_type_is_compared_and_has_a_cpu_implementation():
    assert set(imgproc_types()) == set(SPECS)
    assert set(SPECS) <= set(cpu_kernels.CPU_IMPLEMENTATIONS)
    # Crop is a slice in the library itself; every other type has a numpy reference
    assert set(SPECS) - set(REFERENCES) == {"Crop", "CropGray"}


def independent(type_name: str, params: dict):
    """The numpy reference of a type with these parameters, or None where the library's
    CPU form is numpy itself (Crop, a slice): the kernel is then its check."""
    if type_name.startswith("Crop"):
        return None
    return REFERENCES[type_name]


# -- photographs -------------------------------------------------------------------------
PHOTOS = {"chelsea": skdata.chelsea, "coffee": skdata.coffee, "astronaut": skdata.astronaut}


@pytest.fixture(scope="module")
def photos():
    """RGB and gray versions of the photographs (gray with OpenCV's own conversion)."""
    out = {}
    for name, load in PHOTOS.items():
        rgb = np.ascontiguousarray(load())
        out[name] = {3: rgb, 1: cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)}
    return out


def variants(type_name: str) -> list[tuple[int, str]]:
    """(channels, dtype) of every input a type takes: each channel count and element type
    of a generic type (a deprecated alias: its one channel count)."""
    port = next(iter(imgproc_types()[type_name].inputs.values()))
    dtypes = port.dtypes or (port.dtype,)
    if type_name in OTHER_DTYPES_ELSEWHERE:
        dtypes = ("uint8",)
    return [(c, d) for c in port.channel_counts or (port.channels,) for d in dtypes]


# their int16 and float32 frames (and Crop's any element type) are tests/test_ops_lib.py's,
# on small crops: on these photographs, a kernel build each size, they took a minute more;
# Sobel's float32 frames are tests/test_ops_derivatives.py's, GaussianBlur's int16 and
# float32 ones tests/test_ops_gauss.py's (within OpenCV's float bounds, not bit-exact),
# RgbToGray's float32 ones tests/test_ops_lib.py's (OpenCV's scalar tail differs by an ulp)
OTHER_DTYPES_ELSEWHERE = ("InRange", "Resize", "Crop", "Sobel", "GaussianBlur", "RgbToGray")


# every type over every channel count and element type it takes; the deprecated aliases
# ('GaussianBlurGray': GaussianBlur with 1 channel) are the same operation, run in the
# pipelines of test_imgproc_pipeline.py under their old names
VARIANTS = [(name, c, d) for name in TYPES if not imgproc_types()[name].alias_of
            for c, d in variants(name)]


def variant_id(value) -> str:
    return str(value) if isinstance(value, str) else f"{value}ch" if isinstance(value, int) \
        else ""


def as_dtype(image: np.ndarray, dtype: str) -> np.ndarray:
    """A photograph as a frame of another element type, as a pipeline would make it: int16
    as Sobel's x gradient (-1020..1020), float32 scaled and shifted to fractions and
    negative values."""
    if dtype == "uint8":
        return image
    if dtype == "int16":
        return cv2.Sobel(image, cv2.CV_16S, 1, 0, ksize=3)
    return np.ascontiguousarray(image.astype(np.float32) * np.float32(0.73) - np.float32(41.5))


def inputs_for(type_name: str, image: np.ndarray, dtype: str = "uint8") -> list[np.ndarray]:
    image = as_dtype(image, dtype)
    if SPECS[type_name].inputs == 2:  # a second, different frame of the same size
        return [image, np.ascontiguousarray(image[::-1, ::-1] // 2 + image // 3)]
    return [image]


class Kernels:
    """Launch a type's kernel: a hand-written one (Resize, Crop) as the calling convention
    says, built once a file; a fusable type's generated one (conftest.run_generated)."""

    def __init__(self, context, queue):
        self.context, self.queue, self.programs = context, queue, {}

    def run(self, type_name: str, arrays: list[np.ndarray], params: dict,
            setting=(16, 16, 16)) -> np.ndarray:
        import pyopencl as cl

        from gpucompgen import sizeexpr
        from gpucompgen.c_convention import kernel_parameters
        from gpucompgen.model import DTYPES

        ctype = imgproc_types()[type_name]
        if ctype.generic:  # the ports of a component fed these arrays (resolve-types)
            ctype = ctype.specialized(arrays[0].dtype.name,
                                      arrays[0].shape[2] if arrays[0].ndim == 3 else 1)
        inputs = dict(zip(ctype.inputs, arrays))
        sizes = {k: v.shape[:2] for k, v in inputs.items()}
        ints = {k: v for k, v in params.items() if ctype.params[k].type == "int"}
        (oname, oport), = ctype.outputs.items()
        shape = (sizeexpr.evaluate(oport.height, sizes, ints),
                 sizeexpr.evaluate(oport.width, sizes, ints))
        if oport.channels > 1:
            shape += (oport.channels,)
        if ctype.kernel_file is None:  # a fusable type: the kernel generated from its form
            from conftest import run_generated

            tile, bx, by = setting
            return run_generated(self.context, self.queue, ctype, params, arrays, shape,
                                 (tile, bx, by, 1))
        path = ctype.kernel_file
        if path not in self.programs:
            self.programs[path] = cl.Program(self.context, path.read_text()).build()
        kernel = cl.Kernel(self.programs[path], ctype.kernel_function)
        result = np.empty(shape, np.dtype(DTYPES[oport.dtype][0]))
        mf = cl.mem_flags
        buffers = {k: cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                hostbuf=np.ascontiguousarray(v)) for k, v in inputs.items()}
        buffers[oname] = cl.Buffer(self.context, mf.WRITE_ONLY, max(result.nbytes, 1))
        all_sizes = {**sizes, oname: shape[:2]}
        args = []
        for p in kernel_parameters(ctype):
            if p.kind == "buffer":
                args.append(buffers[p.port])
            elif p.role == "size":
                args.append(np.int32(all_sizes[p.port][0 if p.dim == "height" else 1]))
            elif p.role == "param":
                value = params[p.param]
                args.append(np.float32(value) if p.c_type == "float" else np.int32(value))
            else:
                args.append(np.int32(setting[0]))
        kernel.set_args(*args)
        tile, bx, by = setting
        # as the system launches it (passes/lower.py): whole rows a work-group, or squares
        gx = bx if ctype.cover == "rows" else -(-shape[1] // tile) * bx
        cl.enqueue_nd_range_kernel(self.queue, kernel, (gx, -(-shape[0] // tile) * by, 1),
                                   (bx, by, 1))
        cl.enqueue_copy(self.queue, result, buffers[oname])
        self.queue.finish()
        for b in buffers.values():
            b.release()
        return result


@pytest.fixture(scope="module")
def kernels(cl_context, cl_queue):
    return Kernels(cl_context, cl_queue)


def largest_difference(ours: np.ndarray, reference: np.ndarray) -> int:
    assert ours.shape == reference.shape and ours.dtype == reference.dtype
    return int(np.abs(ours.astype(np.int32) - reference.astype(np.int32)).max(initial=0))


@pytest.mark.parametrize("type_name,channels,dtype", VARIANTS, ids=variant_id)
def test_photographs_cpu_and_gpu_against_opencv(type_name, channels, dtype, photos, kernels):
    """On each photograph and parameter set: GPU == CPU, and both within max_diff of cv2,
    for every channel count and element type the type takes."""
    spec = SPECS[type_name]
    cpu_function = cpu_kernels.CPU_IMPLEMENTATIONS[type_name]
    worst = 0
    for photo, (name, versions) in enumerate(photos.items()):
        arrays = inputs_for(type_name, versions[channels], dtype)
        for i, params in enumerate(spec.cases):
            reference = spec.opencv(*arrays, **params)
            cpu = cpu_function(*arrays, **params)
            numpy_reference = independent(type_name, params)
            if numpy_reference is not None:
                np.testing.assert_array_equal(cpu, numpy_reference(*arrays, **params),
                                              err_msg=f"{name} {params}")
            difference = largest_difference(cpu, reference)
            if params.get("interpolation", 1) == 0:  # nearest resize: bit-exact
                assert difference == 0, (name, params)
            worst = max(worst, difference)
            assert difference <= spec.max_diff, (name, params)
            if i < 2 or photo == 0:  # the kernel on every parameter set of the first
                # photograph (each set is a build), on the first two of the others
                gpu = kernels.run(type_name, arrays, params)
                np.testing.assert_array_equal(gpu, cpu, err_msg=f"{name} {params}")
    assert worst == spec.max_diff, "the documented largest difference is not the measured one"


def test_all_colours_gray_and_hsv():
    """RgbToGray and RgbToHsv (OpenCV) against the numpy references on every one of the
    2^24 RGB colours."""
    c = np.arange(1 << 24, dtype=np.uint32)
    image = np.stack([c >> 16, (c >> 8) & 255, c & 255], -1).astype(np.uint8)
    image = image.reshape(4096, 4096, 3)
    for name in ("RgbToGray", "RgbToHsv"):
        np.testing.assert_array_equal(cpu_kernels.CPU_IMPLEMENTATIONS[name](image),
                                      REFERENCES[name](image), err_msg=name)


def test_all_colours_on_the_gpu(kernels):
    """The colour kernels on every green-blue pair, for every 15th red value (the whole
    cube is left to the CPU test above)."""
    g, b = np.meshgrid(np.arange(256), np.arange(256), indexing="ij")
    for red in range(0, 256, 15):
        image = np.stack([np.full_like(g, red), g, b], -1).astype(np.uint8)
        for name in ("RgbToGray", "RgbToHsv"):
            np.testing.assert_array_equal(kernels.run(name, [image], {}),
                                          cpu_kernels.CPU_IMPLEMENTATIONS[name](image))


# -- random frames, parameters and GPU settings ------------------------------------------
sizes = st.integers(1, 24) | st.sampled_from([31, 33, 47])
# (tile, block_x, block_y): few block shapes, as PoCL compiles a kernel once per shape
SETTINGS = [(8, 1, 1), (16, 16, 16), (32, 8, 3), (64, 2, 5)]


@st.composite
def params_for(draw, type_name: str) -> dict:
    """Parameters within the declared ranges that satisfy the type's requirements."""
    ctype = imgproc_types()[type_name]
    if type_name.startswith("Sobel"):
        dx = draw(st.integers(0, 1))
        return {"dx": dx, "dy": 1 - dx}
    if type_name.startswith("GaussianBlur"):
        return {"ksize": draw(st.sampled_from([3, 5]))}
    if type_name.startswith("MedianBlur"):  # larger: tests/test_ops_windows.py
        return {"ksize": 3}
    if type_name.startswith(("Erode", "Dilate")):  # small elements: each is a build
        shape = draw(st.integers(0, 2))
        return {"ksize": draw(st.sampled_from([1, 3, 5])), "shape": shape,
                "iterations": draw(st.integers(1, 2)) if shape == 0 else 1}
    params = {}
    for name, decl in ctype.params.items():
        if decl.type == "float":
            params[name] = draw(st.floats(-4.0, 4.0, allow_nan=False, width=32)
                                | st.sampled_from([0.0, 0.5, 1.0, -1.0, 1e-30, 300.0]))
        elif name in ("width", "height") and not type_name.startswith("Crop"):
            params[name] = draw(sizes)
        else:
            params[name] = draw(st.integers(int(decl.minimum), min(int(decl.maximum), 255)))
    return params


def random_frame(rng, shape, dtype: str) -> np.ndarray:
    """Values over the element type's range: every int16, float32 with fractions and
    exact halves (the rounding's ties)."""
    if dtype == "uint8":
        return rng.integers(0, 256, shape, dtype=np.uint8)
    if dtype == "int16":
        return rng.integers(-32768, 32768, shape, dtype=np.int16)
    values = rng.uniform(-700.0, 700.0, shape).astype(np.float32)
    halves = rng.random(shape) < 0.2
    values[halves] = np.round(values[halves] * 2) / 2
    return values


@st.composite
def cases(draw, type_name: str, channels: int = 1, dtype: str = "uint8"):
    height, width = draw(sizes), draw(sizes)
    shape = (height, width) if channels == 1 else (height, width, channels)
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    arrays = [random_frame(rng, shape, dtype) for _ in range(SPECS[type_name].inputs)]
    params = draw(params_for(type_name))
    if type_name.startswith("Crop"):  # a rectangle inside the frame
        params["width"] = draw(st.integers(1, width))
        params["height"] = draw(st.integers(1, height))
        params["left"] = draw(st.integers(0, width - params["width"]))
        params["top"] = draw(st.integers(0, height - params["height"]))
    return arrays, params, draw(st.sampled_from(SETTINGS))


@pytest.mark.parametrize("type_name,channels,dtype", VARIANTS, ids=variant_id)
def test_random_frames_gpu_equals_cpu_and_opencv(type_name, channels, dtype, kernels):
    spec = SPECS[type_name]

    # each example is a build (sizes are constants of the kernel): 8 on uint8 frames, 4
    # on each other element type, which takes the same paths with another type (82
    # variants: 350 s of the suite's CPU time at 12 and 6, a fifth of it)
    @settings(PROPERTY, max_examples=8 if dtype == "uint8" else 4)
    @given(case=cases(type_name, channels, dtype))
    def check(case):
        arrays, params, setting = case
        cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
        np.testing.assert_array_equal(kernels.run(type_name, arrays, params, setting), cpu)
        numpy_reference = independent(type_name, params)
        if numpy_reference is not None:
            np.testing.assert_array_equal(cpu, numpy_reference(*arrays, **params))
        assert largest_difference(cpu, spec.opencv(*arrays, **params)) <= spec.max_diff

    check()


@pytest.mark.parametrize("type_name", ["Resize", "ResizeGray"])
def test_bilinear_resize_every_path_of_the_kernel(type_name, kernels):
    """Bilinear Resize at whole factors (OpenCV's INTER_AREA where both halve), other
    ratios and enlargements, with runs split across threads: the kernel equals the CPU
    form, OpenCV's."""
    rng = np.random.default_rng(24)
    channels = 1 if type_name.endswith("Gray") else 3
    for out_width, factor, height, out_height in ((5, 2, 7, 3), (37, 2, 30, 15), (1, 2, 4, 4),
                                                 (29, 3, 9, 13), (70, 4, 33, 8), (3, 4, 1, 1),
                                                 (40, 1, 12, 5), (13, 5, 10, 10),
                                                 (45, 1.5, 20, 31), (100, 0.5, 6, 2),
                                                 (100, 2.5, 5, 3), (100, 4.5, 5, 3)):
        width = int(out_width * factor)
        shape = (height, width) + ((channels,) if channels > 1 else ())
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        params = {"width": out_width, "height": out_height, "interpolation": 1}
        cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](image, **params)
        np.testing.assert_array_equal(cpu, REFERENCES[type_name](image, **params))
        for setting in SETTINGS:
            np.testing.assert_array_equal(kernels.run(type_name, [image], params, setting), cpu,
                                          err_msg=f"{width}x{height} -> {params} {setting}")


# -- the CPU functions' own checks -------------------------------------------------------
def test_cpu_functions_reject_bad_inputs():
    image = np.zeros((4, 5, 3), np.uint8)
    with pytest.raises(ValueError, match="thresh_type"):
        cpu_kernels.threshold(image, thresh=1, maxval=2, thresh_type=5)
    with pytest.raises(ValueError, match="inside"):
        cpu_kernels.crop(image, left=3, top=0, width=3, height=1)
    with pytest.raises(ValueError, match="same size"):
        cpu_kernels.absdiff(image, image[:3])
    with pytest.raises(ValueError, match="ksize"):
        cpu_kernels.gaussian_blur(image, ksize=4)
    with pytest.raises(ValueError, match="orders dx, dy below it"):
        cpu_ops.sobel(image, dx=3, dy=0)
    with pytest.raises(ValueError, match="5 or -1 for a float32 frame"):
        cpu_ops.sobel(image.astype(np.float32), dx=1, dy=0)
    with pytest.raises(TypeError, match="uint8, int16 or float32"):
        cpu_ops.erode(image.astype(np.float64))
    with pytest.raises(ValueError, match="Erode: iterations must be 1..4, above 1 for shape 0"):
        cpu_ops.erode(image, shape=1, iterations=2)
    with pytest.raises(ValueError, match="same size and element type"):
        cpu_kernels.absdiff(image, image.astype(np.int16))
    with pytest.raises(TypeError, match="uint8, int16 or float32"):
        cpu_kernels.in_range(image.astype(np.float64))
    out = np.empty((4, 5, 3), np.uint8)
    assert cpu_kernels.median_blur(image, out=out) is out
    gradient = np.empty((4, 5, 3), np.int16)
    assert cpu_ops.sobel(image, dx=0, dy=1, out=gradient) is gradient


# -- values computed by hand -------------------------------------------------------------
def test_hand_computed_values():
    """A few pixels per operation, worked out on paper from the definitions; they pin the
    channel order (the library's frames are RGB) and the rounding rules."""
    c = cpu_kernels
    rgb = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30]]], np.uint8)
    # (19596 r + 38470 g + 7470 b + 32768) >> 16: red 76, green 150, blue 29, and
    # (195960 + 769400 + 224100 + 32768) >> 16 = 18
    np.testing.assert_array_equal(c.rgb_to_gray(rgb), [[76, 150, 29, 18]])
    # hue in degrees / 2: red 0, green 60, blue 120; (10, 20, 30): v 30, s 255 * 20 / 30
    # = 170, blue is the maximum: hue 240 + 60 * (r - g) / diff = 240 - 30 = 210 degrees
    np.testing.assert_array_equal(c.rgb_to_hsv(rgb), [[[0, 255, 255], [60, 255, 255],
                                                       [120, 255, 255], [105, 170, 30]]])
    gray = np.array([[5, 7, 100, 101]], np.uint8)
    # round half to even: 2.5 -> 2, 3.5 -> 4, 50, 50.5 -> 50
    np.testing.assert_array_equal(c.convert_scale(gray, alpha=0.5, beta=0.0), [[2, 4, 50, 50]])
    # |5 * -2 + 1| = 9, |7 * -2 + 1| = 13, 300 and 302 saturate to 255... |-199| -> 199
    np.testing.assert_array_equal(c.convert_scale(gray, alpha=-2.0, beta=1.0),
                                  [[9, 13, 199, 201]])
    np.testing.assert_array_equal(c.threshold(gray, thresh=100, maxval=9, thresh_type=0),
                                  [[0, 0, 0, 9]])
    np.testing.assert_array_equal(c.threshold(gray, thresh=6, maxval=9, thresh_type=2),
                                  [[5, 6, 6, 6]])
    np.testing.assert_array_equal(c.threshold(gray, thresh=6, maxval=9, thresh_type=4),
                                  [[5, 0, 0, 0]])
    np.testing.assert_array_equal(c.in_range(gray, lowerb_0=7, upperb_0=100), [[0, 255, 255, 0]])
    np.testing.assert_array_equal(
        c.in_range(rgb, lowerb_0=0, lowerb_1=0, lowerb_2=0, upperb_0=255, upperb_1=0,
                   upperb_2=255), [[255, 0, 255, 0]])
    np.testing.assert_array_equal(c.absdiff(gray, gray[:, ::-1].copy()), [[96, 93, 93, 96]])
    # 0.5 * 5 + 0.25 * 101 + 1 = 28.75 -> 29, 0.5 * 101 + 0.25 * 5 + 1 = 52.75 -> 53
    np.testing.assert_array_equal(
        c.add_weighted(gray, gray[:, ::-1].copy(), alpha=0.5, beta=0.25, gamma=1.0)[0, [0, 3]],
        [29, 53])
    # one bright pixel of 16 in a 5x5 frame
    spot = np.zeros((5, 5), np.uint8)
    spot[2, 2] = 16
    blurred = c.gaussian_blur(spot, ksize=3)  # (1 2 1) x (1 2 1) / 16
    np.testing.assert_array_equal(blurred[1:4, 1:4], [[1, 2, 1], [2, 4, 2], [1, 2, 1]])
    assert blurred.sum() == 16
    np.testing.assert_array_equal(cpu_ops.dilate(spot)[1:4, 1:4], np.full((3, 3), 16))
    assert cpu_ops.dilate(spot).sum() == 9 * 16 and not cpu_ops.erode(spot).any()
    # a 3x3 cross reaches the 4 neighbours only; the 5x5 ellipse's rows are 1, 5, 5, 5, 1
    # wide (half widths round(sqrt(4 - dy^2)): 0, 2, 2, 2, 0); the 3x3 rectangle twice is 5x5
    assert cpu_ops.dilate(spot, shape=1).sum() == 5 * 16
    assert cpu_ops.dilate(spot, ksize=5, shape=2).sum() == 17 * 16
    assert cpu_ops.dilate(spot, ksize=3, iterations=2).sum() == 25 * 16
    assert not c.median_blur(spot).any()  # one pixel in nine is not the median
    # Sobel dx at the centre: (-1 0 1) across, (1 2 1) down: row 2's 2 * (0 - 16) = -32 at
    # x = 3, +32 at x = 1
    gradient = cpu_ops.sobel(spot, dx=1, dy=0)
    assert gradient.dtype == np.int16 and (gradient[2, 1], gradient[2, 3]) == (32, -32)
    assert (gradient[1, 1], gradient[3, 3]) == (16, -16)
    assert c.flip_horizontal(gray).tolist() == [[101, 100, 7, 5]]
    assert c.rotate180(np.array([[1, 2], [3, 4]], np.uint8)).tolist() == [[4, 3], [2, 1]]
    assert c.resize(gray, width=2, height=1, interpolation=0).tolist() == [[5, 100]]


def test_one_channel_frames_as_height_width_1():
    """A one-channel frame may come as height x width x 1 (issue 22): the CPU functions
    take it as it is and answer in the same shape, the values those of height x width."""
    rng = np.random.default_rng(3)
    gray = rng.integers(0, 256, (9, 10), np.uint8)
    column = gray[..., None]
    assert np.shares_memory(column, gray)
    for name, params in (("ThresholdGray", {"thresh": 100, "maxval": 255, "thresh_type": 0}),
                         ("ErodeGray", {}), ("GaussianBlurGray", {"ksize": 5}),
                         ("MedianBlurGray", {}),
                         ("ResizeGray", {"width": 4, "height": 3, "interpolation": 1}),
                         ("CropGray", {"left": 1, "top": 2, "width": 3, "height": 4}),
                         ("SobelGray", {"dx": 0, "dy": 1})):
        function = cpu_kernels.CPU_IMPLEMENTATIONS[name]
        flat, deep = function(gray, **params), function(column, **params)
        assert deep.shape == flat.shape + (1,), name
        np.testing.assert_array_equal(deep[..., 0], flat, err_msg=name)
    mask = cpu_kernels.in_range(column, lowerb_0=10, upperb_0=90)
    np.testing.assert_array_equal(mask, cpu_kernels.in_range(gray, lowerb_0=10, upperb_0=90))
