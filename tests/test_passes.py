"""Each pass on a small hand-built IR: the whole dump before and after it, hand-checked.

Like xDSL's filecheck tests: a test builds an IR by hand (gpucompgen/ir.py), brings it to
the state the pass expects with the passes before it (pipeline order, docs/development.md),
checks the dump, runs ONE pass and checks the dump again, so a change of what a pass does
shows as a diff of readable text. No model file, no OpenCL device.
"""

from __future__ import annotations

import textwrap
from types import SimpleNamespace

from gpucompgen.device import PROFILES
from gpucompgen.errors import Pos, Reporter
from gpucompgen.ir import Edge, System, component_node
from gpucompgen.model import Endpoint, library_types
from gpucompgen.passes.allocate_gpu import AllocateGpu
from gpucompgen.passes.assign_queues import AssignQueues
from gpucompgen.passes.check_connections import CheckConnections
from gpucompgen.passes.check_port_types import CheckPortTypes
from gpucompgen.passes.insert_adapters import InsertAdapters
from gpucompgen.passes.name_variables import NameVariables
from gpucompgen.passes.place import Place
from gpucompgen.passes.propagate_sizes import PropagateSizes
from gpucompgen.passes.schedule import Schedule
from gpucompgen.passes.stage_frames import StageFrames

TYPES = library_types()
# what allocate-gpu reads of the model: no settings given, no thread budget
MODEL = SimpleNamespace(gpu_overrides={}, thread_budget=None, thread_budget_pos=None)


def hand_built(components: dict[str, str], *edges: str, mode: str = "gpu-aware",
               execution: str = "parallel") -> System:
    """components: name -> 'Type param=int ... [on=gpu|cpu]' (other parameters the type's
    defaults; on=: a flexible component's side, asked by the model); edges 'a.x -> b.y'."""
    system = System("hand", MODEL, PROFILES["portable"], mode, execution)
    for i, (name, spec) in enumerate(components.items()):
        tname, *settings = spec.split()
        t = TYPES[tname]
        params = {k: d.default for k, d in t.params.items()}
        asked, by = "gpu", "default"  # a flexible component asked nothing: the GPU
        for setting in settings:
            key, value = setting.split("=")
            if key == "on":
                asked, by = value, "model"
            else:
                params[key] = int(value)
        system.add_node(component_node(name, t, params, Pos("hand.yaml", i + 1, 1), i, mode,
                                       asked, by))
    for e in edges:
        src, dst = (Endpoint(*s.strip().split(".")) for s in e.split("->"))
        system.edges.append(Edge(src, dst))
    return system


def apply(system: System, *passes) -> Reporter:
    rep = Reporter()
    for p in passes:
        p.apply(system, rep)
        system.done.append(p.name)
        if not rep.has_errors:
            system.verify()
    return rep


def expect(system: System, text: str) -> None:
    """The dump from its first node on (the head line names the system and its settings,
    the 'after:' line the passes applied) is text, both dedented."""
    lines = system.dump().split("\n")
    assert lines[0].startswith("system hand (") and lines[1].startswith("  after:") \
        == bool(system.done)
    got = textwrap.dedent("\n".join(lines[2 if system.done else 1:]))
    assert got == textwrap.dedent(text).strip("\n"), "dump:\n" + got


# the passes before allocate-gpu, in pipeline order (fuse left out: tests/test_fusion.py)
UP_TO_ADAPTERS = (CheckConnections(), CheckPortTypes(), Schedule(), PropagateSizes(), Place(),
                  InsertAdapters())


def test_check_connections_keeps_the_first_writer_and_reports_the_rest():
    system = hand_built({"a": "StillImage width=8 height=4", "b": "StillImage width=8 height=4",
                         "m": "VerticalMirror", "sink": "FrameSink"},
                        "a.image -> sink.image", "b.image -> sink.image")
    expect(system, """
      component a: StillImage on CPU (width=8, height=4, seed=1, frames=0)
        out image: CPU uint8x3
      component b: StillImage on CPU (width=8, height=4, seed=1, frames=0)
        out image: CPU uint8x3
      component m: VerticalMirror on GPU
        in image: GPU uint8x3
        out mirrored: GPU uint8x3
      component sink: FrameSink on CPU (output='')
        in image: CPU uint8x3
      edge a.image -> sink.image
      edge b.image -> sink.image
    """)
    rep = apply(system, CheckConnections())
    expect(system, """
      component a: StillImage on CPU (width=8, height=4, seed=1, frames=0)
        out image: CPU uint8x3
      component b: StillImage on CPU (width=8, height=4, seed=1, frames=0)
        out image: CPU uint8x3
      component m: VerticalMirror on GPU
        in image: GPU uint8x3
        out mirrored: GPU uint8x3
      component sink: FrameSink on CPU (output='')
        in image: CPU uint8x3
      edge a.image -> sink.image
    """)
    assert [d.message for d in rep.diagnostics] == [
        "input 'sink.image' has two writers: 'a.image' and 'b.image'",
        "output 'b.image' is not connected",
        "component 'b' is connected to nothing",
        "input 'm.image' is not connected",
        "output 'm.mirrored' is not connected",
        "component 'm' is connected to nothing",
    ]


def test_schedule_orders_by_the_edges_and_numbers_the_stages():
    system = hand_built({"sink": "FrameSink", "m": "VerticalMirror",
                         "cam": "StillImage width=8 height=4"},
                        "m.mirrored -> sink.image", "cam.image -> m.image")
    apply(system, CheckConnections(), CheckPortTypes())
    expect(system, """
      component sink: FrameSink on CPU (output='')
        in image: CPU uint8x3
      component m: VerticalMirror on GPU
        in image: GPU uint8x3
        out mirrored: GPU uint8x3
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0)
        out image: CPU uint8x3
      edge m.mirrored -> sink.image
      edge cam.image -> m.image
    """)
    assert not apply(system, Schedule()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3
      component m: VerticalMirror on GPU [stage 2]
        in image: GPU uint8x3
        out mirrored: GPU uint8x3
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3
      edge m.mirrored -> sink.image
      edge cam.image -> m.image
    """)


def test_propagate_sizes_from_the_source_down():
    system = hand_built({"cam": "StillImage width=8 height=4", "m": "ImageMerger",
                         "sink": "FrameSink"},
                        "cam.image -> m.left", "cam.image -> m.right", "m.merged -> sink.image")
    apply(system, CheckConnections(), CheckPortTypes(), Schedule())
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3
      component m: ImageMerger on GPU [stage 2]
        in left: GPU uint8x3
        in right: GPU uint8x3
        out merged: GPU uint8x3
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3
      edge cam.image -> m.left
      edge cam.image -> m.right
      edge m.merged -> sink.image
    """)
    assert not apply(system, PropagateSizes()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      component m: ImageMerger on GPU [stage 2]
        in left: GPU uint8x3 = 4x8x3 uint8
        in right: GPU uint8x3 = 4x8x3 uint8
        out merged: GPU uint8x3 = 4x16x3 uint8
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x16x3 uint8
      edge cam.image -> m.left : 4x8x3 uint8
      edge cam.image -> m.right : 4x8x3 uint8
      edge m.merged -> sink.image : 4x16x3 uint8
    """)


def test_place_moves_a_component_and_its_ports_to_the_side_asked():
    system = hand_built({"cam": "StillImage width=8 height=4", "flip": "FlipHorizontal",
                         "blur": "BoxBlur on=cpu", "sink": "FrameSink"},
                        "cam.image -> flip.image", "flip.flipped -> blur.image",
                        "blur.smooth -> sink.image")
    # asked by the command line after the node was built (on the GPU, the default)
    flip = system.nodes["flip"]
    flip.asked, flip.placed_by = "cpu", "command line"
    apply(system, CheckConnections(), CheckPortTypes(), Schedule(), PropagateSizes())
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      component flip: FlipHorizontal on GPU [asked cpu by command line] [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out flipped: GPU uint8x3 = 4x8x3 uint8
      component blur: BoxBlur on CPU [asked cpu by model] (radius=1) [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
        out smooth: CPU uint8x3 = 4x8x3 uint8
      component sink: FrameSink on CPU (output='') [stage 4]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> flip.image : 4x8x3 uint8
      edge flip.flipped -> blur.image : 4x8x3 uint8
      edge blur.smooth -> sink.image : 4x8x3 uint8
    """)
    assert not apply(system, Place()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      component flip: FlipHorizontal on CPU [asked cpu by command line] [stage 2]
        in image: CPU uint8x3 = 4x8x3 uint8
        out flipped: CPU uint8x3 = 4x8x3 uint8
      component blur: BoxBlur on CPU [asked cpu by model] (radius=1) [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
        out smooth: CPU uint8x3 = 4x8x3 uint8
      component sink: FrameSink on CPU (output='') [stage 4]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> flip.image : 4x8x3 uint8
      edge flip.flipped -> blur.image : 4x8x3 uint8
      edge blur.smooth -> sink.image : 4x8x3 uint8
      placed flip: CPU (by command line)
      placed blur: CPU (by model)
    """)


def test_insert_adapters_puts_a_copy_on_each_edge_that_crosses_memories():
    system = hand_built({"cam": "StillImage width=8 height=4", "blur": "BoxBlur on=gpu",
                       "sink": "FrameSink"}, "cam.image -> blur.image", "blur.smooth -> sink.image")
    apply(system, CheckConnections(), CheckPortTypes(), Schedule(), PropagateSizes(), Place())
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      component blur: BoxBlur on GPU [asked gpu by model] (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> blur.image : 4x8x3 uint8
      edge blur.smooth -> sink.image : 4x8x3 uint8
      placed blur: GPU (by model)
    """)
    assert not apply(system, InsertAdapters()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8
      component blur: BoxBlur on GPU [asked gpu by model] (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8
      adapter adapter2_gpu2cpu: gpu2cpu of blur.smooth [stage 2]
        in input: GPU uint8x3 = 4x8x3 uint8
        out output: CPU uint8x3 = 4x8x3 uint8
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge blur.smooth -> adapter2_gpu2cpu.input : 4x8x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x8x3 uint8
      placed blur: GPU (by model)
    """)


def test_allocate_gpu_gives_each_gpu_node_its_settings_within_the_budget():
    system = hand_built({"cam": "StillImage width=8 height=4", "blur": "BoxBlur on=gpu",
                       "sink": "FrameSink"}, "cam.image -> blur.image", "blur.smooth -> sink.image")
    apply(system, *UP_TO_ADAPTERS)
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8
      component blur: BoxBlur on GPU [asked gpu by model] (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8
      adapter adapter2_gpu2cpu: gpu2cpu of blur.smooth [stage 2]
        in input: GPU uint8x3 = 4x8x3 uint8
        out output: CPU uint8x3 = 4x8x3 uint8
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge blur.smooth -> adapter2_gpu2cpu.input : 4x8x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x8x3 uint8
      placed blur: GPU (by model)
    """)
    assert not apply(system, AllocateGpu()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8
      component blur: BoxBlur on GPU [asked gpu by model] (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
      adapter adapter2_gpu2cpu: gpu2cpu of blur.smooth [stage 2]
        in input: GPU uint8x3 = 4x8x3 uint8
        out output: CPU uint8x3 = 4x8x3 uint8
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge blur.smooth -> adapter2_gpu2cpu.input : 4x8x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x8x3 uint8
      placed blur: GPU (by model)
      thread budget 16,384
      can run together: blur
    """)


def test_assign_queues_runs_branches_on_two_lanes_with_waits_where_they_meet():
    system = hand_built({"cam": "StillImage width=8 height=4", "m": "VerticalMirror",
                         "blur": "BoxBlur", "merge": "ImageMerger", "sink": "FrameSink"},
                        "cam.image -> m.image", "cam.image -> blur.image",
                        "m.mirrored -> merge.left", "blur.smooth -> merge.right",
                        "merge.merged -> sink.image")
    apply(system, *UP_TO_ADAPTERS, AllocateGpu(), NameVariables())
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8 -> var cam_image
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8 -> var cam_image_gpu
      component m: VerticalMirror on GPU [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out mirrored: GPU uint8x3 = 4x8x3 uint8 -> var m_mirrored
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
      component blur: BoxBlur on GPU (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8 -> var blur_smooth
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
      component merge: ImageMerger on GPU [stage 3]
        in left: GPU uint8x3 = 4x8x3 uint8
        in right: GPU uint8x3 = 4x8x3 uint8
        out merged: GPU uint8x3 = 4x16x3 uint8 -> var merge_merged
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
      adapter adapter2_gpu2cpu: gpu2cpu of merge.merged [stage 3]
        in input: GPU uint8x3 = 4x16x3 uint8
        out output: CPU uint8x3 = 4x16x3 uint8 -> var merge_merged_cpu
      component sink: FrameSink on CPU (output='') [stage 4]
        in image: CPU uint8x3 = 4x16x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> m.image : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge m.mirrored -> merge.left : 4x8x3 uint8
      edge blur.smooth -> merge.right : 4x8x3 uint8
      edge merge.merged -> adapter2_gpu2cpu.input : 4x16x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x16x3 uint8
      placed m: GPU (by default)
      placed blur: GPU (by default)
      placed merge: GPU (by default)
      thread budget 16,384
      can run together: m, blur
      can run together: merge
    """)
    assert not apply(system, AssignQueues()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8 -> var cam_image
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8 -> var cam_image_gpu
        queue 0
      component m: VerticalMirror on GPU [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out mirrored: GPU uint8x3 = 4x8x3 uint8 -> var m_mirrored
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
        queue 0
      component blur: BoxBlur on GPU (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8 -> var blur_smooth
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
        queue 1, waits adapter1_cpu2gpu
      component merge: ImageMerger on GPU [stage 3]
        in left: GPU uint8x3 = 4x8x3 uint8
        in right: GPU uint8x3 = 4x8x3 uint8
        out merged: GPU uint8x3 = 4x16x3 uint8 -> var merge_merged
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
        queue 0, waits blur
      adapter adapter2_gpu2cpu: gpu2cpu of merge.merged [stage 3]
        in input: GPU uint8x3 = 4x16x3 uint8
        out output: CPU uint8x3 = 4x16x3 uint8 -> var merge_merged_cpu
        queue 0
      component sink: FrameSink on CPU (output='') [stage 4]
        in image: CPU uint8x3 = 4x16x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> m.image : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge m.mirrored -> merge.left : 4x8x3 uint8
      edge blur.smooth -> merge.right : 4x8x3 uint8
      edge merge.merged -> adapter2_gpu2cpu.input : 4x16x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x16x3 uint8
      placed m: GPU (by default)
      placed blur: GPU (by default)
      placed merge: GPU (by default)
      thread budget 16,384
      can run together: m, blur
      can run together: merge
    """)


def test_stage_frames_cuts_stages_and_doubles_the_buffers_between_them():
    system = hand_built({"cam": "StillImage width=8 height=4", "blur": "BoxBlur on=gpu",
                       "sink": "FrameSink"}, "cam.image -> blur.image", "blur.smooth -> sink.image")
    system.frames_in_flight = 2
    apply(system, *UP_TO_ADAPTERS, AllocateGpu(), NameVariables(), AssignQueues())
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8 -> var cam_image
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8 -> var cam_image_gpu
        queue 0
      component blur: BoxBlur on GPU [asked gpu by model] (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8 -> var blur_smooth
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
        queue 0
      adapter adapter2_gpu2cpu: gpu2cpu of blur.smooth [stage 2]
        in input: GPU uint8x3 = 4x8x3 uint8
        out output: CPU uint8x3 = 4x8x3 uint8 -> var blur_smooth_cpu
        queue 0
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge blur.smooth -> adapter2_gpu2cpu.input : 4x8x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x8x3 uint8
      placed blur: GPU (by model)
      thread budget 16,384
      can run together: blur
    """)
    assert not apply(system, StageFrames()).diagnostics
    expect(system, """
      component cam: StillImage on CPU (width=8, height=4, seed=1, frames=0) [stage 1]
        out image: CPU uint8x3 = 4x8x3 uint8 -> var cam_image
      adapter adapter1_cpu2gpu: cpu2gpu of cam.image [stage 1]
        in input: CPU uint8x3 = 4x8x3 uint8
        out output: GPU uint8x3 = 4x8x3 uint8 -> var cam_image_gpu
        queue 0
      component blur: BoxBlur on GPU [asked gpu by model] (radius=1) [stage 2]
        in image: GPU uint8x3 = 4x8x3 uint8
        out smooth: GPU uint8x3 = 4x8x3 uint8 -> var blur_smooth
        config_gpu: tile=32 block=(16, 16, 1) [preferred]
        queue 0
      adapter adapter2_gpu2cpu: gpu2cpu of blur.smooth [stage 2]
        in input: GPU uint8x3 = 4x8x3 uint8
        out output: CPU uint8x3 = 4x8x3 uint8 -> var blur_smooth_cpu
        queue 0
      component sink: FrameSink on CPU (output='') [stage 3]
        in image: CPU uint8x3 = 4x8x3 uint8
      edge cam.image -> adapter1_cpu2gpu.input : 4x8x3 uint8
      edge adapter1_cpu2gpu.output -> blur.image : 4x8x3 uint8
      edge blur.smooth -> adapter2_gpu2cpu.input : 4x8x3 uint8
      edge adapter2_gpu2cpu.output -> sink.image : 4x8x3 uint8
      placed blur: GPU (by model)
      thread budget 16,384
      can run together: blur
      stage 1 of 2 frames in flight: cam, adapter1_cpu2gpu
      stage 2 of 2 frames in flight: blur, adapter2_gpu2cpu
      stage 3 of 2 frames in flight: sink
      2 buffer sets: adapter1_cpu2gpu (written in stage1, read in stage2 by blur: the next frame is written while this one is read)
      2 buffer sets: adapter2_gpu2cpu (written in stage2, read in stage3 by sink: the next frame is written while this one is read)
    """)
