"""Host cost of one kernel launch: what KernelComponent.execute() costs the CPU.

    python benchmarks/launch_cost.py [--launches 3000] [--rounds 5]

The vision system's ImageMerger (three buffers and the tile: its kernel, generated from
its form, has its sizes as constants), generated and
configured as the program does it, is launched over and over on a small frame (so the
device's work is negligible: what is timed is the host's).  Three ways, interleaved round
after round:

- ``set every launch``: every argument set before every launch, as execute() did before
  (kernel.set_args with the input buffers, the output buffer and the scalars);
- ``set once per set``: execute() as it is now: each buffer set has its own kernel object
  whose arguments are set the first time and only again when an input buffer changes
  (never, in a generated program: producers keep their buffers);
- ``bare enqueue``: pyopencl's enqueue_nd_range_kernel on a kernel set up once, the floor.

Microseconds per launch (host wall time, median over rounds), queue.finish() every 100
launches included.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def merger(tmp: Path):
    import numpy as np

    from gpucompgen import runtime
    from gpucompgen.build import compile_model, write
    from gpucompgen.kernelgen.fused import group_kernel, group_of_one
    from gpucompgen.model import library_types

    out = tmp / "vision"
    # unfused: the ImageMerger component alone, not the merger_detector group
    write(compile_model(ROOT / "models" / "vision_system.yaml", out, fusion="off"), out)
    module = runtime.load_module(out / "vision_system.py", "launch_cost_vision")
    context = runtime.create_context()
    queue = runtime.create_queue(context, False)
    # the kernel a lone merger runs, generated for 16x16 frames (its sizes are constants)
    group = group_of_one(library_types()["ImageMerger"], {},
                         {"left": (16, 16), "right": (16, 16), "merged": (16, 32)},
                         name=module.ImageMerger.function)
    source = tmp / "merger.cl"
    source.write_text(group_kernel(group, "launch cost"), encoding="utf-8")
    program = runtime.build_program(context, source, "merger")
    m = module.ImageMerger(context, queue, program)
    size = runtime.Size(16, 16, 3)
    m.initialize(size, size)
    m.config_gpu(tile=16, local_size=(16, 16, 1), global_size=(16, 16, 1),
                 settings_source="preferred", arguments=["left", "right", "merged",
                                                         np.int32(16)])
    import pyopencl as cl

    left = cl.Buffer(context, cl.mem_flags.READ_ONLY, size.nbytes(np.uint8))
    right = cl.Buffer(context, cl.mem_flags.READ_ONLY, size.nbytes(np.uint8))
    return m, queue, left, right


def time_launches(launch, queue, n: int) -> float:
    start = time.perf_counter()
    for i in range(n):
        launch()
        if i % 100 == 99:
            queue.finish()
    queue.finish()
    return (time.perf_counter() - start) / n * 1e6


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--launches", type=int, default=3000)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    import pyopencl as cl

    with tempfile.TemporaryDirectory(prefix="launch-cost-") as tmp:
        m, queue, left, right = merger(Path(tmp))

        def every():
            m._bound[0] = None  # forget what was set: set_args before every launch
            m.execute(left, right)

        def once():
            m.execute(left, right)

        kernel = m.kernels[0]
        m.execute(left, right)

        def bare():
            cl.enqueue_nd_range_kernel(queue, kernel, m.global_size, m.local_size)

        ways = {"set every launch": every, "set once per set": once, "bare enqueue": bare}
        times: dict[str, list[float]] = {k: [] for k in ways}
        for _ in range(args.rounds):
            for name, launch in ways.items():
                times[name].append(time_launches(launch, queue, args.launches))
        m.free_memory()
    print(f"host time per launch of ImageMerger (4 arguments), median of {args.rounds} "
          f"rounds of {args.launches:,} launches:")
    base = statistics.median(times["set every launch"])
    for name, values in times.items():
        med = statistics.median(values)
        print(f"  {name:<18} {med:8.1f} us  ({med / base:.2f} of set every launch)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
