"""Library types in a generated program: a long chain of imgproc types over photographs.

The program is generated from a model written here (folder camera over models/photos/,
every geometric, pointwise and stencil kind of type, float and int parameters, a fan-out
and a two-input join, int16 Sobel output) and run on the pinned OpenCL device; its
sinks' results must equal the same chain composed from OpenCV's functions.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.library.mask_writer import find_objects

cv2 = pytest.importorskip("cv2")
Image = pytest.importorskip("PIL.Image")

PHOTOS = ROOT / "models" / "photos"
SQUARE = np.ones((3, 3), np.uint8)

MODEL = f"""
system: imgproc_chain
platform: {{device: portable}}
components:
  camera: {{type: Camera, params: {{folder: "{PHOTOS.as_posix()}", width: 301, height: 200}}}}
  crop: {{type: Crop, params: {{x: 10, y: 5, width: 281, height: 181}}}}
  resize: {{type: Resize, params: {{width: 203, height: 151, interpolation: 0}}}}
  blur: {{type: GaussianBlur, params: {{ksize: 5}}}}
  flip: {{type: FlipHorizontal}}
  turn: {{type: Rotate180}}
  median: {{type: MedianBlur}}
  trunc: {{type: Threshold, params: {{thresh: 180, maxval: 255, thresh_type: 2}}}}
  scale: {{type: ConvertScale, params: {{alpha: 1.37, beta: -12.5}}}}
  blend: {{type: AddWeighted, params: {{alpha: 0.6, beta: 0.45, gamma: 3.25}}}}
  diff: {{type: AbsDiff}}
  erode: {{type: Erode}}
  dilate: {{type: Dilate}}
  sink: {{type: FrameSink}}
  gray: {{type: RgbToGray}}
  edges: {{type: SobelGray, params: {{dx: 1, dy: 0}}}}
  band: {{type: InRangeGray, params: {{lowerb: 40, upperb: 150}}}}
  open1: {{type: ErodeGray}}
  open2: {{type: DilateGray}}
  writer: {{type: MaskWriter, params: {{min_area: 20, print_objects: false}}}}
connections:
  - camera.image -> crop.image
  - crop.cropped -> resize.image
  - resize.resized -> blur.image
  - blur.blurred -> flip.image
  - flip.flipped -> turn.image
  - turn.rotated -> median.image
  - median.median -> trunc.image
  - trunc.thresholded -> scale.image
  - scale.scaled -> blend.src1
  - resize.resized -> blend.src2
  - blend.blended -> diff.src1
  - flip.flipped -> diff.src2
  - diff.diff -> erode.image
  - erode.eroded -> dilate.image
  - dilate.dilated -> sink.image
  - dilate.dilated -> gray.image
  - gray.gray -> edges.image
  - gray.gray -> band.image
  - band.mask -> open1.image
  - open1.eroded -> open2.image
  - open2.dilated -> writer.mask
  - dilate.dilated -> writer.image
"""


def opencv_chain(photo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same chain with OpenCV: the 3-channel result and the gray mask."""
    im = photo[5:5 + 181, 10:10 + 281]
    resized = cv2.resize(im, (203, 151), interpolation=cv2.INTER_NEAREST)
    flipped = cv2.flip(cv2.GaussianBlur(resized, (5, 5), 0), 1)
    median = cv2.medianBlur(cv2.rotate(flipped, cv2.ROTATE_180), 3)
    trunc = cv2.threshold(median, 180, 255, cv2.THRESH_TRUNC)[1]
    scaled = cv2.convertScaleAbs(trunc, alpha=1.37, beta=-12.5)
    blended = cv2.addWeighted(scaled, 0.6, resized, 0.45, 3.25)
    result = cv2.dilate(cv2.erode(cv2.absdiff(blended, flipped), SQUARE), SQUARE)
    band = cv2.inRange(cv2.cvtColor(result, cv2.COLOR_RGB2GRAY), 40, 150)
    return result, cv2.dilate(cv2.erode(band, SQUARE), SQUARE)


def test_chain_of_library_types_matches_opencv(tmp_path, cl_context):
    require_opencl()
    from gpucompgen.build import compile_model, write

    model = tmp_path / "imgproc_chain.yaml"
    model.write_text(MODEL)
    out = tmp_path / "out"
    write(compile_model(model, out, "gpu-aware", None), out)
    program = load_generated(out / "imgproc_chain.py", "imgproc_chain_under_test")
    result = program.run(frames=3, context=cl_context)
    assert result.frames == 3
    with Image.open(max(PHOTOS.glob("*.jpg"))) as im:  # the last frame
        last = np.asarray(im.convert("RGB"))
    expected, mask = opencv_chain(last)
    np.testing.assert_array_equal(result.components["sink"].last, expected)
    writer = result.components["writer"]
    assert len(writer.history) == 3
    assert writer.history[-1] == find_objects(mask, 20) != []
