"""The kernel generator (kernelgen/fused.py) and the fusion cost model (passes/fuse.py).

- Names: whatever the model calls its components (like a port, like the generated
  kernel's own locals and macros, like a snippet's locals), every group kernel compiles
  and gives the bytes of the unfused program: the generator's names live in their own
  namespace (a leading underscore, which model names cannot have).  Hypothesis draws the
  names from a hostile pool.
- The cost model: every group chosen is estimated cheaper than its members apart, plan
  reports exactly the groups chosen with their estimate, and a chain of index maps that
  each read their input many times is refused rather than fused into an explosion.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from conftest import load_generated, require_opencl
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen.build import compile_model, write

# names the generated kernels used (or use) for themselves, the library snippets' locals,
# the ports of the types below, OpenCL-ish words a model may use
HOSTILE = ["image", "row", "tile", "y0", "y1", "x0", "x1", "per", "nx", "x", "y", "c", "a", "b",
           "GROUP_ARGS", "GROUP_PARAMS", "src1", "src2", "diff", "eroded", "mirrored",
           "flipped", "rotated", "t", "p4", "r0", "h2", "w1", "shift", "m0", "in0",
           "out", "reflect101", "thresholded", "only", "group", "m0_a", "a_b"]
_built = itertools.count()

CHAIN = """\
system: hostile
components:
  {src}: {{type: StillImage, params: {{width: 23, height: 11}}}}
  {n1}: {{type: FlipHorizontal}}
  {n2}: {{type: Rotate180}}
  {n3}: {{type: AbsDiff}}
  {n4}: {{type: Erode}}
  {n5}: {{type: VerticalMirror}}
  {sink}: {{type: FrameSink}}
connections:
  - {src}.image -> {n1}.image
  - {src}.image -> {n2}.image
  - {n1}.flipped -> {n3}.src1
  - {n2}.rotated -> {n3}.src2
  - {n3}.diff -> {n4}.image
  - {n4}.eroded -> {n5}.image
  - {n5}.mirrored -> {sink}.image
"""


def _frames(model: Path, out: Path, fusion: str):
    result = compile_model(model, out, fusion=fusion)
    write(result, out)
    module = load_generated(out / "hostile.py", f"hostile_{out.name}_{next(_built)}")
    got = []
    original = module.FrameSink.execute

    def spy(self, *data):
        got.extend(np.array(d, copy=True) for d in data)
        return original(self, *data)

    module.FrameSink.execute = spy
    try:
        module.run(frames=1)
    finally:
        module.FrameSink.execute = original
    return result, got


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from(HOSTILE), min_size=7, max_size=7, unique=True))
def test_hostile_component_names_compile_and_fuse_to_the_same_bytes(tmp_path_factory, names):
    require_opencl()
    keys = ("src", "n1", "n2", "n3", "n4", "n5", "sink")
    folder = tmp_path_factory.mktemp("hostile")
    model = folder / "m.yaml"
    model.write_text(CHAIN.format(**dict(zip(keys, names))))
    fused, got = _frames(model, folder / "fused", "auto")
    assert fused.system.plan.groups, "the chain must fuse somewhere for the test to mean much"
    _, expected = _frames(model, folder / "unfused", "off")
    assert len(got) == len(expected) == 1
    np.testing.assert_array_equal(got[0], expected[0])


def test_a_group_is_never_named_like_a_component_of_the_model(tmp_path):
    """b1 and mirror fuse into a group that would be named b1_mirror; the model has a
    component b1_mirror elsewhere (itself fused away, into a group of its own)."""
    model = tmp_path / "m.yaml"
    model.write_text(
        "system: s\ncomponents:\n"
        "  src: {type: StillImage, params: {width: 16, height: 8}}\n"
        "  b1: {type: Threshold}\n  mirror: {type: VerticalMirror}\n"
        "  b1_mirror: {type: Threshold}\n  last: {type: VerticalMirror}\n"
        "  s1: {type: FrameSink}\n  s2: {type: FrameSink}\n"
        "connections:\n  - src.image -> b1.image\n  - b1.thresholded -> mirror.image\n"
        "  - mirror.mirrored -> s1.image\n  - src.image -> b1_mirror.image\n"
        "  - b1_mirror.thresholded -> last.image\n  - last.mirrored -> s2.image\n")
    plan = compile_model(model, tmp_path / "out").system.plan
    names = {g.part for g in plan.groups}
    assert len(names) == 2
    assert not names & {"b1", "mirror", "b1_mirror", "last", "src", "s1", "s2"}


def test_every_group_chosen_is_estimated_cheaper_and_plan_reports_it(tmp_path):
    from gpucompgen.plan import plan_lines

    root = Path(__file__).resolve().parent.parent
    for path in sorted((root / "models").glob("*.yaml")):
        result = compile_model(path, tmp_path / path.stem)  # every example model builds
        plan = result.system.plan
        text = "\n".join(plan_lines(plan))
        for g in plan.groups:
            assert g.estimate.startswith("estimate: "), g
            fused, apart = (float(n) for n in
                            __import__("re").findall(r"([\d.]+) ms", g.estimate)[:2])
            assert fused < apart, (path.name, g)
            assert f"{g.part}: one kernel" in text
        for g in result.system.groups:  # the figures the plan shows are the ones decided
            assert g.estimate_s[0] < g.estimate_s[1], (path.name, g.name)
            assert f"{g.estimate_s[0] * 1e3:.3f} ms a frame as one kernel" in g.estimate
        assert text.count(": one kernel (") == len(plan.groups)


INDEX_MAP_40 = """\
component_types:
  Read40:
    kind: gpu-aware
    inputs:
      image: {{memory: gpu, dtype: uint8, channels: 3}}
    outputs:
      out: {{memory: gpu, dtype: uint8, channels: 3}}
    kernel: {{file: op.cl, function: op}}
    fusable:
      form: index_map
      value: "{value}"
"""


def test_index_maps_that_read_many_times_are_not_fused_into_an_explosion(tmp_path):
    """Issue 22: five chained index maps each reading their input 40 times fused into a
    kernel that did not finish a 32x16 frame in 45 s: 40^5 evaluations an element."""
    reads = " + ".join(f"image(y, (x + {k}) % image_width, c)" for k in range(40))
    (tmp_path / "t.yaml").write_text(INDEX_MAP_40.format(value=f"({reads}) / 40"))
    (tmp_path / "op.cl").write_text(
        "__kernel void op(__global const uchar *image, __global uchar *out,\n"
        "  const int image_height, const int image_width, const int out_height,\n"
        "  const int out_width, const int tile) { }\n")
    names = [f"r{i}" for i in range(5)]
    model = tmp_path / "m.yaml"
    model.write_text(
        "system: s\ntypes: [t.yaml]\ncomponents:\n"
        "  src: {type: StillImage, params: {width: 32, height: 16}}\n"
        + "".join(f"  {n}: {{type: Read40}}\n" for n in names)
        + "  sink: {type: FrameSink}\nconnections:\n  - src.image -> r0.image\n"
        + "".join(f"  - r{i}.out -> r{i + 1}.image\n" for i in range(4))
        + "  - r4.out -> sink.image\n")
    plan = compile_model(model, tmp_path / "out").system.plan
    # on this tiny frame a launch (33 µs on a CPU device) outweighs one level of 40
    # reads, never two (1,600 evaluations of the first an element)
    assert all(len(g.members) <= 2 for g in plan.groups), plan.groups
    why = dict(plan.unfused)
    refused = [why[e] for e in why if e.startswith("r")]
    assert refused and all(w.startswith("cost model: with r") for w in refused)
    assert any("1600 times per output element" in w for w in refused), refused


@pytest.mark.parametrize("device,expected", [(None, "runs"), ("pocl-cpu", "runs"),
                                             ("portable", "runs"),
                                             ("nvidia-hopper", "strided")])
def test_the_schedule_follows_the_device(device, expected):
    from gpucompgen.device import PROFILES
    from gpucompgen.kernelgen.fused import schedule

    assert schedule(PROFILES.get(device)) == expected


STENCIL_CHAIN = """\
system: hostile
platform: {{device: {device}, placement: gpu}}
components:
  src: {{type: StillImage, params: {{width: 23, height: 11}}}}
  t: {{type: Threshold, params: {{thresh: 120, maxval: 255, thresh_type: 2}}}}
  e: {{type: Erode}}
  g: {{type: GaussianBlur, params: {{ksize: 5}}}}
  sink: {{type: FrameSink}}
connections:
  - src.image -> t.image
  - t.thresholded -> e.image
  - e.eroded -> g.image
  - g.blurred -> sink.image
"""


@pytest.mark.parametrize("device", ["portable", "nvidia-hopper"])
def test_stencil_groups_interior_and_border_paths_give_the_same_bytes(tmp_path, device):
    """A small frame: launches dominate, so the pointwise step and the stencils fuse, and
    the group kernel has channel-flat interior and border versions, on both schedules."""
    require_opencl()
    model = tmp_path / "m.yaml"
    model.write_text(STENCIL_CHAIN.format(device=device))
    fused, got = _frames(model, tmp_path / "fused", "auto")
    kernels = [p.read_text() for p in (tmp_path / "fused").rglob("group_*.cl")]
    assert kernels and all("_in(_ARGS" in k for k in kernels)
    _, expected = _frames(model, tmp_path / "off", "off")
    np.testing.assert_array_equal(got[0], expected[0])


def test_the_gpu_schedule_gives_the_same_bytes(tmp_path):
    """The strided schedule (adjacent work-items, adjacent elements), built for a GPU's
    facts, run here on whatever OpenCL device there is: the bytes of the unfused program.
    The chain has a channel-flat stencil group (interior and border paths)."""
    require_opencl()
    names = {name: name for name in ("src", "n1", "n2", "n3", "n4", "n5", "sink")}
    text = CHAIN.format(**names).replace(
        "components:", "platform: {device: nvidia-hopper, placement: gpu}\ncomponents:", 1)
    model = tmp_path / "m.yaml"
    model.write_text(text)
    fused, got = _frames(model, tmp_path / "gpu", "auto")
    kernels = [p.read_text() for p in (tmp_path / "gpu").rglob("group_*.cl")]
    assert kernels and all("_x += _nx" in k for k in kernels)
    _, expected = _frames(model, tmp_path / "off", "off")
    np.testing.assert_array_equal(got[0], expected[0])


# -- parameters as build constants ---------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_a_float_parameter_is_written_as_the_same_float32(value):
    """c_literal writes the float32 the kernel argument np.float32(value) was: C reads the
    literal (a float, suffix f) back to the same bits."""
    from gpucompgen.runtime.programs import c_literal

    text = c_literal(value, "float")
    assert text.endswith(("f", "f)"))
    assert np.float32(float(text.strip("()").removesuffix("f"))) == np.float32(value)


def test_build_options_override_a_generated_kernels_model_values(cl_context, cl_queue):
    """The program builds a generated kernel with -D NAME=VALUE (runtime.build_program's
    defines, after --set): the option wins over the value the file defines, and a build
    without it gets the model's value.  ThresholdGray's thresh_type picks the rule."""
    import cv2
    import pyopencl as cl

    from gpucompgen.c_convention import group_constants
    from gpucompgen.kernelgen.fused import (
        group_kernel,
        group_of_one,
        kernel_name,
        launch_arguments,
    )
    from gpucompgen.model import library_types
    from gpucompgen.runtime.programs import define_options

    require_opencl()
    frame = np.random.default_rng(3).integers(0, 256, (9, 13), np.uint8)
    params = {"thresh": 100, "maxval": 200, "thresh_type": 0}
    group = group_of_one(library_types()["ThresholdGray"], params,
                         {"src": (9, 13), "dst": (9, 13)})
    macro = next(p.name for p in group_constants(group) if p.param == "m.thresh_type")
    source = group_kernel(group, "test")
    mf = cl.mem_flags
    src = cl.Buffer(cl_context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=frame)
    dst = cl.Buffer(cl_context, mf.WRITE_ONLY, frame.nbytes)
    for options, rule in (((), cv2.THRESH_BINARY),
                          (define_options({macro: np.int32(1)}), cv2.THRESH_BINARY_INV)):
        program = cl.Program(cl_context, source).build(options=list(options))
        kernel = cl.Kernel(program, kernel_name(group))
        kernel.set_args(*launch_arguments(group, {"src": src}, dst, 4))
        cl.enqueue_nd_range_kernel(cl_queue, kernel, (8, 3 * 8, 1), (8, 8, 1))
        got = np.empty_like(frame)
        cl.enqueue_copy(cl_queue, got, dst)
        cl_queue.finish()
        np.testing.assert_array_equal(got, cv2.threshold(frame, 100, 200, rule)[1])


def test_stencils_on_frames_narrower_or_lower_than_their_window(cl_context, cl_queue):
    """Every stencil of the library on frames of 1 to 2 radius + 1 pixels a side, at its
    largest window: the generated kernel (its border and interior loops split a row at
    the window's margin) equals the CPU form.  A row narrower than two margins once made
    the left border loop run past the row into the next rows (BoxBlur radius 3 on a
    33x1 frame)."""
    from conftest import run_generated

    from gpucompgen.library import cpu_kernels
    from gpucompgen.model import library_types

    rng = np.random.default_rng(7)
    checked, pairs = 0, set()
    stencils = [(n, t) for n, t in sorted(library_types().items())
                if t.fusable is not None and t.fusable.form == "stencil" and not t.alias_of]
    settings = ((16, 1, 4, 1), (1, 1, 1, 1), (4, 8, 2, 1))
    for index, (name, ctype) in enumerate(stencils):
        radius = ctype.fusable.radius
        params = {p: d.default for p, d in ctype.params.items()}
        if isinstance(radius, str) and radius in ctype.params and \
                ctype.params[radius].maximum is not None:
            params[radius] = min(int(ctype.params[radius].maximum), 3)
        port = next(iter(ctype.inputs.values()))
        channels = (port.channel_counts or (port.channels,))[-1]
        dtype = (port.dtypes or (port.dtype,))[0]
        # a build each: sizes are constants; and a launch setting each, the three turning
        # with the type so that every size meets every setting over the stencils (each
        # setting is a compile of its own on PoCL: all three at every size took 50 s)
        for i, (h, w) in enumerate(((1, 1), (33, 1), (1, 33), (7, 5))):
            shape = (h, w) + ((channels,) if channels > 1 else ())
            frame = rng.integers(0, 256, shape).astype(dtype)
            cpu = cpu_kernels.CPU_IMPLEMENTATIONS[name](frame, **params)
            setting = settings[(i + index) % len(settings)]
            gpu = run_generated(cl_context, cl_queue, ctype, params, [frame], cpu.shape,
                                setting)
            np.testing.assert_array_equal(gpu, cpu, f"{name} {params} {h}x{w} {setting}")
            pairs.add(((h, w), setting))
            checked += 1
    assert checked >= 6 * 6
    assert len(pairs) == 4 * len(settings), "every size under every launch setting"
