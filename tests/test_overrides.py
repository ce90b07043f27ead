"""Run-time overrides of a generated program: --input, --output, --set (checked against the
parameters' declarations, without a rebuild) and --place globs."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, require_opencl

from gpucompgen import io
from gpucompgen.build import compile_model, write
from gpucompgen.runtime.overrides import OverrideError, Param, param_values, parse_overrides

Image = pytest.importorskip("PIL.Image")
W, H = 48, 32

MODEL = """\
system: spots
platform: {{device: portable}}
components:
  camera: {{type: Camera, params: {{width: {W}, height: {H}, folder: shots}}}}
  detector: {{type: ObjectDetector, params: {{red_min: 150}}}}
  writer: {{type: MaskWriter, params: {{min_area: 4}}}}
connections:
  - camera.image -> detector.frame
  - camera.image -> writer.image
  - detector.mask -> writer.mask
"""


def shot(red: int) -> np.ndarray:
    """A dark frame with one red square of colour (red, 20, 20)."""
    image = np.full((H, W, 3), 30, np.uint8)
    image[8:16, 10:20] = (red, 20, 20)
    return image


@pytest.fixture(scope="module")
def program(tmp_path_factory) -> Path:
    """The program built next to its model, then copied to another folder without it."""
    require_opencl()
    root = tmp_path_factory.mktemp("overrides")
    (root / "model").mkdir()
    (root / "model" / "spots.yaml").write_text(MODEL.format(W=W, H=H))
    (root / "model" / "shots").mkdir()
    out = root / "model" / "generated"
    write(compile_model(root / "model" / "spots.yaml", out), out)
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(out / "spots.py", elsewhere)
    shutil.copytree(out / "spots_lib", elsewhere / "spots_lib")
    shutil.rmtree(root / "model")  # the model, its folder and its build are gone
    return elsewhere / "spots.py"


def run(program: Path, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(program), *args], capture_output=True,
                          text=True, timeout=300, check=False, env=dict(os.environ), cwd=cwd)


def shots(folder: Path, reds=(200, 170, 120)) -> Path:
    folder.mkdir(exist_ok=True)
    for i, red in enumerate(reds):
        Image.fromarray(shot(red)).save(folder / f"{i:02d}.png")
    return folder


def objects(stdout: str) -> list[int]:
    return [int(line.split(": ")[1].split()[0]) for line in stdout.splitlines()
            if line.startswith("frame ")]


def test_a_copied_program_runs_with_its_input_given(program, tmp_path):
    proc = run(program, "--frames", "1")
    assert proc.returncode == 1 and "shots' does not exist" in proc.stderr
    folder = shots(tmp_path / "mine")
    proc = run(program, "--input", "camera=mine", cwd=tmp_path)  # relative to the cwd
    assert proc.returncode == 0, proc.stderr
    assert objects(proc.stdout) == [1, 1, 0]  # 200 and 170 pass red_min 150; 120 does not
    proc = run(program, "--input", f"camera={folder}/0[01].png")
    assert proc.returncode == 0 and objects(proc.stdout) == [1, 1]


def test_set_changes_a_threshold_without_a_rebuild(program, tmp_path):
    folder = shots(tmp_path / "mine")
    before = {p: p.stat().st_mtime_ns for p in program.parent.rglob("*") if p.is_file()}
    proc = run(program, "--input", f"camera={folder}", "--set", "detector.red_min=100")
    assert proc.returncode == 0, proc.stderr
    assert objects(proc.stdout) == [1, 1, 1]
    proc = run(program, "--input", f"camera={folder}", "--set", "detector.red_min=180",
               "--set", "writer.print_objects=yes")
    assert objects(proc.stdout) == [1, 0, 0]
    after = {p: p.stat().st_mtime_ns for p in program.parent.rglob("*") if p.is_file()
             if "__pycache__" not in p.parts}
    assert {p: t for p, t in before.items() if "__pycache__" not in p.parts} == after


@pytest.mark.parametrize(("args", "message"), [
    (("--set", "detector.red_min=300"), "--set detector.red_min=300: 300 is above the "
                                        "maximum 255"),
    (("--set", "detector.red_min=high"), "expected a whole number, e.g. detector.red_min=150"),
    (("--set", "detector.red_mn=3"), "did you mean 'detector.red_min'?"),
    (("--set", "camera.width=64"), "'camera.width' cannot be set at run time"),
    (("--set", "cam.seed=3"), "no component 'cam' with settable parameters (did you mean "
                              "'camera'?)"),
    (("--set", "detector=3"), "write --set NAME.PARAM=VALUE"),
    (("--input", "writer=x/"), "component 'writer' takes no source URI; components that "
                               "do: camera"),
    (("--input", "camera"), "write --input NAME=URI"),
    (("--output", "camera=out.mp4"), "component 'camera' takes no output URI; components "
                                     "that do: writer"),
])
def test_bad_overrides_are_usage_errors(program, args, message):
    proc = run(program, *args)
    assert proc.returncode == 2
    assert message in proc.stderr and "Traceback" not in proc.stderr


def test_bad_input_uri_is_one_line_naming_it(program, tmp_path):
    proc = run(program, "--input", "camera=rtsp://127.0.0.1:9/cam")
    assert proc.returncode == 1
    assert "cannot connect to 127.0.0.1:9" in proc.stderr and "Traceback" not in proc.stderr
    proc = run(program, "--input", "camera=mcap://nothing.mcap", cwd=tmp_path)
    assert proc.returncode == 1 and "nothing.mcap does not exist" in proc.stderr


def test_output_uris_receive_the_annotated_frames_and_masks(program, tmp_path):
    folder = shots(tmp_path / "mine")
    for out in ("out.avi", "frames/", "mcap://rec.mcap?topic=/spots"):
        proc = run(program, "--input", f"camera={folder}", "--output", f"writer={out}",
                   "-q", cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
    pytest.importorskip("cv2")
    for uri, n in ((tmp_path / "out.avi", 3), (tmp_path / "out_mask.avi", 3),
                   (tmp_path / "frames" / "0*.png", 3), (tmp_path / "frames" / "mask_*.png", 3),
                   (f"mcap://{tmp_path}/rec.mcap?topic=/spots/mask", 3)):
        source = io.open_source(str(uri))
        assert source.open() == (H, W), uri
        got = []
        while (f := source.read()) is not None:
            got.append(f)
        assert len(got) == n, uri
    mask = np.asarray(Image.open(tmp_path / "frames" / "mask_000000.png"))
    assert mask[8:16, 10:20].min() == 255 and mask.sum() == 255 * 80  # the red square


def test_place_glob_puts_every_flexible_component_on_the_cpu(tmp_path):
    require_opencl()
    folder = shots(tmp_path / "shots")
    (tmp_path / "spots.yaml").write_text(MODEL.format(W=W, H=H))
    cmd = [sys.executable, "-m", "gpucompgen", "run", str(tmp_path / "spots.yaml"),
           "--place", "*=cpu", "--input", f"camera={folder}", "--set", "detector.red_min=160"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    assert objects(proc.stdout) == [1, 1, 0]
    plan = subprocess.run([sys.executable, "-m", "gpucompgen", "plan",
                           str(tmp_path / "spots.yaml"), "--place", "*=cpu"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert "detector: CPU (by command line)" in plan.stdout
    bad = subprocess.run([sys.executable, "-m", "gpucompgen", "plan",
                          str(tmp_path / "spots.yaml"), "--place", "x*=cpu"],
                         capture_output=True, text=True, timeout=120, check=False)
    assert bad.returncode == 2
    assert "the pattern matches no flexible component (flexible: detector)" in bad.stderr


def test_param_values_and_input_clears_the_older_input_params():
    table = {"cam.source": Param("path", ""), "cam.folder": Param("path", "/old"),
             "cam.seed": Param("int", 1, minimum=0), "det.gain": Param("float", 1.0),
             "w.output": Param("str", "")}
    got = parse_overrides(table, ["cam.seed=0x10", "det.gain=2.5"], ["cam=mcap://a.mcap"],
                          ["w=display://"])
    assert got == {"cam.source": "mcap://a.mcap", "cam.folder": "", "cam.seed": 16,
                   "det.gain": 2.5, "w.output": "display://"}
    assert param_values(table, got)["cam.folder"] == ""
    for bad, message in (({"cam.seed": -1}, "below the minimum 0"),
                         ({"cam.seed": True}, "expected int, not bool"),
                         ({"det.gain": "2"}, "expected float, not str"),
                         ({"cam.sed": 1}, "did you mean 'cam.seed'")):
        with pytest.raises(OverrideError, match=message):
            param_values(table, bad)
    assert parse_overrides(table, [], ["cam=shots"], [])["cam.source"] == \
        os.path.abspath("shots")
    for bad in (["cam.seed=-1"], ["det.gain=nan"], ["cam.seed=1.5"]):
        with pytest.raises(OverrideError):
            parse_overrides(table, bad, [], [])


def test_generated_programs_declare_what_set_may_change():
    text = (ROOT / "generated" / "vision_system.py").read_text()
    assert "'detector.red_min': runtime.Param('int', 150, minimum=0, maximum=255)" in text
    assert "'camera1.width'" not in text  # a size: fixed at build time
    assert "np.int32(params['detector.red_min'])" in text


def test_drop_counts_what_the_pipeline_did_not_take(program, tmp_path):
    import json

    folder = shots(tmp_path / "mine")
    proc = run(program, "--input", f"camera={folder}", "--drop", "--stats-json",
               str(tmp_path / "s.json"))
    assert proc.returncode == 0, proc.stderr
    stats = json.loads((tmp_path / "s.json").read_text())
    dropped = stats["dropped_frames"]["camera"]
    assert stats["frames"] + dropped == 3 and stats["frames"] >= 1
    assert f"processed {stats['frames']} frame(s); dropped {dropped} (camera {dropped})" \
        in proc.stderr
