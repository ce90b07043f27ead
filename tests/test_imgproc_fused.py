"""The imgproc types' fusable forms: the same bytes fused and unfused.

A type's form alone is the kernel a lone component runs (a group of one): test_imgproc
runs it on photographs with every parameter set and on random frames of every size from
1x1. Here, in generated programs: one model of chains over models/photos/ in which every
fusable imgproc type sits inside a fused group (pointwise and index-map members
recomputed by a stencil root, two-input joins reading a shared producer; launches made so
dear that the cost model fuses wherever fusion is legal), built with fusion on, with
fusion off and placed on the CPU: the three give the same bytes, and those equal the same
chains composed from OpenCV's functions.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT, keep_type_for, load_generated, require_opencl, write_keep_types
from test_imgproc import SPECS, imgproc_types

from gpucompgen.passes.fuse import FUSION_COSTS

cv2 = pytest.importorskip("cv2")
Image = pytest.importorskip("PIL.Image")

FUSABLE = sorted(n for n, t in imgproc_types().items() if t.fusable is not None)
# fused in tests/test_ops_lib.py's program (over int16 and float32 as well), not here
ELSEWHERE = {"Crop", "CropGray", "Resize", "ResizeGray"}


def test_every_imgproc_type_is_fusable():
    assert set(FUSABLE) == set(imgproc_types())


# -- fused groups in generated programs ------------------------------------------------
PHOTOS = ROOT / "models" / "photos"
FRAMES = 3

# name: (type, params, inputs: component names; "camera" is the source). Each chain ends
# in a stencil that absorbs what feeds it and is read by the CPU (so its output is
# materialized); the next chain starts from it. A spine rather than ten branches from the
# camera: allocate-gpu enumerates the GPU components that can run at the same time, which
# grows with the product of parallel branch lengths (minutes at ten branches).
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    # flip -> rotate -> trunc -> scale, recomputed by the 5x5 Gaussian's 25 taps
    "flip": ("FlipHorizontal", {}, ("camera",)),
    "turn": ("Rotate180", {}, ("flip",)),
    "trunc": ("Threshold", {"thresh": 180, "maxval": 255, "thresh_type": 2}, ("turn",)),
    "scale": ("ConvertScale", {"alpha": 1.37, "beta": -12.5}, ("trunc",)),
    "blur": ("GaussianBlur", {"ksize": 5}, ("scale",)),
    # HSV under a median
    "hsv": ("RgbToHsv", {}, ("blur",)),
    "median": ("MedianBlur", {}, ("hsv",)),
    # a blend and a difference sharing a producer, under an erode
    "mirror": ("FlipHorizontal", {}, ("median",)),
    "blend": ("AddWeighted", {"alpha": 0.6, "beta": 0.45, "gamma": 3.25}, ("mirror", "camera")),
    "diff": ("AbsDiff", {}, ("blend", "mirror")),
    "erode": ("Erode", {}, ("diff",)),
    "binary": ("Threshold", {"thresh": 100, "maxval": 200, "thresh_type": 0}, ("erode",)),
    "dilate": ("Dilate", {}, ("binary",)),
    # three branches from dilate: an int16 gradient, a red mask, the one-channel spine
    "gain": ("ConvertScale", {"alpha": -0.8, "beta": 10.5}, ("blur",)),
    "sobel": ("Sobel", {"dx": 1, "dy": 0}, ("gain",)),
    "red": ("InRange", {"lowerb_0": 120, "lowerb_1": 0, "lowerb_2": 0,
                        "upperb_0": 255, "upperb_1": 110, "upperb_2": 110}, ("camera",)),
    "reddil": ("DilateGray", {}, ("red",)),
    "gray": ("RgbToGray", {}, ("median",)),
    "gflip": ("FlipHorizontalGray", {}, ("gray",)),
    "gturn": ("Rotate180Gray", {}, ("gflip",)),
    "gzero": ("ThresholdGray", {"thresh": 90, "maxval": 255, "thresh_type": 3}, ("gturn",)),
    "gscale": ("ConvertScaleGray", {"alpha": 1.3, "beta": -7.25}, ("gzero",)),
    "gblur": ("GaussianBlurGray", {"ksize": 3}, ("gscale",)),
    "gsrc": ("ConvertScaleGray", {"alpha": 0.9, "beta": 3.0}, ("gblur",)),
    "gmirror": ("FlipHorizontalGray", {}, ("gsrc",)),
    "gblend": ("AddWeightedGray", {"alpha": 1.3, "beta": -0.4, "gamma": 12.7},
               ("gmirror", "gsrc")),
    "gdiff": ("AbsDiffGray", {}, ("gblend", "gsrc")),
    "gmedian": ("MedianBlurGray", {}, ("gdiff",)),
    "gband": ("InRangeGray", {"lowerb": 40, "upperb": 150}, ("gmedian",)),
    "gerode": ("ErodeGray", {}, ("gband",)),
    "ginv": ("ThresholdGray", {"thresh": 127, "maxval": 255, "thresh_type": 1}, ("gerode",)),
    "gsobel": ("SobelGray", {"dx": 0, "dy": 1}, ("ginv",)),
    # generic types under their own names over one channel, and int16 gradients made
    # 8-bit (convertScaleAbs) by ConvertScale under OpenCV's name, ConvertScaleAbs, and its
    # deprecated one-channel name: Sobel -> ConvertScaleAbsGray recomputed by a median; the
    # three-channel gradient (read by the CPU too, so not fused) under a dilate
    "s16": ("Sobel", {"dx": 1, "dy": 0}, ("gerode",)),
    "sabs": ("ConvertScaleAbsGray", {"alpha": 0.5, "beta": 1.5}, ("s16",)),
    "smedian": ("MedianBlur", {}, ("sabs",)),
    "sabs3": ("ConvertScaleAbs", {"alpha": 0.25, "beta": 0.0}, ("sobel",)),
    "sdilate": ("Dilate", {}, ("sabs3",)),
}
ENDS = ["blur", "median", "erode", "dilate", "sobel", "reddil", "gblur", "gmedian", "gerode",
        "gsobel", "smedian", "sdilate"]
def output_port(type_name: str) -> str:
    return next(iter(imgproc_types()[type_name].outputs))


def model_text(placement: str) -> str:
    lines = ["system: imgproc_fused", "types: [keep.yaml]",
             f"platform: {{device: portable, placement: {placement}}}", "components:",
             f'  camera: {{type: Camera, params: {{folder: "{PHOTOS.as_posix()}", '
             'width: 301, height: 200}}']
    connections = []
    for name, (type_name, params, inputs) in CHAIN.items():
        written = ", ".join(f"{k}: {v}" for k, v in params.items())
        lines.append(f"  {name}: {{type: {type_name}, params: {{{written}}}}}")
        for port, source in zip(imgproc_types()[type_name].inputs, inputs, strict=True):
            out = "image" if source == "camera" else output_port(CHAIN[source][0])
            connections.append(f"  - {source}.{out} -> {name}.{port}")
    for name in ENDS:
        (port,) = imgproc_types()[CHAIN[name][0]].outputs.values()
        keep = keep_type_for(port)
        lines.append(f"  keep_{name}: {{type: {keep}}}")
        connections.append(f"  - {name}.{output_port(CHAIN[name][0])} -> keep_{name}.image")
    return "\n".join(lines + ["connections:"] + connections) + "\n"


@pytest.fixture(scope="module")
def programs(tmp_path_factory, cl_context):
    """{variant: (build result, {end: [output of each frame]})} for fused, unfused, cpu."""
    require_opencl()
    from gpucompgen.build import compile_model, write

    folder = tmp_path_factory.mktemp("imgproc_fused")
    write_keep_types(folder)
    found = {}
    for variant, placement, fusion in (("fused", "gpu", "auto"), ("unfused", "gpu", "off"),
                                       ("cpu", "cpu", "auto")):
        model = folder / f"imgproc_{variant}.yaml"
        model.write_text(model_text(placement))
        out = folder / f"out_{variant}"
        with pytest.MonkeyPatch.context() as patch:
            # every legal group, whatever the cost model says: this test is about the
            # bytes of every type inside a group (launches made very dear: fusing wins)
            patch.setattr("gpucompgen.passes.fuse.FUSION_COSTS",
                          {k: {**v, "launch_s": 1e6} for k, v in FUSION_COSTS.items()})
            built = compile_model(model, out, fusion=fusion)
        write(built, out)
        program = load_generated(out / "imgproc_fused.py", f"imgproc_fused_{variant}")
        result = program.run(frames=FRAMES, context=cl_context)
        assert result.frames == FRAMES
        found[variant] = (built, {n: result.components[f"keep_{n}"].frames for n in ENDS})
    return found


def test_every_fusable_type_runs_inside_a_group(programs):
    built, _ = programs["fused"]
    groups = built.system.groups
    grouped = {m.name: m.type.name for g in groups for m in g.members}
    assert set(grouped) == set(CHAIN), sorted(set(CHAIN) - set(grouped))
    assert set(grouped.values()) == set(FUSABLE) - ELSEWHERE
    assert len(groups) == len(ENDS)  # one kernel, one launch per chain
    assert not programs["unfused"][0].system.groups
    assert not programs["cpu"][0].system.groups


@pytest.mark.parametrize("end", ENDS)
def test_fused_unfused_cpu_and_opencv_give_the_same_bytes(programs, end):
    reference = []
    for path in sorted(PHOTOS.glob("*.jpg")):
        with Image.open(path) as im:
            values = {"camera": np.asarray(im.convert("RGB"))}
        for name, (type_name, params, inputs) in CHAIN.items():
            ctype = imgproc_types()[type_name]  # old parameter names: the parameters'
            given = {ctype.canonical_param(k): v for k, v in params.items()}
            values[name] = SPECS[type_name].opencv(*(values[s] for s in inputs), **given)
        reference.append(values[end])
    for variant, (_, outputs) in programs.items():
        assert len(outputs[end]) == FRAMES
        for i, (got, expected) in enumerate(zip(outputs[end], reference, strict=True)):
            assert got.dtype == expected.dtype
            np.testing.assert_array_equal(got, expected, err_msg=f"{variant}: {end}, frame {i}")


def test_rgb_to_hsv_kernel_equals_opencv_on_every_colour(cl_context, cl_queue):
    """Every one of the 2^24 colours once (a 4096x4096 frame): the generated RgbToHsv
    kernel's float quotient, corrected to OpenCV's integer division tables, gives
    cv2.cvtColor's bytes (a quotient off by one would show on some colour)."""
    from conftest import run_generated

    require_opencl()
    v = np.arange(1 << 24, dtype=np.uint32)
    frame = np.stack([(v >> 16) & 255, (v >> 8) & 255, v & 255], -1).astype(np.uint8)
    frame = frame.reshape(4096, 4096, 3)
    got = run_generated(cl_context, cl_queue, imgproc_types()["RgbToHsv"], {}, [frame],
                        frame.shape)
    np.testing.assert_array_equal(got, cv2.cvtColor(frame, cv2.COLOR_RGB2HSV))
