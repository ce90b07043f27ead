"""CPU-side operations of features.yaml and drawing.yaml: standard components (the
four-method interface) that call OpenCV.

They stay on the CPU because their work depends on the data (Canny's hysteresis follows
edges across the frame, fillPoly scans a polygon, HoughLinesP votes and walks segments,
connected components label the whole frame) and OpenCV's results are not reproducible bit
for bit by a per-element kernel; the system copies their frames from and to the GPU.

What flows between components is always a frame (a numpy array of a port's fixed
height x width x channels), so a variable number of things found is a **fixed-capacity
table**: HoughLinesP's ``lines`` is ``max_lines`` x 1 x 4 int32 (x1, y1, x2, y2 per row),
ConnectedComponentsWithStats' ``stats`` is ``max_components`` x 1 x 5 int32 (x, y, width,
height, area per row, largest area first), FindContours' ``contours`` the same with each
outer contour's box and number of points; rows past the last thing found are -1. The
drawing components take such a table beside an image and return the image annotated.
"""

from __future__ import annotations

import cv2
import numpy as np

from gpucompgen.runtime import Size

UNUSED = -1  # a table row past the last thing found


def _gray(frame: np.ndarray) -> np.ndarray:
    return frame.reshape(frame.shape[:2]) if frame.ndim == 3 and frame.shape[2] == 1 else frame


class Canny:
    """Canny / CannyGray: cv2.Canny(src, threshold1, threshold2,
    apertureSize=aperture_size, L2gradient=l2_gradient): 255 on edges, else 0 (three
    channels: the gradient of the channel where it is largest, as OpenCV)."""

    def __init__(self, *, threshold1: float = 100.0, threshold2: float = 200.0,
                 aperture_size: int = 3, l2_gradient: bool = False):
        self.low, self.high = float(threshold1), float(threshold2)
        self.aperture, self.l2 = int(aperture_size), bool(l2_gradient)

    def initialize(self, src: Size) -> Size:
        return Size(src.height, src.width, 1)

    def execute(self, src: np.ndarray) -> np.ndarray:
        return cv2.Canny(_gray(src), self.low, self.high, apertureSize=self.aperture,
                         L2gradient=self.l2)

    def free_memory(self) -> None:
        pass


class RoiMask:
    """RoiMask / RoiMaskGray: a mask of the frame's size, 255 inside the polygon
    ``points`` (x, y pairs) and 0 outside: cv2.fillPoly(np.zeros((h, w), np.uint8),
    [points], 255). The frame only gives the size; the mask is drawn once."""

    def __init__(self, *, points):
        self.points = np.array(points, np.int32).reshape(-1, 1, 2)
        self.mask = None

    def initialize(self, src: Size) -> Size:
        self.mask = cv2.fillPoly(np.zeros((src.height, src.width), np.uint8), [self.points],
                                 255)
        return Size(src.height, src.width, 1)

    def execute(self, src: np.ndarray) -> np.ndarray:
        return self.mask.copy()  # a frame of its own: a reader never shares the template

    def free_memory(self) -> None:
        self.mask = None


class HoughLinesP:
    """HoughLinesP: cv2.HoughLinesP(src, rho, theta_degrees * pi / 180, threshold,
    minLineLength=min_line_length, maxLineGap=max_line_gap), the first max_lines segments
    as a max_lines x 1 x 4 int32 table (x1, y1, x2, y2); unused rows -1."""

    def __init__(self, *, rho: float = 1.0, theta_degrees: float = 1.0, threshold: int = 50,
                 min_line_length: float = 20.0, max_line_gap: float = 10.0,
                 max_lines: int = 64):
        self.rho, self.theta = float(rho), float(theta_degrees) * np.pi / 180.0
        self.threshold, self.max_lines = int(threshold), int(max_lines)
        self.min_length, self.max_gap = float(min_line_length), float(max_line_gap)

    def initialize(self, src: Size) -> Size:
        return Size(self.max_lines, 1, 4)

    def execute(self, src: np.ndarray) -> np.ndarray:
        found = cv2.HoughLinesP(_gray(src), self.rho, self.theta, self.threshold,
                                minLineLength=self.min_length, maxLineGap=self.max_gap)
        table = np.full((self.max_lines, 1, 4), UNUSED, np.int32)
        if found is not None:  # N x 1 x 4 (N x 4 in some OpenCV versions)
            found = found.reshape(-1, 4)[:self.max_lines]
            table[:len(found), 0] = found
        return table

    def free_memory(self) -> None:
        pass


class ConnectedComponentsWithStats:
    """ConnectedComponentsWithStats: cv2.connectedComponentsWithStats(src > 0,
    connectivity=connectivity) without the background, the max_components largest by
    area (ties: OpenCV's label order) as a max_components x 1 x 5 int32 table (x, y,
    width, height, area), components under min_area left out; unused rows -1."""

    def __init__(self, *, connectivity: int = 8, min_area: int = 1, max_components: int = 64):
        self.connectivity, self.min_area = int(connectivity), int(min_area)
        self.max_components = int(max_components)

    def initialize(self, src: Size) -> Size:
        return Size(self.max_components, 1, 5)

    def execute(self, src: np.ndarray) -> np.ndarray:
        binary = (_gray(src) > 0).astype(np.uint8)
        _, _, stats, _ = cv2.connectedComponentsWithStats(binary,
                                                          connectivity=self.connectivity)
        stats = stats[1:]  # label 0 is the background
        stats = stats[stats[:, cv2.CC_STAT_AREA] >= self.min_area]
        order = np.argsort(-stats[:, cv2.CC_STAT_AREA], kind="stable")
        table = np.full((self.max_components, 1, 5), UNUSED, np.int32)
        chosen = stats[order[:self.max_components]]
        table[:len(chosen), 0] = chosen
        return table

    def free_memory(self) -> None:
        pass


class FindContours:
    """FindContours: cv2.findContours(src > 0, cv2.RETR_EXTERNAL,
    cv2.CHAIN_APPROX_SIMPLE), the outer contours in OpenCV's order, each as its bounding
    box and its number of points (x, y, width, height, points: cv2.boundingRect and
    len(contour)), the first max_contours as a max_contours x 1 x 5 int32 table; unused
    rows -1. DrawBoxes draws it."""

    def __init__(self, *, max_contours: int = 64):
        self.max_contours = int(max_contours)

    def initialize(self, src: Size) -> Size:
        return Size(self.max_contours, 1, 5)

    def execute(self, src: np.ndarray) -> np.ndarray:
        binary = (_gray(src) > 0).astype(np.uint8)
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        table = np.full((self.max_contours, 1, 5), UNUSED, np.int32)
        for i, contour in enumerate(contours[:self.max_contours]):
            table[i, 0] = (*cv2.boundingRect(contour), len(contour))
        return table

    def free_memory(self) -> None:
        pass


class DrawLines:
    """DrawLines: src with every used row (x1, y1, x2, y2) of a lines table drawn:
    cv2.line(image, (x1, y1), (x2, y2), (red, green, blue), thickness)."""

    def __init__(self, *, red: int = 255, green: int = 0, blue: int = 0, thickness: int = 2):
        self.colour, self.thickness = (int(red), int(green), int(blue)), int(thickness)

    def initialize(self, src: Size, lines: Size) -> Size:
        return src

    def execute(self, src: np.ndarray, lines: np.ndarray) -> np.ndarray:
        out = src.copy()
        for x1, y1, x2, y2 in lines.reshape(-1, 4):
            if x1 != UNUSED:
                cv2.line(out, (int(x1), int(y1)), (int(x2), int(y2)), self.colour,
                         self.thickness)
        return out

    def free_memory(self) -> None:
        pass


class DrawBoxes:
    """DrawBoxes: src with every used row (x, y, width, height, ...) of a boxes table
    outlined: cv2.rectangle(image, (x, y), (x + width - 1, y + height - 1), colour,
    thickness)."""

    def __init__(self, *, red: int = 0, green: int = 255, blue: int = 0, thickness: int = 1):
        self.colour, self.thickness = (int(red), int(green), int(blue)), int(thickness)

    def initialize(self, src: Size, boxes: Size) -> Size:
        return src

    def execute(self, src: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        out = src.copy()
        for row in boxes.reshape(boxes.shape[0], -1):
            x, y, w, h = (int(v) for v in row[:4])
            if x != UNUSED:
                cv2.rectangle(out, (x, y), (x + w - 1, y + h - 1), self.colour, self.thickness)
        return out

    def free_memory(self) -> None:
        pass
