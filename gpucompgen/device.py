"""Device facts as plain data, so allocation can be planned for devices we do not have.

A model names a profile (``device: portable``), or gives facts (``device: {profile:
portable, max_work_group_size: 128}``); ``gpucompgen build --device auto`` reads the
OpenCL device that ``PYOPENCL_CTX`` selects.  The build result depends only on these facts,
never on the machine that runs the generator, so checked-in output is reproducible.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

from .errors import Pos, Reporter, did_you_mean
from .runtime.facts import DeviceFacts

KiB, MiB, GiB = 1 << 10, 1 << 20, 1 << 30


PROFILES: dict[str, DeviceFacts] = {
    # What every OpenCL 1.2 GPU and CPU device offers: safe default for checked-in code.
    "portable": DeviceFacts("portable OpenCL 1.2 device", 8, 256, (256, 256, 64), 32 * KiB,
                            1 * GiB, 256 * MiB, False, 2048),
    # PoCL on a CPU: host memory is device memory.
    "pocl-cpu": DeviceFacts("PoCL CPU device", 2, 4096, (4096, 4096, 4096), 4 * MiB,
                            8 * GiB, 4 * GiB, True, 4096),
    # The paper's evaluation platform: an NVIDIA Kepler GPU (GK104-class).
    "nvidia-kepler": DeviceFacts("NVIDIA Kepler GPU", 8, 1024, (1024, 1024, 64), 48 * KiB,
                                 2 * GiB, 512 * MiB, False, 2048),
    # An embedded board with an integrated GPU (Jetson-class): unified memory.
    "embedded-igpu": DeviceFacts("embedded integrated GPU", 2, 1024, (1024, 1024, 64),
                                 48 * KiB, 4 * GiB, 1 * GiB, True, 2048),
    # A small mobile GPU (Mali-class): small work-groups.
    "mobile-gpu": DeviceFacts("small mobile GPU", 2, 64, (64, 64, 64), 32 * KiB, 1 * GiB,
                              256 * MiB, True, 384),
    # A large discrete GPU (Hopper-class).
    "nvidia-hopper": DeviceFacts("NVIDIA Hopper GPU", 132, 1024, (1024, 1024, 64), 48 * KiB,
                                 80 * GiB, 20 * GiB, False, 2048),
}

FACT_KEYS = tuple(f.name for f in fields(DeviceFacts))
# the range a declared integer fact must be in: beyond it, it is a typo, not a device
FACT_RANGES = {
    "compute_units": (1, 1 << 20),
    "max_work_group_size": (1, 1 << 20),
    "max_work_item_sizes": (1, (1 << 31) - 1),
    "local_mem_size": (1, 1 << 30),
    "global_mem_size": (1 * MiB, 1 << 50),
    "max_mem_alloc_size": (1 * MiB, 1 << 50),
    "threads_per_compute_unit": (1, 1 << 16),
}
MAX_NAME = 100


def _fact_problem(key: str, value: Any) -> str:
    """Why value cannot be the device fact key ('' when it can)."""
    if key == "name":
        if not isinstance(value, str) or not 0 < len(value) <= MAX_NAME:
            return f"device name must be a string of 1 to {MAX_NAME} characters"
        return ""
    if key == "host_unified_memory":
        return "" if isinstance(value, bool) else "host_unified_memory must be true or false"
    low, high = FACT_RANGES[key]
    if key == "max_work_item_sizes":
        if not (isinstance(value, list) and len(value) == 3 and all(
                isinstance(v, int) and not isinstance(v, bool) and low <= v <= high
                for v in value)):
            return (f"max_work_item_sizes must be a list of three integers from {low:,} "
                    f"to {high:,}")
        return ""
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        return f"device fact '{key}' must be a positive integer, not {value!r}"
    if not low <= value <= high:
        unit = " bytes" if key.endswith("_size") and key != "max_work_group_size" else ""
        return (f"device fact '{key}' is {value:,}{unit}, outside the range of real devices "
                f"({low:,} to {high:,}{unit})")
    return ""


def resolve(spec: Any, pos: Pos, rep: Reporter,
            positions: dict[str, tuple[Pos, Pos]] | None = None,
            query=None) -> DeviceFacts | None:
    """Turn a model's ``platform.device`` into facts; report problems at pos, or for a
    mapping at the (key, value) positions of each fact where given.  query: what 'auto'
    asks (the backend's device query; default the OpenCL device programs use)."""
    positions = positions or {}
    if spec is None:
        spec = "portable"
    if isinstance(spec, str):
        if spec == "auto":
            from .runtime import PipelineError

            try:
                return (query or query_device)()
            except PipelineError as exc:
                rep.error(pos, f"device 'auto': {exc}",
                          "name a device profile instead, or see 'gpucompgen devices'")
                return None
        if spec not in PROFILES:
            rep.error(pos, f"unknown device profile {spec!r}",
                      did_you_mean(spec, list(PROFILES) + ["auto"]))
            return None
        return PROFILES[spec]
    if not isinstance(spec, dict):
        rep.error(pos, "platform.device must be a profile name or a mapping of device facts")
        return None
    base_name = spec.get("profile", "portable")
    if not isinstance(base_name, str) or base_name not in PROFILES:
        rep.error(positions.get("profile", (pos, pos))[1],
                  f"unknown device profile {base_name!r}", did_you_mean(str(base_name), PROFILES))
        return None
    changes: dict[str, Any] = {}
    for key, value in spec.items():
        if key == "profile":
            continue
        key_pos, value_pos = positions.get(key, (pos, pos))
        if key not in FACT_KEYS:
            rep.error(key_pos, f"unknown device fact '{key}'",
                      did_you_mean(str(key), FACT_KEYS + ("profile",)))
            continue
        problem = _fact_problem(key, value)
        if problem:
            rep.error(value_pos, problem)
            continue
        changes[key] = tuple(value) if key == "max_work_item_sizes" else value
    facts = replace(PROFILES[base_name], **changes)
    if facts.max_mem_alloc_size > facts.global_mem_size:
        key = "max_mem_alloc_size" if "max_mem_alloc_size" in changes else "global_mem_size"
        rep.error(positions.get(key, (pos, pos))[1],
                  f"max_mem_alloc_size ({facts.max_mem_alloc_size:,} bytes) is larger than "
                  f"global_mem_size ({facts.global_mem_size:,} bytes)",
                  "one allocation cannot be larger than the device's memory")
        return None
    return facts


def query_device(device: Any = None) -> DeviceFacts:
    """Facts of a real OpenCL device (the one the runtime selects when device is None)."""
    from .runtime import device_api

    api = device_api.get()
    return api.facts(device if device is not None else api.select_device())
