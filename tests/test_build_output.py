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
    with pytest.raises(build_mod.OutputError, match="No space left on device"):
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
    assert proc.returncode == 2, proc.stderr  # an output problem: a usage error
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
    # merger and detector are fused: the merged frame is never in memory, and check says so
    assert "merger.merged: 480x1280x3 uint8 (fused: no buffer)" in proc.stdout
    assert "merger.merged: 480x1280x3 uint8\n" in _gpucompgen("check", MODEL, "--fusion", "off",
                                                              cwd=tmp_path).stdout
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


@pytest.mark.parametrize("case,message", [
    ("output-is-a-file", "gpucompgen build: error: output folder {out} is a file"),
    ("program-is-a-folder", "gpucompgen build: error: {out}/vision_system.py is a folder, "
                            "where the program would go"),
    ("lib-is-a-file", "gpucompgen build: error: {out}/vision_system_lib is a file, where the "
                      "kernels folder would go"),
])
def test_an_output_path_that_cannot_be_written_is_a_usage_error(tmp_path, case, message):
    out = tmp_path / "gen"
    if case == "output-is-a-file":
        out.write_text("mine")
    else:
        out.mkdir()
        if case == "program-is-a-folder":
            (out / "vision_system.py").mkdir()
        else:
            (out / "vision_system_lib").write_text("mine")
    before = _snapshot(tmp_path)
    proc = _gpucompgen("build", MODEL, "-o", out, "--overwrite")
    assert proc.returncode == 2
    assert message.format(out=out) in proc.stderr
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    assert _snapshot(tmp_path) == before
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(
        p.name for p in tmp_path.rglob("*") if not p.name.startswith("."))  # no staging left


def test_a_failing_final_rename_puts_the_old_output_back(tmp_path, monkeypatch):
    """The lib folder is replaced first; if the program cannot follow, the old lib returns."""
    out = tmp_path / "gen"
    write(compile_model(MODEL, out), out)
    before = _snapshot(out)
    result = compile_model(MODEL, out)
    kernel = result.files[1]  # a kernel file: the lib folder differs
    result.files[1] = type(kernel)(kernel.path, kernel.text + "// changed\n")
    real_replace = build_mod.os.replace

    def failing_replace(src, dst):
        if Path(dst).name == "vision_system.py":
            raise PermissionError(13, "Permission denied")
        return real_replace(src, dst)

    monkeypatch.setattr(build_mod.os, "replace", failing_replace)
    with pytest.raises(build_mod.OutputError, match="cannot write into .*: Permission denied"):
        write(result, out)
    assert _snapshot(out) == before
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("target", ["missing/x.dot", "missing/x.svg"])
def test_graph_into_a_missing_folder_is_a_usage_error(tmp_path, target):
    proc = _gpucompgen("graph", MODEL, "-o", tmp_path / target)
    assert proc.returncode == 2
    assert f"cannot write {tmp_path / target}: folder {tmp_path / 'missing'} does not exist" \
        in proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_generated_program_that_would_not_compile_is_refused_before_writing(tmp_path,
                                                                           monkeypatch):
    """The names checks are the first defence; compiling the program is the last."""
    real_renderer = build_mod.renderer

    def broken_render(system, source, *args):
        files = real_renderer("opencl")(system, source, *args)
        program = files[0]
        files[0] = type(program)(program.path,
                                 program.text.replace("def run(", "def run(frames, frames, ", 1))
        return files

    monkeypatch.setattr(build_mod, "renderer", lambda backend: broken_render)
    with pytest.raises(RuntimeError, match="generated program does not compile: duplicate "
                                           "argument 'frames'"):
        compile_model(MODEL, tmp_path / "gen")
    assert not (tmp_path / "gen").exists()
