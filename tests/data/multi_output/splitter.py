import numpy as np


class Splitter:
    def initialize(self, image):
        return image, image

    def execute(self, image):
        return image, (255 - image).astype(np.uint8)

    def free_memory(self):
        pass
