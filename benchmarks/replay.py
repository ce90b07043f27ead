"""gpucompgen replay: how long a fleet of short recordings takes, locally and on Ray.

    python benchmarks/replay.py [--recordings 100] [--frames 10] [--slots 2] [--no-ray]

Makes N short recordings (image folders of F frames, 320x240, a red disc moving), replays
the red-buoy model (Camera -> ObjectDetector -> VisionManager) over them with the local
engine and with the Ray engine (a local Ray instance with --slots CPUs), one after the
other, and prints the wall time of each, the time per recording and the Ray engine's
overhead against local. Both runs' summaries are checked identical but for timings.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import cv2
import numpy as np

H, W = 240, 320


def make_recordings(root: Path, n: int, frames: int) -> list[Path]:
    recs = []
    for r in range(n):
        folder = root / f"rec{r:04d}"
        folder.mkdir(parents=True)
        for f in range(frames):
            frame = np.full((H, W, 3), 25, np.uint8)
            cv2.circle(frame, (20 + (7 * f + 11 * r) % (W - 40), 60 + r % 100), 12,
                       (30, 30, 240), -1)  # BGR: red
            cv2.imwrite(str(folder / f"{f:04d}.png"), frame)
        recs.append(folder)
    return recs


def replay(model: Path, recs: list[Path], out: Path, *extra: str) -> float:
    started = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "replay", str(model),
                           *map(str, recs), "--out", str(out), *extra],
                          capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - started
    if proc.returncode != 0:
        sys.exit(f"replay failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return seconds


def comparable(out: Path) -> dict:
    run = json.loads((out / "summary.json").read_text())
    found = {}
    for row in run["recordings"]:
        s = json.loads((out / row["folder"] / "summary.json").read_text())
        found[row["recording"]] = {k: v for k, v in s.items() if k not in
                                   ("seconds", "frames_per_second", "latency_median_seconds",
                                    "attempts", "job")}
    return found


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--recordings", type=int, default=100)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--slots", type=int, default=2)
    ap.add_argument("--no-ray", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        model = root / "model.yaml"
        model.write_text(textwrap.dedent(f"""\
            system: fleet
            components:
              camera: {{type: Camera, params: {{width: {W}, height: {H}}}}}
              detector: {{type: ObjectDetector}}
              manager: {{type: VisionManager, params: {{min_area: 5, print_decisions: false}}}}
            connections:
              - camera.image -> detector.frame
              - detector.mask -> manager.mask
            """), encoding="utf-8")
        recs = make_recordings(root / "recs", args.recordings, args.frames)
        print(f"{args.recordings} recordings of {args.frames} frames ({W}x{H}), "
              f"--slots {args.slots}, {os.cpu_count()} cores, load "
              f"{os.getloadavg()[0]:.1f}, device {os.environ.get('PYOPENCL_CTX', 'default')}")
        local = replay(model, recs, root / "local", "--slots", str(args.slots))
        print(f"local: {local:7.1f} s  ({local / args.recordings * 1000:.0f} ms a recording)")
        if args.no_ray:
            return
        ray = replay(model, recs, root / "ray", "--slots", str(args.slots), "--engine", "ray")
        print(f"ray:   {ray:7.1f} s  ({ray / args.recordings * 1000:.0f} ms a recording)")
        print(f"ray / local: {ray / local:.2f}x (Ray's start and per-task cost)")
        same = comparable(root / "local") == comparable(root / "ray")
        print(f"summaries identical but for timings: {same}")
        if not same:
            sys.exit(1)


if __name__ == "__main__":
    main()
