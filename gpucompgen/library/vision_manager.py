"""VisionManager: a standard sink that turns a black-and-white mask into movement decisions."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import ndimage

from gpucompgen.runtime import Size

ACTIONS = ("forward", "turn_left", "turn_right", "stop", "search")


@dataclass(frozen=True)
class Sighting:
    x: float  # centroid column in the mask
    y: float  # centroid row
    area: int  # pixels
    radius: float  # radius of a disk of that area


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
    def __init__(self, *, min_area: int = 30, stop_radius: int = 60,
                 print_decisions: bool = True, decisions_file: str = ""):
        self.min_area, self.stop_radius = min_area, stop_radius
        self.print_decisions, self.decisions_file = print_decisions, decisions_file
        self.history: list[Decision] = []
        self.frame = 0
        self.size: Size | None = None
        self._out = None

    def initialize(self, mask: Size) -> None:
        self.size = Size(*mask)
        if self.decisions_file:
            self._out = open(self.decisions_file, "w", encoding="utf-8")

    def execute(self, mask: np.ndarray) -> None:
        labels, count = ndimage.label(mask > 0)
        sightings = []
        if count:
            index = np.arange(1, count + 1)
            areas = ndimage.sum_labels(np.ones_like(labels), labels, index)
            centres = ndimage.center_of_mass(mask > 0, labels, index)
            for area, (cy, cx) in zip(areas, centres):
                if area >= self.min_area:
                    sightings.append(Sighting(float(cx), float(cy), int(area),
                                              math.sqrt(area / math.pi)))
        sightings.sort(key=lambda s: (s.x, s.y))
        action, target = decide(sightings, mask.shape[1], self.stop_radius)
        decision = Decision(self.frame, action, target, sightings)
        self.history.append(decision)
        if self.print_decisions:
            print(decision.line(), flush=True)
        if self._out is not None:
            self._out.write(json.dumps(asdict(decision)) + "\n")
        self.frame += 1

    def free_memory(self) -> None:
        if self._out is not None:
            self._out.close()
            self._out = None
