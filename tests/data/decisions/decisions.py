"""Sources and sinks of the property test of every decision."""

import time

import numpy as np


class Noise:
    def __init__(self, seed=1, width=8, height=8, frames=0):
        self.seed, self.shape, self.frames = seed, (height, width, 3), frames
        self.frame = 0

    def initialize(self):
        return self.shape  # a plain tuple: the program makes it a Size

    def execute(self):
        if self.frames and self.frame >= self.frames:
            return None
        rng = np.random.default_rng([self.seed, self.frame])
        self.frame += 1
        return rng.integers(0, 256, self.shape, dtype=np.uint8)

    def free_memory(self):
        pass


class Sink:
    def __init__(self, delay=0.0):
        self.delay, self.frames = delay, []

    def initialize(self, image):
        self.size = image

    def execute(self, image):
        if self.delay:
            time.sleep(self.delay)
        self.frames.append(np.array(image, copy=True))

    def free_memory(self):
        pass
