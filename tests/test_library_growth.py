"""A library that can grow: a type the library adds never makes a valid model invalid.

A user's own type named like a library type is the one their model gets (``check`` notes
the shadowing); the library's stays reachable as ``lib.Name``.  The corpus test gives the
library, at once, a type of every name each model's own type files declare and of every
component name, and demands the same generated files as before.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from gpucompgen import model as model_mod
from gpucompgen.build import compile_model
from gpucompgen.errors import GpucompgenError
from gpucompgen.loader import FileProblem, read_text, starts_with_key
from gpucompgen.model import types as model_types
from gpucompgen.names import fold

ROOT = Path(__file__).resolve().parent.parent


def corpus() -> list[Path]:
    """Every model under models/ and tests/ that names a type file of its own."""
    found = []
    for path in sorted([*ROOT.glob("models/**/*.y*ml"), *ROOT.glob("tests/**/*.y*ml")]):
        try:
            text = read_text(path, 1 << 18)
        except FileProblem:
            continue
        if starts_with_key(text, "system") and "\ntypes:" in text:
            found.append(path)
    return found


def _files(path: Path):
    try:
        result = compile_model(path, path.parent / "generated")
    except GpucompgenError:
        return None  # a bad model stays out of the corpus (it is tested for its errors)
    return result, [(str(f.path), f.text) for f in result.files]


@pytest.fixture
def grown_library(monkeypatch):
    """A function that gives the library extra types of the given names (each a copy of a
    library type under that name), for the rest of the test."""
    original = model_mod.library_types()

    def grow(names):
        library = dict(original)
        base = library["AbsDiff"]
        folded = {fold(n) for n in library}
        for name in names:
            if fold(name) not in folded:
                folded.add(fold(name))
                library[name] = dataclasses.replace(base, name=name)
        monkeypatch.setattr(model_types, "_LIBRARY_CACHE", library)
    return grow


def type_files() -> list[Path]:
    found = []
    for path in sorted([*ROOT.glob("models/**/*.y*ml"), *ROOT.glob("tests/**/*.y*ml")]):
        try:
            if starts_with_key(read_text(path, 1 << 18), "component_types"):
                found.append(path)
        except FileProblem:
            continue
    return found


def test_a_library_type_of_any_name_a_model_uses_changes_nothing(grown_library):
    """Every valid model of the corpus builds to the same files with a library that has a
    type of each name of its own types and components (and their case variants)."""
    checked = 0
    for path in corpus():
        grown_library([])
        before = _files(path)
        if before is None:
            continue  # a bad model (tested for its errors)
        result, files = before
        own = [t.name for t in result.system.model.types.values() if t.origin == "user"]
        names = own + list(result.system.model.components)
        grown_library(names + [n.lower() for n in names] + [n.upper() for n in names])
        after = _files(path)
        assert after is not None, f"{path}: a library grown by {sorted(names)} broke it"
        assert after[1] == files, path
        shadowed = {n.message.split("'")[1] for n in after[0].system.model.notes}
        assert set(own) <= shadowed, path
        checked += 1
    assert checked >= 3


def test_every_type_file_still_loads_when_the_library_has_its_names(tmp_path, grown_library):
    """Each user type file of the corpus, in a model that lists it: what loads today loads
    with a library that has a type of each of its names (and their case variants)."""
    checked = 0
    model = tmp_path / "m.yaml"
    for path in type_files():
        grown_library([])
        model.write_text(f"system: s\ntypes: [{path.as_posix()}]\ncomponents:\n"
                         "  camera1: {type: Camera, params: {width: 16, height: 16}}\n")
        try:
            before = model_mod.load_system(model)
        except GpucompgenError:
            continue  # a bad type file (tested for its errors)
        own = [t.name for t in before.types.values() if t.origin == "user"]
        grown_library(own + [n.lower() for n in own] + [n.upper() for n in own])
        after = model_mod.load_system(model)
        assert {n: t.origin for n, t in after.types.items() if t.origin == "user"} == \
            {n: "user" for n in own}, path
        checked += 1
    assert checked >= 10


TYPES = textwrap.dedent("""\
    component_types:
      AbsDiff:
        kind: standard
        description: my own AbsDiff, written before the library had one
        inputs:
          a: {memory: cpu, channels: 3}
        outputs:
          o: {memory: cpu, channels: 3, height: a.height, width: a.width}
        python: {file: mine.py, class: MyAbsDiff}
    """)

MINE = "class MyAbsDiff:\n    def process(self, a):\n        return {'o': a}\n"


def _project(tmp_path: Path, components: str) -> Path:
    (tmp_path / "t.yaml").write_text(TYPES)
    (tmp_path / "mine.py").write_text(MINE)
    model = tmp_path / "m.yaml"
    model.write_text("system: s\ntypes: [t.yaml]\ncomponents:\n" + textwrap.indent(
        textwrap.dedent(components), "  "))
    return model


def gpucompgen(*args, cwd):
    return subprocess.run([sys.executable, "-m", "gpucompgen", *args], cwd=cwd,
                          capture_output=True, text=True, check=False)


def test_own_type_shadows_the_library_and_check_notes_it(tmp_path):
    _project(tmp_path, """\
        camera1: {type: Camera, params: {width: 16, height: 16}}
        diff: AbsDiff
        connections_are_below: {type: FrameSink}
        """)
    (tmp_path / "m.yaml").write_text((tmp_path / "m.yaml").read_text().replace(
        "  connections_are_below: {type: FrameSink}\n",
        "  sink: FrameSink\nconnections:\n  - camera1.image -> diff.a\n"
        "  - diff.o -> sink.image\n"))
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "t.yaml:2:3: note: component type 'AbsDiff' shadows the library's 'AbsDiff'" \
        in proc.stderr
    assert "hint: the model gets this file's 'AbsDiff'; write 'lib.AbsDiff' for the " \
        "library's" in proc.stderr
    assert "warning" not in proc.stderr
    assert gpucompgen("check", "--strict", "m.yaml", cwd=tmp_path).returncode == 0
    model = model_mod.load_system(tmp_path / "m.yaml")
    assert model.components["diff"].type.origin == "user"
    assert model.components["diff"].type.python_class == "MyAbsDiff"


def test_the_library_type_stays_reachable_by_its_qualified_name(tmp_path):
    model = _project(tmp_path, "d: lib.AbsDiff\n")
    loaded = model_mod.load_system(model)
    assert loaded.components["d"].type is model_mod.library_types()["AbsDiff"] or \
        loaded.components["d"].type.origin == "library"
    proc = gpucompgen("types", "lib.AbsDiff", cwd=tmp_path)
    assert proc.returncode == 0 and "AbsDiff" in proc.stdout, proc.stderr
    proc = gpucompgen("types", "--model", "m.yaml", "AbsDiff", cwd=tmp_path)
    assert "my own AbsDiff" in proc.stdout
    proc = gpucompgen("types", "--model", "m.yaml", "lib.AbsDiff", cwd=tmp_path)
    assert proc.returncode == 0 and "my own AbsDiff" not in proc.stdout
    listed = gpucompgen("types", "--model", "m.yaml", cwd=tmp_path).stdout.splitlines()
    assert any(line.split()[:2] == ["lib.AbsDiff", "flexible"] for line in listed)
    assert any(line.split()[:2] == ["AbsDiff", "standard"] for line in listed)


def test_a_case_variant_of_a_library_name_shadows_it_too(tmp_path):
    (tmp_path / "t.yaml").write_text(TYPES.replace("AbsDiff:", "abs_diff:"))
    (tmp_path / "mine.py").write_text(MINE)
    (tmp_path / "m.yaml").write_text("system: s\ntypes: [t.yaml]\ncomponents:\n  d: abs_diff\n")
    loaded = model_mod.load_system(tmp_path / "m.yaml")
    assert "AbsDiff" not in loaded.types and loaded.types["abs_diff"].origin == "user"
    assert [n.message for n in loaded.notes] == [
        "component type 'abs_diff' shadows the library's 'AbsDiff'"]


def test_two_own_types_of_one_name_are_still_refused(tmp_path):
    (tmp_path / "t.yaml").write_text(TYPES)
    (tmp_path / "u.yaml").write_text(TYPES.replace("AbsDiff:", "Abs_Diff:"))
    (tmp_path / "mine.py").write_text(MINE)
    (tmp_path / "m.yaml").write_text("system: s\ntypes: [t.yaml, u.yaml]\ncomponents:\n"
                                     "  d: AbsDiff\n")
    with pytest.raises(GpucompgenError, match="'Abs_Diff' is already defined elsewhere as "
                                              "'AbsDiff'"):
        model_mod.load_system(tmp_path / "m.yaml")


def test_the_schema_accepts_the_qualified_name():
    import json

    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads((ROOT / "gpucompgen" / "schema" / "model.schema.json").read_text())
    for name, valid in (("lib.AbsDiff", True), ("AbsDiff", True), ("lib.", False),
                        ("other.AbsDiff", False)):
        for written in (name, {"type": name}):
            errors = list(jsonschema.Draft202012Validator(schema).iter_errors(
                {"system": "s", "components": {"d": written}}))
            assert (not errors) == valid, (name, errors)
