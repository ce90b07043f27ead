"""Operations generic over element types (issue 26): uint8, int16 and float32 frames through
Erode, Dilate, MedianBlur, Threshold, AbsDiff, AddWeighted, the flips, Rotate180 and the
bitwise operations, against OpenCV; and the snippet language's names for a port's element
type (<port>_t) and its bounds (<port>_min, <port>_max) that make one snippet serve them.

Every operation and element type runs as OpenCV's call, as its CPU form and as the OpenCL
kernel the generator writes from its fusable form (conftest.run_generated, on PoCL), on
crops of the photographs (int16 frames spread over the whole int16 range, float32 ones
with fractions and negatives), equal bit for bit; AddWeighted on float32, where OpenCV
computes in double, within its stated bound.  One generated program takes int16 (Sobel)
and float32 (Magnitude) frames of the camera's photographs through every operation, on
the GPU, the CPU and alternating, fused and unfused, against OpenCV.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import require_opencl, run_generated

from gpucompgen.library import cpu_channels, cpu_kernels
from gpucompgen.snippet import analyse

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

K3 = np.ones((3, 3), np.uint8)
WIDE = ("int16", "float32")  # the element types new to these operations (uint8: test_imgproc*)


# -- the snippet language: <port>_t, <port>_min, <port>_max ----------------------------------
def test_port_types_and_bounds_are_names_of_their_own_kind():
    a = analyse("const src_t v = src(y, x, c);\nconst float f = (float)v;\n"
                "return f > dst_max ? dst_max : (dst_t)f;", "pointwise", ["src"], ["dst"], [])
    assert not a.problems
    assert a.names["src_t"] == "type" and a.names["dst_t"] == "type"
    assert a.names["dst_max"] == "limit" and "src_min" not in a.names


@pytest.mark.parametrize(("text", "message"), [
    ("return src_t + 1;", "'src_t' is a type (the element type of port 'src'), not a value"),
    ("int src_t = 1; return src_t;", "'src_t' names the element type of port 'src', not a local"),
    ("const nope_t v = 1; return v;", "expected a type, found 'nope_t'"),
    ("src_max = 3; return 0;", "'src_max' is given to the snippet; it cannot be assigned"),
])
def test_misuse_is_a_positioned_problem(text, message):
    a = analyse(text, "pointwise", ["src"], ["dst"], [])
    assert [p.message for p in a.problems][:1] == [message], a.problems
    assert 0 <= a.problems[0].offset < len(text)
    if "nope_t" in text:
        assert "(src_t, dst_t)" in a.problems[0].hint


def test_a_port_named_size_keeps_opencl_size_t():
    a = analyse("const size_t n = 2; return size(y, x, c) * n;", "pointwise", ["size"], ["out"],
                [])
    assert not a.problems and a.names.get("size_t") is None


def _types_file(tmp_path, params: str, value: str):
    from gpucompgen.build import compile_model

    (tmp_path / "t.yaml").write_text(
        "component_types:\n  K:\n    kind: flexible\n" + params +
        "    inputs:\n      src: {dtype: [uint8, int16, float32], channels: [1, 3]}\n"
        "    outputs:\n      dst: {dtype: src.dtype, channels: src.channels, "
        "height: src.height, width: src.width}\n"
        "    cpu: {file: k.py, function: k}\n"
        f"    fusable:\n      form: pointwise\n      value: {value!r}\n")
    (tmp_path / "k.py").write_text("def k(src, *, out=None, **params):\n    return src\n")
    model = tmp_path / "m.yaml"
    model.write_text("system: s\ntypes: [t.yaml]\ncomponents:\n"
                     "  src: {type: StillImage, params: {width: 8, height: 8}}\n"
                     "  k: {type: K}\n  sink: {type: FrameSink}\n"
                     "connections: [src.image -> k.src, k.dst -> sink.image]\n")
    return lambda: compile_model(model, tmp_path / "o")


def test_a_parameter_named_like_a_port_type_is_a_positioned_error(tmp_path):
    from gpucompgen.errors import GpucompgenError

    build = _types_file(tmp_path, "    params:\n      src_t: {type: int, default: 1}\n",
                        "src(y, x, c)")
    with pytest.raises(GpucompgenError) as info:
        build()
    text = str(info.value)
    assert re.search(r"t\.yaml:5:7: error: parameter 'src_t' of 'K' has the name its fusable "
                     r"snippet gets for the element type of port 'src'", text), text
    assert "hint: rename the parameter" in text


def test_a_snippet_using_the_type_as_a_value_is_a_positioned_error(tmp_path):
    from gpucompgen.errors import GpucompgenError

    build = _types_file(tmp_path, "", "src(y, x, c) + src_t")
    with pytest.raises(GpucompgenError) as info:
        build()
    assert re.search(r"t\.yaml:11:\d+: error: fusable snippet of 'K': 'src_t' is a type",
                     str(info.value)), str(info.value)


def _kernel(type_name: str, dtype: str, channels: int = 1) -> str:
    from gpucompgen.kernelgen.fused import group_kernel, group_of_one
    from gpucompgen.model import library_types

    ctype = library_types()[type_name].specialized(dtype, channels)
    params = {p: d.default for p, d in ctype.params.items()}
    shapes = dict.fromkeys([*ctype.inputs, *ctype.outputs], (7, 9))
    return group_kernel(group_of_one(ctype, params, shapes), "test")


def test_the_kernel_declares_the_types_and_bounds_the_snippet_uses():
    assert "    typedef short src_t;" in _kernel("Erode", "int16").splitlines()
    assert "    typedef float src_t;" in _kernel("MedianBlur", "float32").splitlines()
    lines = _kernel("AbsDiff", "int16").splitlines()
    assert "    typedef short src1_t;" in lines
    assert "    const short dst_max = 32767;" in lines
    lines = _kernel("Threshold", "float32").splitlines()
    assert "    const float src_min = -3.40282347e+38f, src_max = 3.40282347e+38f;" in lines
    assert "_t;" not in _kernel("FlipHorizontal", "int16")  # only where used


def _input_dtypes(type_name: str) -> tuple[str, ...]:
    from gpucompgen.model import library_types

    port = next(iter(library_types()[type_name].inputs.values()))
    return port.dtypes or (port.dtype,)


def test_the_cuda_backend_compiles_every_element_type():
    """The .cu text of each generic operation for int16 and float32 compiles with NVRTC
    (the typedef and the bounds are plain C++)."""
    from test_cuda import TARGETS, nvrtc_of

    from gpucompgen.backend.cuda import prelude

    major, arch = TARGETS[-1]
    lib = nvrtc_of(major)
    for name in ("Erode", "MedianBlur", "Threshold", "AbsDiff", "AddWeighted", "BitwiseNot",
                 "Blur", "Filter2D", "WarpAffine", "Remap", "Undistort", "BgrToRgb", "RgbToGray"):
        for dtype in WIDE:
            if dtype not in _input_dtypes(name):
                continue
            compiled = lib.compile(prelude.cuda_source(_kernel(name, dtype, 3)),
                                   f"{name}-{dtype}.cu", arch)
            assert compiled.ok, f"{name} {dtype}:\n{compiled.log}"


# -- photographs of every element type ------------------------------------------------------
@pytest.fixture(scope="module")
def frames():
    """{dtype: [(a, b) per photograph]}: crops of two photographs as uint8 RGB; as int16
    over the whole range (p * 257 - 32768: -32768 and 32767 both occur); as float32 with
    fractions and negatives.  b is another crop of the same photograph (two-input ops)."""
    out = {"uint8": [], "int16": [], "float32": []}
    for load in (skdata.chelsea, skdata.coffee):
        rgb = load()
        a, b = (np.ascontiguousarray(c) for c in (rgb[40:88, 60:124], rgb[100:148, 10:74]))
        out["uint8"].append((a, b))
        out["int16"].append(tuple((x.astype(np.int32) * 257 - 32768).astype(np.int16)
                                  for x in (a, b)))
        out["float32"].append(tuple(x.astype(np.float32) * np.float32(0.73)
                                    - np.float32(41.5) for x in (a, b)))
    return out


def _gray(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a[..., 1])


@pytest.fixture(scope="module")
def gpu(cl_context, cl_queue):
    require_opencl()
    from gpucompgen.model import library_types

    types = library_types()

    def run(type_name, arrays, params, shape):
        return run_generated(cl_context, cl_queue, types[type_name], params, arrays, shape)
    return run


def check(type_name: str, arrays: list, params: dict, reference: np.ndarray, gpu,
          what: str) -> None:
    """CPU form = GPU kernel = reference, bit for bit."""
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
    assert cpu.dtype == reference.dtype and cpu.shape == reference.shape, what
    np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU {type_name} {what} {params}")
    found = gpu(type_name, arrays, params, reference.shape)
    np.testing.assert_array_equal(found, reference, err_msg=f"GPU {type_name} {what} {params}")


ONE_INPUT = {
    "Erode": lambda a: cv2.erode(a, K3),
    "Dilate": lambda a: cv2.dilate(a, K3),
    "MedianBlur": lambda a: cv2.medianBlur(a, 3),
    "FlipHorizontal": lambda a: cv2.flip(a, 1),
    "FlipVertical": lambda a: cv2.flip(a, 0),
    "VerticalMirror": lambda a: cv2.flip(a, 0),
    "Rotate180": lambda a: cv2.rotate(a, cv2.ROTATE_180),
    "BitwiseNot": cv2.bitwise_not,
}


@pytest.mark.parametrize("dtype", WIDE)
@pytest.mark.parametrize("type_name", sorted(ONE_INPUT))
def test_one_input_operations_on_photographs(type_name, dtype, frames, gpu):
    if type_name == "BitwiseNot" and dtype == "float32":
        pytest.skip("bitwise operations take integer types")
    for i, (a, _) in enumerate(frames[dtype]):
        # three channels for one photograph, one for the other: one kernel build each
        src = a if i == 0 else _gray(a)
        check(type_name, [src], {}, ONE_INPUT[type_name](src), gpu, f"{dtype} photo {i}")


def _bitwise_and_mask(a, b, m):
    out = np.zeros_like(a)
    return cv2.bitwise_and(a, b, dst=out, mask=m)


TWO_INPUTS = {
    "AbsDiff": cv2.absdiff,
    "BitwiseAnd": cv2.bitwise_and,
    "BitwiseOr": cv2.bitwise_or,
    "BitwiseXor": cv2.bitwise_xor,
}


@pytest.mark.parametrize("dtype", WIDE)
@pytest.mark.parametrize("type_name", sorted(TWO_INPUTS))
def test_two_input_operations_on_photographs(type_name, dtype, frames, gpu):
    if type_name.startswith("Bitwise") and dtype == "float32":
        pytest.skip("bitwise operations take integer types")
    for i, pair in enumerate(frames[dtype]):
        a, b = pair if i == 0 else (_gray(pair[0]), _gray(pair[1]))
        check(type_name, [a, b], {}, TWO_INPUTS[type_name](a, b), gpu, f"{dtype} photo {i}")


def test_bitwise_and_mask_on_int16_photographs(frames, gpu):
    for i, (a, b) in enumerate(frames["int16"]):
        mask = cv2.threshold(frames["uint8"][i][0][..., 0], 120, 255, cv2.THRESH_BINARY)[1]
        check("BitwiseAndMask", [a, b, mask], {}, _bitwise_and_mask(a, b, mask), gpu,
              f"photo {i}")


def test_absdiff_saturates_int16_as_opencv():
    a = np.array([[32767, -32768, 5, -1]], np.int16)
    b = np.array([[-32768, 32767, -7, 1]], np.int16)
    found = cpu_kernels.absdiff(a, b)
    np.testing.assert_array_equal(found, cv2.absdiff(a, b))
    assert found.tolist() == [[32767, 32767, 12, 2]]


# Threshold: OpenCV's rules per element type; thresh and maxval that are fractions, outside
# the type's range and that saturate
THRESHOLDS = {
    "uint8": [{"thresh": 100.5, "maxval": 200.5}, {"thresh": -5.0, "maxval": 300.0},
              {"thresh": 254.9, "maxval": 77.5}],
    "int16": [{"thresh": -300.7, "maxval": 40000.0}, {"thresh": 1200.5, "maxval": -3.5},
              {"thresh": -40000.0, "maxval": 6.5}],
    "float32": [{"thresh": 50.25, "maxval": 7.75}, {"thresh": -20.125, "maxval": -1e6}],
}


@pytest.mark.parametrize("dtype", sorted(THRESHOLDS))
def test_threshold_every_rule_on_photographs(dtype, frames, gpu):
    a = frames[dtype][0][0]
    for k, bounds in enumerate(THRESHOLDS[dtype]):
        src = a if k % 2 == 0 else _gray(a)
        for thresh_type in range(5):
            params = {**bounds, "thresh_type": thresh_type}
            reference = cv2.threshold(src, params["thresh"], params["maxval"], thresh_type)[1]
            check("Threshold", [src], params, reference, gpu, dtype)


def test_threshold_hand_computed_values():
    a = np.array([[-32768, -301, -300, 0, 32767]], np.int16)
    found = cpu_kernels.threshold(a, thresh=-300.7, maxval=40000.0, thresh_type=0)
    # above floor(-300.7) = -301; maxval saturated to 32767
    assert found.tolist() == [[0, 0, 32767, 32767, 32767]]
    found = cpu_kernels.threshold(a, thresh=-40000.0, maxval=1.0, thresh_type=2)
    assert found.tolist() == [[0, 0, 0, 0, 0]]  # TRUNC below the type's range: 0


# AddWeighted: uint8 and int16 bit-exact; float32 within its bound of OpenCV (in double)
WEIGHTS = [{"alpha": 0.7, "beta": -1.3, "gamma": 5.5}, {"alpha": 0.25, "beta": 0.75,
                                                          "gamma": -1000.0}]


@pytest.mark.parametrize("dtype", WIDE)
def test_add_weighted_on_photographs(dtype, frames, gpu):
    for i, pair in enumerate(frames[dtype]):
        a, b = pair if i == 0 else (_gray(pair[0]), _gray(pair[1]))
        params = WEIGHTS[i]
        opencv = cv2.addWeighted(a, params["alpha"], b, params["beta"], params["gamma"])
        if dtype == "int16":
            check("AddWeighted", [a, b], params, opencv, gpu, f"photo {i}")
            continue
        alpha, beta, gamma = (np.float32(params[k]) for k in ("alpha", "beta", "gamma"))
        ours = (a * alpha + b * beta) + gamma  # each operation rounded to float32
        check("AddWeighted", [a, b], params, ours, gpu, f"photo {i}")
        bound = 2.0 ** -22 * (np.abs(a * alpha) + np.abs(b * beta) + abs(gamma))
        assert (np.abs(ours.astype(np.float64) - opencv) <= bound).all()
        print(f"AddWeighted float32: {float((ours != opencv).mean()):.1%} of the elements "
              "differ from OpenCV's, within the bound")


# -- one generated program: int16 and float32 frames, every placement, fused and not -------------
CHAIN: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    "dx": ("Sobel", {"dx": 1, "dy": 0}, ("camera",)),
    "dy": ("Sobel", {"dx": 0, "dy": 1}, ("camera",)),
    "gdx": ("ExtractChannel", {"channel": 1}, ("dx",)),
    "mag": ("Magnitude", {}, ("dx", "dy")),
    "gray": ("RgbToGray", {}, ("camera",)),
    "mask": ("Threshold", {"thresh": 100, "maxval": 255, "thresh_type": 0}, ("gray",)),
    "erode_s": ("Erode", {}, ("dx",)),
    "dilate_f": ("Dilate", {}, ("mag",)),
    "erode_f": ("Erode", {}, ("mag",)),
    "dilate_s": ("Dilate", {}, ("gdx",)),
    "median_s": ("MedianBlur", {}, ("gdx",)),
    "median_f": ("MedianBlur", {}, ("mag",)),
    "thresh_s": ("Threshold", {"thresh": -100.5, "maxval": 40000.0, "thresh_type": 1}, ("dx",)),
    "thresh_f": ("Threshold", {"thresh": 50.25, "maxval": 7.5, "thresh_type": 2}, ("mag",)),
    "diff_s": ("AbsDiff", {}, ("dx", "erode_s")),
    "diff_f": ("AbsDiff", {}, ("mag", "dilate_f")),
    "blend_s": ("AddWeighted", {"alpha": 0.7, "beta": -1.3, "gamma": 5.5}, ("dx", "dy")),
    "blend_f": ("AddWeighted", {"alpha": 0.5, "beta": 0.25, "gamma": -3.0},
                ("mag", "median_f")),
    "xor_s": ("BitwiseXor", {}, ("dx", "dy")),
    "not_s": ("BitwiseNot", {}, ("xor_s",)),
    "cut_s": ("BitwiseAndMask", {}, ("gdx", "median_s", "mask")),
    "flip_s": ("FlipHorizontal", {}, ("thresh_s",)),
    "flipv_f": ("FlipVertical", {}, ("thresh_f",)),
    "rot_f": ("Rotate180", {}, ("diff_f",)),
    "mirror_s": ("VerticalMirror", {}, ("cut_s",)),
}


def _chain_opencv(type_name: str, params: dict, *inputs):
    if type_name == "Sobel":
        return cv2.Sobel(inputs[0], cv2.CV_16S, params["dx"], params["dy"], ksize=3)
    if type_name == "ExtractChannel":
        return cv2.extractChannel(inputs[0], params["channel"])
    if type_name == "Magnitude":
        return cpu_channels.magnitude(*inputs)  # the bytes; OpenCV's bound: test_ops_channels
    if type_name == "RgbToGray":
        return cv2.cvtColor(inputs[0], cv2.COLOR_RGB2GRAY)
    if type_name == "Threshold":
        return cv2.threshold(inputs[0], params["thresh"], params["maxval"],
                             params["thresh_type"])[1]
    if type_name == "AddWeighted":
        a, b = inputs
        if a.dtype == np.float32:  # the bytes; OpenCV's bound is tested above
            return cpu_kernels.add_weighted(a, b, **params)
        return cv2.addWeighted(a, params["alpha"], b, params["beta"], params["gamma"])
    if type_name == "BitwiseAndMask":
        return _bitwise_and_mask(*inputs)
    if type_name == "BitwiseXor":
        return cv2.bitwise_xor(*inputs)
    if type_name == "AbsDiff":
        return cv2.absdiff(*inputs)
    return ONE_INPUT[type_name](inputs[0])


@pytest.fixture(scope="module")
def program_outputs(tmp_path_factory, cl_context):
    require_opencl()
    from test_ops_yuv import placed_outputs

    return placed_outputs(tmp_path_factory.mktemp("dtypes_all"), "dtypes_all", CHAIN,
                          cl_context)


def test_generated_program_equals_opencv_on_every_placement(program_outputs):
    from test_imgproc_ops import _camera_frames

    kinds = set()
    for i, camera in enumerate(_camera_frames()):
        values = {"camera": camera}
        for name, (type_name, params, inputs) in CHAIN.items():
            values[name] = _chain_opencv(type_name, params, *(values[s] for s in inputs))
            kinds.add((type_name, values[name].dtype.name))
            for placement, components in program_outputs.items():
                ours = components[name][i]
                np.testing.assert_array_equal(ours.reshape(values[name].shape), values[name],
                                              err_msg=f"{placement}: {name}, frame {i}")
    for type_name in ("Erode", "Dilate", "MedianBlur", "Threshold", "AbsDiff", "AddWeighted"):
        assert {(type_name, "int16"), (type_name, "float32")} <= kinds, type_name


def test_fused_equals_unfused_equals_cpu(tmp_path, cl_context):
    require_opencl()
    from test_ops_yuv import assert_fused_equal, fused_builds

    generic = {t for t, _, _ in CHAIN.values()} - {"Sobel", "RgbToGray", "Magnitude",
                                                   "ExtractChannel"}
    assert_fused_equal(fused_builds(tmp_path, "dtypes_fused", CHAIN, cl_context), generic)


def test_every_library_kernel_compiles_without_a_warning(cl_context):
    """Every fusable library type's kernel alone, for each element type it takes (three
    channels where it takes them), builds on the OpenCL device with an empty log: a
    warning (an unused value, a constant condition, a narrowing) is a line a reviewer
    reads in the generated code, and the printer's pruning is meant to leave none."""
    import pyopencl as cl

    from gpucompgen.kernelgen.fused import group_kernel, group_of_one
    from gpucompgen.model import library_types

    require_opencl()
    built = 0
    for name, ctype in sorted(library_types().items()):
        if ctype.fusable is None or ctype.alias_of:
            continue
        first = next(iter(ctype.inputs.values()))
        channels = 3 if 3 in first.channel_counts else None
        for dtype in first.dtypes or (first.dtype,):
            params = {p: d.default for p, d in ctype.params.items()}
            if dtype != "uint8":  # OpenCV's rules: the input's depth, nearest neighbour
                params.update({p: v for p, v in (("ddepth", -1), ("interpolation", 0))
                               if p in params})
            one = ctype.specialized(dtype, channels, params)
            shapes = dict.fromkeys([*one.inputs, *one.outputs], (37, 53))
            text = group_kernel(group_of_one(one, params, shapes), "test")
            program = cl.Program(cl_context, text).build()
            log = "".join(program.get_build_info(d, cl.program_build_info.LOG)
                          for d in cl_context.devices)
            assert "warning" not in log.lower(), f"{name} {dtype}:\n{log}"
            built += 1
    assert built > 60
