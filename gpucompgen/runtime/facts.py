"""Device facts: the one declaration of what the generator plans for and the runtime checks.

The generator plans GPU settings and memory for described devices (profiles in
``gpucompgen.device``); each device API reads the same facts from a real device
(``opencl.facts``, ``cuda.device_facts``), for ``--device auto`` at build time and for the
program's checks at run time.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class DeviceFacts:
    name: str
    compute_units: int
    max_work_group_size: int
    max_work_item_sizes: tuple[int, int, int]
    local_mem_size: int
    global_mem_size: int
    max_mem_alloc_size: int
    host_unified_memory: bool
    # Threads one compute unit keeps resident; compute_units * this is the device's total,
    # the default thread budget for components that run at the same time.
    threads_per_compute_unit: int = 2048
    # The device's class, for the decisions that depend on it (placement by default, the
    # fusion cost model): "cpu" (a CPU OpenCL device, PoCL or Intel's: it runs on the cores
    # the CPU forms use), "integrated-gpu" (shares the host's memory), "discrete-gpu"
    # (behind PCIe), or "" when unknown (the 'portable' profile: any OpenCL 1.2 device).
    kind: str = ""

    @property
    def total_threads(self) -> int:
        return self.compute_units * self.threads_per_compute_unit

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["max_work_item_sizes"] = list(self.max_work_item_sizes)
        return d


KINDS = ("cpu", "integrated-gpu", "discrete-gpu")


def kind_of(is_cpu: bool, is_gpu: bool, unified: bool) -> str:
    """A device's class from its type and whether it shares the host's memory."""
    if is_cpu:
        return "cpu"
    if is_gpu:
        return "integrated-gpu" if unified else "discrete-gpu"
    return ""  # an accelerator, a custom device: unknown
