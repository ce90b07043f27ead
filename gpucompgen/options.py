"""BuildOptions: how one build goes beyond what its model says.

The command line's options (``--mode``, ``--device``, ``--backend``, ``--execution``,
``--zero-copy``, ``--fusion``, ``--frames-in-flight``, ``--staging``, ``--place``,
``--debug``, ``--print-between-passes``) as one record, which ``build.compile_model`` and
``passes.pipeline.run_passes`` take.  A setting left None keeps the model's own (its
``platform:``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any


@dataclass(frozen=True)
class BuildOptions:
    # "gpu-aware", or "standard": the paper's baseline (every component copies its own
    # data, one kernel per component, run in sequence)
    mode: str = "gpu-aware"
    # a device profile's name, a mapping of facts, or "auto" (the device at hand); None:
    # platform.device
    device: Any = None
    backend: str | None = None  # "opencl" | "cuda": the printer (gpucompgen.backend)
    execution: str | None = None  # "parallel" | "sequential"
    zero_copy: str | None = None  # "auto" | "on" | "off"
    fusion: str | None = None  # "auto" | "off"
    frames_in_flight: int | None = None  # 1 or more
    staging: str | None = None  # "auto" | "pinned" | "pageable"
    # --place COMPONENT=gpu|cpu|auto (globs too): flexible components' placements
    places: dict[str, str] | None = None
    # with device "auto": every kernel file of the user's that the model names is built on
    # that device, fused or not, and what its compiler says is reported with the model's
    # problems (check, build and plan do)
    compile_kernels: bool = False
    # check the IR's invariants after every pass (--debug; None: when GPUCOMPGEN_VERIFY
    # is set, as the test suite does)
    verify: bool | None = None
    dump: Callable[[str], None] | None = None  # gets the IR after every pass
    display: str | None = None  # the model's path as messages show it


def build_options(options: BuildOptions | None = None, **overrides: Any) -> BuildOptions:
    """options (the defaults when None) with the fields named replaced; a name that is no
    option raises TypeError."""
    return replace(options or BuildOptions(), **overrides)
