"""The benchmark's own parts (see types.yaml)."""

import cv2
import numpy as np

from gpucompgen.runtime import Size


class PanFrames:
    def __init__(self, path="", width=640, height=360):
        self.path, self.width, self.height = path, width, height
        self.index = 0

    def initialize(self):
        self.frames = np.load(self.path)
        return Size(self.height, self.width, 3)

    def execute(self):
        frame = self.frames[self.index % len(self.frames)]
        self.index += 1
        return frame

    def free_memory(self):
        self.frames = None


class PanPairs(PanFrames):
    def initialize(self):
        size = super().initialize()
        return size, size

    def execute(self):
        n = len(self.frames)
        pair = self.frames[self.index % n], self.frames[(self.index - 1) % n]
        self.index += 1
        return pair


class MaskSink:
    def __init__(self):
        self.last = self.kept = None
        self.frames = 0

    def initialize(self, mask):
        pass

    def execute(self, mask):
        self.last = mask  # an adapter's array, reused: copied once, when freed
        self.frames += 1

    def free_memory(self):
        self.kept = None if self.last is None else np.array(self.last)
        self.last = None


def abs_gray16(image):
    """AbsGray16 on the CPU: cv2.convertScaleAbs, |x| saturated to 0..255."""
    return cv2.convertScaleAbs(image)
