import numpy as np


class MeanProbe:
    def __init__(self):
        self.means = []

    def initialize(self, image):
        self.size = image

    def execute(self, image):
        self.means.append(float(np.mean(image, dtype=np.float64)))

    def free_memory(self):
        pass
