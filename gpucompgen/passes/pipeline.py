"""The pipeline: every pass in order, verified after each when asked, dumped when asked.

    check-connections → resolve-types → check-port-types → schedule → propagate-sizes → check-reads
    → place → insert-adapters → fuse → allocate-gpu → name-variables → assign-queues → stage-frames
    → lower
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Callable
from typing import Any

from ..errors import GpucompgenError, Reporter, UsageError, did_you_mean
from ..ir import MODES, System, build_system
from ..model import EXECUTIONS, FUSION, STAGING, ZERO_COPY, SystemModel
from ..options import BuildOptions, build_options
from ..runtime.facts import DeviceFacts
from .allocate_gpu import AllocateGpu
from .assign_queues import AssignQueues
from .base import Pass
from .check_connections import CheckConnections
from .check_port_types import CheckPortTypes
from .check_reads import CheckReads
from .fuse import Fuse
from .insert_adapters import InsertAdapters
from .lower import Lower
from .name_variables import NameVariables
from .place import Place
from .propagate_sizes import PropagateSizes
from .resolve_types import ResolveTypes
from .schedule import Schedule
from .stage_frames import StageFrames

PIPELINE: tuple[Pass, ...] = (CheckConnections(), ResolveTypes(), CheckPortTypes(), Schedule(),
                             PropagateSizes(), CheckReads(), Place(), InsertAdapters(), Fuse(), AllocateGpu(),
                             NameVariables(), AssignQueues(), StageFrames(), Lower())


def new_system(model: SystemModel, device: DeviceFacts, options: BuildOptions | None = None,
               **overrides: Any) -> System:
    """The IR of a model with its platform decisions (mode, execution, zero-copy, fusion,
    frames in flight, staging) taken.

    options (with the fields given as keywords replaced): execution, zero_copy, fusion,
    frames_in_flight and staging override the model's platform settings (the command
    line's --execution, --zero-copy, --fusion, --frames-in-flight and --staging); places
    (--place COMPONENT=gpu|cpu) overrides flexible components' placements and raises
    UsageError for an unknown component or one whose type cannot run on that side.
    """
    options = build_options(options, **overrides)
    mode, fusion = options.mode, options.fusion
    execution = options.execution or model.execution
    zero_copy = options.zero_copy or model.zero_copy
    staging = options.staging or model.staging
    frames_in_flight = options.frames_in_flight or model.frames_in_flight
    if (mode not in MODES or execution not in EXECUTIONS or zero_copy not in ZERO_COPY
            or staging not in STAGING or frames_in_flight < 1
            or (fusion or "auto") not in FUSION):
        raise ValueError(f"mode {mode!r}, execution {execution!r}, zero_copy {zero_copy!r}, "
                         f"staging {staging!r}, frames_in_flight {frames_in_flight!r}, "
                         f"fusion {fusion!r}")
    places = check_places(model, options.places or {})
    system = build_system(model, device, mode,
                          "sequential" if mode == "standard" else execution, places)
    if mode == "standard":
        system.fusion, system.fusion_reason = "off", "standard mode: one kernel per component"
    else:
        system.fusion = fusion or model.fusion
        system.fusion_reason = ("--fusion" if fusion else "platform.fusion"
                                if model.fusion != "auto" else "default")
    if mode == "standard":
        system.zero_copy_reason = "standard mode: components copy their own data"
    elif zero_copy == "auto":
        system.zero_copy = device.host_unified_memory
        system.zero_copy_reason = (f"auto: device {'has' if system.zero_copy else 'has no'} "
                                   "unified host memory")
    else:
        system.zero_copy = zero_copy == "on"
        system.zero_copy_reason = "forced by the model or the command line"
    system.frames_in_flight = frames_in_flight
    if mode == "standard":
        system.staging, system.staging_reason = "pageable", "standard mode: no adapters"
    elif system.zero_copy:
        system.staging, system.staging_reason = "pageable", "zero-copy adapters copy nothing"
    elif staging == "auto":
        system.staging = "pageable" if device.host_unified_memory else "pinned"
        system.staging_reason = (f"auto: device {'has' if device.host_unified_memory else 'has no'}"
                                 " unified host memory")
    else:
        system.staging = staging
        system.staging_reason = "forced by the model or the command line"
    return system


def check_places(model: SystemModel, places: dict[str, str]) -> dict[str, str]:
    """--place COMPONENT=gpu|cpu names a flexible component of the model, or is a glob
    ('*=cpu', 'blur*=gpu') over the flexible components; the later of two options for a
    component wins.  Returns {component: side}, globs expanded."""
    result: dict[str, str] = {}
    for name, side in places.items():
        if side not in ("gpu", "cpu", "auto"):
            raise UsageError(f"--place {name}={side}: the side must be gpu, cpu or auto")
        if any(c in name for c in "*?["):
            matched = [n for n, inst in model.components.items()
                       if inst.type.flexible and fnmatch.fnmatchcase(n, name)]
            if not matched:
                flexible = [n for n, inst in model.components.items() if inst.type.flexible]
                raise UsageError(f"--place {name}={side}: the pattern matches no flexible "
                                 "component (flexible: "
                                 f"{', '.join(flexible) if flexible else 'none'})")
            for n in matched:
                result.pop(n, None)
                result[n] = side
            continue
        inst = model.components.get(name)
        if inst is None:
            hint = did_you_mean(name, model.components)
            raise UsageError(f"--place {name}={side}: the model has no component '{name}'"
                             + (f" ({hint})" if hint else ""))
        if not inst.type.flexible and side != ("gpu" if inst.type.gpu_aware else "cpu"):
            raise UsageError(f"--place {name}={side}: '{name}' is {inst.type.kind} "
                             f"({inst.type.name}) and runs on the "
                             f"{'GPU' if inst.type.gpu_aware else 'CPU'} only; only "
                             "flexible types can be placed")
        result.pop(name, None)
        result[name] = side
    return result


def verify_by_default() -> bool:
    """The test suite verifies the IR after every pass (GPUCOMPGEN_VERIFY=1)."""
    return os.environ.get("GPUCOMPGEN_VERIFY", "") not in ("", "0")


def run_pipeline(system: System, passes: tuple[Pass, ...] = PIPELINE,
                 dump: Callable[[str], None] | None = None,
                 verify: bool | None = None) -> tuple[System, list]:
    """Run passes and return the system and its warnings, or raise with every problem.

    Once a pass has found errors, only the checking passes that cope with a partly checked
    system still run (Pass.runs_after_errors); the others are skipped, and the IR is no
    longer verified (it may be partly checked).
    """
    verify = verify_by_default() if verify is None else verify
    rep = Reporter()
    for p in passes:
        if rep.has_errors and not p.runs_after_errors:
            continue
        system = p.apply(system, rep)
        system.done.append(p.name)
        if verify and not rep.has_errors:
            system.verify()
        if dump is not None:
            dump(f"// after {p.name}\n{system.dump()}\n")
    loaded = list(getattr(system.model, "load_warnings", None) or [])
    if rep.has_errors:
        raise GpucompgenError(sorted(set(rep.diagnostics + loaded)))
    return system, sorted(rep.warnings + loaded)


def run_passes(model: SystemModel, device: DeviceFacts, options: BuildOptions | None = None,
               **overrides: Any) -> tuple[System, list]:
    """Build the IR of a model and run every pass on it (options as for new_system; their
    dump and verify go to run_pipeline)."""
    options = build_options(options, **overrides)
    return run_pipeline(new_system(model, device, options), PIPELINE, options.dump,
                        options.verify)


def passes_names() -> list[str]:
    return [p.name for p in PIPELINE]
