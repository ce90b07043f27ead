"""Frame sinks: a window, a video file, a folder of images, an MCAP recording.

``open_sink(uri)`` returns a sink whose ``write(frame, name)`` takes an RGB or gray uint8
frame of one named output (a sink with several outputs, such as the MaskWriter's annotated
image and mask, names each); ``close()`` finishes the file.  Video and image folders keep
one file or folder per output beyond the first (``out.mp4`` and ``out_mask.mp4``); an MCAP
file keeps one topic per output.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

from gpucompgen.runtime.errors import PipelineError

from .convert import cv2_or_fail, to_output
from .uri import Uri, parse_sink

VIDEO_FPS = 30.0
# codecs tried for each container, best first (FourCC)
CODECS = {".mp4": ("avc1", "H264", "mp4v"), ".m4v": ("avc1", "mp4v"), ".mov": ("avc1", "mp4v"),
          ".mkv": ("H264", "X264", "XVID", "MJPG"), ".avi": ("XVID", "MJPG"),
          ".webm": ("VP80", "VP90"), ".mjpeg": ("MJPG",), ".h264": ("H264",)}
CODEC_NAMES = {"avc1": "H.264", "H264": "H.264", "X264": "H.264", "mp4v": "MPEG-4 Part 2",
               "XVID": "MPEG-4 Part 2 (Xvid)", "MJPG": "Motion JPEG", "VP80": "VP8",
               "VP90": "VP9"}


def available_codecs(suffix: str = ".mp4") -> list[str]:
    """The FourCCs this OpenCV can write into a `suffix` file (tried on a tiny video)."""
    import tempfile

    cv2 = cv2_or_fail("writing video")
    found = []
    with tempfile.TemporaryDirectory() as tmp:
        for fourcc in CODECS.get(suffix, ()):
            path = os.path.join(tmp, f"probe_{fourcc}{suffix}")
            if _silenced(lambda p=path, f=fourcc: _probe(cv2, p, f)):
                found.append(fourcc)
    return found


def _probe(cv2, path: str, fourcc: str) -> bool:
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*fourcc), VIDEO_FPS, (16, 16))
    ok = writer.isOpened()
    if ok:
        writer.write(np.zeros((16, 16, 3), np.uint8))
    writer.release()
    return ok and os.path.getsize(path) > 0


def _silenced(call):
    """OpenCV's FFmpeg prints to fd 2 when a codec is missing; hide it while probing."""
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            return call()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class Sink:
    def __init__(self, uri: Uri):
        self.uri = uri
        self.frames: dict[str, int] = {}

    def open(self) -> None:
        pass

    def write(self, frame: np.ndarray, name: str = "image") -> None:
        raise NotImplementedError  # pragma: no cover

    def close(self) -> None:
        pass

    def fail(self, what: str) -> PipelineError:
        return PipelineError(f"output {self.uri.describe()}: {what}")

    def count(self, name: str) -> int:
        n = self.frames.get(name, 0)
        self.frames[name] = n + 1
        return n


def open_sink(text: str | Uri, base: Path | None = None) -> Sink:
    uri = text if isinstance(text, Uri) else parse_sink(text, base)
    return {"display": Display, "video": VideoFile, "images": ImageFolder,
            "mcap": McapFile}[uri.kind](uri)


def _writable_folder(sink: Sink, folder: Path) -> None:
    if not folder.is_dir():
        raise sink.fail(f"folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise sink.fail(f"folder {folder} is not writable")


def _named(path: Path, name: str, first: str) -> Path:
    """The file of output `name`: the path itself for the first output, else path_name."""
    return path if name == first else path.with_name(f"{path.stem}_{name}{path.suffix}")


class ImageFolder(Sink):
    """PNG files NNNNNN.png in a folder (name_NNNNNN.png for every output but the first)."""

    def open(self) -> None:
        from .sources import pillow

        pillow()
        self.folder = Path(self.uri.path)
        if self.folder.exists() and not self.folder.is_dir():
            raise self.fail("exists and is not a folder")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise self.fail(f"cannot create the folder: {exc.strerror}") from None
        self.first = None

    def write(self, frame: np.ndarray, name: str = "image") -> None:
        from .sources import pillow

        self.first = self.first or name
        n = self.count(name)
        array, _ = to_output(frame)
        prefix = "" if name == self.first else f"{name}_"
        try:
            pillow().fromarray(array).save(self.folder / f"{prefix}{n:06d}.png")
        except OSError as exc:
            raise self.fail(f"cannot save frame {n}: {exc}") from None


class VideoFile(Sink):
    """A video file per output (OpenCV's VideoWriter), H.264 where this OpenCV has it."""

    def open(self) -> None:
        self.cv2 = cv2_or_fail("writing video")
        self.path = Path(self.uri.path)
        _writable_folder(self, self.path.parent if str(self.path.parent) else Path("."))
        self.suffix = self.path.suffix.lower()
        self.writers: dict[str, object] = {}
        self.first = None
        self.codec = ""

    def _writer(self, name: str, shape) -> object:
        cv2 = self.cv2
        path = _named(self.path, name, self.first)
        height, width = shape[:2]
        for fourcc in CODECS.get(self.suffix, ("mp4v",)):
            writer = _silenced(lambda f=fourcc: cv2.VideoWriter(
                str(path), cv2.VideoWriter_fourcc(*f), VIDEO_FPS, (width, height)))
            if writer.isOpened():
                self.codec = self.codec or fourcc
                return writer
            writer.release()
        raise self.fail(f"OpenCV cannot write {self.suffix} video here (tried "
                        f"{', '.join(CODECS.get(self.suffix, ('mp4v',)))}); codecs that work: "
                        + describe_codecs())

    def write(self, frame: np.ndarray, name: str = "image") -> None:
        self.first = self.first or name
        array, encoding = to_output(frame)
        writer = self.writers.get(name)
        if writer is None:
            writer = self.writers[name] = self._writer(name, array.shape)
        self.count(name)
        cv2 = self.cv2
        bgr = cv2.cvtColor(array, cv2.COLOR_GRAY2BGR if encoding == "mono8"
                           else cv2.COLOR_RGB2BGR)
        writer.write(bgr)

    def close(self) -> None:
        for writer in self.writers.values():
            writer.release()
        self.writers = {}


def describe_codecs() -> str:
    """The codecs that work for each container, e.g. '.mp4: mp4v (MPEG-4 Part 2)'."""
    parts = []
    for suffix in (".mp4", ".avi", ".mkv"):
        found = available_codecs(suffix)
        parts.append(f"{suffix}: " + (", ".join(f"{c} ({CODEC_NAMES.get(c, c)})"
                                                for c in found) or "none"))
    return "; ".join(parts)


class Display(Sink):
    """A window per output (OpenCV's highgui)."""

    def open(self) -> None:
        cv2 = cv2_or_fail("showing frames")
        self.cv2 = cv2
        if os.name == "posix" and not (os.environ.get("DISPLAY")
                                       or os.environ.get("WAYLAND_DISPLAY")):
            raise self.fail("no display here (DISPLAY is not set); write the frames to a "
                            "video (out.mp4) or a folder (out/) instead")
        try:
            cv2.namedWindow("gpucompgen", cv2.WINDOW_NORMAL)
        except cv2.error:
            raise self.fail("this OpenCV has no window support (opencv-python-headless); "
                            "pip install opencv-python, or write to a video or a folder") \
                from None

    def write(self, frame: np.ndarray, name: str = "image") -> None:
        array, encoding = to_output(frame)
        self.count(name)
        cv2 = self.cv2
        cv2.imshow(name, cv2.cvtColor(array, cv2.COLOR_GRAY2BGR if encoding == "mono8"
                                      else cv2.COLOR_RGB2BGR))
        cv2.waitKey(1)

    def close(self) -> None:
        with contextlib.suppress(Exception):  # a window the user closed already
            self.cv2.destroyAllWindows()


class McapFile(Sink):
    """sensor_msgs/msg/Image messages, a topic per output: /NAME, or ?topic=PREFIX/NAME."""

    def open(self) -> None:
        from .recordings import McapWriter

        path = Path(self.uri.path)
        _writable_folder(self, path.parent if str(path.parent) else Path("."))
        self.writer = McapWriter(path)

    def write(self, frame: np.ndarray, name: str = "image") -> None:
        n = self.count(name)
        prefix = self.uri.topic.rstrip("/")
        stamp = n * 10**9 // 30  # 30 frames a second, from 0: the same file every run
        self.writer.write(f"{prefix}/{name}", frame, stamp)

    def close(self) -> None:
        if getattr(self, "writer", None) is not None:
            self.writer.close()
            self.writer = None
