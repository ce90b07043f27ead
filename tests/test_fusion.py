"""Fusion: chains of fusable GPU components run as one generated kernel, bit-identical.

Fused and unfused programs of every model in models/ give the same bytes; a property test
builds random chains and DAGs of the library's fusable types (odd sizes, parameters,
shared producers, CPU readers in the middle) and compares fused, unfused and an
independent numpy reference (gpucompgen/library/cpu_kernels.py), in parallel and
sequential execution, zero-copy on and off.  The plan of the vision system loses the
merged buffer and launches one kernel for merger + detector.
"""

from __future__ import annotations

import itertools
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen import fusable, sizeexpr
from gpucompgen.build import compile_model, write
from gpucompgen.errors import GpucompgenError
from gpucompgen.library import cpu_kernels
from gpucompgen.library.still_image import still_frame
from gpucompgen.model import DTYPES, library_types

MODELS = sorted((ROOT / "models").glob("*.yaml"))
_built = itertools.count()


def _module(model: Path, out: Path, **options):
    result = compile_model(model, out, **options)
    write(result, out)
    return result, load_generated(out / f"{result.system.model.name}.py",
                                  f"fusion_{out.name}_{next(_built)}")


def _outputs(module, frames: int) -> list[np.ndarray]:
    """Every array a CPU sink got (FrameSink, VisionManager, MaskWriter, the property
    test's Keep_* sinks), in order; each a copy."""
    got: list[np.ndarray] = []
    patched = []
    names = ["FrameSink", "VisionManager", "MaskWriter"]
    names += [n for n in vars(module) if n.startswith("Keep_")]
    classes = {id(c): c for c in (getattr(module, n, None) for n in names) if c is not None}
    for cls in classes.values():
        original = cls.execute

        def spy(self, *data, _original=original):
            got.extend(np.array(d, copy=True) for d in data)
            return _original(self, *data)

        cls.execute = spy
        patched.append((cls, original))
    try:
        assert module.run(frames=frames).frames == frames
    finally:
        for cls, original in patched:
            cls.execute = original
    return got


# -- the plan ----------------------------------------------------------------------------

def test_vision_system_merger_and_detector_are_one_launch_and_the_merged_buffer_is_gone():
    model = ROOT / "models" / "vision_system.yaml"
    fused = compile_model(model, ROOT / "generated").system.plan
    unfused = compile_model(model, ROOT / "generated", fusion="off").system.plan
    assert [la.part for la in fused.launches] == ["merger_detector"]
    assert [la.part for la in unfused.launches] == ["merger", "detector"]
    merged = [b for b in unfused.buffers if b.what == "merger.merged"]
    assert [b.nbytes for b in merged] == [1_843_200]  # 480 x 1280 x 3
    assert not any("merged" in b.what for b in fused.buffers)
    assert unfused.device_bytes - fused.device_bytes == 1_843_200
    # the group keeps the model's gpu_settings of the detector: one config_gpu
    (la,) = fused.launches
    assert (la.tile, la.local_size, la.settings_source) == (32, (16, 16, 1), "model")
    assert [(g.part, [m for m, _, _ in g.members]) for g in fused.groups] == \
        [("merger_detector", ["merger", "detector"])]


OPAQUE_TYPE = """\
component_types:
  Op:
    kind: gpu-aware
    description: A user's kernel without a fusable form.
    inputs:
      image: {memory: gpu, channels: 3}
    outputs:
      out: {memory: gpu, channels: 3}
    kernel: {file: op.cl, function: op}
"""
OPAQUE_KERNEL = """\
__kernel void op(__global const uchar *image, __global uchar *out,
                 const int image_height, const int image_width,
                 const int out_height, const int out_width, const int tile)
{
    const size_t n = (size_t)image_height * image_width * 3;
    for (size_t i = get_global_id(1) * get_global_size(0) + get_global_id(0); i < n;
         i += get_global_size(0) * get_global_size(1))
        out[i] = image[i];
}
"""


def test_plan_and_check_name_groups_and_why_edges_stay_unfused(tmp_path):
    """Every kind of reason, each on the edge it concerns, in the plan and in plan/check
    output; the group in between."""
    (tmp_path / "t.yaml").write_text(OPAQUE_TYPE)
    (tmp_path / "op.cl").write_text(OPAQUE_KERNEL)
    model = tmp_path / "m.yaml"
    model.write_text(
        "system: why\ntypes: [t.yaml]\ncomponents:\n"
        # a frame where recomputing a 5x5 blur 25 times costs more than a launch
        "  src: {type: StillImage, params: {width: 320, height: 240}}\n"
        "  m1: {type: VerticalMirror}\n  m2: {type: VerticalMirror}\n"
        "  b1: {type: BoxBlur, params: {radius: 2}}\n  b2: {type: BoxBlur, params: {radius: 2}}\n"
        "  m3: {type: VerticalMirror, fuse: false}\n  op: {type: Op}\n"
        "  m4: {type: VerticalMirror, placement: cpu}\n"
        "  s1: {type: FrameSink}\n  s2: {type: FrameSink}\n"
        "connections:\n  - src.image -> m1.image\n  - m1.mirrored -> m2.image\n"
        "  - m1.mirrored -> s1.image\n  - m2.mirrored -> b1.image\n"
        "  - b1.smooth -> b2.image\n  - b2.smooth -> m3.image\n  - m3.mirrored -> op.image\n"
        "  - op.out -> m4.image\n  - m4.mirrored -> s2.image\n")
    plan = compile_model(model, tmp_path / "out").system.plan
    why = dict(plan.unfused)
    expected = {
        "m1.dst -> m2.src": "read by several consumers: m1.dst is also read by "
                                   "the CPU (s1.image, through adapter",
        "b1.dst -> b2.src": "cost model: with b1 the group's kernel takes an estimated ",
        "b2.dst -> m3.src": "fuse: false: the model keeps m3 out of every group",
        "m3.dst -> op.image": "opaque type: op (Op) has no fusable form",
        "op.out -> m4.src": "placed on the CPU: m4 runs its CPU function (model)",
    }
    assert set(why) == set(expected)
    for edge, text in expected.items():
        assert why[edge].startswith(text), (edge, why[edge])
    assert [[m for m, _, _ in g.members] for g in plan.groups] == [["m2", "b1"]]
    for command in ("plan", "check"):
        proc = subprocess.run([sys.executable, "-m", "gpucompgen", command, str(model)],
                              capture_output=True, text=True, check=False)
        assert proc.returncode == 0, proc.stderr
        out = " ".join(proc.stdout.split())  # check indents, plan wraps long reasons
        assert "fusion: auto, 1 group: m2_b1: one kernel (group_m2_b1.cl) for " \
            "m2 (VerticalMirror, index_map) -> b1 (BoxBlur, stencil)" in out
        for edge, text in expected.items():
            assert f"not fused: {edge}: {' '.join(text.split())}" in out
    off = subprocess.run([sys.executable, "-m", "gpucompgen", "plan", str(model),
                          "--fusion", "off"], capture_output=True, text=True, check=False)
    out = " ".join(off.stdout.split())
    assert "fusion: off, 0 groups" in out
    assert "not fused: m2.dst -> b1.src: fusion off (--fusion)" in out
    assert "not fused: op.out -> m4.src: placed on the CPU" in out
    standard = compile_model(model, tmp_path / "std", mode="standard").system.plan
    assert dict(standard.unfused)["m2.dst -> b1.src"] == \
        "fusion off (standard mode: one kernel per component)"


def test_graph_draws_each_group_as_a_cluster(tmp_path):
    from gpucompgen.graph import dot_text

    model = ROOT / "models" / "parallel_branches.yaml"
    text = dot_text(compile_model(model, tmp_path / "a").system)
    cluster = text.split('subgraph "cluster_merger_detector" {\n')[1].split("\n  }\n")[0]
    assert "fused group merger_detector: one kernel, one launch" in cluster
    for member in ("merger", "detector"):
        assert f'\n    "{member}" [label="{member}\\n' in cluster
    assert '"merger" -> "detector" [style=dashed, label="fused"' in cluster
    assert text.count('subgraph "cluster_') == 1
    # edges from outside reach the members the group's inputs feed, the root's output
    assert '"blur1" -> "merger"' in text and '"detector" -> "adapter' in text
    assert '"merger_detector"' not in text.replace('"cluster_merger_detector"', "")
    assert "cluster_" not in dot_text(compile_model(model, tmp_path / "b",
                                                   fusion="off").system)
    if shutil.which("dot"):  # Graphviz reads it
        subprocess.run(["dot", "-Tsvg"], input=text.encode(), capture_output=True, check=True)


def test_platform_fusion_off_and_bad_values(tmp_path):
    base = ("system: s\n{platform}components:\n"
            "  src: {{type: StillImage, params: {{width: 8, height: 8}}}}\n"
            "  m1: {{type: VerticalMirror{fuse}}}\n  m2: {{type: VerticalMirror}}\n"
            "  sink: {{type: FrameSink}}\nconnections:\n  - src.image -> m1.image\n"
            "  - m1.mirrored -> m2.image\n  - m2.mirrored -> sink.image\n")
    model = tmp_path / "m.yaml"
    model.write_text(base.format(platform="platform: {fusion: off}\n", fuse=""))
    assert not compile_model(model, tmp_path / "o").system.groups
    model.write_text(base.format(platform="platform: {fusion: sometimes}\n", fuse=""))
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "o")
    assert "m.yaml:2:" in str(info.value) and "platform.fusion must be 'auto' or 'off'" \
        in str(info.value)
    model.write_text(base.format(platform="", fuse=", fuse: maybe"))
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "o")
    assert "fuse of 'm1' must be true or false" in str(info.value)


# -- snippets are checked without a device -------------------------------------------------

@pytest.mark.parametrize("form,value,message", [
    ("index_map", "image(y, x)", "takes 3 arguments (y, x, c), or 4 with"),
    ("index_map", "image(y, x, c, 0, 1)", "(y, x, c, fill), not 5"),
    ("pointwise", "image(y, x, c, 0)", "always inside the frame: no fill value"),
    ("index_map", "imag(y, x, c)", "unknown function 'imag'"),
    ("pointwise", "image(y + 1, x, c)", "reads inputs at (y, x) only"),
    ("index_map", "image(y, x, c) + ((1)", "'(' is never closed"),
    ("index_map", "barrier(CLK_LOCAL_MEM_FENCE)", "'barrier' is not allowed"),
    ("index_map", "((__global uchar *)0)[0]", "'__global' is not allowed"),
    ("index_map", "int a = image(y, x, c); a", "statements must end by returning"),
    ("index_map", "#define A 1\nimage(y, x, c)", "preprocessor lines"),
    ("index_map", "out(y, x, c)", "output 'out' is what the snippet returns"),
    ("index_map", "image(y, x, c) + " * 400 + "0", "more than 4,000"),
])
def test_bad_snippets_are_positioned_errors(tmp_path, form, value, message):
    types = tmp_path / "t.yaml"
    (tmp_path / "k.cl").write_text("__kernel void k(__global const uchar *image, "
                                   "__global uchar *out) {}\n")
    types.write_text("component_types:\n  K:\n    kind: gpu-aware\n    inputs:\n"
                     "      image: {memory: gpu, channels: 3}\n    outputs:\n"
                     "      out: {memory: gpu, channels: 3}\n"
                     "    kernel: {file: k.cl, function: k}\n"
                     f"    fusable:\n      form: {form}\n      value: {value!r}\n")
    model = tmp_path / "m.yaml"
    model.write_text("system: s\ntypes: [t.yaml]\ncomponents:\n"
                     "  src: {type: StillImage, params: {width: 8, height: 8}}\n"
                     "  k: {type: K}\n  sink: {type: FrameSink}\n"
                     "connections: [src.image -> k.image, k.out -> sink.image]\n")
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "o")
    text = str(info.value)
    assert re.search(r"t\.yaml:\d+:\d+: error: fusable snippet of 'K': ", text), text
    assert message in text, text


COMMENTED_TYPE = """\
component_types:
  Brighten:
    kind: gpu-aware
    params:
      gain: {type: int, default: 40, min: 0, max: 255}
    inputs:
      image: {memory: gpu, channels: 3}
    outputs:
      brighter: {memory: gpu, channels: 3}
    kernel: {file: brighten.cl, function: brighten}
    fusable:
      form: pointwise
      value: "min(image(y, x, c) + gain, 255)  // saturates at 255"
  BrightenLocal:
    kind: gpu-aware
    params:
      gain: {type: int, default: 40, min: 0, max: 255}
    inputs:
      image: {memory: gpu, channels: 3}
    outputs:
      brighter: {memory: gpu, channels: 3}
    kernel: {file: brighten.cl, function: brighten}
    fusable:
      form: pointwise
      value: |
        /* the pixel */ const int p = image(y, x, c);  // read once
        return min(p + gain, 255);  /* saturates */ // at 255
"""
BRIGHTEN_KERNEL = """\
__kernel void brighten(__global const uchar *image, __global uchar *brighter,
                       const int image_height, const int image_width,
                       const int brighter_height, const int brighter_width,
                       const int gain, const int tile)
{
    const size_t n = (size_t)image_height * image_width * 3;
    for (size_t i = get_global_id(1) * get_global_size(0) + get_global_id(0); i < n;
         i += get_global_size(0) * get_global_size(1))
        brighter[i] = min(image[i] + gain, 255);
}
"""


@pytest.mark.parametrize("type_name", ["Brighten", "BrightenLocal"])
def test_snippet_comments_never_reach_the_kernel(tmp_path, type_name):
    """A trailing '// comment' once commented out the generated 'return (...);': the
    kernel gets the snippet printed from its tree, so comments stay behind."""
    require_opencl()
    (tmp_path / "t.yaml").write_text(COMMENTED_TYPE)
    (tmp_path / "brighten.cl").write_text(BRIGHTEN_KERNEL)
    model = tmp_path / "m.yaml"
    model.write_text(
        f"system: commented\ntypes: [t.yaml]\ncomponents:\n"
        f"  src: {{type: StillImage, params: {{width: 24, height: 18}}}}\n"
        f"  b: {{type: {type_name}}}\n  m: {{type: VerticalMirror}}\n"
        f"  sink: {{type: FrameSink}}\n"
        f"connections: [src.image -> b.image, b.brighter -> m.image, m.mirrored -> sink.image]\n")
    result, fused = _module(model, tmp_path / "fused")
    assert [m.name for m in result.system.groups[0].members] == ["b", "m"]
    _, unfused = _module(model, tmp_path / "unfused", fusion="off")
    expected = np.minimum(still_frame(24, 18).astype(int) + 40, 255).astype(np.uint8)[::-1]
    for got in (_outputs(fused, 2), _outputs(unfused, 2)):
        assert len(got) == 2 and all(np.array_equal(g, expected) for g in got)


def test_only_single_output_types_are_fusable(tmp_path):
    (tmp_path / "k.cl").write_text("__kernel void k() {}\n")
    (tmp_path / "t.yaml").write_text(
        "component_types:\n  K:\n    kind: gpu-aware\n    inputs:\n"
        "      image: {memory: gpu, channels: 3}\n    outputs:\n"
        "      a: {memory: gpu, channels: 3}\n      b: {memory: gpu, channels: 3}\n"
        "    kernel: {file: k.cl, function: k}\n"
        "    fusable: {form: pointwise, value: 'image(y, x, c)'}\n")
    model = tmp_path / "m.yaml"
    model.write_text("system: s\ntypes: [t.yaml]\ncomponents:\n  k: {type: K}\n")
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "o")
    assert "only types with a single output can be fusable; 'K' has 2" in str(info.value)


def test_library_snippets_pass_the_check_and_compile(cl_context):
    """Every library snippet, as a one-member group kernel, compiles on the device (every
    library type with a fusable form, found by itself: new ones are covered too)."""
    import pyopencl as cl

    from gpucompgen.ir import ComponentNode, Data, GroupNode, Port
    from gpucompgen.kernelgen.fused import group_kernel
    from gpucompgen.model import Endpoint
    from gpucompgen.runtime.sizes import Size

    fusable_types = {n: t for n, t in library_types().items() if t.fusable}
    assert {"VerticalMirror", "ImageMerger", "ObjectDetector", "BoxBlur"} <= set(fusable_types)

    def port(p, direction, d):
        return Port(p, direction, "gpu", d.dtype, d.channels,
                    Data(Size(7, 5, d.channels), d.dtype))

    for name, t in fusable_types.items():
        lengths = [n for p, d in t.params.items() if d.shape
                   for n in fusable.length_names(p, len(d.shape))]
        # the value reads the inputs and the stages (fusable.Stage), a stage the inputs
        # and the stages before it
        stages = list(t.fusable.stages)
        assert not fusable.analyse(t.fusable.value, t.fusable.form, [*t.inputs, *stages],
                                   list(t.outputs), [*t.params, *t.fusable.tables, *lengths],
                                   arrays=[*(p for p, d in t.params.items() if d.shape),
                                           *t.fusable.tables]).problems
        for i, stage in enumerate(t.fusable.stages.values()):
            assert not fusable.analyse(stage.decl.value, "stencil", [*t.inputs, *stages[:i]],
                                       [stage.name], [*t.params, *lengths],
                                       arrays=[p for p, d in t.params.items()
                                               if d.shape]).problems
        ports = {p: port(p, "in", d) for p, d in t.inputs.items()}
        outs = {p: port(p, "out", d) for p, d in t.outputs.items()}
        member = ComponentNode("member", None, ports, outs, type=t,
                               params={k: d.default for k, d in t.params.items()})
        group = GroupNode("only", None, {f"member_{p}": port for p, port in ports.items()},
                          outs, members=[member],
                          feeds={f"member_{p}": Endpoint("member", p) for p in ports})
        cl.Program(cl_context, group_kernel(group, f"test of {name}")).build()


# -- fused equals unfused ------------------------------------------------------------------

@pytest.mark.parametrize("model", MODELS, ids=lambda p: p.stem)
def test_every_model_fused_and_unfused_give_the_same_bytes(tmp_path, model):
    require_opencl()
    fused_result, fused = _module(model, tmp_path / "fused")
    _, unfused = _module(model, tmp_path / "unfused", fusion="off")
    # a model fuses something unless its GPU-to-GPU edges touch only opaque types
    why = dict(fused_result.system.plan.unfused)
    assert fused_result.system.groups or all("no fusable form" in w for w in why.values()), why
    a, b = _outputs(fused, 3), _outputs(unfused, 3)
    assert len(a) == len(b) > 0
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and x.shape == y.shape
        assert np.array_equal(x, y)


def _fusable_library() -> dict[str, object]:
    """Every library type with a fusable form whose inputs are all GPU ports: the property
    test draws from these, so a type that gains a form is tested without a change here."""
    return {n: t for n, t in sorted(library_types().items())
            if t.fusable is not None and t.inputs and all(
                p.memory in ("gpu", "any") for p in t.inputs.values())}


def test_every_fusable_library_type_has_a_numpy_reference():
    fusable_types = _fusable_library()
    assert {"VerticalMirror", "BoxBlur", "ImageMerger", "ObjectDetector"} <= set(fusable_types)
    assert set(fusable_types) <= set(cpu_kernels.CPU_IMPLEMENTATIONS)


def _kind(decl) -> tuple[str, int]:
    return decl.dtype, decl.channels


def _param_values(draw, ctype) -> dict:
    """Parameters drawn in their declared ranges (long ranges cut to their low end, so
    that sizes stay small); a parameter without a range keeps its default or takes a
    small value."""
    values = {}
    for name, p in ctype.params.items():
        if p.type == "int":
            lo = int(p.minimum) if p.minimum is not None else 0
            hi = int(p.maximum) if p.maximum is not None else lo + 15
            values[name] = draw(st.integers(lo, hi if hi - lo <= 255 else lo + 15))
        elif p.type == "float":
            lo = p.minimum if p.minimum is not None else -3.0
            hi = p.maximum if p.maximum is not None else 3.0
            values[name] = draw(st.integers(0, 100)) / 100 * (hi - lo) + lo
            values[name] = round(values[name], 2)
        elif p.default is not None:
            values[name] = p.default
    return values


@st.composite
def fusable_systems(draw):
    """A model of StillImage sources and stages of the library's fusable types (streams
    may be read by several stages and by sinks, stages may say 'fuse: false'), with the
    numpy reference of every sink's input.  A stream of uint8x3 goes to a FrameSink, any
    other to a Keep sink of its element type (written by the test)."""
    fusable_types = _fusable_library()
    height = draw(st.integers(1, 9))
    comps = {}
    conns = []
    streams = []  # (endpoint, reference array, (dtype, channels))
    for i in range(draw(st.integers(1, 2))):
        w = draw(st.integers(1, 11))
        comps[f"src{i}"] = {"type": "StillImage",
                            "params": {"width": w, "height": height, "seed": i + 1}}
        streams.append((f"src{i}.image", still_frame(w, height, i + 1), ("uint8", 3)))
    readers = set()
    for i in range(draw(st.integers(1, 5))):
        kinds = {s[2] for s in streams}
        usable = [n for n, t in fusable_types.items()
                  if all(_kind(p) in kinds for p in t.inputs.values())]
        name = f"stage{i}"
        tname = draw(st.sampled_from(usable))
        ctype = fusable_types[tname]
        feeds = []
        for port in ctype.inputs.values():
            fitting = [s for s in streams if s[2] == _kind(port)]
            feeds.append(fitting[draw(st.integers(0, len(fitting) - 1))])
        # (height, width, channels, itemsize): a requirement may compare channels
        # (ExtractChannel) or the element's size (Resize's bilinear)
        sizes = {p: (*ref.shape[:2], kind[1], DTYPES[kind[0]][2])
                 for p, (_, ref, kind) in zip(ctype.inputs, feeds)}
        params = _param_values(draw, ctype)
        ints = {k: v for k, v in params.items() if ctype.params[k].type == "int"}
        if not all(sizeexpr.evaluate(tree, sizes, ints) for tree, _ in ctype.requires):
            continue  # the type's requirements fail for these inputs: no stage here
        comps[name] = {"type": tname, "params": params}
        if draw(st.booleans()):
            comps[name]["fuse"] = draw(st.booleans())
        for port, (end, _, _) in zip(ctype.inputs, feeds):
            conns.append(f"{end} -> {name}.{port}")
            readers.add(end)
        (out_name, out_decl), = ctype.outputs.items()
        ref = cpu_kernels.CPU_IMPLEMENTATIONS[tname](*(f[1] for f in feeds), **params)
        streams.append((f"{name}.{out_name}", ref, _kind(out_decl)))
    expected = []
    # every stream nobody reads (and some that are read) goes to a sink
    for j, (end, ref, kind) in enumerate(streams):
        if end not in readers or (not end.startswith("src") and draw(st.booleans())):
            sink = "FrameSink" if kind == ("uint8", 3) else f"Keep_{kind[0]}x{kind[1]}"
            comps[f"sink{j}"] = {"type": sink}
            conns.append(f"{end} -> sink{j}.image")
            expected.append(ref)
    return comps, conns, expected


KEEP_PY = '''class Keep:
    """Sink of the property test: the test spies on execute."""

    def initialize(self, image):
        pass

    def execute(self, image):
        pass

    def free_memory(self):
        pass
'''


def _keep_types(comps: dict) -> dict:
    """The Keep_<dtype>x<channels> sink types a drawn model uses."""
    types = {}
    for spec in comps.values():
        if spec["type"].startswith("Keep_"):
            dtype, channels = spec["type"][len("Keep_"):].split("x")
            types[spec["type"]] = {
                "kind": "standard", "description": "keeps nothing (test sink)",
                "inputs": {"image": {"memory": "cpu", "dtype": dtype,
                                     "channels": int(channels)}},
                "python": {"file": "keep.py", "class": "Keep"}}
    return types


_modules: dict[str, object] = {}


@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(system=fusable_systems(), execution=st.sampled_from(["parallel", "sequential"]),
       zero_copy=st.sampled_from(["off", "on"]))
def test_random_fusable_systems_fused_equals_unfused_equals_numpy(tmp_path_factory, system,
                                                                  execution, zero_copy):
    import yaml

    require_opencl()
    comps, conns, expected = system
    folder = tmp_path_factory.mktemp("fz")
    model = folder / "m.yaml"
    doc = {"system": "fz", "components": comps, "connections": conns}
    keep = _keep_types(comps)
    if keep:
        (folder / "keep.py").write_text(KEEP_PY)
        (folder / "keep.yaml").write_text(yaml.safe_dump({"component_types": keep}))
        doc = {"system": "fz", "types": ["keep.yaml"], "components": comps,
               "connections": conns}
    model.write_text(yaml.safe_dump(doc, sort_keys=False))
    got = {}
    for fusion in ("auto", "off"):
        _, module = _module(model, folder / fusion, fusion=fusion, execution=execution,
                            zero_copy=zero_copy)
        outs = _outputs(module, 2)
        got[fusion] = outs
    assert len(got["auto"]) == len(got["off"]) == 2 * len(expected)
    sinks = len(expected)
    for k, (a, b) in enumerate(zip(got["auto"], got["off"])):
        assert np.array_equal(a, b), (k, comps, conns)
    # the sinks are called in run order, which is not model order: compare as multisets
    frame = sorted((x.tobytes(), x.shape) for x in got["auto"][:sinks])
    want = sorted((x.tobytes(), x.shape) for x in expected)
    assert frame == want, (comps, conns)


# -- a lone component of a fusable type runs the kernel generated from its form ------------

LONE_TYPES = """component_types:
  Brighten:
    kind: gpu-aware
    params:
      amount: {type: int, default: 40, min: 0, max: 255}
    inputs:
      image: {memory: gpu, dtype: uint8, channels: 3}
    outputs:
      brighter: {memory: gpu, dtype: uint8, channels: 3}
    fusable:
      form: pointwise
      value: "add_sat(image(y, x, c), (uchar)amount)"
"""


def _lone_model(tmp_path: Path, platform: str = "", name: str = "bright") -> Path:
    (tmp_path / "types.yaml").write_text(LONE_TYPES)
    model = tmp_path / "m.yaml"
    model.write_text(
        f"system: s\ntypes: [types.yaml]\n{platform}components:\n"
        "  src: {type: StillImage, params: {width: 24, height: 10}}\n"
        f"  {name}: {{type: Brighten, params: {{amount: 60}}}}\n"
        "  m: {type: VerticalMirror}\n  sink: {type: FrameSink}\nconnections:\n"
        f"  - src.image -> {name}.image\n  - {name}.brighter -> m.image\n"
        "  - m.mirrored -> sink.image\n")
    return model


def test_a_fusable_type_needs_no_kernel_and_runs_alone_what_its_form_says(tmp_path):
    """A type with a form and no 'kernel:' builds; with fusion off each component runs the
    kernel generated for it alone (a group of one, <component>.cl), the plan says so,
    and the bytes are numpy's; the parameter stays settable at run time."""
    require_opencl()
    model = _lone_model(tmp_path, "platform: {fusion: off}\n")
    result = compile_model(model, tmp_path / "o")
    plan = result.system.plan
    assert plan.groups == () and result.system.groups == []
    assert plan.generated == (("bright", "Brighten", "pointwise", "bright.cl"),
                              ("m", "VerticalMirror", "index_map", "m.cl"))
    assert [p.file for p in plan.programs] == ["bright.cl", "m.cl"]
    assert list(result.system.components) == ["src", "bright", "m", "sink"]
    write(result, tmp_path / "o")
    text = (tmp_path / "o" / "s.py").read_text()
    assert "class Brighten(runtime.KernelComponent)" in text
    assert "kernels generated from fusable forms, one component each: bright" in text
    assert "params['bright.amount']" in text  # still settable at run time
    module = load_generated(tmp_path / "o" / "s.py", "lone_fusable")
    out = module.run(frames=2).components["sink"].last
    frame = still_frame(24, 10)
    expected = np.flipud(np.minimum(frame.astype(int) + 60, 255).astype(np.uint8))
    np.testing.assert_array_equal(out, expected)


def test_a_kernel_entry_point_never_takes_an_opencl_builtins_name(tmp_path):
    require_opencl()
    model = _lone_model(tmp_path, "platform: {fusion: off}\n", name="trunc")
    result = compile_model(model, tmp_path / "o")
    assert result.system.plan.launch("trunc").function == "trunc_kernel"
    write(result, tmp_path / "o")
    module = load_generated(tmp_path / "o" / "s.py", "lone_trunc")
    assert module.run(frames=1).frames == 1


def test_gpu_settings_without_a_kernel_are_an_error(tmp_path):
    model = _lone_model(tmp_path)
    (tmp_path / "types.yaml").write_text(LONE_TYPES + "    gpu: {tiles: [8]}\n")
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "o")
    assert "types.yaml:13:5: error: 'gpu' settings of 'Brighten' are for a hand-written " \
        "kernel" in str(info.value)
