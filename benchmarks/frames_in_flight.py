"""Frames in flight: N = 1, 2, 3 on the vision system, zero-copy on and off, in one run.

    python benchmarks/frames_in_flight.py [--model models/vision_system.yaml] [--rounds 3]
        [--frames 150] [--n 1 2 3] [--zero-copy on off] [--device auto] [--staging auto]
        [--json FILE]

Builds the model once per (zero-copy, N) (`--zero-copy Z --frames-in-flight N`) for the
device programs use (as `gpucompgen run` does: `--device auto`), then runs the programs as
a user does (`python vision_system.py --frames F -q --stats-json ...`, each its own
process), interleaved round after round so that a noisy machine slows every variant alike.
Per variant: frames per second (frames / wall time of the run, building kernels included,
median over rounds), the per-frame latency (start of the frame's sources to end of its
last sink) median and 95th percentile over every frame of every round, from --stats-json,
and the processor time the run took (user + system, of the process and its threads) per
frame and per second of wall time ("cores": how many cores it kept busy on average).

The machine's load is printed with the results: on a machine shared with other jobs the
ratios between N are what to read, not the absolute figures; "cores" says how much of the
machine a run got.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
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


def run_once(program: Path, frames: int, stats: Path) -> tuple[dict, float]:
    """The run's --stats-json, and the processor seconds (user + system) it took."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run([sys.executable, str(program), "--frames", str(frames), "-q",
                           "--stats-json", str(stats)], capture_output=True, text=True,
                          env=env, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{program} failed: {proc.stderr.strip()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads(stats.read_text()), cpu


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
    parser.add_argument("--zero-copy", nargs="+", default=["on", "off"],
                        choices=("auto", "on", "off"), help="zero-copy settings to compare")
    parser.add_argument("--staging", default="auto", choices=("auto", "pinned", "pageable"))
    parser.add_argument("--json", type=Path, help="also write the results as JSON here")
    args = parser.parse_args(argv)
    variants = [(z, n) for z in args.zero_copy for n in args.n]
    fps: dict = {v: [] for v in variants}
    latency: dict = {v: [] for v in variants}
    cpu: dict = {v: [] for v in variants}  # processor seconds per frame, per round
    cores: dict = {v: [] for v in variants}
    with tempfile.TemporaryDirectory(prefix="flight-bench-") as tmp:
        programs = {(z, n): build(args.model, Path(tmp) / f"{z}-n{n}", n, args.device, z,
                                  args.staging) for z, n in variants}
        for r in range(args.rounds):
            for v in variants:
                doc, seconds = run_once(programs[v], args.frames,
                                        Path(tmp) / f"stats-{v[0]}-{v[1]}-{r}.json")
                fps[v].append(doc["frames_per_second"])
                latency[v] += doc["frame_seconds"][args.skip:]
                cpu[v].append(seconds / doc["frames"])
                cores[v].append(seconds / doc["wall_seconds"])
                print(f"round {r + 1}, zero-copy {v[0]}, N={v[1]}: "
                      f"{doc['frames_per_second']:.1f} frames/s", file=sys.stderr)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{args.model.name}: {args.frames} frames a run, {args.rounds} rounds interleaved, "
          f"device {args.device}, staging {args.staging}; {os.cpu_count()} CPUs, "
          f"load average {load:.1f}")
    print(f"{'zero-copy':>9}  {'N':>2}  {'frames/s':>8}  {'vs N=1':>6}  "
          f"{'latency median':>14}  {'p95':>8}  {'CPU ms/frame':>12}  {'cores':>5}")
    results = []
    for z in args.zero_copy:
        base = statistics.median(fps[z, args.n[0]])
        for n in args.n:
            v = (z, n)
            rate = statistics.median(fps[v])
            med, p95 = percentile(latency[v], 50), percentile(latency[v], 95)
            per_frame, busy = statistics.median(cpu[v]), statistics.median(cores[v])
            results.append({"zero_copy": z, "frames_in_flight": n, "frames_per_second": rate,
                            "rounds": fps[v], "latency_median_seconds": med,
                            "latency_p95_seconds": p95, "cpu_seconds_per_frame": per_frame,
                            "cores": busy})
            print(f"{z:>9}  {n:>2}  {rate:>8.1f}  {rate / base:>5.2f}x  "
                  f"{med * 1000:>11.1f} ms  {p95 * 1000:>5.1f} ms  {per_frame * 1000:>12.2f}  "
                  f"{busy:>5.2f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
