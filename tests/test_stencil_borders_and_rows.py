"""Stencil borders an int parameter picks (OpenCV's codes) and the CPU schedule's rows
computed together (backend/opencl/fused.py), against a numpy reference of their own: the
positions OpenCV's borderInterpolate reads, reflected step by step as it does (the kernel
reflects by a modulo)."""

from __future__ import annotations

import conftest
import numpy as np
import pytest
from conftest import require_opencl, run_generated

from gpucompgen.backend.opencl import fused
from gpucompgen.model import library_types

BORDER_CODES = (0, 1, 2, 4)  # BORDER_CONSTANT, _REPLICATE, _REFLECT, _REFLECT_101


def _source(p: int, n: int, border_type: int) -> int | None:
    """Where position p of a row of n reads under OpenCV's border_type (None: outside, 0)."""
    if 0 <= p < n:
        return p
    if border_type == 0:
        return None
    if border_type == 1 or n == 1:
        return min(max(p, 0), n - 1)
    delta = 1 if border_type == 4 else 0
    while not 0 <= p < n:
        p = -p - 1 + delta if p < 0 else n - 1 - (p - n) - delta
    return p


def _blur_reference(image: np.ndarray, ksize: int, border_type: int) -> np.ndarray:
    """The ksize x ksize mean, rounded to nearest, with border_type's reads outside."""
    r = ksize // 2
    h, w = image.shape[:2]
    total = np.zeros(image.shape, np.int64)
    for y in range(h):
        for x in range(w):
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    v, u = _source(y + dy, h, border_type), _source(x + dx, w, border_type)
                    if v is not None and u is not None:
                        total[y, x] += image[v, u]
    return ((total + ksize * ksize // 2) // (ksize * ksize)).astype(np.uint8)


def test_a_border_parameter_is_a_constant_of_the_build():
    from gpucompgen.convention import group_constants
    from gpucompgen.passes.program_facts import size_names

    blur = library_types()["Blur"]
    decl = blur.fusable
    assert decl.border == "border_type"
    assert decl.radius_names() == {"ksize", "border_type"}
    assert {code: decl.border_of({"border_type": code}) for code in (0, 1, 2, 4)} == \
        {0: "constant", 1: "clamp", 2: "reflect", 4: "reflect101"}
    with pytest.raises(ValueError, match="border code"):
        decl.border_of({"border_type": 3})
    assert "border_type" in size_names(blur)  # not settable at run time: the accessors
    group = fused.group_of_one(blur.specialized("uint8", 1), {"ksize": 3, "border_type": 2},
                               {"src": (5, 7), "dst": (5, 7)})
    assert not [p for p in group_constants(group) if p.param.endswith("border_type")]
    assert "_reflect((y_), 5)" in fused.group_kernel(group, "test")


@pytest.mark.parametrize("border_type", BORDER_CODES)
@pytest.mark.parametrize("channels", [1, 3])
def test_every_border_rule_equals_numpy_pad(cl_context, cl_queue, border_type, channels):
    require_opencl()
    rng = np.random.default_rng(border_type * 10 + channels)
    blur = library_types()["Blur"]
    for h, w in ((1, 1), (2, 3), (3, 1), (5, 7), (9, 4), (12, 11)):
        shape = (h, w) if channels == 1 else (h, w, channels)
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        for ksize in (3, 5, 9):
            params = {"ksize": ksize, "border_type": border_type}
            got = run_generated(cl_context, cl_queue, blur, params, [image], shape,
                                (4, 1, 2, 1))
            np.testing.assert_array_equal(got, _blur_reference(image, ksize, border_type),
                                          err_msg=f"{shape} {params}")


def test_rows_together_only_for_small_stencil_groups_on_a_cpu():
    types = library_types()

    def group(name, params, h=20, w=30):
        t = types[name]
        t = t.specialized("uint8", 1) if t.generic else t
        return fused.group_of_one(t, params, {"src": (h, w), "dst": (h, w)})

    assert fused.rows_together(group("Erode", {}), "runs") == fused.ROWS_TOGETHER
    assert fused.rows_together(group("Erode", {}), "strided") == 1  # a GPU
    assert fused.rows_together(group("Threshold", {"thresh": 1, "maxval": 2,
                                                   "thresh_type": 0}), "runs") == 1
    big = {"op": 2, "shape": 0, "ksize": 7, "iterations": 1}  # 13 x 13 reads an element
    assert fused.rows_together(group("MorphologyEx", big), "runs") == 1
    text = fused.group_kernel(group("Erode", {}), "test")
    assert f"_p += {fused.ROWS_TOGETHER} * _n" in text


@pytest.mark.parametrize("name,params", [
    ("Erode", {}), ("Blur", {"ksize": 3, "border_type": 4}),
    ("MorphologyEx", {"op": 4, "shape": 1, "ksize": 3, "iterations": 1})])
def test_rows_together_compute_what_one_row_at_a_time_computes(
        cl_context, cl_queue, monkeypatch, name, params):
    """Heights around the groups of rows, work-groups' tiles, 1 and 3 channels:
    the kernel that computes rows together equals the one that computes a row at a time
    (generated with ROWS_TOGETHER 1), element for element."""
    require_opencl()

    t = library_types()[name]
    rng = np.random.default_rng(7)
    default = fused.ROWS_TOGETHER
    # 11 rows: groups of 4 rows, the rows left over, the borders; 5 rows: one group at most
    for shape in ((11, 23, 3), (5, 23)):
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        results = []
        for together in (default, 1):
            monkeypatch.setattr(fused, "ROWS_TOGETHER", together)
            conftest._GENERATED.clear()
            for setting in ((8, 1, 1, 1), (5, 2, 3, 1), (32, 8, 8, 1)):
                results.append(run_generated(cl_context, cl_queue, t, params, [image],
                                             shape, setting))
        for r in results[1:]:
            np.testing.assert_array_equal(r, results[0], err_msg=f"{name} {shape}")
    conftest._GENERATED.clear()


@pytest.mark.parametrize("op,ksize,iterations,ok", [
    (2, 15, 1, True), (3, 5, 3, True), (3, 15, 2, False), (5, 9, 4, False),
    (0, 15, 4, True), (4, 15, 4, True)])
def test_a_window_of_windows_too_large_for_one_kernel_is_refused(tmp_path, op, ksize,
                                                                  iterations, ok):
    """Open, close, top hat and black hat of (ksize // 2) * iterations above 7 would read
    more than 15^4 elements an output (ksize 15, 4 iterations: not compiled in 5 minutes):
    check refuses them, saying what to chain instead."""
    from gpucompgen.build import compile_model
    from gpucompgen.errors import GpucompgenError

    model = tmp_path / "m.yaml"
    model.write_text(
        "system: morph\ncomponents:\n"
        "  src: {type: StillImage, params: {width: 64, height: 48}}\n"
        f"  morph: {{type: MorphologyEx, params: {{op: {op}, ksize: {ksize}, "
        f"iterations: {iterations}}}}}\n"
        "  sink: {type: FrameSink}\n"
        "connections:\n  - src.image -> morph.src\n  - morph.dst -> sink.image\n")
    if ok:
        compile_model(model, tmp_path / "out")
        return
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "out")
    text = str(info.value)
    assert "m.yaml:4:3" in text and "window of windows" in text and "op 0 then op 1" in text
