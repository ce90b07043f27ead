"""Output problems on the command line are usage errors (exit 2) with a clear message, never
an internal error; what the user typed is shown escaped; -q prints nothing but errors."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest
from conftest import ROOT, require_opencl


def gpucompgen(*args, cwd=ROOT, stdout=subprocess.PIPE):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "gpucompgen", *map(str, args)], cwd=cwd,
                          stdout=stdout, stderr=subprocess.PIPE, text=True, check=False,
                          env=env)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
@pytest.mark.parametrize("args", [["schema"], ["schema", "--types"], ["types"],
                                  ["types", "InRange"], ["check", "models/red_objects.yaml"],
                                  ["plan", "models/vision_system.yaml"]])
def test_a_full_standard_output_is_an_output_error(args):
    with open("/dev/full", "w") as full:
        proc = gpucompgen(*args, stdout=full)
    assert proc.returncode == 2, proc.stderr
    # (check notes the red-objects model's deprecated names on stderr first)
    assert proc.stderr.strip().splitlines()[-1] == f"gpucompgen {args[0]}: error: cannot " \
        "write the output: No space left on device"


@pytest.mark.parametrize("name", ["Foo\x1b[31mRed", "Two\nLines", "Tab\there"])
def test_types_shows_an_unknown_name_escaped_on_one_line(name):
    proc = gpucompgen("types", name)
    assert proc.returncode == 1
    first = proc.stderr.splitlines()[0]
    assert first == f"gpucompgen types: error: no component type {name!r} in the library"
    assert "\x1b" not in proc.stderr and len(proc.stderr.splitlines()) == 2


@pytest.mark.parametrize("flag", ["--stats-json", "--decisions", "--save-images"])
def test_an_empty_file_name_is_refused_as_empty(flag):
    proc = gpucompgen("run", "models/vision_system.yaml", "--frames", "1", flag, "")
    assert proc.returncode == 2
    assert f"argument {flag}: an empty name; name a file" in proc.stderr
    assert "is a folder" not in proc.stderr


WARNER = textwrap.dedent("""\
    import numpy as np


    class Warner:
        def initialize(self, size):
            return size

        def execute(self, image):
            np.float32(1) / np.float32(0)  # numpy's RuntimeWarning: divide by zero
            return image

        def free_memory(self):
            pass
    """)


def test_quiet_prints_no_warnings(tmp_path):
    require_opencl()
    (tmp_path / "warner.py").write_text(WARNER)
    (tmp_path / "t.yaml").write_text(textwrap.dedent("""\
        component_types:
          Warner:
            kind: standard
            inputs:
              image: {memory: cpu, channels: 3}
            outputs:
              out: {memory: cpu, channels: 3, height: image.height, width: image.width}
            python: {file: warner.py, class: Warner}
        """))
    (tmp_path / "m.yaml").write_text(
        "system: s\ntypes: [t.yaml]\ncomponents:\n"
        "  src: {type: StillImage, params: {width: 8, height: 8}}\n  w: Warner\n"
        "  sink: FrameSink\nconnections: [src.image -> w.image, w.out -> sink.image]\n")
    loud = gpucompgen("run", "m.yaml", "--frames", "2", cwd=tmp_path)
    assert loud.returncode == 0 and "RuntimeWarning" in loud.stderr, loud.stderr
    quiet = gpucompgen("run", "m.yaml", "--frames", "2", "-q", cwd=tmp_path)
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stderr == "" and quiet.stdout == ""
