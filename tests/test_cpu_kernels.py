"""The library's CPU implementations (gpucompgen/library/cpu_kernels.py) against its kernels.

Each kernel is built from gpucompgen/library/*.cl and launched directly with pyopencl on
the pinned device (PoCL in CI), its arguments in the order the calling convention
declares (gpucompgen/c_convention.py), with random sizes (odd ones, one
pixel high or wide), parameters, images and GPU settings; the CPU function must give
the same bytes. Each CPU function is also compared with an independent reference:
np.flipud and cv2.flip, np.hstack, the detector's rule written per pixel, and for the
box blur a sum of shifted copies and OpenCV's cv2.blur with BORDER_REPLICATE (the
kernel's clamped coordinates; OpenCV's default border, BORDER_REFLECT_101, differs).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from gpucompgen.library import cpu_kernels

LIBRARY = ROOT / "gpucompgen" / "library"
PROPERTY = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
# BoxBlur's kernel is generated for each size and radius (constants of the kernel, 4 rows
# together for windows up to 5x5): each drawn example is a new build of 1 to 3 s, so its
# properties draw fewer, and radii to 3 (a 15x15 window builds in seconds: their @examples
# pin radius 7 and the extreme sizes)
# each example is a kernel build (sizes are constants of it): 10 drawn, besides the
# @example edge cases each test states
GENERATED_PROPERTY = settings(PROPERTY, max_examples=10)

sizes = st.integers(1, 40) | st.sampled_from([16, 32, 48, 63, 64, 65])
images = st.integers(0, 2 ** 32 - 1)  # a seed: hypothesis shrinks it, numpy draws pixels


def random_image(seed: int, height: int, width: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


@st.composite
def gpu_settings(draw, type_name: str):
    from gpucompgen.model import library_types

    tiles = library_types()[type_name].gpu.tiles or [8, 16, 32]
    blocks = st.sampled_from([1, 2, 3, 4, 8, 16])
    return draw(st.sampled_from(list(tiles))), draw(blocks), draw(blocks)


class Kernels:
    """Launch a library type's kernel as the calling convention says, and read back."""

    def __init__(self, context, queue):
        self.context, self.queue, self.programs = context, queue, {}

    def run(self, type_name: str, inputs: dict, outputs: dict, params: dict, setting):
        import pyopencl as cl

        from gpucompgen.c_convention import kernel_parameters
        from gpucompgen.model import library_types

        ctype = library_types()[type_name]
        if ctype.kernel_file is None:  # generated from the type's form, as a lone one runs
            from conftest import run_generated

            tile, block_x, block_y = setting
            return [run_generated(self.context, self.queue, ctype, params,
                                  list(inputs.values()), shape, (tile, block_x, block_y, 1))
                    for shape in outputs.values()]
        if type_name not in self.programs:
            source = (LIBRARY / ctype.kernel_file.name).read_text()
            self.programs[type_name] = cl.Program(self.context, source).build()
        kernel = cl.Kernel(self.programs[type_name], ctype.kernel_function)
        mf = cl.mem_flags
        arrays = {**inputs, **{k: np.empty(shape, np.uint8) for k, shape in outputs.items()}}
        buffers = {k: cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                hostbuf=np.ascontiguousarray(v)) for k, v in inputs.items()}
        buffers.update({k: cl.Buffer(self.context, mf.READ_WRITE, arrays[k].nbytes)
                        for k in outputs})
        tile, block_x, block_y = setting
        args = []
        for p in kernel_parameters(ctype):
            if p.kind == "buffer":
                args.append(buffers[p.port])
            elif p.role == "size":
                args.append(np.int32(arrays[p.port].shape[0 if p.dim == "height" else 1]))
            elif p.role == "param":
                args.append(np.int32(params[p.param]))
            else:
                args.append(np.int32(tile))
        kernel.set_args(*args)
        # the grid covers the (only) output port: tile x tile squares, or tile whole rows
        height, width = next(iter(outputs.values()))[:2]
        groups_x = 1 if ctype.cover == "rows" else -(-width // tile)
        cl.enqueue_nd_range_kernel(self.queue, kernel,
                                   (groups_x * block_x, -(-height // tile) * block_y, 1),
                                   (block_x, block_y, 1))
        for name in outputs:
            cl.enqueue_copy(self.queue, arrays[name], buffers[name])
        self.queue.finish()
        for buffer in buffers.values():
            buffer.release()
        return [arrays[name] for name in outputs]


@pytest.fixture(scope="module")
def kernels(cl_context, cl_queue):
    return Kernels(cl_context, cl_queue)


# -- VerticalMirror ---------------------------------------------------------------------
@PROPERTY
@given(height=sizes, width=sizes, seed=images, setting=gpu_settings("VerticalMirror"))
@example(height=1, width=1, seed=0, setting=(8, 1, 1))
@example(height=7, width=16, seed=1, setting=(8, 8, 8))  # rows of 48 bytes: uint4 copies
def test_vertical_mirror(kernels, height, width, seed, setting):
    image = random_image(seed, height, width)
    cpu = cpu_kernels.vertical_mirror(image)
    np.testing.assert_array_equal(cpu, np.flipud(image))
    assert cpu.flags.c_contiguous
    (gpu,) = kernels.run("VerticalMirror", {"image": image},
                         {"mirrored": (height, width, 3)}, {}, setting)
    np.testing.assert_array_equal(cpu, gpu)


def test_vertical_mirror_matches_opencv():
    cv2 = pytest.importorskip("cv2")
    image = random_image(3, 37, 21)
    np.testing.assert_array_equal(cpu_kernels.vertical_mirror(image), cv2.flip(image, 0))


# -- ImageMerger ------------------------------------------------------------------------
@PROPERTY
@given(height=sizes, left_width=sizes, right_width=sizes, seed=images,
       setting=gpu_settings("ImageMerger"))
@example(height=1, left_width=1, right_width=1, seed=0, setting=(8, 1, 1))
def test_image_merger(kernels, height, left_width, right_width, seed, setting):
    left = random_image(seed, height, left_width)
    right = random_image(seed + 1, height, right_width)
    cpu = cpu_kernels.image_merger(left, right)
    np.testing.assert_array_equal(cpu, np.hstack((left, right)))
    (gpu,) = kernels.run("ImageMerger", {"left": left, "right": right},
                         {"merged": (height, left_width + right_width, 3)}, {}, setting)
    np.testing.assert_array_equal(cpu, gpu)


def test_image_merger_refuses_different_heights():
    with pytest.raises(ValueError, match="same height"):
        cpu_kernels.image_merger(random_image(0, 4, 5), random_image(0, 5, 5))


# -- ObjectDetector ---------------------------------------------------------------------
def detector_reference(frame, red_min, margin):
    """The kernel's is_red(), one pixel at a time in Python ints."""
    mask = np.zeros(frame.shape[:2], np.uint8)
    for y in range(frame.shape[0]):
        for x in range(frame.shape[1]):
            r, g, b = (int(v) for v in frame[y, x])
            mask[y, x] = 255 if r >= red_min and r - g >= margin and r - b >= margin else 0
    return mask


thresholds = st.integers(0, 255) | st.sampled_from([-1000, -256, -255, -1, 256, 1000])


@PROPERTY
@given(height=st.integers(1, 24), width=st.integers(1, 24), seed=images,
       red_min=thresholds, margin=thresholds, setting=gpu_settings("ObjectDetector"))
@example(height=1, width=1, seed=0, red_min=150, margin=80, setting=(8, 1, 1))
def test_object_detector(kernels, height, width, seed, red_min, margin, setting):
    frame = random_image(seed, height, width)
    # pixels on each side of the thresholds: red exactly red_min, differences exactly margin
    if 0 <= red_min <= 255 and 0 <= red_min - margin <= 255:
        frame[0, 0] = (red_min, red_min - margin, red_min - margin)
    cpu = cpu_kernels.object_detector(frame, red_min=red_min, margin=margin)
    np.testing.assert_array_equal(cpu, detector_reference(frame, red_min, margin))
    (gpu,) = kernels.run("ObjectDetector", {"frame": frame}, {"mask": (height, width)},
                         {"red_min": red_min, "margin": margin}, setting)
    np.testing.assert_array_equal(cpu, gpu)


def test_object_detector_on_a_camera_frame(kernels):
    from gpucompgen.library.camera import Camera

    cam = Camera(seed=4, width=161, height=97)
    cam.initialize()
    frame = cam.execute()
    cpu = cpu_kernels.object_detector(frame, red_min=150, margin=80)
    assert 0 < np.count_nonzero(cpu) < cpu.size  # the buoys, and only them
    (gpu,) = kernels.run("ObjectDetector", {"frame": frame}, {"mask": (97, 161)},
                         {"red_min": 150, "margin": 80}, (32, 16, 16))
    np.testing.assert_array_equal(cpu, gpu)


# -- BoxBlur ----------------------------------------------------------------------------
def blur_reference(image, radius):
    """Sum of the (2r + 1)^2 shifted copies, coordinates clamped, rounded half up."""
    height, width = image.shape[:2]
    total = np.zeros(image.shape, np.int64)
    for dy in range(-radius, radius + 1):
        rows = np.clip(np.arange(height) + dy, 0, height - 1)
        for dx in range(-radius, radius + 1):
            cols = np.clip(np.arange(width) + dx, 0, width - 1)
            total += image[rows[:, None], cols[None, :]]
    n = (2 * radius + 1) ** 2
    return ((total + n // 2) // n).astype(np.uint8)


@GENERATED_PROPERTY
@given(height=sizes, width=sizes, seed=images, radius=st.integers(0, 3),
       setting=gpu_settings("BoxBlur"))
@example(height=1, width=1, seed=0, radius=7, setting=(8, 1, 1))
@example(height=1, width=33, seed=0, radius=3, setting=(16, 4, 1))
@example(height=33, width=1, seed=0, radius=3, setting=(16, 1, 4))
@example(height=40, width=37, seed=2, radius=7, setting=(16, 4, 4))  # an interior at 7
def test_box_blur(kernels, height, width, seed, radius, setting):
    image = random_image(seed, height, width)
    cpu = cpu_kernels.box_blur(image, radius=radius)
    np.testing.assert_array_equal(cpu, blur_reference(image, radius))
    (gpu,) = kernels.run("BoxBlur", {"image": image}, {"smooth": (height, width, 3)},
                         {"radius": radius}, setting)
    np.testing.assert_array_equal(cpu, gpu)


@settings(max_examples=100, deadline=None)
@given(height=sizes, width=sizes, seed=images, radius=st.integers(0, 7))
def test_box_blur_matches_opencv_with_replicated_borders(height, width, seed, radius):
    cv2 = pytest.importorskip("cv2")
    image = random_image(seed, height, width)
    side = 2 * radius + 1
    expected = cv2.blur(image, (side, side), borderType=cv2.BORDER_REPLICATE)
    np.testing.assert_array_equal(cpu_kernels.box_blur(image, radius=radius), expected)


def test_box_blur_extremes_and_large_radius():
    white = np.full((3, 4, 3), 255, np.uint8)
    np.testing.assert_array_equal(cpu_kernels.box_blur(white, radius=7), white)
    image = random_image(5, 9, 11)
    np.testing.assert_array_equal(cpu_kernels.box_blur(image, radius=0), image)
    # beyond the type's range the sums leave uint16: still exact
    np.testing.assert_array_equal(cpu_kernels.box_blur(image, radius=9),
                                  blur_reference(image, 9))
    # by hand: a 1 x 2 frame, radius 1. Output pixel 0's window, clamped, is rows 0, 0, 0
    # by columns 0, 0, 1: three times (1, 2, 3), sums 3, 6, 9 over n = 9 pixels, and
    # (sum + 4) // 9 = 0, 1, 1 (3/9 rounds down, 6/9 and 9/9 to 1)
    pair = np.array([[[0, 0, 0], [1, 2, 3]]], np.uint8)
    np.testing.assert_array_equal(cpu_kernels.box_blur(pair, radius=1)[0, 0], [0, 1, 1])


# -- the interface ----------------------------------------------------------------------
def test_registry_names_library_types_with_kernels():
    from gpucompgen.model import library_types

    types = library_types()
    for name in cpu_kernels.CPU_IMPLEMENTATIONS:
        # a kernel: hand-written, or generated from the type's fusable form
        assert types[name].gpu_aware and (types[name].kernel_file is not None
                                          or types[name].fusable is not None)


def test_out_arrays_are_filled_and_checked():
    image = random_image(1, 6, 5)
    out = np.empty((6, 5, 3), np.uint8)
    assert cpu_kernels.box_blur(image, radius=2, out=out) is out
    np.testing.assert_array_equal(out, blur_reference(image, 2))
    assert cpu_kernels.vertical_mirror(image, out=out) is out
    np.testing.assert_array_equal(out, np.flipud(image))
    merged = np.empty((6, 10, 3), np.uint8)
    assert cpu_kernels.image_merger(image, image, out=merged) is merged
    mask = np.empty((6, 5), np.uint8)
    assert cpu_kernels.object_detector(image, red_min=0, margin=-255, out=mask) is mask
    assert (mask == 255).all()
    with pytest.raises(ValueError, match=r"out= for 'dst' must be a C-contiguous uint8"):
        cpu_kernels.vertical_mirror(image, out=np.empty((5, 6, 3), np.uint8))


@pytest.mark.parametrize("bad,message", [
    (np.zeros((4, 4, 2), np.uint8), "height x width x 3"),  # one channel or three
    (np.zeros((4, 4, 4), np.uint8), "height x width x 3"),
    (np.zeros((0, 4, 3), np.uint8), "at least 1"),
    (np.zeros((4, 4, 3), np.float32), "uint8 numpy array"),
])
def test_bad_inputs_are_refused_with_the_port_named(bad, message):
    with pytest.raises((ValueError, TypeError), match=message) as info:
        cpu_kernels.box_blur(bad, radius=1)
    assert "BoxBlur: 'src'" in str(info.value)


# -- generic over channels: BoxBlur and VerticalMirror take 1 or 3 ------------------------
@GENERATED_PROPERTY
@given(height=sizes, width=sizes, seed=images, radius=st.integers(0, 3),
       setting=gpu_settings("BoxBlur"))
@example(height=1, width=1, seed=0, radius=7, setting=(8, 1, 1))
def test_box_blur_and_mirror_over_one_channel(kernels, height, width, seed, radius, setting):
    """A gray frame, as a component fed one gets it (resolve-types): the kernel generated
    for one channel, the CPU function, the reference and OpenCV agree."""
    cv2 = pytest.importorskip("cv2")
    gray = np.ascontiguousarray(random_image(seed, height, width)[..., 1])
    side = 2 * radius + 1
    cpu = cpu_kernels.box_blur(gray, radius=radius)
    np.testing.assert_array_equal(cpu, cv2.blur(gray, (side, side),
                                                 borderType=cv2.BORDER_REPLICATE))
    np.testing.assert_array_equal(cpu, blur_reference(gray, radius))
    (gpu,) = kernels.run("BoxBlur", {"src": gray}, {"dst": (height, width)},
                         {"radius": radius}, setting)
    np.testing.assert_array_equal(gpu, cpu)
    mirrored = cpu_kernels.vertical_mirror(gray)
    np.testing.assert_array_equal(mirrored, cv2.flip(gray, 0))
    (gpu,) = kernels.run("VerticalMirror", {"src": gray}, {"dst": (height, width)}, {},
                         setting)
    np.testing.assert_array_equal(gpu, mirrored)


@pytest.mark.parametrize("channels", [1, 3])
def test_box_blur_and_mirror_on_photographs(kernels, channels):
    cv2 = pytest.importorskip("cv2")
    skdata = pytest.importorskip("skimage.data")
    for load in (skdata.chelsea, skdata.coffee, skdata.astronaut):
        image = np.ascontiguousarray(load())
        if channels == 1:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        shape = image.shape
        for radius in (1, 3):
            side = 2 * radius + 1
            expected = cv2.blur(image, (side, side), borderType=cv2.BORDER_REPLICATE)
            np.testing.assert_array_equal(cpu_kernels.box_blur(image, radius=radius), expected)
            (gpu,) = kernels.run("BoxBlur", {"src": image}, {"dst": shape},
                                 {"radius": radius}, (16, 16, 4))
            np.testing.assert_array_equal(gpu, expected)
        expected = cv2.flip(image, 0)
        np.testing.assert_array_equal(cpu_kernels.vertical_mirror(image), expected)
        (gpu,) = kernels.run("VerticalMirror", {"src": image}, {"dst": shape}, {}, (16, 16, 4))
        np.testing.assert_array_equal(gpu, expected)
