"""BuildOptions: one record of what a build overrides (issue 23: compile_model took 13
parameters). Keywords make the same record; a name that is no option is refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from gpucompgen.build import compile_model
from gpucompgen.options import BuildOptions, build_options

ROOT = Path(__file__).resolve().parent.parent
VISION = ROOT / "models" / "vision_system.yaml"


def _texts(result) -> list[tuple[str, str]]:
    return [(str(f.path), f.text) for f in result.files]


def test_keywords_and_the_record_build_the_same(tmp_path):
    options = BuildOptions(mode="standard", device="portable", zero_copy="off")
    by_record = compile_model(VISION, tmp_path, options)
    by_keywords = compile_model(VISION, tmp_path, mode="standard", device="portable",
                                zero_copy="off")
    assert _texts(by_record) == _texts(by_keywords)
    # and the options do something: the default build differs
    assert _texts(compile_model(VISION, tmp_path)) != _texts(by_record)


def test_keywords_replace_fields_of_the_record():
    base = BuildOptions(mode="standard", fusion="off")
    assert build_options(base, fusion="auto") == BuildOptions(mode="standard", fusion="auto")
    assert base.fusion == "off"  # the record given is not changed
    assert build_options() == BuildOptions()


def test_an_unknown_option_is_refused(tmp_path):
    with pytest.raises(TypeError):
        compile_model(VISION, tmp_path, fusoin="off")
    with pytest.raises(ValueError):
        compile_model(VISION, tmp_path, mode="fast")
