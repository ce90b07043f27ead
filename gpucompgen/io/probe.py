"""The frame size of an input, read from a header when a model is checked or built: an
image file's header, a video container's, a recording's first image message.  Nothing of
the user's is imported or run; live inputs (cameras, streams) have no size until they run.
"""

from __future__ import annotations

from pathlib import Path

from .sources import open_source
from .uri import parse_source

LIVE = ("camera", "rtsp")


def probe_size(text: str, base: Path | None = None) -> tuple[int, int] | None:
    """(height, width) of the input a URI names, None for a live one; PipelineError when it
    is missing, empty or unreadable."""
    uri = parse_source(text, base)
    if uri.kind in LIVE:
        return None
    source = open_source(uri)
    try:
        return source.open()
    finally:
        source.close()
