"""MaskWriter: a standard sink that finds the objects in a mask and saves what it found.

For every frame it gets the camera's image and a black-and-white mask of the same size
(255 = object). Connected white regions (8-connected, scipy.ndimage.label) of at least
``min_area`` pixels are the objects; their bounding boxes are printed, kept in
``history`` (the latest frames only, so memory stays flat), and, with a ``folder`` (or the
generated program's ``--save-images DIR``), written as two PNGs per frame:
``mask_NNNNNN.png`` (the mask as it arrived) and ``annotated_NNNNNN.png`` (the image with
the mask's pixels tinted and each object boxed in green).  With ``output`` (a gpucompgen.io
sink URI: ``display://``, ``out.mp4``, a folder, ``mcap://out.mcap``) the annotated frames
and the masks go there too, as the outputs ``annotated`` and ``mask``.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gpucompgen.runtime import PipelineError, Size

BOX_COLOUR = (0, 255, 0)
TINT = np.array([255, 0, 255], np.uint16)  # magenta: visible on red, skin and sky


@dataclass(frozen=True)
class Box:
    """An object's bounding box (pixels) and its area (white pixels)."""

    x: int
    y: int
    width: int
    height: int
    area: int


def find_objects(mask: np.ndarray, min_area: int) -> list[Box]:
    """The mask's 8-connected white regions of at least min_area pixels, top to bottom."""
    from scipy import ndimage

    labels, count = ndimage.label(mask > 0, structure=np.ones((3, 3), bool))
    if count == 0:
        return []
    areas = np.bincount(labels.ravel(), minlength=count + 1)
    boxes = []
    for k, (rows, cols) in enumerate(ndimage.find_objects(labels), start=1):
        if areas[k] >= min_area:
            boxes.append(Box(cols.start, rows.start, cols.stop - cols.start,
                             rows.stop - rows.start, int(areas[k])))
    return sorted(boxes, key=lambda b: (b.y, b.x))


def annotate(image: np.ndarray, mask: np.ndarray, boxes: list[Box]) -> np.ndarray:
    """image with the mask's pixels tinted half-way to magenta and every box outlined."""
    out = image.copy()
    hit = mask > 0
    out[hit] = ((image[hit].astype(np.uint16) + TINT) // 2).astype(np.uint8)
    for b in boxes:
        x0, y0, x1, y1 = b.x, b.y, b.x + b.width - 1, b.y + b.height - 1
        for t in range(2):  # two pixels wide, inside the box
            out[y0 + min(t, y1 - y0), x0:x1 + 1] = BOX_COLOUR
            out[y1 - min(t, y1 - y0), x0:x1 + 1] = BOX_COLOUR
            out[y0:y1 + 1, x0 + min(t, x1 - x0)] = BOX_COLOUR
            out[y0:y1 + 1, x1 - min(t, x1 - x0)] = BOX_COLOUR
    return out


class MaskWriter:
    RUNTIME_OPTIONS = ("save_images", "quiet")
    HISTORY = 1000  # the latest frames' objects kept for inspection

    def __init__(self, *, min_area: int = 30, folder: str = "", print_objects: bool = True,
                 output: str = ""):
        self.min_area, self.print_objects = min_area, print_objects
        self.output = output
        self.sink = None
        self.folder = Path(folder) if folder else None
        self.history: deque[list[Box]] = deque(maxlen=self.HISTORY)
        self.frame = 0

    def runtime_options(self, options: dict) -> None:
        """Options of the generated program's command line; they override the params."""
        if options.get("save_images"):
            self.folder = Path(options["save_images"])
        if options.get("quiet"):
            self.print_objects = False

    def initialize(self, image: Size, mask: Size) -> None:
        self.size = image
        if self.folder is not None:
            try:
                import PIL  # noqa: F401  (checked here, before the first frame)
            except ImportError:
                raise PipelineError("saving images needs Pillow: "
                                    "pip install 'gpucompgen[image]'") from None
            try:
                self.folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise PipelineError(f"cannot create image folder {self.folder}: "
                                    f"{exc.strerror}") from None
        if self.output:
            from gpucompgen import io

            self.sink = io.open_sink(self.output)
            self.sink.open()

    def execute(self, image: np.ndarray, mask: np.ndarray) -> None:
        boxes = find_objects(mask, self.min_area)
        self.history.append(boxes)
        if self.print_objects:
            shown = "; ".join(f"{b.width}x{b.height} at ({b.x}, {b.y}), {b.area:,} px"
                              for b in boxes)
            print(f"frame {self.frame}: {len(boxes)} object{'s' if len(boxes) != 1 else ''}"
                  + (f": {shown}" if boxes else ""), flush=True)
        annotated = annotate(image, mask, boxes) if self.sink is not None or self.folder is not None else None
        if self.sink is not None:
            self.sink.write(annotated, "annotated")
            self.sink.write(mask, "mask")
        if self.folder is not None:
            from PIL import Image

            name = f"{self.frame:06d}.png"
            try:
                Image.fromarray(mask).save(self.folder / f"mask_{name}")
                Image.fromarray(annotated).save(
                    self.folder / f"annotated_{name}")
            except OSError as exc:
                raise PipelineError(f"cannot save images in {self.folder}: {exc}") from None
        self.frame += 1

    def report(self) -> dict | None:
        """The objects of the last frame, for --digests (gpucompgen replay compares them)."""
        if not self.history:
            return None
        return {"frame": self.frame - 1, "objects": [asdict(b) for b in self.history[-1]]}

    def free_memory(self) -> None:
        if self.sink is not None:
            sink, self.sink = self.sink, None
            sink.close()
