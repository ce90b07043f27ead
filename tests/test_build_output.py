"""The tool owns its output: nothing written for a bad model, all-or-nothing writes, and
no overwriting of files it did not generate unless --overwrite."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

from gpucompgen import build as build_mod
from gpucompgen.build import compile_model, write

MODEL = ROOT / "models" / "vision_system.yaml"


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _gpucompgen(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "gpucompgen", *map(str, args)], check=False,
                          capture_output=True, text=True, cwd=cwd)


def test_a_bad_model_leaves_existing_output_untouched(tmp_path):
    out = tmp_path / "gen"
    write(compile_model(MODEL, out), out)
    before = _snapshot(out)
    bad = tmp_path / "vision_system.yaml"
    bad.write_text(MODEL.read_text().replace("type: ImageMerger", "type: Nope"))
    proc = _gpucompgen("build", bad, "-o", out)
    assert proc.returncode == 1 and "unknown component type 'Nope'" in proc.stderr
    assert _snapshot(out) == before


def test_a_failed_write_keeps_the_old_output_and_leaves_no_staging(tmp_path, monkeypatch):
    out = tmp_path / "gen"
    write(compile_model(MODEL, out), out)
    before = _snapshot(out)
    result = compile_model(MODEL, out)
    result.files[-1] = type(result.files[-1])(result.files[-1].path, "changed\n")
    real = Path.write_text
    calls = []

    def failing(self, *args, **kwargs):
        calls.append(self)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", failing)
    with pytest.raises(OSError):
        build_mod.write(result, out)
    monkeypatch.undo()
    assert _snapshot(out) == before
    assert sorted(p.name for p in out.iterdir()) == ["vision_system.py", "vision_system_lib"]


def test_refuses_a_foreign_file_in_the_lib_folder(tmp_path):
    out = tmp_path / "gen"
    write(compile_model(MODEL, out), out)
    mine = out / "vision_system_lib" / "notes.txt"
    mine.write_text("my notes\n")
    proc = _gpucompgen("build", MODEL, "-o", out)
    assert proc.returncode == 1, proc.stderr
    assert "refusing to overwrite 1 file(s) that gpucompgen did not generate" in proc.stderr
    assert "--overwrite" in proc.stderr and "Traceback" not in proc.stderr
    assert mine.read_text() == "my notes\n"
    assert _gpucompgen("build", MODEL, "-o", out, "--overwrite").returncode == 0
    assert not mine.exists(), "--overwrite replaces the whole lib folder"


def test_check_writes_nothing_and_exits_by_severity(tmp_path):
    proc = _gpucompgen("check", MODEL, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "3 adapters will be inserted" in proc.stdout
    assert "adapter3_gpu2cpu: detector.mask -> manager.mask (480x1280x1 uint8" in proc.stdout
    assert "merger.merged: 480x1280x3 uint8" in proc.stdout
    assert list(tmp_path.iterdir()) == []
    warn = tmp_path / "w.yaml"
    warn.write_text(MODEL.read_text().replace("  - detector.mask -> manager.mask\n", "")
                    .replace("  manager: {type: VisionManager, params: {stop_radius: 60}}\n", ""))
    proc = _gpucompgen("check", warn)
    assert proc.returncode == 0 and "warning: output 'detector.mask' is not connected" in \
        proc.stderr
    assert _gpucompgen("check", warn, "--strict").returncode == 1
    for args in (["check"], ["check", tmp_path], ["check", tmp_path / "missing.yaml"],
                 ["check", MODEL, "--bogus"]):
        proc = _gpucompgen(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "Traceback" not in proc.stderr
