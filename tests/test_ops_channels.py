"""channels.yaml (ExtractChannel, MergeChannels2/3/4) and magnitude.yaml (Magnitude)
against OpenCV, and the requirement that compares a parameter with an input's channels.

ExtractChannel and MergeChannels run as OpenCV's cv2.extractChannel and cv2.merge, as their
CPU forms (cpu_channels.py), as numpy slicing and stacking, and as the OpenCL kernel the
generator writes from the fusable form (conftest.run_generated), on PoCL: on the
photographs (RGB, gray, RGBA, and int16 and float32 frames made from them) and
Hypothesis-drawn frames, all equal bit for bit. Magnitude's kernel and CPU form equal bit
for bit and equal a float64 reference of the same roundings; OpenCV's cv2.magnitude, whose
square root is not correctly rounded, is within 2 units in the last place (asserted; the
share of elements that differ is printed). One generated program chains them over the
photographs on the GPU, the CPU and alternating.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_opencl, run_generated
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen import sizeexpr
from gpucompgen.library import cpu_channels, cpu_kernels

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

FILES = ("channels.yaml", "magnitude.yaml")
PROPERTY = settings(max_examples=10, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


def new_types():
    from gpucompgen.model import library_types

    return {n: t for n, t in library_types().items() if t.decl_file.name in FILES}


def test_every_type_is_tested_flexible_fusable_with_a_family():
    types = new_types()
    assert set(types) == {"ExtractChannel", "MergeChannels2", "MergeChannels3",
                          "MergeChannels4", "Magnitude"}
    assert set(types) <= set(cpu_kernels.CPU_IMPLEMENTATIONS)
    for name, t in types.items():
        assert t.flexible and t.fusable is not None, name
        assert t.family == ("arithmetic" if name == "Magnitude" else "colour"), name
        assert set(t.outputs) == {"dst"}, name


# -- a requirement may compare an input's channels ----------------------------------------------
def test_requirements_compare_channels_and_sizes_do_not():
    tree = sizeexpr.parse("channel < src.channels", {"src"}, {"channel"}, condition=True)
    assert sizeexpr.evaluate(tree, {"src": (4, 5, 3)}, {"channel": 2}) is True
    assert sizeexpr.evaluate(tree, {"src": (4, 5, 3)}, {"channel": 3}) is False
    with pytest.raises(sizeexpr.SizeExprError, match="not known here"):
        sizeexpr.evaluate(tree, {"src": (4, 5)}, {"channel": 0})  # sizes without channels
    with pytest.raises(sizeexpr.SizeExprError, match="in a requirement"):
        sizeexpr.parse("src.channels * 2", {"src"}, set())  # an output size never follows them
    with pytest.raises(sizeexpr.SizeExprError, match="only .height and .width"):
        sizeexpr.parse("src.depth == 1", {"src"}, set(), condition=True)


# -- photographs ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def photos():
    """Frames of every kind the types take, from each photograph: RGB, gray, RGBA, int16
    (Sobel of RGB and gray) and float32 (the RGB scaled)."""
    out = []
    for load in (skdata.chelsea, skdata.coffee, skdata.astronaut):
        rgb = np.ascontiguousarray(load())
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        out.append({
            "rgb": rgb, "gray": gray, "rgba": cv2.cvtColor(rgb, cv2.COLOR_RGB2RGBA),
            "dx3": cv2.Sobel(rgb, cv2.CV_16S, 1, 0), "dy3": cv2.Sobel(rgb, cv2.CV_16S, 0, 1),
            "dx": cv2.Sobel(gray, cv2.CV_16S, 1, 0), "dy": cv2.Sobel(gray, cv2.CV_16S, 0, 1),
            "fx": cv2.Sobel(gray, cv2.CV_32F, 1, 0) * np.float32(0.37),
            "fy": cv2.Sobel(gray, cv2.CV_32F, 0, 1) - np.float32(0.5),
            "float": rgb.astype(np.float32) * np.float32(0.73) - np.float32(41.5),
        })
    return out


@pytest.fixture(scope="module")
def gpu(cl_context, cl_queue):
    require_opencl()

    def run(type_name, arrays, params, shape, setting=(16, 16, 16, 1)):
        return run_generated(cl_context, cl_queue, new_types()[type_name], params, arrays,
                             shape, setting)
    return run


def check_exact(type_name, arrays, params, opencv, numpy, gpu, setting=None, what=""):
    reference = opencv(*arrays, **params)
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
    assert cpu.dtype == reference.dtype and cpu.shape == reference.shape, what
    np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU {type_name} {what}")
    np.testing.assert_array_equal(numpy(*arrays, **params), reference,
                                  err_msg=f"numpy {type_name} {what}")
    found = gpu(type_name, arrays, params, reference.shape,
                *(() if setting is None else (setting,)))
    np.testing.assert_array_equal(found, reference, err_msg=f"GPU {type_name} {what}")


def _extract_cv(a, channel):
    return cv2.extractChannel(a, channel) if a.ndim == 3 else a.copy()


def _merge_cv(*planes):
    return cv2.merge(list(planes))


def test_extract_channel_photographs(photos, gpu):
    for i, p in enumerate(photos[:2]):
        for kind, channels in (("rgb", 3), ("gray", 1), ("rgba", 4), ("dx3", 3),
                               ("float", 3)):
            for channel in range(channels):
                check_exact("ExtractChannel", [p[kind]], {"channel": channel}, _extract_cv,
                            lambda a, channel: a.reshape(a.shape[:2] + (-1,))[..., channel],
                            gpu, what=f"photo {i} {kind}")


def test_merge_channels_photographs(photos, gpu):
    for i, p in enumerate(photos):
        planes = {"uint8": [np.ascontiguousarray(p["rgb"][..., c]) for c in range(3)]
                  + [p["gray"]],
                  "int16": [p["dx"], p["dy"], np.ascontiguousarray(p["dx3"][..., 1]),
                            np.ascontiguousarray(p["dy3"][..., 2])],
                  "float32": [p["fx"], p["fy"], np.ascontiguousarray(p["float"][..., 0]),
                              np.ascontiguousarray(p["float"][..., 2])]}
        for dtype, four in planes.items():
            for n in (2, 3, 4):
                check_exact(f"MergeChannels{n}", four[:n], {}, _merge_cv,
                            lambda *a: np.stack(a, -1), gpu, what=f"photo {i} {dtype}")
        # merging the channels of RGB back gives the photograph
        np.testing.assert_array_equal(cpu_channels.merge_channels(*planes["uint8"][:3]),
                                      p["rgb"])


# -- Magnitude: bit-exact with numpy, within 2 ulp of OpenCV --------------------------------
def magnitude_reference(a, b) -> np.ndarray:
    """In float64: each square and the sum rounded to float32 on the way, the square root
    correctly rounded (float64's sqrt of a float32 value, rounded to float32, is: a double
    has more than twice float's precision)."""
    a, b = a.astype(np.float64), b.astype(np.float64)
    aa = (a * a).astype(np.float32).astype(np.float64)  # a * a is exact in float64
    bb = (b * b).astype(np.float32).astype(np.float64)
    total = (aa + bb).astype(np.float32).astype(np.float64)  # exact, then rounded once
    return np.sqrt(total).astype(np.float32)


def ulps(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """|x - y| in units in the last place of float32 (both finite and not negative)."""
    return np.abs(x.view(np.int32).astype(np.int64) - y.view(np.int32).astype(np.int64))


def check_magnitude(a, b, gpu, setting=None, what="") -> float:
    """Kernel = CPU = float64 reference bit for bit, OpenCV within 2 ulp; returns the share
    of elements where OpenCV differs."""
    ours = cpu_channels.magnitude(a, b)
    np.testing.assert_array_equal(ours, magnitude_reference(a, b), err_msg=f"CPU {what}")
    found = gpu("Magnitude", [a, b], {}, ours.shape, *(() if setting is None else (setting,)))
    np.testing.assert_array_equal(found, ours, err_msg=f"GPU {what}")
    opencv = cv2.magnitude(a.astype(np.float32), b.astype(np.float32))
    assert opencv.size == ours.size and opencv.dtype == np.float32
    opencv = opencv.reshape(ours.shape)  # h x w x 1 comes back h x w
    assert ulps(ours, opencv).max() <= 2, what
    return float((ours != opencv).mean())


def test_magnitude_photographs(photos, gpu):
    shares = []
    for i, p in enumerate(photos):
        shares.append(check_magnitude(p["dx"], p["dy"], gpu, what=f"photo {i} int16"))
        shares.append(check_magnitude(p["dx3"], p["dy3"], gpu, what=f"photo {i} int16 x3"))
        shares.append(check_magnitude(p["fx"], p["fy"], gpu, what=f"photo {i} float32"))
    print(f"OpenCV's cv2.magnitude differs (1 or 2 ulp) on {min(shares):.1%} to "
          f"{max(shares):.1%} of the elements")


def test_magnitude_hand_computed_values():
    a = np.array([[3, -14, 0, 1020, -32768]], np.int16)
    b = np.array([[4, 0, 0, 1020, -32768]], np.int16)
    found = cpu_channels.magnitude(a, b)
    assert found.dtype == np.float32
    # 5; 14 exactly (OpenCV gives 14.000001); 0; 1020 sqrt 2; 32768 sqrt 2 (2^31 exact)
    assert found[0, :3].tolist() == [5.0, 14.0, 0.0]
    assert found[0, 3] == np.float32(np.sqrt(np.float64(2 * 1020 ** 2)))
    assert found[0, 4] == np.float32(32768 * np.sqrt(2.0))
    with pytest.raises(ValueError, match="same size"):
        cpu_channels.magnitude(a, b[:, :3])
    with pytest.raises(TypeError, match="int16 or float32"):
        cpu_channels.magnitude(a.astype(np.uint8), b.astype(np.uint8))


def test_cpu_forms_reject_bad_inputs():
    rgb = np.zeros((2, 3, 3), np.uint8)
    with pytest.raises(ValueError, match="0..2"):
        cpu_channels.extract_channel(rgb, channel=3)
    with pytest.raises(ValueError, match="same size"):
        cpu_channels.merge_channels(rgb[..., 0], rgb[:1, :, 0])
    with pytest.raises(ValueError, match="one channel"):
        cpu_channels.merge_channels(rgb, rgb)
    with pytest.raises(ValueError, match="same size and element type"):
        cpu_channels.merge_channels(rgb[..., 0], rgb[..., 0].astype(np.int16))


# -- random frames --------------------------------------------------------------------------
SETTINGS = [(8, 1, 1, 1), (16, 16, 16, 1), (32, 8, 3, 1)]
DTYPES = {"uint8": np.uint8, "int16": np.int16, "float32": np.float32}


def _random(rng, shape, dtype):
    if dtype == "float32":
        return (rng.standard_normal(shape) * 300).astype(np.float32)
    info = np.iinfo(DTYPES[dtype])
    return rng.integers(info.min, info.max + 1, shape, dtype=DTYPES[dtype])


@st.composite
def cases(draw):
    h, w = draw(st.integers(1, 20)), draw(st.integers(1, 33))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    return h, w, rng, draw(st.sampled_from(list(DTYPES))), draw(st.sampled_from(SETTINGS))


@PROPERTY
@given(case=cases(), channels=st.integers(1, 4), n=st.integers(2, 4))
def test_random_frames_extract_and_merge(gpu, case, channels, n):
    h, w, rng, dtype, setting = case
    frame = _random(rng, (h, w, channels), dtype)
    channel = int(rng.integers(0, channels))
    check_exact("ExtractChannel", [frame], {"channel": channel}, _extract_cv,
                lambda a, channel: a[..., channel], gpu, setting, f"{frame.shape} {dtype}")
    planes = [_random(rng, (h, w), dtype) for _ in range(n)]
    check_exact(f"MergeChannels{n}", planes, {}, _merge_cv, lambda *a: np.stack(a, -1), gpu,
                setting, f"{h}x{w} {dtype}")


@PROPERTY
@given(case=cases(), channels=st.sampled_from([1, 3]))
def test_random_frames_magnitude(gpu, case, channels):
    h, w, rng, dtype, setting = case
    dtype = "int16" if dtype == "uint8" else dtype
    a, b = (_random(rng, (h, w, channels), dtype) for _ in range(2))
    check_magnitude(a, b, gpu, setting, f"{a.shape} {dtype}")


# -- every type in one generated program -------------------------------------------------------
FRAMES = 3
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    "red": ("ExtractChannel", {"channel": 0}, ("camera",)),
    "green": ("ExtractChannel", {"channel": 1}, ("camera",)),
    "blue": ("ExtractChannel", {"channel": 2}, ("camera",)),
    "bgr": ("MergeChannels3", {}, ("blue", "green", "red")),
    "inverse": ("BitwiseNot", {}, ("bgr",)),  # a reader: MergeChannels3 in a fused group
    "pair": ("MergeChannels2", {}, ("green", "red")),
    "rgba": ("MergeChannels4", {}, ("red", "green", "blue", "green")),
    "alpha": ("ExtractChannel", {"channel": 3}, ("rgba",)),
    "second": ("ExtractChannel", {"channel": 1}, ("pair",)),
    "dx": ("Sobel", {"dx": 1, "dy": 0}, ("camera",)),
    "dy": ("Sobel", {"dx": 0, "dy": 1}, ("camera",)),
    "magnitude": ("Magnitude", {}, ("dx", "dy")),
    "edges": ("ConvertScale", {"alpha": 0.5, "beta": 0.0}, ("magnitude",)),
    "gdx": ("ExtractChannel", {"channel": 1}, ("dx",)),
    "gdy": ("ExtractChannel", {"channel": 1}, ("dy",)),
    "gmag": ("Magnitude", {}, ("gdx", "gdy")),
    "both": ("MergeChannels2", {}, ("gmag", "gmag")),
}


def _chain_opencv(type_name: str, params: dict, *inputs):
    if type_name == "ExtractChannel":
        return _extract_cv(*inputs, **params)
    if type_name.startswith("MergeChannels"):
        return _merge_cv(*inputs)
    if type_name == "Magnitude":
        return cpu_channels.magnitude(*inputs)  # the bytes; OpenCV's bound is tested above
    if type_name == "BitwiseNot":
        return cv2.bitwise_not(inputs[0])
    if type_name == "Sobel":
        return cv2.Sobel(inputs[0], cv2.CV_16S, params["dx"], params["dy"], ksize=3)
    return cv2.convertScaleAbs(inputs[0], alpha=params["alpha"], beta=params["beta"])


@pytest.fixture(scope="module")
def program_outputs(tmp_path_factory, cl_context):
    require_opencl()
    from test_ops_yuv import placed_outputs

    return placed_outputs(tmp_path_factory.mktemp("channels_all"), "channels_all", CHAIN,
                          cl_context)


def test_generated_program_equals_opencv_on_every_placement(program_outputs):
    from test_imgproc_ops import _camera_frames

    assert set(new_types()) <= {t for t, _, _ in CHAIN.values()}
    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = _chain_opencv(type_name, params, *(values[s] for s in inputs))
            for placement, components in program_outputs.items():
                ours = components[name][i]
                np.testing.assert_array_equal(ours.reshape(values[name].shape), values[name],
                                              err_msg=f"{placement}: {name}, frame {i}")


def test_docs_list_every_type_beside_its_opencv_call():
    """docs/library.md has a table row naming each type and the OpenCV call it equals."""
    import re

    from conftest import ROOT

    rows = [line for line in (ROOT / "docs" / "library.md").read_text().splitlines()
            if line.startswith("| ")]
    for name in new_types():
        assert any(re.search(rf"\b{name}\b", row) and "cv2." in row for row in rows), name


def test_fused_equals_unfused_equals_cpu(tmp_path, cl_context):
    require_opencl()
    from test_ops_yuv import assert_fused_equal, fused_builds

    assert_fused_equal(fused_builds(tmp_path, "channels_fused", CHAIN, cl_context),
                       new_types())
