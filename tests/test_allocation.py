"""The allocator: device limits and the thread budget hold on described and real devices.

Random pipelines (hypothesis) are built from the library types on described devices; the
checks below recompute reachability, groups that can run together and resident threads
independently of the allocator's own code.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import ROOT, require_opencl
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen.build import compile_model
from gpucompgen.device import PROFILES, resolve
from gpucompgen.errors import GpucompgenError, Reporter
from gpucompgen.model import library_types


def _write(tmp: Path, name: str, model: dict) -> Path:
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(model, sort_keys=False))
    return path


@st.composite
def pipelines(draw):
    """A random acyclic pipeline: cameras, then blurs and merges of earlier outputs."""
    h = draw(st.sampled_from([16, 48, 480]))
    cams = draw(st.integers(1, 3))
    comps = {f"cam{i}": {"type": "Camera", "params": {"width": draw(st.sampled_from(
        [16, 64, 640])), "height": h, "seed": i}} for i in range(cams)}
    outputs = [f"cam{i}.image" for i in range(cams)]
    conns = []
    for i in range(draw(st.integers(1, 6))):
        if len(outputs) >= 2 and draw(st.booleans()):
            left, right = draw(st.permutations(outputs))[:2]
            comps[f"m{i}"] = {"type": "ImageMerger"}
            conns += [f"{left} -> m{i}.left", f"{right} -> m{i}.right"]
            outputs.append(f"m{i}.merged")
        else:
            src = draw(st.sampled_from(outputs))
            comps[f"b{i}"] = {"type": "BoxBlur"}
            conns.append(f"{src} -> b{i}.image")
            outputs.append(f"b{i}.smooth")
    src = draw(st.sampled_from(outputs))
    comps["det"] = {"type": "ObjectDetector"}
    comps["vm"] = {"type": "VisionManager", "params": {"print_decisions": False}}
    conns += [f"{src} -> det.frame", "det.mask -> vm.mask"]
    return comps, conns


devices = st.one_of(
    st.sampled_from(sorted(PROFILES)),
    st.fixed_dictionaries({
        "profile": st.sampled_from(["portable", "mobile-gpu", "embedded-igpu"]),
        "compute_units": st.integers(1, 16),
        "max_work_group_size": st.sampled_from([16, 64, 100, 256, 1024]),
        "threads_per_compute_unit": st.sampled_from([64, 384, 2048]),
    }))


def _reach(comps: dict, conns: list[str]) -> dict[str, set[str]]:
    succ = {n: set() for n in comps}
    for c in conns:
        a, b = (s.strip().split(".")[0] for s in c.split("->"))
        succ[a].add(b)
    reach = {}
    for n in comps:
        seen, todo = set(), [n]
        while todo:
            for m in succ[todo.pop()]:
                if m not in seen:
                    seen.add(m)
                    todo.append(m)
        reach[n] = seen
    return reach


def _resident(system, name) -> int:
    s = system.settings[name]
    t = system.gpu_node(name).type  # a component alone on a generated kernel: its group's
    grid = system.sizes[next(e for e in system.sizes if e.component == name
                             and e.port == t.grid)]
    # tile x tile squares a work-group, or tile whole rows (generated kernels)
    across = 1 if t.cover == "rows" else math.ceil(grid.width / s.tile)
    groups = across * math.ceil(grid.height / s.tile)
    return min(groups * s.block_x * s.block_y * s.block_z, system.device.total_threads)


def _antichains(gpu: list[str], reach) -> list[tuple[str, ...]]:
    """Every set of GPU components with no path between any two (brute force)."""
    free = [g for r in range(1, len(gpu) + 1) for g in itertools.combinations(gpu, r)
            if all(b not in reach[a] and a not in reach[b]
                   for a, b in itertools.combinations(g, 2))]
    return free


def _check_system(system, comps, conns, budget):
    dev = system.device
    types = library_types()
    gpu = sorted(n for n in comps if types[comps[n]["type"]].gpu_aware)
    assert sorted(system.settings) == gpu
    for n, s in system.settings.items():
        decl = system.gpu_node(n).type.gpu  # the kernel it runs (generated, or the type's)
        assert s.tile in decl.tiles and s.block_z in decl.block_z
        assert s.block_x * s.block_y * s.block_z <= dev.max_work_group_size
        for v, limit in zip((s.block_x, s.block_y, s.block_z), dev.max_work_item_sizes):
            assert 1 <= v <= limit
    # the model's budget caps the device's total, never raises it
    cap = min(budget, dev.total_threads) if budget else dev.total_threads
    assert system.thread_budget == cap
    for group in _antichains(gpu, _reach(comps, conns)):
        assert sum(_resident(system, n) for n in group) <= cap, group


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pipe=pipelines(), device=devices, budget=st.one_of(st.none(), st.integers(1, 40000)))
def test_random_pipelines_stay_within_limits_and_budget(tmp_path_factory, pipe, device,
                                                        budget):
    comps, conns = pipe
    # every flexible component on the GPU: this is about allocating GPU work (a device of
    # a known class would place some on the CPU by default)
    platform = {"device": device, "placement": "gpu"}
    if budget:
        platform["thread_budget"] = budget
    model = _write(tmp_path_factory.mktemp("m"), "rand",
                   {"system": "rand", "platform": platform, "components": comps,
                    "connections": conns})
    try:
        # allocation of single components: fusion would make groups of them
        result = compile_model(model, model.parent / "out", fusion="off")
    except GpucompgenError as exc:
        # only an impossible budget may fail: the named group can run together, and even
        # at their smallest settings (largest tile, one thread per work-group) its
        # components need more threads than the budget
        # (the device's total is the default budget, and small devices can miss it too)
        messages = [d.message for d in exc.errors]
        assert messages and all("over the thread budget" in m for m in messages), messages
        facts = PROFILES[device] if isinstance(device, str) else resolve(
            device, None, Reporter())
        budget = min(budget, facts.total_threads) if budget else facts.total_threads
        # sizes and GPU-setting limits do not depend on the budget: a device with room for
        # every thread gives a system to read them from
        roomy = {"profile": device if isinstance(device, str) else device["profile"],
                 **({} if isinstance(device, str) else device), "compute_units": 10 ** 6}
        model.write_text(yaml.safe_dump({"system": "rand", "platform": {"device": roomy,
                                                                        "placement": "gpu"},
                                         "components": comps, "connections": conns}))
        system = compile_model(model, model.parent / "out", fusion="off").system  # sizes
        reach = _reach(comps, conns)
        for m in messages:
            head = m.split(" can run")[0].split(" needs")[0]
            names = head.split(" ", 1)[1].split(", ")
            assert set(names) in [set(g) for g in _antichains(sorted(names), reach)]
            least = 0
            for n in names:
                kt = system.gpu_node(n).type  # the kernel it runs
                grid = system.sizes[next(e for e in system.sizes if e.component == n
                                         and e.port == kt.grid)]
                t = max(kt.gpu.tiles)
                across = 1 if kt.cover == "rows" else math.ceil(grid.width / t)
                least += min(across * math.ceil(grid.height / t), facts.total_threads)
            assert f"at least {least} resident threads" in m, (m, least)
            assert least > budget
        return
    _check_system(result.system, comps, conns, budget)


# what the allocation tests allocate: GPU work, not what a device's class would place
EVERY_FLEXIBLE_ON_THE_GPU = {"*": "gpu"}


@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_parallel_branches_share_the_budget_on_every_profile(profile):
    result = compile_model(ROOT / "models" / "parallel_branches.yaml", ROOT / "generated",
                           device=profile, fusion="off", places=EVERY_FLEXIBLE_ON_THE_GPU)
    system = result.system
    assert ("blur1", "blur2") in system.concurrent
    total = _resident(system, "blur1") + _resident(system, "blur2")
    assert total <= system.device.total_threads
    comps = yaml.safe_load((ROOT / "models" / "parallel_branches.yaml").read_text())
    _check_system(system, comps["components"], comps["connections"], None)


def test_allocator_shrinks_concurrent_components_it_would_not_shrink_alone(tmp_path):
    """A blur alone keeps its preference; two that can run together are made to fit.
    (Each blur's kernel prefers 960 resident threads: a budget of 1,200 holds one, not two.)"""
    base = yaml.safe_load((ROOT / "models" / "parallel_branches.yaml").read_text())
    base["platform"] = {**base.get("platform", {}), "thread_budget": TIGHT_BUDGET}
    alone = compile_model(_write(tmp_path, "tight", base), tmp_path / "t", device="portable",
                          fusion="off").system
    assert alone.settings["merger"].source == "preferred"
    sources = [alone.settings[name].source for name in ("blur1", "blur2")]
    assert "shrunk to share the thread budget" in sources, sources
    assert _resident(alone, "blur1") + _resident(alone, "blur2") <= TIGHT_BUDGET
    # the same blur with no sibling: the type's preference, capped by the device only
    single = dict(base, components={k: v for k, v in base["components"].items()
                                    if k != "blur2"},
                  connections=[c for c in base["connections"] if "blur2" not in c]
                  + ["camera2.image -> merger.right"])
    s = compile_model(_write(tmp_path, "single", single), tmp_path / "o", fusion="off").system
    assert s.settings["blur1"].source == "preferred"
    assert (s.settings["blur1"].tile, s.settings["blur1"].block_x) == (32, 8)


def test_real_device_allocation_fits_its_limits(tmp_path):
    require_opencl()
    result = compile_model(ROOT / "models" / "parallel_branches.yaml", tmp_path,
                           device="auto", fusion="off", places=EVERY_FLEXIBLE_ON_THE_GPU)
    base = yaml.safe_load((ROOT / "models" / "parallel_branches.yaml").read_text())
    _check_system(result.system, base["components"], base["connections"], None)


def _cli(tmp_path, text, *args):
    model = tmp_path / "m.yaml"
    model.write_text(text)
    # allocation of single components: fusion would make groups of them
    return subprocess.run([sys.executable, "-m", "gpucompgen", "plan", str(model),
                           "--fusion", "off", *args], capture_output=True, text=True)


BRANCHES = (ROOT / "models" / "parallel_branches.yaml").read_text()
# a thread budget that holds one blur of parallel_branches at its preference, not two
TIGHT_BUDGET = 1200


def test_impossible_budget_is_an_error_naming_the_components(tmp_path):
    text = BRANCHES.replace("  device: portable\n", "  device: portable\n  thread_budget: 6\n")
    proc = _cli(tmp_path, text)
    assert proc.returncode == 1, proc.stdout
    assert "Traceback" not in proc.stderr
    # each blur's generated kernel covers whole rows: 480 rows with the largest tile (128)
    # are 4 work-groups of at least one thread each
    assert "error: components blur1, blur2 can run at the same time and together need at " \
           "least 8 resident threads, over the thread budget of 6" in proc.stderr, \
        proc.stderr
    assert "hint: raise platform.thread_budget" in proc.stderr


def test_budget_the_model_fixes_is_reported_with_the_fixed_settings(tmp_path):
    text = BRANCHES.replace("  device: portable\n", (
        "  device: portable\n"
        "  thread_budget: 20000\n"
        "  gpu_settings:\n"
        "    blur1: {tile: 8, block_x: 16, block_y: 16}\n"
        "    blur2: {tile: 8, block_x: 16, block_y: 16}\n"))
    proc = _cli(tmp_path, text)
    assert proc.returncode == 1
    assert "components blur1, blur2 can run at the same time" in proc.stderr
    assert "(settings fixed by the model: blur1, blur2)" in proc.stderr


@pytest.mark.parametrize("override,message", [
    ("{tile: 16, block_x: 32, block_y: 32}", "block 32x32x1 = 1024 threads is over the "
     "device's work-group limit of 256"),
    ("{tile: 12}", "tile 12 is not one the kernel accepts [1, 2, 4, 8, 16, 32, 64, 128]"),
    ("{block_z: 2}", "block_z 2 is not one the kernel accepts [1]"),
    ("{block_x: 512, block_y: 1}", "block_x 512 is over the device's 256"),
])
def test_overrides_that_break_limits_are_errors(tmp_path, override, message):
    text = BRANCHES.replace("  device: portable\n",
                            f"  device: portable\n  gpu_settings:\n    blur1: {override}\n")
    proc = _cli(tmp_path, text)
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr
    assert f"error: gpu_settings of 'blur1': {message}" in proc.stderr, proc.stderr


def test_valid_override_is_honoured_and_the_other_branch_makes_room(tmp_path):
    text = BRANCHES.replace("  device: portable\n", (
        "  device: portable\n"
        f"  thread_budget: {TIGHT_BUDGET}\n"
        "  gpu_settings:\n"
        "    blur1: {tile: 64, block_x: 8, block_y: 8}\n"))
    model = tmp_path / "m.yaml"
    model.write_text(text)
    system = compile_model(model, tmp_path / "o", fusion="off").system
    s1, s2 = system.settings["blur1"], system.settings["blur2"]
    assert (s1.tile, s1.block_x, s1.block_y, s1.source) == (64, 8, 8, "model")
    assert s2.source == "shrunk to share the thread budget"
    assert _resident(system, "blur1") + _resident(system, "blur2") <= TIGHT_BUDGET


def test_a_budget_above_the_device_total_is_capped_with_a_warning(tmp_path):
    model = tmp_path / "big_budget.yaml"
    model.write_text(BRANCHES.replace("  device: portable\n",
                                      "  device: portable\n  thread_budget: 1000000\n"))
    result = compile_model(model, tmp_path / "out", fusion="off")
    total = PROFILES["portable"].total_threads
    assert result.system.thread_budget == total
    (warning,) = [w for w in result.warnings if "thread_budget" in w.message]
    assert warning.message == (f"platform.thread_budget 1,000,000 is more than device "
                               f"'{PROFILES['portable'].name}' can hold resident "
                               f"({total:,} threads); using {total:,}")
    assert (warning.line, warning.col) == (BRANCHES.splitlines().index("  device: portable")
                                           + 2, 18)


SHAPED_TYPES = """\
component_types:
  Shaped:
    kind: gpu-aware
    inputs:
      image: {memory: gpu, dtype: uint8, channels: 3}
    outputs:
      out: {memory: gpu, dtype: uint8, channels: 3}
    kernel: {file: shaped.cl, function: shaped}
    gpu:
      tiles: [16, 32]
      max_threads: 64
      square: true
      prefer: {tile: 16, block_x: 32, block_y: 32, block_z: 1}
"""


@pytest.mark.parametrize("device", ["nvidia-hopper", "portable", "embedded-igpu"])
@pytest.mark.parametrize("budget", [None, 1024, 300])
def test_block_shape_constraints_hold_when_fitting_and_sharing_the_budget(tmp_path, device,
                                                                         budget):
    """A type's max_threads and square hold for the preference cut down to fit, and while
    two concurrent components shrink to share the budget."""
    (tmp_path / "shaped.yaml").write_text(SHAPED_TYPES)
    (tmp_path / "shaped.cl").write_text(
        "__kernel void shaped(__global const uchar *image, __global uchar *out,\n"
        "    const int image_height, const int image_width, const int out_height,\n"
        "    const int out_width, const int tile) {}\n")
    platform = {"device": device} | ({"thread_budget": budget} if budget else {})
    comps = {"camera1": {"type": "Camera", "params": {"width": 320, "height": 240}},
             "camera2": {"type": "Camera", "params": {"width": 320, "height": 240, "seed": 2}},
             "a": {"type": "Shaped"}, "b": {"type": "Shaped"},
             "merger": {"type": "ImageMerger"}, "detector": {"type": "ObjectDetector"},
             "manager": {"type": "VisionManager"}}
    conns = ["camera1.image -> a.image", "camera2.image -> b.image", "a.out -> merger.left",
             "b.out -> merger.right", "merger.merged -> detector.frame",
             "detector.mask -> manager.mask"]
    model = _write(tmp_path, "shaped_system", {"system": "shaped_system", "types": ["shaped.yaml"],
                                                "platform": platform, "components": comps,
                                                "connections": conns})
    system = compile_model(model, tmp_path / "out", fusion="off").system
    for name in ("a", "b"):
        s = system.settings[name]
        assert s.block_x == s.block_y, (name, s)
        assert s.block_x * s.block_y * s.block_z <= 64, (name, s)
    cap = min(budget, system.device.total_threads) if budget else system.device.total_threads
    assert sum(_resident(system, n) for n in ("a", "b")) <= cap
    if budget == 300:  # 2 x (10 x 8 work-groups of tile 32) = 160 groups: 1 thread each
        assert [system.settings[n].block_x for n in ("a", "b")] == [1, 1]


def test_many_parallel_branches_are_budgeted_as_one_group(tmp_path):
    """k parallel branches of L GPU components have L^k groups that can run together
    (8 branches of 4: 65,536); enumerating them all made build time explode. Past
    MAX_CONCURRENT_GROUPS every GPU component counts as concurrent with every other."""
    from gpucompgen.passes.allocate_gpu import MAX_CONCURRENT_GROUPS, resident_threads

    lines = ["system: par", "platform: {fusion: off}", "components:",
             "  src: {type: StillImage, params: {width: 16, height: 16}}"]
    conns = []
    for i in range(8):
        prev = "src.image"
        for j in range(4):
            lines.append(f"  m{i}_{j}: VerticalMirror")
            conns.append(f"  - {prev} -> m{i}_{j}.image")
            prev = f"m{i}_{j}.mirrored"
        lines.append(f"  s{i}: FrameSink")
        conns.append(f"  - {prev} -> s{i}.image")
    model = tmp_path / "par.yaml"
    model.write_text("\n".join(lines + ["connections:"] + conns) + "\n")
    system = compile_model(model, tmp_path / "out").system
    assert 4 ** 8 > MAX_CONCURRENT_GROUPS
    gpu = [n for n in system.order if n in system.settings]
    assert len(gpu) == 32 and system.concurrent == [tuple(gpu)]
    total = sum(resident_threads(system, n) for n in gpu)
    assert total <= system.thread_budget
    # below the cap the groups are listed exactly: 2 branches of 4 give 4 x 4 pairs
    two = tmp_path / "two.yaml"
    text = model.read_text()
    two.write_text("\n".join(line for line in text.splitlines()
                             if not any(f"m{i}_" in line or f"s{i}" in line
                                        for i in range(2, 8))) + "\n")
    system = compile_model(two, tmp_path / "out2").system
    assert len(system.concurrent) == 16 and all(len(g) == 2 for g in system.concurrent)
