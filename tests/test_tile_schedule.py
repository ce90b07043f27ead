"""The staged schedule of the kernel generator (kernelgen/fused.py: staged_pieces):
a stencil read by a stencil — a stage of one type (Blur's row sums, an opening's
erosion: fusable.Stage) or a stencil member fused behind another — computed once a tile
into local memory, then read there, instead of at every read of it.  Decisions are
checked on described devices; results against OpenCV on frames narrower than the
window and than a tile, tiles of whole rows and of columns, one and three channels,
every border rule (a few builds: each is a kernel of its own)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import require_opencl, run_generated

from gpucompgen.kernelgen import fused
from gpucompgen.model import library_types


def _group(name, params, h=40, w=64, channels=1):
    t = library_types()[name]
    t = t.specialized("uint8", channels) if t.generic else t
    return fused.group_of_one(t, params, {"src": (h, w), "dst": (h, w)})


def _morph(op, ksize, shape=0, iterations=1):
    return {"op": op, "shape": shape, "ksize": ksize, "iterations": iterations}


def test_what_is_staged_and_in_what_tiles():
    """A stage is staged where its readers would read more than MIN_STAGED_READS input
    elements through it inline (Blur k7's 49, not k5's 25), and never one that reads one
    element (MorphologyEx's stage is src itself for erode and gradient); nothing on a
    GPU's schedule; tiles of whole rows where they fit, else of columns."""
    staged = {}
    for name, params in (("Blur", {"ksize": 3, "border_type": 4}),
                         ("Blur", {"ksize": 5, "border_type": 4}),
                         ("Blur", {"ksize": 7, "border_type": 4}),
                         ("Blur", {"ksize": 31, "border_type": 0}),
                         ("MorphologyEx", _morph(4, 5)), ("MorphologyEx", _morph(0, 15)),
                         ("MorphologyEx", _morph(2, 3)), ("MorphologyEx", _morph(6, 5, 2))):
        pieces, tile = fused.staged_pieces(_group(name, params), "runs")
        staged[name, params.get("ksize"), params.get("op")] = sorted(pieces)
        assert fused.staged_pieces(_group(name, params), "strided")[0] == frozenset()
    assert staged == {("Blur", 3, None): [], ("Blur", 5, None): [], ("Blur", 7, None): ["m.rows"],
                      ("Blur", 31, None): ["m.rows"], ("MorphologyEx", 5, 4): [],
                      ("MorphologyEx", 15, 0): [], ("MorphologyEx", 3, 2): ["m.inner"],
                      ("MorphologyEx", 5, 6): ["m.inner"]}
    # tiles: whole rows where they fit in STAGED_BYTES, else columns
    for w, expected in ((48, (32, 48)), (200, (32, 64)), (1280, None)):
        group = _group("Blur", {"ksize": 31, "border_type": 4}, 360, w)
        pieces, (rows, cols) = fused.staged_pieces(group, "runs")
        assert pieces == {"m.rows"}
        # (rows + 30) x cols int32 row sums: the sums down a column read them 15 rows
        # either side, in the same column
        assert (rows + 30) * cols * 4 <= fused.STAGED_BYTES
        assert (rows, cols) == expected or expected is None and cols < w
    # three channels: 12 bytes an element; 64 columns no longer fit with 8 rows, 16 do
    # (the narrowest tiles were 64 columns: RGB k31 ran inline, 961 reads an element)
    pieces, (rows, cols) = fused.staged_pieces(
        _group("Blur", {"ksize": 31, "border_type": 4}, 360, 640, channels=3), "runs")
    assert pieces == {"m.rows"} and (rows + 30) * cols * 12 <= fused.STAGED_BYTES
    text = fused.group_kernel(_group("Blur", {"ksize": 31, "border_type": 4}, 360, 1280),
                              "test")
    assert "    int _s0[" in text and "barrier" not in text


# (type, parameters, frame shape, launch settings, OpenCV): frames narrower than the
# window and than a tile, taller than a strip, wider than a column tile, 1 and 3 channels, every border rule; one build each
def _cv(op, k, shape=0, iterations=1):
    import cv2

    return lambda a: cv2.morphologyEx(a, op, cv2.getStructuringElement(shape, (k, k)),
                                      iterations=iterations)


def _blur(k, border):
    import cv2

    return lambda a: cv2.blur(a, (k, k), borderType=border)


CASES = [
    ("Blur", {"ksize": 15, "border_type": 0}, (5, 7), (8, 1, 1, 1), _blur(15, 0)),
    ("Blur", {"ksize": 9, "border_type": 2}, (45, 150, 3), (40, 2, 3, 1), _blur(9, 2)),
    ("Blur", {"ksize": 31, "border_type": 4}, (70, 200), (64, 2, 1, 1), _blur(31, 4)),
    ("Blur", {"ksize": 31, "border_type": 2}, (70, 90, 3), (64, 2, 1, 1), _blur(31, 2)),
    ("Blur", {"ksize": 7, "border_type": 1}, (3, 1), (4, 1, 2, 1), _blur(7, 1)),
    ("MorphologyEx", _morph(2, 5), (35, 90), (16, 4, 1, 1), _cv(2, 5)),
    ("MorphologyEx", _morph(6, 5, 2), (6, 4, 3), (8, 1, 1, 1), _cv(6, 5, 2)),
    ("MorphologyEx", _morph(3, 3, 0, 2), (33, 170), (40, 1, 3, 1), _cv(3, 3, 0, 2)),
    ("MorphologyEx", _morph(5, 7, 1), (17, 300, 3), (8, 2, 2, 1), _cv(5, 7, 1)),
]


@pytest.mark.parametrize("name,params,shape,settings,reference", CASES,
                         ids=[f"{c[0]}-{'-'.join(map(str, c[1].values()))}-{c[2]}"
                              for c in CASES])
def test_staged_kernels_equal_opencv(cl_context, cl_queue, name, params, shape, settings,
                                     reference):
    require_opencl()
    ctype = library_types()[name]
    group = _group(name, params, shape[0], shape[1], shape[2] if len(shape) == 3 else 1)
    assert fused.staged_pieces(group, "runs")[0], "the case must run the staged schedule"
    image = np.random.default_rng(sum(shape)).integers(0, 256, shape, dtype=np.uint8)
    got = run_generated(cl_context, cl_queue, ctype, params, [image], shape, settings)
    np.testing.assert_array_equal(got, reference(image))


def _chain(first, first_params, second, second_params, h, w):
    """The group of two library stencils, first feeding second (as the fuse pass makes
    it), on frames of h x w, one channel."""
    from gpucompgen.ir import Edge
    from gpucompgen.model import Endpoint

    types = library_types()
    a = fused.group_of_one(types[first].specialized("uint8", 1), first_params,
                           {"src": (h, w), "dst": (h, w)}, "a")
    b = fused.group_of_one(types[second].specialized("uint8", 1), second_params,
                           {"src": (h, w), "dst": (h, w)}, "b")
    return replace(b, members=[*a.members, *b.members], inputs=a.inputs, feeds=a.feeds,
                   internal=[Edge(Endpoint("a", "dst"), Endpoint("b", "src"))])


def test_a_stencil_behind_a_stencil_is_staged_and_equals_opencv(cl_context, cl_queue):
    """GaussianBlur 5x5 fused into a 3x3 erosion: inline, the erosion would compute the
    blur at each of its 9 taps (225 reads an output); staged, once a tile."""
    import cv2
    import pyopencl as cl

    from gpucompgen.c_convention import group_parameters

    require_opencl()
    h, w = 37, 101
    group = _chain("GaussianBlur", {"ksize": 5}, "Erode", {}, h, w)
    assert fused.staged_pieces(group, "runs")[0] == {"a"}
    assert fused.unrolled_reads(group) >= 225  # the blur's reads at each of 9 taps
    assert fused.unrolled_reads(group, frozenset({"a"})) == 9
    image = np.random.default_rng(3).integers(0, 256, (h, w), dtype=np.uint8)
    mf = cl.mem_flags
    src = cl.Buffer(cl_context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=image)
    out = cl.Buffer(cl_context, mf.READ_WRITE, h * w)
    program = cl.Program(cl_context, fused.group_kernel(group, "test")).build()
    kernel = cl.Kernel(program, fused.kernel_name(group))
    tile = 16
    kernel.set_args(*[src if p.role == "input" else out if p.role == "output"
                      else np.int32(tile) for p in group_parameters(group)])
    gsize, lsize = fused.launch_geometry(group, tile, 2, 2)
    cl.enqueue_nd_range_kernel(cl_queue, kernel, gsize, lsize)
    got = np.empty((h, w), np.uint8)
    cl.enqueue_copy(cl_queue, got, out)
    cl_queue.finish()
    expected = cv2.erode(cv2.GaussianBlur(image, (5, 5), 0), np.ones((3, 3), np.uint8))
    np.testing.assert_array_equal(got, expected)
