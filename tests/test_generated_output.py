"""What the generated program and its lib folder hold, for inputs that once broke them.

Types with two outputs crossing memories (issue 12, section 1), string parameters that look
like comments on long lines and two user files of the same name (section 6).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.build import compile_model, write
from gpucompgen.library.camera import Camera

MULTI = ROOT / "tests" / "data" / "multi_output"


def _frames(width: int, height: int, seed: int, n: int) -> list[np.ndarray]:
    cam = Camera(width=width, height=height, seed=seed)
    cam.initialize()
    return [cam.execute().copy() for _ in range(n)]


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpucompgen", *args], capture_output=True,
                          text=True, timeout=600)


@pytest.mark.parametrize("model", ["gpu_two_outputs", "cpu_two_outputs"])
def test_multi_output_types_pass_every_command(tmp_path, model):
    path = MULTI / f"{model}.yaml"
    for args in (["check", str(path)], ["plan", str(path)],
                 ["graph", str(path), "-o", str(tmp_path / "g.dot")],
                 ["build", str(path), "-o", str(tmp_path / "out")],
                 ["--debug", "check", str(path), "--mode", "standard"]):
        proc = _cli(*args)
        assert proc.returncode == 0, (args, proc.stderr)
        assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr
    dot = (tmp_path / "g.dot").read_text()
    assert dot.count("generated adapter") == 3


def test_build_writes_each_file_once(tmp_path):
    """Keep1 and Keep3 share keep.py: one copy, one 'wrote' line."""
    proc = _cli("build", str(MULTI / "gpu_two_outputs.yaml"), "-o", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    wrote = proc.stdout.splitlines()
    assert len(wrote) == len(set(wrote)) == 3, wrote
    assert sorted(p.name for p in (tmp_path / "gpu_two_outputs_lib").iterdir()) == [
        "keep.py", "luma_sub.cl"]
    assert "# Copied from the component type file of Keep1, Keep3." in \
        (tmp_path / "gpu_two_outputs_lib" / "keep.py").read_text()


def _run(tmp_path: Path, model: str, mode: str, zero_copy: str, frames: int):
    out = tmp_path / f"{model}-{mode}-{zero_copy}"
    result = compile_model(MULTI / f"{model}.yaml", out, mode=mode, device="pocl-cpu",
                           zero_copy=zero_copy)
    write(result, out)
    module = load_generated(out / f"{model}.py", f"{model}_{mode}_{zero_copy}")
    return result, module.run(frames=frames)


VARIANTS = [("gpu-aware", "off"), ("gpu-aware", "on"), ("standard", "off")]


@pytest.mark.parametrize("mode,zero_copy", VARIANTS)
def test_gpu_type_with_two_outputs_to_the_cpu_matches_numpy(tmp_path, mode, zero_copy):
    require_opencl()
    result, run = _run(tmp_path, "gpu_two_outputs", mode, zero_copy, 3)
    assert len(result.system.adapters) == (3 if mode == "gpu-aware" else 0)
    luma, sub = run.components["keep_luma"].frames, run.components["keep_sub"].frames
    assert len(luma) == len(sub) == 3
    for f, image in enumerate(_frames(45, 33, 4, 3)):
        rgb = image.astype(np.int32)
        expected = ((77 * rgb[..., 0] + 150 * rgb[..., 1] + 29 * rgb[..., 2]) >> 8)
        np.testing.assert_array_equal(luma[f], expected.astype(np.uint8))
        np.testing.assert_array_equal(sub[f], image[::2, ::2])


@pytest.mark.parametrize("mode,zero_copy", VARIANTS)
def test_standard_type_with_two_outputs_to_the_gpu_matches_numpy(tmp_path, mode, zero_copy):
    require_opencl()
    _, run = _run(tmp_path, "cpu_two_outputs", mode, zero_copy, 3)
    kept = run.components["keep"].frames
    assert len(kept) == 3
    for f, image in enumerate(_frames(40, 24, 5, 3)):
        np.testing.assert_array_equal(kept[f], np.hstack([image, 255 - image]))


def test_gpucompgen_run_on_a_multi_output_model():
    require_opencl()
    proc = _cli("run", str(MULTI / "gpu_two_outputs.yaml"), "--frames", "2", "--quiet")
    assert proc.returncode == 0, proc.stderr


# --- issue 12, section 6 ---------------------------------------------------------------

COMMENT_LIKE = "a  # b, and a folder name long enough to need the whole line and then some"


def test_a_string_parameter_that_looks_like_a_comment_is_kept_whole(tmp_path):
    text = (ROOT / "models" / "vision_system.yaml").read_text().replace(
        "params: {seed: 1, width: 640, height: 480}",
        f"params: {{seed: 1, width: 640, height: 480, folder: '{COMMENT_LIKE}'}}")
    assert COMMENT_LIKE in text
    model = tmp_path / "m.yaml"
    model.write_text(text)
    result = compile_model(model, tmp_path / "out")
    program = result.files[0].text
    compile(program, "vision_system.py", "exec")
    # a path parameter: relative to the model, seen from the program's folder
    literal = repr(f"../{COMMENT_LIKE}")
    assert f"runtime.model_path(__file__, {literal})" in program  # in PARAMS
    assert "folder=params['camera1.folder']" in program
    # every other line fits the line length; the literal is never broken
    long = [line for line in program.splitlines() if len(line) > 100]
    assert all(literal in line for line in long), long


def test_generated_programs_fit_the_line_length():
    for program in (ROOT / "generated").rglob("*.py"):
        if program.parent.name.endswith("_lib"):
            continue
        for n, line in enumerate(program.read_text().splitlines(), 1):
            assert len(line) <= 100, f"{program}:{n}: {len(line)} columns"


TYPE = """\
component_types:
  {name}:
    kind: standard
    inputs:
      image: {{memory: cpu, dtype: uint8, channels: 3}}
    python: {{file: comp.py, class: {name}}}
"""

COMP = """\
class {name}:
    def __init__(self):
        self.frames = 0

    def initialize(self, image):
        pass

    def execute(self, image):
        self.frames += 1
        self.tag = {tag!r}

    def free_memory(self):
        pass
"""


def test_user_files_of_the_same_name_in_two_folders_stay_apart(tmp_path):
    for folder, name in (("a", "SinkA"), ("b", "SinkB")):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "types.yaml").write_text(TYPE.format(name=name))
        (tmp_path / folder / "comp.py").write_text(COMP.format(name=name, tag=folder))
    model = tmp_path / "two.yaml"
    model.write_text("system: two\ntypes: [a/types.yaml, b/types.yaml]\ncomponents:\n"
                     "  camera: {type: Camera, params: {width: 16, height: 16}}\n"
                     "  sa: {type: SinkA}\n  sb: {type: SinkB}\n"
                     "connections:\n  - camera.image -> sa.image\n  - camera.image -> sb.image\n")
    out = tmp_path / "out"
    result = compile_model(model, out)
    write(result, out)
    names = sorted(p.name for p in (out / "two_lib").iterdir())
    assert names == ["comp.py", "comp_2.py"]
    texts = {n: (out / "two_lib" / n).read_text() for n in names}
    assert "class SinkA" in texts["comp.py"] and "class SinkB" in texts["comp_2.py"]
    require_opencl()
    run = load_generated(out / "two.py", "two_under_test").run(frames=2)
    assert (run.components["sa"].tag, run.components["sb"].tag) == ("a", "b")
    assert run.components["sa"].frames == run.components["sb"].frames == 2


def test_print_between_passes_prints_the_whole_ir_after_each_pass():
    proc = _cli("build", str(ROOT / "models" / "vision_system.yaml"), "--check",
                "--print-between-passes")
    assert proc.returncode == 0, proc.stderr
    from gpucompgen.passes import passes_names

    for name in passes_names():
        assert f"// after {name}\n" in proc.stderr
    last = proc.stderr.split("// after lower\n")[1]
    for line in ("group merger_detector on GPU: merger (ImageMerger), detector (ObjectDetector) "
                 "[stage 3]",
                 "adapter adapter3_gpu2cpu: gpu2cpu of detector.mask [stage 3]",
                 "edge adapter1_cpu2gpu.output -> merger_detector.merger_left : 480x640x3 uint8",
                 "fused edge merger.merged -> detector.frame",
                 "launch merger_detector: merger_detector global (16, 240, 1) local (16, 16, 1)",
                 "transfer adapter1_cpu2gpu: cpu2gpu 921,600 bytes"):
        assert line in last, last
