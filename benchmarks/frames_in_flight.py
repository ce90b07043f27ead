"""Frames in flight: N = 1, 2, 3 on the vision system, in one run.

    python benchmarks/frames_in_flight.py [--model models/vision_system.yaml] [--rounds 3]
        [--frames 150] [--n 1 2 3] [--device auto] [--zero-copy auto] [--staging auto]
        [--json FILE]

Builds the model once per N (`--frames-in-flight N`) for the device programs use (as
`gpucompgen run` does: `--device auto`; on PoCL that means zero-copy adapters), then runs the programs as a user
does (`python vision_system.py --frames F -q --stats-json ...`, each its own process),
interleaved round after round so that a noisy machine slows every N alike.  Per N:
frames per second (frames / wall time of the run, building kernels included, median over
rounds) and the per-frame latency (start of the frame's sources to end of its last sink)
median and 95th percentile over every frame of every round, from --stats-json.

The machine's load is printed with the results: on a machine shared with other jobs the
ratios between N are what to read, not the absolute figures.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def build(model: Path, out: Path, n: int, device: str, zero_copy: str, staging: str) -> Path:
    from gpucompgen.build import compile_model, write

    result = compile_model(model, out, device=device, zero_copy=zero_copy,
                           frames_in_flight=n, staging=staging)
    write(result, out)
    return out / f"{result.system.model.name}.py"


def run_once(program: Path, frames: int, stats: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(program), "--frames", str(frames), "-q",
                           "--stats-json", str(stats)], capture_output=True, text=True,
                          env=env, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"{program} failed: {proc.stderr.strip()}")
    return json.loads(stats.read_text())


def percentile(values: list[float], q: float) -> float:
    from gpucompgen.runtime.monitor import percentile as p

    return p(values, q)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=ROOT / "models" / "vision_system.yaml")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=150, help="frames per run")
    parser.add_argument("--skip", type=int, default=10,
                        help="first frames of each run left out of the latencies")
    parser.add_argument("--n", type=int, nargs="+", default=[1, 2, 3],
                        help="frames in flight to compare")
    parser.add_argument("--device", default="auto",
                        help="device facts to plan for (default: the device programs use)")
    parser.add_argument("--zero-copy", default="auto", choices=("auto", "on", "off"))
    parser.add_argument("--staging", default="auto", choices=("auto", "pinned", "pageable"))
    parser.add_argument("--json", type=Path, help="also write the results as JSON here")
    args = parser.parse_args(argv)
    fps: dict[int, list[float]] = {n: [] for n in args.n}
    latency: dict[int, list[float]] = {n: [] for n in args.n}
    with tempfile.TemporaryDirectory(prefix="flight-bench-") as tmp:
        programs = {n: build(args.model, Path(tmp) / f"n{n}", n, args.device, args.zero_copy,
                             args.staging) for n in args.n}
        for r in range(args.rounds):
            for n in args.n:
                doc = run_once(programs[n], args.frames, Path(tmp) / f"stats-{n}-{r}.json")
                fps[n].append(doc["frames_per_second"])
                latency[n] += doc["frame_seconds"][args.skip:]
                print(f"round {r + 1}, N={n}: {doc['frames_per_second']:.1f} frames/s",
                      file=sys.stderr)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{args.model.name}: {args.frames} frames a run, {args.rounds} rounds interleaved, "
          f"device {args.device}, zero-copy {args.zero_copy}, staging {args.staging}; "
          f"{os.cpu_count()} CPUs, "
          f"load average {load:.1f}")
    print(f"{'N':>3}  {'frames/s':>9}  {'vs N=1':>7}  {'latency median':>15}  {'p95':>9}")
    base = statistics.median(fps[args.n[0]])
    results = {}
    for n in args.n:
        rate = statistics.median(fps[n])
        med, p95 = percentile(latency[n], 50), percentile(latency[n], 95)
        results[n] = {"frames_per_second": rate, "rounds": fps[n],
                      "latency_median_seconds": med, "latency_p95_seconds": p95}
        print(f"{n:>3}  {rate:>9.1f}  {rate / base:>6.2f}x  {med * 1000:>12.1f} ms  "
              f"{p95 * 1000:>6.1f} ms")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
