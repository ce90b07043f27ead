"""What a model declares, as typed records: component types (ports, parameters, GPU
settings), the components of a system (instances), its connections and the system model
itself; the words the model language knows (element types, kinds, families, placements)
and the bounds on a system's size."""

from __future__ import annotations

import ast
import copy
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import fusable as fusable_forms
from ..dataflow import Endpoint
from ..errors import Diagnostic, Pos
from ..names import snake

DTYPES = {  # element type → (numpy name, OpenCL C type, bytes)
    "uint8": ("uint8", "uchar", 1),
    "int8": ("int8", "char", 1),
    "uint16": ("uint16", "ushort", 2),
    "int16": ("int16", "short", 2),
    "int32": ("int32", "int", 4),
    "uint32": ("uint32", "uint", 4),
    "float32": ("float32", "float", 4),
}
# OpenCV's depth codes (CV_8U .. CV_32F), for an output whose element type an int
# parameter gives ('dtype: ddepth', as cv2.filter2D's ddepth; -1: the first input's)
DEPTH_CODES = {0: "uint8", 1: "int8", 2: "uint16", 3: "int16", 4: "int32", 5: "float32"}
MEMORIES = ("gpu", "cpu")
# a generic port's 'dtype: any' (every element type) or 'channels: any' (any count)
ANY = ("any",)


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
    aliases: tuple[str, ...] = ()  # old names of the parameter, still accepted (deprecated)

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
    dtype_param: str = ""  # 'dtype: ddepth' (outputs): int parameter ddepth, OpenCV's
    # depth code (DEPTH_CODES; -1: the first input's element type)
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
        return bool(self.dtypes or self.dtype_of or self.dtype_param or self.channel_counts
                    or self.any_channels
                    or self.channels_of or self.channels_param)

    def dtype_text(self) -> str:
        """The element type as declared: 'uint8', 'uint8|int16' or 'as src'."""
        if self.dtype_of:
            return f"as {self.dtype_of}"
        if self.dtype_param:
            return f"parameter {self.dtype_param}"
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

    def canonical_param(self, name: str) -> str | None:
        """The parameter a name (its own or a deprecated alias) stands for, or None."""
        if name in self.params:
            return name
        return next((p.name for p in self.params.values() if name in p.aliases), None)

    def specialized(self, dtype: str | None = None, channels: int | None = None,
                    params: dict[str, Any] | None = None) -> ComponentType:
        """A copy whose generic ports are fixed: inputs that accept several take dtype and
        channels (their first choice when not given), ports that follow another port or a
        parameter take its value (params: the parameters' values, else their defaults).
        For tests, benchmarks and examples: a model's components are resolved from what
        feeds them (passes/resolve_types.py)."""
        from ..typeresolve import resolve_ports

        given = {p: (dtype, channels) for p in self.inputs}
        ports = resolve_ports(self, given, {**{p: d.default for p, d in self.params.items()},
                                            **(params or {})})
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
