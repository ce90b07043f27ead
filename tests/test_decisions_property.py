"""Every decision at once: the frames each sink gets never depend on a decision.

Hypothesis draws systems — DAGs with fan-out and fan-in, one to three sources of seeded
random frames (a new frame every frame, some ending early), odd sizes from 1x1, the
library's flexible types (fusable ones, opaque ones, 'fuse: false'), a GPU-aware type and
a standard type with two outputs each, sinks of every element type, some of them slow —
and runs each under combinations of the decisions:

    frames in flight 1, 2, 3 · fusion auto, off · zero-copy on, off · staging pinned,
    pageable · placement all GPU, all CPU, mixed, by the device (nobody asks: the place
    pass decides for a device class drawn per system, from its estimate, which weighs
    each chain of fusable components whole, as the groups it would make on the device;
    the estimate's table is drawn too, the class's own or one under which chains of these
    small frames go to the device where their components alone would not) · execution
    parallel, sequential · mode gpu-aware, standard

Every sink's frames must equal the reference run's (one frame in flight, no fusion,
sequential, zero-copy off, every flexible component on the GPU), frame by frame, in order.
And every build's decisions must be the ones its plan reports: each flexible component's
side and who decided (with the estimate's figures where an estimate decided, and no
placement estimated slower than all on one side), each chain weighed whole with its
figures (never placed at more than its estimate on the CPU or on the device) and each of
its groups chosen exactly where all its members run on the device, each group with its
estimate fused faster than apart, and a reason for every edge between GPU components left
unfused.

The combinations are the rows of a pairwise covering array (every pair of values of any
two decisions is in some row), so each system runs under ~10 combinations instead of 288.
GPUCOMPGEN_PROPERTY_PROFILE=nightly draws more systems and adds random rows to the array.
At the end the module prints how many systems and runs it checked (pytest -s shows it;
docs/development.md records the figures).
"""

from __future__ import annotations

import itertools
import os
import random
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import ROOT, load_generated, require_opencl
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from gpucompgen import sizeexpr
from gpucompgen.build import compile_model, write
from gpucompgen.errors import Reporter
from gpucompgen.model import DTYPES, library_types, load_types_file
from gpucompgen.runtime import Monitor

DATA = ROOT / "tests" / "data"
TYPES = [(DATA / "decisions" / "types.yaml").as_posix(),
         (DATA / "multi_output" / "types.yaml").as_posix()]
FRAMES = 5  # frames each run asks for (a source may end sooner)

DECISIONS = {
    "frames_in_flight": (1, 2, 3),
    "placement": ("gpu", "cpu", "mixed", "device"),
    "fusion": ("auto", "off"),
    "zero_copy": ("on", "off"),
    "staging": ("pinned", "pageable"),
    "execution": ("parallel", "sequential"),
    "mode": ("gpu-aware", "standard"),
}
REFERENCE = {"frames_in_flight": 1, "placement": "gpu", "fusion": "off", "zero_copy": "off",
             "staging": "pageable", "execution": "sequential", "mode": "gpu-aware"}
NIGHTLY = os.environ.get("GPUCOMPGEN_PROPERTY_PROFILE", "") == "nightly"
# systems drawn: 5 in the suite, 60 nightly (GPUCOMPGEN_PROPERTY_SYSTEMS=N overrides)
SYSTEMS = int(os.environ.get("GPUCOMPGEN_PROPERTY_SYSTEMS") or (60 if NIGHTLY else 5))


def valid(row: dict) -> bool:
    """Standard mode decides fusion (off), execution (sequential), zero-copy and staging
    itself (components copy their own data): a row that says otherwise would claim pairs
    it does not test."""
    return row["mode"] != "standard" or (
        row["fusion"], row["execution"], row["zero_copy"], row["staging"]) == (
        "off", "sequential", "off", "pageable")


def covering(factors: dict[str, tuple], strength: int = 2) -> list[dict]:
    """A covering array: every `strength` decisions take every combination of their values
    that a valid row can take together in some row.  Built greedily: each row is the valid
    full combination that covers the most combinations not yet covered (the first such,
    so it is deterministic)."""
    names = list(factors)
    rows = [r for r in (dict(zip(names, v)) for v in itertools.product(*factors.values()))
            if valid(r)]

    def tuples(row):
        return {tuple((a, row[a]) for a in group)
                for group in itertools.combinations(names, strength)}

    uncovered = set().union(*(tuples(r) for r in rows))
    chosen = []
    while uncovered:
        best = max(rows, key=lambda r: len(tuples(r) & uncovered))
        chosen.append(best)
        uncovered -= tuples(best)
    return chosen


# default: pairwise; nightly: every three decisions together
COMBINATIONS = covering(DECISIONS, 3 if NIGHTLY else 2)


def test_the_covering_array_covers_every_pair_a_valid_row_can_take():
    rows = covering(DECISIONS)
    assert len(rows) <= 13 and all(valid(r) for r in rows)
    for a, b in itertools.combinations(DECISIONS, 2):
        for x in DECISIONS[a]:
            for y in DECISIONS[b]:
                possible = any(valid({**REFERENCE, **c, a: x, b: y})
                               for c in ({}, {"mode": "gpu-aware"}))
                assert any(r[a] == x and r[b] == y for r in rows) == possible, (a, x, b, y)


# --- the systems -----------------------------------------------------------------------------

def _stage_types() -> dict[str, object]:
    """The library's flexible types (fusable and opaque) and the two-output types of
    tests/data/multi_output (LumaSub runs on the GPU, Splitter on the CPU)."""
    global _TYPES
    if _TYPES is None:
        rep = Reporter()
        extra = load_types_file(Path(TYPES[1]), TYPES[1], "user", rep)
        rep.raise_if_errors()
        _TYPES = {n: t for n, t in sorted(library_types().items()) if t.flexible}
        _TYPES.update({n: extra[n] for n in ("LumaSub", "Splitter")})
    return _TYPES


_TYPES: dict | None = None


def _kind(decl) -> tuple[str, int]:
    return decl.dtype, decl.channels


def _params(draw, ctype) -> dict:
    values = {}
    for name, p in ctype.params.items():
        if p.type == "int":
            lo = int(p.minimum) if p.minimum is not None else 0
            hi = int(p.maximum) if p.maximum is not None else lo + 7
            values[name] = draw(st.integers(lo, min(hi, lo + 12)))
        elif p.type == "float":
            lo = p.minimum if p.minimum is not None else -2.0
            hi = p.maximum if p.maximum is not None else 2.0
            values[name] = round(draw(st.integers(0, 20)) / 20 * (hi - lo) + lo, 2)
    return values


@st.composite
def systems(draw):
    """(components, connections, flexible components placed on the CPU when 'mixed', the
    device profile a 'device' placement builds for: one of each class)."""
    types = _stage_types()
    comps: dict[str, dict] = {}
    conns: list[str] = []
    streams: list[tuple[str, tuple[str, int], tuple[int, int]]] = []
    for i in range(draw(st.integers(1, 3))):
        h, w = draw(st.integers(1, 13)), draw(st.integers(1, 13))
        if streams and draw(st.booleans()):  # same size as another: fan-in fits
            h, w = streams[-1][2]
        comps[f"src{i}"] = {"type": "Noise", "params": {
            "seed": i + 1, "width": w, "height": h,
            "frames": draw(st.sampled_from([0, 0, 3]))}}
        streams.append((f"src{i}.image", ("uint8", 3), (h, w)))
    read: set[str] = set()
    for i in range(draw(st.integers(1, 7))):
        kinds = {s[1] for s in streams}
        usable = [n for n, t in types.items()
                  if all(_kind(p) in kinds for p in t.inputs.values())]
        tname = draw(st.sampled_from(usable))
        ctype = types[tname]
        feeds = []
        for port in ctype.inputs.values():  # the newest stream half the time: chains
            fitting = [s for s in streams if s[1] == _kind(port)]
            k = len(fitting) - 1
            feeds.append(fitting[k if draw(st.booleans()) else draw(st.integers(0, k))])
        # (height, width, channels, itemsize): a requirement may compare channels
        # (ExtractChannel) or the element's size (Resize's bilinear)
        sizes = {p: (*f[2], f[1][1], DTYPES[f[1][0]][2]) for p, f in zip(ctype.inputs, feeds)}
        params = _params(draw, ctype)
        ints = {k: v for k, v in params.items() if ctype.params[k].type == "int"}
        if not all(sizeexpr.evaluate(tree, sizes, ints) for tree, _ in ctype.requires):
            continue
        outs = []
        for p, decl in ctype.outputs.items():
            first = next(iter(sizes.values()))
            h = sizeexpr.evaluate(decl.height, sizes, ints) if decl.height else first[0]
            w = sizeexpr.evaluate(decl.width, sizes, ints) if decl.width else first[1]
            outs.append((p, decl, (h, w)))
        if not all(1 <= h <= 64 and 1 <= w <= 64 for _, _, (h, w) in outs):
            continue
        name = f"c{i}"
        comps[name] = {"type": tname, "params": params}
        if ctype.fusable is not None and draw(st.integers(0, 4)) == 0:
            comps[name]["fuse"] = False
        for port, feed in zip(ctype.inputs, feeds):
            conns.append(f"{feed[0]} -> {name}.{port}")
            read.add(feed[0])
        streams += [(f"{name}.{p}", _kind(decl), size) for p, decl, size in outs]
    for j, (end, (dtype, channels), _) in enumerate(streams):
        if end not in read or (not end.startswith("src") and draw(st.integers(0, 3)) == 0):
            delay = draw(st.sampled_from([0.0, 0.0, 0.0, 0.002]))
            comps[f"sink{j}"] = {"type": f"Sink_{dtype}x{channels}",
                                 "params": {"delay": delay} if delay else {}}
            conns.append(f"{end} -> sink{j}.image")
    flexible = [n for n, c in comps.items() if types.get(c["type"]) is not None
                and types[c["type"]].flexible]
    on_cpu = {n for n in flexible if draw(st.booleans())}
    return comps, conns, sorted(on_cpu), draw(st.sampled_from(DEVICES))


# --- the decisions, as the plan reports them -------------------------------------------------

# a 'device' placement builds for one device of each class (the runs are on PoCL whatever
# the class: the program is correct on any device)
DEVICES = ("pocl-cpu", "embedded-igpu", "nvidia-hopper")
# the placement estimate's table a 'device' placement uses: the class's own, or one under
# which a component of these small frames is cheaper on the CPU than its launch but a
# chain of them, one kernel, is not (so the chains' choice is drawn both ways)
COSTS = (None, {"cpu_bytes_per_s": 2e7, "gpu_bytes_per_s": 1e10, "gpu_launch_s": 25e-6})


def decisions_as_planned(system) -> None:
    """The placement and fusion the build chose are the ones its plan reports, with the
    figures that decided them, and none is estimated slower than its alternative."""
    from gpucompgen.ir import ComponentNode, GroupNode
    from gpucompgen.passes.place import a_device

    placement, plan = system.placement, system.plan
    lines = {line.split(":")[0]: line for line in plan.placement}
    kind = system.device.kind
    for name, (side, by) in placement.decided.items():
        node = system.component(name)
        assert node.placement == side, name
        line = lines[name]
        assert line.startswith(f"{name}: {side.upper()} (by {by}"), line
        if node.asked == "default":  # nobody asked: the device's class decides
            assert by == (f"default for {a_device(kind)}" if kind else "default"), line
            assert kind or side == "gpu", line
        if by == "auto" or by.startswith("default for "):  # an estimate decided
            cost = placement.costs[name]
            assert f"est. CPU {cost.cpu_s * 1e3:.3f} ms, GPU {cost.gpu_s * 1e3:.3f} ms" in line
    if placement.estimate_s is not None:  # the chosen placement is the least estimated
        margin = max((c.margin for c in placement.chains), default=0.0)  # device wins by it
        assert placement.estimate_s <= min(placement.all_gpu_s * (1 + margin),
                                           placement.all_cpu_s) + 1e-12
        assert any(line.startswith("auto (") for line in plan.placement)
    for chain in placement.chains:  # weighed whole: the least of its options, as planned
        RAN["chains"] += 1
        RAN["chains on the device"] += chain.side != "cpu"
        assert chain.chosen_s <= min(chain.cpu_s, chain.gpu_s * (1 + chain.margin)) + 1e-12, \
            chain
        sides = {system.component(m).placement for m in chain.members}
        assert sides == ({"gpu", "cpu"} if chain.side == "mixed" else {chain.side}), chain
        assert any(line.startswith(f"chain {', '.join(chain.members)}: {chain.where}; "
                                   f"frame est. {chain.chosen_s * 1e3:.3f} ms")
                   for line in plan.placement), chain
        for members, chosen, *_ in chain.groups:
            assert chosen == all(system.component(m).placement == "gpu" for m in members)
            assert any(line.strip().startswith(f"group {'+'.join(members)} "
                                               f"{'chosen' if chosen else 'refused'}: ")
                       for line in plan.placement), members
        for m in chain.members:
            assert f"its chain weighed whole: {chain.where}" in lines[m]
    groups = [g for g in system.groups]
    assert [[m for m, _, _ in g.members] for g in plan.groups] == \
        [[m.name for m in g.members] for g in groups]
    for g, shown in zip(groups, plan.groups):
        fused, apart = g.estimate_s
        assert fused < apart, g.name  # never a group estimated slower than its members
        assert shown.estimate == g.estimate and f"{fused * 1e3:.3f} ms" in g.estimate
    where = {m.name: g.name for g in system.kernel_groups for m in g.members}
    unfused = dict(plan.unfused)
    for e in system.model.connections:
        a, b = (system.nodes.get(where.get(x.component, x.component))
                for x in (e.source, e.target))
        both_gpu = all(isinstance(n, (ComponentNode, GroupNode)) and n.on_gpu
                       for n in (a, b))
        if both_gpu and a is not b:  # a GPU-to-GPU connection between two kernels
            assert f"{e.source} -> {e.target}" in unfused, f"{e.source} -> {e.target}"


# --- running them --------------------------------------------------------------------------------

RAN = {"systems": 0, "runs": 0, "chains": 0, "chains on the device": 0}
_loaded = itertools.count()


def _places(comps: dict, on_cpu: list[str], placement: str) -> dict[str, str]:
    types = _stage_types()
    flexible = [n for n, c in comps.items()
                if c["type"] in types and types[c["type"]].flexible]
    if placement == "mixed":
        return {n: "cpu" if n in on_cpu else "gpu" for n in flexible}
    if placement == "device":  # nobody asks: decided for the device's class
        return {}
    return dict.fromkeys(flexible, placement)


def _sink_frames(model: Path, comps: dict, on_cpu: list[str], row: dict, out: Path,
                 device: str | None = None, costs: dict | None = None):
    from gpucompgen.passes import place

    options = {k: row[k] for k in ("frames_in_flight", "fusion", "zero_copy", "staging",
                                   "execution", "mode")}
    with pytest.MonkeyPatch.context() as patch:
        for kind in ("cpu", "integrated-gpu", "discrete-gpu") if costs else ():
            patch.setitem(place.PLACEMENT_COSTS, kind, {**place.PLACEMENT_COSTS[kind], **costs})
        result = compile_model(model, out, places=_places(comps, on_cpu, row["placement"]),
                               device=device if row["placement"] == "device" else None,
                               **options)
    decisions_as_planned(result.system)
    write(result, out)
    module = load_generated(out / f"{result.system.model.name}.py",
                            f"decisions_{next(_loaded)}")
    ran = module.run(frames=FRAMES, monitor=Monitor(progress=False, options={"quiet": True}))
    RAN["runs"] += 1
    return ran.frames, {n: c.frames for n, c in ran.components.items() if n.startswith("sink")}


def _rows(seed: str) -> list[dict]:
    if not NIGHTLY:
        return COMBINATIONS
    rng = random.Random(seed)  # a few more, drawn per system
    extra = [{k: rng.choice(v) for k, v in DECISIONS.items()} for _ in range(6)]
    return COMBINATIONS + [r for r in extra if valid(r)]


# two more rows per system, drawn: across systems they reach combinations of more than two
# decisions that the covering array leaves out.  One is any valid row; the other takes the
# decisions that work on frames together at once — two or three frames in flight, fusion,
# GPU-aware mode — with the rest drawn (the race of issue 22 needed five decisions at once:
# frames in flight, fusion, zero-copy off, GPU placement, GPU-aware mode)
_any_row = st.fixed_dictionaries({k: st.sampled_from(v)
                                  for k, v in DECISIONS.items()}).filter(valid)
_together = st.fixed_dictionaries({**{k: st.sampled_from(v) for k, v in DECISIONS.items()},
                                   "frames_in_flight": st.sampled_from((2, 3)),
                                   "fusion": st.just("auto"), "mode": st.just("gpu-aware")})
extra_rows = st.tuples(_any_row, _together).map(list)

# the race of issue 22: two fused branches, each downloaded to its own sink
RACE = ({"src0": {"type": "Noise", "params": {"seed": 3, "width": 11, "height": 7}},
         "c0": {"type": "InRange", "params": {"lowerb_0": 100}},
         "c1": {"type": "ErodeGray"},
         "c2": {"type": "InRange", "params": {"lowerb_1": 80}},
         "c3": {"type": "ErodeGray"},
         "sink0": {"type": "Sink_uint8x1"}, "sink1": {"type": "Sink_uint8x1"}},
        ["src0.image -> c0.image", "src0.image -> c2.image", "c0.mask -> c1.image",
         "c2.mask -> c3.image", "c1.eroded -> sink0.image", "c3.eroded -> sink1.image"], [],
        "pocl-cpu")
# the combinations the issue ran it under
RACE_ROWS = [{**REFERENCE, "frames_in_flight": 2, "fusion": "auto", "execution": "parallel"},
             {**REFERENCE, "frames_in_flight": 3, "fusion": "auto"}]
# a chain that placement weighs whole (issue 24): under COSTS[1] each component alone is
# cheaper on the CPU, some of its groups on the device are not; with a fan-out read by a
# sink (its output must be materialized) and a stencil behind a pointwise step
CHAIN = ({"src0": {"type": "Noise", "params": {"seed": 5, "width": 13, "height": 11}},
          "c0": {"type": "RgbToGray"},
          "c1": {"type": "ThresholdGray", "params": {"thresh": 90, "thresh_type": 2}},
          "c2": {"type": "ConvertScaleGray", "params": {"alpha": 1.5, "beta": -3.0}},
          "c3": {"type": "ErodeGray"},
          "c4": {"type": "InRange", "params": {"lowerb_0": 60}},
          "c5": {"type": "AbsDiffGray"},
          "sink0": {"type": "Sink_uint8x1"}, "sink1": {"type": "Sink_uint8x1"}},
         ["src0.image -> c0.image", "c0.gray -> c1.image", "c1.thresholded -> c2.image",
          "c2.scaled -> c3.image", "src0.image -> c4.image", "c4.mask -> c5.src1",
          "c3.eroded -> c5.src2", "c2.scaled -> sink0.image", "c5.diff -> sink1.image"],
         [], "pocl-cpu")
CHAIN_ROWS = [{**REFERENCE, "placement": "device", "fusion": "auto", "zero_copy": "on"},
              {**REFERENCE, "placement": "device", "fusion": "auto", "frames_in_flight": 3,
               "execution": "parallel", "staging": "pinned"}]


@settings(max_examples=SYSTEMS, deadline=None, derandomize=not NIGHTLY,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                 HealthCheck.function_scoped_fixture])
@given(system=systems(), extra=extra_rows, costs=st.sampled_from(COSTS))
@example(system=RACE, extra=RACE_ROWS, costs=COSTS[1])
@example(system=CHAIN, extra=CHAIN_ROWS, costs=COSTS[1])
def test_every_decision_gives_the_reference_frames(tmp_path_factory, system, extra, costs):
    require_opencl()
    comps, conns, on_cpu, device = system
    folder = tmp_path_factory.mktemp("decisions")
    model = folder / "m.yaml"
    model.write_text(yaml.safe_dump({"system": "decisions", "types": TYPES,
                                     "components": comps, "connections": conns},
                                    sort_keys=False), encoding="utf-8")
    RAN["systems"] += 1
    frames, want = _sink_frames(model, comps, on_cpu, REFERENCE, folder / "reference")
    assert want and all(len(f) == frames for f in want.values())
    for k, row in enumerate(_rows(model.read_text()) + extra):
        got_frames, got = _sink_frames(model, comps, on_cpu, row, folder / f"run{k}", device,
                                       costs)
        where = (f"{row} costs={costs}\n"
                 f"{yaml.safe_dump({'components': comps, 'connections': conns})}")
        assert got_frames == frames, where
        assert got.keys() == want.keys(), where
        for sink in want:
            assert len(got[sink]) == len(want[sink]), (sink, where)
            for f, (a, b) in enumerate(zip(got[sink], want[sink])):
                assert a.dtype == b.dtype and a.shape == b.shape, (sink, f, where)
                assert np.array_equal(a, b), f"{sink} frame {f} differs under {where}"


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    if RAN["systems"]:
        print(f"\ndecisions property test: {RAN['systems']} systems, each under "
              f"{len(COMBINATIONS)} combinations covering every "
              f"{'three' if NIGHTLY else 'two'} decisions + 2 drawn"
              f"{' + up to 6 random' if NIGHTLY else ''}, and the reference: "
              f"{RAN['runs']} runs; {RAN['chains']} chains weighed whole, "
              f"{RAN['chains on the device']} of them (wholly or in part) on the device")
