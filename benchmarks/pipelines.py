"""Five everyday pipelines, generated from library types, side by side with OpenCV.

    python benchmarks/pipelines.py [--sizes 640x360,1280x720] [--rounds 5] [--frames 12]
                                   [--pipelines lanes,colour,edges,motion,pointwise]
                                   [--backend opencl|cuda]

Each pipeline is a model of library types (benchmarks/pipeline_types/ adds the frame
source, the sink and the one step the library lacks) and the same steps written as plain
cv2 calls:

- lanes: gray -> Gaussian 5 -> morphological gradient -> threshold -> closing (the
  gradient and the closing are MorphologyExGray, op 4 and op 3, as cv2 calls
  morphologyEx; until the library had MorphologyEx they were DilateGray and ErodeGray
  into AbsDiffGray, and DilateGray -> ErodeGray: eight components for cv2's five calls)
- colour: HSV -> inRange -> erode -> dilate
- edges: gray -> Gaussian 3 -> Sobel (x) -> abs -> threshold (abs: AbsGray16, a
  benchmark type: the library has no int16 -> uint8 |x|; cv2.convertScaleAbs)
- motion: absdiff of consecutive frames -> gray -> threshold -> median 3
- pointwise: gray -> scale -> threshold (trunc) -> scale -> threshold

The frames are a pan across a photograph (scikit-image's astronaut, resized; 2 pixels a
frame, 16 frames replayed), not noise. Every variant is built for the device at hand
(`--device auto`, as `gpucompgen run` builds: the OpenCL device PYOPENCL_CTX selects, or
with `--backend cuda` the CUDA device CUDA_DEVICE selects, its class deciding placement
and the fusion cost model's constants). Variants: the default
build (no placement, no fusion option: placed for the device's class, each chain of
fusable components weighed whole as the groups it would make on the device; the chains'
decisions are printed after the table), every component on
the device (placement: gpu) with fusion auto and with --fusion off, every component on the
CPU (placement: cpu: the library's CPU forms, OpenCV), placement: auto after
`gpucompgen tune` (its profile: components and groups measured), and every component on
the device after `tune` (the groups it measured slower than their members are refused). All run in ONE process, rounds interleaved (each round runs every variant of every
pipeline and size, then cv2), so load from other programs falls on all of them. A
variant's time of a frame is the time between two frames reaching the end of its loop
(building and initializing are not counted); cv2's the time of one frame's calls. Every
round checks the last frame's output of every variant against cv2's: equal bytes or the
benchmark fails. Prints ms a frame (median over every frame of every round), the
interquartile range and the ratio to cv2, with the machine, the OpenCL device (choose it
with PYOPENCL_CTX) and the load average before and after. Halide's fused JIT is timed
where the `halide` module is installed; otherwise the table says it was skipped.
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
TYPES = Path(__file__).resolve().parent / "pipeline_types" / "types.yaml"

T = 40  # the thresholds' level (gradient, edges, motion)
HUE = {"lowerb_0": 5, "upperb_0": 30, "lowerb_1": 60, "upperb_1": 255,
       "lowerb_2": 60, "upperb_2": 255}  # skin and warm colours of the photograph
SCALE1, SCALE2 = (1.2, 10.0), (0.8, -5.0)

# name -> (source type, components, connections); the sink is 'sink', fed by 'last'
PIPELINES = {
    "lanes": ("PanFrames", {
        "gray": "RgbToGray", "blur": "GaussianBlurGray ksize=5",
        "grad": "MorphologyExGray op=4 ksize=3",
        "thr": f"ThresholdGray thresh={T} maxval=255 thresh_type=0",
        "close": "MorphologyExGray op=3 ksize=3"}, [
        "source.image -> gray.image", "gray.gray -> blur.image", "blur.blurred -> grad.src",
        "grad.dst -> thr.image", "thr.thresholded -> close.src", "close.dst -> sink.mask"]),
    "colour": ("PanFrames", {
        "hsv": "RgbToHsv", "inrange": "InRange " + " ".join(f"{k}={v}" for k, v in HUE.items()),
        "ero": "ErodeGray", "dil": "DilateGray"}, [
        "source.image -> hsv.image", "hsv.hsv -> inrange.image", "inrange.mask -> ero.image",
        "ero.eroded -> dil.image", "dil.dilated -> sink.mask"]),
    "edges": ("PanFrames", {
        "gray": "RgbToGray", "blur": "GaussianBlurGray ksize=3", "sobel": "SobelGray dx=1 dy=0",
        "absolute": "AbsGray16", "thr": f"ThresholdGray thresh={T} maxval=255 thresh_type=0"}, [
        "source.image -> gray.image", "gray.gray -> blur.image", "blur.blurred -> sobel.image",
        "sobel.gradient -> absolute.image", "absolute.absolute -> thr.image",
        "thr.thresholded -> sink.mask"]),
    "motion": ("PanPairs", {
        "diff": "AbsDiff", "gray": "RgbToGray",
        "thr": f"ThresholdGray thresh={T // 2} maxval=255 thresh_type=0",
        "median": "MedianBlurGray"}, [
        "source.image -> diff.src1", "source.previous -> diff.src2", "diff.diff -> gray.image",
        "gray.gray -> thr.image", "thr.thresholded -> median.image",
        "median.median -> sink.mask"]),
    "pointwise": ("PanFrames", {
        "gray": "RgbToGray", "scale1": f"ConvertScaleGray alpha={SCALE1[0]} beta={SCALE1[1]}",
        "thr1": "ThresholdGray thresh=200 maxval=255 thresh_type=2",
        "scale2": f"ConvertScaleGray alpha={SCALE2[0]} beta={SCALE2[1]}",
        "thr2": "ThresholdGray thresh=90 maxval=255 thresh_type=0"}, [
        "source.image -> gray.image", "gray.gray -> scale1.image",
        "scale1.scaled -> thr1.image", "thr1.thresholded -> scale2.image",
        "scale2.scaled -> thr2.image", "thr2.thresholded -> sink.mask"]),
}
VARIANTS = {  # name -> (platform lines, fusion); every one built for the device at hand
    "default": ("", None),
    "device": ("placement: gpu", None),
    "device fusion off": ("placement: gpu", "off"),
    "all CPU": ("placement: cpu", None),
    "auto after tune": ("placement: auto", None),  # `gpucompgen tune MODEL` first
    "device after tune": ("placement: gpu", None),  # tune's groups refuse the losers
}


def opencv_steps(cv2, np):
    """name -> f(frame, previous) -> mask: the same steps in plain cv2."""
    k = np.ones((3, 3), np.uint8)
    lo = np.array([HUE[f"lowerb_{c}"] for c in range(3)], np.float64)
    hi = np.array([HUE[f"upperb_{c}"] for c in range(3)], np.float64)

    def lanes(f, p):
        b = cv2.GaussianBlur(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), (5, 5), 0)
        g = cv2.morphologyEx(b, cv2.MORPH_GRADIENT, k)
        return cv2.morphologyEx(cv2.threshold(g, T, 255, 0)[1], cv2.MORPH_CLOSE, k)

    def colour(f, p):
        m = cv2.inRange(cv2.cvtColor(f, cv2.COLOR_RGB2HSV), lo, hi)
        return cv2.dilate(cv2.erode(m, k), k)

    def edges(f, p):
        b = cv2.GaussianBlur(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), (3, 3), 0)
        a = cv2.convertScaleAbs(cv2.Sobel(b, cv2.CV_16S, 1, 0, ksize=3))
        return cv2.threshold(a, T, 255, 0)[1]

    def motion(f, p):
        g = cv2.cvtColor(cv2.absdiff(f, p), cv2.COLOR_RGB2GRAY)
        return cv2.medianBlur(cv2.threshold(g, T // 2, 255, 0)[1], 3)

    def pointwise(f, p):
        g = cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)
        t = cv2.threshold(cv2.convertScaleAbs(g, alpha=SCALE1[0], beta=SCALE1[1]), 200, 255,
                          cv2.THRESH_TRUNC)[1]
        return cv2.threshold(cv2.convertScaleAbs(t, alpha=SCALE2[0], beta=SCALE2[1]), 90, 255,
                             cv2.THRESH_BINARY)[1]

    return {"lanes": lanes, "colour": colour, "edges": edges, "motion": motion,
            "pointwise": pointwise}


def pan(np, cv2, width: int, height: int, count: int = 16, step: int = 2):
    """count frames of a pan across the astronaut photograph, step pixels a frame."""
    from skimage import data

    photo = np.ascontiguousarray(data.astronaut())
    wide = cv2.resize(photo, (width + count * step, height + count * step // 2),
                      interpolation=cv2.INTER_AREA)
    return np.stack([wide[i * step // 2:i * step // 2 + height, i * step:i * step + width]
                     for i in range(count)])


def model_text(name: str, width: int, height: int, frames: Path, platform_line: str) -> str:
    source, components, connections = PIPELINES[name]
    lines = [f"system: {name}_{width}x{height}", f"types: [{TYPES.as_posix()}]"]
    if platform_line:
        lines += ["platform:", f"  {platform_line}"]
    lines += ["components:", (f"  source: {{type: {source}, params: {{path: "
                              f"\"{frames.as_posix()}\", width: {width}, height: {height}}}}}")]
    for comp, spec in components.items():
        tname, *params = spec.split()
        given = ", ".join(p.replace("=", ": ") for p in params)
        lines.append(f"  {comp}: {{type: {tname}" + (f", params: {{{given}}}}}" if given
                                                      else "}"))
    lines += ["  sink: {type: MaskSink}", "connections:"]
    lines += [f"  - {c}" for c in connections]
    return "\n".join(lines) + "\n"


class Variant:
    """One generated program: run(frames) -> (seconds between frames, last mask)."""

    def __init__(self, module, context):
        self.module, self.context = module, context

    def run(self, frames: int):
        from gpucompgen import runtime

        stamps = []

        class Clock(runtime.Monitor):
            def frame_done(self, done: int) -> None:
                stamps.append(time.perf_counter())
                super().frame_done(done)

        result = self.module.run(frames=frames + 2, context=self.context,
                                 monitor=Clock(progress=False))
        deltas = [b - a for a, b in itertools.pairwise(stamps[2:])]  # 2 frames warm up
        return deltas, result.components["sink"].kept


def tuned(model: Path, frames: int, backend: str = "opencl", text: str | None = None) -> str:
    """What `gpucompgen tune MODEL` does: measure, write tune/<system>.yaml beside it; returns
    the profile.  Given the profile text of the same pipeline (tune measures components and
    candidate groups, whatever the model's placement line), writes that instead: both
    variants after tune then read one measurement, and the benchmark tunes once."""
    from gpucompgen.model import load_system
    from gpucompgen.tune import default_profile_path, tune

    if text is None:
        text, _ = tune(model, frames=frames, backend=backend)
    path = default_profile_path(model, load_system(model))
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)
    return text


def halide_note() -> str:
    try:
        import halide  # noqa: F401
    except ImportError:
        return "Halide: not installed (the `halide` Python module), its column skipped"
    return "Halide: installed, but its pipelines are not written yet: column skipped"


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.node()}: {cpu}, {os.cpu_count()} cores"


def load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main(argv=None) -> int:
    import cv2
    import numpy as np

    from gpucompgen import runtime
    from gpucompgen.build import compile_model, write
    from gpucompgen.runtime import device_api

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="640x360,1280x720")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--frames", type=int, default=12, help="timed frames a round")
    parser.add_argument("--pipelines", default=",".join(PIPELINES))
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--tune-frames", type=int, default=5,
                        help="frames tune times each component for 'auto after tune'")
    parser.add_argument("--backend", choices=device_api.NAMES, default="opencl",
                        help="build and run every variant for opencl or cuda (default: opencl)")
    args = parser.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    names = args.pipelines.split(",")
    variants = args.variants.split(",")
    for given, known, what in ((names, PIPELINES, "pipeline"), (variants, VARIANTS, "variant")):
        unknown = [v for v in given if v not in known]
        if unknown:
            parser.error(f"unknown {what} {', '.join(map(repr, unknown))}; "
                         f"choose from {', '.join(map(repr, known))}")
    steps = opencv_steps(cv2, np)
    api = device_api.get(args.backend)
    try:
        context = api.create_context()
    except runtime.PipelineError as exc:  # no driver, binding or device: say which
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(machine())
    label = {"opencl": "OpenCL", "cuda": "CUDA"}[args.backend]
    print(f"{label} device: {api.device_name(api.context_device(context))}; "
          f"cv2 {cv2.__version__}, {cv2.getNumThreads()} threads; {halide_note()}")
    print(f"load average before: {load()}")
    programs, frames_of, placed, profiles = {}, {}, [], {}
    with tempfile.TemporaryDirectory() as temporary:
        tmp = Path(temporary)
        for width, height in sizes:
            path = tmp / f"pan_{width}x{height}.npy"
            frames_of[width, height] = pan(np, cv2, width, height)
            np.save(path, frames_of[width, height])
            for name in names:
                for variant in variants:
                    line, fusion = VARIANTS[variant]
                    folder = tmp / f"{name}_{width}x{height}_{variant.replace(' ', '_')}"
                    folder.mkdir()
                    model = folder / "model.yaml"
                    model.write_text(model_text(name, width, height, path, line))
                    if variant.endswith("after tune"):  # the profile the build then reads
                        profiles[name, width, height] = tuned(
                            model, args.tune_frames, args.backend,
                            profiles.get((name, width, height)))
                    result = compile_model(model, folder / "out", device="auto",
                                           fusion=fusion, backend=args.backend)
                    write(result, folder / "out")
                    groups = ["+".join(m.name for m in g.members) for g in result.system.groups]
                    if groups:
                        placed.append(f"{variant}, {name} {width}x{height}: groups "
                                      f"{', '.join(groups)}")
                    if variant in ("default", "auto after tune"):
                        placed += [f"{variant}, {name} {width}x{height}: {chain.lines()[0]}"
                                   for chain in result.system.placement.chains]
                        on_gpu = [n for n in PIPELINES[name][1]
                                  if result.system.component(n).placement == "gpu"]
                        placed.append(f"{variant}, {name} {width}x{height}: "
                                      f"{len(on_gpu)} of {len(PIPELINES[name][1])} on the "
                                      f"device{' (' + ', '.join(on_gpu) + ')' if on_gpu else ''}")
                    module = runtime.load_module(folder / "out" / f"{name}_{width}x{height}.py",
                                                 f"bench_{folder.name}")
                    programs[name, (width, height), variant] = Variant(module, context)
        samples = {key: [] for key in programs}
        samples.update({(n, s, "cv2"): [] for n in names for s in sizes})
        for _ in range(args.rounds):
            for name, size in itertools.product(names, sizes):
                stack = frames_of[size]
                count = args.frames + 2
                expected = steps[name](stack[(count - 1) % len(stack)],
                                       stack[(count - 2) % len(stack)])
                for variant in variants:
                    deltas, last = programs[name, size, variant].run(args.frames)
                    samples[name, size, variant] += deltas
                    if not np.array_equal(last, expected):
                        print(f"error: {name} {size} {variant}: the last frame differs from "
                              f"cv2's", file=sys.stderr)
                        return 1
                for i in range(count):
                    start = time.perf_counter()
                    steps[name](stack[i % len(stack)], stack[(i - 1) % len(stack)])
                    if i >= 2:
                        samples[name, size, "cv2"].append(time.perf_counter() - start)
    print(f"load average after: {load()}")
    print(f"{args.rounds} rounds x {args.frames} frames; ms a frame, median (IQR); every "
          "variant's output equal to cv2's in every round\n")
    header = ["pipeline", "size", "cv2", *variants]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * 2 + "---:|" * (len(header) - 2))
    for name, size in itertools.product(names, sizes):
        base = statistics.median(samples[name, size, "cv2"])
        cells = []
        for variant in ["cv2", *variants]:
            values = [1e3 * v for v in samples[name, size, variant]]
            q = statistics.quantiles(values, n=4) if len(values) > 1 else values * 3
            med = statistics.median(values)
            ratio = "" if variant == "cv2" else f" {med / (1e3 * base):.1f}x"
            cells.append(f"{med:.2f} ({q[0]:.2f}-{q[2]:.2f}){ratio}")
        print(f"| {name} | {size[0]}x{size[1]} | " + " | ".join(cells) + " |")
    print()
    for line in placed:
        print(line)
    for variant in variants:
        ratios = [statistics.median(samples[n, s, variant])
                  / statistics.median(samples[n, s, "cv2"]) for n, s in
                  itertools.product(names, sizes)]
        print(f"geometric mean {variant} / cv2: {statistics.geometric_mean(ratios):.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
