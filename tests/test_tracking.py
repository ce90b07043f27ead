"""models/tracking.yaml: the colour-tracking example against the synthetic camera's ground
truth and OpenCV.

The checked-in program (generated/tracking.py) runs on PoCL and writes every annotated
frame to a folder (--output sink=DIR/). The camera draws its red buoys as disks whose
centres and radii it knows (Camera.ground_truth); the 3x3 opening removes each disk's
one-pixel tips at the top, bottom, left and right, so the box of a buoy of radius r at
(x, y) is (x - r + 1, y - r + 1, 2r - 1, 2r - 1), worked out by hand. Every frame must be
the camera's frame with exactly these boxes drawn (cv2.rectangle, the model's colour and
thickness) and nothing else, and the same as OpenCV's own pipeline (cvtColor, two inRange,
bitwise_or, morphologyEx, connectedComponentsWithStats, rectangle) written out here.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import yaml
from conftest import ROOT, require_opencl

from gpucompgen.library.camera import Camera

cv2 = pytest.importorskip("cv2")
Image = pytest.importorskip("PIL.Image")

MODEL = ROOT / "models" / "tracking.yaml"
FRAMES = 12


def _params(name: str) -> dict:
    return yaml.safe_load(MODEL.read_text())["components"][name]["params"]


def _camera() -> Camera:
    camera = Camera(**_params("camera"))
    camera.initialize()
    return camera


def _draw(frame: np.ndarray, boxes) -> np.ndarray:
    p = _params("boxes")
    out = frame.copy()
    for x, y, w, h in boxes:
        cv2.rectangle(out, (int(x), int(y)), (int(x + w - 1), int(y + h - 1)),
                      (p["red"], p["green"], p["blue"]), p["thickness"])
    return out


def truth_boxes(camera: Camera, frame: int) -> list[tuple[int, int, int, int]]:
    """Each buoy's disk, less the one-pixel tips the 3x3 opening removes."""
    return [(b.x - b.radius + 1, b.y - b.radius + 1, 2 * b.radius - 1, 2 * b.radius - 1)
            for b in camera.ground_truth(frame)]


def opencv_boxes(frame: np.ndarray) -> list[tuple[int, int, int, int]]:
    """The model's pipeline written with OpenCV's functions, largest region first."""
    hsv = cv2.cvtColor(frame, cv2.COLOR_RGB2HSV)
    masks = []
    for name in ("low_red", "high_red"):
        p = _params(name)
        masks.append(cv2.inRange(hsv, np.array([p[f"lowerb_{c}"] for c in range(3)]),
                                  np.array([p[f"upperb_{c}"] for c in range(3)])))
    clean = _params("clean")
    mask = cv2.morphologyEx(cv2.bitwise_or(*masks), clean["op"], cv2.getStructuringElement(
        clean["shape"], (clean["ksize"], clean["ksize"])), iterations=clean["iterations"])
    regions = _params("objs")
    _, _, stats, _ = cv2.connectedComponentsWithStats((mask > 0).astype(np.uint8),
                                                      connectivity=regions["connectivity"])
    kept = sorted((s for s in stats[1:] if s[4] >= regions["min_area"]), key=lambda s: -s[4])
    return [tuple(int(v) for v in s[:4]) for s in kept[:regions["max_components"]]]


def test_boxes_by_hand_equal_opencv_on_the_camera():
    """The hand-worked boxes are OpenCV's pipeline's, on many frames (the camera alone)."""
    camera = _camera()
    for frame in range(0, 200, 7):
        assert sorted(opencv_boxes(camera.render(frame))) == sorted(truth_boxes(camera, frame))


def test_generated_program_draws_the_ground_truth_boxes(tmp_path):
    require_opencl()
    out = tmp_path / "annotated"
    out.mkdir()
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "tracking.py"),
                           "--frames", str(FRAMES), "--output", f"sink={out}/"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    written = sorted(out.glob("*.png"))
    assert len(written) == FRAMES, written
    camera = _camera()
    for frame, path in enumerate(written):
        ours = np.asarray(Image.open(path))
        image = camera.render(frame)
        boxes = truth_boxes(camera, frame)
        assert len(boxes) == _params("camera")["buoys"]
        np.testing.assert_array_equal(ours, _draw(image, boxes), err_msg=f"frame {frame}")
        np.testing.assert_array_equal(ours, _draw(image, opencv_boxes(image)))
