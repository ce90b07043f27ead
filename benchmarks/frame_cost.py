"""The fixed cost of a frame in a generated program: a chain of N trivial components.

    python benchmarks/frame_cost.py [--lengths 1,10,25] [--frames 300] [--rounds 7]

StillImage (an 8x8 frame) -> N x VerticalMirror -> FrameSink, built three ways: every
mirror on the GPU device unfused (--fusion off: N kernel launches a frame), fused (one
launch), and every mirror on the CPU (platform.placement: cpu: N calls of the CPU form).
An 8x8 frame makes the device's and cv2's work negligible, so what is timed is the
program's own work per frame: the loop, the checks of user frames, the adapters, the
launches. The time of a frame is the time between two frames reaching the loop's end
(the monitor's frame_done), so building and initializing are not counted; rounds are
interleaved. Prints microseconds a frame (median and IQR over every frame of every round)
and per component, with the machine and its load.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SIZE = 8


def model_text(n: int, placement: str) -> str:
    """gpucompgen bench's chain of n mirrors on SIZE x SIZE frames, placed as asked."""
    from gpucompgen.bench import chain_model

    return chain_model(n, SIZE, SIZE).replace(
        "components:", f"platform:\n  placement: {placement}\ncomponents:", 1)


def build(tmp: Path, n: int, placement: str, fusion: str):
    from gpucompgen import runtime
    from gpucompgen.build import compile_model, write

    name = f"cost_{placement}_{n}_{fusion}"
    path = tmp / f"{name}.yaml"
    path.write_text(model_text(n, placement))
    out = tmp / name
    write(compile_model(path, out, fusion=fusion), out)
    return runtime.load_module(out / f"mirror_chain_{n}.py", name)


def per_frame(module, context, frames: int) -> list[float]:
    """Seconds between consecutive frames' ends, the first 10 frames left out (warm-up)."""
    from gpucompgen import runtime

    stamps = []

    class Clock(runtime.Monitor):
        def frame_done(self, done: int) -> None:
            stamps.append(time.perf_counter())
            super().frame_done(done)

    module.run(frames=frames + 10, context=context, monitor=Clock(progress=False))
    return [b - a for a, b in itertools.pairwise(stamps[10:])]


def main(argv=None) -> int:
    from gpucompgen import runtime

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--lengths", default="1,10,25")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    lengths = [int(v) for v in args.lengths.split(",")]
    context = runtime.create_context()
    variants = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in lengths:
            variants[(n, "GPU unfused")] = build(Path(tmp), n, "gpu", "off")
            variants[(n, "GPU fused")] = build(Path(tmp), n, "gpu", "auto")
            variants[(n, "CPU")] = build(Path(tmp), n, "cpu", "off")
        load = os.getloadavg()
        print(f"{os.uname().nodename}: {os.cpu_count()} cores, load average "
              f"{' '.join(f'{v:.2f}' for v in load)}; device "
              f"{context.devices[0].name.strip()} ({context.devices[0].platform.name.strip()})"
              f"; {SIZE}x{SIZE} frames, {args.frames} frames x {args.rounds} rounds")
        samples = {k: [] for k in variants}
        for _ in range(args.rounds):
            for key, module in variants.items():
                samples[key] += [1e6 * v for v in per_frame(module, context, args.frames)]
    print(f"{'N':>3} {'variant':12} {'us/frame':>9} {'IQR':>13} {'us/component':>13}")
    for (n, variant), values in samples.items():
        q = statistics.quantiles(values, n=4)
        med = statistics.median(values)
        print(f"{n:3} {variant:12} {med:9.1f} {q[0]:6.1f}-{q[2]:<6.1f} {med / n:13.1f}")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
