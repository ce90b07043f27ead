"""A relative path parameter (the Camera's folder and video) is relative to the model file,
not to the working directory of whoever runs the program (issue 12, section 3)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
from conftest import require_opencl

from gpucompgen.build import compile_model, write

MODEL = """\
system: paths
components:
  camera: {{type: Camera, params: {{width: 24, height: 16, folder: {folder}}}}}
  detector: {{type: ObjectDetector}}
  manager: {{type: VisionManager, params: {{print_decisions: false}}}}
connections:
  - camera.image -> detector.frame
  - detector.mask -> manager.mask
"""


def build(tmp_path, folder: str):
    models = tmp_path / "models"
    models.mkdir()
    (models / "m.yaml").write_text(MODEL.format(folder=folder), encoding="utf-8")
    out = tmp_path / "out" / "deeper"
    write(compile_model(models / "m.yaml", out), out)
    return models, out / "paths.py"


def run(program, cwd):
    return subprocess.run([sys.executable, str(program), "--frames", "2", "-q"], cwd=cwd,
                          capture_output=True, text=True, timeout=300, env=dict(os.environ))


def test_a_relative_folder_is_found_from_any_working_directory(tmp_path):
    require_opencl()
    from PIL import Image

    models, program = build(tmp_path, "shots")
    (models / "shots").mkdir()
    Image.fromarray(np.zeros((16, 24, 3), np.uint8)).save(models / "shots" / "a.png")
    text = program.read_text(encoding="utf-8")
    assert "runtime.model_path(__file__, '../../models/shots')" in text
    assert str(tmp_path) not in text  # no absolute path in generated code
    for cwd in (tmp_path, models, program.parent):
        proc = run(program, cwd)
        assert proc.returncode == 0, proc.stderr


def test_a_missing_folder_is_named_by_the_absolute_path_looked_at(tmp_path):
    require_opencl()
    models, program = build(tmp_path, "nowhere")
    proc = run(program, tmp_path)
    assert proc.returncode == 1
    assert str((models / "nowhere").resolve()) in proc.stderr
    assert "Traceback" not in proc.stderr


def test_absolute_paths_and_devices_are_left_as_written(tmp_path):
    for value, shown in ((str(tmp_path / "abs"), repr(str(tmp_path / "abs"))),
                         ("''", "''")):
        sub = tmp_path / str(abs(hash(value)))
        sub.mkdir()
        _, program = build(sub, value if value != "''" else "''")
        text = program.read_text(encoding="utf-8")
        # the model's value sits in the PARAMS table --set may override
        # (however the program's lines wrap a long path: as one line)
        assert f"runtime.Param('input', {shown})" in re.sub(r"\(\s+", "(", re.sub(
            r",\s+", ", ", text))
        assert "folder=params['camera.folder']" in text
