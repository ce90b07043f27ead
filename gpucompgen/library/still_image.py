"""StillImage: a standard source that sends one synthetic frame again and again."""

from __future__ import annotations

import numpy as np

from gpucompgen.runtime import Size


class StillImage:
    def __init__(self, *, width: int = 1152, height: int = 864, seed: int = 1, frames: int = 0):
        self.width, self.height, self.seed, self.frames = width, height, seed, frames
        self.frame = 0
        self.image: np.ndarray | None = None

    def initialize(self) -> Size:
        self.image = still_frame(self.width, self.height, self.seed)
        return Size(self.height, self.width, 3)

    def execute(self) -> np.ndarray | None:
        if self.frames and self.frame >= self.frames:
            return None
        self.frame += 1
        return self.image

    def free_memory(self) -> None:
        self.image = None


def still_frame(width: int, height: int, seed: int = 1) -> np.ndarray:
    """The frame StillImage sends: the synthetic Camera's first frame; for frames smaller
    than the Camera's minimum of 16x16, seeded noise."""
    if width >= 16 and height >= 16:
        from gpucompgen.library.camera import Camera

        cam = Camera(width=width, height=height, seed=seed)
        cam.initialize()
        return np.ascontiguousarray(cam.render(0))
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)
