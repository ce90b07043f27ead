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

    @property
    def total_threads(self) -> int:
        return self.compute_units * self.threads_per_compute_unit

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["max_work_item_sizes"] = list(self.max_work_item_sizes)
        return d
