"""Bad models give positioned errors (file:line:col), never tracebacks."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

BASE = """\
system: s
components:
  camera1: {type: Camera, params: {width: 64, height: 48}}
  camera2: {type: Camera, params: {width: 64, height: 48}}
  merger: {type: ImageMerger}
  detector: {type: ObjectDetector}
  manager: {type: VisionManager}
connections:
  - camera1.image -> merger.left
  - camera2.image -> merger.right
  - merger.merged -> detector.frame
  - detector.mask -> manager.mask
"""

CASES = {
    "unknown_type": (BASE.replace("type: ImageMerger", "type: ImageMerjer"), 5, 18,
                     "unknown component type 'ImageMerjer'", "did you mean 'ImageMerger'"),
    "unknown_port": (BASE.replace("merger.right", "merger.rigth"), 10, 5,
                     "'merger' (ImageMerger) has no port 'rigth'", "merger.right"),
    "unknown_component": (BASE.replace("detector.mask ->", "detektor.mask ->"), 12, 5,
                          "unknown component 'detektor'", "did you mean 'detector'"),
    "channel_mismatch": (BASE.replace("merger.merged -> detector.frame",
                                      "merger.merged -> manager.mask").replace(
        "  - detector.mask -> manager.mask\n", "  - camera1.image -> detector.frame\n"), 11, 5,
        "channel mismatch: 'merger.merged' gives 3 channel(s), 'manager.mask' takes 1", ""),
    "size_mismatch": (BASE.replace("camera2: {type: Camera, params: {width: 64, height: 48}}",
                                   "camera2: {type: Camera, params: {width: 64, height: 50}}"),
                      5, 3, "'merger' (ImageMerger): left and right frames must have the same height "
                      "(left is 48x64, right is 50x64)", ""),
    "two_writers": (BASE + "  - detector.mask -> merger.left\n", 13, 5,
                    "input 'merger.left' has two writers", "first is at line 9"),
    "from_input": (BASE.replace("detector.mask -> manager.mask", "manager.mask -> detector.mask"),
                   12, 5, "connection from 'manager.mask', which is an input", ""),
    "wrong_param_type": (BASE.replace("{width: 64, height: 48}}\n  camera2",
                                      "{width: sixty, height: 48}}\n  camera2"), 3, 43,
                         "parameter 'width' of 'Camera' must be int", ""),
    "yaml_syntax": ("system: s\ncomponents: [\n", 3, 1, "invalid YAML", ""),
}


def _check(tmp_path, text):
    model = tmp_path / "bad.yaml"
    model.write_text(text)
    return subprocess.run([sys.executable, "-m", "gpucompgen", "build", str(model), "-o",
                           str(tmp_path / "out")], capture_output=True, text=True)


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_model_gets_a_positioned_error(tmp_path, case):
    text, line, col, message, hint = CASES[case]
    proc = _check(tmp_path, text)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"bad.yaml:{line}:{col}: error: {message}" in proc.stderr, proc.stderr
    assert hint in proc.stderr
    assert not (tmp_path / "out").exists(), "nothing is written when a model has errors"


def test_a_true_cycle_is_reported(tmp_path):
    types = tmp_path / "t.yaml"
    types.write_text(textwrap.dedent("""\
        component_types:
          Pass:
            kind: gpu-aware
            inputs: {a: {memory: gpu, channels: 3}, b: {memory: gpu, channels: 3}}
            outputs: {o: {memory: gpu, channels: 3, height: a.height, width: a.width}}
            kernel: {file: k.cl, function: pass_through}
        """))
    (tmp_path / "k.cl").write_text(
        "__kernel void pass_through(__global const uchar *a, __global const uchar *b,\n"
        "    __global uchar *o, const int a_height, const int a_width, const int b_height,\n"
        "    const int b_width, const int o_height, const int o_width, const int tile) {}\n")
    proc = _check(tmp_path, textwrap.dedent("""\
        system: s
        types: [t.yaml]
        components:
          cam: {type: Camera}
          p1: {type: Pass}
          p2: {type: Pass}
        connections:
          - cam.image -> p1.a
          - p2.o -> p1.b
          - p1.o -> p2.a
          - cam.image -> p2.b
        """))
    assert proc.returncode == 1
    assert "cycle: p1 -> p2 -> p1" in proc.stderr, proc.stderr


def test_all_errors_are_reported_at_once(tmp_path):
    text = BASE.replace("type: ImageMerger", "type: Nope").replace("detector.mask ->",
                                                                  "detector.masc ->")
    proc = _check(tmp_path, text)
    assert "unknown component type 'Nope'" in proc.stderr
    assert "has no port 'masc'" in proc.stderr
    assert "2 errors found" in proc.stderr
