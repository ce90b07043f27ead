"""Recordings: MCAP files and ROS 2 bags, read and written without a ROS install.

Read: ``mcap://FILE?topic=NAME`` (the ``mcap`` package, ROS 2 messages decoded by
``mcap-ros2-support``, JSON-encoded Foxglove messages too) and ROS 2 bag folders or their
``.db3`` file (``rosbags``).  The image messages: ``sensor_msgs/msg/Image`` and
``CompressedImage``, Foxglove's ``RawImage`` and ``CompressedImage``.  The topic is the one
``?topic=`` names, else the recording's only image topic; otherwise the error lists them.

Write: :class:`McapWriter` writes frames as ``sensor_msgs/msg/Image`` messages, a topic per
output.  The packages are an optional extra: ``pip install 'gpucompgen[recordings]'``.
"""

from __future__ import annotations

import base64
import json
import time
from pathlib import Path

import numpy as np

from gpucompgen.runtime.errors import PipelineError

from .convert import decode_compressed, raw_to_rgb, to_output
from .sources import Source, regular_file_problem
from .uri import Uri

INSTALL = "pip install 'gpucompgen[recordings]'"
RAW = ("sensor_msgs/msg/Image", "sensor_msgs/Image", "foxglove_msgs/msg/RawImage",
       "foxglove.RawImage")
COMPRESSED = ("sensor_msgs/msg/CompressedImage", "sensor_msgs/CompressedImage",
              "foxglove_msgs/msg/CompressedImage", "foxglove.CompressedImage")
IMAGE_TYPES = RAW + COMPRESSED

TIME_MSG = "int32 sec\nuint32 nanosec\n"
HEADER_MSG = "builtin_interfaces/Time stamp\nstring frame_id\n"
SEPARATOR = "=" * 80
IMAGE_MSGDEF = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
    "uint8 is_bigendian\nuint32 step\nuint8[] data\n"
    f"{SEPARATOR}\nMSG: std_msgs/Header\n{HEADER_MSG}"
    f"{SEPARATOR}\nMSG: builtin_interfaces/Time\n{TIME_MSG}")


def need(module: str, what: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise PipelineError(f"{what} needs the '{module.split('.')[0]}' package: "
                            f"{INSTALL}") from None


def field(msg, name: str, default=None):
    """A message field: decoded ROS messages are objects, JSON ones dicts."""
    if isinstance(msg, dict):
        return msg.get(name, default)
    return getattr(msg, name, default)


def message_to_rgb(msg, msgtype: str) -> np.ndarray:
    """An image message of one of IMAGE_TYPES as (H, W, 3) RGB."""
    data = field(msg, "data", b"")
    if isinstance(data, str):  # JSON messages carry bytes as base64
        data = base64.b64decode(data)
    if msgtype in COMPRESSED:
        return decode_compressed(data, str(field(msg, "format", "")))
    return raw_to_rgb(data, str(field(msg, "encoding", "")), int(field(msg, "width", 0)),
                      int(field(msg, "height", 0)), int(field(msg, "step", 0) or 0),
                      bool(field(msg, "is_bigendian", 0)))


def choose_topic(uri: Uri, topics: dict[str, str]) -> str:
    """The image topic to read: topics maps every topic of the recording to its type."""
    images = sorted(t for t, kind in topics.items() if kind in IMAGE_TYPES)
    listed = ", ".join(f"{t} ({topics[t]})" for t in sorted(topics)) or "none"
    where = uri.describe()
    if uri.topic:
        if uri.topic not in topics:
            raise PipelineError(f"{where}: no topic '{uri.topic}'; its topics: {listed}")
        if uri.topic not in images:
            raise PipelineError(f"{where}: topic '{uri.topic}' has {topics[uri.topic]} "
                                f"messages, not images ({', '.join(IMAGE_TYPES[:2])}, "
                                "Foxglove's RawImage or CompressedImage)")
        return uri.topic
    if len(images) == 1:
        return images[0]
    if not images:
        raise PipelineError(f"{where}: no image topic (sensor_msgs/msg/Image or "
                            f"CompressedImage, Foxglove's RawImage or CompressedImage); "
                            f"its topics: {listed}")
    raise PipelineError(f"{where}: {len(images)} image topics ({', '.join(images)}); "
                        f"choose one with ?topic=NAME, e.g. mcap://FILE?topic={images[0]}")


class Recording(Source):
    """A recording's image messages as frames; subclasses give topics() and messages()."""

    def __init__(self, uri: Uri):
        super().__init__(uri)
        self.topic = ""
        self.msgtype = ""
        self.iterator = None

    def open(self) -> tuple[int, int] | None:
        path = Path(self.uri.path)
        if not path.exists():
            raise self.fail(f"{path.resolve()} does not exist")
        topics = self.topics()
        self.topic = choose_topic(self.uri, topics)
        self.msgtype = topics[self.topic]
        # the size is the first message's: read it now, and hand it out as frame 0
        self.iterator = self.messages()
        first = self._next()
        self.pending = first
        return None if first is None else first.shape[:2]

    def _next(self) -> np.ndarray | None:
        try:
            msg = next(self.iterator, None)
        except PipelineError:
            raise
        except Exception as exc:
            where = f"after frame {self.frames - 1}" if self.frames else "before its first frame"
            raise self.fail(f"damaged or truncated {where} on topic {self.topic}: "
                            f"{type(exc).__name__}: {exc}") from None
        if msg is None:
            return None
        try:
            return message_to_rgb(msg, self.msgtype)
        except PipelineError as exc:
            raise self.fail(f"message {self.frames} on {self.topic}: {exc}") from None

    def read(self) -> np.ndarray | None:
        if self.pending is not None:
            frame, self.pending = self.pending, None
        else:
            frame = self._next()
        if frame is not None:
            self.frames += 1
        return frame

    def close(self) -> None:
        self.iterator = None


class McapSource(Recording):
    """An MCAP file's image messages (ROS 2 CDR, or Foxglove JSON)."""

    def __init__(self, uri: Uri):
        super().__init__(uri)
        self.pending = None

    def topics(self) -> dict[str, str]:
        mcap_reader = need("mcap.reader", "reading MCAP recordings")
        problem = regular_file_problem(Path(self.uri.path))
        if problem:
            raise self.fail(problem.replace("an image file", "an MCAP file"))
        topics: dict[str, str] = {}
        summary = None
        try:
            with open(self.uri.path, "rb") as f:
                summary = mcap_reader.make_reader(f).get_summary()
        except Exception:  # no summary (a truncated file): find the channels by reading
            summary = None
        if summary is not None:
            return {c.topic: summary.schemas[c.schema_id].name
                    if c.schema_id in summary.schemas else "" for c in
                    summary.channels.values()}
        from mcap.records import Channel, Schema
        from mcap.stream_reader import StreamReader

        schemas: dict[int, str] = {}
        try:
            with open(self.uri.path, "rb") as f:
                for record in StreamReader(f, emit_chunks=False).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record.name
                    elif isinstance(record, Channel):
                        topics[record.topic] = schemas.get(record.schema_id, "")
        except Exception as exc:
            if not topics:
                raise self.fail(f"not a readable MCAP file: {type(exc).__name__}: "
                                f"{exc}") from None
        return topics

    def messages(self):
        from mcap.reader import NonSeekingReader

        decoders: dict[int, object] = {}
        factory = need("mcap_ros2.decoder", "reading ROS 2 messages in MCAP").DecoderFactory()
        with open(self.uri.path, "rb") as f:
            # read front to back, CRCs checked: a damaged file gives every frame before
            # the damage, then the error (in file order: sorting by time would load it all)
            reader = NonSeekingReader(f, validate_crcs=True)
            for schema, channel, message in reader.iter_messages(topics=[self.topic],
                                                                 log_time_order=False):
                if channel.message_encoding == "json":
                    yield json.loads(message.data)
                    continue
                decode = decoders.get(channel.id)
                if decode is None:
                    decode = factory.decoder_for(channel.message_encoding, schema)
                    if decode is None:
                        raise self.fail(f"topic {self.topic}: messages encoded as "
                                        f"'{channel.message_encoding}' cannot be decoded "
                                        "(ROS 2 CDR and JSON can)")
                    decoders[channel.id] = decode
                yield decode(message.data)


class BagSource(Recording):
    """A ROS 2 bag (a folder with metadata.yaml, or its .db3 file), read with rosbags."""

    def __init__(self, uri: Uri):
        super().__init__(uri)
        self.pending = None
        path = Path(uri.path)
        self.folder = path.parent if path.suffix.lower() == ".db3" else path

    def _reader(self):
        rosbag2 = need("rosbags.rosbag2", "reading ROS 2 bags")
        if not (self.folder / "metadata.yaml").is_file():
            raise self.fail(f"{self.folder} has no metadata.yaml: not a ROS 2 bag folder")
        try:
            reader = rosbag2.Reader(self.folder)
            reader.open()
        except Exception as exc:
            raise self.fail(f"cannot open the bag: {type(exc).__name__}: {exc}") from None
        return reader

    def topics(self) -> dict[str, str]:
        reader = self._reader()
        try:
            return {c.topic: c.msgtype for c in reader.connections}
        finally:
            reader.close()

    def messages(self):
        typesys = need("rosbags.typesys", "reading ROS 2 bags")
        store = typesys.get_typestore(typesys.Stores.LATEST)
        reader = self._reader()
        try:
            connections = [c for c in reader.connections if c.topic == self.topic]
            if self.msgtype not in store.types:
                raise self.fail(f"topic {self.topic}: message type {self.msgtype} is not "
                                "known to rosbags (ROS 2 bags: sensor_msgs images)")
            for connection, _, raw in reader.messages(connections=connections):
                yield store.deserialize_cdr(raw, connection.msgtype)
        finally:
            reader.close()


class McapWriter:
    """Frames as sensor_msgs/msg/Image messages in an MCAP file, a topic per output."""

    def __init__(self, path: Path):
        writer_mod = need("mcap_ros2.writer", "writing MCAP recordings")
        self.path = path
        self.file = open(path, "wb")  # noqa: SIM115  (closed by close(), after finish())
        self.writer = writer_mod.Writer(self.file)
        self.schema = self.writer.register_msgdef("sensor_msgs/msg/Image", IMAGE_MSGDEF)
        self.sequence: dict[str, int] = {}

    def write(self, topic: str, frame: np.ndarray, stamp_ns: int | None = None) -> None:
        array, encoding = to_output(frame)
        height, width = array.shape[:2]
        stamp_ns = time.time_ns() if stamp_ns is None else stamp_ns
        seq = self.sequence.get(topic, 0)
        self.sequence[topic] = seq + 1
        step = width * (3 if encoding == "rgb8" else 1)
        self.writer.write_message(topic, self.schema, {
            "header": {"stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
                       "frame_id": topic.strip("/").replace("/", "_")},
            "height": height, "width": width, "encoding": encoding, "is_bigendian": 0,
            "step": step, "data": array.tobytes()}, log_time=stamp_ns, sequence=seq)

    def close(self) -> None:
        if self.file is not None:
            try:
                self.writer.finish()
            finally:
                self.file.close()
                self.file = None
