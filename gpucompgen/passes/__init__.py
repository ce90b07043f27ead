"""Passes over the system IR, one per module; each has a ``name`` and ``apply(system, rep)``.

    check_connections   one writer per input, required inputs fed
    resolve_types       generic ports' element types and channels, from what feeds them
    check_port_types    both ends of an edge carry the same element type and channels
    schedule            run order and stages; cycles
    propagate_sizes     every port's size, from the sources down
    insert_adapters     an adapter node on every edge that crosses CPU/GPU memory
    allocate_gpu        each GPU component's tile and work-group, within the thread budget
    name_variables      the variable of every port in generated code
    assign_queues       queues (lanes) and waits of GPU commands
    stage_frames        frames in flight: the stages, one thread each, and the buffer sets
    lower               the ProgramPlan the backend prints

``pipeline`` runs them (``gpucompgen build --print-between-passes`` dumps the IR after each).
"""

from __future__ import annotations

from ..ir import MODES, GpuSettings, System
from .allocate_gpu import concurrent_groups, descendants, limit_problems, resident_threads
from .base import Pass
from .pipeline import PIPELINE, new_system, passes_names, run_passes, run_pipeline

__all__ = ["MODES", "PIPELINE", "GpuSettings", "Pass", "System", "concurrent_groups",
           "descendants", "limit_problems", "new_system", "passes_names", "resident_threads",
           "run_passes", "run_pipeline"]
