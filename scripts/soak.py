#!/usr/bin/env python3
"""Soak test of the generated vision system (not part of the default test suite: slow).

1. Stream FRAMES frames through one run of the vision system, once with copying adapters
   and once with zero-copy adapters (which wrap a new host buffer every frame); every
   SAMPLE frames record the process's resident memory (RSS) and the number of live OpenCL
   buffers. Pass: after warm-up (the first 10% of frames) RSS stays within --rss-slack MiB
   of its warm-up value; RSS fitted over the second half of the stream grows by less than
   --max-growth MiB per FRAMES frames (a slow leak that the slack would hide); the live
   buffer count never changes while streaming and is 0 after free.
2. CYCLES times in one process: build the system, load the program, run a few frames,
   free. Pass: the live buffer count is 0 after every cycle, and RSS after the last cycle
   is within --rss-slack MiB of RSS after the first few cycles.

Live buffers are counted by wrapping cl.Buffer in the generated program's namespace:
created minus released (explicitly, or when pyopencl frees them).

    .venv/bin/python scripts/soak.py                        # 5,000 frames at 640x480
    .venv/bin/python scripts/soak.py --width 320 --height 240

Exit code 0 when both parts pass, 1 otherwise.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import tempfile
import time
from pathlib import Path

import pyopencl as cl

from gpucompgen.build import compile_model, write
from gpucompgen.runtime import Monitor

ROOT = Path(__file__).resolve().parent.parent


def rss_mib() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


class BufferCounter:
    """cl.Buffer as the generated program sees it, counting live buffers."""

    def __init__(self):
        self.live = 0
        self.created = 0
        counter = self

        class CountedBuffer(cl.Buffer):
            def __init__(self, *args, **kwargs):
                super().__init__(*args, **kwargs)
                counter.live += 1
                counter.created += 1
                self._counted = True

            def release(self):
                if getattr(self, "_counted", False):
                    self._counted = False
                    counter.live -= 1
                super().release()

            def __del__(self):
                if getattr(self, "_counted", False):
                    self._counted = False
                    counter.live -= 1

        self.Buffer = CountedBuffer


class SamplingMonitor(Monitor):
    def __init__(self, every: int, counter: BufferCounter):
        super().__init__(progress=False, options={"quiet": True})
        self.every, self.counter = every, counter
        self.samples: list[tuple[int, float, int]] = []  # (frame, RSS MiB, live buffers)

    def frame_done(self, frames: int) -> None:
        super().frame_done(frames)
        if frames % self.every == 0:
            self.samples.append((frames, rss_mib(), self.counter.live))


def model_text(width: int, height: int) -> str:
    text = (ROOT / "models" / "vision_system.yaml").read_text(encoding="utf-8")
    return text.replace("width: 640, height: 480", f"width: {width}, height: {height}")


def load(program: Path, counter: BufferCounter):
    name = "soak_vision_system"
    spec = importlib.util.spec_from_file_location(name, program)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    module.cl = _with_buffer(counter)
    return module


def _with_buffer(counter: BufferCounter):
    """A stand-in for the pyopencl module whose Buffer is the counting one."""

    class ClWithCountedBuffer:
        Buffer = counter.Buffer

        def __getattr__(self, name):
            return getattr(cl, name)

    return ClWithCountedBuffer()


def slope(points: list[tuple[int, float]]) -> float:
    """Least-squares slope of y over x."""
    n = len(points)
    mx = sum(x for x, _ in points) / n
    my = sum(y for _, y in points) / n
    sxx = sum((x - mx) ** 2 for x, _ in points)
    return sum((x - mx) * (y - my) for x, y in points) / sxx if sxx else 0.0


def stream(work: Path, args, zero_copy: str) -> bool:
    model = work / "vision_system.yaml"
    model.write_text(model_text(args.width, args.height), encoding="utf-8")
    out = work / f"out-{zero_copy}"
    write(compile_model(model, out, zero_copy=zero_copy), out)
    counter = BufferCounter()
    module = load(out / "vision_system.py", counter)
    monitor = SamplingMonitor(args.sample, counter)
    start = time.perf_counter()
    result = module.run(frames=args.frames, monitor=monitor)
    seconds = time.perf_counter() - start
    warm = [s for s in monitor.samples if s[0] >= args.frames // 10]
    rss0 = warm[0][1]
    worst = max(abs(s[1] - rss0) for s in warm)
    buffers = {s[2] for s in monitor.samples}
    late = [(f, rss) for f, rss, _ in monitor.samples if f >= args.frames // 2]
    growth = slope(late) * args.frames if len(late) >= 3 else 0.0
    adapters = "zero-copy" if zero_copy == "on" else "copying"
    print(f"stream ({adapters} adapters): {result.frames} frames of 2 x "
          f"{args.width}x{args.height} in {seconds:.0f} s ({result.frames / seconds:.1f} "
          "frames/s)")
    print(f"  RSS after warm-up (frame {warm[0][0]}): {rss0:.1f} MiB; at the end "
          f"(frame {warm[-1][0]}): {warm[-1][1]:.1f} MiB; largest change {worst:.1f} MiB")
    print(f"  RSS trend over the second half: {growth:+.2f} MiB per {args.frames} frames "
          f"(limit {args.max_growth} MiB)")
    print(f"  live OpenCL buffers while streaming: {sorted(buffers)}; after free: "
          f"{counter.live} (created {counter.created})")
    for frame, rss, live in monitor.samples[:: max(1, len(monitor.samples) // 10)]:
        print(f"    frame {frame:6d}: RSS {rss:8.1f} MiB, live buffers {live}")
    return (worst <= args.rss_slack and growth <= args.max_growth and len(buffers) == 1
            and counter.live == 0)


def cycles(work: Path, args) -> bool:
    model = work / "vision_system.yaml"
    model.write_text(model_text(args.width, args.height), encoding="utf-8")
    after = []
    leaked = []
    for i in range(args.cycles):
        out = work / "cycles"
        write(compile_model(model, out), out)
        counter = BufferCounter()
        module = load(out / "vision_system.py", counter)
        result = module.run(frames=args.cycle_frames, monitor=Monitor(options={"quiet": True}))
        assert result.frames == args.cycle_frames
        del module, result
        if counter.live:
            leaked.append((i, counter.live))
        after.append(rss_mib())
    warm = min(5, len(after))
    base = after[warm - 1]
    print(f"cycles: {args.cycles} x (build, load, run {args.cycle_frames} frames, free)")
    print(f"  RSS after cycle {warm}: {base:.1f} MiB; after cycle {args.cycles}: {after[-1]:.1f} "
          f"MiB; change {after[-1] - base:+.1f} MiB")
    print(f"  cycles that left live buffers: {leaked or 'none'}")
    return not leaked and after[-1] - base <= args.rss_slack


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=5000)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--sample", type=int, default=100, help="sample every N frames")
    p.add_argument("--cycles", type=int, default=50)
    p.add_argument("--cycle-frames", type=int, default=5)
    p.add_argument("--rss-slack", type=float, default=8.0, metavar="MIB")
    p.add_argument("--max-growth", type=float, default=1.0, metavar="MIB",
                   help="largest RSS growth per FRAMES frames, fitted over the second half")
    p.add_argument("--adapters", choices=("both", "copying", "zero-copy"), default="both")
    args = p.parse_args()
    forms = {"both": ("off", "on"), "copying": ("off",), "zero-copy": ("on",)}[args.adapters]
    with tempfile.TemporaryDirectory(prefix="gpucompgen-soak-") as tmp:
        streamed = [stream(Path(tmp), args, zero_copy) for zero_copy in forms]  # run all
        ok_stream = all(streamed)
        ok_cycles = cycles(Path(tmp), args)
    print("PASS" if ok_stream and ok_cycles else "FAIL")
    return 0 if ok_stream and ok_cycles else 1


if __name__ == "__main__":
    sys.exit(main())
