"""The small runtime that generated programs import (``from gpucompgen import runtime``).

It holds what every generated program needs and nothing of the generator: a neutral core
that imports numpy only, and one module per device API behind the device interface
(device_api.py).  ``from gpucompgen import runtime`` is the runtime of OpenCL programs: the
core's names and the OpenCL module's.  CUDA programs import ``runtime.cuda`` instead.

The core, one module per concern:

    errors      PipelineError (a problem the user can act on) and Stopped (a signal)
    sizes       Size, the size of the data on one port
    facts       DeviceFacts: the device facts the generator plans for and the runtime checks
    device_api  the device interface: what the core asks of a device API, picked by name
    devices     device status, kernel limits, the work-group and memory checks
    adapters    the CPU<->GPU adapters (copying and zero-copy), the same in every system
    components  KernelComponent, the base class of generated GPU-aware component classes
    programs    kernel files and build logs made readable, the component named in errors
    frames      shape and element type of frames crossing components
    lifecycle   size checks, user modules, failures named by component, freeing
    session     Session: what every run() does around its own lines (parts, failures, freeing)
    profiling   --profile: event times and bytes moved
    pipeline    frames in flight: the stages of a stream, one thread each
    monitor     progress, --stats-json, runtime options
    signals     SIGINT and SIGTERM stop a run cleanly
    overrides   --set, --input and --output, checked against the program's PARAMS
    cli         the generated program's command line (main)

The device APIs:

    opencl      OpenCL: device selection, facts, building, memory, copies, launches, events
    cuda        CUDA (cuda-python): the names an OpenCL program calls, driving CUDA

Everything is importable from ``gpucompgen.runtime`` as before.
"""

from __future__ import annotations

from .adapters import (
    CpuToGpuAdapter,
    GpuToCpuAdapter,
    ZeroCopyCpuToGpuAdapter,
    ZeroCopyGpuToCpuAdapter,
)
from .cli import add_program_options, main
from .components import CpuFunctionComponent, KernelComponent
from .devices import (
    DeviceLimits,
    DeviceStatus,
    KernelLimits,
    _build_problem,
    check_device_memory,
)
from .errors import PipelineError, Stopped
from .frames import check_frame
from .lifecycle import (
    Parts,
    Result,
    component_failure,
    expect_size,
    failing_component,
    free_all,
    load_class,
    load_function,
    load_module,
    model_path,
)
from .monitor import Monitor
from .opencl import (
    NO_DEVICE_HINT,
    build_program,
    check_work_group,
    create_context,
    create_queue,
    device_limits,
    kernel_limits,
    probe_device,
    quiet_compiler,
    select_device,
    survey_devices,
    unusable_message,
)
from .overrides import Param, param_values
from .pipeline import FrameFailure, stream_in_flight
from .profiling import Profile
from .session import Session
from .signals import _stop_on_signals
from .sizes import Size

__all__ = [
    "NO_DEVICE_HINT",
    "CpuFunctionComponent",
    "CpuToGpuAdapter",
    "DeviceLimits",
    "DeviceStatus",
    "FrameFailure",
    "GpuToCpuAdapter",
    "KernelComponent",
    "KernelLimits",
    "Monitor",
    "Param",
    "Parts",
    "PipelineError",
    "Profile",
    "Result",
    "Session",
    "Size",
    "Stopped",
    "ZeroCopyCpuToGpuAdapter",
    "ZeroCopyGpuToCpuAdapter",
    "_build_problem",
    "_stop_on_signals",
    "add_program_options",
    "build_program",
    "check_device_memory", "check_frame",
    "check_work_group",
    "component_failure",
    "create_context",
    "create_queue",
    "device_limits",
    "expect_size",
    "failing_component",
    "free_all",
    "kernel_limits",
    "load_class",
    "load_function",
    "load_module",
    "main", "model_path", "param_values",
    "probe_device",
    "quiet_compiler",
    "select_device",
    "stream_in_flight",
    "survey_devices",
    "unusable_message",
]
