"""One-channel frames as height x width x 1 (see types.yaml)."""

import numpy as np

from gpucompgen.runtime import Size


def frame_of(index: int, height: int, width: int) -> np.ndarray:
    return np.random.default_rng(index).integers(0, 256, (height, width, 1), dtype=np.uint8)


class DeepGraySource:
    def __init__(self, width=10, height=9, frames=3):
        self.width, self.height, self.frames = width, height, frames
        self.index = 0

    def initialize(self):
        return Size(self.height, self.width, 1)

    def execute(self):
        if self.index >= self.frames:
            return None
        self.index += 1
        return frame_of(self.index - 1, self.height, self.width)

    def free_memory(self):
        pass


class DeepInvert:
    def initialize(self, image):
        return image

    def execute(self, image):
        assert image.ndim == 2, image.shape  # the system hands on height x width
        return (255 - image)[..., None]

    def free_memory(self):
        pass


class GrayRecorder:
    def __init__(self, path=""):
        self.path, self.frames = path, []

    def initialize(self, image):
        pass

    def execute(self, image):
        self.frames.append(np.array(image))

    def free_memory(self):
        np.save(self.path, np.stack(self.frames))
