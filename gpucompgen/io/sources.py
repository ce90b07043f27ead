"""Frame sources: image folders, video files, cameras, streams and recordings.

Each reads RGB frames (H, W, 3, uint8), one at a time: ``open()`` returns the frame size
when a header tells it ((height, width), or None), ``read()`` the next frame or None at the
end, ``close()`` releases it.  A problem is a PipelineError naming the source and, once
frames flowed, the frame where it happened; frames before a damaged part are delivered.
"""

from __future__ import annotations

import glob
import os
import socket
import stat
from pathlib import Path

import numpy as np

from gpucompgen.runtime.errors import PipelineError

from .convert import cv2_or_fail, to_rgb
from .uri import IMAGE_SUFFIXES, Uri, parse_source

OPEN_TIMEOUT_MS = 5000  # a stream that does not answer within this is reported


class Source:
    """What every source does; `frames` counts the frames read."""

    def __init__(self, uri: Uri):
        self.uri = uri
        self.frames = 0

    def open(self) -> tuple[int, int] | None:
        return None

    def read(self) -> np.ndarray | None:  # pragma: no cover - every source has its own
        raise NotImplementedError

    def close(self) -> None:
        pass

    def fail(self, what: str) -> PipelineError:
        return PipelineError(f"{self.uri.describe()}: {what}")


def open_source(text: str | Uri, base: Path | None = None) -> Source:
    """The source a URI names (not opened yet)."""
    uri = text if isinstance(text, Uri) else parse_source(text, base)
    if uri.kind == "images":
        return ImageFiles(uri)
    if uri.kind in ("video", "camera", "rtsp"):
        return VideoCapture(uri)
    from . import recordings

    if uri.kind == "mcap":
        return recordings.McapSource(uri)
    return recordings.BagSource(uri)


def regular_file_problem(path: Path) -> str:
    """Why a path cannot be read as a file without blocking, or '' for a regular file."""
    try:
        mode = path.stat().st_mode
    except OSError as exc:
        return exc.strerror or "cannot be read"
    if stat.S_ISREG(mode):
        return ""
    kinds = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
             (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
             (stat.S_ISDIR, "a folder"))
    what = next((name for test, name in kinds if test(mode)), "not a regular file")
    return f"is {what}, not an image file"


class ImageFiles(Source):
    """A folder of images, a glob, or one image, in sorted order (Pillow)."""

    def __init__(self, uri: Uri):
        super().__init__(uri)
        self.files: list[Path] = []

    def open(self) -> tuple[int, int] | None:
        self.files = self._files()
        for f in self.files:  # a FIFO named 01.png would block the first read forever
            problem = regular_file_problem(f)
            if problem:
                raise self.fail(f"{f.name} {problem}; remove it, or name the images "
                                "with a glob")
        return image_size(self.files[0])

    def _files(self) -> list[Path]:
        spec = self.uri.path
        if glob.has_magic(spec):
            files = sorted(Path(p) for p in glob.glob(spec)
                           if Path(p).suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                raise PipelineError(f"no images match '{spec}' ({', '.join(IMAGE_SUFFIXES)})")
            return files
        path = Path(spec)
        if path.suffix.lower() in IMAGE_SUFFIXES and not path.is_dir():
            if not path.exists():
                raise PipelineError(f"image '{spec}' does not exist")
            return [path]
        if not path.is_dir():
            raise PipelineError(f"image folder '{spec}' "
                                + ("is not a folder" if path.exists() else "does not exist"))
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise PipelineError(f"image folder '{spec}' has no images "
                                f"({', '.join(IMAGE_SUFFIXES)})")
        return files

    def read(self) -> np.ndarray | None:
        if self.frames >= len(self.files):
            return None
        image = read_image(self.files[self.frames])
        self.frames += 1
        return image


def pillow():
    try:
        from PIL import Image
    except ImportError:
        raise PipelineError("reading images needs Pillow: pip install 'gpucompgen[image]'") \
            from None
    return Image


def image_size(path: Path) -> tuple[int, int]:
    """(height, width) from an image file's header; the pixels are not decoded."""
    problem = regular_file_problem(path)
    if problem:
        raise PipelineError(f"image {path} {problem}")
    try:
        with pillow().open(path) as im:
            return im.height, im.width
    except OSError as exc:
        raise PipelineError(f"cannot read image {path}: {exc}") from None


def read_image(path: Path) -> np.ndarray:
    problem = regular_file_problem(path)
    if problem:
        raise PipelineError(f"image {path} {problem}")
    try:
        with pillow().open(path) as im:
            return np.ascontiguousarray(np.asarray(im.convert("RGB")))
    except OSError as exc:
        raise PipelineError(f"cannot read image {path}: {exc}") from None


def video_devices() -> list[str]:
    return sorted(glob.glob("/dev/video*"))


def has_gstreamer(cv2) -> bool:
    for line in cv2.getBuildInformation().splitlines():
        if "GStreamer" in line:
            return "YES" in line
    return False


def check_reachable(url: str, timeout: float = 3.0) -> None:
    """A stream's host is looked up and its port connected to, so an unreachable server
    is one clear line rather than OpenCV's silence."""
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    host, port = parts.hostname, parts.port or (322 if parts.scheme == "rtsps" else 554)
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except OSError as exc:
        raise PipelineError(f"stream '{url}': host '{host}' not found "
                            f"({exc.strerror or exc})") from None
    error = None
    for family, kind, proto, _, address in infos:
        try:
            with socket.socket(family, kind, proto) as s:
                s.settimeout(timeout)
                s.connect(address)
                return
        except OSError as exc:
            error = exc
    reason = "timed out" if isinstance(error, TimeoutError) else \
        (getattr(error, "strerror", None) or str(error)).lower()
    raise PipelineError(f"stream '{url}': cannot connect to {host}:{port}: {reason}; is the "
                        "RTSP server running, and the address and port right?")


class VideoCapture(Source):
    """A video file, a camera or an RTSP stream, read with OpenCV (BGR becomes RGB here)."""

    def __init__(self, uri: Uri):
        super().__init__(uri)
        self.capture = None
        self.expected = 0  # frames the container says it has (0: unknown)

    def open(self) -> tuple[int, int] | None:
        cv2 = cv2_or_fail(f"reading {self.uri.describe()}")
        uri = self.uri
        if uri.kind == "video":
            path = Path(uri.path)
            if not path.exists():
                raise PipelineError(f"video file '{uri.path}' does not exist")
            problem = regular_file_problem(path)
            if problem:
                raise self.fail(problem.replace("image", "video"))
            capture = cv2.VideoCapture(str(path))
        elif uri.kind == "rtsp":
            check_reachable(uri.path)
            capture = cv2.VideoCapture(uri.path, cv2.CAP_FFMPEG,
                                       [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, OPEN_TIMEOUT_MS,
                                        cv2.CAP_PROP_READ_TIMEOUT_MSEC, OPEN_TIMEOUT_MS])
        elif uri.path.startswith("csi://"):
            if not has_gstreamer(cv2):
                raise self.fail("CSI cameras are read through GStreamer's nvarguscamerasrc "
                                "(NVIDIA Jetson), and this OpenCV is built without "
                                "GStreamer; use v4l2:///dev/videoN or device:N")
            pipeline = (f"nvarguscamerasrc sensor-id={uri.index} ! video/x-raw(memory:NVMM) "
                        "! nvvidconv ! video/x-raw,format=BGRx ! videoconvert ! "
                        "video/x-raw,format=BGR ! appsink drop=1")
            capture = cv2.VideoCapture(pipeline, cv2.CAP_GSTREAMER)
        else:
            device = uri.path or f"/dev/video{uri.index}"
            if os.name == "posix" and Path("/dev").is_dir() and not Path(device).exists():
                found = video_devices()
                raise self.fail(f"no camera {device} here (cameras: "
                                f"{', '.join(found) if found else 'none'})")
            capture = cv2.VideoCapture(uri.path if uri.path else uri.index)
        if not capture.isOpened():
            capture.release()
            raise self.fail("OpenCV cannot open it" + (
                " (not a video, or a damaged or truncated one?)" if uri.kind == "video"
                else ""))
        self.capture = capture
        self.expected = max(int(capture.get(cv2.CAP_PROP_FRAME_COUNT)), 0) \
            if uri.kind == "video" else 0
        width = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        return (height, width) if width > 0 and height > 0 else None

    def read(self) -> np.ndarray | None:
        ok, bgr = self.capture.read()
        if not ok or bgr is None:
            if self.uri.kind == "video" and self.expected and self.frames < self.expected - 1:
                raise self.fail(f"frame {self.frames} cannot be decoded: the file says it has "
                                f"{self.expected} frames (damaged or truncated?)")
            return None
        self.frames += 1
        return to_rgb(bgr, "gray" if bgr.ndim == 2 else "bgr")

    def close(self) -> None:
        if self.capture is not None:
            capture, self.capture = self.capture, None
            capture.release()
