"""Generate the JSON Schemas from the loader's own declaration of the model language.

The keys of every mapping, the enums (kinds, element types, memories, parameter types,
device profiles, executions, ...), the name pattern, the device fact ranges and the size
limits come from model/, device.py, names.py and sizeexpr.py; this module only adds
the JSON type and a description per key.  Every mapping is built with :func:`_object`,
which refuses a key table and a set of fragments that differ, so a key added to the
loader cannot be forgotten here.

Regenerate the checked-in files with ``python -m gpucompgen.schema.generate --write``;
tests/test_schema.py checks that they equal what this module generates.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

from .. import device, model, sizeexpr
from .. import fusable as fusable_forms
from ..names import MAX_NAME, NAME_RE
from ..runtime.facts import KINDS
from . import MODEL, TYPES

HERE = Path(__file__).resolve().parent
DRAFT = "https://json-schema.org/draft/2020-12/schema"
NAME = {"type": "string", "pattern": "^" + NAME_RE.pattern.removesuffix("\\Z") + "$",
        "maxLength": MAX_NAME}
ENDPOINT = NAME["pattern"].strip("^$") + "\\." + NAME["pattern"].strip("^$")
POSITIVE = {"type": "integer", "minimum": 1}
TEXT = {"type": "string"}
SIZE_EXPR = {"type": ["integer", "string"], "maxLength": sizeexpr.MAX_SOURCE,
             "description": "size expression: integers, int parameters, <input>.height/.width, "
                            "+ - * // %, min(a, b, ...), max(a, b, ...)"}
# a parameter's value: a scalar, or an array parameter's (nested) list of numbers
VALUE = {"anyOf": [{"type": ["integer", "number", "boolean", "string"]},
                   {"type": "array", "items": {"anyOf": [
                       {"type": "number"},
                       {"type": "array", "items": {"anyOf": [
                           {"type": "number"},
                           {"type": "array", "items": {"type": "number"}}]}}]}}]}
SETTING_DESCRIPTIONS = {"tile": "square of the output each work-group covers",
                        "block_x": "work-group size in x", "block_y": "work-group size in y",
                        "block_z": "work-group size in z"}


def _object(keys: tuple[str, ...], fragments: dict[str, Any], required: tuple[str, ...] = (),
            **extra: Any) -> dict[str, Any]:
    """A closed object schema with exactly the loader's keys, in the loader's order."""
    if set(keys) != set(fragments):
        raise ValueError(f"schema and loader disagree on keys: loader {sorted(keys)}, "
                         f"schema {sorted(fragments)}")
    schema: dict[str, Any] = {"type": "object", "additionalProperties": False}
    if required:
        schema["required"] = list(required)
    schema["properties"] = {k: fragments[k] for k in keys}
    schema.update(extra)
    return schema


def _named_map(values: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """A mapping from names to values."""
    return {"type": "object", **extra, "propertyNames": NAME, "additionalProperties": values}


def _enum(values, description: str = "") -> dict[str, Any]:
    schema: dict[str, Any] = {"enum": list(values)}
    if description:
        schema["description"] = description
    return schema


def _settings() -> dict[str, Any]:
    return _object(model.SETTING_KEYS, {k: dict(POSITIVE, description=SETTING_DESCRIPTIONS[k])
                                        for k in model.SETTING_KEYS})


def _fact(key: str) -> dict[str, Any]:
    if key == "name":
        return {"type": "string", "minLength": 1, "maxLength": device.MAX_NAME,
                "description": "device name shown in the plan"}
    if key == "host_unified_memory":
        return {"type": "boolean"}
    if key == "kind":
        return {"type": "string", "enum": list(KINDS),
                "description": "the device's class: where flexible components run by "
                               "default, the fusion cost model's constants"}
    low, high = device.FACT_RANGES[key]
    number = {"type": "integer", "minimum": low, "maximum": high}
    if key == "max_work_item_sizes":
        return {"type": "array", "items": number, "minItems": 3, "maxItems": 3}
    return number


def model_schema() -> dict[str, Any]:
    facts = {k: _fact(k) for k in device.FACT_KEYS}
    facts["profile"] = {"type": "string", "enum": list(device.PROFILES)}
    platform = _object(model.PLATFORM_KEYS, {
        "device": {"description": "device facts to plan GPU settings for", "oneOf": [
            {"type": "string", "enum": [*device.PROFILES, "auto"]},
            _object(("profile", *device.FACT_KEYS), facts)]},
        "gpu_settings": _named_map(_settings(), description="overrides of the GPU settings "
                                   "the system chooses, per component"),
        "thread_budget": dict(POSITIVE, description="threads components running at the same "
                              "time may use together"),
        "execution": _enum(model.EXECUTIONS, "parallel: independent GPU work on separate "
                           "in-order queues, waiting only where data is read (default); "
                           "sequential: one queue, blocking copies"),
        "zero_copy": _enum(model.ZERO_COPY, "zero-copy adapters: auto follows the device's "
                           "unified host memory (default)"),
        "placement": _enum(model.PLACEMENTS, "where flexible components run unless they say "
                           "(default gpu); auto chooses for the least estimated time"),
        "profile": dict(TEXT, description="a profile file written by 'gpucompgen tune', "
                        "relative to this model"),
        "frames_in_flight": dict(POSITIVE, maximum=model.MAX_FRAMES_IN_FLIGHT,
                                 description="frames the program works on at the same time: "
                                 "1 runs one frame at a time (default); 2 or more overlap "
                                 "sources, device work and sinks of consecutive frames"),
        "staging": _enum(model.STAGING, "how copying adapters stage host memory: pinned "
                         "(ALLOC_HOST_PTR buffers, mapped) or pageable; auto is pinned when "
                         "the device has no unified host memory (default)"),
        "fusion": _enum(model.FUSION, "auto: chains of fusable GPU components run as one "
                        "kernel (default); off: one kernel per component"),
        "backend": _enum(model.BACKENDS, "opencl: OpenCL C kernels driven from Python (default); "
                         "cuda: cuda-python and the same kernels as CUDA C++ (docs/cuda.md)"),
    })
    # a type name, or lib.Name for a library type a model's own type shadows
    type_name = dict(NAME, pattern="^(" + re.escape(model.LIBRARY_PREFIX) + ")?"
                     + NAME["pattern"].removeprefix("^"),
                     maxLength=MAX_NAME + len(model.LIBRARY_PREFIX),
                     description="component type (lib.Name: the library's, where a type of "
                                 "the model's own shadows it)")
    instance = _object(model.INSTANCE_KEYS, {
        "type": type_name, "params": _named_map(VALUE), "description": TEXT,
        "placement": _enum(model.PLACEMENTS, "where a flexible component runs"),
        "fuse": {"type": "boolean", "description": "false: never fuse this component with "
                 "its neighbours"}}, ("type",))
    connection = {"oneOf": [
        {"type": "string", "pattern": f"^\\s*{ENDPOINT}\\s*->\\s*{ENDPOINT}\\s*$",
         "description": "producer.output -> consumer.input"},
        _object(("from", "to"), {"from": {"type": "string", "pattern": f"^{ENDPOINT}$"},
                                 "to": {"type": "string", "pattern": f"^{ENDPOINT}$"}},
                ("from", "to"))]}
    suffixes = "|".join(s.removeprefix(".") for s in model.TYPE_FILE_SUFFIXES)
    top = _object(model.SYSTEM_KEYS, {
        "system": dict(NAME, description="name of the system: the generated program is "
                       "<system>.py"),
        "description": dict(TEXT, description="free text, kept as a string in the generated "
                            "program"),
        "types": {"type": "array", "description": "component-type files (.yaml or .yml), "
                  "relative to this model or absolute",
                  "items": {"type": "string", "minLength": 1, "pattern": f"\\.({suffixes})$"}},
        "platform": platform,
        "components": _named_map({"oneOf": [type_name, instance]}, minProperties=1),
        "connections": {"type": "array", "items": connection},
    }, ("system", "components"))
    return {"$schema": DRAFT, "$id": f"https://gpucompgen.invalid/schema/{MODEL}",
            "title": "gpucompgen system model",
            "description": "A pipe-and-filter system of GPU-aware and standard components "
                           "(gpucompgen check MODEL validates everything this schema cannot).",
            **top}


def _local_file(suffix: str) -> dict[str, Any]:
    return {"type": "string",
            "pattern": f"^(?![/\\\\])(?!.*(^|[/\\\\])\\.\\.([/\\\\]|$))[^:]*\\{suffix}$",
            "description": f"a {suffix} file in the folder of this type file (relative, no "
                           "'..', no link out of the folder)"}


def _port(output: bool = False) -> dict[str, Any]:
    """A port's keys: memory, a dtype and channels that may be generic, old names."""
    follows = "^" + NAME["pattern"].strip("^$") + "\\.{}$"
    dtype = {"oneOf": [
        _enum(model.DTYPES), _enum(model.ANY, "any element type"),
        {"type": "array", "items": _enum(model.DTYPES), "minItems": 1, "uniqueItems": True,
         "description": "any of these element types"},
        {"type": "string", "pattern": follows.format("dtype"),
         "description": "the element type of input <port>"}],
        "description": "element type: one, a list, 'any', or '<input>.dtype' (generic ports, "
                       "resolved for each component from what feeds it)"}
    channels = {"oneOf": [
        POSITIVE, _enum(model.ANY, "any number of channels"),
        {"type": "array", "items": POSITIVE, "minItems": 1, "uniqueItems": True,
         "description": "any of these channel counts"},
        {"type": "string", "pattern": follows.format("channels"),
         "description": "the channels of input <port>"},
        # not 'any', which the enum above is (oneOf wants one match)
        dict(NAME, **{"not": _enum(model.ANY)}, description="an int parameter's value")],
        "description": "channels: a number, a list, 'any', '<input>.channels' or an int "
                       "parameter (generic ports, resolved for each component)"}
    if output:  # an output's may also be an int parameter's, OpenCV's depth code
        dtype = {"oneOf": [*dtype["oneOf"], dict(NAME, **{"not": {"anyOf": [
            _enum(model.DTYPES), _enum(model.ANY)]}}, description="an int parameter "
            "holding OpenCV's depth code (-1: the first input's)")],
            "description": "element type: one, a list, 'any', '<input>.dtype' or an int "
                           "parameter (generic ports, resolved for each component)"}
    return {"memory": _enum(model.MEMORIES), "dtype": dtype,
            "channels": channels, "description": TEXT,
            "aliases": {"type": "array", "items": NAME, "uniqueItems": True,
                        "description": "old names of the port, still accepted (deprecated)"}}


def _fusable() -> dict:
    """The schema of a type's 'fusable:'."""
    return _object(model.FUSABLE_KEYS, {
        "form": _enum(fusable_forms.FORMS, "pointwise: reads inputs at (y, x); index_map: "
                      "each input at one computed position; stencil: a window of 'radius' "
                      "with a border rule"),
        "value": dict(TEXT, description="an OpenCL C expression (or statements with "
                      "'return') for output element (y, x, c); inputs read as "
                      "<port>(y, x, c), or <port>(y, x, c, fill) for fill outside the "
                      "frame (stencil, index_map)"),
        "radius": {"type": ["integer", "string"],
                   "description": "stencil: the window's radius, a number or an int parameter"},
        "reads": {"type": ["integer", "string"],
                  "description": "stencil: input elements an output element reads with the "
                                 "snippet's loops unrolled, where its snippet nests windows "
                                 "(a number, an int parameter or an expression of them); "
                                 "by default its reads, (2 radius + 1) a loop level"},
        "border": {"anyOf": [_enum(fusable_forms.BORDERS), {"type": "string"}],
                   "description": "stencil: what a read outside the input gets: clamp, the "
                   "nearest edge pixel; reflect101, OpenCV's BORDER_REFLECT_101 "
                   "(gfedcb|abcdefgh|gfedcba); reflect, BORDER_REFLECT (fedcba|abcdefgh); "
                   "constant, 0; or an int parameter holding OpenCV's border code "
                   "(0 constant, 1 clamp, 2 reflect, 4 reflect101)"},
        "stages": {"type": "object", "additionalProperties": _object(model.STAGE_KEYS, {
            "dtype": {"anyOf": [_enum(model.DTYPES, "the stage's element type"),
                                {"type": "string",
                                 "pattern": r"^[A-Za-z_][A-Za-z0-9_]*\.(sum_)?dtype$",
                                 "description": "an input's element type (<port>.dtype), "
                                                "for a type generic over element types; "
                                                "<port>.sum_dtype: the type its sums are "
                                                "kept in (int32, float32 for float32)"}]},
            "radius": {"type": ["integer", "string"],
                       "description": "the stage's window radius, a number or an int "
                                      "parameter or an expression of them"},
            "axis": _enum(fusable_forms.AXES, "x where the stage's window is a row (it reads at "
                          "(y, x + d) only), y where it is a column"),
            "reads": {"type": ["integer", "string"],
                      "description": "input elements an element of the stage reads with "
                                     "its loops unrolled"},
            "value": dict(TEXT, description="statements ending in 'return ...;' for "
                          "element (y, x, c) of the stage; reads the inputs and the "
                          "stages before it as <name>(y, x, c)")}, ["dtype", "radius", "value"]),
                   "description": "stencil: what the value reads besides the inputs, in "
                   "order, each a stencil of its own over the inputs and the stages before "
                   "it (a box filter's row sums, an opening's erosion); the value reads "
                   "them as <name>(y, x, c); the generator computes a stage at every read "
                   "of it or once into local memory"},
        "axis": _enum(fusable_forms.AXES, "stencil: x where the window is a row (it reads at "
                      "(y, x + d) only), y where it is a column; by default a square"),
        "tables": {"type": "object", "additionalProperties": {"type": "string"},
                   "description": "stencil: arrays the snippet reads, each computed from "
                   "parameters when the kernel is generated by one of gpucompgen's table "
                   "functions, e.g. kx: 'gaussian_q8(ksize, sigma)' (OpenCV's 8-bit "
                   "Gaussian weights)"}}, ("form", "value"),
        description="the per-element work in a form the system may fuse with its neighbours "
                    "into one kernel; a type with a form needs no 'kernel': its kernel, "
                    "alone as in a group, is generated from the form")


def types_schema() -> dict[str, Any]:
    param_types = {"anyOf": [_enum(model.PARAM_TYPES), {
        "type": "string", "pattern": f"^{model.ARRAY_TYPE_PATTERN}$",
        "description": "an array of int or float: one to three dimensions, each a length "
                       "or a range of lengths ('int[256]', 'float[2][3]', 'int[3..64][2]')"}]}
    param = {"oneOf": [param_types, _object(model.PARAM_KEYS, {
        "type": param_types, "default": VALUE, "min": {"type": "number"},
        "max": {"type": "number"}, "description": TEXT,
        "invertible": {"type": "boolean", "description": "a float matrix (2x2, 3x3, 2x3) "
                       "whose determinant must not be 0"},
        "aliases": {"type": "array", "items": NAME, "uniqueItems": True,
                    "description": "old names of the parameter, still accepted "
                                   "(deprecated)"}}, ("type",))]}
    port = _port()
    inputs = _named_map(_object(tuple(k for k in model.PORT_KEYS if k in port), port))
    outputs = _named_map(_object(model.PORT_KEYS, dict(_port(output=True), height=SIZE_EXPR,
                                                         width=SIZE_EXPR)))
    condition = {"type": ["string", "integer"], "maxLength": sizeexpr.MAX_SOURCE}
    requires = {"type": "array", "items": {"oneOf": [
        condition, _object(model.REQUIRE_KEYS, {"check": condition, "message": TEXT},
                           ("check",))]}}
    kernel = _object(model.KERNEL_KEYS, {
        "file": _local_file(".cl"), "function": NAME, "grid": NAME,
        "cover": _enum(model.COVERS, "what one work-group covers of the grid port: a tile x "
                       "tile square of pixels (squares, the default) or tile whole rows "
                       "(rows)")}, ("file",))
    python = _object(model.PYTHON_KEYS, {"file": _local_file(".py"), "class": NAME},
                     ("file",))
    cpu = _object(model.CPU_KEYS, {"file": _local_file(".py"), "function": NAME},
                  ("file", "function"))
    sizes = {"type": "array", "items": POSITIVE, "minItems": 1}
    gpu = _object(model.GPU_KEYS, {
        "tiles": sizes, "block_z": sizes, "prefer": _settings(),
        "max_threads": dict(POSITIVE, description="most threads per work-group the kernel "
                            "accepts (e.g. its __local arrays)"),
        "square": {"type": "boolean", "description": "the kernel needs block_x == block_y"}})
    fusable = _fusable()
    kind_gpu, kind_standard = model.KINDS[1], model.KINDS[0]
    ctype = _object(model.TYPE_KEYS, {
        "kind": _enum(model.KINDS), "description": TEXT,
        "family": _enum(model.FAMILIES, "what 'gpucompgen types' groups the type under"),
        "params": _named_map(param),
        "inputs": inputs, "outputs": outputs, "requires": requires, "kernel": kernel,
        "python": python, "gpu": gpu, "cpu": cpu, "fusable": fusable}, ("kind",), allOf=[
        {"if": {"properties": {"kind": {"const": kind_gpu}}},
         "then": {"anyOf": [{"required": ["kernel"]}, {"required": ["fusable"]}],
                  "not": {"required": ["python"]}}},
        # 'gpu' settings are a hand-written kernel's: a generated kernel has the system's
        {"if": {"not": {"required": ["kernel"]}}, "then": {"not": {"required": ["gpu"]}}},
        {"if": {"properties": {"kind": {"const": kind_standard}}},
         "then": {"required": ["python"],
                  "not": {"anyOf": [{"required": ["kernel"]}, {"required": ["gpu"]}]}}}])
    alias = _object(model.ALIAS_KEYS, {
        "alias": NAME, "channels": POSITIVE, "description": TEXT}, ("alias",),
        description="a deprecated name of a type of this file: the type with its generic "
                    "channels fixed to 'channels'")
    top = _object(("component_types",), {
        "component_types": _named_map({"if": {"required": ["alias"]}, "then": alias,
                                       "else": ctype}, minProperties=1)},
        ("component_types",))
    return {"$schema": DRAFT, "$id": f"https://gpucompgen.invalid/schema/{TYPES}",
            "title": "gpucompgen component types",
            "description": "Component types: ports, parameters and the kernel or Python "
                           "class implementing each.", **top}


def generated() -> dict[str, str]:
    """File name -> text of each schema as it is checked in."""
    return {name: json.dumps(make(), indent=2, ensure_ascii=False) + "\n"
            for name, make in ((MODEL, model_schema), (TYPES, types_schema))}


def main(argv: list[str]) -> int:
    stale = [name for name, text in generated().items()
             if (HERE / name).read_text(encoding="utf-8") != text]
    if argv == ["--write"]:
        for name, text in generated().items():
            (HERE / name).write_text(text, encoding="utf-8")
        return 0
    for name in stale:
        print(f"{name} differs from the generated schema: run python -m "
              "gpucompgen.schema.generate --write", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
