"""The typed model: component types (ports, parameters, kernels) and system models.

Built from positioned YAML documents (see loader.py).  Every problem found while building
is reported through a Reporter with the exact position; building goes on so that one run
shows all problems at once.
"""

from __future__ import annotations

import ast
import copy
import hashlib
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from . import fusable as fusable_forms
from . import sizeexpr
from .backend import BACKENDS, signature_checker
from .backend import DEFAULT as DEFAULT_BACKEND
from .dataflow import Endpoint
from .errors import Diagnostic, GpucompgenError, Pos, Reporter, did_you_mean
from .loader import (
    MAX_FILE_BYTES,
    MAX_SOURCE_BYTES,
    Document,
    FileProblem,
    load_file,
    load_text,
    read_text,
    starts_with_key,
)
from .names import CLASS_RESERVED, MODULE_NAMES, fold, member_names, name_problem, snake

DTYPES = {  # element type → (numpy name, OpenCL C type, bytes)
    "uint8": ("uint8", "uchar", 1),
    "int8": ("int8", "char", 1),
    "uint16": ("uint16", "ushort", 2),
    "int16": ("int16", "short", 2),
    "int32": ("int32", "int", 4),
    "uint32": ("uint32", "uint", 4),
    "float32": ("float32", "float", 4),
}
MEMORIES = ("gpu", "cpu")
# a generic port's 'dtype: any' (every element type) or 'channels: any' (any count)
ANY = ("any",)
# "path": a string naming a file or folder; a relative one is relative to the model file
# "input": a source URI (gpucompgen.io: images, video, camera, stream, recording); a plain
# path in it is relative to the model file, and the frame size is read from its header
PARAM_TYPES = {"int": int, "float": float, "bool": bool, "str": str, "path": str, "input": str}
# array parameters: 'int' or 'float' and one to three dimensions, each a length N or a
# range of lengths A..B ('int[256]', 'float[2][3]', 'int[3..64][2]'): a lookup table, a
# structuring element, a warp matrix, a polygon
ARRAY_TYPE_PATTERN = r"(int|float)((?:\[\d{1,6}(?:\.\.\d{1,6})?\]){1,3})"
ARRAY_TYPE = re.compile(ARRAY_TYPE_PATTERN)
MAX_ARRAY_ELEMENTS = 65536  # of one array parameter (a 256 x 256 table)
KINDS = ("standard", "gpu-aware", "flexible")
# what 'gpucompgen types' groups the library by (a type's 'family:'), in this order
FAMILIES = ("colour", "filters", "morphology", "geometry", "arithmetic", "features", "io")
# where a component runs: "auto" lets the place pass choose (flexible types only)
PLACEMENTS = ("gpu", "cpu", "auto")
SETTING_KEYS = ("tile", "block_x", "block_y", "block_z")
# How a kernel's work-groups cover its grid port: a tile x tile square of pixels each (the
# paper's contract), or `tile` whole rows each (kernels that copy rows, e.g. VerticalMirror).
COVERS = ("squares", "rows")

# Bounds on a system's size: the passes look ports up by scanning, so checking and
# building take time that grows with components x connections. Camera pipelines have tens
# of components; at these bounds check and build take a few seconds (see the README).
MAX_COMPONENTS = 500
MAX_CONNECTIONS = 2000
MAX_PORTS = 64  # inputs, and outputs, of one component type
MAX_PARAMS = 256  # parameters of one component type
MAX_TYPE_FILES = 32  # entries of a model's 'types:' list
MAX_TYPE_BYTES = 1 << 20  # all the type files of one model together

LIBRARY_DIR = Path(__file__).resolve().parent / "library"


@dataclass(frozen=True)
class ParamDecl:
    name: str
    type: str
    default: Any = None
    required: bool = False
    minimum: float | None = None
    maximum: float | None = None
    description: str = ""
    # an array parameter ('int[256]', 'float[2][3]', 'int[3..64][2]'): the (least, most)
    # length of each dimension, outermost first; () for a scalar. min and max bound every
    # element; the value is nested tuples, the element type's numbers.
    shape: tuple[tuple[int, int], ...] = ()
    # a float matrix (2x2, 3x3, or 2x3: its left 2x2) whose determinant must not be 0: a
    # warp's matrix, a camera matrix ('invertible: true' in the type file)
    invertible: bool = False

    @property
    def element(self) -> str:
        """The type of one value: the type itself, or an array's element type."""
        return self.type.split("[", 1)[0]


@dataclass(frozen=True)
class PortDecl:
    name: str
    direction: str  # "in" | "out"
    memory: str  # "gpu" | "cpu" | "any" (a flexible type's port: where it is placed)
    dtype: str  # a generic port: the first it accepts (a component's own is resolved)
    channels: int
    height: ast.Expression | None = None  # outputs only
    width: ast.Expression | None = None
    pos: Pos = Pos("")
    # A generic port (docs/component-types.md#generic-ports): what it may carry, resolved
    # for each component when the model is checked (passes/resolve_types.py), from what
    # feeds it or from the port or parameter it follows.  Empty: the fixed dtype/channels.
    dtypes: tuple[str, ...] = ()  # 'dtype: [uint8, int16]': any of these
    dtype_of: str = ""  # 'dtype: src.dtype': the element type of input port src
    channel_counts: tuple[int, ...] = ()  # 'channels: [1, 3]': any of these
    any_channels: bool = False  # 'channels: any'
    channels_of: str = ""  # 'channels: src.channels': those of input port src
    channels_param: str = ""  # 'channels: n': the value of int parameter n
    aliases: tuple[str, ...] = ()  # old names of the port, still accepted (deprecated)

    @property
    def itemsize(self) -> int:
        return DTYPES[self.dtype][2]

    @property
    def generic(self) -> bool:
        return bool(self.dtypes or self.dtype_of or self.channel_counts or self.any_channels
                    or self.channels_of or self.channels_param)

    def dtype_text(self) -> str:
        """The element type as declared: 'uint8', 'uint8|int16' or 'as src'."""
        if self.dtype_of:
            return f"as {self.dtype_of}"
        return "|".join(self.dtypes) if self.dtypes else self.dtype

    def channels_text(self) -> str:
        """The channels as declared: '3', '1|3', 'any', 'as src' or 'parameter n'."""
        if self.channels_of:
            return f"as {self.channels_of}"
        if self.channels_param:
            return f"parameter {self.channels_param}"
        if self.any_channels:
            return "any"
        return "|".join(map(str, self.channel_counts)) if self.channel_counts \
            else str(self.channels)

    def describe(self) -> str:
        return f"{self.memory.upper()} {self.dtype_text()}x{self.channels_text()}"

    def fixed(self, dtype: str, channels: int) -> PortDecl:
        """The port with this element type and these channels, generic no more."""
        return PortDecl(self.name, self.direction, self.memory, dtype, channels, self.height,
                        self.width, self.pos, aliases=self.aliases)


@dataclass(frozen=True)
class GpuDecl:
    tiles: tuple[int, ...] = (8, 16, 32, 64)
    block_z: tuple[int, ...] = (1,)
    prefer: tuple[int, int, int, int] = (32, 16, 16, 1)
    # block shape constraints of the kernel: at most this many threads per work-group
    # (e.g. __local arrays sized for them), and block_x == block_y
    max_threads: int | None = None
    square: bool = False

    def accepts(self) -> str:
        """What the kernel accepts, for hints."""
        parts = [f"tile {' or '.join(map(str, self.tiles))}",
                 f"block_z {' or '.join(map(str, self.block_z))}"]
        if self.max_threads:
            parts.append(f"at most {self.max_threads} threads per work-group")
        if self.square:
            parts.append("square blocks (block_x == block_y)")
        return ", ".join(parts)


@dataclass
class ComponentType:
    name: str
    kind: str
    description: str
    params: dict[str, ParamDecl]
    inputs: dict[str, PortDecl]
    outputs: dict[str, PortDecl]
    requires: list[tuple[ast.Expression, str]]
    decl_file: Path
    origin: str  # "library" | "user"
    pos: Pos
    kernel_file: Path | None = None
    kernel_function: str = ""
    grid: str = ""  # output port the kernel's work-items cover
    cover: str = "squares"  # one of COVERS: what one work-group covers of the grid port
    python_file: Path | None = None
    python_class: str = ""
    gpu: GpuDecl = field(default_factory=GpuDecl)
    fusable: fusable_forms.FusableDecl | None = None  # None: opaque, never fused
    # the kernel's and the Python file's text, as checked (build writes this text, never
    # a file read again later)
    kernel_text: str = ""
    python_text: str = ""
    # a flexible type's CPU implementation: a function in a Python file (never imported
    # by the generator: checked with ast)
    cpu_file: Path | None = None
    cpu_function: str = ""
    cpu_text: str = ""
    # a deprecated alias ('ErodeGray: {alias: Erode, channels: 1}'): the type it names,
    # with its generic channels fixed
    alias_of: str = ""
    alias_channels: int = 0
    family: str = ""  # one of FAMILIES: how 'gpucompgen types' groups it ("": by file)

    @property
    def generic(self) -> bool:
        """Some port's channels or element type are resolved per component."""
        return any(p.generic for p in (*self.inputs.values(), *self.outputs.values()))

    def canonical_port(self, name: str) -> str | None:
        """The port a name (its own or a deprecated alias) stands for, or None."""
        if name in self.inputs or name in self.outputs:
            return name
        return next((p.name for p in (*self.inputs.values(), *self.outputs.values())
                     if name in p.aliases), None)

    def specialized(self, dtype: str | None = None, channels: int | None = None) -> ComponentType:
        """A copy whose generic ports are fixed: inputs that accept several take dtype and
        channels (their first choice when not given), ports that follow another port or a
        parameter take its value.  For tests, benchmarks and examples: a model's
        components are resolved from what feeds them (passes/resolve_types.py)."""
        from .typeresolve import resolve_ports

        given = {p: (dtype, channels) for p in self.inputs}
        ports = resolve_ports(self, given, {p: d.default for p, d in self.params.items()})
        twin = copy.copy(self)
        twin.inputs = {p: d.fixed(*ports[p]) for p, d in self.inputs.items()}
        twin.outputs = {p: d.fixed(*ports[p]) for p, d in self.outputs.items()}
        return twin

    @property
    def gpu_aware(self) -> bool:
        """The type has a GPU implementation (a kernel): gpu-aware or flexible."""
        return self.kind in ("gpu-aware", "flexible")

    @property
    def flexible(self) -> bool:
        """The type runs on either side: its kernel on the GPU, cpu.function on the CPU."""
        return self.kind == "flexible"

    @property
    def snake(self) -> str:
        return snake(self.name)

    def port(self, name: str) -> PortDecl | None:
        return self.inputs.get(name) or self.outputs.get(name)


@dataclass
class Instance:
    name: str
    type: ComponentType
    params: dict[str, Any]
    pos: Pos
    order: int
    placement: str = ""  # "gpu" | "cpu" | "auto" as the model says; "" when it says nothing
    placement_pos: Pos | None = None
    fuse: bool = True  # 'fuse: false': never fused with its neighbours


@dataclass
class Connection:
    source: Endpoint
    target: Endpoint
    pos: Pos


@dataclass
class SystemModel:
    name: str
    description: str
    file: Path
    display: str  # the model's path as shown in messages and generated headers
    text_sha256: str
    components: dict[str, Instance]
    connections: list[Connection]
    device: Any  # a profile name or a mapping of facts (resolved by device.py)
    device_pos: Pos
    gpu_overrides: dict[str, tuple[dict[str, int], Pos]]
    thread_budget: int | None
    types: dict[str, ComponentType]
    # where each key and value of a mapping platform.device was written (for messages)
    device_positions: dict[str, tuple[Pos, Pos]] = field(default_factory=dict)
    # platform.execution: "parallel" (independent work on separate queues) | "sequential"
    execution: str = "parallel"
    # platform.zero_copy: "auto" (follow the device's unified memory) | "on" | "off"
    zero_copy: str = "auto"
    # platform.frames_in_flight: frames the program works on at the same time (1: one at a
    # time, the paper's loop); platform.staging: how copying adapters stage host memory
    frames_in_flight: int = 1
    staging: str = "auto"
    thread_budget_pos: Pos | None = None
    platform_pos: Pos = Pos("")
    # platform.fusion: "auto" (chains of fusable GPU components become one kernel) | "off"
    fusion: str = "auto"
    # platform.backend: "opencl" (default) | "cuda" (gpucompgen.backend, docs/cuda.md)
    backend: str = "opencl"
    # platform.placement: where flexible components without their own 'placement:' run
    # ("gpu", "cpu", "auto", or "" when the model says nothing: decided for the device,
    # passes/place.py); platform.profile: a `gpucompgen tune` file
    placement: str = ""
    placement_pos: Pos | None = None
    profile: Path | None = None
    profile_pos: Pos | None = None
    # things check says that are no problem: a user's type shadowing a library type
    notes: list[Diagnostic] = field(default_factory=list)
    # every file of the user's that feeds the build (resolved path -> sha256 of the text
    # read): the model, its type files, their kernel, Python and CPU files, and the profile
    # once read.  The generated program records them, so that 'build --check' is stale when
    # any changes; build and tune never write over one.
    inputs: dict[Path, str] = field(default_factory=dict)

    def add_input(self, path: Path, text: str | bytes) -> None:
        data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
        self.inputs[path.resolve()] = hashlib.sha256(data).hexdigest()
    # warnings found while loading (an input that is missing but not needed for sizes)
    load_warnings: list = field(default_factory=list)


# --------------------------------------------------------------------------- helpers

def _expect_map(doc: Document, rep: Reporter, path: tuple, value: Any, what: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        rep.error(doc.pos(*path), f"{what} must be a mapping, not {_kind(value)}")
        return {}
    return value


def _named(value: Any, choices) -> bool:
    """value is a string among choices (a YAML list or mapping is never a choice)."""
    return isinstance(value, str) and value in choices


def _kind(value: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a mapping", type(None): "empty"}.get(type(value),
                                                                         type(value).__name__)


def _unknown_keys(doc: Document, rep: Reporter, path: tuple, mapping: dict,
                  allowed: tuple[str, ...], what: str) -> None:
    for key in mapping:
        if key not in allowed:
            rep.error(doc.key_pos(*path, key), f"unknown key '{key}' in {what}",
                      did_you_mean(key, allowed))


def _text(doc: Document, rep: Reporter, path: tuple, value: Any, what: str) -> str:
    if value is None:
        return ""
    if not isinstance(value, str):
        rep.error(doc.pos(*path), f"{what} must be a string, not {_kind(value)}",
                  "quote the value")
        return ""
    return value


def _positive_int(doc: Document, rep: Reporter, path: tuple, value: Any, what: str,
                  default: int | None = None) -> int | None:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        rep.error(doc.pos(*path), f"{what} must be a positive integer, not {value!r}")
        return default
    return value


# --------------------------------------------------------------------------- types

TYPE_KEYS = ("kind", "description", "family", "params", "inputs", "outputs", "requires",
             "kernel", "python", "gpu", "cpu", "fusable")
PORT_KEYS = ("memory", "dtype", "channels", "height", "width", "description", "aliases")
PARAM_KEYS = ("type", "default", "min", "max", "description", "invertible")
REQUIRE_KEYS = ("check", "message")
KERNEL_KEYS = ("file", "function", "grid", "cover")
GPU_KEYS = ("tiles", "block_z", "prefer", "max_threads", "square")
PYTHON_KEYS = ("file", "class")
CPU_KEYS = ("file", "function")
FUSABLE_KEYS = ("form", "value", "radius", "border")


def load_types_file(path: Path, display: str, origin: str, rep: Reporter,
                    doc: Document | None = None) -> dict[str, ComponentType]:
    """Load one file of component types: ``component_types: {Name: {...}, ...}`` (doc:
    the file, already loaded)."""
    if doc is None:
        doc = load_file(path, display)
    if doc.data is None:
        rep.error(doc.pos(), "the component-type file is empty",
                  "start it with 'component_types:' and one or more types")
    root = _expect_map(doc, rep, (), doc.data, "a component-type file")
    _unknown_keys(doc, rep, (), root, ("component_types",), "a component-type file")
    types_map = _expect_map(doc, rep, ("component_types",), root.get("component_types"),
                            "component_types")
    if not types_map and not rep.has_errors:
        rep.error(doc.pos(), "no component types defined",
                  "add 'component_types:' with one or more types")
    result = {}
    for tname, spec in types_map.items():
        if isinstance(spec, dict) and "alias" in spec:
            continue
        ctype = _load_type(doc, rep, path, origin, tname, spec)
        if ctype is not None:
            result[tname] = ctype
    for tname, spec in types_map.items():
        if isinstance(spec, dict) and "alias" in spec:
            ctype = _load_alias(doc, rep, tname, spec, result)
            if ctype is not None:
                result[tname] = ctype
    return result


ALIAS_KEYS = ("alias", "channels", "description")


def _load_alias(doc: Document, rep: Reporter, tname: str, spec: dict,
                types: dict[str, ComponentType]) -> ComponentType | None:
    """A deprecated name of a type of the same file: ``GaussianBlurGray: {alias:
    GaussianBlur, channels: 1}`` is GaussianBlur with every port whose channels are generic
    fixed to 1 (the ports that follow them too).  Components of the alias build and run
    as before; check notes the type to use instead."""
    base = ("component_types", tname)
    problem = name_problem(tname, "component type name", top_level=True)
    if problem:
        rep.error(doc.key_pos(*base), problem, "use a CamelCase name such as 'ImageMerger'")
        return None
    _unknown_keys(doc, rep, base, spec, ALIAS_KEYS, f"alias '{tname}'")
    target = spec.get("alias")
    if not _named(target, types) or types[target].alias_of:
        rep.error(doc.pos(*base, "alias"), f"alias '{tname}' names {target!r}, which is no "
                  "type of this file", did_you_mean(str(target), [
                      n for n, t in types.items() if not t.alias_of])
                  or "an alias names a type declared in the same file")
        return None
    real = types[target]
    channels = spec.get("channels")
    twin = copy.copy(real)
    twin.name, twin.alias_of, twin.pos = tname, target, doc.key_pos(*base)
    twin.description = _text(doc, rep, base + ("description",), spec.get("description"),
                             "description") or real.description
    if channels is not None:
        pinned = _positive_int(doc, rep, base + ("channels",), channels, "channels")
        counts = {c for p in (*real.inputs.values(), *real.outputs.values())
                  for c in p.channel_counts}
        if pinned is None:
            return None
        if counts and pinned not in counts:
            rep.error(doc.pos(*base, "channels"), f"alias '{tname}' fixes {pinned} channels; "
                      f"'{target}' takes {' or '.join(map(str, sorted(counts)))}",
                      "give one of them")
            return None

        def pin(port: PortDecl) -> PortDecl:
            if port.channel_counts or port.any_channels or port.channels_of:
                return replace(port, channels=pinned, channel_counts=(), any_channels=False,
                               channels_of="")
            return port
        twin.alias_channels = pinned
        twin.inputs = {p: pin(d) for p, d in real.inputs.items()}
        twin.outputs = {p: pin(d) for p, d in real.outputs.items()}
    return twin


def _load_type(doc: Document, rep: Reporter, path: Path, origin: str, tname: str,
               spec: Any) -> ComponentType | None:
    base = ("component_types", tname)
    seen = len(rep.diagnostics)
    # a GPU-aware type becomes a class of the generated program: a module-level name
    problem = name_problem(tname, "component type name", top_level=True)
    if problem:
        rep.error(doc.key_pos(*base), problem, "use a CamelCase name such as 'ImageMerger'")
        return None
    spec = _expect_map(doc, rep, base, spec, f"component type '{tname}'")
    _unknown_keys(doc, rep, base, spec, TYPE_KEYS, f"component type '{tname}'")
    kind = spec.get("kind")
    if kind not in KINDS:
        rep.error(doc.pos(*base, "kind") if "kind" in spec else doc.key_pos(*base),
                  f"component type '{tname}' needs kind 'standard', 'gpu-aware' or "
                  f"'flexible', not {kind!r}",
                  "add 'kind: gpu-aware', 'kind: standard' or 'kind: flexible'")
        return None
    ctype = ComponentType(
        name=tname, kind=kind,
        description=_text(doc, rep, base + ("description",), spec.get("description"),
                          "description"),
        params={}, inputs={}, outputs={}, requires=[], decl_file=path, origin=origin,
        pos=doc.key_pos(*base))
    if "family" in spec:
        if _named(spec["family"], FAMILIES):
            ctype.family = spec["family"]
        else:
            rep.error(doc.pos(*base, "family"), f"family of '{tname}' must be one of "
                      f"{', '.join(FAMILIES)}, not {spec['family']!r}",
                      did_you_mean(str(spec["family"]), FAMILIES) or
                      "it groups the type in 'gpucompgen types'")
    # parameters
    params = _expect_map(doc, rep, base + ("params",), spec.get("params"), "params")
    if len(params) > MAX_PARAMS:
        rep.error(doc.key_pos(*base, "params"),
                  f"component type '{tname}' has {len(params):,} parameters; at most "
                  f"{MAX_PARAMS:,} are allowed", "pass fewer, larger values")
        return None
    for pname, written in params.items():
        ppath = base + ("params", pname)
        problem = name_problem(pname, "parameter name")
        if problem:
            rep.error(doc.key_pos(*ppath), problem)
            continue
        pspec = _expect_map(doc, rep, ppath, {"type": written} if isinstance(written, str)
                            else written, f"parameter '{pname}'")
        _unknown_keys(doc, rep, ppath, pspec, PARAM_KEYS, f"parameter '{pname}'")
        ptype = pspec.get("type")
        shape: tuple[tuple[int, int], ...] = ()
        if isinstance(ptype, str) and "[" in ptype:
            shape, problem = array_shape(ptype)
            if problem:
                rep.error(doc.pos(*ppath, "type"), f"parameter '{pname}' has type {ptype!r}: "
                          f"{problem}", "an array is 'int[N]' or 'float[N]' with one to three "
                          "dimensions, each a length or a range of lengths, e.g. 'int[256]', "
                          "'float[2][3]', 'int[3..64][2]'")
                continue
        elif not _named(ptype, PARAM_TYPES):
            rep.error(doc.pos(*ppath, "type"), f"parameter '{pname}' has type {ptype!r}",
                      "use one of 'int', 'float', 'bool', 'str', or an array such as "
                      "'int[256]'")
            continue
        if gpu_kernel_param_problem(kind, ptype):
            rep.error(doc.pos(*ppath, "type"),
                      f"parameter '{pname}' of GPU-aware type '{tname}' is {ptype}: "
                      "kernel parameters must be int, float or bool")
            continue
        bounds = {}
        for key in ("min", "max"):
            bound = pspec.get(key)
            numeric = ptype in ("int", "float") or bool(shape)
            if bound is not None and (not numeric or not _value_fits(
                    bound, "float") or not math.isfinite(bound)):
                rep.error(doc.pos(*ppath, key),
                          f"'{key}' of parameter '{pname}' must be a finite number"
                          + ("" if numeric else f", and only for int or "
                             f"float parameters, not {ptype}"),
                          f"remove '{key}' or give a number such as {key}: 0")
                bound = None
            bounds[key] = bound
        default = pspec.get("default")
        if "default" in pspec and default is None:
            rep.error(doc.pos(*ppath, "default"), f"default of '{pname}' is empty (null)",
                      f"give {'an' if ptype == 'int' else 'a'} {ptype} default, or remove "
                      "'default:' to make the parameter required")
        invertible = pspec.get("invertible", False)
        if invertible is not False and (invertible is not True or not _matrix(ptype, shape)):
            rep.error(doc.pos(*ppath, "invertible"), f"'invertible' of parameter '{pname}' "
                      "is only 'true', on a float matrix (float[2][2], float[3][3] or "
                      f"float[2][3]), not {py_yaml(invertible)} on {ptype}",
                      "remove 'invertible', or make the parameter such a matrix")
            invertible = False
        decl = ParamDecl(pname, ptype, minimum=bounds["min"], maximum=bounds["max"],
                         shape=shape, invertible=invertible)
        problem, at = (None, ()) if default is None else _value_problem_at(
            default, decl, kind in ("gpu-aware", "flexible"))
        if problem:
            rep.error(doc.pos(*ppath, "default", *at),
                      f"default of '{pname}' {problem}",
                      f"give a {ptype} default within min and max, or none to make "
                      "the parameter required")
            default = None
        ctype.params[pname] = ParamDecl(pname, ptype, param_value(default, decl),
                                        "default" not in pspec,
                                        bounds["min"], bounds["max"],
                                        _text(doc, rep, ppath + ("description",),
                                              pspec.get("description"), "description"),
                                        shape, invertible)
    # ports
    seen_ports: dict[str, str] = {}
    failed_inputs = 0
    for direction, key in (("in", "inputs"), ("out", "outputs")):
        ports = _expect_map(doc, rep, base + (key,), spec.get(key), key)
        if len(ports) > MAX_PORTS:
            rep.error(doc.key_pos(*base, key),
                      f"component type '{tname}' has {len(ports):,} {key}; at most "
                      f"{MAX_PORTS:,} are allowed", "split the component")
            return None
        for pname, pspec in ports.items():
            port = _load_port(doc, rep, base + (key, pname), ctype, direction, pname, pspec)
            if port is None:
                failed_inputs += direction == "in"
                continue
            if fold(pname) in seen_ports:
                rep.error(doc.key_pos(*base, key, pname),
                          f"port '{pname}' collides with port '{seen_ports[fold(pname)]}'",
                          "input and output ports of a type need distinct names")
                continue
            seen_ports[fold(pname)] = pname
            for alias in port.aliases:
                if fold(alias) in seen_ports:
                    rep.error(doc.pos(*base, key, pname, "aliases"),
                              f"alias '{alias}' of port '{pname}' collides with port "
                              f"'{seen_ports[fold(alias)]}'", "give each port its own names")
                seen_ports.setdefault(fold(alias), f"{pname}' (alias '{alias}')")
            (ctype.inputs if direction == "in" else ctype.outputs)[pname] = port
    _check_generic(doc, rep, base, ctype, spec)
    if not ctype.inputs and not ctype.outputs:
        rep.error(ctype.pos, f"component type '{tname}' has no ports",
                  "declare 'inputs:' and/or 'outputs:'")
    if kind in ("gpu-aware", "flexible"):
        _check_class_members(doc, rep, base, ctype)
    # output sizes need the input ports, so parse them after all ports are known
    for pname, port in list(ctype.outputs.items()):
        ctype.outputs[pname] = _port_sizes(doc, rep, base + ("outputs", pname), ctype, port,
                                           quiet=failed_inputs > 0)
    # requirements between input sizes
    requires = spec.get("requires") or []
    if not isinstance(requires, list):
        rep.error(doc.pos(*base, "requires"), "requires must be a list of conditions")
        requires = []
    for i, written in enumerate(requires):
        rpath = base + ("requires", i)
        message, req = "", written
        if isinstance(written, dict):
            _unknown_keys(doc, rep, rpath, written, REQUIRE_KEYS, "a requirement")
            message = _text(doc, rep, rpath + ("message",), written.get("message"), "message")
            req = written.get("check")
        try:
            tree = sizeexpr.parse(req, set(ctype.inputs), set(_int_params(ctype)),
                                  condition=True)
        except sizeexpr.SizeExprError as exc:
            rep.error(doc.pos(*rpath), f"requirement of '{tname}': {exc}")
            continue
        ctype.requires.append((tree, message or f"requires {ast.unparse(tree.body)}"))
    # implementation
    if kind == "flexible":
        _load_kernel(doc, rep, base, ctype, spec, signature_check=len(rep.diagnostics) == seen)
        _load_cpu(doc, rep, base, ctype, spec)
        if "fusable" in spec:
            _load_fusable(doc, rep, base, ctype, spec["fusable"])
        if "python" in spec:
            rep.error(doc.key_pos(*base, "python"),
                      "a flexible type's CPU side is a function, 'cpu: {file, function}', "
                      "not 'python'", "write 'cpu: {file: x.py, function: f}'")
    elif kind == "gpu-aware":
        _load_kernel(doc, rep, base, ctype, spec, signature_check=len(rep.diagnostics) == seen)
        if "cpu" in spec:
            rep.error(doc.key_pos(*base, "cpu"),
                      f"'cpu' is only for flexible types; '{tname}' is gpu-aware",
                      "set 'kind: flexible' (and remove 'memory:' from its ports) or "
                      "remove 'cpu:'")
        if "fusable" in spec:
            _load_fusable(doc, rep, base, ctype, spec["fusable"])
        if "python" in spec:
            rep.error(doc.key_pos(*base, "python"),
                      "a GPU-aware type is implemented by its OpenCL kernel, not 'python'",
                      "remove 'python:' or make the type 'kind: standard'")
    else:
        _load_python(doc, rep, base, ctype, spec)
        for key in ("kernel", "gpu", "cpu", "fusable"):
            if key in spec:
                rep.error(doc.key_pos(*base, key),
                          f"'{key}' is only for GPU-aware or flexible types; '{tname}' is "
                          "standard", "set 'kind: gpu-aware' or 'kind: flexible', or remove "
                          "the key")
    return ctype


def _check_class_members(doc: Document, rep: Reporter, base: tuple,
                         ctype: ComponentType) -> None:
    """A GPU-aware type's parameters and ports become members and locals of one generated
    class (self.<param>, self.<port>_size, ...): none may clash with another or with what
    the class itself uses."""
    owners: dict[str, tuple[str, str]] = {}  # member -> (what made it, the declared name)
    declared = ([(p, "param", ("params", p)) for p in ctype.params]
                + [(p, "in", ("inputs", p)) for p in ctype.inputs]
                + [(p, "out", ("outputs", p)) for p in ctype.outputs])
    what = {"param": "parameter", "in": "input port", "out": "output port"}
    for pname, role, key in declared:
        this = f"{what[role]} '{pname}'"
        members = member_names(pname, role)
        member = next((m for m in members if m in CLASS_RESERVED or m in owners), None)
        if member is None:
            owners.update(dict.fromkeys(members, (this, pname)))
            continue
        made = "" if member == pname else f" (it makes '{member}')"
        if member in CLASS_RESERVED:
            clash = f"'{member}', a name the generated component class uses itself"
        else:
            other, other_name = owners[member]
            clash = other + ("" if member == other_name else f", which makes '{member}' too")
        rep.error(doc.key_pos(*base, *key),
                  f"{this} of '{ctype.name}'{made} clashes with {clash}",
                  "rename it: parameters and ports of a GPU-aware type share the generated "
                  "class's names")


def gpu_kernel_param_problem(kind: str, ptype: str) -> bool:
    return kind in ("gpu-aware", "flexible") and ptype in ("str", "path", "input")


def _int_params(ctype: ComponentType) -> list[str]:
    return [p.name for p in ctype.params.values() if p.type == "int"]


INT32 = (-(1 << 31), (1 << 31) - 1)
FLOAT32_MAX = 3.4028234663852886e38


def array_shape(ptype: str) -> tuple[tuple[tuple[int, int], ...], str]:
    """The dimensions of an array type such as 'int[3..64][2]' ((3, 64), (2, 2)), and ''
    or why the text is no array type."""
    m = ARRAY_TYPE.fullmatch(ptype)
    if m is None:
        return (), "not an array type"
    shape = []
    for dim in m.group(2)[1:-1].split("]["):
        low, _, high = dim.partition("..")
        lo, hi = int(low), int(high or low)
        if lo < 1 or hi < lo:
            return (), (f"dimension [{dim}] must be a length of 1 or more, or a range "
                        "A..B with 1 <= A <= B")
        if shape and hi != lo:  # rows of one length: a rectangular table
            return (), f"only the first dimension may be a range of lengths, not [{dim}]"
        shape.append((lo, hi))
    if math.prod(hi for _, hi in shape) > MAX_ARRAY_ELEMENTS:
        return (), f"it may hold more than {MAX_ARRAY_ELEMENTS:,} values"
    return tuple(shape), ""


def _array_problem(value: Any, decl: ParamDecl, kernel: bool,
                   index: tuple[int, ...] = ()) -> tuple[str, tuple[int, ...]] | None:
    """Why value is no array of decl's shape, element type and bounds, and the index of
    the element (or list) where that was found, so that the error points at it."""
    depth = len(index)
    where = "".join(f"[{i}]" for i in index)
    what = f"element {where} " if where else ""
    if depth == len(decl.shape):
        element = ParamDecl(decl.name, decl.element, minimum=decl.minimum,
                            maximum=decl.maximum)
        problem = _param_value_problem(value, element, kernel)
        return None if problem is None else (f"{what}{problem}", index)
    lo, hi = decl.shape[depth]
    if not isinstance(value, (list, tuple)):
        return (f"{what}must be a list of {lo}" + (f" to {hi}" if hi != lo else "")
                + f" values, not {_kind(value)}", index)
    if not lo <= len(value) <= hi:
        length = f"{lo}" if lo == hi else f"{lo} to {hi}"
        return f"{what}has {len(value)} values where {decl.type} takes {length}", index
    for i, item in enumerate(value):
        found = _array_problem(item, decl, kernel, index + (i,))
        if found:
            return found
    return None


def _value_problem_at(value: Any, decl: ParamDecl,
                      kernel: bool) -> tuple[str | None, tuple[int, ...]]:
    """_param_value_problem, and for an array the index of the element at fault."""
    if decl.shape:
        found = _array_problem(value, decl, kernel)
        if found is None and decl.invertible:
            return _singular(value), ()
        return found or (None, ())
    return _param_value_problem(value, decl, kernel), ()


def _matrix(ptype: str, shape: tuple[tuple[int, int], ...]) -> bool:
    """Whether an array type is a matrix 'invertible:' can apply to."""
    return ptype.startswith("float") and shape in (((2, 2), (2, 2)), ((3, 3), (3, 3)),
                                                   ((2, 2), (3, 3)))


def _singular(value) -> str | None:
    """Why a matrix (2x3: its left 2x2) is not invertible, or None: its determinant is 0
    within float32's precision, relative to its rows' sizes."""
    a = [[float(v) for v in row[:len(value)]] for row in value]
    if len(a) == 2:
        det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
    else:
        det = (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
               - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
               + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
    scale = math.prod(max(abs(v) for v in row) for row in a)
    if abs(det) > 1e-6 * scale:
        return None
    return (f"is a singular matrix (determinant {det:.3g}): it maps the whole frame onto a "
            "line or a point, and has no inverse")


def param_value(value: Any, decl: ParamDecl) -> Any:
    """A checked value as the program keeps it: a float parameter's number as float, an
    array as nested tuples (immutable, hashable) of its element type's numbers."""
    if value is None:
        return None
    if decl.shape:
        def freeze(v: Any) -> Any:
            if isinstance(v, (list, tuple)):
                return tuple(freeze(i) for i in v)
            return float(v) if decl.element == "float" else v
        return freeze(value)
    return float(value) if decl.type == "float" else value


def _param_value_problem(value: Any, decl: ParamDecl, kernel: bool) -> str | None:
    """Why value cannot be given to parameter decl, or None when it can."""
    if decl.shape:
        return _value_problem_at(value, decl, kernel)[0]
    if not _value_fits(value, decl.type):
        return f"must be {decl.type}, not {_kind(value)} ({value!r})"
    if decl.type in ("int", "float"):
        if not math.isfinite(value):
            return f"must be a finite number, not {value!r}"
        if decl.minimum is not None and value < decl.minimum or \
                decl.maximum is not None and value > decl.maximum:
            return f"is {value!r}, outside [{decl.minimum}, {decl.maximum}]"
        if kernel and decl.type == "int" and not INT32[0] <= value <= INT32[1]:
            return f"is {value}, which does not fit the kernel's 32-bit int"
        if kernel and decl.type == "float" and abs(value) > FLOAT32_MAX:
            return f"is {value!r}, which does not fit the kernel's 32-bit float"
    return None


def py_yaml(value: Any) -> str:
    """A value as it would be written in YAML (for hints)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):  # an array parameter's value
        return "[" + ", ".join(py_yaml(v) for v in value) + "]"
    return repr(value) if isinstance(value, str) else str(value)


def _value_fits(value: Any, ptype: str) -> bool:
    if ptype == "float":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if ptype == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, PARAM_TYPES[ptype])


def _load_port(doc, rep, path, ctype, direction, pname, pspec) -> PortDecl | None:
    problem = name_problem(pname, "port name")
    if problem:
        rep.error(doc.key_pos(*path), problem)
        return None
    pspec = _expect_map(doc, rep, path, pspec, f"port '{pname}'")
    _unknown_keys(doc, rep, path, pspec, PORT_KEYS, f"port '{pname}'")
    if ctype.kind == "flexible":
        if "memory" in pspec:
            rep.error(doc.key_pos(*path, "memory"),
                      f"port '{pname}' of flexible type '{ctype.name}' has no memory of its "
                      "own: it lives where the component is placed",
                      "remove 'memory:'; the system inserts the adapters its neighbours need")
        memory = "any"
    else:
        memory = pspec.get("memory", "cpu")
    if memory != "any" and memory not in MEMORIES:
        rep.error(doc.pos(*path, "memory"), f"port '{pname}': memory must be 'gpu' or 'cpu', "
                  f"not {memory!r}")
        return None
    if memory == "gpu" and ctype.kind == "standard":
        rep.error(doc.pos(*path, "memory"),
                  f"standard type '{ctype.name}' cannot have GPU port '{pname}'",
                  "standard components have only CPU ports; make the type 'kind: gpu-aware'")
        return None
    if memory == "cpu" and ctype.kind == "gpu-aware":
        rep.error(doc.pos(*path, "memory"),
                  f"GPU-aware kernel type '{ctype.name}': port '{pname}' must be a GPU port",
                  "kernel components read and write device buffers; let the system insert "
                  "adapters by declaring 'memory: gpu'")
        return None
    generic = _generic_spec(doc, rep, path, ctype, pname, pspec)
    if generic is None:
        return None
    dtype, channels, extra = generic
    if direction == "in":
        for key in ("height", "width"):
            if key in pspec:
                rep.error(doc.key_pos(*path, key),
                          f"input port '{pname}' takes its size from what feeds it",
                          f"remove '{key}'; sizes are declared on outputs")
    aliases = pspec.get("aliases", [])
    if not isinstance(aliases, list) or any(name_problem(a, "port alias") for a in aliases):
        rep.error(doc.pos(*path, "aliases"), f"aliases of port '{pname}' must be a list of "
                  "port names", "e.g. 'aliases: [image]': old names still accepted")
        aliases = []
    return PortDecl(pname, direction, memory, dtype, channels, pos=doc.key_pos(*path),
                    aliases=tuple(aliases), **extra)


FOLLOW_RE = re.compile(r"^\s*([A-Za-z_]\w*)\s*\.\s*(dtype|channels)\s*$")


def _generic_spec(doc, rep, path, ctype, pname, pspec) -> tuple[str, int, dict] | None:
    """A port's dtype and channels as declared: fixed, a list of choices, 'any', another
    port's ('src.dtype', 'src.channels') or an int parameter's value (channels only).
    Returns (dtype, channels, the PortDecl fields of a generic port); which port or
    parameter is followed is checked once every port is known (_check_generic)."""
    extra: dict[str, Any] = {}
    dtype = pspec.get("dtype", "uint8")
    follow = FOLLOW_RE.match(dtype) if isinstance(dtype, str) else None
    if follow and follow[2] == "dtype":
        extra["dtype_of"], dtype = follow[1], "uint8"
    elif dtype in ANY or isinstance(dtype, list):
        choices = list(DTYPES) if dtype in ANY else dtype
        bad = [d for d in choices if not _named(d, DTYPES)]
        if bad or not choices or len(set(choices)) != len(choices):
            rep.error(doc.pos(*path, "dtype"), f"port '{pname}': dtype must list distinct "
                      f"element types of {', '.join(DTYPES)}"
                      + (f"; {bad[0]!r} is none" if bad else ""),
                      did_you_mean(str(bad[0]), DTYPES) if bad else "e.g. [uint8, int16]")
            return None
        if len(choices) > 1:
            extra["dtypes"] = tuple(choices)
        dtype = choices[0]
    elif not _named(dtype, DTYPES):
        rep.error(doc.pos(*path, "dtype"), f"port '{pname}': unknown element type {dtype!r}",
                  did_you_mean(str(dtype), DTYPES) or
                  "an element type, a list of them, 'any', or '<input>.dtype'")
        return None
    channels = pspec.get("channels")
    follow = FOLLOW_RE.match(channels) if isinstance(channels, str) else None
    if follow and follow[2] == "channels":
        extra["channels_of"], channels = follow[1], 1
    elif channels in ANY:
        extra["any_channels"], channels = True, 1
    elif isinstance(channels, str) and channels.isidentifier():
        extra["channels_param"], channels = channels, 1
    elif isinstance(channels, list):
        if not channels or len(set(channels)) != len(channels) or not all(
                isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in channels):
            rep.error(doc.pos(*path, "channels"), f"port '{pname}': channels must list "
                      "distinct positive integers", "e.g. 'channels: [1, 3]'")
            return None
        if len(channels) > 1:
            extra["channel_counts"] = tuple(channels)
        channels = channels[0]
    else:
        channels = _positive_int(doc, rep, path + ("channels",), channels, "channels", 1)
    return dtype, channels, extra


def _check_generic(doc, rep, base, ctype: ComponentType, spec: dict) -> None:
    """What generic ports follow exists, and every generic port can be resolved: an input
    follows an earlier input, an output an input or an int parameter; an output never
    chooses among several (nothing would choose); a hand-written kernel is written for
    one element type and channel count."""
    inputs = list(ctype.inputs)
    for key, ports in (("inputs", ctype.inputs), ("outputs", ctype.outputs)):
        for pname, port in ports.items():
            path = base + (key, pname)
            for what, followed in (("dtype", port.dtype_of), ("channels", port.channels_of)):
                if not followed:
                    continue
                earlier = inputs[:inputs.index(pname)] if key == "inputs" else inputs
                if followed not in earlier:
                    rep.error(doc.pos(*path, what), f"port '{pname}' of '{ctype.name}' takes "
                              f"the {what} of '{followed}', which is no "
                              + ("earlier input" if key == "inputs" else "input") + " port",
                              did_you_mean(followed, earlier) or
                              f"write '{what}: <input>.{what}' with one of its inputs")
            if port.channels_param and ctype.params.get(port.channels_param, ParamDecl(
                    "", "")).type != "int":
                rep.error(doc.pos(*path, "channels"), f"channels of port '{pname}' of "
                          f"'{ctype.name}' name {port.channels_param!r}, which is no int "
                          "parameter", did_you_mean(port.channels_param, _int_params(ctype))
                          or "give a number, a list, 'any', '<input>.channels' or an int "
                          "parameter")
            if key == "outputs" and (port.dtypes or port.channel_counts or port.any_channels):
                what = "dtype" if port.dtypes else "channels"
                rep.error(doc.pos(*path, what), f"output '{pname}' of '{ctype.name}' may "
                          f"have several {what}: nothing would choose one",
                          f"give one, or follow an input: '{what}: "
                          f"{inputs[0] if inputs else '<input>'}.{what}'"
                          + (" or an int parameter" if what == "channels" else ""))
    if ctype.generic and "kernel" in spec:
        rep.error(doc.key_pos(*base, "kernel"), f"'{ctype.name}' has generic ports and a "
                  "hand-written kernel, which is written for one element type and channel "
                  "count", "give the type a fusable form instead (its kernel is generated "
                  "for each component), or fix its ports' dtype and channels")


def _port_sizes(doc, rep, path, ctype, port: PortDecl, quiet: bool = False) -> PortDecl:
    """Parse an output's size expressions; quiet: an input failed (already reported), so a
    missing size that the input would have given is not reported again."""
    spec = doc.data
    for key in path:
        spec = spec.get(key, {}) if isinstance(spec, dict) else {}
    trees = {}
    for dim in sizeexpr.DIMS:
        text = spec.get(dim) if isinstance(spec, dict) else None
        if text is None:
            if len(ctype.inputs) == 1:  # default: same size as the only input
                text = f"{next(iter(ctype.inputs))}.{dim}"
            elif quiet:
                continue
            else:
                rep.error(port.pos, f"output '{port.name}' of '{ctype.name}' needs '{dim}:'",
                          f"give a size expression, e.g. '{dim}: 480' or "
                          f"'{dim}: <input>.{dim}'")
                continue
        try:
            trees[dim] = sizeexpr.parse(text, set(ctype.inputs), set(_int_params(ctype)))
        except sizeexpr.SizeExprError as exc:
            rep.error(doc.pos(*path, dim), f"output '{port.name}' of '{ctype.name}': {exc}")
    return replace(port, height=trees.get("height"), width=trees.get("width"))


def _resolve_file(doc, rep, path, decl_dir: Path, value: Any, suffix: str,
                  what: str) -> tuple[Path, str] | None:
    """A kernel or Python file of a type and its text, or None after reporting why not.

    The file must be a regular file inside the folder of the type file, also after
    resolving symbolic links, at most MAX_SOURCE_BYTES long and UTF-8 text."""
    if not isinstance(value, str) or not value:
        rep.error(doc.pos(*path), f"expected a file name ending in {suffix}")
        return None
    rel = Path(value)
    if "\0" in value or rel.is_absolute() or ".." in rel.parts or rel.suffix != suffix:
        rep.error(doc.pos(*path), f"file {value!r} must be a relative path ending in {suffix}, "
                  "inside the folder of the type file", "move the file next to the type file")
        return None
    full = decl_dir / rel
    try:
        real = full.resolve()
        inside = real.is_relative_to(decl_dir.resolve())
    except (OSError, RuntimeError):  # a loop of links
        inside = False
    if not inside:
        rep.error(doc.pos(*path), f"file {value!r} is a link to a file outside the folder "
                  "of the type file", "copy the file next to the type file instead of "
                  "linking to it")
        return None
    shown = str(Path(doc.file).parent / rel)
    try:
        text = read_text(full, MAX_SOURCE_BYTES, f"{what} {value!r}")
    except FileProblem as exc:
        if exc.line:  # not UTF-8: say where in that file
            rep.diagnostics.append(Diagnostic(shown, exc.line, exc.col, "error", exc.message,
                                              exc.hint))
        elif exc.message.endswith("not found"):
            rep.error(doc.pos(*path), f"file {value!r} not found (looked in {decl_dir.name}/)",
                      "paths are relative to the component-type file")
        else:
            rep.error(doc.pos(*path), exc.message, exc.hint)
        return None
    return full, text


def _check_signature(doc, rep, base, ctype: ComponentType, kspec: dict) -> None:
    """The kernel's real definition takes what the calling convention passes."""
    pos = doc.pos(*base, "kernel", "function") if "function" in kspec else \
        doc.key_pos(*base, "kernel")
    shown = str(Path(doc.file).parent / kspec["file"])
    check, signature_error = signature_checker()  # kernel files are OpenCL C
    try:
        check(ctype, ctype.kernel_text, ctype.kernel_function)
    except signature_error as exc:
        where = f"{shown}:{exc.line}" if exc.line else shown
        rep.error(pos, f"kernel file {where}: {exc.message}", exc.hint)


def _no_array_params(doc, rep, base, ctype: ComponentType) -> None:
    """A hand-written kernel's arguments are numbers (the calling convention): array
    parameters reach generated kernels only."""
    for pname, decl in ctype.params.items():
        if decl.shape:
            rep.error(doc.pos(*base, "params", pname, "type"),
                      f"array parameter '{pname}' of '{ctype.name}' cannot reach a "
                      "hand-written kernel (its arguments are numbers)",
                      "declare a 'fusable:' form instead of 'kernel:' (its generated kernel "
                      "gets the array as a constant table), or pass numbers")


def _load_kernel(doc, rep, base, ctype: ComponentType, spec,
                 signature_check: bool = True) -> None:
    if "kernel" not in spec and "fusable" in spec:
        # the kernel is generated from the fusable form (backend/opencl/fused.py), for a
        # component alone as for a fused group: the operation is declared once
        ctype.grid = next(iter(ctype.outputs), "")
        ctype.cover = "rows"
        if "gpu" in spec:
            rep.error(doc.key_pos(*base, "gpu"),
                      f"'gpu' settings of '{ctype.name}' are for a hand-written kernel; its "
                      "kernel is generated from its fusable form, with the system's settings",
                      "remove 'gpu:' (or add 'kernel: {file, function}')")
        return
    kspec = _expect_map(doc, rep, base + ("kernel",), spec.get("kernel"), "kernel")
    if not kspec:
        rep.error(ctype.pos, f"GPU-aware type '{ctype.name}' needs 'kernel: {{file, function}}'",
                  "or a 'fusable:' form, from which the system generates its kernel")
        return
    _unknown_keys(doc, rep, base + ("kernel",), kspec, KERNEL_KEYS, "kernel")
    _no_array_params(doc, rep, base, ctype)
    found = _resolve_file(doc, rep, base + ("kernel", "file"), ctype.decl_file.parent,
                          kspec.get("file"), ".cl", "kernel file")
    if found is not None:
        ctype.kernel_file, ctype.kernel_text = found
    function = kspec.get("function", ctype.snake)
    problem = name_problem(function, "kernel function name")
    if problem:
        rep.error(doc.pos(*base, "kernel", "function"), problem)
    else:
        ctype.kernel_function = function
        if found is not None and signature_check:
            _check_signature(doc, rep, base, ctype, kspec)
    grid = kspec.get("grid", next(iter(ctype.outputs), ""))
    if not _named(grid, ctype.outputs):
        rep.error(doc.pos(*base, "kernel", "grid") if "grid" in kspec else ctype.pos,
                  f"kernel grid {grid!r} of '{ctype.name}' is not an output port",
                  did_you_mean(str(grid), ctype.outputs))
    else:
        ctype.grid = grid
    cover = kspec.get("cover", "squares")
    if cover not in COVERS:
        rep.error(doc.pos(*base, "kernel", "cover"),
                  f"kernel cover {cover!r} of '{ctype.name}' is not one of {list(COVERS)}",
                  "'squares': a work-group covers tile x tile pixels; 'rows': tile whole rows")
    else:
        ctype.cover = cover
    gspec = _expect_map(doc, rep, base + ("gpu",), spec.get("gpu"), "gpu")
    _unknown_keys(doc, rep, base + ("gpu",), gspec, GPU_KEYS, "gpu")
    decl = GpuDecl()
    tiles = gspec.get("tiles", list(decl.tiles))
    block_z = gspec.get("block_z", list(decl.block_z))
    for key, values in (("tiles", tiles), ("block_z", block_z)):
        if not isinstance(values, list) or not values or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in values):
            rep.error(doc.pos(*base, "gpu", key), f"gpu.{key} must be a list of positive integers")
            return
    prefer = _expect_map(doc, rep, base + ("gpu", "prefer"), gspec.get("prefer"), "prefer")
    _unknown_keys(doc, rep, base + ("gpu", "prefer"), prefer, SETTING_KEYS, "prefer")
    values = []
    for key, fallback in zip(SETTING_KEYS, decl.prefer):
        v = _positive_int(doc, rep, base + ("gpu", "prefer", key), prefer.get(key), key, fallback)
        values.append(v)
    max_threads = None
    if "max_threads" in gspec:
        max_threads = _positive_int(doc, rep, base + ("gpu", "max_threads"),
                                    gspec["max_threads"], "max_threads", None)
    square = gspec.get("square", False)
    if not isinstance(square, bool):
        rep.error(doc.pos(*base, "gpu", "square"), "gpu.square must be true or false")
        square = False
    if square and values[1] != values[2]:
        rep.error(doc.pos(*base, "gpu", "prefer") if prefer else doc.pos(*base, "gpu"),
                  f"gpu.prefer of '{ctype.name}' has block {values[1]}x{values[2]}, but "
                  "gpu.square asks for block_x == block_y",
                  "prefer a square block such as block_x: 16, block_y: 16")
    ctype.gpu = GpuDecl(tuple(sorted(set(tiles))), tuple(sorted(set(block_z))), tuple(values),
                        max_threads, square)


def _load_fusable(doc, rep, base, ctype: ComponentType, fspec) -> None:
    """The type's fusable form (gpucompgen/fusable.py), checked as far as possible without
    a device."""
    path = base + ("fusable",)
    fspec = _expect_map(doc, rep, path, fspec, "fusable")
    _unknown_keys(doc, rep, path, fspec, FUSABLE_KEYS, "fusable")
    form = fspec.get("form")
    if not _named(form, fusable_forms.FORMS):
        rep.error(doc.pos(*path, "form") if "form" in fspec else doc.key_pos(*path),
                  f"fusable form of '{ctype.name}' must be one of "
                  f"{', '.join(fusable_forms.FORMS)}, not {form!r}",
                  "pointwise: inputs read at (y, x); index_map: each input at one computed "
                  "position; stencil: a window of 'radius' with a 'border' rule")
        return
    if len(ctype.outputs) != 1:
        rep.error(doc.key_pos(*path), f"only types with a single output can be fusable; "
                  f"'{ctype.name}' has {len(ctype.outputs)}",
                  "remove 'fusable:' (the type stays opaque: its kernel runs on its own)")
        return
    value = fspec.get("value")
    if not isinstance(value, str) or not value.strip():
        rep.error(doc.pos(*path, "value") if "value" in fspec else doc.key_pos(*path),
                  f"fusable '{ctype.name}' needs 'value': an OpenCL C expression (or "
                  "statements ending in 'return ...;') for output element (y, x, c)",
                  "e.g. value: \"image(image_height - 1 - y, x, c)\"")
        return
    analysis = fusable_forms.analyse(value, form, list(ctype.inputs), list(ctype.outputs),
                                     list(ctype.params),
                                     arrays=[n for n, d in ctype.params.items() if d.shape])
    start = doc.pos(*path, "value")
    raw, style = doc.sources.get(path + ("value",), (None, None))
    for p in analysis.problems:
        at = fusable_forms.snippet_position(start, raw, style, value, p.offset)
        where = "" if at is not None else f" (at character {p.offset + 1} of the snippet)"
        rep.error(at or start, f"fusable snippet of '{ctype.name}': {p.message}{where}",
                  p.hint or "a snippet uses y, x, c, its ports as <port>(y, x, c), "
                  "<port>_height, <port>_width, its parameters and its own locals")
    radius: int | str = 0
    border = fspec.get("border", "clamp")
    if form == "stencil":
        radius = fspec.get("radius")
        int_params = _int_params(ctype)
        expression = None
        if isinstance(radius, str) and not _named(radius, int_params):
            try:  # an expression of int parameters, e.g. 'ksize // 2'
                expression = sizeexpr.parse(radius, set(), set(int_params))
            except sizeexpr.SizeExprError:
                expression = None
        if not (isinstance(radius, int) and not isinstance(radius, bool) and radius >= 0) \
                and not _named(radius, int_params) and expression is None:
            rep.error(doc.pos(*path, "radius") if "radius" in fspec else doc.key_pos(*path),
                      f"stencil '{ctype.name}' needs 'radius': a number of pixels (0 or "
                      f"more), an int parameter or an expression of them, not {radius!r}",
                      did_you_mean(str(radius), int_params) if int_params else
                      "e.g. radius: 1")
            return
        if border not in fusable_forms.BORDERS:
            rep.error(doc.pos(*path, "border"), f"stencil border {border!r} of "
                      f"'{ctype.name}' is not one of {list(fusable_forms.BORDERS)}",
                      "clamp: reads outside the input take the nearest edge pixel")
            return
    else:
        for key in ("radius", "border"):
            if key in fspec:
                rep.error(doc.key_pos(*path, key), f"'{key}' is only for the stencil form",
                          f"remove '{key}' or use 'form: stencil'")
    if analysis.problems:
        return
    ctype.fusable = fusable_forms.FusableDecl(form, value, analysis.tree, analysis.names,
                                              radius, border)


def _check_class(doc, rep, base, ctype: ComponentType, pspec: dict) -> None:
    """The Python file defines the class at module level: read with ast, never imported."""
    shown = str(Path(doc.file).parent / pspec["file"])
    try:
        module = ast.parse(ctype.python_text, shown)
    except SyntaxError as exc:
        rep.diagnostics.append(Diagnostic(shown, exc.lineno or 1, exc.offset or 1, "error",
                                          f"syntax error in Python file: {exc.msg}",
                                          "fix the module: the generated program imports it"))
        return
    except (ValueError, RecursionError, MemoryError) as exc:
        rep.error(doc.pos(*base, "python", "file"),
                  f"Python file {pspec['file']!r} cannot be read as Python: "
                  f"{type(exc).__name__}", "fix the module: the generated program imports it")
        return
    defined = module_names(module.body)
    if ctype.python_class not in defined:
        classes = [n for n, kind in defined.items() if kind == "class"]
        pos = doc.pos(*base, "python", "class") if "class" in pspec else \
            doc.key_pos(*base, "python")
        rep.error(pos, f"class '{ctype.python_class}' is not defined in {shown}",
                  did_you_mean(ctype.python_class, classes) if classes else
                  f"define 'class {ctype.python_class}:' at the top level of {pspec['file']}")


def module_names(body: list[ast.stmt]) -> dict[str, str]:
    """Names a module's top level binds: name -> "class" | "other" (also inside if/try/with
    blocks at module level, never inside functions or classes)."""
    names: dict[str, str] = {}
    for node in body:
        if isinstance(node, ast.ClassDef):
            names[node.name] = "class"
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            names.setdefault(node.name, "other")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            for alias in node.names:
                if alias.name != "*":
                    names.setdefault(alias.asname or alias.name.split(".")[0], "other")
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                for sub in ast.walk(target):
                    if isinstance(sub, ast.Name):
                        names.setdefault(sub.id, "other")
        elif isinstance(node, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
            blocks = [node.body, getattr(node, "orelse", []), getattr(node, "finalbody", [])]
            blocks += [h.body for h in getattr(node, "handlers", [])]
            for block in blocks:
                for name, kind in module_names(block).items():
                    if names.get(name) != "class":
                        names[name] = kind
    return names


def _load_python(doc, rep, base, ctype: ComponentType, spec) -> None:
    pspec = _expect_map(doc, rep, base + ("python",), spec.get("python"), "python")
    if not pspec:
        rep.error(ctype.pos, f"standard type '{ctype.name}' needs 'python: {{file, class}}'")
        return
    _unknown_keys(doc, rep, base + ("python",), pspec, PYTHON_KEYS, "python")
    found = _resolve_file(doc, rep, base + ("python", "file"), ctype.decl_file.parent,
                          pspec.get("file"), ".py", "Python file")
    if found is not None:
        ctype.python_file, ctype.python_text = found
    cls = pspec.get("class", ctype.name)
    problem = name_problem(cls, "class name", top_level=True)  # imported at module level
    if problem:
        rep.error(doc.pos(*base, "python", "class"), problem)
    else:
        ctype.python_class = cls
        if found is not None:
            _check_class(doc, rep, base, ctype, pspec)
    if ctype.python_file is not None and ctype.origin == "user":
        problem = name_problem(ctype.python_file.stem, "Python module name")
        if problem:
            rep.error(doc.pos(*base, "python", "file"), problem,
                      "rename the file to a valid module name")


def _load_cpu(doc, rep, base, ctype: ComponentType, spec) -> None:
    """A flexible type's CPU side: ``cpu: {file: x.py, function: f}``.

    The function takes every input port (a numpy array) and every parameter as keywords
    and returns the output array (a tuple of them for several outputs, in the type's
    order).  Its file is parsed with ast, never imported: it must define the function at
    module level, and the function must accept those keywords.
    """
    path = base + ("cpu",)
    cspec = _expect_map(doc, rep, path, spec.get("cpu"), "cpu")
    if not cspec:
        if "cpu" not in spec:
            rep.error(ctype.pos, f"flexible type '{ctype.name}' needs "
                      "'cpu: {file, function}', its CPU implementation",
                      "write a numpy function taking the inputs and parameters as keywords "
                      "and returning the output(s)")
        return
    _unknown_keys(doc, rep, path, cspec, CPU_KEYS, "cpu")
    found = _resolve_file(doc, rep, path + ("file",), ctype.decl_file.parent,
                          cspec.get("file"), ".py", "Python file")
    cpu_text = ""
    if found is not None:
        ctype.cpu_file, cpu_text = found
        ctype.cpu_text = cpu_text
    function = cspec.get("function", ctype.snake)
    fpos = doc.pos(*path, "function") if "function" in cspec else doc.key_pos(*path)
    problem = name_problem(function, "function name")
    if problem:
        rep.error(fpos, problem)
        return
    ctype.cpu_function = function
    if ctype.cpu_file is None:
        return
    if ctype.origin == "user":
        problem = name_problem(ctype.cpu_file.stem, "Python module name")
        if problem:
            rep.error(doc.pos(*path, "file"), problem, "rename the file to a valid module name")
    try:
        tree = ast.parse(cpu_text, str(ctype.cpu_file))
    except SyntaxError as exc:
        rep.error(doc.pos(*path, "file"), f"{ctype.cpu_file.name}:{exc.lineno}: {exc.msg}",
                  "fix the Python syntax of the CPU implementation")
        return
    found = next((n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
                  and n.name == function), None)
    if found is None:
        defined = [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]
        rep.error(fpos, f"{ctype.cpu_file.name} defines no function '{function}' at module "
                  "level", did_you_mean(function, defined) or
                  f"define 'def {function}({', '.join(ctype.inputs)}, ...)' there")
        return
    if isinstance(found, ast.AsyncFunctionDef):
        rep.error(fpos, f"'{function}' in {ctype.cpu_file.name} is async", "make it a plain def")
        return
    a = found.args
    named = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    wanted = list(ctype.inputs) + list(ctype.params)
    positional_only = {x.arg for x in a.posonlyargs}
    missing = [w for w in wanted if w not in named or w in positional_only]
    if missing and a.kwarg is None:
        rep.error(fpos, f"function '{function}' in {ctype.cpu_file.name} does not take "
                  + ", ".join(f"'{m}'" for m in missing) + " as keyword"
                  + ("s" if len(missing) > 1 else ""),
                  f"it is called as {function}("
                  + ", ".join(f"{w}=..." for w in wanted) + "): add the missing parameters")
    # parameters it has that the call never passes must have defaults
    n_pos = len(a.posonlyargs) + len(a.args)
    pos_defaults = n_pos - len(a.defaults)
    unfilled = [x.arg for i, x in enumerate(a.posonlyargs + a.args)
                if i < pos_defaults and x.arg not in wanted]
    unfilled += [x.arg for x, d in zip(a.kwonlyargs, a.kw_defaults)
                 if d is None and x.arg not in wanted]
    if unfilled:
        rep.error(fpos, f"function '{function}' in {ctype.cpu_file.name} needs "
                  + ", ".join(f"'{u}'" for u in unfilled) + f", which is no input or "
                  f"parameter of '{ctype.name}'",
                  "give it a default, or declare it as a parameter of the type")


_LIBRARY_CACHE: dict[str, ComponentType] | None = None


def library_types() -> dict[str, ComponentType]:
    """Component types shipped with gpucompgen (gpucompgen/library/*.yaml)."""
    global _LIBRARY_CACHE
    if _LIBRARY_CACHE is None:
        rep = Reporter()
        types: dict[str, ComponentType] = {}
        for path in sorted(LIBRARY_DIR.glob("*.yaml")):
            types.update(load_types_file(path, f"<gpucompgen>/library/{path.name}", "library",
                                         rep))
        rep.raise_if_errors()
        _LIBRARY_CACHE = types
    return dict(_LIBRARY_CACHE)


# --------------------------------------------------------------------------- systems

SYSTEM_KEYS = ("system", "description", "types", "platform", "components", "connections")
PLATFORM_KEYS = ("device", "gpu_settings", "thread_budget", "execution", "zero_copy",
                 "placement", "profile", "frames_in_flight", "staging", "fusion", "backend")
FUSION = ("auto", "off")
EXECUTIONS = ("parallel", "sequential")
ZERO_COPY = ("auto", "on", "off")
STAGING = ("auto", "pinned", "pageable")
MAX_FRAMES_IN_FLIGHT = 16
INSTANCE_KEYS = ("type", "params", "description", "placement", "fuse")
CONNECTION_RE = re.compile(r"^\s*([^\s.]+)\.([^\s.]+)\s*->\s*([^\s.]+)\.([^\s.]+)\s*$")


TYPE_FILE_SUFFIXES = (".yaml", ".yml")
# a model names a library type shadowed by its own type of the same name as lib.Name
LIBRARY_PREFIX = "lib."


def _load_user_types(doc: Document, rep: Reporter, path: Path, display: str, i: int,
                     rel: Any, read: dict[Path, tuple[int, int]], texts: dict[Path, str]
                     ) -> dict[str, ComponentType] | None:
    """The types of entry i of the model's 'types:' list, or None after reporting why not.

    A type file is any .yaml/.yml file, relative to the model (``../shared/types.yaml``)
    or absolute, so models can share type files.  Nothing of a file that does not start
    as a component-type file (``component_types:``) is ever quoted in a message."""
    pos = doc.pos("types", i)
    if not isinstance(rel, str) or not rel:
        rep.error(pos, "expected the path of a component-type .yaml file")
        return None
    if "\0" in rel or not rel.endswith(TYPE_FILE_SUFFIXES):
        rep.error(pos, f"component-type file {rel!r} must be a .yaml or .yml file",
                  "component types are declared in YAML files that start with "
                  "'component_types:'")
        return None
    tpath = path.parent / rel
    shown = str(Path(display).parent / rel)
    what = f"component-type file {rel!r}"
    try:
        first = read.get(tpath.resolve())
    except (OSError, RuntimeError):  # a link loop: read_text says what is wrong
        first = None
    if first is not None:
        rep.error(pos, f"{what} is listed twice (also entry {first[0] + 1} of 'types:')",
                  "list each type file once")
        return {}
    try:
        text = read_text(tpath, MAX_FILE_BYTES, what)
    except FileProblem as exc:
        if exc.line and starts_with_key(exc.prefix, "component_types"):
            rep.diagnostics.append(Diagnostic(shown, exc.line, exc.col, "error",
                                              exc.message, exc.hint))
        elif exc.line:
            rep.error(pos, f"{what} is not a component-type file (it is not UTF-8 text)",
                      "a component-type file starts with 'component_types:'")
        else:
            rep.error(pos, exc.message, "paths are relative to the model file"
                      if exc.message.endswith("not found") else exc.hint)
        return None
    size = len(text.encode("utf-8", "surrogatepass"))
    total = size + sum(n for _, n in read.values())
    if total > MAX_TYPE_BYTES:
        rep.error(pos, f"the model's type files come to {total:,} bytes with {rel!r}; at most "
                  f"{MAX_TYPE_BYTES:,} are allowed", "keep only the types the model uses")
        return None
    read[tpath.resolve()] = (i, size)
    texts[tpath.resolve()] = text
    if not starts_with_key(text, "component_types"):
        rep.error(pos, f"{what} is not a component-type file",
                  "a component-type file starts with 'component_types:' (its content is "
                  "not shown)")
        return None
    try:
        return load_types_file(tpath.resolve(), shown, "user", rep, load_text(text, shown))
    except GpucompgenError as exc:
        rep.diagnostics.extend(exc.diagnostics)
        return None


def load_system(path: Path, display: str | None = None) -> SystemModel:
    """Load a system model and everything it refers to; raise GpucompgenError on problems."""
    display = display or str(path)
    doc = load_file(path, display)
    rep = Reporter()
    if doc.data is None:
        rep.error(doc.pos(), "the model is empty",
                  "a model starts with 'system: <name>' and lists 'components:'")
    elif not isinstance(doc.data, dict):
        rep.error(doc.pos(), f"a system model must be a mapping, not {_kind(doc.data)}",
                  "a model is a mapping of keys: 'system: <name>', 'components:', ...")
    rep.raise_if_errors()
    root = doc.data
    _unknown_keys(doc, rep, (), root, SYSTEM_KEYS, "the system model")
    name = root.get("system")
    problem = name_problem(name, "system name", top_level=True)
    if not problem and name in MODULE_NAMES:
        problem = (f"system name '{name}' would make {name}.py, which hides the module "
                   f"'{name}' that generated programs import")
    if problem:
        rep.error(doc.pos("system") if "system" in root else doc.pos(), problem,
                  "start the model with 'system: my_system'")
        name = "system"
    description = _text(doc, rep, ("description",), root.get("description"), "description")
    # component types: library, then the user's files
    types = library_types()
    type_files = root.get("types") or []
    if not isinstance(type_files, list):
        rep.error(doc.pos("types"), "types must be a list of component-type files")
        type_files = []
    elif len(type_files) > MAX_TYPE_FILES:
        rep.error(doc.key_pos("types"), f"the model lists {len(type_files):,} type files; "
                  f"at most {MAX_TYPE_FILES} are allowed", "put related types in one file")
        rep.raise_if_errors()
    types_failed = False  # a type file could not be read: its types are not "unknown"
    library = dict(types)
    folded_types = {fold(t): t for t in types}
    notes: list[Diagnostic] = []
    read: dict[Path, tuple[int, int]] = {}  # type file read -> (index in the list, bytes)
    texts: dict[Path, str] = {}  # type file read -> its text
    for i, rel in enumerate(type_files):
        user = _load_user_types(doc, rep, path, display, i, rel, read, texts)
        types_failed |= user is None
        user = user or {}
        for tname, ctype in user.items():
            clash = folded_types.get(fold(tname))
            if clash is not None and types[clash].origin == "library":
                # The user's own type is the one their model gets: a type the library adds
                # later never breaks a model that worked before.
                del types[clash]
                notes.append(Diagnostic(ctype.pos.file, ctype.pos.line, ctype.pos.col, "note",
                                        f"component type '{tname}' shadows the library's "
                                        f"'{clash}'", f"the model gets this file's '{tname}'; "
                                        f"write '{LIBRARY_PREFIX}{clash}' for the library's"))
            elif clash is not None:
                rep.error(ctype.pos, f"component type '{tname}' is already defined elsewhere"
                          + ("" if clash == tname else f" as '{clash}'"),
                          "give your type another name (case and underscores do not count)")
                continue
            types[tname] = ctype
            folded_types[fold(tname)] = tname
    # platform
    platform = _expect_map(doc, rep, ("platform",), root.get("platform"), "platform")
    _unknown_keys(doc, rep, ("platform",), platform, PLATFORM_KEYS, "platform")
    device = platform.get("device", "portable")
    overrides: dict[str, tuple[dict[str, int], Pos]] = {}
    settings = _expect_map(doc, rep, ("platform", "gpu_settings"), platform.get("gpu_settings"),
                           "gpu_settings")
    for cname, written in settings.items():
        spath = ("platform", "gpu_settings", cname)
        sspec = _expect_map(doc, rep, spath, written, f"gpu_settings of '{cname}'")
        _unknown_keys(doc, rep, spath, sspec, SETTING_KEYS, f"gpu_settings of '{cname}'")
        values = {}
        for key in SETTING_KEYS:
            if key in sspec:
                v = _positive_int(doc, rep, spath + (key,), sspec[key], key)
                if v is not None:
                    values[key] = v
        overrides[cname] = (values, doc.key_pos(*spath))
    budget = _positive_int(doc, rep, ("platform", "thread_budget"),
                           platform.get("thread_budget"), "thread_budget")
    execution = platform.get("execution", "parallel")
    if execution not in EXECUTIONS:
        rep.error(doc.pos("platform", "execution"),
                  f"platform.execution must be 'parallel' or 'sequential', not {execution!r}")
        execution = "parallel"
    zero_copy = platform.get("zero_copy", "auto")
    if isinstance(zero_copy, bool):  # YAML 1.1 reads on/off as booleans
        zero_copy = "on" if zero_copy else "off"
    if zero_copy not in ZERO_COPY:
        rep.error(doc.pos("platform", "zero_copy"),
                  f"platform.zero_copy must be 'auto', 'on' or 'off', not {zero_copy!r}")
        zero_copy = "auto"
    fusion = platform.get("fusion", "auto")
    if isinstance(fusion, bool):  # YAML 1.1 reads off as a boolean
        fusion = "auto" if fusion else "off"
    if fusion not in FUSION:
        rep.error(doc.pos("platform", "fusion"),
                  f"platform.fusion must be 'auto' or 'off', not {fusion!r}",
                  "auto: chains of fusable GPU components run as one kernel")
        fusion = "auto"
    backend = platform.get("backend", DEFAULT_BACKEND)
    if backend not in BACKENDS:
        rep.error(doc.pos("platform", "backend"),
                  f"platform.backend must be one of {', '.join(BACKENDS)}, not {backend!r}",
                  did_you_mean(str(backend), list(BACKENDS)))
        backend = DEFAULT_BACKEND
    placement = platform.get("placement", "")  # "": decided for the device (place.py)
    if "placement" in platform and not _named(placement, PLACEMENTS):
        rep.error(doc.pos("platform", "placement"),
                  f"platform.placement must be 'gpu', 'cpu' or 'auto', not {placement!r}",
                  "it places the flexible components that say nothing themselves")
        placement = ""
    profile = None
    if "profile" in platform:
        rel = platform["profile"]
        ppos = doc.pos("platform", "profile")
        if not isinstance(rel, str) or not rel.endswith((".yaml", ".yml")):
            rep.error(ppos, "platform.profile must be the path of a .yaml profile",
                      "e.g. 'profile: tune/my_system.yaml', written by 'gpucompgen tune'")
        else:  # read (and found missing) only where a placement is 'auto'
            profile = path.parent / rel
    frames_in_flight = 1
    if "frames_in_flight" in platform:
        frames_in_flight = _positive_int(doc, rep, ("platform", "frames_in_flight"),
                                         platform["frames_in_flight"], "frames_in_flight") or 1
        if frames_in_flight > MAX_FRAMES_IN_FLIGHT:
            rep.error(doc.pos("platform", "frames_in_flight"),
                      f"platform.frames_in_flight is {frames_in_flight}; at most "
                      f"{MAX_FRAMES_IN_FLIGHT} frames can be in flight",
                      "2 or 3 overlap sources, device work and sinks; each frame in flight "
                      "costs one more set of the buffers it crosses stages with")
            frames_in_flight = 1
    staging = platform.get("staging", "auto")
    if not _named(staging, STAGING):
        rep.error(doc.pos("platform", "staging"),
                  f"platform.staging must be 'auto', 'pinned' or 'pageable', not {staging!r}",
                  "auto stages copies through pinned host buffers when the device has no "
                  "unified host memory")
        staging = "auto"
    # components
    components: dict[str, Instance] = {}
    comps = _expect_map(doc, rep, ("components",), root.get("components"), "components")
    if not comps:
        rep.error(doc.pos("components") if "components" in root else doc.pos(),
                  "the system has no components", "add 'components:' with named instances")
    elif len(comps) > MAX_COMPONENTS:
        rep.error(doc.key_pos("components"),
                  f"the system has {len(comps):,} components; at most {MAX_COMPONENTS:,} "
                  "are allowed", "split it into several systems")
        rep.raise_if_errors()
    folded: dict[str, str] = {}
    for order, (cname, written) in enumerate(comps.items()):
        cpath = ("components", cname)
        problem = name_problem(cname, "component name", top_level=True)
        if problem:
            rep.error(doc.key_pos(*cpath), problem, "use a name such as 'camera1'")
            continue
        if fold(cname) in folded:
            rep.error(doc.key_pos(*cpath),
                      f"component name '{cname}' collides with '{folded[fold(cname)]}'",
                      "names must differ by more than case and underscores")
            continue
        folded[fold(cname)] = cname
        cspec = _expect_map(doc, rep, cpath, {"type": written} if isinstance(written, str)
                            else written, f"component '{cname}'")
        _unknown_keys(doc, rep, cpath, cspec, INSTANCE_KEYS, f"component '{cname}'")
        tname = cspec.get("type")
        if isinstance(tname, str) and tname.startswith(LIBRARY_PREFIX) and \
                tname[len(LIBRARY_PREFIX):] in library:
            ctype = library[tname[len(LIBRARY_PREFIX):]]  # the library's, even if shadowed
        elif not _named(tname, types):
            if types_failed and isinstance(tname, str):
                continue
            rep.error(doc.pos(*cpath, "type") if "type" in cspec else doc.key_pos(*cpath),
                      f"unknown component type {tname!r} for '{cname}'",
                      did_you_mean(str(tname), types))
            continue
        else:
            ctype = types[tname]
        params = _instance_params(doc, rep, cpath, ctype, cspec.get("params"))
        _sizes_from_input(doc, rep, cpath, ctype, params, cspec.get("params"), path.parent)
        fuse = cspec.get("fuse", True)
        if not isinstance(fuse, bool):
            rep.error(doc.pos(*cpath, "fuse"), f"fuse of '{cname}' must be true or false, "
                      f"not {fuse!r}", "'fuse: false' keeps the component out of every "
                      "group (it runs its kernel alone)")
            fuse = True
        where, where_pos = cspec.get("placement", ""), None
        if "placement" in cspec:
            where_pos = doc.pos(*cpath, "placement")
            where = placement_problem(rep, where_pos, cname, ctype, where)
        components[cname] = Instance(cname, ctype, params, doc.key_pos(*cpath), order,
                                     where, where_pos, fuse=fuse)
    _check_class_names(doc, rep, components)
    for cname, (_, pos) in overrides.items():
        if cname not in components and cname in comps:
            continue
        if cname not in components:
            rep.error(pos, f"gpu_settings for unknown component '{cname}'",
                      did_you_mean(cname, comps))
        elif not components[cname].type.gpu_aware:
            rep.error(pos, f"gpu_settings for '{cname}', which is a standard component",
                      "only GPU-aware components take GPU settings")
    # connections
    connections = []
    conns = root.get("connections") or []
    if not isinstance(conns, list):
        rep.error(doc.pos("connections"), "connections must be a list of "
                  "'producer.port -> consumer.port'")
        conns = []
    elif len(conns) > MAX_CONNECTIONS:
        rep.error(doc.key_pos("connections"),
                  f"the system has {len(conns):,} connections; at most {MAX_CONNECTIONS:,} "
                  "are allowed", "split it into several systems")
        rep.raise_if_errors()
    renamed: dict[str, tuple[Pos, dict[str, str]]] = {}  # component -> old port names used
    for i, text in enumerate(conns):
        conn = _parse_connection(doc, rep, ("connections", i), text, comps, components,
                                 renamed)
        if conn is not None:
            connections.append(conn)
    rep.raise_if_errors()
    notes += sorted(_deprecation_notes(doc, components, library | types, renamed))
    model_bytes = path.read_bytes()
    model = SystemModel(name=name, description=description, file=path, display=display,
                       text_sha256=hashlib.sha256(model_bytes).hexdigest(),
                       components=components, connections=connections, device=device,
                       device_pos=doc.pos("platform", "device"), gpu_overrides=overrides,
                       thread_budget=budget,
                       thread_budget_pos=doc.pos("platform", "thread_budget"), types=types, execution=execution,
                       zero_copy=zero_copy, frames_in_flight=frames_in_flight,
                       staging=staging, platform_pos=doc.pos("platform"), fusion=fusion,
                       backend=backend,
                       placement=placement, placement_pos=doc.pos("platform", "placement"),
                       profile=profile, profile_pos=doc.pos("platform", "profile"),
                       notes=notes,
                       load_warnings=rep.warnings,
                       device_positions={k: (doc.key_pos("platform", "device", k),
                                             doc.pos("platform", "device", k))
                                         for k in (device if isinstance(device, dict) else {})
                                         if isinstance(k, str)})
    model.add_input(path, model_bytes)
    for tpath, text in texts.items():
        model.add_input(tpath, text)
    for t in types.values():
        if t.origin != "user":
            continue
        for source, text in ((t.kernel_file, t.kernel_text), (t.python_file, t.python_text),
                             (t.cpu_file, t.cpu_text)):
            if source is not None:
                model.add_input(source, text)
    return model


def _check_class_names(doc: Document, rep: Reporter, components: dict[str, Instance]) -> None:
    """Names the generated program gives classes: those of the types the model uses.

    A component is a variable of run(): it must not hide a class the program defines or
    imports (a GPU-aware type's own class, or a standard type's Python class).  Only the
    types used count, so a type the library adds can never collide with a model's names.
    Two types used under names that differ only by case and underscores (the user's own
    'AbsDiff' and the library's 'lib.AbsDiff') would be two classes of one name.
    """
    used: dict[str, ComponentType] = {}
    for inst in components.values():
        first = used.setdefault(fold(inst.type.name), inst.type)
        if first is not inst.type:
            rep.error(inst.pos, f"component '{inst.name}' uses the library's type "
                      f"'{LIBRARY_PREFIX}{inst.type.name}' and the model also uses its own "
                      f"'{first.name}'" if inst.type.origin == "library" else
                      f"component '{inst.name}' uses the model's own type '{inst.type.name}' "
                      f"and the model also uses the library's '{LIBRARY_PREFIX}{first.name}'",
                      "the generated program names a class after each type: rename your own "
                      "type to use both")
    class_names = {t.python_class or t.name: t.name for t in used.values()}
    class_names.update({t.name: t.name for t in used.values()})
    for inst in components.values():
        clash = class_names.get(inst.name)  # `Camera = Camera()` would shadow the class
        if clash is not None:
            rep.error(doc.key_pos("components", inst.name),
                      f"component name '{inst.name}' collides with "
                      + (f"component type '{clash}'" if clash == inst.name else
                         f"the Python class of component type '{clash}'"),
                      "the generated program uses type names as class names: name the "
                      f"component after its role, e.g. '{snake(clash)}1'")


def placement_problem(rep: Reporter, pos: Pos, cname: str, ctype: ComponentType,
                      where: Any) -> str:
    """The placement asked for a component, or "" after reporting why it cannot be."""
    if not _named(where, PLACEMENTS):
        rep.error(pos, f"placement of '{cname}' must be 'gpu', 'cpu' or 'auto', not {where!r}",
                  did_you_mean(str(where), PLACEMENTS))
        return ""
    side = {"gpu-aware": "gpu", "standard": "cpu"}.get(ctype.kind)
    if side is not None and where != side:
        shown = "automatically ('auto')" if where == "auto" else f"on the {where.upper()}"
        rep.error(pos, f"'{cname}' cannot be placed {shown}: its type '{ctype.name}' is "
                  f"{ctype.kind} and runs on the {side.upper()} only",
                  "only flexible types (kind: flexible, with a kernel and a 'cpu:' function) "
                  "can be placed; remove 'placement:'")
        return ""
    return where


def _instance_params(doc, rep, cpath, ctype: ComponentType, given) -> dict[str, Any]:
    given = _expect_map(doc, rep, cpath + ("params",), given, "params")
    params: dict[str, Any] = {}
    for pname, value in given.items():
        decl = ctype.params.get(pname)
        if decl is None:
            rep.error(doc.key_pos(*cpath, "params", pname),
                      f"'{ctype.name}' has no parameter '{pname}'",
                      did_you_mean(pname, ctype.params) or f"'{ctype.name}' takes no parameters")
            continue
        problem, at = _value_problem_at(value, decl, ctype.gpu_aware)
        if problem:
            hint = ""
            if decl.invertible and _array_problem(value, decl, ctype.gpu_aware) is None:
                hint = ("give an invertible matrix: no row a combination of the others "
                        "(of a 2x3, of its left 2x2)")
            elif decl.shape:
                hint = (f"give {decl.type}: nested lists of {decl.element} values within "
                        "the parameter's range"
                        + (f", e.g. '{pname}: {py_yaml(decl.default)}'"
                           if decl.default is not None and len(str(decl.default)) <= 60
                           else ""))
            elif isinstance(value, bool) and decl.type in ("str", "path", "input"):
                hint = "YAML 1.1 reads yes/no/on/off as booleans: quote the value"
            elif decl.type in ("int", "float") and _value_fits(value, decl.type):
                hint = "give a value within the parameter's range"
            else:
                example = decl.default if decl.default not in (None, "") else \
                    {"int": 1, "float": 1.0, "bool": True, "str": "text", "path": "images",
                     "input": "shots/"}[decl.type]
                wanted = {"int": "an integer", "float": "a number", "bool": "true or false",
                          "str": "a string (quoted if it looks like a number or boolean)",
                          "path": "a path, relative to the model file or absolute",
                          "input": "an input URI or a path relative to the model file"}
                hint = f"give {wanted[decl.type]}, e.g. '{pname}: {py_yaml(example)}'"
            rep.error(doc.pos(*cpath, "params", pname, *at),
                      f"parameter '{pname}' of '{ctype.name}' {problem}", hint)
            continue
        params[pname] = param_value(value, decl)
    for pname, decl in ctype.params.items():
        if pname not in params and pname not in given:
            if decl.required:
                rep.error(doc.key_pos(*cpath), f"component '{cpath[-1]}' of type "
                          f"'{ctype.name}' needs parameter '{pname}' ({decl.type})",
                          f"add 'params: {{{pname}: ...}}'")
            else:
                params[pname] = decl.default
    return params


def _sizes_from_input(doc, rep, cpath, ctype: ComponentType, params: dict, given,
                      model_dir: Path) -> None:
    """A source's 'input' parameter names images, a video or a recording: its frame size is
    read from the header (never user code) into the size parameters the model left out,
    and checked against those it gave.  A missing or empty input is an error where the
    size depends on it, else a warning (the program may be run with --input elsewhere)."""
    given = given if isinstance(given, dict) else {}
    inputs = [p for p, d in ctype.params.items() if d.type == "input" and params.get(p)]
    if len(inputs) > 1:
        rep.error(doc.pos(*cpath, "params", inputs[1]),
                  f"'{cpath[-1]}' sets {' and '.join(repr(p) for p in inputs)}: one input only",
                  f"keep one of them ('{inputs[0]}' or '{inputs[1]}')")
        return
    if not inputs or not isinstance(params[inputs[0]], str):
        return
    pname = inputs[0]
    dims = {}  # 'height'/'width' -> the parameter an output's size is
    for port in ctype.outputs.values():
        for dim in ("height", "width"):
            expr = getattr(port, dim)
            if expr is not None and isinstance(expr.body, ast.Name) \
                    and expr.body.id in ctype.params:
                dims[dim] = expr.body.id
    if not dims:
        return
    from .io.probe import probe_size
    from .runtime.errors import PipelineError

    missing = [p for p in dims.values() if p not in given]
    where = doc.pos(*cpath, "params", pname)
    try:
        size = probe_size(params[pname], model_dir)
    except PipelineError as exc:
        if missing:
            rep.error(where, f"input of '{cpath[-1]}': {exc}",
                      f"fix '{pname}', or give {' and '.join(missing)} (then the program "
                      "can be run with --input)")
        else:
            rep.warning(where, f"input of '{cpath[-1]}': {exc}",
                        f"the program will need --input {cpath[-1]}=URI")
        return
    if size is None:
        if missing:
            rep.error(where, f"the frame size of '{params[pname]}' (a live camera or stream) "
                      "is not known before it runs",
                      f"give {' and '.join(missing)} in 'params'")
        return
    for dim, value in zip(("height", "width"), size):
        p = dims.get(dim)
        if p is None:
            continue
        if p not in given:
            params[p] = value
        elif given[p] != value:
            rep.error(doc.pos(*cpath, "params", p),
                      f"'{p}' of '{cpath[-1]}' is {given[p]}, but '{params[pname]}' has frames "
                      f"of {size[1]}x{size[0]} (width x height)",
                      f"set '{p}: {value}', or leave it out: it is read from the input")


def _deprecation_notes(doc: Document, components: dict[str, Instance],
                       types: dict[str, ComponentType], renamed: dict[str, tuple[Pos, dict[str, str]]]) -> list[Diagnostic]:
    """check's notes on deprecated names the model uses: a type alias ('ErodeGray'), old
    port names ('erode.eroded').  Both keep working; the notes say what to write."""
    notes = []
    for inst in components.values():
        t = inst.type
        if t.alias_of:
            pos = doc.pos("components", inst.name, "type") if isinstance(
                doc.data["components"][inst.name], dict) else doc.pos("components", inst.name)
            notes.append(Diagnostic(pos.file, pos.line, pos.col, "note",
                                    f"'{t.name}' of '{inst.name}' is a deprecated name of "
                                    f"'{t.alias_of}' with {_alias_channels(t)}",
                                    f"write 'type: {t.alias_of}': it takes "
                                    f"{_generic_channels(types.get(t.alias_of))} channels, "
                                    "from what feeds it"))
        if inst.name in renamed:
            pos, old = renamed[inst.name]
            notes.append(Diagnostic(pos.file, pos.line, pos.col, "note",
                                    f"'{inst.name}' ({t.name}) is connected by old port "
                                    f"names: " + ", ".join(f"'{o}' is now '{n}'"
                                                           for o, n in old.items()),
                                    "the old names work for now; write "
                                    + ", ".join(f"'{inst.name}.{n}'" for n in old.values())))
    return notes


def _alias_channels(t: ComponentType) -> str:
    n = t.alias_channels
    return f"{n} channel{'s' if n != 1 else ''}" if n else "the same ports"


def _generic_channels(real: ComponentType | None) -> str:
    port = next(iter(real.inputs.values()), None) if real is not None else None
    return port.channels_text().replace("|", " or ") if port is not None else "any"


def _parse_connection(doc, rep, path, text, comps, components,
                      renamed: dict | None = None) -> Connection | None:
    pos = doc.pos(*path)
    if isinstance(text, dict) and set(text) == {"from", "to"}:
        text = f"{text['from']} -> {text['to']}"
    if not isinstance(text, str):
        rep.error(pos, "a connection is written 'producer.port -> consumer.port'")
        return None
    m = CONNECTION_RE.match(text)
    if not m:
        rep.error(pos, f"cannot read connection {text!r}",
                  "write it as 'producer.port -> consumer.port'")
        return None
    src, dst = Endpoint(m[1], m[2]), Endpoint(m[3], m[4])
    ok = True
    for written, want in ((src, "out"), (dst, "in")):
        end = written
        if end.component not in components:
            if end.component not in comps:  # else: already reported where it was declared
                rep.error(pos, f"unknown component '{end.component}' in connection",
                          did_you_mean(end.component, comps))
            ok = False
            continue
        ctype = components[end.component].type
        canonical = ctype.canonical_port(end.port)
        if canonical is not None and canonical != end.port:  # a deprecated name
            if renamed is not None:
                renamed.setdefault(end.component, (pos, {}))[1][end.port] = canonical
            end = Endpoint(end.component, canonical)
            if want == "out":
                src = end
            else:
                dst = end
        port = ctype.port(end.port)
        if port is None:
            rep.error(pos, f"'{end.component}' ({ctype.name}) has no port '{end.port}'",
                      did_you_mean(f"{end.component}.{end.port}",
                                   [f"{end.component}.{p}" for p in
                                    (ctype.outputs if want == "out" else ctype.inputs)]))
            ok = False
        elif port.direction != want:
            if want == "out":
                rep.error(pos, f"connection from '{end}', which is an input",
                          "a connection goes from an output to an input: "
                          "'producer.out -> consumer.in'")
            else:
                rep.error(pos, f"connection to '{end}', which is an output",
                          "a connection goes from an output to an input: "
                          "'producer.out -> consumer.in'")
            ok = False
    return Connection(src, dst, pos) if ok else None
