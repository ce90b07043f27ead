"""VisionManager: a standard sink that turns a black-and-white mask into movement decisions.

Sinks: one line per frame on stdout (print_decisions), JSON lines to decisions_file, and
the runtime options of the generated program (see RUNTIME_OPTIONS): --decisions FILE
(JSON lines for .jsonl/.json, else the text lines), --save-images DIR (mask_NNNNNN.png and
annotated_NNNNNN.png per frame, with Pillow), --quiet (no lines on stdout).
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from gpucompgen.runtime import PipelineError, Size

ACTIONS = ("forward", "turn_left", "turn_right", "stop", "search")


@dataclass(frozen=True)
class Sighting:
    x: float  # centroid column in the mask
    y: float  # centroid row
    area: int  # pixels
    radius: float  # half the extent of its bounding box: exact for a disk


@dataclass
class Decision:
    frame: int
    action: str
    target: Sighting | None
    sightings: list[Sighting] = field(default_factory=list)

    def line(self) -> str:
        seen = " ".join(f"({s.x:.0f},{s.y:.0f} r={s.radius:.0f})" for s in self.sightings)
        return f"frame {self.frame}: {self.action:<10} buoys: {seen or 'none'}"


def decide(sightings: list[Sighting], width: int, stop_radius: float) -> tuple[str, Sighting | None]:
    """Head for the largest object: stop when it is close, turn to keep it centred."""
    if not sightings:
        return "search", None
    target = max(sightings, key=lambda s: (s.area, -s.x))
    if target.radius >= stop_radius:
        return "stop", target
    if target.x < width / 3:
        return "turn_left", target
    if target.x >= 2 * width / 3:
        return "turn_right", target
    return "forward", target


# Above this many candidate rectangles, labelling the whole mask at once is cheaper than
# one small labelling per rectangle (each costs tens of microseconds of call overhead).
MAX_RECTANGLES = 48


def find_sightings(mask: np.ndarray, min_area: int) -> list[Sighting]:
    """The objects of at least min_area pixels in a 2-D mask (non-zero is foreground).

    Objects are 4-connected components, as scipy.ndimage.label finds them. Each object's
    centroid is its pixels' mean row and column (integer sums, one division: the same
    float as scipy.ndimage.center_of_mass), its area its pixel count, its radius half the
    extent of its bounding box. Sorted by (x, y); objects with the same centroid keep the
    order of their first pixel in raster order, which is scipy's label order.

    Fast on the masks a camera gives (a few objects, mostly background): a connected
    component never crosses an empty row or an empty column, so only the rectangles that
    the empty rows and columns leave (see _rectangles) are labelled and measured. Each
    pixel of the mask is read twice (the test for non-zero, the profile of its rows);
    the rest costs as much as the objects' surroundings are large. A mask cut into more
    than MAX_RECTANGLES rectangles (noise, many specks) is labelled whole instead, and
    measured with bincount over its labels: a few passes, however many objects.
    """
    foreground = mask > 0
    height, width = foreground.shape
    rectangles = _rectangles(foreground)
    if len(rectangles) > MAX_RECTANGLES:
        rectangles = [(0, height, 0, width)]
    found = []  # (x, y, first pixel in raster order, Sighting)
    for y0, y1, x0, x1 in rectangles:
        found.extend(_measure(foreground[y0:y1, x0:x1], y0, x0, width, min_area))
    found.sort(key=lambda item: item[:3])
    return [item[3] for item in found]


def _runs(occupied: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True in a 1-D boolean array (not empty)."""
    edges = (np.flatnonzero(occupied[1:] != occupied[:-1]) + 1).tolist()
    if occupied[0]:
        edges.insert(0, 0)
    if occupied[-1]:
        edges.append(len(occupied))
    return list(zip(edges[::2], edges[1::2]))


def _rectangles(foreground: np.ndarray) -> list[tuple[int, int, int, int]]:
    """(y0, y1, x0, x1) rectangles that hold every foreground pixel, none split by an object.

    No 4-connected (nor 8-connected) component crosses an empty row or column, so the mask
    is cut along its empty rows into bands, each band along its empty columns, and each
    piece again along its empty rows (an XY cut, three levels deep): each component lies
    in exactly one rectangle, and on a camera's mask the rectangles are about the objects'
    bounding boxes. Stops early (returning more than MAX_RECTANGLES) on a cluttered mask.
    """
    rectangles = [(0, foreground.shape[0], 0, foreground.shape[1])]
    for axis in (1, 0, 1):  # rows (reduce along x), columns, rows
        pieces = []
        for y0, y1, x0, x1 in rectangles:
            occupied = foreground[y0:y1, x0:x1].any(axis=axis)
            for a, b in _runs(occupied):
                pieces.append((y0 + a, y0 + b, x0, x1) if axis == 1 else (y0, y1, x0 + a, x0 + b))
            if len(pieces) > MAX_RECTANGLES:
                return pieces
        rectangles = pieces
    return rectangles


STRUCTURE = ndimage.generate_binary_structure(2, 1)  # 4-connectivity, scipy's default


def _measure(part: np.ndarray, y0: int, x0: int, width: int, min_area: int) -> list:
    """The objects of at least min_area pixels in part, a rectangle at (y0, x0) of the mask.

    Returns (x, y, first pixel's index in the mask, Sighting) for each.
    """
    if part.size < min_area or np.count_nonzero(part) < min_area:
        return []  # no object that large fits
    labels, count = ndimage.label(part, STRUCTURE)
    if count == 1:  # the usual case: the statistics from the row and column profiles
        row_counts = np.count_nonzero(part, axis=1)
        col_counts = np.count_nonzero(part, axis=0)
        filled_rows, filled_cols = np.flatnonzero(row_counts), np.flatnonzero(col_counts)
        areas = [0, int(row_counts.sum())]
        row_sums = [0, int(row_counts @ np.arange(part.shape[0]))]
        col_sums = [0, int(col_counts @ np.arange(part.shape[1]))]
        boxes = [(slice(int(filled_rows[0]), int(filled_rows[-1]) + 1),
                  slice(int(filled_cols[0]), int(filled_cols[-1]) + 1))]
    else:
        flat = labels.ravel()
        pixels = np.flatnonzero(flat)
        owner = flat[pixels]
        areas = np.bincount(owner, minlength=count + 1)
        rows, cols = np.divmod(pixels, part.shape[1])
        # float64 sums of integer coordinates are exact (below 2**53), as are scipy's
        row_sums = np.bincount(owner, weights=rows, minlength=count + 1)
        col_sums = np.bincount(owner, weights=cols, minlength=count + 1)
        boxes = ndimage.find_objects(labels)
    found = []
    for k in range(1, count + 1):
        area = int(areas[k])
        if area < min_area:
            continue
        box_rows, box_cols = boxes[k - 1]
        # the sums of the mask's coordinates, as integers, then one division, as scipy's
        # center_of_mass does (its float64 sums of integers are exact): the same float
        y = (int(row_sums[k]) + y0 * area) / area
        x = (int(col_sums[k]) + x0 * area) / area
        # a digital disk of radius r spans 2r + 1 pixels each way; its area is
        # a little under pi r^2, which would put r = 60 at 59.99
        radius = (box_rows.stop - box_rows.start + box_cols.stop - box_cols.start - 2) / 4
        top = box_rows.start
        first_col = box_cols.start + int(np.argmax(labels[top, box_cols] == k))
        first = (y0 + top) * width + x0 + first_col
        found.append((x, y, first, Sighting(x, y, area, radius)))
    return found


class VisionManager:
    RUNTIME_OPTIONS = ("decisions", "save_images", "quiet")
    HISTORY = 1000  # the latest decisions kept for inspection: memory stays flat for hours

    def __init__(self, *, min_area: int = 30, stop_radius: int = 60,
                 print_decisions: bool = True, decisions_file: str = ""):
        self.min_area, self.stop_radius = min_area, stop_radius
        self.print_decisions, self.decisions_file = print_decisions, decisions_file
        self.decisions_json = True
        self.images: Path | None = None
        self.history: deque[Decision] = deque(maxlen=self.HISTORY)
        self.frame = 0
        self.size: Size | None = None
        self._out = None

    def runtime_options(self, options: dict) -> None:
        """Options of the generated program's command line; they override the params."""
        if options.get("decisions"):
            self.decisions_file = options["decisions"]
            self.decisions_json = Path(self.decisions_file).suffix.lower() in (".jsonl", ".json")
        if options.get("save_images"):
            self.images = Path(options["save_images"])
        if options.get("quiet"):
            self.print_decisions = False

    def initialize(self, mask: Size) -> None:
        self.size = Size(*mask)
        if self.images is not None:
            try:
                import PIL  # noqa: F401  (checked here, before the first frame)
            except ImportError:
                raise PipelineError("saving images needs Pillow: "
                                    "pip install 'gpucompgen[image]'") from None
            try:
                self.images.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise PipelineError(f"cannot create image folder {self.images}: "
                                    f"{exc.strerror}") from None
        if self.decisions_file:
            try:
                self._out = open(self.decisions_file, "w", encoding="utf-8")  # noqa: SIM115
            except OSError as exc:
                raise PipelineError(f"cannot write decisions to {self.decisions_file}: "
                                    f"{exc.strerror}") from None

    def execute(self, mask: np.ndarray) -> None:
        sightings = find_sightings(mask, self.min_area)
        action, target = decide(sightings, mask.shape[1], self.stop_radius)
        decision = Decision(self.frame, action, target, sightings)
        self.history.append(decision)
        if self.print_decisions:
            print(decision.line(), flush=True)
        if self._out is not None:
            text = json.dumps(asdict(decision)) if self.decisions_json else decision.line()
            self._out.write(text + "\n")
        if self.images is not None:
            self._save_images(mask, decision)
        self.frame += 1

    def report(self) -> dict | None:
        """The decision of the last frame, for --digests (gpucompgen replay compares them)."""
        return asdict(self.history[-1]) if self.history else None

    def free_memory(self) -> None:
        if self._out is not None:
            out, self._out = self._out, None
            out.close()

    def _save_images(self, mask: np.ndarray, decision: Decision) -> None:
        """The mask, and the mask in colour with every sighting boxed (the target in red)."""
        from PIL import Image, ImageDraw

        name = f"{decision.frame:06d}.png"
        Image.fromarray(mask).save(self.images / f"mask_{name}")
        annotated = Image.fromarray(np.stack([mask // 2] * 3, axis=-1))
        draw = ImageDraw.Draw(annotated)
        for s in decision.sightings:
            colour = (255, 40, 40) if s == decision.target else (40, 200, 255)
            r = s.radius + 3
            draw.rectangle((s.x - r, s.y - r, s.x + r, s.y + r), outline=colour, width=2)
        draw.text((8, 8), f"frame {decision.frame}: {decision.action}", fill=(255, 255, 0))
        annotated.save(self.images / f"annotated_{name}")
