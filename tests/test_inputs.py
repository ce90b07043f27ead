"""Camera sources besides the synthetic scene: image folders and globs, video files."""

from __future__ import annotations

import numpy as np
import pytest

from gpucompgen.library.camera import Camera
from gpucompgen.runtime import PipelineError

Image = pytest.importorskip("PIL.Image")


def _frames(n, height=16, width=24):
    rng = np.random.default_rng(5)
    return [rng.integers(0, 256, (height, width, 3), dtype=np.uint8) for _ in range(n)]


def _read_all(cam):
    cam.initialize()
    frames = []
    while (frame := cam.execute()) is not None:
        frames.append(frame)
    cam.free_memory()
    return frames


def test_folder_and_glob_give_the_images_in_sorted_order(tmp_path):
    frames = _frames(3)
    for i, f in enumerate(frames):
        Image.fromarray(f).save(tmp_path / f"shot_{i}.png")
    Image.fromarray(frames[0]).save(tmp_path / "other.png")
    (tmp_path / "notes.txt").write_text("not an image")
    got = _read_all(Camera(width=24, height=16, folder=str(tmp_path)))
    assert len(got) == 4  # other.png, shot_0..2
    globbed = _read_all(Camera(width=24, height=16, folder=str(tmp_path / "shot_*.png")))
    assert len(globbed) == 3
    for a, b in zip(globbed, frames):
        np.testing.assert_array_equal(a, b)


def test_image_errors_say_which_file_and_what_was_expected(tmp_path):
    Image.fromarray(_frames(1, 20, 30)[0]).save(tmp_path / "big.png")
    cam = Camera(width=24, height=16, folder=str(tmp_path))
    # the first image's header is read at initialize: the size is refused before any frame
    with pytest.raises(PipelineError, match=r"image folder '.*' has frames of 30x20 \(width x "
                                            r"height\), but the system was built for 24x16"):
        cam.initialize()
    Image.fromarray(_frames(1, 16, 24)[0]).save(tmp_path / "a_small.png")
    cam = Camera(width=24, height=16, folder=str(tmp_path))
    cam.initialize()
    cam.execute()
    with pytest.raises(PipelineError, match=r"frame 1 of image folder '.*' is 30x20 \(width x "
                                            r"height\), but the system was built for 24x16"):
        cam.execute()
    (tmp_path / "big.png").unlink()
    (tmp_path / "a_small.png").unlink()
    (tmp_path / "broken.png").write_bytes(b"not a png at all")
    with pytest.raises(PipelineError, match=r"cannot read image .*broken.png"):
        Camera(width=24, height=16, folder=str(tmp_path)).initialize()
    Image.fromarray(_frames(1, 16, 24)[0]).save(tmp_path / "a_good.png")
    cam = Camera(width=24, height=16, folder=str(tmp_path))
    cam.initialize()
    assert cam.execute() is not None  # the frame before the damaged one arrives
    with pytest.raises(PipelineError, match=r"cannot read image .*broken.png"):
        cam.execute()
    (tmp_path / "a_good.png").unlink()
    with pytest.raises(PipelineError, match=r"no images match '.*nothing\*.png'"):
        Camera(folder=str(tmp_path / "nothing*.png")).initialize()
    with pytest.raises(PipelineError, match=r"image folder '.*missing' does not exist"):
        Camera(folder=str(tmp_path / "missing")).initialize()


def test_video_file_frames_arrive_as_rgb(tmp_path):
    cv2 = pytest.importorskip("cv2")
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (32, 24))
    red_rgb = np.zeros((24, 32, 3), np.uint8)
    red_rgb[..., 0] = 220
    for _ in range(4):
        writer.write(cv2.cvtColor(red_rgb, cv2.COLOR_RGB2BGR))
    writer.release()
    got = _read_all(Camera(width=32, height=24, video=str(path)))
    assert len(got) == 4
    for frame in got:
        assert frame.shape == (24, 32, 3) and frame.dtype == np.uint8
        r, g, b = (frame[..., i].astype(int).mean() for i in range(3))
        assert r > 180 and g < 40 and b < 40  # red stays red: BGR became RGB

    cam = Camera(width=64, height=48, video=str(path))
    with pytest.raises(PipelineError, match=r"video file '.*clip.avi' has frames of 32x24 "
                                            r"\(width x height\), but the system was built for "
                                            r"64x48"):
        cam.initialize()
    cam.free_memory()
    cam.free_memory()  # safe twice
    with pytest.raises(PipelineError, match=r"video file '.*none.avi' does not exist"):
        Camera(video=str(tmp_path / "none.avi")).initialize()
    with pytest.raises(PipelineError, match=r"write device:N"):
        Camera(video="device:front").initialize()
    with pytest.raises(PipelineError, match=r"not folder and video"):
        Camera(video=str(path), folder=str(tmp_path)).initialize()
