"""A model's 'platform:' section: the device, GPU settings per component, the thread
budget and the policies (execution, zero-copy, fusion, backend, placement, profile, frames
in flight, staging)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..backend import BACKENDS
from ..backend import DEFAULT as DEFAULT_BACKEND
from ..errors import Pos, Reporter, did_you_mean
from ..loader import Document
from .decls import PLACEMENTS, SETTING_KEYS, Instance
from .fields import _expect_map, _named, _positive_int, _unknown_keys

PLATFORM_KEYS = ("device", "gpu_settings", "thread_budget", "execution", "zero_copy",
                 "placement", "profile", "frames_in_flight", "staging", "fusion", "backend")
FUSION = ("auto", "off")
EXECUTIONS = ("parallel", "sequential")
ZERO_COPY = ("auto", "on", "off")
STAGING = ("auto", "pinned", "pageable")
MAX_FRAMES_IN_FLIGHT = 16


def load_platform(doc: Document, rep: Reporter, path: Path, root: dict) -> dict[str, Any]:
    """The model's 'platform:', as the SystemModel fields it sets (with their positions)."""
    platform = _expect_map(doc, rep, ("platform",), root.get("platform"), "platform")
    _unknown_keys(doc, rep, ("platform",), platform, PLATFORM_KEYS, "platform")
    device = platform.get("device", "portable")
    fields: dict[str, Any] = {
        "device": device,
        "device_pos": doc.pos("platform", "device"),
        "device_positions": {k: (doc.key_pos("platform", "device", k),
                                 doc.pos("platform", "device", k))
                             for k in (device if isinstance(device, dict) else {})
                             if isinstance(k, str)},
        "gpu_overrides": _gpu_settings(doc, rep, platform),
        "thread_budget": _positive_int(doc, rep, ("platform", "thread_budget"),
                                       platform.get("thread_budget"), "thread_budget"),
        "thread_budget_pos": doc.pos("platform", "thread_budget"),
        "platform_pos": doc.pos("platform"),
    }
    fields.update(_policies(doc, rep, platform))
    fields.update(_placement(doc, rep, path, platform))
    fields.update(_frames(doc, rep, platform))
    return fields


def _gpu_settings(doc: Document, rep: Reporter,
                  platform: dict) -> dict[str, tuple[dict[str, int], Pos]]:
    """'gpu_settings:': component -> (its settings, where they are written); whether the
    component exists is checked once components are known (check_gpu_settings)."""
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
    return overrides


def _policies(doc: Document, rep: Reporter, platform: dict) -> dict[str, str]:
    """'execution:', 'zero_copy:', 'fusion:' and 'backend:'."""
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
    return {"execution": execution, "zero_copy": zero_copy, "fusion": fusion,
            "backend": backend}


def _placement(doc: Document, rep: Reporter, path: Path, platform: dict) -> dict[str, Any]:
    """'placement:' (of flexible components that say nothing) and 'profile:' (a tune
    file, read only where a placement is 'auto')."""
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
    return {"placement": placement, "placement_pos": doc.pos("platform", "placement"),
            "profile": profile, "profile_pos": doc.pos("platform", "profile")}


def _frames(doc: Document, rep: Reporter, platform: dict) -> dict[str, Any]:
    """'frames_in_flight:' and 'staging:'."""
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
    return {"frames_in_flight": frames_in_flight, "staging": staging}


def check_gpu_settings(rep: Reporter, overrides: dict[str, tuple[dict[str, int], Pos]],
                       comps: dict, components: dict[str, Instance]) -> None:
    """Every component 'gpu_settings:' names exists and is GPU-aware (comps: the model's
    'components:' as written; components: those loaded)."""
    for cname, (_, pos) in overrides.items():
        if cname not in components and cname in comps:
            continue
        if cname not in components:
            rep.error(pos, f"gpu_settings for unknown component '{cname}'",
                      did_you_mean(cname, comps))
        elif not components[cname].type.gpu_aware:
            rep.error(pos, f"gpu_settings for '{cname}', which is a standard component",
                      "only GPU-aware components take GPU settings")
