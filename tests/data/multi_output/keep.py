import numpy as np


class Keep:
    """Keeps a copy of every frame (used by two types: the file is copied once)."""

    def __init__(self):
        self.frames = []

    def initialize(self, image):
        self.size = image

    def execute(self, image):
        self.frames.append(np.array(image, copy=True))

    def free_memory(self):
        pass
