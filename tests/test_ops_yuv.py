"""yuv.yaml's camera formats against OpenCV: NV12, NV21, YUYV, UYVY to RGB, BGR and gray,
and RGB, BGR to YUV.

Each type runs as OpenCV's cv2.cvtColor, as its CPU form (cpu_colour.py, which calls
OpenCV), as a numpy reference written here from the fixed-point rules in yuv.yaml's
header (so the CPU form is not checked only against itself), and as the OpenCL kernel the
generator writes from its fusable form (conftest.run_generated: what a lone component
runs), on PoCL. The rules are first checked on every Y, U, V triple (NV12, the
GPU kernel too) and every RGB colour (RgbToYuv); then the photographs (scikit-image's
chelsea, coffee and astronaut, cut to even sizes and converted to each format as a camera
would send them) and Hypothesis-drawn frames of even sizes down to 2x2 under several
launch settings: all four equal, bit for bit. One generated program chains every type
(with ExtractChannel and MergeChannels2 making the two-channel frames) on the GPU, the CPU
and alternating; the bad models yuv_nv12_odd_size.yaml and yuyv_odd_width.yaml check the
size errors.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import load_generated, require_opencl, run_generated, write_keep_types
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen.library import cpu_colour, cpu_kernels

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

PROPERTY = settings(max_examples=8, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


# -- the fixed-point rules, from yuv.yaml's header ---------------------------------------------
def yuv_to_rgb(Y, U, V) -> np.ndarray:
    """R, G, B (last axis) of Y, U, V arrays: BT.601 video range in 20-bit fixed point."""
    Y, u, v = (np.asarray(a, np.int64) for a in (Y, U, V))
    u, v = u - 128, v - 128
    luma = np.maximum(Y - 16, 0) * 1220542 + (1 << 19)
    rgb = [luma + 1673527 * v, luma - 852492 * v - 409993 * u, luma + 2116026 * u]
    return np.clip(np.stack(rgb, -1) >> 20, 0, 255).astype(np.uint8)


def rgb_to_yuv(rgb) -> np.ndarray:
    """Y, U, V of RGB: 14-bit fixed point, U and V from the rounded Y."""
    r, g, b = (rgb[..., i].astype(np.int64) for i in range(3))
    luma = (4899 * r + 9617 * g + 1868 * b + (1 << 13)) >> 14
    half = (128 << 14) + (1 << 13)
    u = ((b - luma) * 8061 + half) >> 14
    v = ((r - luma) * 14369 + half) >> 14
    return np.clip(np.stack([luma, u, v], -1), 0, 255).astype(np.uint8)


def semi_planar(frame, swap: bool):
    """Y, U, V per pixel of an NV12 (NV21: swap) frame."""
    frame = frame.reshape(frame.shape[:2])
    h = frame.shape[0] * 2 // 3
    chroma = frame[h:].reshape(h // 2, -1, 2)
    u, v = (chroma[..., 1], chroma[..., 0]) if swap else (chroma[..., 0], chroma[..., 1])
    def up(p):
        return np.repeat(np.repeat(p, 2, axis=0), 2, axis=1)

    return frame[:h], up(u), up(v)


def packed(frame, uyvy: bool):
    """Y, U, V per pixel of a YUYV (UYVY: uyvy) frame."""
    luma, chroma = (frame[..., 1], frame[..., 0]) if uyvy else (frame[..., 0], frame[..., 1])
    return luma, np.repeat(chroma[:, 0::2], 2, axis=1), np.repeat(chroma[:, 1::2], 2, axis=1)


@dataclass
class Yuv:
    code: int  # OpenCV's cvtColor code
    numpy: Callable  # frame -> the type's output, from the rules above
    layout: str  # the input: nv (one channel, rows * 3/2), packed2 (YUYV), uyvy, rgb

    def opencv(self, frame):
        return cv2.cvtColor(frame.reshape(frame.shape[:2]) if self.layout == "nv" else frame,
                            self.code)


def _colour(decode, swap, bgr):
    def run(frame):
        rgb = yuv_to_rgb(*decode(frame, swap))
        return rgb[..., ::-1] if bgr else rgb
    return run


TYPES: dict[str, Yuv] = {
    "Nv12ToRgb": Yuv(cv2.COLOR_YUV2RGB_NV12, _colour(semi_planar, False, False), "nv"),
    "Nv12ToBgr": Yuv(cv2.COLOR_YUV2BGR_NV12, _colour(semi_planar, False, True), "nv"),
    "Nv21ToRgb": Yuv(cv2.COLOR_YUV2RGB_NV21, _colour(semi_planar, True, False), "nv"),
    "Nv21ToBgr": Yuv(cv2.COLOR_YUV2BGR_NV21, _colour(semi_planar, True, True), "nv"),
    "Nv12ToGray": Yuv(cv2.COLOR_YUV2GRAY_NV12, lambda f: semi_planar(f, False)[0], "nv"),
    "YuyvToRgb": Yuv(cv2.COLOR_YUV2RGB_YUYV, _colour(packed, False, False), "yuyv"),
    "YuyvToBgr": Yuv(cv2.COLOR_YUV2BGR_YUYV, _colour(packed, False, True), "yuyv"),
    "UyvyToRgb": Yuv(cv2.COLOR_YUV2RGB_UYVY, _colour(packed, True, False), "uyvy"),
    "UyvyToBgr": Yuv(cv2.COLOR_YUV2BGR_UYVY, _colour(packed, True, True), "uyvy"),
    "YuyvToGray": Yuv(cv2.COLOR_YUV2GRAY_YUYV, lambda f: np.ascontiguousarray(f[..., 0]),
                      "yuyv"),
    "UyvyToGray": Yuv(cv2.COLOR_YUV2GRAY_UYVY, lambda f: np.ascontiguousarray(f[..., 1]),
                      "uyvy"),
    "RgbToYuv": Yuv(cv2.COLOR_RGB2YUV, rgb_to_yuv, "rgb"),
    "BgrToYuv": Yuv(cv2.COLOR_BGR2YUV, lambda f: rgb_to_yuv(f[..., ::-1]), "rgb"),
}


def yuv_types():
    from gpucompgen.model import library_types

    return {n: t for n, t in library_types().items() if t.decl_file.name == "yuv.yaml"}


def test_every_yuv_type_is_compared_flexible_fusable_and_coloured():
    types = yuv_types()
    assert set(types) == set(TYPES)
    assert set(TYPES) <= set(cpu_kernels.CPU_IMPLEMENTATIONS)
    for name, t in types.items():
        assert t.flexible and t.fusable is not None and t.family == "colour", name
        assert set(t.inputs) == {"src"} and set(t.outputs) == {"dst"}, name


# -- camera frames from photographs --------------------------------------------------------
def camera_frame(rgb: np.ndarray, layout: str) -> np.ndarray:
    """rgb (even sides) as a camera of that layout sends it: NV12 from OpenCV's I420 (its
    U and V planes interleaved), YUYV and UYVY from OpenCV's YUV with the chroma of each
    pair of pixels taken from the first (U) and the second (V)."""
    h, w = rgb.shape[:2]
    if layout == "rgb":
        return rgb
    if layout == "nv":
        i420 = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420)
        quarter = h // 2 * (w // 2)
        u = i420[h:].reshape(-1)[:quarter].reshape(h // 2, w // 2)
        v = i420[h:].reshape(-1)[quarter:].reshape(h // 2, w // 2)
        nv12 = np.empty((h * 3 // 2, w), np.uint8)
        nv12[:h] = i420[:h]
        nv12[h:] = np.stack([u, v], -1).reshape(h // 2, w)
        return nv12
    yuv = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV)
    frame = np.empty((h, w, 2), np.uint8)
    frame[..., 0] = yuv[..., 0]
    frame[:, 0::2, 1] = yuv[:, 0::2, 1]
    frame[:, 1::2, 1] = yuv[:, 1::2, 2]
    return np.ascontiguousarray(frame[..., ::-1]) if layout == "uyvy" else frame


@pytest.fixture(scope="module")
def photos():
    out = []
    for load in (skdata.chelsea, skdata.coffee, skdata.astronaut):
        rgb = load()
        out.append(np.ascontiguousarray(rgb[:rgb.shape[0] // 2 * 2, :rgb.shape[1] // 2 * 2]))
    return out


@pytest.fixture(scope="module")
def gpu(cl_context, cl_queue):
    require_opencl()

    def run(type_name, frame, shape, setting=(16, 16, 16, 1)):
        return run_generated(cl_context, cl_queue, yuv_types()[type_name], {}, [frame], shape,
                             setting)
    return run


def check_all(type_name: str, frame: np.ndarray, gpu, setting=None, what: str = "") -> None:
    spec = TYPES[type_name]
    reference = spec.opencv(frame)
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](frame)
    assert cpu.dtype == reference.dtype and cpu.shape == reference.shape, what
    np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU form {what}")
    np.testing.assert_array_equal(spec.numpy(frame), reference, err_msg=f"numpy {what}")
    found = gpu(type_name, frame, reference.shape, *(() if setting is None else (setting,)))
    np.testing.assert_array_equal(found, reference, err_msg=f"GPU {what}")


# -- every triple, every colour ------------------------------------------------------------
def test_rules_and_nv12_kernel_equal_opencv_on_every_yuv_triple(gpu):
    """2^24 (Y, U, V): 64 NV12 frames of 2 x 131,072 pixels, each 2x2 block one of the
    65,536 (U, V) pairs with four Y values, through OpenCV, the rules and the kernel."""
    pairs = np.arange(1 << 16)
    u, v = (pairs >> 8).astype(np.uint8), (pairs & 255).astype(np.uint8)
    for k in range(64):
        frame = np.empty((3, 2 << 16), np.uint8)
        frame[0, 0::2], frame[0, 1::2], frame[1, 0::2], frame[1, 1::2] = range(4 * k, 4 * k + 4)
        frame[2, 0::2], frame[2, 1::2] = u, v
        expected = cv2.cvtColor(frame, cv2.COLOR_YUV2RGB_NV12)
        np.testing.assert_array_equal(TYPES["Nv12ToRgb"].numpy(frame), expected, f"Y {4 * k}")
        np.testing.assert_array_equal(gpu("Nv12ToRgb", frame, expected.shape), expected)


def test_rules_and_rgb_to_yuv_kernel_equal_opencv_on_every_colour(gpu):
    every = np.arange(1 << 24)
    rgb = np.stack([every >> 16, (every >> 8) & 255, every & 255], -1).astype(np.uint8)
    rgb = rgb.reshape(4096, 4096, 3)
    expected = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV)
    np.testing.assert_array_equal(rgb_to_yuv(rgb), expected)
    np.testing.assert_array_equal(gpu("RgbToYuv", rgb, expected.shape), expected)


def test_hand_computed_values():
    """A few pixels worked out on paper: the video range, the rounding, the clamping."""
    # Y 16, U = V = 128: black; Y 235: 219 * 1.164 = 254.9 -> (255,255,255)
    assert yuv_to_rgb(16, 128, 128).tolist() == [0, 0, 0]
    assert yuv_to_rgb(235, 128, 128).tolist() == [255, 255, 255]
    # Y 100, V 200: R = (84 * 1220542 + 72 * 1673527 + 2^19) >> 20 = 212
    assert yuv_to_rgb(100, 128, 200).tolist()[0] == (84 * 1220542 + 72 * 1673527 + 2 ** 19) >> 20
    # below 16 counts as 16: Y 0 and Y 16 give the same colour
    assert yuv_to_rgb(0, 30, 220).tolist() == yuv_to_rgb(16, 30, 220).tolist()
    nv12 = np.array([[16, 235], [100, 50], [90, 240]], np.uint8)  # 2x2 pixels, U 90, V 240
    out = cpu_colour.nv12_to_rgb(nv12)
    assert out.shape == (2, 2, 3) and out[0, 0].tolist() == yuv_to_rgb(16, 90, 240).tolist()
    assert cpu_colour.nv21_to_rgb(nv12)[1, 1].tolist() == yuv_to_rgb(50, 240, 90).tolist()
    assert cpu_colour.nv12_to_gray(nv12).tolist() == [[16, 235], [100, 50]]
    yuyv = np.array([[[81, 90], [145, 240]]], np.uint8)
    assert cpu_colour.yuyv_to_rgb(yuyv)[0, 1].tolist() == yuv_to_rgb(145, 90, 240).tolist()
    assert cpu_colour.uyvy_to_gray(yuyv).tolist() == [[90, 240]]
    # white: Y 255, U = V = 128 (the rounding's half lands exactly on 128)
    assert cpu_colour.rgb_to_yuv(np.full((1, 1, 3), 255, np.uint8)).tolist() == [[[255, 128,
                                                                                   128]]]
    assert cpu_colour.bgr_to_yuv(np.array([[[255, 0, 0]]], np.uint8)).tolist() == \
        [[rgb_to_yuv(np.array([0, 0, 255])).tolist()]]


def test_cpu_forms_reject_bad_frames():
    with pytest.raises(ValueError, match="multiple of 3"):
        cpu_colour.nv12_to_rgb(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="even width"):
        cpu_colour.nv12_to_gray(np.zeros((3, 5), np.uint8))
    with pytest.raises(ValueError, match="x 2 of an even width"):
        cpu_colour.yuyv_to_rgb(np.zeros((2, 3, 2), np.uint8))
    with pytest.raises(ValueError, match="x 2"):
        cpu_colour.uyvy_to_bgr(np.zeros((2, 4, 3), np.uint8))
    with pytest.raises(TypeError, match="uint8"):
        cpu_colour.rgb_to_yuv(np.zeros((2, 2, 3), np.float32))
    with pytest.raises(ValueError, match="out="):
        cpu_colour.nv12_to_rgb(np.zeros((3, 2), np.uint8), out=np.empty((3, 2, 3), np.uint8))


# -- photographs and random frames -----------------------------------------------------------
@pytest.mark.parametrize("type_name", sorted(TYPES))
def test_photographs_cpu_gpu_numpy_equal_opencv(type_name, photos, gpu):
    for i, rgb in enumerate(photos):
        check_all(type_name, camera_frame(rgb, TYPES[type_name].layout), gpu,
                  what=f"photo {i}")


SETTINGS = [(8, 1, 1, 1), (16, 16, 16, 1), (32, 8, 3, 1)]


@st.composite
def frames(draw, layout: str):
    """Frames of even sizes 2x2 to 40x34 of that layout, random bytes."""
    h, w = 2 * draw(st.integers(1, 20)), 2 * draw(st.integers(1, 17))
    shape = {"nv": (h * 3 // 2, w), "rgb": (h, w, 3)}.get(layout, (h, w, 2))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    return rng.integers(0, 256, shape, dtype=np.uint8), draw(st.sampled_from(SETTINGS))


@pytest.mark.parametrize("type_name", sorted(TYPES))
def test_random_frames_cpu_gpu_numpy_equal_opencv(type_name, gpu):
    @PROPERTY
    @given(case=frames(TYPES[type_name].layout))
    def check(case):
        frame, setting = case
        check_all(type_name, frame, gpu, setting, what=str(frame.shape))

    check()


# -- every type in one generated program -------------------------------------------------------
FRAMES = 3
# name: (type, params, inputs); camera: the 301x200 photographs, resized to 240x180 so that
# the gray frame is an NV12 frame (180 rows, a multiple of 3) and the YUYV one is even
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    "small": ("Resize", {"width": 240, "height": 180, "interpolation": 0}, ("camera",)),
    "yuv": ("RgbToYuv", {}, ("small",)),
    "bgr_yuv": ("BgrToYuv", {}, ("small",)),
    "plane": ("RgbToGray", {}, ("small",)),
    "nv12_rgb": ("Nv12ToRgb", {}, ("plane",)),
    "nv12_bgr": ("Nv12ToBgr", {}, ("plane",)),
    "nv21_rgb": ("Nv21ToRgb", {}, ("plane",)),
    "nv21_bgr": ("Nv21ToBgr", {}, ("plane",)),
    "nv12_gray": ("Nv12ToGray", {}, ("plane",)),
    "luma": ("ExtractChannel", {"channel": 0}, ("yuv",)),
    "chroma": ("ExtractChannel", {"channel": 2}, ("bgr_yuv",)),
    "yuyv": ("MergeChannels2", {}, ("luma", "chroma")),
    "yuyv_rgb": ("YuyvToRgb", {}, ("yuyv",)),
    "yuyv_bgr": ("YuyvToBgr", {}, ("yuyv",)),
    "uyvy_rgb": ("UyvyToRgb", {}, ("yuyv",)),
    "uyvy_bgr": ("UyvyToBgr", {}, ("yuyv",)),
    "yuyv_gray": ("YuyvToGray", {}, ("yuyv",)),
    "uyvy_gray": ("UyvyToGray", {}, ("yuyv",)),
}
OPENCV = {
    "Resize": lambda a, width, height, interpolation: cv2.resize(
        a, (width, height), interpolation=interpolation),
    "RgbToGray": lambda a: cv2.cvtColor(a, cv2.COLOR_RGB2GRAY),
    "ExtractChannel": lambda a, channel: cv2.extractChannel(a, channel),
    "MergeChannels2": lambda a, b: cv2.merge([a, b]),
    **{name: spec.opencv for name, spec in TYPES.items()},
}
def placed_outputs(folder, system: str, chain: dict, cl_context) -> dict:
    """{placement: {component: frames}}: chain (as test_imgproc_ops.chain_model takes it)
    built with every component on the GPU, on the CPU and alternating, run FRAMES frames."""
    from test_imgproc_ops import chain_model

    from gpucompgen.build import compile_model, write

    write_keep_types(folder)
    mixed = {name: ("cpu" if i % 2 else "gpu") for i, name in enumerate(chain)}
    found = {}
    for variant, places in (("gpu", None), ("cpu", None), ("mixed", mixed)):
        model = folder / f"{system}_{variant}.yaml"
        model.write_text(chain_model(system, chain, "cpu" if variant == "cpu" else "gpu"))
        out = folder / f"out_{variant}"
        built = compile_model(model, out, places=places)
        write(built, out)
        program = load_generated(out / f"{system}.py", f"{system}_{variant}")
        result = program.run(frames=FRAMES, context=cl_context)
        assert result.frames == FRAMES
        found[variant] = {n: result.components[f"keep_{n}"].frames for n in chain}
    return found


@pytest.fixture(scope="module")
def program_outputs(tmp_path_factory, cl_context):
    require_opencl()
    return placed_outputs(tmp_path_factory.mktemp("yuv_all"), "yuv_all", CHAIN, cl_context)


def test_the_chain_has_every_yuv_type():
    assert set(TYPES) <= {t for t, _, _ in CHAIN.values()}


def test_generated_program_equals_opencv_on_every_placement(program_outputs):
    from test_imgproc_ops import _camera_frames

    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = OPENCV[type_name](*(values[s] for s in inputs), **params)
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
    for name in yuv_types():
        assert any(re.search(rf"\b{name}\b", row) and "cv2." in row for row in rows), name


# -- fused, unfused and on the CPU: the same bytes ---------------------------------------------
def fused_builds(folder, system: str, chain: dict, cl_context) -> dict:
    """{variant: (build, {end: frames})}: chain (as chain_model takes it) with only its ends
    kept, built fused (launches made so dear that every legal group forms), unfused and on
    the CPU, each run for FRAMES frames."""
    from test_imgproc_ops import chain_model

    from gpucompgen.build import compile_model, write
    from gpucompgen.passes.fuse import FUSION_COSTS

    write_keep_types(folder)
    ends = sorted(set(chain) - {s for _, _, inputs in chain.values() for s in inputs})
    found = {}
    for variant, placement, fusion in (("fused", "gpu", "auto"), ("unfused", "gpu", "off"),
                                       ("cpu", "cpu", "auto")):
        model = folder / f"{system}_{variant}.yaml"
        model.write_text(chain_model(system, chain, placement, keep=ends))
        out = folder / f"out_{variant}"
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr("gpucompgen.passes.fuse.FUSION_COSTS",
                          {k: {**v, "launch_s": 1e6} for k, v in FUSION_COSTS.items()})
            built = compile_model(model, out, fusion=fusion)
        write(built, out)
        program = load_generated(out / f"{system}.py", f"{system}_{variant}")
        result = program.run(frames=FRAMES, context=cl_context)
        found[variant] = (built, {n: result.components[f"keep_{n}"].frames for n in ends})
    return found


def _fused_chain() -> dict:
    """Each type with one reader (BitwiseNot), each YUYV/UYVY one with a MergeChannels2 of
    its own: every type can be inside a group."""
    chain = {"small": CHAIN["small"], "plane": CHAIN["plane"]}
    for i, (name, spec) in enumerate(sorted(TYPES.items())):
        source = {"nv": "plane", "rgb": "small"}.get(spec.layout, f"packed{i}")
        if spec.layout in ("yuyv", "uyvy"):
            chain[source] = ("MergeChannels2", {}, ("plane", "plane"))
        chain[f"t{i}"] = (name, {}, (source,))
        chain[f"not{i}"] = ("BitwiseNot", {}, (f"t{i}",))
    return chain


def assert_fused_equal(found: dict, type_names) -> None:
    """Every one of type_names inside a group of the fused build, no group unfused, and
    the three builds' frames equal."""
    built, fused = found["fused"]
    grouped = {m.type.name for g in built.system.groups for m in g.members}
    assert set(type_names) <= grouped, sorted(set(type_names) - grouped)
    assert not found["unfused"][0].system.groups
    for variant in ("unfused", "cpu"):
        for name, frames in found[variant][1].items():
            for i, frame in enumerate(frames):
                np.testing.assert_array_equal(fused[name][i], frame,
                                              err_msg=f"{variant}: {name}, frame {i}")


def test_fused_equals_unfused_equals_cpu(tmp_path, cl_context):
    require_opencl()
    assert_fused_equal(fused_builds(tmp_path, "yuv_fused", _fused_chain(), cl_context), TYPES)
