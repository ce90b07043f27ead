"""VisionManager's object finder against the algorithm it replaced (issue 16).

The reference below is the VisionManager of before: scipy labels the whole mask, then
sum_labels and center_of_mass scan the whole mask once per object. It is slow (about
47 ms a 480x1280 frame in the demo) but plainly right; the library's find_sightings must
give exactly the same sightings (positions, areas, radii, order) and the same decisions,
on the synthetic camera's frames and on random masks. benchmarks/vision_manager.py times
the two side by side.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy import ndimage

from gpucompgen.library import vision_manager
from gpucompgen.library.camera import Camera
from gpucompgen.library.vision_manager import Sighting, VisionManager, find_sightings


# -- the reference: VisionManager.execute before issue 16, unchanged -----------------------
def reference_sightings(mask: np.ndarray, min_area: int) -> list[Sighting]:
    labels, count = ndimage.label(mask > 0)
    sightings = []
    if count:
        index = np.arange(1, count + 1)
        areas = ndimage.sum_labels(np.ones_like(labels), labels, index)
        centres = ndimage.center_of_mass(mask > 0, labels, index)
        boxes = ndimage.find_objects(labels)
        for area, (cy, cx), (rows, cols) in zip(areas, centres, boxes):
            if area >= min_area:
                radius = (rows.stop - rows.start + cols.stop - cols.start - 2) / 4
                sightings.append(Sighting(float(cx), float(cy), int(area), radius))
    sightings.sort(key=lambda s: (s.x, s.y))
    return sightings


def reference_decide(sightings, width, stop_radius):
    if not sightings:
        return "search", None
    target = max(sightings, key=lambda s: (s.area, -s.x))
    if target.radius >= stop_radius:
        return "stop", target
    if target.x < width / 3:
        return "turn_left", target
    if target.x >= 2 * width / 3:
        return "turn_right", target
    return "forward", target


def assert_same(mask: np.ndarray, min_area: int, stop_radius: int = 60) -> list[Sighting]:
    """find_sightings and a VisionManager both agree exactly with the reference."""
    expected = reference_sightings(mask, min_area)
    got = find_sightings(mask, min_area)
    # Sighting equality compares the floats exactly; types too (no numpy scalars leak out)
    assert got == expected
    assert all(type(v) is t for s in got for v, t in
               zip((s.x, s.y, s.area, s.radius), (float, float, int, float)))
    manager = VisionManager(min_area=min_area, stop_radius=stop_radius, print_decisions=False)
    manager.initialize((mask.shape[0], mask.shape[1], 1))
    manager.execute(mask)
    decision = manager.history[-1]
    assert decision.sightings == expected
    assert (decision.action, decision.target) == reference_decide(expected, mask.shape[1],
                                                                  stop_radius)
    return got


@pytest.fixture(params=["rectangles", "whole mask"])
def path(request, monkeypatch):
    """Both ways of finding objects: per rectangle of the XY cut, and the whole mask."""
    if request.param == "whole mask":
        monkeypatch.setattr(vision_manager, "MAX_RECTANGLES", 0)
    return request.param


def detect(frame: np.ndarray, red_min: int = 150, margin: int = 80) -> np.ndarray:
    """The ObjectDetector's rule in numpy (as tests/test_kernels.py checks the kernel)."""
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return np.where((r >= red_min) & (r - g >= margin) & (r - b >= margin), 255, 0).astype(
        np.uint8)


@pytest.mark.parametrize("seeds,buoys,size", [((1, 2), 2, (480, 640)),  # the demo
                                              ((3, 4), 8, (480, 640)),
                                              ((5, 6), 1, (97, 131))])
def test_same_as_reference_on_camera_frames(path, seeds, buoys, size):
    height, width = size
    cameras = [Camera(seed=s, width=width, height=height, buoys=buoys) for s in seeds]
    for cam in cameras:
        cam.initialize()
    seen = 0
    for _ in range(40):
        mask = detect(np.hstack([cam.execute() for cam in cameras]))
        seen += len(assert_same(mask, 30))
        assert_same(mask, 1, stop_radius=10)  # also the noise specks, if any
    assert seen > 0


def test_same_as_reference_with_noise_and_low_thresholds(path):
    """A lax detector on the camera's frames: specks, ragged objects, touching borders."""
    cam = Camera(seed=9, width=320, height=240, buoys=3)
    cam.initialize()
    for _ in range(5):
        mask = detect(cam.execute(), red_min=20, margin=-40)
        assert_same(mask, 1)
        assert_same(mask, 5)


def test_demo_frames_give_the_ground_truth():
    """Independent of the reference: the disks the camera drew, as a test can compute."""
    cams = [Camera(seed=1), Camera(seed=2)]
    for cam in cams:
        cam.initialize()
    for f in range(10):
        mask = detect(np.hstack([cam.execute() for cam in cams]))
        truth = sorted([(b.x, b.y, b.radius) for b in cams[0].ground_truth(f)]
                       + [(b.x + 640, b.y, b.radius) for b in cams[1].ground_truth(f)])
        got = find_sightings(mask, 30)
        assert [(s.x, s.y, s.radius) for s in got] == truth
        for s in got:  # a digital disk's area, counted directly
            r = int(s.radius)
            yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
            assert s.area == int(np.count_nonzero(yy ** 2 + xx ** 2 <= r * r))


def test_objects_with_the_same_centroid_keep_the_label_order(path):
    mask = np.zeros((9, 9), np.uint8)
    mask[2:7, 2:7] = 255
    mask[3:6, 3:6] = 0
    mask[4, 4] = 255  # a dot inside a ring: two objects, both centred on (4, 4)
    got = assert_same(mask, 1)
    assert [(s.x, s.y, s.area) for s in got] == [(4.0, 4.0, 16), (4.0, 4.0, 1)]
    flipped = np.ascontiguousarray(mask[::-1])
    assert_same(flipped, 1)


def test_hand_made_masks(path):
    empty = np.zeros((5, 7), np.uint8)
    assert assert_same(empty, 1) == []
    full = np.full((5, 7), 3, np.uint8)
    assert assert_same(full, 1) == [Sighting(3.0, 2.0, 35, 2.5)]
    one = empty.copy()
    one[4, 6] = 1  # one pixel in the corner
    assert assert_same(one, 1) == [Sighting(6.0, 4.0, 1, 0.0)]
    assert assert_same(one, 2) == []
    diagonal = np.eye(6, dtype=np.uint8)  # 4-connectivity: six objects, not one
    assert len(assert_same(diagonal, 1)) == 6
    lattice = np.zeros((60, 60), np.uint8)
    lattice[::2, ::2] = 255  # 900 one-pixel objects: more rectangles than MAX_RECTANGLES
    assert len(assert_same(lattice, 1)) == 900
    lattice[10:20, 10:50] = 200
    assert len(assert_same(lattice, 3)) == 1


@st.composite
def masks(draw):
    """Random masks: noise of any density, blobs (rectangles and disks) that may touch
    each other and the borders, lattices of specks; values any non-zero byte."""
    height = draw(st.integers(1, 48))
    width = draw(st.integers(1, 48))
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    mask = np.zeros((height, width), np.uint8)
    kind = draw(st.sampled_from(["noise", "blobs", "lattice", "mixed"]))
    if kind in ("noise", "mixed"):
        density = draw(st.sampled_from([0.0, 0.02, 0.1, 0.3, 0.6, 0.95, 1.0]))
        mask[rng.random((height, width)) < density] = 255
    if kind in ("blobs", "mixed"):
        yy, xx = np.mgrid[:height, :width]
        for _ in range(draw(st.integers(0, 12))):
            y, x = int(rng.integers(-3, height + 3)), int(rng.integers(-3, width + 3))
            r = int(rng.integers(0, 12))
            if rng.random() < 0.5:
                mask[(yy - y) ** 2 + (xx - x) ** 2 <= r * r] = 255
            else:
                mask[max(y - r, 0):max(y + r, 0), max(x - r, 0):max(x + r, 0)] = 255
            if rng.random() < 0.3:  # holes: rings, and objects inside them
                mask[(yy - y) ** 2 + (xx - x) ** 2 <= (r // 2) ** 2] = 0
    if kind == "lattice":
        step = draw(st.integers(2, 4))
        mask[rng.integers(0, step)::step, rng.integers(0, step)::step] = 255
    values = rng.integers(1, 256, mask.shape).astype(np.uint8)
    return np.where(mask > 0, values, 0).astype(np.uint8)


PROPERTY = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@PROPERTY
@given(mask=masks(), min_area=st.integers(1, 40), stop_radius=st.integers(1, 30))
@example(mask=np.zeros((1, 1), np.uint8), min_area=1, stop_radius=1)
@example(mask=np.full((1, 1), 255, np.uint8), min_area=1, stop_radius=1)
@example(mask=np.full((1, 48), 255, np.uint8), min_area=1, stop_radius=1)
@example(mask=np.full((48, 1), 255, np.uint8), min_area=1, stop_radius=1)
def test_same_as_reference_on_random_masks(path, mask, min_area, stop_radius):
    assert_same(mask, min_area, stop_radius)


def test_a_camera_mask_is_labelled_in_small_rectangles():
    """What makes it fast: on the demo's mask only the objects' surroundings are labelled."""
    cams = [Camera(seed=1), Camera(seed=2)]
    for cam in cams:
        cam.initialize()
    mask = detect(np.hstack([cam.execute() for cam in cams]))
    rectangles = vision_manager._rectangles(mask > 0)
    assert len(rectangles) == 4
    area = sum((y1 - y0) * (x1 - x0) for y0, y1, x0, x1 in rectangles)
    assert area < mask.size // 20
