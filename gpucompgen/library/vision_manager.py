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
        labels, count = ndimage.label(mask > 0)
        sightings = []
        if count:
            index = np.arange(1, count + 1)
            areas = ndimage.sum_labels(np.ones_like(labels), labels, index)
            centres = ndimage.center_of_mass(mask > 0, labels, index)
            boxes = ndimage.find_objects(labels)
            for area, (cy, cx), (rows, cols) in zip(areas, centres, boxes):
                if area >= self.min_area:
                    # a digital disk of radius r spans 2r + 1 pixels each way; its area is
                    # a little under pi r^2, which would put r = 60 at 59.99
                    radius = (rows.stop - rows.start + cols.stop - cols.start - 2) / 4
                    sightings.append(Sighting(float(cx), float(cy), int(area), radius))
        sightings.sort(key=lambda s: (s.x, s.y))
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
