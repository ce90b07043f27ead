"""File-level failures of the loader become GpucompgenError with the file and a position."""

from __future__ import annotations

import pytest

from gpucompgen.errors import GpucompgenError, Reporter
from gpucompgen.loader import MAX_FILE_BYTES, load_file, load_text
from gpucompgen.model import load_system, load_types_file


def _error(fn, *args) -> str:
    with pytest.raises(GpucompgenError) as info:
        fn(*args)
    assert info.value.errors
    return str(info.value)


def test_file_problems(tmp_path):
    assert _error(load_file, tmp_path / "nope.yaml", "nope.yaml") == (
        "nope.yaml: error: file not found\n  hint: check the path")
    assert "is a directory" in _error(load_file, tmp_path, "dir")
    big = tmp_path / "big.yaml"
    big.write_text("a: 1\n" * (MAX_FILE_BYTES // 5 + 1))
    assert f"larger than {MAX_FILE_BYTES:,} bytes" in _error(load_file, big, "big.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"a: 1\nb: \xff\n")
    assert _error(load_file, bad, "bad.yaml").startswith(
        "bad.yaml:2:4: error: file is not UTF-8 text: byte 0xff")


def test_empty_files(tmp_path):
    assert load_text("", "e.yaml").data is None
    empty = tmp_path / "e.yaml"
    empty.write_text("")
    assert _error(load_system, empty, "e.yaml").startswith("e.yaml:1:1: error: the model is empty")
    assert "the component-type file is empty" in _error(
        lambda: (rep := Reporter(), load_types_file(empty, "e.yaml", "user", rep),
                 rep.raise_if_errors()))


def test_a_byte_order_mark_is_accepted():
    assert load_text("\ufeffsystem: s\n", "m.yaml").data == {"system": "s"}


def test_positions_are_kept():
    doc = load_text("system: s\ncomponents:\n  cam: {type: Camera}\n", "m.yaml")
    assert (doc.pos("components", "cam", "type").line, doc.pos("components", "cam",
                                                               "type").col) == (3, 15)
    assert (doc.key_pos("components", "cam").line, doc.key_pos("components", "cam").col) == (3, 3)
