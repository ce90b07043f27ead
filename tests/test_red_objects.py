"""models/red_objects.yaml: red objects in real photographs, checked against OpenCV.

The checked-in program (generated/red_objects.py) runs on PoCL over models/photos/ and
saves every mask and annotated photo; each mask must be byte for byte what OpenCV's own
pipeline makes of the same decoded photo: cvtColor(RGB2HSV), inRange, erode and dilate
with a 3x3 rectangle. The MaskWriter's object finding is checked on hand-drawn masks.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import yaml
from conftest import ROOT, require_opencl

from gpucompgen.library.mask_writer import Box, annotate, find_objects

cv2 = pytest.importorskip("cv2")
Image = pytest.importorskip("PIL.Image")

MODEL = ROOT / "models" / "red_objects.yaml"
PHOTOS = sorted((ROOT / "models" / "photos").glob("*.jpg"))


def opencv_mask(photo: np.ndarray, params: dict) -> np.ndarray:
    lower = np.array([params[f"lowerb_{c}"] for c in range(3)])
    upper = np.array([params[f"upperb_{c}"] for c in range(3)])
    mask = cv2.inRange(cv2.cvtColor(photo, cv2.COLOR_RGB2HSV), lower, upper)
    square = np.ones((3, 3), np.uint8)
    return cv2.dilate(cv2.erode(mask, square), square)


def test_masks_of_the_photographs_match_opencv(tmp_path):
    require_opencl()
    assert len(PHOTOS) == 3
    out = tmp_path / "red-out"
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "red_objects.py"),
                           "--save-images", str(out)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) == 3 and "processed 3 frame(s)" in proc.stderr
    params = yaml.safe_load(MODEL.read_text())["components"]["red"]["params"]
    min_area = yaml.safe_load(MODEL.read_text())["components"]["writer"]["params"]["min_area"]
    for frame, path in enumerate(PHOTOS):
        with Image.open(path) as im:
            photo = np.asarray(im.convert("RGB"))
        expected = opencv_mask(photo, params)
        mask = np.asarray(Image.open(out / f"mask_{frame:06d}.png"))
        np.testing.assert_array_equal(mask, expected, err_msg=path.name)
        annotated = np.asarray(Image.open(out / f"annotated_{frame:06d}.png"))
        boxes = find_objects(expected, min_area)
        np.testing.assert_array_equal(annotated, annotate(photo, expected, boxes))
        assert lines[frame].startswith(f"frame {frame}: {len(boxes)} object")
    # what the photographs show: red bits of the astronaut's flag and patch, the coffee's
    # red cup and saucer (two large objects), nothing red on the cat
    counts = [int(line.split(":")[1].split()[0]) for line in lines]
    assert counts[1] == 2 and counts[2] == 0 and counts[0] >= 1


def test_find_objects_on_hand_drawn_masks():
    mask = np.zeros((10, 12), np.uint8)
    mask[1:4, 2:6] = 255  # 12 px
    mask[6, 8] = mask[7, 9] = mask[8, 10] = 255  # a diagonal: one 8-connected object
    mask[9, 0] = 255  # one pixel
    assert find_objects(mask, 1) == [Box(2, 1, 4, 3, 12), Box(8, 6, 3, 3, 3), Box(0, 9, 1, 1, 1)]
    assert find_objects(mask, 3) == [Box(2, 1, 4, 3, 12), Box(8, 6, 3, 3, 3)]
    assert find_objects(np.zeros((4, 4), np.uint8), 1) == []


def test_annotate_tints_the_mask_and_draws_boxes():
    image = np.full((6, 7, 3), 100, np.uint8)
    mask = np.zeros((6, 7), np.uint8)
    mask[3, 3] = 255
    out = annotate(image, mask, [Box(1, 1, 5, 4, 1)])
    assert tuple(out[0, 0]) == (100, 100, 100)  # outside: unchanged
    assert tuple(out[1, 1]) == (0, 255, 0) and tuple(out[4, 5]) == (0, 255, 0)  # the box
    assert tuple(out[3, 3]) == (0, 255, 0)  # inside the 2-pixel border of a small box
    big = annotate(np.full((20, 20, 3), 100, np.uint8), np.pad(mask, ((0, 14), (0, 13))),
                   [Box(0, 0, 20, 20, 1)])
    assert tuple(big[3, 3]) == (177, 50, 177)  # tinted half-way to magenta
