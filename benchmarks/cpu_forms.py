"""The library's CPU forms against the same OpenCV call, one operation at a time.

    python benchmarks/cpu_forms.py [--size 640x360] [--rounds 15] [--against OLD.py]

For every type with a CPU form (gpucompgen/library/cpu_kernels.py), on a photograph
(scikit-image's astronaut, resized to the size; its gray version for one-channel types):
the CPU form as a flexible component calls it (with out=), and the OpenCV call it stands
for, rounds interleaved, in one process. --against names another cpu_kernels.py (say the
numpy one from before issue 24: ``git show 7bfeebb:gpucompgen/library/cpu_kernels.py >
/tmp/old.py``) to time beside them. Prints ms a call (median over rounds, each round the
mean of enough calls to last ~20 ms) and the ratio to OpenCV, with the machine's load.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import time
from functools import partial
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# type -> (parameters, the OpenCV call it stands for); one-channel types run on gray
CASES = {
    "RgbToGray": ({}, lambda cv2, im: cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)),
    "RgbToHsv": ({}, lambda cv2, im: cv2.cvtColor(im, cv2.COLOR_RGB2HSV)),
    "InRangeGray": ({"lowerb_0": 60, "upperb_0": 180},  # the CPU form takes the new names
                    lambda cv2, im: cv2.inRange(im, 60, 180)),
    "ThresholdGray": ({"thresh": 100, "maxval": 255, "thresh_type": 0},
                      lambda cv2, im: cv2.threshold(im, 100, 255, 0)[1]),
    "ConvertScaleGray": ({"alpha": 1.7, "beta": -30.2},
                         lambda cv2, im: cv2.convertScaleAbs(im, alpha=1.7, beta=-30.2)),
    "AbsDiffGray": ({}, lambda cv2, a, b: cv2.absdiff(a, b)),
    "GaussianBlurGray": ({"ksize": 5}, lambda cv2, im: cv2.GaussianBlur(im, (5, 5), 0)),
    "SobelGray": ({"dx": 1, "dy": 0}, lambda cv2, im: cv2.Sobel(im, cv2.CV_16S, 1, 0)),
    "ErodeGray": ({}, lambda cv2, im: cv2.erode(im, KERNEL)),
    "DilateGray": ({}, lambda cv2, im: cv2.dilate(im, KERNEL)),
    "MedianBlurGray": ({}, lambda cv2, im: cv2.medianBlur(im, 3)),
    "FlipHorizontal": ({}, lambda cv2, im: cv2.flip(im, 1)),
    "VerticalMirror": ({}, lambda cv2, im: cv2.flip(im, 0)),
    "BoxBlur": ({"radius": 2}, lambda cv2, im: cv2.blur(im, (5, 5),
                                                         borderType=cv2.BORDER_REPLICATE)),
}
KERNEL = None


def timed(call, budget=0.02) -> float:
    """ms a call: the mean over enough calls to last about budget seconds."""
    start, n = time.perf_counter(), 0
    while True:
        call()
        n += 1
        elapsed = time.perf_counter() - start
        if elapsed >= budget:
            return 1e3 * elapsed / n


def main(argv=None) -> int:
    global KERNEL
    import cv2
    import numpy as np
    from skimage import data

    from gpucompgen.library import cpu_kernels

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--against", type=Path, help="another cpu_kernels.py to time beside")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    KERNEL = np.ones((3, 3), np.uint8)
    rgb = cv2.resize(np.ascontiguousarray(data.astronaut()), (width, height))
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    old = None
    if args.against:
        spec = importlib.util.spec_from_file_location("old_cpu_kernels", args.against)
        old = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(old)
    print(f"{os.uname().nodename}: {os.cpu_count()} cores, load average "
          f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}; frame {width}x{height}, "
          f"cv2 {cv2.__version__} with {cv2.getNumThreads()} threads")
    header = f"{'type':18} {'cv2 ms':>8} {'CPU form':>9} {'ratio':>6}"
    print(header + (f" {'--against':>10} {'ratio':>7}" if old else ""))
    for name, (params, opencv) in CASES.items():
        image = gray if name.endswith("Gray") and name != "RgbToGray" else rgb
        inputs = [image, image[::-1].copy()] if name.startswith("AbsDiff") else [image]
        form = cpu_kernels.CPU_IMPLEMENTATIONS[name]
        expected = opencv(cv2, *inputs)
        out = np.empty_like(expected)
        calls = {"cv2": partial(opencv, cv2, *inputs),
                 "form": partial(form, *inputs, **params, out=out)}
        if old is not None:
            calls["old"] = partial(old.CPU_IMPLEMENTATIONS[name], *inputs, **params)
        assert np.array_equal(form(*inputs, **params), expected), name
        times = {k: [] for k in calls}
        for _ in range(args.rounds):
            for k, call in calls.items():
                times[k].append(timed(call))
        med = {k: statistics.median(v) for k, v in times.items()}
        line = f"{name:18} {med['cv2']:8.3f} {med['form']:9.3f} {med['form'] / med['cv2']:5.1f}x"
        if old is not None:
            line += f" {med['old']:10.3f} {med['old'] / med['cv2']:6.0f}x"
        print(line)
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
