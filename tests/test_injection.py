"""Free text from a model (descriptions, string parameters, device names, the model's own
file name) is legal, but reaches the generated program only inside string literals and
comments: building succeeds, and importing or compiling the program runs none of it."""

from __future__ import annotations

import io
import shutil
import tokenize

from conftest import ROOT, load_generated

from gpucompgen.build import compile_model, write

MARK = "PWNED"
# Each payload tries to end the literal or comment it lands in and run code.
PAYLOADS = [
    f'"""\nopen("{MARK}_1", "w").close()\n"""',
    f"'); open('{MARK}_2', 'w').close(); ('",
    f"\nopen('{MARK}_3', 'w').close()\n#",
    f"\\\nopen('{MARK}_4', 'w').close()",
    f"\r\nopen('{MARK}_5', 'w').close()\u2028open('{MARK}_6', 'w').close()",
    f"*/ {MARK}_7 /*\n{MARK}_8();",
]


def _yaml_str(text: str) -> str:
    """A YAML double-quoted string (JSON escaping is valid YAML)."""
    import json

    return json.dumps(text)


def _model(tmp_path, payload: str, file_name: str = "evil.yaml"):
    src = ROOT / "tests" / "data" / "user_model"
    for name in ("brighten.cl", "probe.py"):
        shutil.copy(src / name, tmp_path / name)
    types = (src / "my_types.yaml").read_text(encoding="utf-8").replace(
        "description: Adds gain to every channel, saturating at 255.",
        f"description: {_yaml_str(payload)}")
    assert payload[:5] in types or _yaml_str(payload)[:5] in types
    (tmp_path / "my_types.yaml").write_text(types, encoding="utf-8")
    model = tmp_path / file_name
    model.write_text(f"""\
system: evil
description: {_yaml_str(payload)}
types: [my_types.yaml]
platform:
  device: {{profile: pocl-cpu, name: {_yaml_str(payload)}}}
components:
  camera: {{type: Camera, params: {{width: 32, height: 16, folder: {_yaml_str(payload)}}}}}
  brighten: {{type: Brighten, description: {_yaml_str(payload)}}}
  probe: {{type: MeanProbe}}
connections:
  - camera.image -> brighten.image
  - brighten.brighter -> probe.image
""", encoding="utf-8")
    return model


def _check_program(text: str) -> None:
    compile(text, "evil.py", "exec")
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if MARK in tok.string:
            assert tok.type in (tokenize.STRING, tokenize.COMMENT), (
                f"model text became code at line {tok.start[0]}: {tok.line!r}")


def _check_kernel(text: str) -> None:
    # a kernel file gets only the header from the generator: the rest is the user's kernel
    for line in text.splitlines():
        if MARK in line:
            assert line.startswith("// "), line


def test_free_text_stays_in_literals_and_comments(tmp_path, monkeypatch):
    for i, payload in enumerate(PAYLOADS):
        folder = tmp_path / f"case{i}"
        folder.mkdir()
        # the model file's own name is free text too (it is written in every header)
        name = "evil.yaml" if i % 2 else f"evil\nopen('{MARK}_name', 'w').close()\n.yaml"
        model = _model(folder, payload, name)
        out = folder / "out"
        result = compile_model(model, out)
        write(result, out)
        program = (out / "evil.py").read_text(encoding="utf-8")
        assert program.count(MARK) >= 3, "the payloads reach the program (as text)"
        _check_program(program)
        for kernel in (out / "evil_lib").glob("*.cl"):
            _check_kernel(kernel.read_text(encoding="utf-8"))
        # importing the program runs its module level; nothing of the payload may run
        monkeypatch.chdir(folder)
        module = load_generated(out / "evil.py", f"evil_under_test_{i}")
        assert module.DESCRIPTION == payload
        assert not list(folder.glob(f"{MARK}*")), "a payload ran on import"
