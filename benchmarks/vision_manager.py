"""VisionManager per frame: the whole-mask scipy algorithm it had against find_sightings.

    python benchmarks/vision_manager.py [--frames 60] [--rounds 7]

Masks: the vision demo's, 480x1280 (cameras seed 1 and 2, 640x480 each, side by side,
through the ObjectDetector's rule with its default thresholds), made before timing.
Variants, both a VisionManager with the demo's parameters and no printing, timed around
execute() (the whole component: finding objects, the decision, its history):

- reference: objects found by tests/test_vision_manager.py's reference_sightings, the
  algorithm VisionManager had before issue 16 (label the whole mask, then sum_labels and
  center_of_mass over the whole mask);
- new: objects found by gpucompgen.library.vision_manager.find_sightings.

Rounds alternate the variants in one process, so a busy machine slows both alike. Prints
the median and interquartile range of ms per frame over all frames of all rounds, and the
ratio of the medians; checks first that both give the same decisions.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # the reference lives with its test


def demo_masks(frames: int) -> list[np.ndarray]:
    from gpucompgen.library.camera import Camera

    cameras = [Camera(seed=1, width=640, height=480), Camera(seed=2, width=640, height=480)]
    for cam in cameras:
        cam.initialize()
    masks = []
    for _ in range(frames):
        frame = np.hstack([cam.execute() for cam in cameras])
        r, g, b = (frame[..., i].astype(int) for i in range(3))
        masks.append(np.where((r >= 150) & (r - g >= 80) & (r - b >= 80), 255, 0)
                     .astype(np.uint8))
    return masks


def run(variant: str, masks: list[np.ndarray]) -> tuple[list[float], list]:
    """Seconds per execute() and the decisions, with the variant's object finder."""
    from test_vision_manager import reference_sightings

    from gpucompgen.library import vision_manager

    shipped = vision_manager.find_sightings
    if variant == "reference":
        vision_manager.find_sightings = reference_sightings
    try:
        manager = vision_manager.VisionManager(stop_radius=60, print_decisions=False)
        manager.initialize((*masks[0].shape, 1))
        times = []
        for mask in masks:
            start = time.perf_counter()
            manager.execute(mask)
            times.append(time.perf_counter() - start)
        manager.free_memory()
    finally:
        vision_manager.find_sightings = shipped
    return times, list(manager.history)


def describe(values: list[float]) -> str:
    q1, med, q3 = np.percentile(values, [25, 50, 75])
    return f"{med * 1e3:7.2f} ms/frame  (IQR {q1 * 1e3:.2f}-{q3 * 1e3:.2f}, n={len(values)})"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="demo frames per round")
    parser.add_argument("--rounds", type=int, default=7, help="rounds of each variant")
    args = parser.parse_args(argv)
    masks = demo_masks(args.frames)
    print(f"{len(masks)} masks of {masks[0].shape[0]}x{masks[0].shape[1]}, "
          f"{args.rounds} rounds", flush=True)
    _, old = run("reference", masks)
    _, new = run("new", masks)
    if [(d.action, d.target, d.sightings) for d in old] != \
            [(d.action, d.target, d.sightings) for d in new]:
        print("error: the variants' decisions differ", file=sys.stderr)
        return 1
    times: dict[str, list[float]] = {"reference": [], "new": []}
    for _ in range(args.rounds):
        for variant in times:
            times[variant] += run(variant, masks)[0]
    for variant, values in times.items():
        print(f"{variant:<10} {describe(values)}")
    ratio = statistics.median(times["reference"]) / statistics.median(times["new"])
    print(f"reference / new: {ratio:.1f}x  (same decisions on all {len(masks)} frames)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
