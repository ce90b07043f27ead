"""Pixel formats to the model's RGB, and the RGB or gray frames of a model to outputs.

Encodings are ROS's (sensor_msgs/image_encodings), which Foxglove's RawImage shares:
``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``mono8``, ``mono16``, ``8UC1``, ``8UC3`` (BGR, as
cv_bridge reads it), ``yuv422`` (UYVY), ``yuv422_yuy2`` / ``yuyv`` (YUYV), ``nv12``, ``nv21``.
The YUV conversions are OpenCV's (BT.601, video range), which cameras and codecs use.
"""

from __future__ import annotations

import numpy as np

from gpucompgen.runtime.errors import PipelineError

# encoding: (bytes per pixel of a row, channels of the array, how it becomes RGB)
PACKED = {
    "rgb8": (3, 3, None), "bgr8": (3, 3, "bgr"), "8uc3": (3, 3, "bgr"),
    "rgba8": (4, 4, "rgba"), "bgra8": (4, 4, "bgra"), "8uc4": (4, 4, "bgra"),
    "mono8": (1, 1, "gray"), "8uc1": (1, 1, "gray"),
    "yuv422": (2, 2, "uyvy"), "uyvy": (2, 2, "uyvy"),
    "yuv422_yuy2": (2, 2, "yuyv"), "yuyv": (2, 2, "yuyv"), "yuy2": (2, 2, "yuyv"),
}
PLANAR = ("nv12", "nv21")
SIXTEEN = ("mono16", "16uc1")
ENCODINGS = tuple(PACKED) + PLANAR + SIXTEEN


def cv2_or_fail(what: str):
    try:
        import cv2
    except ImportError:
        raise PipelineError(f"{what} needs OpenCV: pip install 'gpucompgen[video]'") from None
    return cv2


def to_rgb(array: np.ndarray, how: str | None) -> np.ndarray:
    """An (H, W, C) uint8 array in the layout `how` names, as contiguous RGB."""
    if how is None:
        return np.ascontiguousarray(array)
    if how == "gray":
        return np.ascontiguousarray(np.repeat(array.reshape(array.shape[0], -1, 1), 3, axis=2))
    if how == "bgr":
        return np.ascontiguousarray(array[..., ::-1])
    if how in ("rgba", "bgra"):
        rgb = array[..., :3]
        return np.ascontiguousarray(rgb[..., ::-1] if how == "bgra" else rgb)
    cv2 = cv2_or_fail(f"converting {how.upper()} frames")
    codes = {"uyvy": cv2.COLOR_YUV2RGB_UYVY, "yuyv": cv2.COLOR_YUV2RGB_YUYV,
             "nv12": cv2.COLOR_YUV2RGB_NV12, "nv21": cv2.COLOR_YUV2RGB_NV21}
    return cv2.cvtColor(np.ascontiguousarray(array), codes[how])


def raw_to_rgb(data, encoding: str, width: int, height: int, step: int = 0,
               big_endian: bool = False) -> np.ndarray:
    """A raw image message's bytes (ROS Image, Foxglove RawImage) as (height, width, 3) RGB."""
    enc = encoding.strip().lower()
    buf = np.frombuffer(bytes(data) if not isinstance(data, (bytes, bytearray, memoryview,
                                                                np.ndarray)) else data,
                        np.uint8).ravel()
    if width <= 0 or height <= 0:
        raise PipelineError(f"image of {width}x{height} pixels")
    if enc in PACKED:
        bpp, channels, how = PACKED[enc]
        row = width * bpp
        step = step or row
        if step < row or buf.size < step * (height - 1) + row:
            raise PipelineError(f"{encoding} image of {width}x{height} needs "
                                f"{row * height:,} bytes (step {step}), has {buf.size:,}")
        rows = np.lib.stride_tricks.as_strided(buf, (height, row), (step, 1))
        return to_rgb(rows.reshape(height, width, channels), how)
    if enc in PLANAR:
        if width % 2 or height % 2:
            raise PipelineError(f"{encoding} image of odd size {width}x{height}")
        step = step or width
        need = step * height * 3 // 2
        if buf.size < need:
            raise PipelineError(f"{encoding} image of {width}x{height} needs {need:,} bytes, "
                                f"has {buf.size:,}")
        planes = buf[:need].reshape(height * 3 // 2, step)[:, :width]
        return to_rgb(planes, enc)
    if enc in SIXTEEN:
        step = step or 2 * width
        if buf.size < step * height:
            raise PipelineError(f"{encoding} image of {width}x{height} needs "
                                f"{step * height:,} bytes, has {buf.size:,}")
        words = buf[:step * height].reshape(height, step)[:, :2 * width].copy()
        values = words.view(">u2" if big_endian else "<u2")
        return to_rgb((values >> 8).astype(np.uint8), "gray")
    raise PipelineError(f"image encoding '{encoding}' is not supported; supported: "
                        + ", ".join(ENCODINGS))


def decode_compressed(data, fmt: str = "") -> np.ndarray:
    """A compressed image message's bytes (JPEG, PNG; ROS CompressedImage, Foxglove
    CompressedImage) as RGB."""
    cv2 = cv2_or_fail("decoding compressed images")
    image = cv2.imdecode(np.frombuffer(bytes(data), np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise PipelineError(f"cannot decode the compressed image (format '{fmt}')")
    if image.dtype != np.uint8:
        image = (image >> 8).astype(np.uint8)
    if image.ndim == 2:
        return to_rgb(image, "gray")
    return to_rgb(image, "bgr" if image.shape[2] == 3 else "bgra")


def to_output(frame: np.ndarray) -> tuple[np.ndarray, str]:
    """A model frame ((H, W), (H, W, 1) or (H, W, 3) uint8) for a writer: the array and its
    ROS encoding ('mono8' or 'rgb8')."""
    array = np.asarray(frame)
    if array.dtype != np.uint8:
        raise PipelineError(f"only uint8 frames can be written, not {array.dtype}")
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[..., 0]
    if array.ndim == 2:
        return np.ascontiguousarray(array), "mono8"
    if array.ndim == 3 and array.shape[2] == 3:
        return np.ascontiguousarray(array), "rgb8"
    if array.ndim == 3 and array.shape[2] == 4:
        return np.ascontiguousarray(array[..., :3]), "rgb8"
    raise PipelineError(f"a frame of shape {array.shape} cannot be written as an image")
