"""Parallel queues against sequential execution, zero-copy against copying adapters.

    python benchmarks/parallel.py [--model models/parallel_branches.yaml] [--rounds 7]

Builds the model four ways (execution parallel|sequential x adapters copying|zero-copy),
then runs them interleaved, round after round in the same process and OpenCL context, so
that a noisy machine slows every variant alike.  Reported per variant:

- frame time: the time between two consecutive frames reaching the last standard
  component, in steady state (the first frames of a run, with program building, are left
  out);
- adapter time: the generated adapter classes alone, per frame of the model's sizes
  (two 480x640x3 uploads and one 480x1280x1 download): upload transfer() calls, a
  queue.finish(), then download transfer() (and unmap()) from a buffer the device has
  finished writing.  Inside a running program the download would also include waiting
  for the kernels, which is not adapter cost.

Medians over all frames of all rounds, with the interquartile range, and the ratios.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def build(model: Path, out: Path, execution: str, zero_copy: str):
    from gpucompgen.build import compile_model, write
    from gpucompgen.runtime import load_module

    folder = out / f"{execution}-{zero_copy}"
    result = compile_model(model, folder, execution=execution, zero_copy=zero_copy)
    write(result, folder)
    return load_module(folder / f"{result.system.model.name}.py",
                       f"bench_{execution}_{zero_copy}")


def sink_class(module):
    """The last standard component class (its execute marks the end of a frame)."""
    return module.VisionManager


def describe(values: list[float]) -> str:
    q1, med, q3 = np.percentile(values, [25, 50, 75])
    return f"{med * 1e3:8.2f} ms  (IQR {q1 * 1e3:.2f}-{q3 * 1e3:.2f}, n={len(values)})"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=ROOT / "models" / "parallel_branches.yaml")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--frames", type=int, default=12, help="frames per run")
    parser.add_argument("--skip", type=int, default=2, help="first frame periods left out")
    args = parser.parse_args(argv)

    from gpucompgen import runtime

    context = runtime.create_context()
    device = context.devices[0]
    variants = [(e, z) for e in ("parallel", "sequential") for z in ("off", "on")]
    frame_times: dict[tuple, list[float]] = defaultdict(list)
    adapter_times: dict[str, list[float]] = defaultdict(list)
    with tempfile.TemporaryDirectory(prefix="gpucompgen-bench-") as tmp:
        modules = {}
        for e, z in variants:
            modules[e, z] = build(args.model, Path(tmp), e, z)
        for e, z in variants:  # warm-up: build programs, fill PoCL's cache
            modules[e, z].run(frames=2, context=context)
        for r in range(args.rounds):
            order = variants if r % 2 == 0 else variants[::-1]
            for key in order:
                frame_times[key] += _run_with(modules[key], args.frames, context, args.skip)
            for z in ("off", "on") if r % 2 == 0 else ("on", "off"):
                adapter_times[z] += _adapters(modules["sequential", z], context, args.frames)
    print(f"model {args.model.name} on {device.name.strip()} "
          f"({device.max_compute_units} compute units), cpu count {os.cpu_count()}; "
          f"{args.rounds} rounds x {args.frames} frames, interleaved")
    print("\nframe time (median, interquartile range):")
    for key in variants:
        print(f"  {key[0]:10s} zero-copy {key[1]:3s}  {describe(frame_times[key])}")
    med = {k: statistics.median(v) for k, v in frame_times.items()}
    print(f"  sequential / parallel (copying):   "
          f"{med['sequential', 'off'] / med['parallel', 'off']:.3f}")
    print(f"  sequential / parallel (zero-copy): "
          f"{med['sequential', 'on'] / med['parallel', 'on']:.3f}")
    print(f"  copying / zero-copy (parallel):    "
          f"{med['parallel', 'off'] / med['parallel', 'on']:.3f}")
    print("\nadapter time per frame (2 uploads + 1 download, sequential classes):")
    for z in ("off", "on"):
        print(f"  {'zero-copy' if z == 'on' else 'copying':10s}  "
              f"{describe(adapter_times[z])}")
    am = {z: statistics.median(adapter_times[z]) for z in ("off", "on")}
    print(f"  copying / zero-copy: {am['off'] / am['on']:.2f}")
    return 0


def _run_with(module, frames, context, skip):
    """One run: steady-state frame periods (seconds)."""
    ends: list[float] = []
    cls = sink_class(module)
    original = cls.execute

    def timed(self, *args):
        result = original(self, *args)
        ends.append(time.perf_counter())
        return result

    cls.execute = timed
    try:
        module.run(frames=frames, context=context)
    finally:
        cls.execute = original
    return list(np.diff(ends)[skip:])


def _adapters(module, context, frames):
    """Per-frame seconds of the model's adapters alone (see the module docstring)."""
    import pyopencl as cl

    from gpucompgen.library.camera import Camera
    from gpucompgen.runtime import Size

    zero = hasattr(module, "ZeroCopyCpuToGpuAdapter")
    up_cls = module.ZeroCopyCpuToGpuAdapter if zero else module.CpuToGpuAdapter
    down_cls = module.ZeroCopyGpuToCpuAdapter if zero else module.GpuToCpuAdapter
    queue = cl.CommandQueue(context)
    cams = [Camera(seed=1), Camera(seed=2)]
    image, mask = Size(480, 640, 3), Size(480, 1280, 1)
    ups = [up_cls(context, queue) for _ in cams]
    for cam, up in zip(cams, ups):
        cam.initialize()
        up.initialize(image, np.uint8)
    down = down_cls(context, queue)
    down.initialize(mask, np.uint8)
    flags = cl.mem_flags.READ_WRITE | (cl.mem_flags.ALLOC_HOST_PTR if zero else 0)
    produced = cl.Buffer(context, flags, mask.nbytes(np.uint8))
    cl.enqueue_fill_buffer(queue, produced, np.uint8(255), 0, mask.nbytes(np.uint8)).wait()
    times = []
    for _ in range(frames):
        frames_in = [cam.execute() for cam in cams]
        t0 = time.perf_counter()
        for up, frame in zip(ups, frames_in):
            up.transfer(frame)
        queue.finish()
        view = down.transfer(produced)
        assert view[0, 0] == 255
        if zero:
            down.unmap()
        times.append(time.perf_counter() - t0)
    for a in ups + [down]:
        a.free_memory()
    return times


if __name__ == "__main__":
    sys.exit(main())
