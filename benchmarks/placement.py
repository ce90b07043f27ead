"""Placement of flexible components: `tune` + `auto` against all-GPU and all-CPU.

    python benchmarks/placement.py [--model models/vision_system.yaml] [--rounds 5]
                                   [--frames 40] [--update-profile]

Runs `gpucompgen tune` on the model (on the OpenCL device programs use, PYOPENCL_CTX),
writes the profile beside a copy of the model (or, with --update-profile, to the path the
model names in platform.profile, to check in), then builds the model three ways — every
flexible component on the GPU, every one on the CPU, and `auto` from the fresh profile —
for the device it runs on, and runs them interleaved, round after round in one process,
so that a noisy machine slows every variant alike.

Reported per variant: where `auto` put each component, the cost model's estimate of a
frame, and the measured frame time (between two consecutive frames reaching the last
standard component, steady state: each run's first 5 frames left out) as the median over
all rounds, with frames per second.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

WARMUP = 5


def build(model: Path, out: Path, tag: str, places: dict[str, str]):
    from gpucompgen.build import compile_model, write
    from gpucompgen.runtime import load_module

    folder = out / tag
    result = compile_model(model, folder, device="auto", places=places)
    write(result, folder)
    module = load_module(folder / f"{result.system.model.name}.py", f"bench_place_{tag}")
    return result.system, module


def run_timed(module, frames: int) -> list[float]:
    """Frame times: between consecutive VisionManager.execute calls, after WARMUP."""
    from gpucompgen import runtime

    stamps: list[float] = []
    original = module.VisionManager.execute

    def stamp(self, mask):
        result = original(self, mask)
        stamps.append(time.perf_counter())
        return result

    module.VisionManager.execute = stamp
    try:
        module.run(frames=frames,
                   monitor=runtime.Monitor(progress=False, options={"quiet": True}))
    finally:
        module.VisionManager.execute = original
    return list(np.diff(stamps[WARMUP:]))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=ROOT / "models" / "vision_system.yaml")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--frames", type=int, default=40, help="frames per run (default 40)")
    parser.add_argument("--tune-frames", type=int, default=20)
    parser.add_argument("--update-profile", action="store_true",
                        help="write the profile where the model's platform.profile says")
    args = parser.parse_args(argv)

    from gpucompgen.model import load_system
    from gpucompgen.tune import default_profile_path, tune

    model = load_system(args.model)
    flexible = [n for n, i in model.components.items() if i.type.flexible]
    with tempfile.TemporaryDirectory(prefix="bench-placement-") as tmp:
        out = Path(tmp)
        copy = out / args.model.name
        shutil.copy(args.model, copy)
        text, rows = tune(args.model, args.tune_frames, str(args.model))
        target = default_profile_path(args.model, model) if args.update_profile else \
            default_profile_path(copy, load_system(copy))
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")
        if args.update_profile:  # the copy reads the same profile
            copy_profile = default_profile_path(copy, load_system(copy))
            copy_profile.parent.mkdir(parents=True, exist_ok=True)
            copy_profile.write_text(text, encoding="utf-8")
        print(f"profile ({'wrote ' + str(target) if args.update_profile else 'not kept'}):")
        print(f"  {'component':<10} {'CPU ms':>8} {'GPU ms':>8}")
        for name, _, _, cpu_us, gpu_us in rows:
            print(f"  {name:<10} {cpu_us / 1e3:8.3f} {gpu_us / 1e3:8.3f}")
        variants = {"all-GPU": dict.fromkeys(flexible, "gpu"),
                    "all-CPU": dict.fromkeys(flexible, "cpu"),
                    "auto": dict.fromkeys(flexible, "auto")}
        built = {tag: build(copy, out, tag.replace("-", "_"), places)
                 for tag, places in variants.items()}
        times: dict[str, list[float]] = {tag: [] for tag in variants}
        for _ in range(args.rounds):
            for tag, (_, module) in built.items():
                times[tag] += run_timed(module, args.frames)
        system = built["auto"][0]
        device = system.device.name
        print(f"\n{args.model.name} on '{device}', {args.rounds} rounds x "
              f"{args.frames - WARMUP - 1} frames, zero-copy {'on' if system.zero_copy else 'off'}")
        print(f"{'variant':<8} {'placement':<40} {'est. ms':>8} {'ms/frame':>9} "
              f"{'frames/s':>9}")
        auto_est = system.placement.estimate_s
        ests = {"all-GPU": system.placement.all_gpu_s, "all-CPU": system.placement.all_cpu_s,
                "auto": auto_est}
        for tag, (sys_, _) in built.items():
            where = ", ".join(f"{n} {sys_.components[n].placement.upper()}" for n in flexible)
            med = float(np.median(times[tag]))
            print(f"{tag:<8} {where:<40} {ests[tag] * 1e3:8.3f} {med * 1e3:9.2f} "
                  f"{1 / med:9.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
