"""Flexible components and their placement (issue 15).

Every placement of the flexible components of the vision system and of the two-branch
model gives the same masks and decisions, frame by frame, as an independent numpy
reference; `auto` follows described profiles, with estimates computed here by hand;
command-line placement errors are usage errors.
"""

from __future__ import annotations

import itertools
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen import cli
from gpucompgen.build import compile_model, write
from gpucompgen.device import resolve
from gpucompgen.errors import GpucompgenError, Pos, Reporter, UsageError
from gpucompgen.library.camera import Camera
from gpucompgen.model import load_system
from gpucompgen.passes import fuse as fuse_mod
from gpucompgen.passes import place as place_mod
from gpucompgen.passes import run_passes
from gpucompgen.plan import plan_lines

VISION = ROOT / "models" / "vision_system.yaml"
BRANCHES = ROOT / "models" / "parallel_branches.yaml"
MIB = 1_000_000


def _passes(path: Path, places=None, zero_copy="off", fusion=None):
    model = load_system(path)
    facts = resolve("portable", Pos(""), Reporter())
    return run_passes(model, facts, places=places, zero_copy=zero_copy, fusion=fusion)


# --------------------------------------------------------------------------- defaults

def test_flexible_components_stay_on_the_gpu_unless_asked():
    system, _ = _passes(VISION)
    assert {n: system.component(n).placement for n in system.model.components} == {
        "camera1": "cpu", "camera2": "cpu", "merger": "gpu", "detector": "gpu",
        "manager": "cpu"}
    assert [a.direction for a in system.adapters] == ["cpu2gpu", "cpu2gpu", "gpu2cpu"]
    assert system.placement.decided == {"merger": ("gpu", "default"),
                                        "detector": ("gpu", "default")}


@pytest.mark.parametrize("device, sides, by", [
    # no class: the GPU, as the paper's system (and every checked-in example) does
    ("portable", ("gpu", "gpu"), "default"),
    # a CPU OpenCL device runs on the cores the CPU forms use: its estimate picks them
    ("pocl-cpu", ("cpu", "cpu"), "default for a cpu device"),
    ({"profile": "portable", "kind": "cpu"}, ("cpu", "cpu"), "default for a cpu device"),
    # a discrete GPU's kernels are fast enough to pay the detector's crossings; the merger's
    # copy of two frames side by side is not worth a launch and its transfers... or is it:
    # whatever the estimate says, the plan must say the same (below)
    ("nvidia-hopper", None, "default for a discrete-gpu device"),
    ("embedded-igpu", None, "default for an integrated-gpu device"),
])
def test_nobody_asking_places_for_the_devices_class(tmp_path, device, sides, by):
    """The default placement is the estimate of the device's class (or the GPU when the
    class is unknown); the plan names it with the figures, and the placement chosen is
    the least estimated of all."""
    model = load_system(_without_profile(tmp_path))
    rep = Reporter()
    facts = resolve(device, Pos(""), rep)
    rep.raise_if_errors()
    system, _ = run_passes(model, facts, zero_copy="off")
    placement = system.placement
    got = tuple(system.component(n).placement for n in ("merger", "detector"))
    if sides is not None:
        assert got == sides
    assert {b for _, b in placement.decided.values()} == {by}
    lines = "\n".join(plan_lines(system.plan))
    for name, side in zip(("merger", "detector"), got):
        assert f"{name}: {side.upper()} (by {by}" in lines
    if facts.kind:  # the estimate decided: its figures are shown, and it is the best
        cost = placement.costs["merger"]
        assert f"est. CPU {cost.cpu_s * 1e3:.3f} ms, GPU {cost.gpu_s * 1e3:.3f} ms" in lines
        margin = max((c.margin for c in placement.chains), default=0.0)  # device wins by it
        assert placement.estimate_s <= min(placement.all_gpu_s * (1 + margin),
                                           placement.all_cpu_s) + 1e-12
    else:
        assert placement.estimate_s is None and "est." not in lines


def _without_profile(tmp_path: Path) -> Path:
    """The vision system without its profile (tune's measurements replace the estimate)."""
    text = "\n".join(line for line in VISION.read_text().splitlines()
                     if not line.strip().startswith("profile:"))
    (tmp_path / "vs.yaml").write_text(text.replace("../", str(ROOT) + "/"))
    return tmp_path / "vs.yaml"


def test_an_explicit_placement_wins_over_the_devices_class(tmp_path):
    model = load_system(_without_profile(tmp_path))
    facts = resolve("pocl-cpu", Pos(""), Reporter())
    system, _ = run_passes(model, facts, places={"merger": "gpu"})
    assert system.placement.decided["merger"] == ("gpu", "command line")
    side, by = system.placement.decided["detector"]
    assert by == "default for a cpu device"
    # the detector is weighed with the merger it would be one kernel with on the device
    (chain,) = system.placement.chains
    assert chain.members == ("detector",) and chain.side == side
    assert [g[0] for g in chain.groups] == [("merger", "detector")]


def test_adapters_follow_the_placement_and_none_between_same_side_neighbours():
    system, _ = _passes(VISION, {"merger": "cpu"})
    # camera -> merger stays on the CPU; merged crosses to the detector on the GPU
    assert [(str(a.source), a.direction) for a in system.adapters] == [
        ("merger.merged", "cpu2gpu"), ("detector.mask", "gpu2cpu")]
    system, _ = _passes(VISION, {"merger": "cpu", "detector": "cpu"})
    assert system.adapters == []
    assert system.plan.copied_bytes == 0 and system.plan.launches == ()
    assert system.plan.programs == ()  # no kernel is built when nothing runs on the GPU
    system, _ = _passes(VISION, {"detector": "cpu"})
    assert [(str(a.source), a.direction) for a in system.adapters] == [
        ("camera1.image", "cpu2gpu"), ("camera2.image", "cpu2gpu"),
        ("merger.merged", "gpu2cpu")]
    assert [p.file for p in system.plan.programs] == ["merger.cl"]  # generated from its form


def test_command_line_placement_errors_are_usage_errors(capsys):
    for argv, message in (
            (["--place", "mergr=cpu"], "the model has no component 'mergr' (did you mean "
                                       "'merger'?)"),
            (["--place", "manager=gpu"], "'manager' is standard (VisionManager) and runs on "
                                         "the CPU only")):
        assert cli.main(["plan", str(VISION), *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, err
    with pytest.raises(SystemExit) as exc:
        cli.main(["plan", str(VISION), "--place", "merger:cpu"])
    assert exc.value.code == 2
    assert "write COMPONENT=gpu, COMPONENT=cpu or COMPONENT=auto" in capsys.readouterr().err
    with pytest.raises(UsageError):
        _passes(VISION, {"camera1": "gpu"})


def test_plan_says_who_placed_each_component(capsys):
    assert cli.main(["plan", str(VISION), "--place", "detector=cpu"]) == 0
    out = capsys.readouterr().out
    assert "  merger: GPU (by default)" in out
    assert "  detector: CPU (by command line)" in out


# --------------------------------------------------------------------------- auto

def _auto_model(tmp_path: Path, profile: str | None, extra: str = "") -> Path:
    if profile is not None:
        (tmp_path / "prof.yaml").write_text(textwrap.dedent(profile))
    (tmp_path / "vs.yaml").write_text(textwrap.dedent(f"""\
        system: vs
        platform:
          placement: auto
        {"  profile: prof.yaml" if profile is not None else ""}
        components:
          camera1: {{type: Camera, params: {{seed: 1}}}}
          camera2: {{type: Camera, params: {{seed: 2}}}}
          merger: {{type: ImageMerger{extra}}}
          detector: {{type: ObjectDetector}}
          manager: {{type: VisionManager}}
        connections:
          - camera1.image -> merger.left
          - camera2.image -> merger.right
          - merger.merged -> detector.frame
          - detector.mask -> manager.mask
        """))
    return tmp_path / "vs.yaml"


def _profile(merger, detector, latency_us, mb_s):
    return f"""\
        transfer: {{latency_us: {latency_us}, bandwidth_mb_s: {mb_s}}}
        components:
          merger: {{cpu_us: {merger[0]}, gpu_us: {merger[1]}}}
          detector: {{cpu_us: {detector[0]}, gpu_us: {detector[1]}}}
        """


# bytes crossing per frame with everything on the GPU: two camera frames in, the mask out
CAMERA, MERGED, MASK = 480 * 640 * 3, 480 * 1280 * 3, 480 * 1280


def _sides(system):
    return {n: system.component(n).placement for n in ("merger", "detector")}


def test_auto_puts_components_on_the_cpu_when_the_profile_says_it_is_faster(tmp_path):
    system, _ = _passes(_auto_model(tmp_path, _profile((100, 2000), (100, 2000), 10, 10_000)))
    assert _sides(system) == {"merger": "cpu", "detector": "cpu"}
    assert system.placement.estimate_s == pytest.approx(200e-6)
    assert system.adapters == []


def test_auto_keeps_components_on_the_gpu_when_that_is_faster_with_transfers(tmp_path):
    system, _ = _passes(_auto_model(tmp_path, _profile((5000, 100), (5000, 100), 10, 10_000)))
    assert _sides(system) == {"merger": "gpu", "detector": "gpu"}
    # by hand: 2 x 100 µs compute, which the two as one kernel take at the fusion
    # estimate's ratio (its fused time taken at the model's error more: place.py
    # CostModel.saving), + 3 copies of 10 µs + their bytes at 10,000 MB/s
    (group,) = system.groups
    fused, apart = group.estimate_s
    error = fuse_mod.fusion_costs(system)["error"]
    by_hand = 200e-6 * min(1, fused * (1 + error) / apart) + 3 * 10e-6 + \
        (2 * CAMERA + MASK) / 10_000e6
    assert system.placement.estimate_s == pytest.approx(by_hand)
    assert system.placement.all_cpu_s == pytest.approx(10_000e-6)


def test_auto_chooses_the_cpu_when_transfers_outweigh_a_faster_gpu(tmp_path):
    """Each component is twice as fast on the GPU, but the frames it would have to cross
    cost more than the time it saves (fusion off: each priced alone; the two as one kernel
    are weighed in tests/test_place_groups.py)."""
    system, _ = _passes(_auto_model(tmp_path, _profile((1000, 500), (1000, 500), 50, 1000)),
                        fusion="off")
    assert _sides(system) == {"merger": "cpu", "detector": "cpu"}
    assert system.placement.estimate_s == pytest.approx(2000e-6)
    all_gpu = 1000e-6 + 3 * 50e-6 + (2 * CAMERA + MASK) / 1000e6  # 3,607.6 µs
    assert system.placement.all_gpu_s == pytest.approx(all_gpu)
    lines = "\n".join(plan_lines(system.plan))
    assert "merger: CPU (by auto; est. CPU 1.000 ms, GPU 0.500 ms (profile))" in lines
    assert "est. 2.000 ms a frame (all on GPU 3.608 ms, all on CPU 2.000 ms)" in lines


def test_auto_splits_when_one_component_pays_for_its_transfers(tmp_path):
    """merger is fixed on the GPU by the model; the detector gains 1 ms on the CPU but its
    input (1,843,200 bytes) would cross instead of its mask (614,400 bytes).  Fusion off:
    each priced alone (on the GPU the detector would be one kernel with the merger)."""
    path = _auto_model(tmp_path, _profile((1, 1), (3000, 2900), 0, 1000),
                       extra=", placement: gpu")
    system, _ = _passes(path, fusion="off")
    assert _sides(system) == {"merger": "gpu", "detector": "gpu"}
    assert system.placement.decided["merger"] == ("gpu", "model")
    path = _auto_model(tmp_path, _profile((1, 1), (3000, 1000), 0, 1000),
                       extra=", placement: gpu")
    # detector on the GPU: 1000 µs + mask 614.4 µs; on the CPU: 3000 µs + merged 1843.2 µs
    system, _ = _passes(path, fusion="off")
    assert _sides(system)["detector"] == "gpu"
    path = _auto_model(tmp_path, _profile((1, 1), (300, 2000), 0, 1000),
                       extra=", placement: gpu")
    system, _ = _passes(path, fusion="off")  # 300 + 1843.2 < 2000 + 614.4
    assert _sides(system)["detector"] == "cpu"


def test_auto_without_a_profile_uses_the_static_estimate(tmp_path):
    system, _ = _passes(_auto_model(tmp_path, None))
    cost = system.placement.costs["detector"]
    nbytes = MERGED + MASK
    assert cost.source == "static estimate"
    assert cost.cpu_s == pytest.approx(nbytes / 1e9)
    assert cost.gpu_s == pytest.approx(20e-6 + nbytes / 20e9)


def test_auto_reads_the_profile_tune_writes_without_platform_profile(tmp_path):
    """(issue 24) `tune MODEL` writes tune/<system>.yaml when the model names no profile;
    placement: auto reads that file, not the static estimate, and plan says so."""
    path = _auto_model(tmp_path, None)
    (tmp_path / "tune").mkdir()
    (tmp_path / "tune" / "vs.yaml").write_text(textwrap.dedent(
        _profile((100, 2000), (100, 2000), 10, 10_000)))
    system, _ = _passes(path)
    assert _sides(system) == {"merger": "cpu", "detector": "cpu"}
    assert {c.source for c in system.placement.costs.values()} == {"profile"}
    assert "merger: CPU (by auto; est. CPU 0.100 ms, GPU 2.000 ms (profile);" in \
        "\n".join(plan_lines(system.plan))
    from gpucompgen.tune import default_profile_path

    model = load_system(path)
    assert default_profile_path(path, model) == tmp_path / "tune" / "vs.yaml"
    # a broken one is reported in place, as a named one is
    (tmp_path / "tune" / "vs.yaml").write_text("components: {merger: {cpu_us: -1}}\n")
    with pytest.raises(GpucompgenError, match="must be a number"):
        _passes(path)


def test_tune_frames_are_camera_frames_in_each_ports_own_type():
    """tune feeds camera-like frames (not uniform noise), every byte of the port: an int16
    port gets twice a uint8 port's bytes."""
    from gpucompgen.tune import camera_frame

    rgb = camera_frame((48, 64, 3), "uint8")
    np.testing.assert_array_equal(rgb, _camera_frame(64, 48))
    gray = camera_frame((48, 64), "uint8")
    assert gray.shape == (48, 64) and gray.dtype == np.uint8
    gradient = camera_frame((48, 64), "int16")
    assert gradient.dtype == np.int16 and gradient.nbytes == 2 * gray.nbytes
    np.testing.assert_array_equal(gradient, (gray.astype(np.int16) - 128) * 4)
    assert not np.array_equal(camera_frame((48, 64), "uint8", 1), gray)  # a second input
    # smoother than noise: neighbouring pixels differ by little on the whole
    assert np.abs(np.diff(gray.astype(np.int16), axis=1)).mean() < 20


def _camera_frame(width: int, height: int) -> np.ndarray:
    camera = Camera(width=width, height=height, seed=1)
    camera.initialize()
    return camera.execute()


def test_the_heuristic_agrees_with_exhaustive_search(tmp_path, monkeypatch):
    for profile in (_profile((1000, 500), (1000, 500), 50, 1000),
                    _profile((5000, 100), (5000, 100), 10, 10_000),
                    _profile((1, 1), (300, 2000), 0, 1000)):
        exhaustive, _ = _passes(_auto_model(tmp_path, profile))
        monkeypatch.setattr(place_mod, "EXHAUSTIVE_LIMIT", 0)
        greedy, _ = _passes(_auto_model(tmp_path, profile))
        monkeypatch.undo()
        assert _sides(greedy) == _sides(exhaustive)
        assert greedy.placement.search == "greedy + local improvement"


def test_auto_on_a_long_chain_uses_the_heuristic(tmp_path):
    mirrors = [f"mirror{i}" for i in range(1, 21)]
    comps = "\n".join(f"  {m}: {{type: VerticalMirror, placement: auto}}" for m in mirrors)
    chain = ["source.image"] + [f"{m}.mirrored" for m in mirrors]
    conns = "\n".join(f"  - {a} -> {b.split('.')[0]}.image"
                      for a, b in zip(chain, [f"{m}.x" for m in mirrors]))
    path = tmp_path / "chain.yaml"
    path.write_text(f"system: chain\ncomponents:\n  source: {{type: StillImage}}\n{comps}\n"
                    f"  sink: {{type: FrameSink}}\nconnections:\n{conns}\n"
                    f"  - mirror20.mirrored -> sink.image\n")
    system, _ = _passes(path)
    assert system.placement.search == "greedy + local improvement"
    # the static estimate favours the GPU for a frame this size, once it is there
    assert {system.component(m).placement for m in mirrors} == {"gpu"}


def test_profile_problems_are_reported_in_place(tmp_path):
    path = _auto_model(tmp_path, """\
        transfer: {latency_us: fast, bandwidth_mb_s: 1000}
        components:
          merger: {cpu_us: 1, gpu_us: 2, sizes: "1x1x3 -> 1x2x3"}
          nobody: {cpu_us: 1, gpu_us: 2}
        """)
    with pytest.raises(GpucompgenError) as exc:
        _passes(path)
    text = str(exc.value)
    assert "prof.yaml:1:24: error: transfer.latency_us must be a number from 0 to 1e+12, " \
        "not 'fast'" in text
    path = _auto_model(tmp_path, """\
        components:
          merger: {cpu_us: 1, gpu_us: 2, sizes: "1x1x3 -> 1x2x3"}
          nobody: {cpu_us: 1, gpu_us: 2}
        """)
    _, warnings = _passes(path)
    text = "\n".join(w.format() for w in warnings)
    assert "prof.yaml:2:41: warning: 'merger' was timed at 1x1x3 -> 1x2x3" in text
    assert "prof.yaml:3:3: warning: the profile times 'nobody'" in text


def _tree(tmp_path: Path, n: int, profile: str = "") -> Path:
    """A source feeding a binary tree of n VerticalMirrors placed auto (fan-out at every
    level), each leaf into a sink."""
    comps = [f"  m{i}: {{type: VerticalMirror, placement: auto}}" for i in range(n)]
    conns = [f"  - {'source.image' if i == 0 else f'm{(i - 1) // 2}.mirrored'} -> m{i}.image"
             for i in range(n)]
    leaves = [i for i in range(n) if 2 * i + 1 >= n]
    comps += [f"  sink{i}: FrameSink" for i in leaves]
    conns += [f"  - m{i}.mirrored -> sink{i}.image" for i in leaves]
    if profile:
        (tmp_path / "prof.yaml").write_text(profile)
    path = tmp_path / "tree.yaml"
    path.write_text("system: tree\n" + ("platform: {profile: prof.yaml}\n" if profile else "")
                    + "components:\n  source: {type: StillImage, params: {width: 4096, "
                    "height: 4096}}\n" + "\n".join(comps) + "\nconnections:\n"
                    + "\n".join(conns) + "\n")
    return path


def test_sixteen_auto_components_are_placed_without_calling_frame_per_placement(
        tmp_path, monkeypatch):
    """2^16 placements are summed at once: frame() runs for the near-best few only (it
    rescanned every edge for each of the 65,536 placements: ~210 s)."""
    import random
    import time

    rng = random.Random(16)
    profile = "transfer: {latency_us: 30, bandwidth_mb_s: 9000}\ncomponents:\n" + "".join(
        f"  m{i}: {{cpu_us: {rng.randint(1, 9000)}, gpu_us: {rng.randint(1, 9000)}}}\n"
        for i in range(16))
    calls = []
    frame = place_mod.CostModel.frame
    monkeypatch.setattr(place_mod.CostModel, "frame",
                        lambda self, sides: calls.append(1) or frame(self, sides))
    start = time.perf_counter()
    system, _ = _passes(_tree(tmp_path, 16, profile))
    took = time.perf_counter() - start
    assert system.placement.search == "exhaustive over 65,536 placements"
    assert len(calls) < 100, len(calls)
    assert took < 30, took  # generous: about a second on a loaded laptop


def test_the_summed_search_picks_what_calling_frame_for_each_placement_picks(tmp_path):
    """choose() against the plain definition: min over itertools.product of frame()."""
    import random

    system, _ = _passes(_tree(tmp_path, 7))
    names = [f"m{i}" for i in range(7)]
    rng = random.Random(7)
    for trial in range(40):
        components = {n: (rng.choice([1, 2, 5, 50, 500]) * 1e-6,
                          rng.choice([1, 2, 5, 50, 500]) * 1e-6) for n in names}
        transfer = (rng.choice([0, 1e-6, 3e-5]), rng.choice([1e8, 1e9, 1e11]))
        for zero_copy in (False, True):
            system.zero_copy = zero_copy
            model = place_mod.CostModel(system, {"components": components,
                                                 "transfer": transfer})

            def key(sides, model=model):
                return (round(model.frame(sides), 12), sum(s == "cpu" for s in sides.values()))

            brute = min((dict(zip(names, combo)) for combo in
                         itertools.product(("gpu", "cpu"), repeat=len(names))), key=key)
            assert place_mod.choose(model, names)[0] == brute, (trial, zero_copy)


def test_profile_numbers_too_large_for_a_float_are_reported_in_place(tmp_path):
    path = _auto_model(tmp_path, f"""\
        transfer: {{latency_us: 1, bandwidth_mb_s: 1000}}
        components:
          merger: {{cpu_us: {"9" * 400}, gpu_us: 2}}
          detector: {{cpu_us: 1.0e+400, gpu_us: -1}}
        """)
    with pytest.raises(GpucompgenError) as exc:
        _passes(path)
    text = str(exc.value)
    assert "prof.yaml:3:20: error: cpu_us must be a number from 0 to 1e+12, not a number " \
        "over 1e+20" in text
    assert "prof.yaml:4:22: error: cpu_us must be a number from 0 to 1e+12, not inf" in text
    assert "error: gpu_us must be a number from 0 to 1e+12, not -1" in text
    assert proc_free(path)


def proc_free(path: Path) -> bool:
    """check says the same, with no internal error."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "check", str(path)],
                          capture_output=True, text=True, check=False)
    return proc.returncode == 1 and "internal error" not in proc.stderr


# --------------------------------------------------------------------------- runs

def _run(tmp_path: Path, model: Path, places: dict, frames: int):
    """Masks the VisionManager got and its decisions, for one placement."""
    tag = "-".join(f"{k}{v}" for k, v in sorted(places.items())) or "default"
    out = tmp_path / tag
    result = compile_model(model, out, device="auto", places=places)
    write(result, out)
    module = load_generated(out / f"{result.system.name}.py", f"placed_{tag}")
    masks: list[np.ndarray] = []
    original = module.VisionManager.execute

    def spy(self, mask):
        masks.append(np.array(mask, copy=True))
        return original(self, mask)

    module.VisionManager.execute = spy
    try:
        from gpucompgen import runtime
        ran = module.run(frames=frames, monitor=runtime.Monitor(progress=False,
                                                               options={"quiet": True}))
    finally:
        module.VisionManager.execute = original
    assert ran.frames == frames
    decisions = [(d.frame, d.action, d.target) for d in ran.components["manager"].history]
    return masks, decisions


def _every_placement(names):
    for sides in itertools.product(("gpu", "cpu"), repeat=len(names)):
        yield dict(zip(names, sides))


def detect(frame, red_min=150, margin=80):
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return np.where((r >= red_min) & (r - g >= margin) & (r - b >= margin), 255, 0
                    ).astype(np.uint8)


def test_every_placement_of_the_vision_system_gives_identical_output(tmp_path):
    require_opencl()
    frames = 30
    runs = {tuple(p.values()): _run(tmp_path, VISION, p, frames)
            for p in _every_placement(["merger", "detector"])}
    cam1, cam2 = Camera(seed=1), Camera(seed=2)
    cam1.initialize()
    cam2.initialize()
    expected = [detect(np.hstack([cam1.execute(), cam2.execute()])) for _ in range(frames)]
    reference_decisions = runs["gpu", "gpu"][1]
    assert any(m.any() for m in expected), "the scene has buoys to detect"
    for key, (masks, decisions) in runs.items():
        assert len(masks) == frames, key
        for f, (mask, want) in enumerate(zip(masks, expected)):
            np.testing.assert_array_equal(mask, want, err_msg=f"{key} frame {f}")
        assert decisions == reference_decisions, key
    assert {a for _, a, _ in reference_decisions} - {"search"}, "some decisions move"


def test_every_placement_of_the_two_branch_model_gives_identical_output(tmp_path):
    require_opencl()
    frames = 10
    names = ["blur1", "blur2", "merger", "detector"]
    runs = {tuple(p.values()): _run(tmp_path, BRANCHES, p, frames)
            for p in _every_placement(names)}
    assert len(runs) == 16
    reference_masks, reference_decisions = runs["gpu", "gpu", "gpu", "gpu"]
    assert any(m.any() for m in reference_masks)
    for key, (masks, decisions) in runs.items():
        for f, (a, b) in enumerate(zip(masks, reference_masks, strict=True)):
            np.testing.assert_array_equal(a, b, err_msg=f"{key} frame {f}")
        assert decisions == reference_decisions, key
    # and the all-CPU run is the library's numpy, not the kernels: compare one frame with
    # an independent reference
    from test_parallel_and_zero_copy import box_blur
    cam1, cam2 = Camera(seed=1), Camera(seed=2)
    cam1.initialize()
    cam2.initialize()
    expected = detect(np.hstack([box_blur(cam1.execute(), 2), box_blur(cam2.execute(), 2)]))
    np.testing.assert_array_equal(runs["cpu", "cpu", "cpu", "cpu"][0][0], expected)


def test_a_cpu_function_returning_the_wrong_shape_is_named(tmp_path):
    from gpucompgen.runtime import CpuFunctionComponent, Size

    # right on initialize()'s zero frame, one column short on a real one
    comp = CpuFunctionComponent(lambda image: image[:, :-1] if image.any() else image, "mirror",
                                inputs=(("image", np.uint8),), outputs=(("mirrored", np.uint8),))
    assert comp.initialize(Size(4, 6, 3)) == Size(4, 6, 3)
    with pytest.raises(ValueError, match=r"mirror\.mirrored: the CPU function <lambda>\(\) "
                                         r"returned uint8 \(4, 5, 3\), not uint8 \(4, 6, 3\)"):
        comp.execute(np.ones((4, 6, 3), np.uint8))


def test_a_cpu_function_may_return_one_channel_as_height_width_1():
    """(issue 22) a one-channel output as height x width x 1 goes on as height x width,
    a view of the same memory; two channels are still refused."""
    from gpucompgen.runtime import CpuFunctionComponent, Size

    comp = CpuFunctionComponent(lambda image: image.sum(axis=2, keepdims=True, dtype=np.uint8),
                                "gray", inputs=(("image", np.uint8),),
                                outputs=(("gray", np.uint8),))
    assert comp.initialize(Size(4, 6, 3)) == Size(4, 6, 1)
    frame = np.arange(72, dtype=np.uint8).reshape(4, 6, 3)
    result = comp.execute(frame)
    assert result.shape == (4, 6)
    np.testing.assert_array_equal(result, frame.sum(axis=2, dtype=np.uint8))
    kept = np.zeros((4, 6, 1), np.uint8)
    comp = CpuFunctionComponent(lambda image: kept, "keep", inputs=(("image", np.uint8),),
                                outputs=(("mask", np.uint8),))
    comp.initialize(Size(4, 6, 3))
    assert np.shares_memory(comp.execute(frame), kept)  # no copy
    comp = CpuFunctionComponent(lambda image: image[..., :2] if image.any() else image[..., :1],
                                "two", inputs=(("image", np.uint8),),
                                outputs=(("mask", np.uint8),))
    comp.initialize(Size(4, 6, 3))
    with pytest.raises(ValueError, match=r"two\.mask: .* returned uint8 \(4, 6, 2\), not "
                                         r"uint8 \(4, 6\) \(or \(4, 6, 1\)\)"):
        comp.execute(frame)


def test_tune_writes_the_profile_that_auto_reads(tmp_path, capsys):
    require_opencl()
    import shutil

    import yaml

    model = tmp_path / "vision_system.yaml"
    shutil.copy(VISION, model)
    assert cli.main(["tune", str(model), "--frames", "2"]) == 0
    profile = tmp_path / "tune" / "vision_system.yaml"  # where the model's profile points
    assert f"wrote {profile}" in capsys.readouterr().out
    data = yaml.safe_load(profile.read_text())
    assert set(data["components"]) == {"merger", "detector"}
    assert data["components"]["detector"]["sizes"] == "480x1280x3 -> 480x1280x1"
    for entry in data["components"].values():
        assert entry["cpu_us"] > 0 and entry["gpu_us"] > 0
    assert data["transfer"]["bandwidth_mb_s"] > 0
    system, warnings = _passes(model, {"merger": "auto", "detector": "auto"})
    assert warnings == []
    assert {c.source for c in system.placement.costs.values()} == {"profile"}
    merger = data["components"]["merger"]
    assert system.placement.costs["merger"].cpu_s == pytest.approx(merger["cpu_us"] * 1e-6)
    # the group the fuse pass chooses, measured against its members apart
    (name, group), = data["groups"].items()
    assert group["members"] == ["merger", "detector"] and group["sizes"] == \
        "480x640x3, 480x640x3 -> 480x1280x1"
    assert group["fused_us"] > 0 and group["apart_us"] > 0
    system, _ = _passes(model)
    lines = "\n".join(plan_lines(system.plan))
    if group["fused_us"] < group["apart_us"]:  # kept, its measurement beside its estimate
        assert [g.name for g in system.groups] == [name]
        # printed as the plan prints seconds (fused_us * 1e-6 s): 1541.5 us is 1.541 ms
        # there, where fused_us * 1e-3 would round to 1.542
        assert f"measured: {group['fused_us'] * 1e-6 * 1e3:.3f} ms as one kernel" in lines
    else:  # refused, with the figures
        assert system.groups == []
        assert "measured: with merger the group's kernel took" in " ".join(lines.split())


def test_a_users_flexible_type_runs_on_either_side(tmp_path):
    """A user's flexible type: its kernel and its CPU function copied beside the program."""
    require_opencl()
    user = ROOT / "tests" / "data" / "user_model"
    import shutil

    shutil.copy(user / "brighten.cl", tmp_path)
    (tmp_path / "brighten_cpu.py").write_text(textwrap.dedent("""\
        import numpy as np

        def brighten(image, gain):
            return np.minimum(image.astype(np.int32) + gain, 255).astype(np.uint8)
        """))
    (tmp_path / "types.yaml").write_text(textwrap.dedent("""\
        component_types:
          Brighten:
            kind: flexible
            params:
              gain: {type: int, default: 40, min: 0, max: 255}
            inputs:
              image: {dtype: uint8, channels: 3}
            outputs:
              brighter: {dtype: uint8, channels: 3}
            kernel: {file: brighten.cl, function: brighten}
            cpu: {file: brighten_cpu.py, function: brighten}
        """))
    model = tmp_path / "bright.yaml"
    model.write_text(textwrap.dedent("""\
        system: bright
        types: [types.yaml]
        components:
          source: {type: StillImage, params: {width: 90, height: 70, seed: 3}}
          brighten: {type: Brighten, params: {gain: 70}}
          sink: {type: FrameSink}
        connections:
          - source.image -> brighten.image
          - brighten.brighter -> sink.image
        """))
    from gpucompgen import runtime
    from gpucompgen.library.still_image import StillImage

    source = StillImage(width=90, height=70, seed=3)
    source.initialize()
    frame = source.execute()
    expected = np.minimum(frame.astype(int) + 70, 255).astype(np.uint8)
    for side in ("gpu", "cpu"):
        out = tmp_path / side
        result = compile_model(model, out, places={"brighten": side})
        write(result, out)
        lib = sorted(p.name for p in (out / "bright_lib").iterdir())
        assert lib == (["brighten.cl"] if side == "gpu" else ["brighten_cpu.py"])
        module = load_generated(out / "bright.py", f"bright_{side}")
        ran = module.run(frames=3, monitor=runtime.Monitor(progress=False))
        np.testing.assert_array_equal(ran.components["sink"].last, expected, err_msg=side)


def test_a_profile_measured_on_another_device_is_left_out_with_a_warning(tmp_path):
    """tune's figures time one device: a build for another device that was queried
    (--device auto, `gpucompgen run`) warns and places by the estimate of its class; the
    same profile on the device it names decides."""
    from dataclasses import replace

    from gpucompgen.device import PROFILES

    profile = "        device: \"Board X\"\n" + _profile((5000, 100), (5000, 100), 10, 10_000)
    path = _auto_model(tmp_path, profile)
    here = replace(PROFILES["pocl-cpu"], name="Board Y")
    system, warnings = run_passes(load_system(path), here, zero_copy="off")
    assert _sides(system) == {"merger": "cpu", "detector": "cpu"}  # the cpu class's estimate
    assert system.placement.costs["merger"].source == "estimate for a cpu device"
    (warning,) = [w for w in warnings if "measured on" in w.message]
    assert warning.message.startswith("this profile was measured on 'Board X', not on the "
                                      "device this build is for ('Board Y')")
    assert (warning.line, warning.col) == (1, 9)
    assert "gpucompgen tune" in warning.hint
    system, warnings = run_passes(load_system(path), replace(here, name="Board X"),
                                  zero_copy="off")
    assert _sides(system) == {"merger": "gpu", "detector": "gpu"}  # the profile's figures
    assert not [w for w in warnings if "measured on" in w.message]
