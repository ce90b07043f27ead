"""Placement weighs fused groups (issue 24): a chain of fusable components placed together
on the device becomes one kernel, so the place pass prices each maximal chain whole — on
the CPU, each its CPU form; on the device, the groups the fuse pass would make — and keeps
the cheaper.  The choices are the estimate's (figures computed here by hand from the cost
tables), `tune`'s measurements replace the estimate, and `plan` reports what decided.
No program runs here: tests/test_decisions_property.py runs the drawn systems under every
decision, this choice included, and demands the reference's frames.
"""

from __future__ import annotations

import itertools
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from gpucompgen.device import resolve
from gpucompgen.errors import Pos, Reporter
from gpucompgen.model import load_system
from gpucompgen.passes import fuse as fuse_mod
from gpucompgen.passes import place as place_mod
from gpucompgen.passes import run_passes
from gpucompgen.plan import plan_lines

SINKS = (ROOT / "tests" / "data" / "decisions" / "types.yaml").as_posix()
# camera -> gray -> threshold -> scale -> sink: a pointwise chain of three
CHAIN = {"gray": "RgbToGray", "thr": "ThresholdGray", "scale": "ConvertScaleGray"}


def _model(tmp_path: Path, width: int, height: int, steps: dict[str, str] = CHAIN,
           profile: str | None = None, extra: str = "") -> Path:
    names = list(steps)
    comps = "\n".join(f"  {n}: {{type: {t}{extra}}}" for n, t in steps.items())
    ports = {"RgbToGray": ("image", "gray"), "ThresholdGray": ("image", "thresholded"),
             "ConvertScaleGray": ("image", "scaled"), "InRange": ("image", "mask"),
             "ErodeGray": ("image", "eroded"), "DilateGray": ("image", "dilated")}
    conns = [f"camera.image -> {names[0]}.{ports[steps[names[0]]][0]}"]
    conns += [f"{a}.{ports[steps[a]][1]} -> {b}.{ports[steps[b]][0]}"
              for a, b in itertools.pairwise(names)]
    conns.append(f"{names[-1]}.{ports[steps[names[-1]]][1]} -> sink.image")
    platform = ""
    if profile is not None:
        (tmp_path / "profile.yaml").write_text(textwrap.dedent(profile))
        platform = "platform:\n  profile: profile.yaml\n"
    (tmp_path / "m.yaml").write_text(
        f"system: chain\ntypes: [{SINKS}]\n{platform}components:\n"
        f"  camera: {{type: Camera, params: {{width: {width}, height: {height}}}}}\n"
        f"{comps}\n  sink: {{type: Sink_uint8x1}}\nconnections:\n"
        + "".join(f"  - {c}\n" for c in conns))
    return tmp_path / "m.yaml"


def _passes(path: Path, device: str = "pocl-cpu", **options):
    facts = resolve(device, Pos(""), Reporter())
    return run_passes(load_system(path), facts, **options)[0]


def _sides(system, names=CHAIN) -> dict[str, str]:
    return {n: system.component(n).placement for n in names}


@pytest.fixture
def costs(monkeypatch):
    """Set the cpu class's placement row (the fitted one changes with the kernels), and
    the fusion estimate's error at 25% (the fitted one changes with every refit)."""
    monkeypatch.setitem(fuse_mod.FUSION_COSTS, "cpu",
                        {**fuse_mod.FUSION_COSTS["cpu"], "error": 0.25})

    def set_row(**row):  # no margin unless a test gives one (the by-hand sums have none)
        monkeypatch.setitem(place_mod.PLACEMENT_COSTS, "cpu",
                            {**place_mod.PLACEMENT_COSTS["cpu"], "error": 0.0, **row})
        return place_mod.PLACEMENT_COSTS["cpu"]
    return set_row


def _by_hand(system, row, names=CHAIN):
    """The chain's frame on the CPU, and on the device apart, from the tables: each
    component's bytes at the CPU forms' rate; on the device its launch and bytes at the
    kernels' rate; and the two zero-copy crossings (camera -> chain, chain -> sink) at
    the transfer's latency.  As one group the device's part is taken at the fusion
    estimate's fused / apart, fused taken at the model's error more (_ratio).  A CPU form
    also costs the loop's call of it (cpu_call_s)."""
    nbytes = {n: sum(p.data.nbytes for p in system.component(n).ports) for n in names}
    cpu = sum(row["cpu_call_s"] + b / row["cpu_bytes_per_s"] for b in nbytes.values())
    apart_gpu = sum(row["gpu_launch_s"] + b / row["gpu_bytes_per_s"] for b in nbytes.values())
    return cpu, apart_gpu, 2 * row["transfer_latency_s"]


def _ratio(system, fused: float, apart: float) -> float:
    return min(1.0, fused * (1 + fuse_mod.fusion_costs(system)["error"]) / apart)


def test_a_chain_goes_to_the_device_when_its_group_beats_the_cpu_forms(tmp_path, costs):
    """Each component alone is cheaper on the CPU (its launch costs more than its CPU form
    saves), but the three as one kernel are cheaper than the three CPU forms."""
    row = costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=50e-6)
    system = _passes(_model(tmp_path, 1280, 720))
    assert _sides(system) == dict.fromkeys(CHAIN, "gpu")
    (group,) = system.groups
    assert [m.name for m in group.members] == list(CHAIN)
    fused, apart = group.estimate_s
    cpu, apart_gpu, crossings = _by_hand(system, row)
    for name in CHAIN:  # alone, each is estimated faster on the CPU
        cost = system.placement.costs[name]
        assert cost.cpu_s < cost.gpu_s
    device = apart_gpu * _ratio(system, fused, apart) + crossings
    assert device < cpu
    assert system.placement.estimate_s == pytest.approx(device)
    (chain,) = system.placement.chains
    assert chain.side == "gpu" and chain.gpu_s == pytest.approx(device)
    assert chain.cpu_s == pytest.approx(cpu)  # nothing crosses: the camera is on the CPU
    lines = "\n".join(plan_lines(system.plan))
    ms = place_mod._ms
    assert (f"chain gray, thr, scale: on the device; frame est. {ms(device)} (with the chain "
            f"on the CPU {ms(cpu)}, on the device {ms(device)} as 1 kernel)") in lines
    saved = apart_gpu * (1 - _ratio(system, fused, apart))
    assert (f"group gray+thr+scale chosen: one kernel saves {ms(saved)} a frame over its "
            f"members apart ({apart / fused:.2f}x: fused {ms(fused)}, apart {ms(apart)}; "
            "fusion estimate for a cpu device, fused taken 1.25x)") in lines
    assert "gray: GPU (by default for a cpu device; est. CPU" in lines
    assert "its chain weighed whole: on the device, one kernel with thr, scale" in lines


def test_the_device_must_win_by_the_estimates_error(tmp_path, costs):
    """With the row's error e, a placement with chain members on the device is weighed
    at (1 + e) its estimate: the chain goes to the device only where its estimate is
    below the CPU's by more than e, found by hand from the sums of the first test."""
    row = costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=50e-6)
    system = _passes(_model(tmp_path, 1280, 720))
    cpu, apart_gpu, crossings = _by_hand(system, row)
    fused, apart = system.groups[0].estimate_s
    device = apart_gpu * _ratio(system, fused, apart) + crossings
    win = cpu / device - 1  # what the device wins by, as a fraction of its estimate
    assert win > 0.02
    for error, side in ((win - 0.01, "gpu"), (win + 0.01, "cpu")):
        costs(error=error)
        system = _passes(_model(tmp_path, 1280, 720))
        assert _sides(system) == dict.fromkeys(CHAIN, side), error
        (chain,) = system.placement.chains
        assert chain.margin == error
        assert chain.chosen_s == pytest.approx(device if side == "gpu" else cpu)
        assert f"the device must win by the estimate's error, {error:.0%})" in \
            "\n".join(plan_lines(system.plan))


def test_a_chain_stays_on_the_cpu_when_its_group_does_not_pay(tmp_path, costs):
    row = costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=1e-3)
    system = _passes(_model(tmp_path, 1280, 720))
    assert _sides(system) == dict.fromkeys(CHAIN, "cpu")
    (chain,) = system.placement.chains
    cpu, apart_gpu, crossings = _by_hand(system, row)
    fused, apart = fuse_mod.estimate(system, set(CHAIN))
    assert chain.side == "cpu" and chain.chosen_s == pytest.approx(cpu)
    assert chain.gpu_s == pytest.approx(apart_gpu * _ratio(system, fused, apart) + crossings)
    lines = "\n".join(plan_lines(system.plan))
    assert "group gray+thr+scale refused: one kernel saves" in lines
    assert "its chain weighed whole: on the CPU" in lines
    assert system.groups == []


def test_small_frames_stay_on_the_cpu_large_ones_go_to_the_device(tmp_path, costs):
    """The same chain, decided by its size: launches dominate a small frame."""
    costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=50e-6)
    small = _passes(_model(tmp_path, 64, 48))
    assert _sides(small) == dict.fromkeys(CHAIN, "cpu")
    large = _passes(_model(tmp_path, 1920, 1080))
    assert _sides(large) == dict.fromkeys(CHAIN, "gpu")


def test_fusion_off_and_fuse_false_weigh_no_chain(tmp_path, costs):
    """Without fusion the components are priced one by one, as before: no chain, and
    the per-component estimate (the CPU) decides."""
    costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=50e-6)
    path = _model(tmp_path, 1280, 720)
    off = _passes(path, fusion="off")
    assert off.placement.chains == [] and _sides(off) == dict.fromkeys(CHAIN, "cpu")
    kept = _passes(_model(tmp_path, 1280, 720, extra=", fuse: false"))
    assert kept.placement.chains == [] and _sides(kept) == dict.fromkeys(CHAIN, "cpu")


def test_an_explicit_placement_is_never_weighed(tmp_path, costs):
    costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=50e-6)
    system = _passes(_model(tmp_path, 1280, 720), places=dict.fromkeys(CHAIN, "cpu"))
    assert _sides(system) == dict.fromkeys(CHAIN, "cpu")
    assert not system.placement.chains


def _profile(fused_us: float, apart_us: float, sizes: str, thr_gpu_us: float = 80) -> str:
    # a group measured slower is refused, and tune measures the next groups the fuse pass
    # then chooses: thr+scale, then gray+thr (here slower too)
    smaller = ("\n          thr_scale: {members: [thr, scale], fused_us: 270, apart_us: 260}"
               "\n          gray_thr: {members: [gray, thr], fused_us: 420, apart_us: 400}"
               if fused_us >= apart_us else "")
    return f"""\
        transfer: {{latency_us: 10, bandwidth_mb_s: 5000}}
        components:
          gray: {{cpu_us: 300, gpu_us: 320}}
          thr: {{cpu_us: 60, gpu_us: {thr_gpu_us}}}
          scale: {{cpu_us: 160, gpu_us: 180}}
        groups:
          gray_thr_scale: {{members: [gray, thr, scale], sizes: "{sizes}", fused_us: {fused_us}, apart_us: {apart_us}}}{smaller}
        """


@pytest.mark.parametrize("fused_us, side", [(300, "gpu"), (700, "cpu")])
def test_tunes_measurement_of_the_group_replaces_the_estimate(tmp_path, fused_us, side):
    """The profile times each component (every one faster on the CPU alone: 520 µs
    against 580) and the group: at 300 µs fused against 580 apart the chain runs on the
    device as one kernel (580 x 300/580 + two crossings of 10 µs = 320 µs < 520); measured
    slower than its members the group is refused, and so is the device (the smaller
    groups the fuse pass would then choose measured slower too)."""
    sizes = "720x1280x3 -> 720x1280x1"
    system = _passes(_model(tmp_path, 1280, 720, profile=_profile(fused_us, 580, sizes)))
    assert _sides(system) == dict.fromkeys(CHAIN, side)
    lines = "\n".join(plan_lines(system.plan))
    if side == "gpu":
        assert system.placement.estimate_s == pytest.approx(320e-6)
        assert ("group gray+thr+scale chosen: one kernel saves 0.280 ms a frame over its "
                "members apart (1.93x: fused 0.300 ms, apart 0.580 ms; measured by tune)") \
            in lines
        (group,) = system.groups
        assert "measured: 0.300 ms as one kernel, 0.580 ms apart (profile)" in group.estimate
    else:  # measured slower: the fuse pass refuses the group, and the chain stays
        assert system.placement.estimate_s == pytest.approx(520e-6)
        assert system.groups == []
        assert "chain gray, thr, scale: on the CPU" in lines


def test_a_measured_group_is_its_own_time_not_its_members_times_its_ratio(tmp_path):
    """A burst of load caught thr's timing alone (3 ms); the group, timed with its
    members apart in turn, took 0.3 ms: the chain's device figure is the group's time
    (+ two crossings), not the ratio times its members' (3.5 ms x 300/580)."""
    sizes = "720x1280x3 -> 720x1280x1"
    system = _passes(_model(tmp_path, 1280, 720,
                            profile=_profile(300, 580, sizes, thr_gpu_us=3000)))
    assert _sides(system) == dict.fromkeys(CHAIN, "gpu")
    assert system.placement.estimate_s == pytest.approx(320e-6)


def test_a_group_alone_on_the_device_when_the_rest_of_its_chain_is_cheaper_on_the_cpu(
        tmp_path, costs):
    """A chain whose stencil members do not fuse (recomputation) and cost much more on
    the device: only its pointwise group goes there."""
    steps = {"gray": "RgbToGray", "thr": "ThresholdGray", "scale": "ConvertScaleGray",
             "ero": "ErodeGray", "dil": "DilateGray"}
    costs(cpu_bytes_per_s=10e9, gpu_bytes_per_s=10e9, gpu_launch_s=50e-6)
    system = _passes(_model(tmp_path, 1280, 720, steps))
    sides = _sides(system, steps)
    (chain,) = system.placement.chains
    assert chain.members == tuple(steps)
    # whatever wins, the placement is the least estimated of those weighed, and the plan
    # says which of its groups were chosen
    assert chain.chosen_s <= min(chain.cpu_s, chain.gpu_s * (1 + chain.margin)) + 1e-12
    for members, chosen, *_ in chain.groups:
        assert chosen == all(sides[m] == "gpu" for m in members)
    assert {sides[m] for m in ("gray", "thr", "scale")} == {"gpu"}
    assert {sides[m] for m in ("ero", "dil")} == {"cpu"}
    assert chain.side == "mixed"


# --------------------------------------------------------------------------- drawn chains

TYPES = ("ThresholdGray", "ConvertScaleGray", "ErodeGray", "DilateGray")


@settings(max_examples=25, deadline=None, derandomize=True)
@given(steps=st.lists(st.sampled_from(TYPES), min_size=1, max_size=5),
       size=st.sampled_from([(16, 16), (320, 180), (1280, 720)]),
       row=st.sampled_from([None, (10e9, 10e9, 100e-6), (2e9, 20e9, 20e-6),
                            (10e9, 10e9, 2e-3)]),
       fusion=st.sampled_from(["auto", "off"]))
def test_drawn_chains_are_placed_at_the_least_estimate_plan_reports(
        tmp_path_factory, steps, size, row, fusion):
    """Random chains at random sizes under drawn cost rows: the placement is never
    estimated slower than its chain all on the CPU or all on the device (as its groups),
    the chain's figures are those, and every component's plan line names its chain's
    decision."""
    names = {"gray": "RgbToGray", **{f"s{i}": t for i, t in enumerate(steps)}}
    with pytest.MonkeyPatch.context() as patch:  # one example's table, not the next's
        if row is not None:
            patch.setitem(place_mod.PLACEMENT_COSTS, "cpu", {
                **place_mod.PLACEMENT_COSTS["cpu"], "cpu_bytes_per_s": row[0],
                "gpu_bytes_per_s": row[1], "gpu_launch_s": row[2]})
        system = _passes(_model(tmp_path_factory.mktemp("c"), *size, names), fusion=fusion)
    placement = system.placement
    sides = _sides(system, names)
    margin = max((c.margin for c in placement.chains), default=0.0)  # device wins by it
    assert placement.estimate_s <= min(placement.all_cpu_s,
                                       placement.all_gpu_s * (1 + margin)) + 1e-12
    lines = {line.split(":")[0]: line for line in system.plan.placement}
    if fusion == "off":
        assert not placement.chains
        return
    (chain,) = placement.chains
    assert chain.chosen_s == pytest.approx(placement.estimate_s)
    assert chain.cpu_s == pytest.approx(placement.all_cpu_s)  # the chain is every component
    assert chain.gpu_s == pytest.approx(placement.all_gpu_s)
    for name in names:
        assert f"its chain weighed whole: {chain.where}" in lines[name]
    want = {"gpu": {"gpu"}, "cpu": {"cpu"}, "mixed": {"gpu", "cpu"}}[chain.side]
    assert set(sides.values()) == want
    # every group the fuse pass then makes is one the placement priced (all its members
    # on the device together)
    priced = {frozenset(g[0]) for g in chain.groups if g[1]}
    assert {frozenset(m.name for m in g.members) for g in system.groups} <= priced


def test_a_window_of_windows_is_priced_at_the_reads_its_kernel_makes(tmp_path):
    """The estimate of a stencil counts what its kernel reads with its loops unrolled: a
    5x5 opening, its erosion staged (kernelgen/fused.py: computed once an element,
    then read at the dilation's 25 taps), 25 + 25 reads an element, twice its own 5x5
    erosion's 25; inline it would be 25 x 25 (it ran 27x OpenCV on this machine's PoCL
    while the window-only estimate priced it as an erosion, 9x staged)."""
    path = tmp_path / "m.yaml"
    path.write_text(
        f"system: opening\ntypes: [{SINKS}]\ncomponents:\n"
        "  camera: {type: Camera, params: {width: 640, height: 360}}\n"
        "  gray: {type: RgbToGray}\n"
        "  ero: {type: MorphologyEx, params: {op: 0, ksize: 5}}\n"
        "  opening: {type: MorphologyEx, params: {op: 2, ksize: 5}}\n"
        "  sink: {type: Sink_uint8x1}\n  sink2: {type: Sink_uint8x1}\n"
        "connections:\n  - camera.image -> gray.src\n  - gray.dst -> ero.src\n"
        "  - gray.dst -> opening.src\n  - ero.dst -> sink.image\n"
        "  - opening.dst -> sink2.image\n")
    system = _passes(path, fusion="off")
    ero = fuse_mod.kernel_features(system, ["ero"])
    opening = fuse_mod.kernel_features(system, ["opening"])
    assert ero["loads"] == 640 * 360 * 25  # the stated reads: the window
    assert opening["loads"] == 640 * 360 * (25 + 25)  # the erosion staged, the dilation
    assert 1.5 * fuse_mod.kernel_s(system, ["ero"]) < fuse_mod.kernel_s(system, ["opening"]) \
        < 3 * fuse_mod.kernel_s(system, ["ero"])


def test_a_member_read_only_through_pointwise_members_is_computed_once_a_channel(tmp_path):
    """models/tracking.yaml's red mask: RgbToHsv read by two InRange (3 channels each),
    OR'ed.  Every member is pointwise, so the fused kernel evaluates hsv at one pixel:
    the six reads are three distinct calls, which the compiler computes once each (tune
    measured the group at 279 µs against 414 µs apart on this machine's PoCL, where
    counting six evaluations of hsv's 53 operations refused it).  Behind a stencil each
    path counts its evaluations at every tap, as before (an upper bound: the two masks
    read hsv at the same 9 pixels)."""
    path = tmp_path / "m.yaml"
    path.write_text(
        f"system: red\ntypes: [{SINKS}]\ncomponents:\n"
        "  camera: {type: Camera, params: {width: 640, height: 480}}\n"
        "  hsv: {type: RgbToHsv}\n  low: {type: InRange}\n  high: {type: InRange}\n"
        "  red: {type: BitwiseOr}\n  ero: {type: ErodeGray}\n  sink: {type: Sink_uint8x1}\n"
        "connections:\n  - camera.image -> hsv.src\n  - hsv.dst -> low.src\n"
        "  - hsv.dst -> high.src\n  - low.dst -> red.src1\n  - high.dst -> red.src2\n"
        "  - red.dst -> ero.src\n  - ero.dst -> sink.image\n")
    system = _passes(path, fusion="off")
    mask = {"hsv", "low", "high", "red"}
    assert fuse_mod.evaluations(system, mask) == {"hsv": 3, "low": 1, "high": 1, "red": 1}
    count = fuse_mod.evaluations(system, mask | {"ero"})
    assert count["red"] == 9 and count["low"] == count["high"] == 9  # the erosion's taps
    assert count["hsv"] == 2 * 9 * 3
