"""gpucompgen.io: every source and sink URI, with files the tests write (MCAP with the same
mcap packages, ROS 2 bags with rosbags, video with OpenCV, images with Pillow), damaged
and truncated ones included, and the pixel formats converted to RGB."""

from __future__ import annotations

import base64
import json
import os
import threading
from pathlib import Path

import numpy as np
import pytest

from gpucompgen import io
from gpucompgen.io.recordings import IMAGE_MSGDEF
from gpucompgen.library.camera import Camera
from gpucompgen.runtime import PipelineError

Image = pytest.importorskip("PIL.Image")
cv2 = pytest.importorskip("cv2")

H, W = 12, 16


def frames(n, height=H, width=W, seed=3):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, (height, width, 3), dtype=np.uint8) for _ in range(n)]


def read_all(source):
    size = source.open()
    got = []
    while (f := source.read()) is not None:
        got.append(f)
    source.close()
    return size, got


# -- URIs -------------------------------------------------------------------------------

@pytest.mark.parametrize(("text", "kind", "path", "index", "topic"), [
    ("v4l2:///dev/video2", "camera", "/dev/video2", 2, ""),
    ("csi://1", "camera", "csi://1", 1, ""),
    ("device:0", "camera", "", 0, ""),
    ("rtsp://cam.local:8554/front", "rtsp", "rtsp://cam.local:8554/front", None, ""),
    ("mcap:///data/drive.mcap?topic=/cam/image", "mcap", "/data/drive.mcap", None,
     "/cam/image"),
    ("rosbag:///data/bag?topic=/cam", "rosbag", "/data/bag", None, "/cam"),
    ("file:///data/road.mp4", "video", "/data/road.mp4", None, ""),
    ("/data/road.mkv", "video", "/data/road.mkv", None, ""),
    ("/data/shots/*.png", "images", "/data/shots/*.png", None, ""),
    ("/data/drive.mcap", "mcap", "/data/drive.mcap", None, ""),
])
def test_source_uris_parse(text, kind, path, index, topic):
    uri = io.parse_source(text)
    assert (uri.kind, uri.path, uri.index, uri.topic) == (kind, path, index, topic)


@pytest.mark.parametrize(("text", "message"), [
    ("", "empty input"),
    ("foo://x", r"unknown input scheme 'foo:'.*mcap://drive.mcap"),
    ("device:front", "write device:N"),
    ("v4l2://video0", r"write v4l2:///dev/videoN"),
    ("csi://left", r"write csi://N"),
    ("rtsp:///path", "names no host"),
    ("rtsp://host:99999/x", "port is not a number"),
    ("mcap://a.mcap?topik=/x", r"unknown option '\?topik='; mcap:// takes \?topic="),
    ("display://", "is an output"),
    ("mcap:a.mcap", r"write mcap://"),
])
def test_bad_source_uris_say_what_to_write(text, message):
    with pytest.raises(io.UriError, match=message):
        io.parse_source(text)


def test_sink_uris_parse_and_refuse_inputs():
    assert io.parse_sink("out.mp4").kind == "video"
    assert io.parse_sink("out/").kind == "images"
    assert io.parse_sink("mcap://out.mcap?topic=/run1").topic == "/run1"
    assert io.parse_sink("display://").kind == "display"
    for bad, message in (("device:0", "is a camera"), ("rtsp://h/x", "not supported"),
                         ("one.png", "is one image")):
        with pytest.raises(io.UriError, match=message):
            io.parse_sink(bad)


def test_unreachable_rtsp_and_missing_cameras_are_one_clear_line():
    with pytest.raises(PipelineError, match=r"cannot connect to 127.0.0.1:9: connection "
                                            r"refused; is the RTSP server running"):
        io.open_source("rtsp://127.0.0.1:9/stream").open()
    with pytest.raises(PipelineError, match="host 'no-such-host.invalid' not found"):
        io.open_source("rtsp://no-such-host.invalid/stream").open()
    if not Path("/dev/video9").exists():
        with pytest.raises(PipelineError, match=r"no camera /dev/video9 here \(cameras: "):
            io.open_source("v4l2:///dev/video9").open()
    if "YES" not in next((ln for ln in cv2.getBuildInformation().splitlines()
                          if "GStreamer" in ln), "NO"):
        with pytest.raises(PipelineError, match="built without GStreamer"):
            io.open_source("csi://0").open()


# -- images -----------------------------------------------------------------------------

def test_image_folder_glob_and_one_image(tmp_path):
    shots = frames(3)
    for i, f in enumerate(shots):
        Image.fromarray(f).save(tmp_path / f"{i:02d}.png")
    size, got = read_all(io.open_source(str(tmp_path)))
    assert size == (H, W) and len(got) == 3
    for a, b in zip(got, shots):
        np.testing.assert_array_equal(a, b)
    assert len(read_all(io.open_source(f"file://{tmp_path}/0[12].png"))[1]) == 2
    assert len(read_all(io.open_source(str(tmp_path / "01.png")))[1]) == 1


def test_a_fifo_in_an_image_folder_is_refused_not_waited_on(tmp_path):
    Image.fromarray(frames(1)[0]).save(tmp_path / "00.png")
    os.mkfifo(tmp_path / "01.png")
    result = {}

    def attempt():
        try:
            Camera(width=W, height=H, source=str(tmp_path)).initialize()
        except PipelineError as exc:
            result["error"] = str(exc)

    t = threading.Thread(target=attempt, daemon=True)
    t.start()
    t.join(10)
    assert not t.is_alive(), "opening a folder with a FIFO in it hung"
    assert "01.png is a FIFO, not an image file" in result["error"]


# -- video ------------------------------------------------------------------------------

def write_video(path, shots, fourcc="MJPG"):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10,
                             (shots[0].shape[1], shots[0].shape[0]))
    assert writer.isOpened()
    for f in shots:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()


def flat_frames(n):
    """Frames of flat colours: lossy codecs keep them within a few levels."""
    return [np.full((32, 48, 3), (40 * i % 256, 200 - 30 * i, 90), np.uint8) for i in range(n)]


def test_video_file_plain_path_and_file_uri(tmp_path):
    shots = flat_frames(5)
    write_video(tmp_path / "clip.avi", shots)
    for text in (str(tmp_path / "clip.avi"), f"file://{tmp_path}/clip.avi"):
        size, got = read_all(io.open_source(text))
        assert size == (32, 48) and len(got) == 5
        for a, b in zip(got, shots):
            assert np.abs(a.astype(int) - b).max() <= 6  # RGB stays RGB through BGR


def test_truncated_and_garbage_video_are_clear_errors(tmp_path):
    (tmp_path / "garbage.mp4").write_bytes(b"\0not a video" * 100)
    with pytest.raises(PipelineError, match=r"video file .*garbage.mp4.*OpenCV cannot open "
                                            r"it \(not a video, or a damaged"):
        io.open_source(str(tmp_path / "garbage.mp4")).open()
    shots = flat_frames(20)
    write_video(tmp_path / "clip.avi", shots)
    data = (tmp_path / "clip.avi").read_bytes()
    (tmp_path / "cut.avi").write_bytes(data[:len(data) // 2])
    source = io.open_source(str(tmp_path / "cut.avi"))
    got = []
    try:
        source.open()
        while (f := source.read()) is not None:
            got.append(f)
    except PipelineError as exc:  # the container's frame count tells the cut
        assert "damaged or truncated" in str(exc) or "cannot open" in str(exc)
    assert len(got) < 20
    for a, b in zip(got, shots):  # whatever came before the cut is the recorded frames
        assert np.abs(a.astype(int) - b).max() <= 6


# -- recordings ---------------------------------------------------------------------------

def ros_image(frame, encoding="rgb8"):
    array = {"rgb8": frame, "bgr8": frame[..., ::-1], "mono8": frame[..., 0]}[encoding]
    array = np.ascontiguousarray(array)
    return {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "cam"},
            "height": array.shape[0], "width": array.shape[1], "encoding": encoding,
            "is_bigendian": 0, "step": array.strides[0], "data": array.tobytes()}


COMPRESSED_MSGDEF = IMAGE_MSGDEF.replace(
    "uint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\n"
    "uint8[] data\n", "string format\nuint8[] data\n")
FOXGLOVE_RAW_MSGDEF = ("builtin_interfaces/Time timestamp\nstring frame_id\nuint32 width\n"
                       "uint32 height\nstring encoding\nuint32 step\nuint8[] data\n"
                       + "=" * 80 + "\nMSG: builtin_interfaces/Time\nint32 sec\n"
                       "uint32 nanosec\n")


def write_mcap(path, shots, extra_topics=True):
    from mcap_ros2.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f, chunk_size=2048)  # small chunks: a cut loses only the last frames
        image = w.register_msgdef("sensor_msgs/msg/Image", IMAGE_MSGDEF)
        compressed = w.register_msgdef("sensor_msgs/msg/CompressedImage", COMPRESSED_MSGDEF)
        fox = w.register_msgdef("foxglove_msgs/msg/RawImage", FOXGLOVE_RAW_MSGDEF)
        for i, f_ in enumerate(shots):
            t = (i + 1) * 10**8
            w.write_message("/cam/rgb", image, ros_image(f_), log_time=t)
            if extra_topics:
                w.write_message("/cam/bgr", image, ros_image(f_, "bgr8"), log_time=t)
                w.write_message("/cam/mono", image, ros_image(f_, "mono8"), log_time=t)
                ok, png = cv2.imencode(".png", cv2.cvtColor(f_, cv2.COLOR_RGB2BGR))
                w.write_message("/cam/png", compressed, {
                    "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "cam"},
                    "format": "png", "data": png.tobytes()}, log_time=t)
                w.write_message("/cam/foxglove", fox, {
                    "timestamp": {"sec": 0, "nanosec": 0}, "frame_id": "cam",
                    "width": W, "height": H, "encoding": "rgb8", "step": 3 * W,
                    "data": f_.tobytes()}, log_time=t)
        w.finish()


def test_mcap_every_image_message_kind(tmp_path):
    shots = frames(4)
    write_mcap(tmp_path / "drive.mcap", shots)
    for topic in ("/cam/rgb", "/cam/bgr", "/cam/png", "/cam/foxglove"):
        size, got = read_all(io.open_source(f"mcap://{tmp_path}/drive.mcap?topic={topic}"))
        assert size == (H, W) and len(got) == 4, topic
        for a, b in zip(got, shots):
            np.testing.assert_array_equal(a, b)
    _, mono = read_all(io.open_source(f"mcap://{tmp_path}/drive.mcap?topic=/cam/mono"))
    np.testing.assert_array_equal(mono[0], np.repeat(shots[0][..., :1], 3, axis=2))
    with pytest.raises(PipelineError, match=r"5 image topics \(/cam/bgr, .*choose one with "
                                            r"\?topic=NAME"):
        io.open_source(f"mcap://{tmp_path}/drive.mcap").open()
    with pytest.raises(PipelineError, match=r"no topic '/nope'; its topics: /cam/bgr "
                                            r"\(sensor_msgs/msg/Image\)"):
        io.open_source(f"mcap://{tmp_path}/drive.mcap?topic=/nope").open()


def test_mcap_foxglove_compressed_image(tmp_path):
    from mcap_ros2.writer import Writer

    msgdef = ("builtin_interfaces/Time timestamp\nstring frame_id\nuint8[] data\n"
              "string format\n" + "=" * 80 + "\nMSG: builtin_interfaces/Time\n"
              "int32 sec\nuint32 nanosec\n")
    shots = frames(2)
    with open(tmp_path / "fox.mcap", "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("foxglove_msgs/msg/CompressedImage", msgdef)
        for i, f_ in enumerate(shots):
            ok, png = cv2.imencode(".png", cv2.cvtColor(f_, cv2.COLOR_RGB2BGR))
            w.write_message("/front", schema, {"timestamp": {"sec": i, "nanosec": 0},
                                               "frame_id": "cam", "data": png.tobytes(),
                                               "format": "png"}, log_time=i + 1)
        w.finish()
    size, got = read_all(io.open_source(f"mcap://{tmp_path}/fox.mcap"))
    assert size == (H, W) and len(got) == 2
    np.testing.assert_array_equal(got[1], shots[1])


def test_mcap_only_image_topic_and_foxglove_json(tmp_path):
    from mcap.writer import Writer

    shots = frames(2)
    with open(tmp_path / "fox.mcap", "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("foxglove.RawImage", "jsonschema", b"{}")
        other = w.register_schema("foxglove.Log", "jsonschema", b"{}")
        cam = w.register_channel("/front", "json", schema)
        log = w.register_channel("/log", "json", other)
        for i, f_ in enumerate(shots):
            w.add_message(log, log_time=i, publish_time=i, data=b'{"message": "hi"}')
            w.add_message(cam, log_time=i, publish_time=i, data=json.dumps({
                "width": W, "height": H, "encoding": "bgr8", "step": 3 * W,
                "data": base64.b64encode(f_[..., ::-1].tobytes()).decode()}).encode())
        w.finish()
    size, got = read_all(io.open_source(str(tmp_path / "fox.mcap")))  # the only image topic
    assert size == (H, W) and len(got) == 2
    np.testing.assert_array_equal(got[1], shots[1])
    with pytest.raises(PipelineError, match=r"topic '/log' has foxglove.Log messages, not "
                                            r"images"):
        io.open_source(f"mcap://{tmp_path}/fox.mcap?topic=/log").open()


def test_truncated_and_corrupt_mcap_give_the_frames_before_the_damage(tmp_path):
    shots = frames(30)
    write_mcap(tmp_path / "drive.mcap", shots, extra_topics=False)
    data = (tmp_path / "drive.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[:len(data) // 2])
    source = io.open_source(f"mcap://{tmp_path}/cut.mcap?topic=/cam/rgb")
    assert source.open() == (H, W)  # no summary: the channels are found by reading
    got = []
    with pytest.raises(PipelineError, match=r"MCAP recording .*cut.mcap.*: damaged or "
                                            r"truncated after frame \d+ on topic /cam/rgb"):
        while (f := source.read()) is not None:
            got.append(f)
    assert 5 <= len(got) < 30
    for a, b in zip(got, shots):
        np.testing.assert_array_equal(a, b)
    corrupt = bytearray(data)
    middle = len(data) // 2
    corrupt[middle:middle + 64] = bytes(64)  # zeros in the middle of a chunk
    (tmp_path / "bad.mcap").write_bytes(bytes(corrupt))
    source = io.open_source(f"mcap://{tmp_path}/bad.mcap?topic=/cam/rgb")
    got = []
    with pytest.raises(PipelineError, match=r"bad.mcap.*damaged or truncated"):
        source.open()
        while (f := source.read()) is not None:
            got.append(f)
    assert len(got) < 30
    for a, b in zip(got, shots):
        np.testing.assert_array_equal(a, b)
    (tmp_path / "text.mcap").write_text("hello")
    with pytest.raises(PipelineError, match=r"not a readable MCAP file"):
        io.open_source(str(tmp_path / "text.mcap")).open()


def write_bag(path, shots, topic="/cam/image", encoding="rgb8"):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    Img = store.types["sensor_msgs/msg/Image"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    with Writer(path, version=8) as w:
        conn = w.add_connection(topic, Img.__msgtype__, typestore=store)
        w.add_connection("/odom_count", "std_msgs/msg/Int32", typestore=store)
        for i, f_ in enumerate(shots):
            array = np.ascontiguousarray(f_[..., ::-1] if encoding == "bgr8" else f_)
            msg = Img(Header(Time(i, 0), "cam"), H, W, encoding, 0, 3 * W,
                      array.reshape(-1))
            w.write(conn, (i + 1) * 10**8, store.serialize_cdr(msg, Img.__msgtype__))


def test_ros2_bag_folder_db3_and_rosbag_uri(tmp_path):
    shots = frames(3)
    write_bag(tmp_path / "bag", shots, encoding="bgr8")
    db3 = next((tmp_path / "bag").glob("*.db3"))
    for text in (str(tmp_path / "bag"), str(db3), f"rosbag://{tmp_path}/bag?topic=/cam/image"):
        size, got = read_all(io.open_source(text))
        assert size == (H, W) and len(got) == 3, text
        for a, b in zip(got, shots):
            np.testing.assert_array_equal(a, b)
    with pytest.raises(PipelineError, match=r"topic '/odom_count' has std_msgs/msg/Int32"):
        io.open_source(f"rosbag://{tmp_path}/bag?topic=/odom_count").open()


def test_damaged_ros2_bag_is_a_clear_error(tmp_path):
    write_bag(tmp_path / "bag", frames(3))
    db3 = next((tmp_path / "bag").glob("*.db3"))
    data = db3.read_bytes()
    db3.write_bytes(data[:len(data) // 3])
    with pytest.raises(PipelineError, match=r"ROS 2 bag .*(cannot open the bag|damaged)"):
        read_all(io.open_source(str(tmp_path / "bag")))
    (tmp_path / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: [")
    with pytest.raises(PipelineError, match=r"cannot open the bag"):
        io.open_source(str(tmp_path / "bag")).open()


def test_camera_reads_recordings_through_its_source(tmp_path):
    shots = frames(3)
    write_mcap(tmp_path / "drive.mcap", shots, extra_topics=False)
    cam = Camera(width=W, height=H, source=f"mcap://{tmp_path}/drive.mcap")
    cam.initialize()
    got = [cam.execute() for _ in range(4)]
    cam.free_memory()
    assert got[3] is None
    for a, b in zip(got, shots):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(PipelineError, match=r"has frames of 16x12 \(width x height\), but the "
                                            r"system was built for 640x480"):
        Camera(source=f"mcap://{tmp_path}/drive.mcap").initialize()


# -- pixel formats --------------------------------------------------------------------------

def bt601(y, u, v):
    """Video-range BT.601 YUV to RGB, by the formula (an independent reference)."""
    c, d, e = y - 16.0, u - 128.0, v - 128.0
    rgb = np.stack([1.164 * c + 1.596 * e, 1.164 * c - 0.392 * d - 0.813 * e,
                    1.164 * c + 2.017 * d], axis=-1)
    return np.clip(np.rint(rgb), 0, 255)


def test_yuyv_uyvy_nv12_become_rgb():
    rng = np.random.default_rng(1)
    y = rng.integers(16, 236, (4, 6)).astype(np.uint8)
    u = rng.integers(16, 241, (4, 3)).astype(np.uint8)
    v = rng.integers(16, 241, (4, 3)).astype(np.uint8)
    yuyv = np.empty((4, 12), np.uint8)
    yuyv[:, 0::2], yuyv[:, 1::4], yuyv[:, 3::4] = y, u, v
    ref = bt601(y.astype(float), np.repeat(u, 2, 1).astype(float),
                np.repeat(v, 2, 1).astype(float))
    got = io.raw_to_rgb(yuyv.tobytes(), "yuv422_yuy2", 6, 4)
    assert np.abs(got.astype(int) - ref).max() <= 2
    uyvy = np.empty_like(yuyv)
    uyvy[:, 1::2], uyvy[:, 0::4], uyvy[:, 2::4] = y, u, v
    assert np.abs(io.raw_to_rgb(uyvy.tobytes(), "yuv422", 6, 4).astype(int) - ref).max() <= 2
    uv = np.empty((2, 6), np.uint8)  # NV12: U and V interleaved, one pair per 2x2 block
    uv[:, 0::2], uv[:, 1::2] = u[::2], v[::2]
    nv12 = np.concatenate([y, uv]).tobytes()
    ref12 = bt601(y.astype(float), np.repeat(np.repeat(u[::2], 2, 0), 2, 1).astype(float),
                  np.repeat(np.repeat(v[::2], 2, 0), 2, 1).astype(float))
    assert np.abs(io.raw_to_rgb(nv12, "nv12", 6, 4).astype(int) - ref12).max() <= 2
    bgr = rng.integers(0, 256, (4, 6, 3), dtype=np.uint8)
    np.testing.assert_array_equal(io.raw_to_rgb(bgr.tobytes(), "bgr8", 6, 4), bgr[..., ::-1])
    padded = np.zeros((4, 20), np.uint8)  # a step wider than the row
    padded[:, :18] = bgr.reshape(4, 18)
    np.testing.assert_array_equal(io.raw_to_rgb(padded.tobytes(), "rgb8", 6, 4, step=20), bgr)
    with pytest.raises(PipelineError, match=r"needs 72 bytes \(step 18\), has 10"):
        io.raw_to_rgb(b"0123456789", "rgb8", 6, 4)
    with pytest.raises(PipelineError, match=r"encoding '32FC1' is not supported"):
        io.raw_to_rgb(b"", "32FC1", 6, 4)


# -- sinks ------------------------------------------------------------------------------

def test_sinks_write_what_the_sources_read_back(tmp_path):
    shots = flat_frames(4)
    for text in (str(tmp_path / "out.avi"), str(tmp_path / "frames"),
                 f"mcap://{tmp_path}/out.mcap?topic=/run"):
        sink = io.open_sink(text)
        sink.open()
        for f in shots:
            sink.write(f)
            sink.write(f[..., 1], "mask")  # a gray output beside it
        sink.close()
    _, video = read_all(io.open_source(str(tmp_path / "out.avi")))
    _, masks = read_all(io.open_source(str(tmp_path / "out_mask.avi")))
    assert len(video) == len(masks) == 4
    assert np.abs(video[2].astype(int) - shots[2]).max() <= 6
    _, images = read_all(io.open_source(str(tmp_path / "frames" / "0*.png")))
    _, mask_images = read_all(io.open_source(str(tmp_path / "frames" / "mask_*.png")))
    np.testing.assert_array_equal(images[3], shots[3])
    np.testing.assert_array_equal(mask_images[3][..., 0], shots[3][..., 1])
    _, recorded = read_all(io.open_source(f"mcap://{tmp_path}/out.mcap?topic=/run/image"))
    _, recorded_masks = read_all(io.open_source(f"mcap://{tmp_path}/out.mcap?topic=/run/mask"))
    np.testing.assert_array_equal(recorded[1], shots[1])
    np.testing.assert_array_equal(recorded_masks[1][..., 2], shots[1][..., 1])


def test_video_codecs_are_named_and_display_needs_one(tmp_path, monkeypatch):
    text = io.describe_codecs()
    assert text.startswith(".mp4: ") and "; .avi: " in text
    sink = io.open_sink(str(tmp_path / "out.mp4"))
    sink.open()
    sink.write(flat_frames(1)[0])
    sink.close()
    assert sink.codec in io.available_codecs(".mp4")  # H.264 (avc1) where OpenCV has it
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(PipelineError, match=r"no display here \(DISPLAY is not set\)"):
        io.open_sink("display://").open()
    with pytest.raises(PipelineError, match=r"folder .*missing does not exist"):
        io.open_sink(str(tmp_path / "missing" / "out.mp4")).open()


GRAY_VIEW = """\
system: grayview
platform: {device: portable}
components:
  camera: {type: Camera, params: {folder: shots}}
  gray: {type: RgbToGray}
  view: {type: FrameSink, params: {output: gray_out/}}
  colour: {type: FrameSink, params: {output: rgb_out/}}
connections:
  - camera.image -> gray.src
  - gray.dst -> view.image
  - camera.image -> colour.image
"""


def test_a_frame_sink_takes_a_gray_frame_as_well_as_rgb(tmp_path):
    """A mask or an edge map is looked at without converting it to RGB first: the
    FrameSink takes one or three channels, and the PNG written is OpenCV's gray."""
    import subprocess
    import sys

    from conftest import require_opencl

    require_opencl()
    shots = frames(3, 20, 36)
    (tmp_path / "shots").mkdir()
    for i, f in enumerate(shots):
        Image.fromarray(f).save(tmp_path / "shots" / f"{i}.png")
    (tmp_path / "m.yaml").write_text(GRAY_VIEW)
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", "m.yaml"],
                          capture_output=True, text=True, timeout=300, check=False,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    _, gray = read_all(io.open_source(str(tmp_path / "gray_out" / "*.png")))
    _, rgb = read_all(io.open_source(str(tmp_path / "rgb_out" / "*.png")))
    assert len(gray) == len(rgb) == 3
    for i, f in enumerate(shots):
        np.testing.assert_array_equal(rgb[i], f)
        # a gray PNG reads back as RGB with three equal channels
        np.testing.assert_array_equal(gray[i][..., 1], cv2.cvtColor(f, cv2.COLOR_RGB2GRAY))


# -- sizes from the input, when the model is checked --------------------------------------

SIZED = """\
system: sized
platform: {{device: portable}}
components:
  camera: {{type: Camera, params: {{{params}}}}}
  detector: {{type: ObjectDetector}}
  manager: {{type: VisionManager}}
connections:
  - camera.image -> detector.frame
  - detector.mask -> manager.mask
"""


def check(tmp_path, params, *extra):
    import subprocess
    import sys

    (tmp_path / "m.yaml").write_text(SIZED.format(params=params))
    return subprocess.run([sys.executable, "-m", "gpucompgen", "check", *extra,
                           str(tmp_path / "m.yaml")], capture_output=True, text=True,
                          timeout=120, check=False)


def test_a_source_without_width_and_height_takes_them_from_its_input(tmp_path):
    shots_dir = tmp_path / "shots"
    shots_dir.mkdir()
    Image.fromarray(frames(1, 20, 36)[0]).save(shots_dir / "a.png")
    proc = check(tmp_path, "folder: shots")  # relative to the model
    assert proc.returncode == 0, proc.stderr
    assert "camera.image: 20x36x3 uint8" in proc.stdout
    write_mcap(tmp_path / "drive.mcap", frames(2), extra_topics=False)
    proc = check(tmp_path, "source: 'mcap://drive.mcap?topic=/cam/rgb'")
    assert proc.returncode == 0, proc.stderr
    assert f"camera.image: {H}x{W}x3 uint8" in proc.stdout
    write_video(tmp_path / "clip.avi", flat_frames(2))
    proc = check(tmp_path, "video: clip.avi")
    assert "camera.image: 32x48x3 uint8" in proc.stdout
    proc = check(tmp_path, "folder: shots, width: 40")
    assert proc.returncode == 1
    assert "m.yaml:4:57: error: 'width' of 'camera' is 40, but 'shots' has frames of 36x20" \
        in proc.stderr
    assert "hint: set 'width: 36', or leave it out: it is read from the input" in proc.stderr


def test_check_reports_a_missing_or_empty_input_at_its_position(tmp_path):
    proc = check(tmp_path, "folder: nowhere")
    assert proc.returncode == 1
    assert (f"m.yaml:4:43: error: input of 'camera': image folder '{tmp_path}/nowhere' does "
            "not exist") in proc.stderr
    (tmp_path / "empty").mkdir()
    proc = check(tmp_path, "folder: empty")
    assert "error: input of 'camera': image folder" in proc.stderr
    assert "has no images" in proc.stderr
    proc = check(tmp_path, "source: device:0")
    assert "the frame size of 'device:0' (a live camera or stream) is not known before it " \
           "runs" in proc.stderr and "hint: give height and width" in proc.stderr
    # with the size given, a missing input is a warning: the program may get --input
    proc = check(tmp_path, "folder: nowhere, width: 32, height: 16")
    assert proc.returncode == 0
    assert "warning: input of 'camera'" in proc.stderr
    assert "hint: the program will need --input camera=URI" in proc.stderr
    assert check(tmp_path, "folder: nowhere, width: 32, height: 16", "--strict").returncode == 1
    proc = check(tmp_path, "folder: a, video: b.avi")
    assert "'camera' sets 'folder' and 'video': one input only" in proc.stderr


# -- --drop: live behaviour -----------------------------------------------------------------

class Ticker(io.Source):
    """A live source: frame i is full of i, one every `period` seconds, `count` frames."""

    def __init__(self, count, period=0.002, fail_at=None):
        super().__init__(io.parse_source("device:0"))
        self.count, self.period, self.fail_at, self.i = count, period, fail_at, 0

    def open(self):
        return (2, 2)

    def read(self):
        import time

        time.sleep(self.period)
        if self.i == self.fail_at:
            raise PipelineError("camera unplugged")
        if self.i >= self.count:
            return None
        self.i += 1
        return np.full((2, 2, 3), self.i - 1, np.uint8)


def test_drop_keeps_the_newest_frame_and_counts_the_rest():
    import time

    from gpucompgen.io.live import DropFrames

    source = DropFrames(Ticker(60))
    source.open()
    got = []
    while (f := source.read()) is not None:
        got.append(int(f[0, 0, 0]))
        time.sleep(0.01)  # a pipeline five times slower than the camera
    source.close()
    assert got == sorted(set(got)) and got[-1] == 59  # newer and newer, up to the last
    assert source.dropped > 0 and source.dropped + len(got) == 60
    failing = DropFrames(Ticker(60, fail_at=5))
    failing.open()
    with pytest.raises(PipelineError, match="camera unplugged"):
        while failing.read() is not None:
            pass
    failing.close()


def test_drop_on_the_camera_and_in_the_statistics(tmp_path):
    for i, f in enumerate(frames(5)):
        Image.fromarray(f).save(tmp_path / f"{i}.png")
    cam = Camera(width=W, height=H, source=str(tmp_path))
    cam.runtime_options({"drop": True})
    cam.initialize()
    got = []
    while (f := cam.execute()) is not None:
        got.append(f)
    cam.free_memory()
    assert cam.dropped_frames + len(got) == 5 and len(got) >= 1
    from gpucompgen.runtime import Monitor

    monitor = Monitor(progress=False)
    monitor.attach({"camera": cam})
    assert monitor.stats()["dropped_frames"] == {"camera": cam.dropped_frames}
