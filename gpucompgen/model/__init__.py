"""The typed model: component types (ports, parameters, kernels) and system models.

Built from positioned YAML documents (see loader.py).  Every problem found while building
is reported through a Reporter with the exact position; building goes on so that one run
shows all problems at once.

One module per concern, one loader per section of the files:

- decls.py: the records (ParamDecl, PortDecl, GpuDecl, ComponentType, Instance,
  Connection, SystemModel), the words of the language and the bounds on a system's size
- fields.py: reading one value of a mapping, with its position
- params.py: parameter types, array shapes and values; a type's 'params:'
- ports.py: a type's 'inputs:' and 'outputs:' (generic ports, output sizes)
- sources.py: a type's kernel, Python and CPU files; its Python class and CPU function
- kernel.py: a type's 'kernel:', 'gpu:' and 'fusable:'
- types.py: a file of component types, each type section by section; aliases; the library
- type_files.py: a model's 'types:' (the user's files, shadowing the library)
- platform.py: a model's 'platform:'
- components.py: a model's 'components:' (parameter values, placement, class names)
- connections.py: a model's 'connections:'
- system.py: load_system, a model file section by section into a SystemModel

This package's names are those importers use (``from gpucompgen.model import ...``).
"""

from __future__ import annotations

from ..backend import BACKENDS
from ..dataflow import Endpoint
from .components import INSTANCE_KEYS, placement_problem
from .connections import CONNECTION_RE
from .decls import (
    ANY,
    COVERS,
    DTYPES,
    FAMILIES,
    KINDS,
    MAX_COMPONENTS,
    MAX_CONNECTIONS,
    MAX_PARAMS,
    MAX_PORTS,
    MAX_TYPE_BYTES,
    MAX_TYPE_FILES,
    MEMORIES,
    PLACEMENTS,
    SETTING_KEYS,
    ComponentType,
    Connection,
    GpuDecl,
    Instance,
    ParamDecl,
    PortDecl,
    SystemModel,
)
from .kernel import FUSABLE_KEYS, GPU_KEYS, KERNEL_KEYS, STAGE_KEYS
from .params import (
    ARRAY_TYPE,
    ARRAY_TYPE_PATTERN,
    FLOAT32_MAX,
    INT32,
    MAX_ARRAY_ELEMENTS,
    PARAM_KEYS,
    PARAM_TYPES,
    array_shape,
    gpu_kernel_param_problem,
    param_value,
    py_yaml,
)
from .platform import (
    EXECUTIONS,
    FUSION,
    MAX_FRAMES_IN_FLIGHT,
    PLATFORM_KEYS,
    STAGING,
    ZERO_COPY,
)
from .ports import FOLLOW_RE, PORT_KEYS
from .sources import CPU_KEYS, PYTHON_KEYS, module_names
from .system import SYSTEM_KEYS, load_system
from .type_files import LIBRARY_PREFIX, TYPE_FILE_SUFFIXES
from .types import (
    ALIAS_KEYS,
    LIBRARY_DIR,
    REQUIRE_KEYS,
    TYPE_KEYS,
    library_types,
    load_types_file,
)

__all__ = [
    "ALIAS_KEYS", "ANY", "ARRAY_TYPE", "ARRAY_TYPE_PATTERN", "BACKENDS", "CONNECTION_RE",
    "COVERS", "CPU_KEYS", "DTYPES", "EXECUTIONS", "FAMILIES", "FLOAT32_MAX", "FOLLOW_RE",
    "FUSABLE_KEYS", "FUSION", "GPU_KEYS", "INSTANCE_KEYS", "INT32", "KERNEL_KEYS", "KINDS",
    "LIBRARY_DIR", "LIBRARY_PREFIX", "MAX_ARRAY_ELEMENTS", "MAX_COMPONENTS",
    "MAX_CONNECTIONS", "MAX_FRAMES_IN_FLIGHT", "MAX_PARAMS", "MAX_PORTS", "MAX_TYPE_BYTES",
    "MAX_TYPE_FILES", "MEMORIES", "PARAM_KEYS", "PARAM_TYPES", "PLACEMENTS",
    "PLATFORM_KEYS", "PORT_KEYS", "PYTHON_KEYS", "REQUIRE_KEYS", "SETTING_KEYS", "STAGE_KEYS",
    "STAGING",
    "SYSTEM_KEYS", "TYPE_FILE_SUFFIXES", "TYPE_KEYS", "ZERO_COPY", "ComponentType",
    "Connection", "Endpoint", "GpuDecl", "Instance", "ParamDecl", "PortDecl", "SystemModel",
    "array_shape", "gpu_kernel_param_problem", "library_types", "load_system",
    "load_types_file", "module_names", "param_value", "placement_problem", "py_yaml",
]
