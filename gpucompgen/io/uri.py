"""Source and sink URIs, as jetson-inference's videoSource / videoOutput write them.

Sources: a folder of images or a glob (``shots/*.png``), a video file (``file://road.mp4``
or a plain path), a camera (``v4l2:///dev/video0``, ``csi://0``, ``device:0``), a stream
(``rtsp://host:8554/cam``), a recording (``mcap://drive.mcap?topic=/camera/image``, a ROS 2
bag folder or ``rosbag://drive_bag?topic=...``).  Sinks: ``display://``, a video file, a
folder of images, ``mcap://out.mcap``.  A plain path is classified by what it names.

Parsing only looks at the text and, for a plain path, at what exists there; nothing is
opened (see sources.py and sinks.py).
"""

from __future__ import annotations

import glob
import re
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

from gpucompgen.runtime.errors import PipelineError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".ppm", ".bmp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov", ".m4v", ".webm", ".mjpeg", ".h264")
SOURCE_KINDS = ("images", "video", "camera", "rtsp", "mcap", "rosbag")
SINK_KINDS = ("display", "video", "images", "mcap")
SCHEMES = ("file", "v4l2", "csi", "device", "rtsp", "rtsps", "mcap", "rosbag", "display")
EXAMPLES = ("shots/ or 'shots/*.png', file://road.mp4, v4l2:///dev/video0, csi://0, device:0, "
            "rtsp://host:8554/stream, mcap://drive.mcap?topic=/camera/image, rosbag://drive_bag")
SINK_EXAMPLES = "display://, out.mp4, out_frames/, mcap://out.mcap"
QUERY_KEYS = {"mcap": ("topic",), "rosbag": ("topic",)}


class UriError(PipelineError):
    """A source or sink URI that cannot be used: says which and what to write."""


@dataclass(frozen=True)
class Uri:
    """A parsed source or sink: its kind, the path or device, and its query options."""

    text: str  # as written
    kind: str  # one of SOURCE_KINDS or SINK_KINDS
    path: str = ""  # file, folder, glob or device path; the host part of rtsp
    index: int | None = None  # a camera's number (csi://N, device:N, /dev/videoN)
    options: dict = field(default_factory=dict)  # ?topic=... and the like

    @property
    def topic(self) -> str:
        return self.options.get("topic", "")

    def describe(self) -> str:
        names = {"images": "image folder", "video": "video file", "camera": "camera",
                 "rtsp": "stream", "mcap": "MCAP recording", "rosbag": "ROS 2 bag",
                 "display": "display"}
        return f"{names.get(self.kind, self.kind)} '{self.text}'"


SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*):(//)?")
DEVICE = re.compile(r"^/dev/video(\d+)$")


def parse_source(text: str, base: Path | None = None) -> Uri:
    """A source URI; relative paths are taken from base (default: the working folder)."""
    return _parse(text, base, sink=False)


def parse_sink(text: str, base: Path | None = None) -> Uri:
    """A sink URI; a path is a video file by its suffix, an .mcap file, else a folder."""
    return _parse(text, base, sink=True)


def _parse(text: str, base: Path | None, sink: bool) -> Uri:
    role = "output" if sink else "input"
    if not isinstance(text, str) or not text.strip():
        raise UriError(f"empty {role}; write one of: {SINK_EXAMPLES if sink else EXAMPLES}")
    text = text.strip()
    m = SCHEME.match(text)
    scheme = m.group(1).lower() if m else ""
    if m and len(scheme) == 1 and not m.group(2):  # C:\... on Windows: a path
        scheme = ""
    if not scheme:
        return _path_uri(text, _resolve(text, base), sink, {})
    if scheme not in SCHEMES:
        raise UriError(f"unknown {role} scheme '{scheme}:' in '{text}'; write one of: "
                       + (SINK_EXAMPLES if sink else EXAMPLES))
    if scheme == "device":
        rest = text[m.end():]
        if sink:
            raise UriError(f"'{text}' is a camera, not an output; write one of: {SINK_EXAMPLES}")
        if not rest.isdigit():
            raise UriError(f"'{text}' is not a camera; write device:N, e.g. device:0")
        return Uri(text, "camera", index=int(rest))
    if not m.group(2):
        raise UriError(f"'{text}': write {scheme}://..., e.g. "
                       + {"file": "file://road.mp4", "v4l2": "v4l2:///dev/video0",
                          "csi": "csi://0", "rtsp": "rtsp://host:8554/stream",
                          "rtsps": "rtsps://host/stream", "mcap": "mcap://drive.mcap",
                          "rosbag": "rosbag://drive_bag", "display": "display://"}[scheme])
    parts = urlsplit(text)
    options = dict(parse_qsl(parts.query, keep_blank_values=True))
    allowed = QUERY_KEYS.get(scheme, ())
    for key in options:
        if key not in allowed:
            raise UriError(f"'{text}': unknown option '?{key}='"
                           + (f"; {scheme}:// takes {', '.join('?' + k + '=' for k in allowed)}"
                              if allowed else f"; {scheme}:// takes no options"))
    if parts.fragment:
        raise UriError(f"'{text}': a '#' has no meaning here; percent-encode it as %23")
    # everything after scheme:// up to '?' is the path (netloc + path: mcap://rel/a.mcap)
    rest = text[m.end():].split("?", 1)[0]
    if scheme == "display":
        if not sink:
            raise UriError(f"'{text}' is an output; an input is one of: {EXAMPLES}")
        if rest and not rest.isdigit():
            raise UriError(f"'{text}': write display:// or display://N (window N)")
        return Uri(text, "display", index=int(rest) if rest else 0)
    if scheme in ("v4l2", "csi"):
        if sink:
            raise UriError(f"'{text}' is a camera, not an output; write one of: {SINK_EXAMPLES}")
        if scheme == "csi":
            if not rest.isdigit():
                raise UriError(f"'{text}': write csi://N, the sensor's number, e.g. csi://0")
            return Uri(text, "camera", path=f"csi://{rest}", index=int(rest))
        d = DEVICE.match(rest)
        if not d:
            raise UriError(f"'{text}': write v4l2:///dev/videoN, e.g. v4l2:///dev/video0")
        return Uri(text, "camera", path=rest, index=int(d.group(1)))
    if scheme in ("rtsp", "rtsps"):
        if sink:
            raise UriError(f"'{text}': streaming out is not supported; write one of: "
                           + SINK_EXAMPLES)
        if not parts.hostname:
            raise UriError(f"'{text}' names no host; write rtsp://HOST[:PORT]/PATH")
        try:
            parts.port  # noqa: B018  (validates it)
        except ValueError:
            raise UriError(f"'{text}': the port is not a number from 0 to 65535") from None
        return Uri(text, "rtsp", path=text)
    if not rest:
        raise UriError(f"'{text}' names no file")
    path = _resolve(rest, base)
    if scheme == "mcap":
        return Uri(text, "mcap", path=path, options=options)
    if scheme == "rosbag":
        if sink:
            raise UriError(f"'{text}': write recordings as mcap://FILE.mcap")
        return Uri(text, "rosbag", path=path, options=options)
    return _path_uri(text, path, sink, options)  # file://


def _resolve(path: str, base: Path | None) -> str:
    p = Path(path).expanduser()
    if base is not None and not p.is_absolute():
        p = Path(base) / p
    return str(p)


def _path_uri(text: str, path: str, sink: bool, options: dict) -> Uri:
    p = Path(path)
    suffix = p.suffix.lower()
    if sink:
        if suffix in VIDEO_SUFFIXES:
            return Uri(text, "video", path=path)
        if suffix == ".mcap":
            return Uri(text, "mcap", path=path, options=options)
        if suffix in IMAGE_SUFFIXES:
            raise UriError(f"'{text}' is one image; write a folder (frames are saved as "
                           "NNNNNN.png in it) or a video file such as out.mp4")
        return Uri(text, "images", path=path)
    if glob.has_magic(path):
        return Uri(text, "images", path=path)
    if suffix in IMAGE_SUFFIXES:
        return Uri(text, "images", path=path)  # one image
    if suffix == ".mcap":
        return Uri(text, "mcap", path=path, options=options)
    if suffix == ".db3" or (p.is_dir() and (p / "metadata.yaml").is_file()):
        return Uri(text, "rosbag", path=path, options=options)
    if p.is_dir():
        return Uri(text, "images", path=path)
    if suffix in VIDEO_SUFFIXES or p.is_file():
        return Uri(text, "video", path=path)
    if not p.exists():
        if suffix:
            return Uri(text, "video", path=path)  # reported missing when opened
        return Uri(text, "images", path=path)
    raise UriError(f"'{text}' is neither a folder, a glob, a video nor a recording")
