"""The same generated programs on the OpenCL and the CUDA backend, side by side.

Builds each model in models/ (and the mirror chain unfused, zero-copy and with two frames
in flight) with --backend opencl and --backend cuda, runs each program for --frames
frames after a warm-up, and prints frames per second and milliseconds per frame for
both.  Run it on a machine with an NVIDIA GPU whose OpenCL (PYOPENCL_CTX) is NVIDIA's,
so both backends drive the same GPU:

    PYOPENCL_CTX=0 python benchmarks/backends.py --frames 200
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CASES = [
    ("mirror_chain", {}), ("mirror_chain", {"fusion": "off"}),
    ("mirror_chain", {"zero_copy": "on"}), ("mirror_chain", {"frames_in_flight": 2}),
    ("vision_system", {}), ("parallel_branches", {}), ("red_objects", {}),
]


def timed(program: Path, frames: int) -> float:
    """Seconds per frame of one program run (after a warm-up run of 5 frames), in a
    process of its own (PoCL's and NVRTC's LLVMs in one process can crash)."""
    code = (
        "import contextlib, os, sys, time\n"
        "from pathlib import Path\n"
        "from gpucompgen.runtime import Monitor, load_module\n"
        "m = load_module(Path(sys.argv[1]), 'program')\n"
        "with open(os.devnull, 'w') as q, contextlib.redirect_stdout(q):\n"
        "    m.run(frames=5, monitor=Monitor(progress=False))\n"
        "    t = time.perf_counter()\n"
        "    r = m.run(frames=int(sys.argv[2]), monitor=Monitor(progress=False))\n"
        "    t = time.perf_counter() - t\n"
        "print(t / max(r.frames, 1))\n")
    proc = subprocess.run([sys.executable, "-c", code, str(program), str(frames)],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        print(proc.stderr[-2000:], file=sys.stderr)
        return float("nan")
    return float(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    args = parser.parse_args(argv)
    from gpucompgen.build import compile_model, write

    rows = [("model", "options", "opencl ms/frame", "cuda ms/frame", "cuda/opencl")]
    with tempfile.TemporaryDirectory() as tmp:
        for model, options in CASES:
            times = []
            for backend in ("opencl", "cuda"):
                out = Path(tmp) / f"{model}-{backend}-{len(rows)}"
                write(compile_model(ROOT / "models" / f"{model}.yaml", out, backend=backend,
                                    **options), out)
                times.append(timed(out / f"{model}.py", args.frames))
            label = ",".join(f"{k}={v}" for k, v in options.items()) or "-"
            rows.append((model, label, f"{times[0] * 1e3:.3f}", f"{times[1] * 1e3:.3f}",
                         f"{times[1] / times[0]:.2f}"))
            print("  ".join(rows[-1]), flush=True)
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    print()
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
