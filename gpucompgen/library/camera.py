"""Camera: a standard source component.

By default it renders deterministic synthetic underwater frames: blue-green water with a
vertical gradient and seeded noise, and red buoys that bob along known paths.  The same
seed always gives the same frames, and :meth:`Camera.ground_truth` tells where every buoy
is in any frame, so tests can check what the pipeline detected.

Real inputs: ``source``, a URI of gpucompgen.io — a folder or glob of images, a video file,
a camera (``v4l2:///dev/video0``, ``csi://0``, ``device:0``), an RTSP stream, an MCAP file
or ROS 2 bag (``mcap://drive.mcap?topic=/camera/image``) — or the older ``folder`` (images)
and ``video`` (a video file or ``device:N``).  Frames are converted to RGB at the edge;
every frame must have the size the system was built for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gpucompgen.runtime import PipelineError, Size

NOISE_FIELDS = 4  # pre-rendered noise fields, cycled, so a frame costs little CPU
RED = np.array((210, 30, 35), np.int16)  # a buoy's colour, before noise


@dataclass(frozen=True)
class Buoy:
    x: int  # centre column
    y: int  # centre row
    radius: int


class Camera:
    RUNTIME_OPTIONS = ("drop",)

    def __init__(self, *, width: int = 640, height: int = 480, seed: int = 1, buoys: int = 2,
                 frames: int = 0, folder: str = "", video: str = "", source: str = ""):
        self.width, self.height, self.seed = width, height, seed
        self.buoys, self.frames, self.folder, self.video = buoys, frames, folder, video
        self.source = source
        self.frame = 0
        self.reader = None  # a gpucompgen.io Source, for real inputs
        self.drop = False  # --drop: read in a thread, keep only the newest frame
        self._dropped = 0
        self.background = None
        self.noise: list[np.ndarray] = []
        self.water: list[np.ndarray] = []

    # -- the component interface ------------------------------------------------------
    def runtime_options(self, options: dict) -> None:
        """--drop: when the pipeline falls behind a live input, frames are dropped (and
        counted) instead of queued."""
        self.drop = bool(options.get("drop"))

    @property
    def dropped_frames(self) -> int:
        """Frames --drop dropped (kept after free_memory, for the run's summary)."""
        return getattr(self.reader, "dropped", self._dropped)

    def initialize(self) -> Size:
        given = [k for k in ("source", "folder", "video") if getattr(self, k)]
        if len(given) > 1:
            raise PipelineError(f"set one of 'source', 'folder' and 'video', not "
                                f"{' and '.join(given)}")
        if given:
            self.reader = self._open(getattr(self, given[0]), given[0])
        else:
            rng = np.random.default_rng(self.seed)
            rows = np.linspace(0.0, 1.0, self.height, dtype=np.float32)[:, None]
            bg = np.empty((self.height, self.width, 3), np.int16)
            bg[..., 0] = 12
            bg[..., 1] = (150 - 60 * rows).astype(np.int16)  # lighter near the surface
            bg[..., 2] = (190 - 70 * rows).astype(np.int16)
            self.background = bg
            self.noise = [rng.integers(-12, 13, size=bg.shape, dtype=np.int16)
                          for _ in range(NOISE_FIELDS)]
            # the water of each noise field, rendered once: a frame is a copy of one with
            # the buoys drawn on it (the same bytes as adding and clipping every frame)
            self.water = [np.clip(bg + noise, 0, 255).astype(np.uint8) for noise in self.noise]
        return Size(self.height, self.width, 3)

    def execute(self) -> np.ndarray | None:
        """The next RGB frame (height x width x 3, uint8), or None at the end of the stream."""
        if self.frames and self.frame >= self.frames:
            return None
        if self.reader is not None:
            image = self.reader.read()
            if image is None:
                return None
            if image.shape[:2] != (self.height, self.width):
                raise PipelineError(
                    f"frame {self.frame} of {self.reader.uri.describe()} is "
                    f"{image.shape[1]}x{image.shape[0]} (width x height), but the system was "
                    f"built for {self.width}x{self.height}; {SIZE_HINT}")
        else:
            image = self.render(self.frame)
        self.frame += 1
        return image

    def free_memory(self) -> None:
        self.background = None
        self.noise = []
        self.water = []
        if self.reader is not None:
            reader, self.reader = self.reader, None
            reader.close()
            self._dropped = getattr(reader, "dropped", 0)

    # -- synthetic scene ----------------------------------------------------------------
    def ground_truth(self, frame: int) -> list[Buoy]:
        """Where the buoys are in a synthetic frame: a pure function of seed and frame.

        Each buoy bobs in its own lane of the frame (so buoys never touch) and drifts
        nearer and farther: its radius grows from a far size to a near one and back, so
        which buoy is largest, and whether one is close, changes over the stream.
        """
        rng = np.random.default_rng([self.seed, 7919])
        lanes = max(self.buoys, 1)
        lane = self.width / lanes
        result = []
        for i in range(self.buoys):
            far = int(rng.integers(max(4, self.height // 40), max(5, self.height // 12) + 1))
            near = int(rng.integers(max(far + 1, self.height // 10),
                                    max(far + 2, self.height // 7) + 1))
            near = min(near, int(lane // 2) - 3, self.height // 2 - 3)
            far = min(far, near)
            if far < 2:
                continue
            period = float(rng.uniform(40, 120))
            phase = float(rng.uniform(0, 2 * math.pi))
            approach = float(rng.uniform(50, 150))  # frames from far to near and back
            approach_phase = float(rng.uniform(0, 2 * math.pi))
            closeness = (0.5 + 0.5 * math.sin(2 * math.pi * frame / approach
                                              + approach_phase)) ** 3
            radius = round(far + (near - far) * closeness)
            # bounds for the nearest size, so the disk stays in its lane and the frame
            lo, hi = i * lane + near + 2, (i + 1) * lane - near - 3
            swing = (hi - lo) / 2
            x = lo + swing + swing * math.sin(2 * math.pi * frame / period + phase)
            ylo, yhi = near + 2, self.height - near - 3
            ymid = float(rng.uniform(ylo, yhi))
            yamp = min(ymid - ylo, yhi - ymid, self.height / 8)
            y = ymid + yamp * math.sin(2 * math.pi * frame / (period * 1.7) + phase)
            result.append(Buoy(round(x), round(y), radius))
        return result

    def render(self, frame: int) -> np.ndarray:
        if self.background is None:
            raise PipelineError("execute() before initialize()")
        img = self.water[frame % NOISE_FIELDS].copy()
        for b in self.ground_truth(frame):
            y0, y1 = b.y - b.radius, b.y + b.radius + 1
            x0, x1 = b.x - b.radius, b.x + b.radius + 1
            yy, xx = np.ogrid[y0:y1, x0:x1]
            disk = (yy - b.y) ** 2 + (xx - b.x) ** 2 <= b.radius ** 2
            red = np.clip(RED + self.noise[(frame + 1) % NOISE_FIELDS][y0:y1, x0:x1], 0, 255)
            np.copyto(img[y0:y1, x0:x1], red, casting="unsafe", where=disk[..., None])
        return img

    # -- real inputs ------------------------------------------------------------------
    def _open(self, spec: str, param: str):
        from gpucompgen import io

        if param == "folder":
            uri = io.parse_source(spec)
            if uri.kind != "images":
                raise PipelineError(f"'folder' is '{spec}', which is not a folder or glob of "
                                    "images; set 'source' for other inputs")
        elif param == "video":
            uri = io.parse_source(spec)
            if uri.kind not in ("video", "camera"):
                raise PipelineError(f"'video' is '{spec}', which is not a video file or a "
                                    "camera; set 'source' for other inputs")
        else:
            uri = io.parse_source(spec)
        reader = io.open_source(uri)
        if self.drop:
            from gpucompgen.io.live import DropFrames

            reader = DropFrames(reader)
        size = reader.open()
        if size is not None and size != (self.height, self.width):
            reader.close()
            raise PipelineError(
                f"{uri.describe()} has frames of {size[1]}x{size[0]} (width x height), but "
                f"the system was built for {self.width}x{self.height}; {SIZE_HINT}")
        return reader


SIZE_HINT = "set the camera's width and height params to the input's size"
