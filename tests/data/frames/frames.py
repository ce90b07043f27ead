"""Components that return wrong frames on purpose (see types.yaml)."""

import numpy as np


class Misshaper:
    def __init__(self, fault="", fault_at=1):
        self.fault, self.fault_at = fault, fault_at
        self.frame = 0

    def initialize(self, image):
        return image

    def execute(self, image):
        frame, self.frame = self.frame, self.frame + 1
        if frame != self.fault_at:
            return image
        if self.fault == "transpose":  # the same bytes, height and width swapped
            return np.ascontiguousarray(image.transpose(1, 0, 2))
        if self.fault == "float32":
            return image.astype(np.float32)
        if self.fault == "narrow":
            return np.ascontiguousarray(image[:, :-1])
        if self.fault == "none":
            return None
        if self.fault == "list":
            return image.tolist()
        if self.fault == "extra_axis":
            return image[np.newaxis]
        return image

    def free_memory(self):
        pass


class Swallow:
    def initialize(self, image):
        self.frames = 0

    def execute(self, image):
        self.frames += 1

    def free_memory(self):
        pass
