"""The camera-format, channel and magnitude types alone on a frame, against OpenCV.

    python benchmarks/camera_formats.py [--sizes 640x480,1280x720] [--rounds 5] [--reps 5]

For each type of yuv.yaml, channels.yaml and magnitude.yaml, on one frame of each size (a
photograph scaled to the size and converted to the camera format the type reads), side by
side in one process, rounds interleaved: the kernel the generator writes for the type
alone (benchmarks/kernels.py's ``gen`` variant: what a lone component runs, launched as the
system launches it; OpenCL profiling events) and the same OpenCV call on the same cores
(wall time around the call).  Every kernel's output is checked against OpenCV first
(Magnitude within 2 ulp, docs/library.md).  Prints ms per call (median over rounds x reps,
with the interquartile range) and the ratio to OpenCV; the figures are in
docs/library.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from kernels import _stats, gen_variant


def _cases(cv2, rgb):
    """name -> (inputs, OpenCV call, params) for a frame rgb of even sides."""
    h, w = rgb.shape[:2]
    i420 = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420)
    nv12 = np.empty((h * 3 // 2, w), np.uint8)
    nv12[:h] = i420[:h]
    chroma = i420[h:].reshape(2, h // 2, w // 2)
    nv12[h:] = np.stack([chroma[0], chroma[1]], -1).reshape(h // 2, w)
    yuv = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV)
    yuyv = np.ascontiguousarray(np.stack([yuv[..., 0], np.where(
        np.arange(w) % 2 == 0, yuv[..., 1], yuv[..., 2])], -1))
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    dx, dy = cv2.Sobel(gray, cv2.CV_16S, 1, 0), cv2.Sobel(gray, cv2.CV_16S, 0, 1)
    planes = [np.ascontiguousarray(rgb[..., c]) for c in range(3)]
    return {
        "Nv12ToRgb": ([nv12], lambda a: cv2.cvtColor(a, cv2.COLOR_YUV2RGB_NV12), {}),
        "Nv12ToGray": ([nv12], lambda a: cv2.cvtColor(a, cv2.COLOR_YUV2GRAY_NV12), {}),
        "YuyvToRgb": ([yuyv], lambda a: cv2.cvtColor(a, cv2.COLOR_YUV2RGB_YUYV), {}),
        "RgbToYuv": ([rgb], lambda a: cv2.cvtColor(a, cv2.COLOR_RGB2YUV), {}),
        "ExtractChannel": ([rgb], lambda a: cv2.extractChannel(a, 1), {"channel": 1}),
        "MergeChannels3": (planes, lambda *a: cv2.merge(list(a)), {}),
        "Magnitude": ([dx, dy], lambda a, b: cv2.magnitude(a.astype(np.float32),
                                                          b.astype(np.float32)), {}),
    }


def main(argv=None) -> int:
    import cv2
    import pyopencl as cl
    from skimage import data

    from gpucompgen.model import library_types
    from gpucompgen.runtime.opencl import facts as facts_of_cl_device

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="640x480,1280x720")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args(argv)
    ctx = cl.create_some_context(interactive=False)
    queue = cl.CommandQueue(ctx, properties=cl.command_queue_properties.PROFILING_ENABLE)
    facts = facts_of_cl_device(ctx.devices[0])
    types = library_types()
    print(f"device: {ctx.devices[0].name.strip()}; cv2 {cv2.__version__} with "
          f"{cv2.getNumThreads()} threads; {a.rounds} rounds x {a.reps} calls")
    for size in a.sizes.split(","):
        w, h = map(int, size.split("x"))
        rgb = cv2.resize(np.ascontiguousarray(data.astronaut()), (w, h),
                         interpolation=cv2.INTER_AREA)
        runs = {}
        for name, (arrays, ref, params) in _cases(cv2, rgb).items():
            t = types[name]
            if t.generic:
                first = arrays[0]
                t = t.specialized(first.dtype.name, first.shape[2] if first.ndim == 3 else 1)
            variant = gen_variant(ctx, queue, t, arrays, params, facts)
            got, expected = variant.output(), ref(*arrays)
            if name == "Magnitude":
                bits = np.abs(got.view(np.int32).astype(np.int64) - expected.view(np.int32))
                ok = bits.max() <= 2
            else:
                ok = np.array_equal(got.reshape(expected.shape), expected)
            if not ok:
                print(f"  {name} {size}: differs from OpenCV")
                return 1
            runs[name] = (variant, ref, arrays, {"gen": [], "cv2": []})
        for _ in range(a.rounds):
            for variant, ref, arrays, samples in runs.values():
                samples["gen"] += variant.time(a.reps)
                for _ in range(a.reps):
                    t0 = time.perf_counter()
                    ref(*arrays)
                    samples["cv2"].append(time.perf_counter() - t0)
        print(f"\n{size}: ms per call, median [IQR]; ratio = kernel / cv2")
        print("| operation | cv2 | generated | ratio |")
        print("|---|---:|---:|---:|")
        for name, (_, _, _, samples) in runs.items():
            c, g = _stats(samples["cv2"]), _stats(samples["gen"])
            print(f"| {name} | {c[0]:.3f} [{c[1]:.3f}-{c[2]:.3f}] | "
                  f"{g[0]:.3f} [{g[1]:.3f}-{g[2]:.3f}] | {g[0] / c[0]:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
