"""The warps (warp.yaml: WarpAffine, WarpPerspective, Remap, Undistort) against OpenCV.

Each type runs as OpenCV's function, as its CPU form (warp_ops.py, which calls OpenCV),
as an independent numpy reference written here from the arithmetic OpenCV 5 was found to
use (float32 positions, fma, round half to even; cv2.undistort's fixed point), and as the
OpenCL kernel the generator writes from its index-map form (conftest.run_generated: what a
lone component runs), on PoCL. On the photographs (chelsea, coffee, astronaut in RGB and
gray) with rotations, scalings, shears and homographies, both interpolations, both border
modes and a border value: bit-exact where docs/library.md says so, else within the bound
it states (asserted here: largest difference and share of elements that differ).
Hypothesis then draws small frames, matrices and GPU settings.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_opencl, run_generated
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from gpucompgen.library import cpu_kernels

cv2 = pytest.importorskip("cv2")
skdata = pytest.importorskip("skimage.data")

PROPERTY = settings(max_examples=12, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])
F32 = np.float32


def warp_types():
    from gpucompgen.model import library_types

    return {n: t for n, t in library_types().items() if t.decl_file.name == "warp.yaml"}


# -- the independent reference: OpenCV 5's arithmetic, written from what was measured ------
def _fma(a, b, c):
    """float32 fma: the exact product (48 bits fit a double), one rounding to float32 of
    the double sum (double rounding changes no result this test compares)."""
    return (np.asarray(a, np.float64) * np.asarray(b, np.float64)
            + np.asarray(c, np.float64)).astype(F32)


def _grid(width, height):
    x = np.broadcast_to(np.arange(width, dtype=F32)[None, :], (height, width))
    y = np.broadcast_to(np.arange(height, dtype=F32)[:, None], (height, width))
    return x, y


def _row(h, i, x, y):
    """fma(h[i][0], x, h[i][1] * y + h[i][2]): the row part rounded to float32 first."""
    return _fma(h[i][0], x, (F32(h[i][1]) * y + F32(h[i][2])).astype(F32))


def _sample(src, sx, sy, interpolation, border_mode, border_value):
    """OpenCV 5's sampling of src at float32 positions."""
    h, w = src.shape[:2]
    sx = np.clip(np.nan_to_num(sx, nan=-4), -4, w + 4).astype(F32)
    sy = np.clip(np.nan_to_num(sy, nan=-4), -4, h + 4).astype(F32)
    planes = src.reshape(h, w, -1).astype(F32)

    def tap(yy, xx):
        inside = (xx >= 0) & (xx < w) & (yy >= 0) & (yy < h)
        v = planes[np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)]
        if border_mode == 0:
            v = np.where(inside[..., None], v, F32(border_value))
        return v

    if interpolation == 0:
        out = tap(np.rint(sy).astype(int), np.rint(sx).astype(int))
    else:
        fx, fy = np.floor(sx), np.floor(sy)
        ax, ay = (sx - fx)[..., None].astype(F32), (sy - fy)[..., None].astype(F32)
        x0, y0 = fx.astype(int), fy.astype(int)
        top = _fma(ax, tap(y0, x0 + 1) - tap(y0, x0), tap(y0, x0))
        bottom = _fma(ax, tap(y0 + 1, x0 + 1) - tap(y0 + 1, x0), tap(y0 + 1, x0))
        out = _fma(ay, bottom - top, top)
        if src.dtype == np.uint8:  # float32: the blend as it is
            out = np.clip(np.rint(out), 0, 255)
    return out.astype(src.dtype).reshape(sx.shape + src.shape[2:])


def numpy_warp_affine(src, m, width, height, flags, border_mode, border_value):
    h = np.asarray(m, F32)
    if not flags & 16:
        h = cv2.invertAffineTransform(h.astype(np.float64)).astype(F32)
    x, y = _grid(width, height)
    return _sample(src, _row(h, 0, x, y), _row(h, 1, x, y), flags & 1, border_mode,
                   border_value)


def numpy_warp_perspective(src, m, width, height, flags, border_mode, border_value):
    h = np.asarray(m, F32)
    if not flags & 16:
        h = np.linalg.inv(h.astype(np.float64)).astype(F32)
    x, y = _grid(width, height)
    w = _row(h, 2, x, y)
    with np.errstate(divide="ignore", invalid="ignore"):  # w = 0: the position (0, 0)
        return _sample(src, np.where(w != 0, _row(h, 0, x, y) / w, 0),
                       np.where(w != 0, _row(h, 1, x, y) / w, 0), flags & 1,
                       border_mode, border_value)


def numpy_remap(src, map1, map2, interpolation, border_mode, border_value):
    return _sample(src, map1.reshape(map1.shape[:2]), map2.reshape(map2.shape[:2]),
                   interpolation, border_mode, border_value)


def numpy_undistort(src, camera_matrix, dist_coeffs):
    """cv2.undistort: a remap with OpenCV's CV_16SC2 maps (positions rounded to 1/32
    pixel), bilinear weights (32 - ay)(32 - ax) 32 ... in 1/32768, zeros outside."""
    k = np.asarray(camera_matrix, F32).astype(np.float64)
    d = np.asarray(dist_coeffs, F32).astype(np.float64)
    h, w = src.shape[:2]
    fixed, frac = cv2.initUndistortRectifyMap(k, d, None, k, (w, h), cv2.CV_16SC2)
    mx = fixed[..., 0].astype(np.int64) * 32 + (frac & 31)
    my = fixed[..., 1].astype(np.int64) * 32 + (frac.astype(np.int64) >> 5)
    x0, y0, ax, ay = mx >> 5, my >> 5, (mx & 31)[..., None], (my & 31)[..., None]
    planes = src.reshape(h, w, -1).astype(np.int64 if src.dtype == np.uint8 else F32)

    def tap(yy, xx):
        inside = (xx >= 0) & (xx < w) & (yy >= 0) & (yy < h)
        return np.where(inside[..., None], planes[np.clip(yy, 0, h - 1),
                                                  np.clip(xx, 0, w - 1)], 0)
    if src.dtype == F32:  # float weights (1 - fy)(1 - fx) ..., the products in order
        fx, fy = (ax / 32).astype(F32), (ay / 32).astype(F32)
        gx, gy = F32(1) - fx, F32(1) - fy
        total = tap(y0, x0) * (gy * gx) + tap(y0, x0 + 1) * (gy * fx)
        total = total + tap(y0 + 1, x0) * (fy * gx)
        return (total + tap(y0 + 1, x0 + 1) * (fy * fx)).astype(F32).reshape(src.shape)
    total = ((32 - ay) * ((32 - ax) * tap(y0, x0) + ax * tap(y0, x0 + 1))
             + ay * ((32 - ax) * tap(y0 + 1, x0) + ax * tap(y0 + 1, x0 + 1)))
    return ((total * 32 + (1 << 14)) >> 15).astype(np.uint8).reshape(src.shape)


def opencv(type_name, arrays, params):
    """OpenCV's own call for a type, written out here (not through the CPU form)."""
    src = arrays[0]
    value = (params.get("border_value", 0),) * 4
    if type_name == "WarpAffine":
        return cv2.warpAffine(src, np.asarray(params["m"], F32).astype(np.float64),
                              (params["width"], params["height"]), flags=params["flags"],
                              borderMode=params["border_mode"], borderValue=value)
    if type_name == "WarpPerspective":
        return cv2.warpPerspective(src, np.asarray(params["m"], F32).astype(np.float64),
                                   (params["width"], params["height"]),
                                   flags=params["flags"],
                                   borderMode=params["border_mode"], borderValue=value)
    if type_name == "Remap":
        # two arrays of their own: OpenCV 5.0 misreads map1 and map2 that are one array
        return cv2.remap(src, arrays[1].copy(), arrays[2].copy(), params["interpolation"],
                         borderMode=params["border_mode"], borderValue=value)
    return cv2.undistort(src, np.asarray(params["camera_matrix"], F32).astype(np.float64),
                         np.asarray(params["dist_coeffs"], F32).astype(np.float64))


NUMPY = {"WarpAffine": numpy_warp_affine, "WarpPerspective": numpy_warp_perspective,
         "Remap": numpy_remap, "Undistort": numpy_undistort}


# -- parameter sets ---------------------------------------------------------------------------
def _tuple(m) -> tuple:
    return tuple(tuple(float(v) for v in row) for row in np.asarray(m, F32))


def affine_matrices(w, h):
    """A rotation with scaling about an off-centre point, a shear with translation, a
    pure scaling (a resize) and a mirror."""
    return [_tuple(cv2.getRotationMatrix2D((w * 0.4, h * 0.6), 33.0, 0.8)),
            _tuple([[1.1, 0.25, -20.5], [-0.1, 0.9, 15.25]]),
            _tuple([[0.5, 0, 0.25], [0, 0.75, 0]]),
            _tuple([[-1, 0, w - 1], [0, 1, 0]])]


def perspective_matrices(w, h):
    src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    out = []
    for shift in ([[20, 10], [-30, 25], [15, -20], [-5, 5]], [[-40, 0], [40, 0], [0, 0], [0, 0]]):
        out.append(_tuple(cv2.getPerspectiveTransform(src, src + np.float32(shift))))
    return out


def warp_cases(type_name, w, h):
    matrices = affine_matrices(w, h) if type_name == "WarpAffine" else \
        perspective_matrices(w, h)
    cases = []
    for i, m in enumerate(matrices):
        for flags in (16, 17, 0, 1):
            border_mode, value = [(0, 0), (1, 0), (0, 77)][(i + flags) % 3]
            cases.append({"m": m, "width": w - 17 + 5 * i, "height": h + 9 - 3 * i,
                          "flags": flags, "border_mode": border_mode,
                          "border_value": value})
    return cases


def remap_inputs(src):
    """Maps of a smaller output: a swirl about the centre (bilinear positions everywhere,
    some outside the frame)."""
    h, w = src.shape[:2]
    oh, ow = h - 13, w + 7
    x, y = np.meshgrid(np.arange(ow, dtype=np.float64), np.arange(oh, dtype=np.float64))
    dx, dy = x - ow / 2, y - oh / 2
    angle = 0.6 * np.exp(-(dx * dx + dy * dy) / (0.1 * w * h))
    map1 = (w / 2 + np.cos(angle) * dx - np.sin(angle) * dy).astype(F32)
    map2 = (h / 2 + np.sin(angle) * dx + np.cos(angle) * dy).astype(F32)
    return [src, map1, map2]


REMAP_CASES = [{"interpolation": i, "border_mode": b, "border_value": v}
               for i in (0, 1) for b, v in ((0, 0), (1, 0), (0, 200))]


def camera(w, h):
    return {"camera_matrix": _tuple([[0.9 * w, 0, w / 2 - 3.5], [0, 0.92 * w, h / 2 + 2.25],
                                     [0, 0, 1]]),
            "dist_coeffs": tuple(float(v) for v in np.float32([-0.28, 0.09, 0.001,
                                                                -0.0015, -0.01]))}


# the largest difference from OpenCV and the largest share of elements differing, per
# type and interpolation, where the kernel is not bit-exact (docs/library.md states them)
# bilinear warps: OpenCV's last SIMD-width columns of a row (its scalar tail) and a few
# perspective positions differ from the vector code in the last bit of the position,
# which moves a blend lying within 1e-4 of a half to the other side
# (nearest: a position within an ulp of a half there takes the other pixel)
BOUNDS = {("WarpAffine", 1): (1, 1e-4), ("WarpPerspective", 1): (1, 2e-4),
          ("WarpAffine", 0): (255, 1e-4), ("WarpPerspective", 0): (255, 1e-4),
          ("Undistort", 1): (8, 5e-4)}  # the position in float, OpenCV's map in double


def bound(type_name, params):
    """Without WARP_INVERSE_MAP the kernels invert m in double-float, OpenCV in double:
    both round the same inverse to float32, so the bounds are those of the inverse given."""
    interpolation = params.get("flags", params.get("interpolation", 1)) & 1
    return BOUNDS.get((type_name, interpolation), (0, 0.0))


MEASURED: list = []  # (what, largest difference, share differing) of every comparison


def assert_within(found, reference, limit, what):
    assert found.shape == reference.shape and found.dtype == reference.dtype, what
    diff = np.abs(found.astype(int) - reference.astype(int))
    MEASURED.append((what, int(diff.max(initial=0)), float((diff > 0).mean())))
    largest, share = limit
    assert diff.max(initial=0) <= largest, f"{what}: largest difference {diff.max()}"
    assert (diff > 0).mean() <= share, f"{what}: {(diff > 0).mean():.2%} differ"


# -- tests ---------------------------------------------------------------------------------
def test_every_warp_is_compared_flexible_fusable_and_in_geometry():
    types = warp_types()
    assert set(types) == set(NUMPY) <= set(cpu_kernels.CPU_IMPLEMENTATIONS)
    for name, t in types.items():
        assert t.flexible and t.fusable is not None and t.fusable.form == "index_map", name
        assert t.family == "geometry", name
        assert set(t.outputs) == {"dst"} and "src" in t.inputs, name


@pytest.fixture(scope="module")
def photos():
    """The photographs in RGB and gray, as tests/test_imgproc_ops.py has them."""
    from test_imgproc_ops import photos as fixture

    return fixture.__wrapped__()


@pytest.fixture(scope="module")
def gpu(cl_context, cl_queue):
    require_opencl()

    def run(type_name, arrays, params, shape, setting=(16, 16, 16, 1)):
        src = arrays[0]
        ctype = warp_types()[type_name].specialized(
            src.dtype.name, src.shape[2] if src.ndim == 3 else 1, params)
        return run_generated(cl_context, cl_queue, ctype, params, arrays, shape, setting)
    return run


def check_all(type_name, arrays, params, gpu, setting=None, what=""):
    reference = opencv(type_name, arrays, params)
    cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
    np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU form {what}")
    limit = bound(type_name, params)
    ours = NUMPY[type_name](*arrays, **params)  # the model of OpenCV's arithmetic
    if type_name == "Undistort":
        np.testing.assert_array_equal(ours, reference, err_msg=f"numpy reference {what}")
    else:
        assert_within(ours, reference, limit, f"numpy {type_name} {what} {params}")
    found = gpu(type_name, arrays, params, reference.shape,
                *(() if setting is None else (setting,)))
    assert_within(found, reference, limit, f"GPU {type_name} {what} {params}")


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("type_name", ["WarpAffine", "WarpPerspective"])
def test_warps_on_photographs(type_name, channels, photos, gpu):
    for i, versions in enumerate(photos):
        src = versions[channels]
        h, w = src.shape[:2]
        for params in warp_cases(type_name, w, h)[i::3]:  # each case on one photograph
            check_all(type_name, [src], params, gpu, what=f"photo {i}")


@pytest.mark.parametrize("channels", [1, 3])
def test_remap_on_photographs(channels, photos, gpu):
    for i, versions in enumerate(photos):
        arrays = remap_inputs(versions[channels])
        for params in REMAP_CASES[i::3]:
            check_all("Remap", arrays, params, gpu, what=f"photo {i}")


@pytest.mark.parametrize("channels", [1, 3])
def test_undistort_on_photographs(channels, photos, gpu):
    for i, versions in enumerate(photos):
        src = versions[channels]
        check_all("Undistort", [src], camera(src.shape[1], src.shape[0]), gpu,
                  what=f"photo {i}")


@pytest.mark.parametrize("channels", [1, 3])
def test_undistort_float32_frames_on_photographs(channels, photos, gpu):
    """float32: OpenCV's float weights of the same 1/32 positions, summed in order: the
    numpy model is cv2.undistort bit for bit; the kernel, whose position is computed in
    float (OpenCV's map in double), equals it but where a position rounds to the
    neighbouring 1/32 (at most 1 element in 1,000, measured 5.4 in 10,000 on the
    photographs: every such position shows in a float32 frame; each within 1/16 of the
    frame's range)."""
    for versions in photos:
        src = (versions[channels].astype(F32) - F32(100.3)) * F32(0.37)
        params = camera(src.shape[1], src.shape[0])
        reference = opencv("Undistort", [src], params)
        assert reference.dtype == F32
        np.testing.assert_array_equal(numpy_undistort(src, **params), reference)
        np.testing.assert_array_equal(
            cpu_kernels.CPU_IMPLEMENTATIONS["Undistort"](src, **params), reference)
        found = gpu("Undistort", [src], params, reference.shape)
        off = np.abs(found.astype(np.float64) - reference)
        assert (off > 0).mean() <= 1e-3
        assert off.max() <= float(src.max() - src.min()) / 16


def test_undistort_reference_is_opencv_on_photographs(photos):
    """The fixed-point model of numpy_undistort is cv2.undistort, bit for bit."""
    for versions in photos:
        for src in versions.values():
            params = camera(src.shape[1], src.shape[0])
            np.testing.assert_array_equal(numpy_undistort(src, **params),
                                          opencv("Undistort", [src], params))


# float32 frames: OpenCV's float arithmetic as for uint8, the blend not rounded; a border
# value with a fraction, negative. Remap bit-exact; the warps but for the last columns of a
# row that OpenCV's vector loop leaves to its scalar code (fewer than two vector widths:
# 32 columns covers AVX-512), where the position may differ by an ulp
TAIL = 32


@pytest.mark.parametrize("type_name", ["WarpAffine", "WarpPerspective", "Remap"])
def test_float32_frames_on_photographs(type_name, photos, gpu):
    for i, versions in enumerate(photos):
        src = (versions[1 + 2 * (i % 2)].astype(F32) - F32(100.3)) * F32(0.37)
        h, w = src.shape[:2]
        if type_name == "Remap":
            arrays, cases = remap_inputs(src), REMAP_CASES[i::2]
        else:
            arrays, cases = [src], warp_cases(type_name, w, h)[i::3]
        for case in cases:
            params = {**case, "border_value": -7.25 if case["border_value"] else 0.0}
            what = f"{type_name} float32 photo {i} {params}"
            reference = opencv(type_name, arrays, params)
            assert reference.dtype == F32
            cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
            np.testing.assert_array_equal(cpu, reference, err_msg=f"CPU form {what}")
            for name, found in (("numpy", NUMPY[type_name](*arrays, **params)),
                                ("GPU", gpu(type_name, arrays, params, reference.shape))):
                assert found.dtype == F32, what
                differ = (found != reference).reshape(reference.shape[:2] + (-1,)).any(-1)
                if type_name == "Remap":
                    assert not differ.any(), f"{name} {what}"
                    continue
                columns = np.nonzero(differ)[1]
                assert (columns >= reference.shape[1] - TAIL).all(), f"{name} {what}"
                if params.get("flags", 1) & 1:  # a position an ulp off, times the slope
                    largest = max(h, w) + 4.0
                    limit = 2.0 ** -21 * largest * float(src.max() - src.min()) + 1e-5
                    off = np.abs(found.astype(np.float64) - reference).max()
                    assert off <= limit, f"{name} {what}: {off} > {limit}"
                else:
                    assert differ.mean() <= 1e-3, f"{name} {what}"


def test_int16_frames_are_a_check_time_error(tmp_path):
    """OpenCV warps int16 frames with its fixed point of before (positions in 1/32
    pixel), which the kernels do not follow: the model is refused, where the frame
    enters."""
    from gpucompgen.build import compile_model
    from gpucompgen.errors import GpucompgenError

    model = tmp_path / "m.yaml"
    model.write_text("system: s\ncomponents:\n"
                     "  camera: {type: Camera, params: {width: 64, height: 48}}\n"
                     "  dx: {type: Sobel}\n  warp: {type: WarpAffine}\n"
                     "  to8: {type: ConvertScale}\n  sink: {type: FrameSink}\n"
                     "connections: [camera.image -> dx.src, dx.dst -> warp.src, "
                     "warp.dst -> to8.src, to8.dst -> sink.image]\n")
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "out")
    assert "'dx.dst' gives int16, 'warp.src' takes uint8 or float32" in str(info.value)


@st.composite
def affine_case(draw, perspective: bool):
    h, w = draw(st.integers(1, 24)), draw(st.integers(1, 24))
    channels = draw(st.sampled_from([1, 3]))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    src = rng.integers(0, 256, (h, w) if channels == 1 else (h, w, 3), dtype=np.uint8)
    m = [[draw(st.floats(-2, 2)) for _ in range(2)] + [draw(st.floats(-30, 30))]
         for _ in range(2)]
    if perspective:
        m.append([draw(st.floats(-0.01, 0.01)), draw(st.floats(-0.01, 0.01)), 1.0])
    square = np.asarray(m, np.float64)[:, :len(m)]
    assume(abs(np.linalg.det(square)) > 1e-3)  # check refuses a singular matrix (invertible)
    params = {"m": _tuple(m), "width": draw(st.integers(1, 24)),
              "height": draw(st.integers(1, 24)),
              "flags": draw(st.sampled_from([0, 1, 16, 17])),
              "border_mode": draw(st.integers(0, 1)), "border_value": draw(st.integers(0, 255))}
    if perspective:  # no output pixel on or near the horizon (w = 0): there OpenCV's
        # bilinear result is 0, whatever the border (docs/library.md)
        h = np.asarray(m, np.float64)
        h = h if params["flags"] & 16 else np.linalg.inv(h)
        x, y = _grid(params["width"], params["height"])
        assume(np.abs(h[2, 0] * x + h[2, 1] * y + h[2, 2]).min() > 1e-3)
    setting = draw(st.sampled_from([(8, 1, 1, 1), (16, 16, 16, 1), (32, 8, 3, 1)]))
    return src, params, setting


@PROPERTY
@given(case=affine_case(False))
def test_warp_affine_random_frames(case, gpu):
    src, params, setting = case
    check_all("WarpAffine", [src], params, gpu, setting, "random")


@PROPERTY
@given(case=affine_case(True))
def test_warp_perspective_random_frames(case, gpu):
    src, params, setting = case
    check_all("WarpPerspective", [src], params, gpu, setting, "random")


@st.composite
def remap_case(draw):
    h, w = draw(st.integers(1, 24)), draw(st.integers(1, 24))
    oh, ow = draw(st.integers(1, 24)), draw(st.integers(1, 24))
    channels = draw(st.sampled_from([1, 3]))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    src = rng.integers(0, 256, (h, w) if channels == 1 else (h, w, 3), dtype=np.uint8)
    # positions inside, on and past the edges, some whole and half pixels
    map1 = rng.uniform(-3, w + 3, (oh, ow)).astype(F32)
    map2 = rng.uniform(-3, h + 3, (oh, ow)).astype(F32)
    map1[::3] = np.round(map1[::3] * 2) / 2
    if draw(st.booleans()):  # one frame feeding both ports: the same array twice
        map2 = map1
    params = {"interpolation": draw(st.integers(0, 1)), "border_mode": draw(st.integers(0, 1)),
              "border_value": draw(st.integers(0, 255))}
    setting = draw(st.sampled_from([(8, 1, 1, 1), (16, 16, 16, 1), (32, 8, 3, 1)]))
    return [src, map1, map2], params, setting


@PROPERTY
@given(case=remap_case())
def test_remap_random_frames(case, gpu):
    arrays, params, setting = case
    check_all("Remap", arrays, params, gpu, setting, "random")


# -- in generated programs: placed on the GPU, the CPU, alternating; fused and unfused ------
FRAMES = 3
ROTATE = _tuple(cv2.getRotationMatrix2D((140.0, 90.0), 20.0, 0.9))  # 301x200 photos


def _lists(value):
    """Matrices (in a dict of parameters, or one) as nested lists, as chain_model writes
    them into YAML."""
    if isinstance(value, dict):
        return {k: _lists(v) for k, v in value.items()}
    return [_lists(v) for v in value] if isinstance(value, (tuple, list)) else value



# name: (type, params, inputs in port order; "camera" is the source, 301x200 RGB)
CHAIN: dict = {
    "gray": ("RgbToGray", {}, ("camera",)),
    "affine": ("WarpAffine", {"m": _lists(ROTATE), "width": 280, "height": 190,
                              "flags": 17, "border_mode": 0, "border_value": 40},
               ("camera",)),
    "blur": ("GaussianBlur", {"ksize": 3}, ("affine",)),  # a stencil over a warp
    "persp": ("WarpPerspective", {"m": _lists(perspective_matrices(301, 200)[0]),
                                  "width": 301, "height": 200, "flags": 16,
                                  "border_mode": 1, "border_value": 0}, ("gray",)),
    "mirror": ("WarpAffine", {"m": [[-1.0, 0.0, 300.0], [0.0, 1.0, 0.0]], "width": 301,
                              "height": 200, "flags": 16, "border_mode": 0,
                              "border_value": 0}, ("persp",)),  # a warp of a warp
    "lens": ("Undistort", _lists(camera(301, 200)), ("camera",)),
    "edges": ("Threshold", {"thresh": 100, "maxval": 255, "thresh_type": 0}, ("lens",)),
}
ENDS = ["blur", "mirror", "edges"]
MIXED = {name: ("cpu" if i % 2 else "gpu") for i, name in enumerate(CHAIN)}


def _opencv_of(type_name):
    if type_name in NUMPY:
        return lambda *arrays, **params: opencv(type_name, list(arrays), params)
    from test_imgproc import SPECS

    return SPECS[type_name].opencv


@pytest.fixture(scope="module")
def programs(tmp_path_factory, cl_context):
    """{variant: {component: frames}}: the chain built on the GPU with every output kept,
    on the CPU, alternating sides, and with only its ends kept fused (launches made so dear
    that every legal group forms) and unfused."""
    require_opencl()
    from conftest import load_generated, write_keep_types
    from test_imgproc_ops import chain_model

    from gpucompgen.build import compile_model, write
    from gpucompgen.passes.fuse import FUSION_COSTS

    folder = tmp_path_factory.mktemp("warps")
    write_keep_types(folder)
    found = {}
    for variant, placement, places, fusion, keep in (
            ("gpu", "gpu", None, "off", None), ("cpu", "cpu", None, "auto", None),
            ("mixed", "gpu", MIXED, "auto", None), ("fused", "gpu", None, "auto", ENDS),
            ("unfused", "gpu", None, "off", ENDS)):
        model = folder / f"warps_{variant}.yaml"
        model.write_text(chain_model("warps", CHAIN, placement, keep=keep))
        out = folder / f"out_{variant}"
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr("gpucompgen.passes.fuse.FUSION_COSTS",
                          {k: {**v, "launch_s": 1e6} for k, v in FUSION_COSTS.items()})
            built = compile_model(model, out, places=places, fusion=fusion)
        write(built, out)
        if variant == "fused":  # every warp inside a group
            grouped = {m.name for g in built.system.groups for m in g.members
                       if len(g.members) > 1}
            assert {"affine", "persp", "mirror", "lens"} <= grouped, grouped
        program = load_generated(out / "warps.py", f"warps_{variant}")
        result = program.run(frames=FRAMES, context=cl_context)
        assert result.frames == FRAMES
        found[variant] = {n: result.components[f"keep_{n}"].frames
                          for n in (keep or CHAIN)}
    return found


def test_programs_equal_opencv_on_every_placement(programs):
    """Each component's output equals OpenCV's function of its inputs as the program
    computed them (within the type's bound on the GPU); on the CPU, OpenCV's own chain."""
    for variant in ("gpu", "cpu", "mixed"):
        frames = programs[variant]
        for i in range(FRAMES):
            for name, (type_name, params, inputs) in CHAIN.items():
                if "camera" in inputs:
                    continue  # the source's frames are the photographs, read by the program
                arrays = [frames[s][i] for s in inputs]
                reference = _opencv_of(type_name)(*arrays, **params)
                limit = bound(type_name, params) if type_name in NUMPY else (0, 0.0)
                if variant == "cpu" or MIXED[name] == "cpu" and variant == "mixed":
                    limit = (0, 0.0)  # OpenCV's own call
                assert_within(np.asarray(frames[name][i]).reshape(reference.shape),
                              reference, limit, f"{variant}: {name}, frame {i}")


def test_fused_equals_unfused(programs):
    for name in ENDS:
        for i in range(FRAMES):
            np.testing.assert_array_equal(programs["fused"][name][i],
                                          programs["unfused"][name][i],
                                          err_msg=f"{name}, frame {i}")
            np.testing.assert_array_equal(programs["fused"][name][i],
                                          programs["gpu"][name][i])
