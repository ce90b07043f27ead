"""Property: whatever text a model file holds, loading it gives a model or the project's
own error (GpucompgenError) with diagnostics, never another exception."""

from __future__ import annotations

import tempfile
from pathlib import Path

from conftest import ROOT
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from gpucompgen.build import compile_model
from gpucompgen.errors import GpucompgenError
from gpucompgen.loader import load_text
from gpucompgen.model import load_system

SEED = (ROOT / "models" / "vision_system.yaml").read_text(encoding="utf-8")
SEED_LINES = SEED.splitlines(keepends=True)
TOKENS = ["{", "}", "[", "]", ":", ": ", "- ", "&a ", "*a", "<<: ", "!!python/name:os.system",
          "!x ", "|", ">", "'", '"', "#", "\t", "\n", "  ", "? ", ",", "...", "---", "%YAML 1.1",
          "~", "null", "no", "on", "010", "0x1F", ".inf", ".nan", "1e999", "2001-13-45",
          "9" * 30, "-1", "0", "type", "params", "components", "connections", "platform",
          "device", "gpu_settings", "{tile: 0}", "[1, 2]", "x'); import os; ('", "\x07", "é",
          "\ufeff", "\u2028", "->", ".", "camera1.image", "ImageMerger", "types: [x.yaml]",
          "types: [../../etc/passwd]", "device: {profile: [1]}", "type: [a]",
          # escapes in double-quoted strings that decode to characters YAML forbids raw
          '"\\x07"', '"\\e"', '"\\0"', '"\\ud800"', '"a\\x85b"', "1:00", "0b101", "1_000"]

@st.composite
def mutated(draw) -> str:
    lines = list(SEED_LINES)
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        op = draw(st.sampled_from(["delete", "duplicate", "swap", "insert", "token", "chars"]))
        if not lines:
            lines = [""]
        i = draw(st.integers(min_value=0, max_value=len(lines) - 1))
        line = lines[i]
        if op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(draw(st.integers(min_value=0, max_value=len(lines))), line)
        elif op == "swap" and len(line) > 1:
            k = draw(st.integers(min_value=0, max_value=len(line) - 2))
            lines[i] = line[:k] + line[k + 1] + line[k] + line[k + 2:]
        elif op == "insert":
            k = draw(st.integers(min_value=0, max_value=len(line)))
            lines[i] = line[:k] + draw(st.text(max_size=8)) + line[k:]
        elif op == "token":
            k = draw(st.integers(min_value=0, max_value=len(line)))
            lines[i] = line[:k] + draw(st.sampled_from(TOKENS)) + line[k:]
        elif op == "chars":
            k = draw(st.integers(min_value=0, max_value=len(line)))
            n = draw(st.integers(min_value=0, max_value=6))
            lines[i] = line[:k] + draw(st.text(max_size=4)) + line[k + n:]
    return "".join(lines)


texts = st.one_of(
    mutated(),
    st.text(max_size=200),
    st.lists(st.sampled_from(TOKENS), max_size=30).map("".join),
)

FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@FUZZ
@given(texts)
@example(SEED)
@example("")
@example("[" * 100)
@example("a: &x 1\nb: *x\n")
@example('description: "a\\x07b\\e\\0"\n')  # once an internal error: ReaderError
@example('a: "\\ud800"\n')
@example("system: s\ncomponents: {a: {type: [1]}}\n")
def test_load_text_returns_a_document_or_our_error(text):
    try:
        load_text(text, "m.yaml")
    except GpucompgenError as exc:
        assert exc.diagnostics and all(d.file == "m.yaml" for d in exc.diagnostics)


@FUZZ
@given(texts)
@example(SEED)
@example("system: s\nplatform: {device: {profile: [1]}}\ncomponents: {a: Camera}\n")
@example("system: s\ncomponents:\n  a: {type: ImageMerger}\n  b: {type: [x]}\n")
def test_load_system_returns_a_model_or_our_error(text):
    """Also through the passes and rendering: a model that loads compiles or is refused."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model.yaml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        try:
            model = load_system(path, "model.yaml")
            assert model.components, "a loaded model has components"
            result = compile_model(path, Path(tmp) / "out", display="model.yaml")
        except GpucompgenError as exc:
            assert exc.errors, "raised without an error"
            return
        assert result.files and not result.files[0].text.startswith(" ")


# -- the fast reading (libyaml) gives what the reference reading (pure Python) gives ------
def _same_document(fast, reference) -> None:
    assert repr(fast.data) == repr(reference.data)  # repr: .nan equals .nan
    assert fast.positions == reference.positions
    assert fast.key_positions == reference.key_positions
    assert fast.sources == reference.sources


@FUZZ
@given(st.one_of(texts, st.text(alphabet=st.characters(max_codepoint=127), max_size=200))
       .map(lambda t: t.encode("ascii", "ignore").decode("ascii")))
@example(SEED)
@example("a: 'it''s'\nb: \"x\\ty\"\nc: |\n  two\n  lines\nd: >-\n  folded\n  text\n")
@example("a:\r\n  - 1\r\n  - {b: c}\r\nd: e\r")
@example("a: b\n---\nc: d\n")
@example("a: {b: }\nc:\nd: [e, ]\n")  # empty values: libyaml places them a column on
def test_the_fast_reading_gives_the_reference_document(text):
    """The library's files are read with libyaml: wherever it and the pure-Python reading
    (which writes every message) both accept a text, they read the same data, the
    position of every value and key, and every string as written.  (libyaml accepts a
    few texts the pure-Python parser refuses, '0\\t' and '|#': a user's file is never
    read by it.)"""
    from gpucompgen.loader import _fast

    fast = _fast(text, "m.yaml")
    if fast is None:
        return
    try:
        reference = load_text(text, "m.yaml")
    except GpucompgenError:
        return
    _same_document(fast, reference)


def test_every_yaml_file_of_the_project_is_read_fast_and_the_same():
    """The library's type files, the example models and the tests' models: every one the
    reference reading accepts is read by libyaml (the speed every command relies on) to
    the same Document."""
    from gpucompgen.loader import _fast

    fast_read = 0
    for path in sorted(ROOT.glob("**/*.yaml")):
        if any(part.startswith(".") for part in path.relative_to(ROOT).parts):
            continue  # .venv, a developer's hidden copies
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:  # a bad model of the tests
            continue
        try:
            reference = load_text(text, path.name)
        except GpucompgenError:
            continue
        if not text.isascii():
            continue
        fast = _fast(text, path.name)
        if fast is None:  # an empty value, say: a test's model may need the slow reading
            assert path.parts[-3:-1] != ("gpucompgen", "library") \
                and path.parent.name != "models", f"{path} is read by the slow reading"
            continue
        _same_document(fast, reference)
        fast_read += 1
    assert fast_read > 40
