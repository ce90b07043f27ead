"""Run a generated program and save every frame its GPU parts hand to the CPU (.npz).

    python tests/frames_of_program.py PROGRAM FRAMES OUT.npz

test_cuda.py runs the OpenCL and the CUDA build of a model each in a process of its own:
PoCL's LLVM and NVRTC's in one process can crash the second compiler (seen on an H100
machine: a segmentation fault in PoCL's program build after NVRTC had compiled).
Keys are 'class-part index-frame', parts numbered in the order they first run.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import numpy as np


def frames_of(program: Path, frames: int) -> dict[str, np.ndarray]:
    from gpucompgen.runtime import Monitor, load_module

    module = load_module(program, program.stem + "_frames")
    runtime = module.runtime
    seen: dict[str, np.ndarray] = {}
    order: list[int] = []
    counts: dict[str, int] = {}
    saved = {}
    for cls in (runtime.GpuToCpuAdapter, runtime.ZeroCopyGpuToCpuAdapter,
                runtime.KernelComponent):
        method = "transfer" if "Adapter" in cls.__name__ else "execute"
        original = getattr(cls, method)
        saved[cls] = (method, original)

        def wrapped(self, *args, _original=original, **kwargs):
            result = _original(self, *args, **kwargs)
            if id(self) not in order:
                order.append(id(self))
            for r in result if isinstance(result, tuple) else (result,):
                if isinstance(r, np.ndarray):
                    part = f"{type(self).__name__}-{order.index(id(self))}"
                    counts[part] = counts.get(part, 0) + 1
                    seen[f"{part}-{counts[part] - 1}"] = r.copy()
            return result

        setattr(cls, method, wrapped)
    with open(os.devnull, "w") as quiet, contextlib.redirect_stdout(quiet):
        module.run(frames=frames, monitor=Monitor(progress=False))
    return seen


if __name__ == "__main__":
    program, frames, out = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    seen = frames_of(program, frames)
    np.savez(out, **seen)
    with np.load(out) as back:  # read back here: a bad file names the process that wrote it
        for key, frame in seen.items():
            if not np.array_equal(back[key], frame):
                sys.exit(f"{out}: {key} differs when read back")
