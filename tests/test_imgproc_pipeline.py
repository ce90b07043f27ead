"""Every imgproc type in generated programs, placed on the GPU, on the CPU and mixed.

One model chains every imgproc type over the photographs of models/photos/ (a folder
camera, 301x200): crops and nearest resizes make odd sizes on the way, both Resize
interpolations, both GaussianBlur sizes, float and int parameters, fan-outs, two-input
joins, int16 Sobel outputs made 8-bit again by ConvertScale, the generic types over three
channels and one, and the deprecated one-channel names ('GaussianBlurGray'). A collector (a standard type written here) keeps every
component's output of every frame. The model is built three times — every flexible
component on the GPU (their OpenCL kernels), every one on the CPU (their numpy functions,
no device buffers at all), and alternating sides (adapters between neighbours) — and each
program runs once over the three photographs, in a module-scoped fixture.

Each component's output must equal the OpenCV function the type stands for
(test_imgproc.SPECS), applied to OpenCV's result for the component's inputs: bit-exact
(the deprecated names with their old parameter names: CropGray's x and y, InRangeGray's
lowerb and upperb); and the three placements must give the same bytes.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT, keep_type_for, load_generated, require_opencl, write_keep_types
from test_imgproc import SPECS, imgproc_types, largest_difference

cv2 = pytest.importorskip("cv2")
Image = pytest.importorskip("PIL.Image")

PHOTOS = ROOT / "models" / "photos"
FRAMES = 3  # the three photographs, in sorted order

# name: (type, params, inputs as component names in port order; "camera" is the source)
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    # -- three channels: 301x200 -> 281x181 -> 203x151 ---------------------------------
    "crop": ("Crop", {"left": 10, "top": 5, "width": 281, "height": 181}, ("camera",)),
    "near": ("Resize", {"width": 203, "height": 151, "interpolation": 0}, ("crop",)),
    "linear": ("Resize", {"width": 150, "height": 97, "interpolation": 1}, ("crop",)),
    "blur3": ("GaussianBlur", {"ksize": 3}, ("near",)),
    "blur5": ("GaussianBlur", {"ksize": 5}, ("crop",)),
    "flip": ("FlipHorizontal", {}, ("blur3",)),
    "turn": ("Rotate180", {}, ("flip",)),
    "median": ("MedianBlur", {}, ("turn",)),
    "trunc": ("Threshold", {"thresh": 180, "maxval": 255, "thresh_type": 2}, ("median",)),
    "scale": ("ConvertScale", {"alpha": 1.37, "beta": -12.5}, ("trunc",)),
    "blend": ("AddWeighted", {"alpha": 0.6, "beta": 0.45, "gamma": 3.25}, ("scale", "near")),
    "diff": ("AbsDiff", {}, ("blend", "flip")),
    "erode": ("Erode", {}, ("diff",)),
    "dilate": ("Dilate", {}, ("erode",)),
    "sobel": ("Sobel", {"dx": 0, "dy": 1}, ("blur5",)),
    "hsv": ("RgbToHsv", {}, ("camera",)),
    "red": ("InRange", {"lowerb_0": 0, "lowerb_1": 100, "lowerb_2": 50,
                        "upperb_0": 20, "upperb_1": 255, "upperb_2": 255}, ("hsv",)),
    # -- one channel: 301x200 -> 251x177 -> 127x99; 333x211 upscaled -------------------
    "gray": ("RgbToGray", {}, ("camera",)),
    "gcrop": ("CropGray", {"x": 3, "y": 7, "width": 251, "height": 177}, ("gray",)),
    "gnear": ("ResizeGray", {"width": 127, "height": 99, "interpolation": 0}, ("gcrop",)),
    "glinear": ("ResizeGray", {"width": 333, "height": 211, "interpolation": 1}, ("gray",)),
    "gblur": ("GaussianBlurGray", {"ksize": 5}, ("gnear",)),
    "gflip": ("FlipHorizontalGray", {}, ("gblur",)),
    "gturn": ("Rotate180Gray", {}, ("gflip",)),
    "gmedian": ("MedianBlurGray", {}, ("gturn",)),
    "gzero": ("ThresholdGray", {"thresh": 90, "maxval": 255, "thresh_type": 3}, ("gmedian",)),
    "gscale": ("ConvertScaleGray", {"alpha": -0.8, "beta": 10.5}, ("gzero",)),
    "gblend": ("AddWeightedGray", {"alpha": 1.3, "beta": -0.4, "gamma": 12.7},
               ("gscale", "gnear")),
    "gdiff": ("AbsDiffGray", {}, ("gblend", "gflip")),
    "gerode": ("ErodeGray", {}, ("gdiff",)),
    "gdilate": ("DilateGray", {}, ("gerode",)),
    "gband": ("InRangeGray", {"lowerb": 40, "upperb": 150}, ("gdilate",)),
    "gsobel": ("SobelGray", {"dx": 1, "dy": 0}, ("gray",)),
    "ginv": ("ThresholdGray", {"thresh": 100, "maxval": 200, "thresh_type": 1}, ("gcrop",)),
    # -- the generic types under their own names: one channel, and Sobel's int16 gradients
    # made 8-bit again (convertScaleAbs), a fused stencil chain over one channel ---------
    "sabs": ("ConvertScale", {"alpha": 0.25, "beta": 0.0}, ("sobel",)),
    "gsabs": ("ConvertScale", {"alpha": 0.5, "beta": 3.0}, ("gsobel",)),
    # ConvertScale under OpenCV's name, and the int16-only one-channel name of before
    "sabs2": ("ConvertScaleAbs", {"alpha": 1.7, "beta": -30.2}, ("sobel",)),
    "gsabs2": ("ConvertScaleAbsGray", {"alpha": 0.37, "beta": 0.25}, ("gsobel",)),
    "g1blur": ("GaussianBlur", {"ksize": 3}, ("gray",)),
    "g1erode": ("Erode", {}, ("g1blur",)),
    "g1median": ("MedianBlur", {}, ("g1erode",)),
    "g1sobel": ("Sobel", {"dx": 0, "dy": 1}, ("g1median",)),
}

def keep_type(type_name: str) -> str:
    (port,) = imgproc_types()[type_name].outputs.values()
    return keep_type_for(port)


def model_text(placement: str) -> str:
    lines = ["system: imgproc_all", "types: [keep.yaml]",
             f"platform: {{device: portable, placement: {placement}}}", "components:",
             f'  camera: {{type: Camera, params: {{folder: "{PHOTOS.as_posix()}", '
             'width: 301, height: 200}}']
    connections = []
    for name, (type_name, params, inputs) in CHAIN.items():
        written = ", ".join(f"{k}: {v}" for k, v in params.items())
        lines.append(f"  {name}: {{type: {type_name}, params: {{{written}}}}}")
        lines.append(f"  keep_{name}: {{type: {keep_type(type_name)}}}")
        ctype = imgproc_types()[type_name]
        for port, source in zip(ctype.inputs, inputs, strict=True):
            out = "image" if source == "camera" else next(iter(imgproc_types()[
                CHAIN[source][0]].outputs))
            connections.append(f"  - {source}.{out} -> {name}.{port}")
        connections.append(f"  - {name}.{next(iter(ctype.outputs))} -> keep_{name}.image")
    return "\n".join(lines + ["connections:"] + connections) + "\n"


# every other component on the CPU: each edge between two of them crosses sides
MIXED = {name: ("cpu" if i % 2 else "gpu") for i, name in enumerate(CHAIN)}


@pytest.fixture(scope="module")
def outputs(tmp_path_factory, cl_context):
    """{placement: {component: [output of each frame]}} and the plans' placements."""
    require_opencl()
    from gpucompgen.build import compile_model, write

    folder = tmp_path_factory.mktemp("imgproc_all")
    write_keep_types(folder)
    found, placed = {}, {}
    for placement, places in (("gpu", None), ("cpu", None), ("mixed", MIXED)):
        model = folder / f"imgproc_{placement}.yaml"
        model.write_text(model_text("gpu" if places else placement))
        out = folder / f"out_{placement}"
        built = compile_model(model, out, places=places)
        write(built, out)
        # a lone GPU component of a fusable type is a group of one: component() finds it
        placed[placement] = {n: built.system.component(n).placement for n in CHAIN}
        program = load_generated(out / "imgproc_all.py", f"imgproc_all_{placement}")
        result = program.run(frames=FRAMES, context=cl_context)
        assert result.frames == FRAMES
        found[placement] = {n: result.components[f"keep_{n}"].frames for n in CHAIN}
    return found, placed


@pytest.fixture(scope="module")
def expected():
    """OpenCV's result for every component and frame, from OpenCV's results before it."""
    frames = []
    for path in sorted(PHOTOS.glob("*.jpg")):
        with Image.open(path) as im:
            values = {"camera": np.asarray(im.convert("RGB"))}
        for name, (type_name, params, inputs) in CHAIN.items():
            ctype = imgproc_types()[type_name]  # old parameter names: the parameters'
            given = {ctype.canonical_param(k): v for k, v in params.items()}
            values[name] = SPECS[type_name].opencv(*(values[s] for s in inputs), **given)
        frames.append(values)
    return frames


def test_the_chain_has_every_imgproc_type():
    assert {t for t, _, _ in CHAIN.values()} == set(imgproc_types())


def test_each_build_places_as_asked(outputs):
    _, placed = outputs
    assert set(placed["gpu"].values()) == {"gpu"}
    assert set(placed["cpu"].values()) == {"cpu"}
    assert placed["mixed"] == MIXED


@pytest.mark.parametrize("name", list(CHAIN))
def test_component_equals_opencv_on_every_placement(outputs, expected, name):
    found, _ = outputs
    type_name, params, _ = CHAIN[name]
    bound = SPECS[type_name].max_diff if params.get("interpolation") == 1 else 0
    for placement, components in found.items():
        frames = components[name]
        assert len(frames) == FRAMES
        for i, (ours, reference) in enumerate(zip(frames, expected, strict=True)):
            difference = largest_difference(ours, reference[name])
            assert difference <= bound, (placement, name, i, difference)


@pytest.mark.parametrize("name", list(CHAIN))
def test_cpu_and_mixed_placements_give_the_gpus_bytes(outputs, name):
    found, _ = outputs
    for i in range(FRAMES):
        gpu = found["gpu"][name][i]
        for placement in ("cpu", "mixed"):
            np.testing.assert_array_equal(found[placement][name][i], gpu,
                                          err_msg=f"{placement}: {name}, frame {i}")
