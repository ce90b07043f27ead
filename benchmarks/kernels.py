"""Every library GPU operation alone on a frame, against the same OpenCV call (issue 24).

    python benchmarks/kernels.py [--sizes 640x360,1280x720] [--rounds 7] [--reps 5]
                                 [--only NAME,NAME] [--no-hand] [--settings TILE,BX,BY]

For each library type with a kernel, on one frame of each size (a photograph scaled to
the size, so that data-dependent work is realistic), side by side in one process, rounds
interleaved (so that a noisy machine slows every variant alike):

- ``hand``: the type's hand-written kernel (its .cl file), launched with the type's
  preferred settings as a lone component is, where the type still has one;
- ``gen``: the kernel the generator (kernelgen/fused.py) writes for the operation
  alone, a group of one, launched as the system launches it (fused.launch_geometry);
- ``cv2``: the same OpenCV call on the same cores (cv2.setNumThreads(0) means all).

Kernel time is the OpenCL profiling events' start-to-end; OpenCV's is wall time around
the call.

With --pipelines, the issue's pipelines instead (lanes, colour, edges up to Sobel, motion,
the pointwise chain), each built with fusion auto and off: the device time of all its
kernels a frame (OpenCL profiling events, median over frames), and the groups the cost
model chose.  A group is a decision of the system: it must not be slower than its
members apart.  Every variant's output is checked equal to OpenCV's (bilinear Resize within 1)
before timing.  Prints ms per call (median over rounds x reps, with the interquartile
range) and the ratio to OpenCV.  The figures live in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

K3 = np.ones((3, 3), np.uint8)


LUT = [min(255, round(255 * (i / 255) ** 0.5)) for i in range(256)]  # a gamma curve


def _cases(cv2):
    """name -> (type, params, OpenCV call, inputs as 'rgb'/'gray', second input)."""
    inr = {"lowerb_0": 100, "lowerb_1": 0, "lowerb_2": 50, "upperb_0": 255,
           "upperb_1": 120, "upperb_2": 200}
    c = {
        "RgbToGray": ("RgbToGray", {}, lambda a: cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)),
        "RgbToHsv": ("RgbToHsv", {}, lambda a: cv2.cvtColor(a, cv2.COLOR_RGB2HSV)),
        "InRange": ("InRange", inr, lambda a: cv2.inRange(
            a, np.array([100, 0, 50]), np.array([255, 120, 200]))),
        "InRangeGray": ("InRangeGray", {**inr, "lowerb_0": 60, "upperb_0": 180},
                        lambda a: cv2.inRange(a, 60, 180)),
        "Threshold": ("Threshold", {"thresh": 100, "maxval": 200, "thresh_type": 0},
                      lambda a: cv2.threshold(a, 100, 200, 0)[1]),
        "ThresholdGray": ("ThresholdGray", {"thresh": 100, "maxval": 200, "thresh_type": 0},
                          lambda a: cv2.threshold(a, 100, 200, 0)[1]),
        "ConvertScale": ("ConvertScale", {"alpha": 1.7, "beta": -30.2},
                         lambda a: cv2.convertScaleAbs(a, alpha=1.7, beta=-30.2)),
        "ConvertScaleGray": ("ConvertScaleGray", {"alpha": 1.7, "beta": -30.2},
                             lambda a: cv2.convertScaleAbs(a, alpha=1.7, beta=-30.2)),
        "AbsDiff": ("AbsDiff", {}, lambda a, b: cv2.absdiff(a, b)),
        "AbsDiffGray": ("AbsDiffGray", {}, lambda a, b: cv2.absdiff(a, b)),
        "AddWeighted": ("AddWeighted", {"alpha": 0.3, "beta": 0.7, "gamma": 0.0},
                        lambda a, b: cv2.addWeighted(a, 0.3, b, 0.7, 0.0)),
        "AddWeightedGray": ("AddWeightedGray", {"alpha": 0.3, "beta": 0.7, "gamma": 0.0},
                            lambda a, b: cv2.addWeighted(a, 0.3, b, 0.7, 0.0)),
        "FlipHorizontal": ("FlipHorizontal", {}, lambda a: cv2.flip(a, 1)),
        "FlipHorizontalGray": ("FlipHorizontalGray", {}, lambda a: cv2.flip(a, 1)),
        "Rotate180": ("Rotate180", {}, lambda a: cv2.rotate(a, cv2.ROTATE_180)),
        "Rotate180Gray": ("Rotate180Gray", {}, lambda a: cv2.rotate(a, cv2.ROTATE_180)),
        "VerticalMirror": ("VerticalMirror", {}, lambda a: cv2.flip(a, 0)),
        "GaussianBlur k3": ("GaussianBlur", {"ksize": 3},
                            lambda a: cv2.GaussianBlur(a, (3, 3), 0)),
        "GaussianBlur k5": ("GaussianBlur", {"ksize": 5},
                            lambda a: cv2.GaussianBlur(a, (5, 5), 0)),
        "GaussianBlurGray k3": ("GaussianBlurGray", {"ksize": 3},
                                lambda a: cv2.GaussianBlur(a, (3, 3), 0)),
        "GaussianBlurGray k5": ("GaussianBlurGray", {"ksize": 5},
                                lambda a: cv2.GaussianBlur(a, (5, 5), 0)),
        "Sobel dx": ("Sobel", {"dx": 1, "dy": 0},
                     lambda a: cv2.Sobel(a, cv2.CV_16S, 1, 0, ksize=3)),
        "SobelGray dx": ("SobelGray", {"dx": 1, "dy": 0},
                         lambda a: cv2.Sobel(a, cv2.CV_16S, 1, 0, ksize=3)),
        "SobelGray dy": ("SobelGray", {"dx": 0, "dy": 1},
                         lambda a: cv2.Sobel(a, cv2.CV_16S, 0, 1, ksize=3)),
        "Erode": ("Erode", {}, lambda a: cv2.erode(a, K3)),
        "ErodeGray": ("ErodeGray", {}, lambda a: cv2.erode(a, K3)),
        "Dilate": ("Dilate", {}, lambda a: cv2.dilate(a, K3)),
        "DilateGray": ("DilateGray", {}, lambda a: cv2.dilate(a, K3)),
        "MedianBlur": ("MedianBlur", {}, lambda a: cv2.medianBlur(a, 3)),
        "MedianBlurGray": ("MedianBlurGray", {}, lambda a: cv2.medianBlur(a, 3)),
        "MedianBlur k5": ("MedianBlur", {"ksize": 5}, lambda a: cv2.medianBlur(a, 5)),
        "MedianBlurGray k5": ("MedianBlurGray", {"ksize": 5}, lambda a: cv2.medianBlur(a, 5)),
        "MedianBlurGray k7": ("MedianBlurGray", {"ksize": 7}, lambda a: cv2.medianBlur(a, 7)),
        "BoxBlur r1": ("BoxBlur", {"radius": 1}, lambda a: cv2.blur(
            a, (3, 3), borderType=cv2.BORDER_REPLICATE)),
        "Crop": ("Crop", {"left": 16, "top": 8, "width": 320, "height": 240},
                 lambda a: a[8:248, 16:336].copy()),
        "Resize nearest": ("Resize", {"width": 320, "height": 180, "interpolation": 0},
                           lambda a: cv2.resize(a, (320, 180),
                                                interpolation=cv2.INTER_NEAREST)),
        "Resize linear": ("Resize", {"width": 320, "height": 180, "interpolation": 1},
                          lambda a: cv2.resize(a, (320, 180), interpolation=cv2.INTER_LINEAR)),
        # the kernel's other paths: a whole factor along x only (640 -> 320, 1280 -> 320),
        # and a ratio that is none
        "Resize linear 320x240": ("Resize", {"width": 320, "height": 240, "interpolation": 1},
                                  lambda a: cv2.resize(a, (320, 240),
                                                       interpolation=cv2.INTER_LINEAR)),
        "Resize linear 333x211": ("Resize", {"width": 333, "height": 211, "interpolation": 1},
                                  lambda a: cv2.resize(a, (333, 211),
                                                       interpolation=cv2.INTER_LINEAR)),
        "ResizeGray linear": ("ResizeGray", {"width": 320, "height": 180, "interpolation": 1},
                              lambda a: cv2.resize(a, (320, 180),
                                                   interpolation=cv2.INTER_LINEAR)),
        # enlarging: 640x360 to 1920x1080 is a whole factor 3, 1280x720 to it 1.5; 777x501
        # a ratio that is none (the tests' size; from 301x200 with --sizes 301x200)
        "Resize linear 1920x1080": ("Resize", {"width": 1920, "height": 1080,
                                               "interpolation": 1},
                                    lambda a: cv2.resize(a, (1920, 1080),
                                                         interpolation=cv2.INTER_LINEAR)),
        "Resize linear 777x501": ("Resize", {"width": 777, "height": 501, "interpolation": 1},
                                  lambda a: cv2.resize(a, (777, 501),
                                                       interpolation=cv2.INTER_LINEAR)),
        "ResizeGray linear 777x501": ("ResizeGray", {"width": 777, "height": 501,
                                                     "interpolation": 1},
                                      lambda a: cv2.resize(a, (777, 501),
                                                           interpolation=cv2.INTER_LINEAR)),
        # the operations issue 26 added
        "BitwiseAnd": ("BitwiseAnd", {}, lambda a, b: cv2.bitwise_and(a, b)),
        "BitwiseAndGray": ("BitwiseAndGray", {}, lambda a, b: cv2.bitwise_and(a, b)),
        "BitwiseNot": ("BitwiseNot", {}, lambda a: cv2.bitwise_not(a)),
        "GrayToRgb": ("GrayToRgb", {}, lambda a: cv2.cvtColor(a, cv2.COLOR_GRAY2RGB)),
        "RgbToBgr": ("RgbToBgr", {}, lambda a: cv2.cvtColor(a, cv2.COLOR_RGB2BGR)),
        "FlipVertical": ("FlipVertical", {}, lambda a: cv2.flip(a, 0)),
        "Lut": ("Lut", {"lut": tuple(LUT)}, lambda a: cv2.LUT(a, np.array(LUT, np.uint8))),
        "Blur k5": ("Blur", {"ksize": 5, "border_type": 4},
                    lambda a: cv2.blur(a, (5, 5), borderType=4)),
        "BlurGray k5": ("BlurGray", {"ksize": 5, "border_type": 4},
                        lambda a: cv2.blur(a, (5, 5), borderType=4)),
        "LaplacianGray k3": ("LaplacianGray", {"ksize": 3},
                             lambda a: cv2.Laplacian(a, cv2.CV_16S, ksize=3)),
        "ScharrGray dx": ("ScharrGray", {"dx": 1, "dy": 0},
                          lambda a: cv2.Scharr(a, cv2.CV_16S, 1, 0)),
        "LaplacianGray k5": ("LaplacianGray", {"ksize": 5},
                             lambda a: cv2.Laplacian(a, cv2.CV_16S, ksize=5)),
        "SobelGray k5 dx2": ("SobelGray", {"dx": 2, "dy": 0, "ksize": 5},
                             lambda a: cv2.Sobel(a, cv2.CV_16S, 2, 0, ksize=5)),
        "SobelGray dx 32F": ("SobelGray", {"dx": 1, "dy": 0, "ddepth": 5, "scale": 0.125},
                             lambda a: cv2.Sobel(a, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)),
        "MorphologyExGray open k3": (
            "MorphologyExGray", {"op": 2, "shape": 0, "ksize": 3, "iterations": 1},
            lambda a: cv2.morphologyEx(a, cv2.MORPH_OPEN, K3)),
        "MorphologyExGray gradient k5": (
            "MorphologyExGray", {"op": 4, "shape": 0, "ksize": 5, "iterations": 1},
            lambda a: cv2.morphologyEx(a, cv2.MORPH_GRADIENT, np.ones((5, 5), np.uint8))),
        # the compile-time criterion's cases (fused.py: MAX_UNROLLED_READS): windows of
        # 3x3 to 7x7, elliptic elements, windows of windows
        "BlurGray k3": ("BlurGray", {"ksize": 3, "border_type": 4},
                        lambda a: cv2.blur(a, (3, 3), borderType=4)),
        "BlurGray k7": ("BlurGray", {"ksize": 7, "border_type": 4},
                        lambda a: cv2.blur(a, (7, 7), borderType=4)),
        # float32 frames (a fourth element: the input's element type)
        "Blur k5 32F": ("Blur", {"ksize": 5, "border_type": 4},
                        lambda a: cv2.blur(a, (5, 5), borderType=4), "float32"),
        "BlurGray k31 32F": ("BlurGray", {"ksize": 31, "border_type": 4},
                             lambda a: cv2.blur(a, (31, 31), borderType=4), "float32"),
        "Filter2D 5x5 32F": ("Filter2D", {"weights": SMOOTH5, "delta": 0.0, "border_type": 4},
                             lambda a: cv2.filter2D(a, -1, np.float32(SMOOTH5), borderType=4),
                             "float32"),
        # large windows (the staged schedule: row sums, then column sums)
        **{f"{t} k{k}": (t, {"ksize": k, "border_type": 4},
                         lambda a, k=k: cv2.blur(a, (k, k), borderType=4))
           for t, k in (("BlurGray", 15), ("BlurGray", 31), ("Blur", 31))},
        **{f"MorphologyExGray {what} k{k}{' ellipse' if shape else ''}": (
            "MorphologyExGray", {"op": op, "shape": shape, "ksize": k, "iterations": 1},
            lambda a, op=op, k=k, shape=shape: cv2.morphologyEx(
                a, op, cv2.getStructuringElement(shape, (k, k))))
           for what, op, k, shape in (("erode", 0, 5, 2), ("gradient", 4, 3, 2),
                                      ("open", 2, 3, 2), ("close", 3, 3, 0),
                                      ("tophat", 5, 3, 0), ("open", 2, 5, 0),
                                      ("open", 2, 5, 2))},
    }
    c.update(_warp_cases(cv2))
    return c


# warp.yaml: a rotation by 10 degrees about (300, 200), scaled 0.9, to 640x360 (the matrix
# maps dst to src: WARP_INVERSE_MAP), a mild homography; Remap reads _remap_maps
ROTATION = ((0.886327, 0.156283, 2.858), (-0.156283, 0.886327, 69.6))
HOMOGRAPHY = ((0.95, 0.05, 10.0), (-0.03, 0.98, 12.0), (1e-5, 2e-5, 1.0))
SMOOTH5 = tuple(tuple(float(np.float32(v / 44.0)) for v in row) for row in (
    (1, 1, 2, 1, 1), (1, 2, 3, 2, 1), (2, 3, -4, 3, 2), (1, 2, 3, 2, 1), (1, 1, 2, 1, 1)))
CAMERA = ((600.0, 0.0, 320.0), (0.0, 600.0, 180.0), (0.0, 0.0, 1.0))
DISTORTION = (-0.28, 0.09, 0.001, -0.0015, -0.01)


def _warp_cases(cv2) -> dict:
    def m64(m):
        return np.asarray(m, np.float32).astype(np.float64)

    def warp(tname, m, flags):
        call = cv2.warpAffine if tname == "WarpAffine" else cv2.warpPerspective
        return (tname, {"m": m, "width": 640, "height": 360, "flags": flags,
                        "border_mode": 0, "border_value": 0},
                lambda a: call(a, m64(m), (640, 360), flags=flags))

    return {
        "WarpAffine nearest": warp("WarpAffine", ROTATION, 16),
        "WarpAffine linear": warp("WarpAffine", ROTATION, 17),
        "WarpPerspective linear": warp("WarpPerspective", HOMOGRAPHY, 17),
        "Remap linear": ("Remap", {"interpolation": 1, "border_mode": 0, "border_value": 0},
                         lambda a, m1, m2: cv2.remap(a, m1, m2, cv2.INTER_LINEAR)),
        "Undistort": ("Undistort", {"camera_matrix": CAMERA, "dist_coeffs": DISTORTION},
                      lambda a: cv2.undistort(a, m64(CAMERA), m64(DISTORTION))),
        # float32 frames (a fourth element: the input's element type)
        "WarpAffine linear 32F": (*warp("WarpAffine", ROTATION, 17), "float32"),
        "Remap linear 32F": ("Remap", {"interpolation": 1, "border_mode": 0,
                                       "border_value": 0},
                             lambda a, m1, m2: cv2.remap(a, m1, m2, cv2.INTER_LINEAR),
                             "float32"),
    }


def _remap_maps(h, w):
    """Remap's maps for an h x w frame: the frame turned by 10 degrees about its centre."""
    x, y = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    c, s = np.cos(0.1745), np.sin(0.1745)
    dx, dy = x - w / 2, y - h / 2
    return ((w / 2 + c * dx - s * dy).astype(np.float32),
            (h / 2 + s * dx + c * dy).astype(np.float32))


def _instance(t, params, dtype=None):
    """A case's type as a component of it gets it: a generic type over the most channels
    it takes (the plain name is the RGB case; its 'Gray' alias the one-channel one), its
    first element type or dtype, its output's element type from the parameters (ddepth)."""
    port = next(iter(t.inputs.values()))
    if not t.generic:
        return t
    return t.specialized(dtype or (port.dtypes or (port.dtype,))[0],
                         max(port.channel_counts or (port.channels,)), params)


def _as(frame: np.ndarray, dtype: str | None = None) -> np.ndarray:
    """A photograph as a frame of a case's element type: float32 with fractions and
    negatives, as a pipeline's float frames."""
    if dtype != "float32":
        return frame
    return frame.astype(np.float32) * np.float32(0.73) - np.float32(41.5)


def _frames(cv2, h, w):
    from skimage import data

    rgb = cv2.resize(np.ascontiguousarray(data.astronaut()), (w, h),
                     interpolation=cv2.INTER_AREA)
    second = np.ascontiguousarray(rgb[::-1, ::-1] // 2 + rgb // 3)
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return {3: (rgb, second), 1: (gray, cv2.cvtColor(second, cv2.COLOR_RGB2GRAY))}


def _out_shape(t, arrays, params):
    from gpucompgen import sizeexpr
    from gpucompgen.model import DTYPES

    sizes = {k: v.shape[:2] for k, v in zip(t.inputs, arrays)}
    ints = {k: v for k, v in params.items() if t.params[k].type == "int"}
    (oname, oport), = t.outputs.items()
    shape = (sizeexpr.evaluate(oport.height, sizes, ints),
             sizeexpr.evaluate(oport.width, sizes, ints))
    if oport.channels > 1:
        shape += (oport.channels,)
    return oname, shape, np.dtype(DTYPES[oport.dtype][0])


class Variant:
    """One kernel ready to launch on fixed buffers: times itself with profiling events."""

    def __init__(self, queue, kernel, gsize, lsize, out_buf, result, keep):
        self.queue, self.kernel, self.gsize, self.lsize = queue, kernel, gsize, lsize
        self.keep = keep  # the kernel's buffers live as long as the kernel
        self.out_buf, self.result = out_buf, result

    def output(self):
        import pyopencl as cl

        self.call()
        cl.enqueue_copy(self.queue, self.result, self.out_buf)
        self.queue.finish()
        return self.result.copy()

    def call(self):
        import pyopencl as cl

        return cl.enqueue_nd_range_kernel(self.queue, self.kernel, self.gsize, self.lsize)

    def time(self, reps):
        out = []
        for _ in range(reps):
            ev = self.call()
            ev.wait()
            out.append((ev.profile.end - ev.profile.start) * 1e-9)
        return out


def hand_variant(ctx, queue, t, arrays, params, programs):
    import pyopencl as cl

    from gpucompgen.c_convention import kernel_parameters

    if t.kernel_file is None:
        return None
    path = t.kernel_file
    if path not in programs:
        programs[path] = cl.Program(ctx, path.read_text()).build()
    kernel = cl.Kernel(programs[path], t.kernel_function)
    oname, shape, dtype = _out_shape(t, arrays, params)
    mf = cl.mem_flags
    bufs = {k: cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(v))
            for k, v in zip(t.inputs, arrays)}
    result = np.empty(shape, dtype)
    bufs[oname] = cl.Buffer(ctx, mf.READ_WRITE, max(result.nbytes, 1))
    sizes = {**{k: v.shape[:2] for k, v in zip(t.inputs, arrays)}, oname: shape[:2]}
    tile, bx, by, _ = t.gpu.prefer
    args = []
    for p in kernel_parameters(t):
        if p.kind == "buffer":
            args.append(bufs[p.port])
        elif p.role == "size":
            args.append(np.int32(sizes[p.port][0 if p.dim == "height" else 1]))
        elif p.role == "param":
            v = params[p.param]
            args.append(np.float32(v) if p.c_type == "float" else np.int32(v))
        else:
            args.append(np.int32(tile))
    kernel.set_args(*args)
    gx = bx if t.cover == "rows" else -(-shape[1] // tile) * bx
    return Variant(queue, kernel, (gx, -(-shape[0] // tile) * by, 1), (bx, by, 1),
                   bufs[oname], result, bufs)


def gen_variant(ctx, queue, t, arrays, params, device, settings=None):
    """The generator's kernel for the operation alone (a group of one member 'op'), with
    the system's preferred settings or the given (tile, block_x, block_y)."""
    import pyopencl as cl

    from gpucompgen.kernelgen import fused

    if t.fusable is None:
        return None
    oname, shape, dtype = _out_shape(t, arrays, params)
    shapes = {**{k: v.shape[:2] for k, v in zip(t.inputs, arrays)}, oname: shape[:2]}
    group = fused.group_of_one(t, params, shapes, "op", "op_alone")
    source = fused.group_kernel(group, f"benchmark of {t.name}")
    start = time.perf_counter()
    program = cl.Program(ctx, source).build()
    kernel = cl.Kernel(program, fused.kernel_name(group))
    mf = cl.mem_flags
    bufs = {k: cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(v))
            for k, v in zip(t.inputs, arrays)}
    result = np.empty(shape, dtype)
    out = cl.Buffer(ctx, mf.READ_WRITE, max(result.nbytes, 1))
    tile, bx, by, _ = fused.preferred_settings(group, device)
    if settings:
        tile, bx, by = settings
    kernel.set_args(*fused.launch_arguments(group, bufs, out, tile))
    gsize, lsize = fused.launch_geometry(group, tile, bx, by)
    variant = Variant(queue, kernel, gsize, lsize, out, result, bufs)
    variant.output()  # PoCL compiles the kernel for its work-group size at the first launch
    variant.build_s = time.perf_counter() - start
    return variant


SINKS = "component_types:\n" + "".join(f"""
  {name}:
    kind: standard
    inputs:
      image: {{memory: cpu, dtype: {dtype}, channels: {channels}}}
    python: {{file: sink.py, class: Sink}}
""" for name, dtype, channels in (("Sink3", "uint8", 3), ("Sink1", "uint8", 1),
                                  ("SinkS1", "int16", 1)))
SINK_PY = """class Sink:
    def initialize(self, image):
        pass

    def execute(self, image):
        pass

    def free_memory(self):
        pass
"""
# name -> [(component, type, params, inputs)], the last one read by the sink
PIPELINES = {
    "lanes": [("gray", "RgbToGray", {}, ["src"]),
              ("blur", "GaussianBlurGray", {"ksize": 5}, ["gray"]),
              ("dil", "DilateGray", {}, ["blur"]), ("ero", "ErodeGray", {}, ["blur"]),
              ("grad", "AbsDiffGray", {}, ["dil", "ero"]),
              ("binary", "ThresholdGray", {"thresh": 40, "maxval": 255, "thresh_type": 0},
               ["grad"]),
              ("close1", "DilateGray", {}, ["binary"]), ("close2", "ErodeGray", {}, ["close1"])],
    "colour": [("hsv", "RgbToHsv", {}, ["src"]),
               ("mask", "InRange", {"lowerb_0": 0, "lowerb_1": 80, "lowerb_2": 80,
                                    "upperb_0": 20, "upperb_1": 255, "upperb_2": 255},
                ["hsv"]),
               ("ero", "ErodeGray", {}, ["mask"]), ("dil", "DilateGray", {}, ["ero"])],
    "edges": [("gray", "RgbToGray", {}, ["src"]),
              ("blur", "GaussianBlurGray", {"ksize": 3}, ["gray"]),
              ("sobel", "SobelGray", {"dx": 1, "dy": 0}, ["blur"])],
    "motion": [("prev", "Rotate180", {}, ["src"]),
               ("diff", "AbsDiff", {}, ["src", "prev"]),
               ("gray", "RgbToGray", {}, ["diff"]),
               ("binary", "ThresholdGray", {"thresh": 30, "maxval": 255, "thresh_type": 0},
                ["gray"]),
               ("median", "MedianBlurGray", {}, ["binary"])],
    "pointwise": [("gray", "RgbToGray", {}, ["src"]),
                  ("s1", "ConvertScaleGray", {"alpha": 1.2, "beta": 5.0}, ["gray"]),
                  ("t1", "ThresholdGray", {"thresh": 200, "maxval": 255, "thresh_type": 2},
                   ["s1"]),
                  ("s2", "ConvertScaleGray", {"alpha": 0.8, "beta": -3.0}, ["t1"]),
                  ("t2", "ThresholdGray", {"thresh": 100, "maxval": 255, "thresh_type": 0},
                   ["s2"])],
}


def pipeline_model(name: str, w: int, h: int) -> str:
    from gpucompgen.model import library_types

    types = library_types()
    steps = PIPELINES[name]
    lines = [f"system: {name}", "types: [sinks.yaml]", "platform: {placement: gpu}",
             "components:", f"  src: {{type: StillImage, params: {{width: {w}, height: {h}}}}}"]
    conns = []
    outs = {"src": "image"}
    for comp, tname, params, inputs in steps:
        t = types[tname]
        written = ", ".join(f"{k}: {v}" for k, v in params.items())
        lines.append(f"  {comp}: {{type: {tname}, params: {{{written}}}}}")
        for port, source in zip(t.inputs, inputs):
            conns.append(f"  - {source}.{outs[source]} -> {comp}.{port}")
        outs[comp] = next(iter(t.outputs))
    last, tname = steps[-1][0], steps[-1][1]
    port = next(iter(types[tname].outputs.values()))
    sink = ("SinkS" if port.dtype == "int16" else "Sink") + str(port.channels)
    lines.append(f"  sink: {{type: {sink}}}")
    conns.append(f"  - {last}.{outs[last]} -> sink.image")
    return "\n".join(lines + ["connections:"] + conns) + "\n"


def pipelines(sizes: list[str], rounds: int, frames: int) -> int:
    import tempfile

    from gpucompgen.build import compile_model, write
    from gpucompgen.runtime import load_module

    folder = Path(tempfile.mkdtemp(prefix="kernels_pipelines_"))
    (folder / "sinks.yaml").write_text(SINKS)
    (folder / "sink.py").write_text(SINK_PY)
    print(f"device time of all kernels a frame (ms, median over {rounds} rounds of "
          f"{frames} frames [IQR]); groups the cost model chose")
    print("| pipeline | size | fusion off | fusion auto | auto / off | groups |")
    print("|---|---|---:|---:|---:|---|")
    count = itertools.count()
    for size in sizes:
        w, h = map(int, size.split("x"))
        for name in PIPELINES:
            model = folder / f"{name}_{size}.yaml"
            model.write_text(pipeline_model(name, w, h))
            programs, groups = {}, ""
            for fusion in ("off", "auto"):
                out = folder / f"{name}_{size}_{fusion}"
                result = compile_model(model, out, fusion=fusion)
                write(result, out)
                programs[fusion] = load_module(out / f"{name}.py",
                                               f"bench_kernels_{name}_{next(count)}")
                if fusion == "auto":
                    groups = "; ".join("+".join(m for m, _, _ in g.members)
                                       for g in result.system.plan.groups) or "none"
            times = {k: [] for k in programs}
            for _ in range(rounds):
                for k, program in programs.items():
                    prof = program.run(frames=frames, profile=True).profile
                    prof.collect()
                    per = {}
                    for (_, what), secs in prof.seconds.items():
                        if what == "kernel":
                            for i, t in enumerate(secs):
                                per[i] = per.get(i, 0.0) + t
                    times[k] += list(per.values())[1:]  # the first frame builds caches
            off, auto = _stats(times["off"]), _stats(times["auto"])
            print(f"| {name} | {size} | {off[0]:.3f} [{off[1]:.3f}-{off[2]:.3f}] | "
                  f"{auto[0]:.3f} [{auto[1]:.3f}-{auto[2]:.3f}] | {auto[0] / off[0]:.2f}x | "
                  f"{groups} |")
    return 0


def _stats(samples):
    q1, med, q3 = (float(np.percentile(samples, p)) * 1e3 for p in (25, 50, 75))
    return med, q1, q3


def main(argv=None) -> int:
    import cv2
    import pyopencl as cl

    from gpucompgen.model import library_types

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="640x360,1280x720")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--only", default="", help="comma-separated case names")
    ap.add_argument("--no-hand", action="store_true", help="skip the hand-written kernels")
    ap.add_argument("--settings", default="",
                    help="TILE,BX,BY: also the generated kernels with these launch settings")
    ap.add_argument("--pipelines", action="store_true",
                    help="the issue's pipelines fused and unfused instead")
    ap.add_argument("--frames", type=int, default=10, help="frames a round (--pipelines)")
    a = ap.parse_args(argv)
    if a.pipelines:
        return pipelines(a.sizes.split(","), a.rounds, a.frames)
    ctx = cl.create_some_context(interactive=False)
    queue = cl.CommandQueue(ctx, properties=cl.command_queue_properties.PROFILING_ENABLE)
    device = ctx.devices[0]
    from gpucompgen.runtime.opencl import facts as facts_of_cl_device

    facts = facts_of_cl_device(device)
    types = library_types()
    cases = _cases(cv2)
    if a.only:
        cases = {k: v for k, v in cases.items() if k in a.only.split(",")}
    print(f"device: {device.name.strip()} ({cl.device_type.to_string(device.type)}); "
          f"cv2 {cv2.__version__} with {cv2.getNumThreads()} threads; "
          f"{a.rounds} rounds x {a.reps} calls")
    programs: dict = {}
    for size in a.sizes.split(","):
        w, h = map(int, size.split("x"))
        frames = _frames(cv2, h, w)
        runs = {}
        for name, (tname, params, ref, *dtype) in cases.items():
            t = _instance(types[tname], params, *dtype)
            arrays = [_as(frames[p.channels][k], *dtype) if k == 0 else frames[p.channels][k]
                      if p.dtype != "float32" else _remap_maps(h, w)[k - 1]
                      for k, p in enumerate(t.inputs.values())]
            expected = ref(*arrays)
            variants = {}
            if not a.no_hand:
                variants["hand"] = hand_variant(ctx, queue, t, arrays, params, programs)
            variants["gen"] = gen_variant(ctx, queue, t, arrays, params, facts)
            if a.settings:
                variants["gen@"] = gen_variant(ctx, queue, t, arrays, params, facts,
                                               tuple(map(int, a.settings.split(","))))
            variants = {k: v for k, v in variants.items() if v is not None}
            for k, v in variants.items():
                got = v.output()
                diff = np.abs(got.astype(np.float64) - expected.astype(np.float64)).max()
                # the bounds docs/library.md states
                # float32: within 1e-5 of the largest value (docs/library.md's bounds)
                limit = 8 if name == "Undistort" else 1 if "linear" in name else 0
                if got.dtype == np.float32:
                    limit = 1e-5 * float(np.abs(expected).max())
                if diff > limit:
                    print(f"  {name} {size} {k}: differs from OpenCV by {diff}")
                    return 1
            runs[name] = (variants, ref, arrays, {k: [] for k in [*variants, "cv2"]})
        for _ in range(a.rounds):
            for name, (variants, ref, arrays, samples) in runs.items():
                for k, v in variants.items():
                    samples[k] += v.time(a.reps)
                for _ in range(a.reps):
                    t0 = time.perf_counter()
                    ref(*arrays)
                    samples["cv2"].append(time.perf_counter() - t0)
        print(f"\n{size}: ms per call, median [IQR]; ratio = kernel / cv2; build: seconds "
              "to build the generated kernel and launch it once (a fresh POCL_CACHE_DIR "
              "for compile times)")
        extra = [f"generated, settings {a.settings}", "ratio"] if a.settings else []
        print("| " + " | ".join(["operation", "cv2", "hand", "ratio", "generated", "ratio",
                                 *extra, "build s"]) + " |")
        print("|---|---:|---:|---:|---:|---:|" + "---:|" * len(extra) + "---:|")
        for name, (variants, _, _, samples) in runs.items():
            c = _stats(samples["cv2"])
            cells = [f"{c[0]:.3f} [{c[1]:.3f}-{c[2]:.3f}]"]
            for k in ("hand", "gen", *(["gen@"] if a.settings else [])):
                if samples.get(k):
                    s = _stats(samples[k])
                    cells += [f"{s[0]:.3f} [{s[1]:.3f}-{s[2]:.3f}]", f"{s[0] / c[0]:.1f}x"]
                else:
                    cells += ["-", "-"]
            built = getattr(variants.get("gen"), "build_s", None)
            cells.append(f"{built:.1f}" if built is not None else "-")
            print(f"| {name} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
