"""System-level fusion (issue 14): the fused mirror chain and the vision system, measured.

    python benchmarks/fusion.py [--size 1152x864] [--length 25] [--rounds 5] [--frames 40]

Side by side in one process, interleaved round after round (so that a noisy machine slows
every variant alike), on the OpenCL device programs use (PYOPENCL_CTX):

- the chain StillImage -> N VerticalMirror -> FrameSink at the given size, generated
  three ways: one unfused mirror (N=1), N unfused mirrors (one kernel each, as in the
  paper) and N mirrors fused into one kernel; the time per frame is the time between
  consecutive frames reaching the sink, as `gpucompgen bench` measures it, and every
  variant's last frame is checked against numpy;
- models/vision_system.yaml, fused (merger and detector as one kernel) and unfused: the
  time per frame (between consecutive frames reaching the VisionManager), the kernel
  launches per frame and the device time of its kernels (OpenCL profiling events, a
  separate run), and the plan's peak device memory.

Beside them, where the `halide` module is installed (`pip install halide`, the `bench`
extra), the same chain of 1 and of N vertical mirrors as one Halide pipeline, JIT-compiled
for these cores (the mirrors inlined into one loop over rows, parallel over rows,
vectorized along them), and `cv2.flip` once: what a hand-scheduled fused pipeline and the
library call cost on the same cores, without the generated program's copies.

Prints every figure (median over all rounds, with the interquartile range) and the ratios
against the targets: fused N / unfused N=1 <= 1.3 and unfused N / fused N >= 5 (issue
14); fused N / fused N=1 <= 1.2 and fused N / Halide N <= 3 (issue 24).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

WARMUP = 3  # frames of each vision run left out (first frames build and fill caches)
TARGET_VS_ONE = 1.30
TARGET_SPEEDUP = 5.0
TARGET_LENGTH_FREE = 1.2  # fused N / fused 1
TARGET_VS_HALIDE = 3.0  # fused N / Halide's fused N


class HalideChain:
    """n vertical mirrors as one Halide pipeline over a (height, width, 3) frame seen as
    rows of width * 3 bytes (a mirror moves whole rows): each stage a Func reading the
    previous one at the mirrored row, all inlined into the output's loop, which runs
    parallel over rows and 32 bytes at a time along them.  JIT-compiled once."""

    def __init__(self, image: np.ndarray, n: int):
        import halide as hl

        h, w, c = image.shape
        self.src = np.ascontiguousarray(image).reshape(h, w * c)
        self.out = np.empty_like(self.src)
        self.input = hl.Buffer(self.src)  # dimension 0 along a row, 1 over rows
        self.output = hl.Buffer(self.out)
        i, y = hl.Var("i"), hl.Var("y")
        stage = hl.Func("image")
        stage[i, y] = self.input[i, y]
        for k in range(n):
            mirrored = hl.Func(f"mirror{k + 1}")
            mirrored[i, y] = stage[i, h - 1 - y]
            stage = mirrored
        stage.parallel(y).vectorize(i, 32)
        stage.compile_jit()
        self.func = stage

    def run(self, frames: int) -> tuple[list[float], np.ndarray]:
        stamps = []
        for _ in range(frames):
            self.func.realize(self.output)
            stamps.append(time.perf_counter())
        return list(np.diff(stamps)), self.out.reshape(-1, self.out.shape[1] // 3, 3)


def halide_chains(image: np.ndarray, n: int) -> dict:
    """{name: (chain, length)} of Halide's fused chains, or {} without the module."""
    try:
        import halide  # noqa: F401
    except ImportError:
        print("Halide: not installed (pip install halide), its rows skipped", file=sys.stderr)
        return {}
    return {"Halide N=1": (HalideChain(image, 1), 1),
            f"Halide N={n}": (HalideChain(image, n), n)}


class Cv2Flip:
    """cv2.flip(image, 0) into a kept array: the library call, once per frame."""

    def __init__(self, image: np.ndarray):
        self.image, self.out = image, np.empty_like(image)

    def run(self, frames: int) -> tuple[list[float], np.ndarray]:
        import cv2

        stamps = []
        for _ in range(frames):
            cv2.flip(self.image, 0, dst=self.out)
            stamps.append(time.perf_counter())
        return list(np.diff(stamps)), self.out


def _stats(samples: list[float]) -> str:
    q1, med, q3 = (np.percentile(samples, p) * 1e3 for p in (25, 50, 75))
    return f"{med:8.3f} ms  [{q1:.3f}-{q3:.3f}]"


class Vision:
    """The vision system, built fused or unfused, timed at the VisionManager."""

    def __init__(self, folder: Path, fusion: str):
        from gpucompgen.build import compile_model, write
        from gpucompgen.runtime import load_module

        model = ROOT / "models" / "vision_system.yaml"
        out = folder / f"vision_{fusion}"
        result = compile_model(model, out, fusion=fusion)
        write(result, out)
        self.plan = result.system.plan
        self.module = load_module(out / "vision_system.py", f"bench_fusion_vision_{fusion}")

    def run(self, frames: int, context) -> list[float]:
        from gpucompgen import runtime

        stamps: list[float] = []
        cls = self.module.VisionManager
        original = cls.execute

        def stamp(manager, mask):
            result = original(manager, mask)
            stamps.append(time.perf_counter())
            return result

        cls.execute = stamp
        try:
            self.module.run(frames=frames + WARMUP, context=context,
                            monitor=runtime.Monitor(progress=False, options={"quiet": True}))
        finally:
            cls.execute = original
        return list(np.diff(stamps[WARMUP:]))

    def kernels(self, frames: int, context) -> tuple[float, float]:
        """(kernel launches per frame, median device ms of the kernels per frame)."""
        from gpucompgen import runtime

        result = self.module.run(frames=frames, context=context, profile=True,
                                 monitor=runtime.Monitor(progress=False,
                                                         options={"quiet": True}))
        result.profile.collect()
        kernels = {k: v for k, v in result.profile.seconds.items() if k[1] == "kernel"}
        launches = sum(len(v) for v in kernels.values()) / frames
        return launches, sum(float(np.median(v)) for v in kernels.values()) * 1e3


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1152x864", help="WIDTHxHEIGHT of the chain")
    parser.add_argument("--length", type=int, default=25, help="mirrors in the chain")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--frames", type=int, default=40, help="frames per variant a round")
    args = parser.parse_args(argv)

    from gpucompgen.bench import Generated, expected_output, parse_sizes
    from gpucompgen.library.still_image import still_frame
    from gpucompgen.runtime import create_context

    (size,) = parse_sizes(args.size)
    n = args.length
    context = create_context()
    device = context.devices[0].name.strip()
    image = still_frame(*size)
    with tempfile.TemporaryDirectory(prefix="gpucompgen-fusion-") as tmp:
        folder = Path(tmp)
        chains = {"unfused N=1": (Generated(folder, 1, size, "gpu-aware", context), 1),
                  f"unfused N={n}": (Generated(folder, n, size, "gpu-aware", context), n),
                  f"fused N={n}": (Generated(folder, n, size, "fused", context), n),
                  "fused N=1": (Generated(folder, 1, size, "fused", context), 1),
                  f"fused zero-copy N={n}": (
                      Generated(folder, n, size, "fused-zero-copy", context), n),
                  "fused zero-copy N=1": (
                      Generated(folder, 1, size, "fused-zero-copy", context), 1),
                  "cv2.flip": (Cv2Flip(image), 1),
                  **halide_chains(image, n)}
        visions = {"vision unfused": Vision(folder, "off"), "vision fused": Vision(folder, "auto")}
        samples: dict[str, list[float]] = {k: [] for k in [*chains, *visions]}
        for r in range(args.rounds):
            print(f"round {r + 1} of {args.rounds}", file=sys.stderr)
            for name, (chain, length) in chains.items():
                times, last = chain.run(args.frames)
                if not np.array_equal(last, expected_output(image, length)):
                    raise SystemExit(f"{name} gave a wrong image")
                samples[name] += times
            for name, vision in visions.items():
                samples[name] += vision.run(args.frames, context)
        kernels = {name: v.kernels(args.frames, context) for name, v in visions.items()}

    med = {k: float(np.median(v)) for k, v in samples.items()}
    print(f"fusion benchmark on {device}: {args.rounds} rounds of {args.frames} frames per "
          "variant, interleaved; ms per frame, median [q1-q3]")
    print(f"\nVerticalMirror chain, {size[0]}x{size[1]}:")
    for name in chains:
        print(f"  {name:22} {_stats(samples[name])}")
    one, unfused, fused = (med[k] for k in list(chains)[:3])
    vs_one, speedup = fused / one, unfused / fused
    print(f"  fused N={n} / unfused N=1 = {vs_one:.2f}x (target <= {TARGET_VS_ONE:.2f}x): "
          f"{'met' if vs_one <= TARGET_VS_ONE else 'NOT met'}")
    print(f"  unfused N={n} / fused N={n} = {speedup:.2f}x (target >= {TARGET_SPEEDUP:.2f}x): "
          f"{'met' if speedup >= TARGET_SPEEDUP else 'NOT met'}")
    fused_one = med["fused N=1"]
    length = fused / fused_one
    print(f"  fused N={n} / fused N=1 = {length:.2f}x (target <= {TARGET_LENGTH_FREE:.2f}x): "
          f"{'met' if length <= TARGET_LENGTH_FREE else 'NOT met'}")
    zc, zc_one = med[f"fused zero-copy N={n}"], med["fused zero-copy N=1"]
    print(f"  fused zero-copy N={n} / fused zero-copy N=1 = {zc / zc_one:.2f}x")
    for name, value in ((f"fused N={n}", fused), (f"fused zero-copy N={n}", zc)):
        if f"Halide N={n}" in med:
            vs = value / med[f"Halide N={n}"]
            print(f"  {name} / Halide N={n} = {vs:.2f}x (target <= {TARGET_VS_HALIDE:.1f}x): "
                  f"{'met' if vs <= TARGET_VS_HALIDE else 'NOT met'}")
        print(f"  {name} / cv2.flip = {value / med['cv2.flip']:.2f}x")
    print("\nvision system (models/vision_system.yaml):")
    for name, vision in visions.items():
        launches, device_ms = kernels[name]
        print(f"  {name:16} {_stats(samples[name])}; {launches:g} kernel launches a frame, "
              f"kernels {device_ms:.3f} ms of device time; peak device memory "
              f"{vision.plan.device_bytes:,} bytes")
    print(f"  unfused / fused = {med['vision unfused'] / med['vision fused']:.2f}x per frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
