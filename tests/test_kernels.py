"""Each library component and each adapter against an independent numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from gpucompgen.library.camera import Camera

ROOT = __import__("pathlib").Path(__file__).resolve().parent.parent


def _types():
    from gpucompgen.model import library_types

    return library_types()


# ImageMerger and ObjectDetector have no hand-written kernel: a lone component runs the
# kernel the generator writes from the type's form (a group of one), tested here at any
# settings the system may choose
@pytest.mark.parametrize("settings", [(16, 16, 16, 1), (8, 4, 2, 1), (64, 8, 8, 1),
                                      (32, 32, 8, 1)])
@pytest.mark.parametrize("shape", [(480, 640), (37, 23), (1, 1)])
def test_image_merger_matches_hstack(cl_context, cl_queue, settings, shape):
    from conftest import run_generated

    rng = np.random.default_rng(shape[0] * 7 + settings[0])
    left = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
    right = rng.integers(0, 256, (shape[0], shape[1] + 5, 3), dtype=np.uint8)
    out = run_generated(cl_context, cl_queue, _types()["ImageMerger"], {}, [left, right],
                        (shape[0], 2 * shape[1] + 5, 3), settings)
    np.testing.assert_array_equal(out, np.hstack([left, right]))


@pytest.mark.parametrize("settings", [(32, 16, 16, 1), (8, 8, 8, 1), (16, 4, 16, 1)])
@pytest.mark.parametrize("red_min,margin", [(150, 80), (0, 0), (255, 255), (100, 10)])
def test_object_detector_matches_numpy(cl_context, cl_queue, settings, red_min, margin):
    from conftest import run_generated

    rng = np.random.default_rng(red_min + margin)
    frame = rng.integers(0, 256, (61, 77, 3), dtype=np.uint8)
    out = run_generated(cl_context, cl_queue, _types()["ObjectDetector"],
                        {"red_min": red_min, "margin": margin}, [frame], (61, 77), settings)
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    expected = np.where((r >= red_min) & (r - g >= margin) & (r - b >= margin), 255, 0)
    np.testing.assert_array_equal(out, expected.astype(np.uint8))


def test_adapters_round_trip_bit_exact(cl_context, cl_queue):
    from gpucompgen.runtime import CpuToGpuAdapter, GpuToCpuAdapter, Size

    size = Size(33, 45, 3)
    up = CpuToGpuAdapter(cl_context, cl_queue, nbytes=size.nbytes(np.uint8))
    down = GpuToCpuAdapter(cl_context, cl_queue, nbytes=size.nbytes(np.uint8))
    up.initialize(size, np.uint8)
    down.initialize(size, np.uint8)
    for seed in range(3):
        frame = np.random.default_rng(seed).integers(0, 256, size.shape, dtype=np.uint8)
        back = down.transfer(up.transfer(frame))
        np.testing.assert_array_equal(back, frame)
    with pytest.raises(Exception, match="bytes"):
        up.transfer(np.zeros((2, 2, 3), np.uint8))
    for a in (up, down):
        a.free_memory()
        a.free_memory()


def test_camera_is_deterministic_and_draws_its_ground_truth():
    cam, again = Camera(seed=5, width=320, height=240), Camera(seed=5, width=320, height=240)
    assert cam.initialize() == (240, 320, 3)
    again.initialize()
    for frame in range(3):
        img = cam.execute()
        np.testing.assert_array_equal(img, again.execute())
        assert img.dtype == np.uint8 and img.shape == (240, 320, 3)
        red = (img[..., 0] > 150) & (img[..., 1] < 80)
        truth = cam.ground_truth(frame)
        assert len(truth) == 2
        expected = np.zeros_like(red)
        yy, xx = np.mgrid[:240, :320]
        for b in truth:
            expected |= (yy - b.y) ** 2 + (xx - b.x) ** 2 <= b.radius ** 2
        np.testing.assert_array_equal(red, expected)
    assert Camera(seed=6, width=320, height=240).ground_truth(0) != cam.ground_truth(0)


def test_camera_frames_param_ends_the_stream():
    cam = Camera(width=32, height=32, frames=2, buoys=1)
    cam.initialize()
    assert cam.execute() is not None and cam.execute() is not None
    assert cam.execute() is None


def test_vision_manager_on_hand_made_masks():
    from gpucompgen.library.vision_manager import VisionManager

    vm = VisionManager(print_decisions=False, stop_radius=20, min_area=5)
    vm.initialize((90, 300, 1))
    empty = np.zeros((90, 300), np.uint8)
    vm.execute(empty)
    left = empty.copy()
    left[10:20, 10:20] = 255  # 100 px at centroid (14.5, 14.5)
    left[50:53, 250:253] = 255  # 9 px, smaller
    vm.execute(left)
    big = empty.copy()
    big[0:80, 120:180] = 255  # 80 x 60 px: radius (79 + 59) / 4 = 34.5 → stop
    vm.execute(big)
    mid = empty.copy()
    mid[40:50, 140:150] = 255
    vm.execute(mid)
    right = empty.copy()
    right[40:44, 280:284] = 255
    vm.execute(right)
    assert [d.action for d in vm.history] == ["search", "turn_left", "stop", "forward",
                                              "turn_right"]
    s = vm.history[1].target
    assert (s.x, s.y, s.area, s.radius) == (14.5, 14.5, 100, 4.5)
    assert vm.history[2].target.radius == 34.5
    assert len(vm.history[1].sightings) == 2
