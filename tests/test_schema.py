"""The shipped JSON Schemas agree with the loader: checked-in files validate, YAML 1.1
surprises fail, and the keys the schemas allow are the keys the loader allows."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest
import yaml
from conftest import ROOT

from gpucompgen import fusable, model
from gpucompgen.device import FACT_KEYS, PROFILES
from gpucompgen.schema import MODEL, TYPES, schema

MODEL_FILES = sorted((ROOT / "models").glob("*.yaml")) + [
    ROOT / "tests" / "data" / "user_model" / "bright.yaml"]
TYPE_FILES = sorted((ROOT / "gpucompgen" / "library").glob("*.yaml")) + [
    ROOT / "tests" / "data" / "user_model" / "my_types.yaml",
    ROOT / "tests" / "bad_models" / "types" / "helpers.yaml",
    ROOT / "tests" / "bad_models" / "types" / "clash.yaml"]


def validator(name):
    s = schema(name)
    jsonschema.Draft202012Validator.check_schema(s)
    return jsonschema.Draft202012Validator(s)


def _errors(name, data):
    return sorted(e.message for e in validator(name).iter_errors(data))


@pytest.mark.parametrize("path", MODEL_FILES + TYPE_FILES, ids=lambda p: p.name)
def test_checked_in_files_validate_and_name_their_schema(path):
    which = MODEL if path in MODEL_FILES else TYPES
    first = path.read_text(encoding="utf-8").splitlines()[0]
    m = re.fullmatch(r"# yaml-language-server: \$schema=(\S+)", first)
    assert m, f"{path.name} does not start with the yaml-language-server modeline"
    assert (path.parent / m[1]).resolve() == (ROOT / "gpucompgen" / "schema" / which).resolve()
    assert _errors(which, yaml.safe_load(path.read_text(encoding="utf-8"))) == []


@pytest.mark.parametrize("text", [
    "system: no", "system: on", "system: 010", "system: 1.5", "system: 'a b'",
    "system: class_ok\nextra: 1", "system: s\ncomponents: {'no': Camera}\nbad: 1", "system: s\ncomponents: {a: {type: Camera, parms: {}}}",
    "system: s\ncomponents: {a: Camera}\nconnections: ['a.image => b.in']",
    "system: s\ncomponents: {a: Camera}\nplatform: {device: portabel}",
    "system: s\ncomponents: {a: Camera}\nplatform: {gpu_settings: {a: {tile: 0}}}",
    "system: s\ncomponents: {'../x': Camera}",
    "system: s\ncomponents: {a: 'yes'}\ndescription: no",
])
def test_schema_rejects_bad_models(text):
    assert _errors(MODEL, yaml.safe_load(text)), text


def test_schema_rejects_yaml_1_1_surprises_for_names():
    base = {"system": "s", "components": {"a": {"type": "Camera"}}}
    for value in (False, True, 8, 1.5, None, "x'); import os; ('", "a\nimport os"):
        assert _errors(MODEL, dict(base, system=value)), value
        assert _errors(MODEL, dict(base, components={"a": {"type": value}})), value


def test_schema_rejects_the_bad_type_file_of_the_bad_models():
    bad = ROOT / "tests" / "bad_models" / "types" / "bad_types.yaml"
    assert len(_errors(TYPES, yaml.safe_load(bad.read_text(encoding="utf-8")))) >= 3


def test_schema_and_loader_agree_on_array_parameter_types():
    """The schema's pattern for array types takes what the loader takes, and refuses the
    same shapes (bad element type, no dimension, four dimensions)."""
    import re

    # a type's entry: 'else' of the schema's alias test (an alias has no params)
    entry = schema(TYPES)["properties"]["component_types"]["additionalProperties"]["else"]
    pattern = re.compile(entry["properties"]["params"]["additionalProperties"]["oneOf"][0]
                         ["anyOf"][1]["pattern"])
    for text, fine in (("int[256]", True), ("float[2][3]", True), ("int[3..64][2]", True),
                       ("bool[3]", False), ("int", False), ("int[]", False),
                       ("int[1][2][3][4]", False), ("int[-1]", False), ("float[2 ]", False)):
        assert bool(pattern.search(text)) == fine, text
        assert bool(model.ARRAY_TYPE.fullmatch(text)) == fine, text


def test_schema_rejects_bad_types():
    good = yaml.safe_load((ROOT / "tests/data/user_model/my_types.yaml").read_text())
    assert _errors(TYPES, good) == []
    brighten = good["component_types"]["Brighten"]
    for change in ({"kind": "gpu"}, {"python": {"file": "x.py"}},
                   {"inputs": {"image": {"dtype": "float64"}}},
                   {"outputs": {"o": {"channels": 0}}}, {"kernel": {"file": "k.c"}},
                   {"params": {"gain": "integer"}}, {"gpu": {"tiles": []}}):
        bad = {"component_types": {"Brighten": dict(brighten, **change)}}
        assert _errors(TYPES, bad), change


def test_schema_keys_agree_with_the_loader():
    m = schema(MODEL)["properties"]
    assert set(m) == set(model.SYSTEM_KEYS)
    assert set(m["platform"]["properties"]) == set(model.PLATFORM_KEYS)
    device = m["platform"]["properties"]["device"]["oneOf"]
    assert set(device[0]["enum"]) == set(PROFILES) | {"auto"}
    assert set(device[1]["properties"]) == set(FACT_KEYS) | {"profile"}
    setting = m["platform"]["properties"]["gpu_settings"]["additionalProperties"]
    assert tuple(setting["properties"]) == model.SETTING_KEYS
    inst = m["components"]["additionalProperties"]["oneOf"][1]["properties"]
    assert set(inst) == set(model.INSTANCE_KEYS)
    named = schema(TYPES)["properties"]["component_types"]["additionalProperties"]
    t, alias = named["else"], named["then"]  # a type, or a deprecated alias of one
    assert set(alias["properties"]) == set(model.ALIAS_KEYS)
    assert set(t["properties"]) == set(model.TYPE_KEYS)
    assert set(t["properties"]["kind"]["enum"]) == set(model.KINDS)
    out = t["properties"]["outputs"]["additionalProperties"]["properties"]
    assert set(out) == set(model.PORT_KEYS)
    assert set(out["dtype"]["oneOf"][0]["enum"]) == set(model.DTYPES)
    assert set(out["memory"]["enum"]) == set(model.MEMORIES)
    param = t["properties"]["params"]["additionalProperties"]["oneOf"]
    assert set(param[0]["anyOf"][0]["enum"]) == set(model.PARAM_TYPES)
    assert param[0]["anyOf"][1]["pattern"] == f"^{model.ARRAY_TYPE_PATTERN}$"
    assert set(param[1]["properties"]) == set(model.PARAM_KEYS)
    name = m["system"]
    from gpucompgen.names import MAX_NAME, NAME_RE
    assert name["maxLength"] == MAX_NAME
    assert name["pattern"].strip("^$") == NAME_RE.pattern.removesuffix("\\Z")


@pytest.mark.parametrize("args,which", [([], MODEL), (["--types"], TYPES)])
def test_schema_command_prints_the_shipped_schema(args, which):
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "schema", *args], check=False,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == (ROOT / "gpucompgen" / "schema" / which).read_text(encoding="utf-8")
    assert Path(ROOT / "pyproject.toml").read_text().count('"gpucompgen.schema" = ["*.json"]') == 1


def test_checked_in_schemas_are_the_generated_ones():
    """The schemas are generated from the loader's key tables and enums (one declaration):
    after changing the language, run ``python -m gpucompgen.schema.generate --write``."""
    from gpucompgen.schema import generate

    for name, text in generate.generated().items():
        assert (ROOT / "gpucompgen" / "schema" / name).read_text(encoding="utf-8") == text, name
    assert generate.main([]) == 0


def test_the_generator_refuses_keys_the_loader_does_not_declare():
    from gpucompgen.schema import generate

    with pytest.raises(ValueError, match="disagree on keys"):
        generate._object(("a", "b"), {"a": {}})
    with pytest.raises(ValueError, match="disagree on keys"):
        generate._object(("a",), {"a": {}, "extra": {}})


def _walk(node, path=()):
    """Every (path, sub-schema) of a schema."""
    yield path, node
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _walk(value, path + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _walk(value, path + (i,))


def test_every_enum_and_closed_mapping_agrees_with_the_loader():
    """Independently of the generator: each enum in the schemas is one of the loader's
    enums, and each closed mapping's keys are one of the loader's key tables."""
    from gpucompgen.device import FACT_KEYS
    from gpucompgen.runtime.facts import KINDS

    enums = {frozenset(e) for e in (model.KINDS, model.DTYPES, model.MEMORIES,
                                    model.PARAM_TYPES, model.COVERS, model.EXECUTIONS,
                                    model.ZERO_COPY, model.STAGING, model.PLACEMENTS,
                                    model.FUSION, model.BACKENDS, fusable.FORMS, fusable.BORDERS, fusable.AXES, PROFILES,
                                    [*PROFILES, "auto"], KINDS, model.ANY, model.FAMILIES)}
    tables = {frozenset(t) for t in (
        model.SYSTEM_KEYS, model.PLATFORM_KEYS, model.INSTANCE_KEYS, model.TYPE_KEYS,
        model.PORT_KEYS, set(model.PORT_KEYS) - {"height", "width"}, model.PARAM_KEYS,
        model.REQUIRE_KEYS, model.KERNEL_KEYS, model.GPU_KEYS, model.PYTHON_KEYS,
        model.CPU_KEYS, model.FUSABLE_KEYS, model.STAGE_KEYS, model.ALIAS_KEYS,
        model.SETTING_KEYS, set(FACT_KEYS) | {"profile"}, ("from", "to"),
        ("component_types",))}
    seen_enums, seen_tables = set(), set()
    for which in (MODEL, TYPES):
        for path, node in _walk(schema(which)):
            if isinstance(node, dict) and "enum" in node and path[-1:] != ("properties",):
                assert frozenset(node["enum"]) in enums, (which, path)
                seen_enums.add(frozenset(node["enum"]))
            if isinstance(node, dict) and node.get("additionalProperties") is False:
                assert frozenset(node["properties"]) in tables, (which, path)
                seen_tables.add(frozenset(node["properties"]))
    assert seen_enums == enums and seen_tables == tables
