"""Inputs are read-only to components, enforced: a component that writes into a frame it
was given fails, named, with a hint, instead of changing what another reader of the same
producer gets (a flexible CPU function doing `image[...] = 0` corrupted its sibling's
frames, exit 0).

Every array a component gets is a non-writable view: CPU functions' inputs, what a CPU
part returns (checked by runtime.check_frame), what a GPU-to-CPU adapter hands on.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import ROOT, require_opencl

from gpucompgen.runtime.frames import check_frame

TYPES = textwrap.dedent("""\
    component_types:
      Scribble:
        kind: flexible
        inputs:
          image: {channels: 3}
        outputs:
          out: {channels: 3, height: image.height, width: image.width}
        kernel: {file: k.cl, function: scribble}
        cpu: {file: cpu.py, function: scribble}
      Eraser:
        kind: standard
        inputs:
          image: {memory: cpu, channels: 3}
        outputs:
          out: {memory: cpu, channels: 3, height: image.height, width: image.width}
        python: {file: eraser.py, class: Eraser}
    """)

KERNEL = """\
__kernel void scribble(__global const uchar *image, __global uchar *out,
                       const int image_height, const int image_width, const int out_height,
                       const int out_width, const int tile) {
    out[get_global_id(0)] = image[get_global_id(0)];
}
"""

CPU = """\
def scribble(image):
    image[0, 0] = 0
    return image
"""

ERASER = """\
class Eraser:
    def initialize(self, size):
        return size

    def execute(self, image):
        image[...] = 0
        return image

    def free_memory(self):
        pass
"""


def project(tmp_path, consumer: str, producers: tuple[str, ...] = (
        "src: {type: StillImage, params: {width: 8, height: 8, frames: 3}}",),
        source_port: str = "src.image", more: str = ""):
    (tmp_path / "t.yaml").write_text(TYPES)
    (tmp_path / "k.cl").write_text(KERNEL)
    (tmp_path / "cpu.py").write_text(CPU)
    (tmp_path / "eraser.py").write_text(ERASER)
    (tmp_path / "m.yaml").write_text(
        "system: s\ntypes: [t.yaml]\ncomponents:\n"
        + "".join(f"  {p}\n" for p in producers)
        + f"  writer: {consumer}\n  sink1: FrameSink\n  sink2: FrameSink\n"
        f"connections: [{more}{source_port} -> writer.image, writer.out -> sink1.image,\n"
        f"              {source_port} -> sink2.image]\n")
    return tmp_path / "m.yaml"


def run(model, *args):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(model), *args],
                          capture_output=True, text=True, check=False, env=env,
                          cwd=model.parent)


@pytest.mark.parametrize("consumer", ["{type: Scribble, placement: cpu}", "Eraser"])
@pytest.mark.parametrize("fif", ["1", "2"])
def test_a_component_writing_its_input_fails_named_with_a_hint(tmp_path, consumer, fif):
    require_opencl()
    model = project(tmp_path, consumer)
    proc = run(model, "--frames", "2", "--frames-in-flight", fif)
    assert proc.returncode == 1, proc.stderr
    assert "writer failed at frame 0: ValueError: assignment destination is read-only" \
        in proc.stderr, proc.stderr
    assert "hint: inputs are read-only to components" in proc.stderr


def test_a_frame_downloaded_from_the_gpu_is_read_only_too(tmp_path):
    require_opencl()
    model = project(tmp_path, "Eraser", (
        "src: {type: StillImage, params: {width: 8, height: 8, frames: 3}}",
        "gpu: {type: VerticalMirror, placement: gpu}"), "gpu.mirrored",
        more="src.image -> gpu.image, ")
    for zero_copy in ("on", "off"):
        proc = run(model, "--frames", "2", "--zero-copy", zero_copy)
        assert proc.returncode == 1, proc.stderr
        assert "writer failed at frame 0: ValueError: assignment destination is " \
            "read-only" in proc.stderr


def test_read_only_views_share_the_producers_memory():
    frame = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
    view = check_frame("a.b", frame, (2, 4, 3), np.uint8)
    assert not view.flags.writeable and np.shares_memory(view, frame)
    assert frame.flags.writeable, "the producer keeps writing its own array"
    with pytest.raises(ValueError, match="read-only"):
        view[0, 0, 0] = 1
    # handed on again (the next reader, the loop's check): the same view, none made
    assert check_frame("a.b", view, (2, 4, 3), np.uint8) is view
