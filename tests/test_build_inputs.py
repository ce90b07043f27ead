"""What feeds a build: every kernel a model names is compiled, every input file is
recorded (so `build --check` sees any change), and none is ever replaced or deleted.

The class behind these: a fused type's hand-written kernel was left out of the program, so a
typo in it passed check, build and run, and editing it left `build --check` "up to date"
(the output held nothing of that file); a build into the folder holding its own inputs
deleted them; `--check` read a whole output file into memory to diff it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import tracemalloc
from pathlib import Path

import pytest
from conftest import ROOT, require_opencl

from gpucompgen import build as build_mod
from gpucompgen.build import compile_model, write

TYPES = textwrap.dedent("""\
    component_types:
      Flip:
        kind: gpu-aware
        inputs:
          image: {memory: gpu, channels: 3}
        outputs:
          out: {memory: gpu, channels: 3, height: image.height, width: image.width}
        kernel: {file: flip.cl, function: flip}
        fusable: {form: index_map, value: "image(image_height - 1 - y, x, c)"}
      Brighten:
        kind: flexible
        inputs:
          image: {channels: 3}
        outputs:
          out: {channels: 3, height: image.height, width: image.width}
        kernel: {file: flip.cl, function: brighten}
        cpu: {file: cpu.py, function: brighten}
    """)

KERNEL = textwrap.dedent("""\
    __kernel void flip(__global const uchar *image, __global uchar *out,
                       const int image_height, const int image_width, const int out_height,
                       const int out_width, const int tile) {
        int i = get_global_id(0);
        out[i] = image[i];
    }

    __kernel void brighten(__global const uchar *image, __global uchar *out,
                           const int image_height, const int image_width,
                           const int out_height, const int out_width, const int tile) {
        int i = get_global_id(0);
        out[i] = image[i];
    }
    """)

CPU = "def brighten(image):\n    return image.copy()\n"

MODEL = textwrap.dedent("""\
    system: s
    types: [TYPES]
    platform: {placement: PLACEMENT, profile: prof.yaml}
    components:
      src: {type: StillImage, params: {width: 8, height: 8, frames: 2}}
      f1: Flip
      f2: {type: VerticalMirror, placement: gpu}
      b: Brighten
      sink: FrameSink
    connections: [src.image -> f1.image, f1.out -> f2.image, f2.mirrored -> b.image,
                  b.out -> sink.image]
    """)


def project(folder: Path, types_at: str = "t.yaml", placement: str = "cpu") -> Path:
    tdir = (folder / types_at).parent
    tdir.mkdir(parents=True, exist_ok=True)
    (folder / types_at).write_text(TYPES)
    (tdir / "flip.cl").write_text(KERNEL)
    (tdir / "cpu.py").write_text(CPU)
    (folder / "prof.yaml").write_text("components:\n  b: {cpu_us: 1, gpu_us: 900}\n")
    model = folder / "m.yaml"
    model.write_text(MODEL.replace("TYPES", types_at).replace("PLACEMENT", placement))
    return model


def gpucompgen(*args, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "gpucompgen", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, check=False, env=env)


def test_a_kernel_not_launched_is_still_in_the_program_and_built(tmp_path):
    model = project(tmp_path)
    result = compile_model(model, tmp_path / "out")
    assert [m.name for g in result.system.groups for m in g.members] == ["f1", "f2"]
    names = {f.path.name for f in result.files}
    assert "flip.cl" in names, "Flip is fused and Brighten on the CPU: flip.cl still built"
    program = result.files[0].text
    assert "LIB_DIR / 'flip.cl',\n        'b (Brighten; on the CPU: built only to check it), " \
        "f1 (Flip; fused: built only to check it)')" in program


def project_with_a_typo(tmp_path: Path) -> Path:
    """The project with 'imgae' for 'image' in Flip's kernel (line 5, column 14)."""
    model = project(tmp_path)
    kernel = tmp_path / "flip.cl"
    kernel.write_text(KERNEL.replace("out[i] = image[i];", "out[i] = imgae[i];", 1))
    return model


def test_a_typo_in_a_fused_types_kernel_fails_the_run(tmp_path):
    require_opencl()
    model = project_with_a_typo(tmp_path)
    assert gpucompgen("check", model, cwd=tmp_path).returncode == 0  # check needs no device
    proc = gpucompgen("run", model, "--frames", "1", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "kernel file flip.cl failed to build" in proc.stderr
    assert "flip.cl:5:14: error: use of undeclared identifier 'imgae'" in proc.stderr


@pytest.mark.parametrize("command", ["check", "build", "plan"])
def test_planned_for_the_device_every_kernel_is_built_at_check_time(tmp_path, command):
    require_opencl()
    model = project_with_a_typo(tmp_path)
    proc = gpucompgen(command, model, "--device", "auto", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "t.yaml:2:3: error: Flip: kernel file flip.cl failed to build:\n" \
        "  flip.cl:5:14: error: use of undeclared identifier 'imgae'" in proc.stderr
    assert not (tmp_path / "generated").exists()


@pytest.mark.parametrize("edited", ["flip.cl", "t.yaml", "cpu.py", "prof.yaml"])
def test_build_check_is_stale_when_any_input_changes(tmp_path, edited):
    model = project(tmp_path, placement="auto")
    out = tmp_path / "out"
    assert gpucompgen("build", model, "-o", out, cwd=tmp_path).returncode == 0
    assert gpucompgen("build", model, "-o", out, "--check", cwd=tmp_path).returncode == 0
    path = tmp_path / edited
    path.write_text(path.read_text() + "\n# an edit\n".replace(
        "#", "//" if edited.endswith(".cl") else "#"))
    proc = gpucompgen("build", model, "-o", out, "--check", cwd=tmp_path)
    assert proc.returncode == 1, f"{edited} changed, --check said: {proc.stderr}"
    assert f"  {edited}" in proc.stdout  # the line naming its digest changed
    assert gpucompgen("build", model, "-o", out, cwd=tmp_path).returncode == 0
    assert gpucompgen("build", model, "-o", out, "--check", cwd=tmp_path).returncode == 0


@pytest.mark.parametrize("types_at", ["s_lib/t.yaml", "s_lib/deeper/t.yaml"])
def test_a_build_never_replaces_its_own_inputs(tmp_path, types_at):
    model = project(tmp_path, types_at)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    for extra in ([], ["--overwrite"]):
        proc = gpucompgen("build", model, "-o", ".", *extra, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert f"would replace {types_at}, an input of the build" in proc.stderr
        assert "Traceback" not in proc.stderr
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


@pytest.mark.parametrize("folder", ["s_lib/photos", "s_lib/photos/*.png"])
def test_a_build_never_replaces_a_path_parameter(tmp_path, folder):
    from PIL import Image

    (tmp_path / "s_lib" / "photos").mkdir(parents=True)
    Image.new("RGB", (16, 16)).save(tmp_path / "s_lib" / "photos" / "01.png")
    (tmp_path / "m.yaml").write_text(
        f"system: s\ncomponents:\n  cam: {{type: Camera, params: {{folder: '{folder}'}}}}\n"
        "  sink: FrameSink\nconnections: [cam.image -> sink.image]\n")
    proc = gpucompgen("build", "m.yaml", "-o", ".", "--overwrite", cwd=tmp_path)
    assert proc.returncode == 2 and "would replace s_lib/photos" in proc.stderr, proc.stderr
    assert (tmp_path / "s_lib" / "photos").is_dir()


def test_build_check_streams_a_huge_file_and_caps_the_diff(tmp_path):
    model = project(tmp_path)
    out = tmp_path / "out"
    result = compile_model(model, out)
    write(result, out)
    huge = out / "s_lib" / "a_huge.bin"  # sorted before flip.cl
    with huge.open("wb") as f:
        f.truncate(64 << 20)  # 64 MiB of zeros (sparse)
    (out / "s_lib" / "flip.cl").write_text("x\n" * 20_000)  # a long text diff
    tracemalloc.start()
    text = build_mod.diff(result, out)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 << 20, f"diff held {peak:,} bytes"
    assert f"s_lib/a_huge.bin: {64 << 20:,} bytes, not shown" in text
    assert text.count("\n") <= build_mod.MAX_DIFF_LINES + 1
    assert "more lines of diff not shown" in text


# --------------------------------------------------------------------------- tune


@pytest.mark.parametrize("output", ["m.yaml", "t.yaml", "flip.cl", "cpu.py"])
def test_tune_never_writes_over_an_input_of_the_build(tmp_path, output):
    model = project(tmp_path)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    for how in (["-o", output], []):
        if not how:  # the same through the model's own platform.profile
            if not output.endswith(".yaml"):
                continue  # check refuses a profile that is no .yaml file
            model.write_text(model.read_text().replace("profile: prof.yaml",
                                                       f"profile: {output}"))
            before[model] = model.read_bytes()
        proc = gpucompgen("tune", model, *how, cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert f"{output} is an input of the build of" in proc.stderr, proc.stderr
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


@pytest.mark.parametrize("output, message", [
    (".", ". is a folder"),
    ("/dev/full", "/dev/full is not a regular file"),
    ("prof.yaml/x.yaml", "prof.yaml is a file, where the profile's folder would go"),
])
def test_tune_checks_its_output_before_measuring(tmp_path, output, message):
    model = project(tmp_path)
    # no device is needed to find out: the output is checked first
    env_device = {"PYOPENCL_CTX": "no-such-device"}
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "tune", str(model), "-o",
                           output], cwd=tmp_path, capture_output=True, text=True,
                          check=False, env={**os.environ, **env_device,
                                            "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))})
    assert proc.returncode == 2, proc.stderr
    assert f"gpucompgen tune: error: {message}" in proc.stderr
    assert "internal error" not in proc.stderr


def test_tune_write_failure_is_a_clear_error(tmp_path, monkeypatch):
    from gpucompgen import tune as tune_mod
    from gpucompgen.errors import OutputError

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(tune_mod.os, "replace", full)
    with pytest.raises(OutputError, match="cannot write the profile .*No space left"):
        tune_mod.write_profile(tmp_path / "p.yaml", "components: {}\n")
    assert list(tmp_path.iterdir()) == [], "no temporary file left behind"


def test_a_cpu_function_raising_under_tune_is_the_users_error(tmp_path):
    require_opencl()
    model = project(tmp_path)
    (tmp_path / "cpu.py").write_text("def brighten(image):\n"
                                     "    raise ValueError('boom')\n")
    proc = gpucompgen("tune", model, "--frames", "1", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "gpucompgen tune: error: b (Brighten): its CPU function 'brighten' raised " \
        "ValueError: boom (at cpu.py:2)" in proc.stderr
    assert "internal error" not in proc.stderr


def test_a_build_never_replaces_a_cpu_file_named_like_its_program(tmp_path):
    model = project(tmp_path)
    (tmp_path / "cpu.py").rename(tmp_path / "s.py")  # s.py: where system 's' goes
    (tmp_path / "t.yaml").write_text(TYPES.replace("file: cpu.py", "file: s.py"))
    proc = gpucompgen("build", model, "-o", ".", "--overwrite", cwd=tmp_path)
    assert proc.returncode == 2 and "would replace s.py, an input of the build" in proc.stderr
    assert (tmp_path / "s.py").read_text() == CPU


def test_neither_build_nor_tune_writes_over_the_librarys_files(tmp_path):
    library = ROOT / "gpucompgen" / "library"
    (tmp_path / "m.yaml").write_text(
        "system: camera\ncomponents:\n  cam: {type: Camera}\n  sink: FrameSink\n"
        "connections: [cam.image -> sink.image]\n")
    proc = gpucompgen("build", "m.yaml", "-o", library, "--overwrite", cwd=tmp_path)
    assert proc.returncode == 2 and "camera.py, an input of the build" in proc.stderr
    proc = gpucompgen("tune", "m.yaml", "-o", library / "vision.yaml", cwd=tmp_path)
    assert proc.returncode == 2 and "vision.yaml is an input of the build" in proc.stderr, \
        proc.stderr
