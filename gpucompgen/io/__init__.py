"""Sources and sinks named by URI: image folders, video, cameras, streams, recordings.

``open_source("mcap://drive.mcap?topic=/cam")`` and ``open_sink("out.mp4")``; the URI
forms are in uri.py and docs/inputs-outputs.md.  The library's Camera, FrameSink and
MaskWriter use them; a generated program's ``--input`` and ``--output`` choose them.
"""

from .convert import ENCODINGS, raw_to_rgb, to_rgb
from .sinks import Sink, available_codecs, describe_codecs, open_sink
from .sources import Source, open_source
from .uri import Uri, UriError, parse_sink, parse_source

__all__ = ["ENCODINGS", "Sink", "Source", "Uri", "UriError", "available_codecs",
           "describe_codecs", "open_sink", "open_source", "parse_sink", "parse_source",
           "raw_to_rgb", "to_rgb"]
