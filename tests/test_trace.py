"""--trace FILE: the Chrome trace-event JSON, checked by a small validator — of its
structure (what Perfetto and chrome://tracing need) and of what it claims about the run."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from collections import defaultdict

import pytest
from conftest import ROOT, require_opencl

PHASES = {"X", "M", "C", "s", "t", "f"}
EPS = 0.01  # µs: rounding of float timestamps


def validate(doc: dict) -> dict:
    """Check a trace's structure; return its slices by kind for the run's own checks."""
    assert isinstance(doc, dict) and isinstance(doc["traceEvents"], list)
    events = doc["traceEvents"]
    slices: dict[tuple[int, int], list[dict]] = defaultdict(list)
    names: dict[tuple[int, int], str] = {}
    processes = {}
    flows: dict[int, list[dict]] = defaultdict(list)
    for e in events:
        assert e["ph"] in PHASES, e
        assert isinstance(e["pid"], int) and isinstance(e["tid"], int), e
        assert isinstance(e["name"], str) and e["name"], e
        if e["ph"] == "M":
            assert e["name"] in ("process_name", "thread_name", "thread_sort_index"), e
            if e["name"] == "thread_name":
                names[(e["pid"], e["tid"])] = e["args"]["name"]
            if e["name"] == "process_name":
                processes[e["pid"]] = e["args"]["name"]
            continue
        assert isinstance(e["ts"], (int, float)) and e["ts"] >= 0, e
        if e["ph"] == "X":
            assert isinstance(e["dur"], (int, float)) and e["dur"] >= 0, e
            assert isinstance(e["args"]["frame"], int), e
            slices[(e["pid"], e["tid"])].append(e)
        elif e["ph"] == "C":
            assert e["args"] and all(isinstance(v, (int, float)) for v in e["args"].values())
        else:
            flows[e["id"]].append(e)
    for key in slices:
        assert key in names, f"track {key} has no thread_name"
        assert key[0] in processes, f"process {key[0]} has no process_name"
    for fid, chain in flows.items():  # s, then t..., then f; each bound to a slice
        chain.sort(key=lambda e: e["ts"])
        assert [e["ph"] for e in chain] == ["s"] + ["t"] * (len(chain) - 2) + ["f"], fid
        for e in chain:
            assert any(s["ts"] - EPS <= e["ts"] <= s["ts"] + s["dur"] + EPS
                       for s in slices[(e["pid"], e["tid"])]), f"flow {fid} binds no slice"
    return {"slices": slices, "names": names, "processes": processes, "flows": flows,
            "counters": [e for e in events if e["ph"] == "C"]}


@pytest.fixture(scope="module")
def vision_trace(tmp_path_factory):
    require_opencl()
    tmp = tmp_path_factory.mktemp("trace")
    cmd = [sys.executable, "-m", "gpucompgen", "run", str(ROOT / "models" / "vision_system.yaml"),
           "--frames", "8", "--frames-in-flight", "3", "--zero-copy", "off", "-q",
           # the merger and detector as one kernel, whatever the device's class would place
           "--place", "*=gpu", "--trace", str(tmp / "trace.json")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=False,
                          env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr
    return json.loads((tmp / "trace.json").read_text())


def test_vision_trace_with_three_frames_in_flight(vision_trace):
    t = validate(vision_trace)
    host = {t["names"][k]: v for k, v in t["slices"].items() if k[0] == 1}
    device = [s for k, v in t["slices"].items() if k[0] == 2 for s in v]
    parts = {"camera1", "camera2", "adapter1_cpu2gpu", "adapter2_cpu2gpu", "merger_detector",
             "adapter3_gpu2cpu", "manager"}
    assert set(host) == parts
    span = {}
    for part, slices in host.items():
        # every frame's slice on every track, in frame order, one after the other
        slices.sort(key=lambda s: s["ts"])
        assert [s["args"]["frame"] for s in slices] == list(range(8)), part
        for a, b in itertools.pairwise(slices):
            assert a["ts"] + a["dur"] <= b["ts"] + EPS, part
        for s in slices:
            lo, hi = span.get(s["args"]["frame"], (float("inf"), 0.0))
            span[s["args"]["frame"]] = (min(lo, s["ts"]), max(hi, s["ts"] + s["dur"]))
    # device slices: the kernel and the three copies of every frame, inside its host span
    kinds = defaultdict(set)
    for s in device:
        kinds[s["args"]["frame"]].add(s["name"].split(" #")[0])
        lo, hi = span[s["args"]["frame"]]
        assert lo - EPS <= s["ts"] and s["ts"] + s["dur"] <= hi + EPS, s
    for frame in range(8):
        assert kinds[frame] == {"merger_detector kernel", "adapter1_cpu2gpu cpu2gpu",
                                "adapter2_cpu2gpu cpu2gpu", "adapter3_gpu2cpu gpu2cpu"}, frame
    # frames overlap, at most three at a time; warm-up = the first three
    level = max(c["args"]["frames"] for c in t["counters"] if c["name"] == "frames in flight")
    assert 1 <= level <= 3
    for slices in t["slices"].values():
        for s in slices:
            assert s["args"]["warmup"] == (s["args"]["frame"] < 3)
            assert s["name"].endswith("(warm-up)") == (s["args"]["frame"] < 3)
    copied = [c["args"] for c in t["counters"] if c["name"] == "bytes copied"]
    assert copied[-1] == {"cpu2gpu": 8 * 2 * 921_600, "gpu2cpu": 8 * 614_400}
    # each frame is one flow through its slices
    assert sorted(t["flows"]) == list(range(8))
    assert vision_trace["otherData"]["warmup_frames"] == 3


def test_validator_catches_a_broken_trace(vision_trace):
    broken = json.loads(json.dumps(vision_trace))
    x = next(e for e in broken["traceEvents"] if e["ph"] == "X")
    x["dur"] = -1
    with pytest.raises(AssertionError):
        validate(broken)
    broken = json.loads(json.dumps(vision_trace))
    broken["traceEvents"] = [e for e in broken["traceEvents"] if e["ph"] != "f"]
    with pytest.raises(AssertionError):
        validate(broken)


def test_trace_path_problems_are_found_before_the_run(tmp_path):
    require_opencl()
    program = ROOT / "generated" / "mirror_chain.py"
    proc = subprocess.run([sys.executable, str(program), "--trace", str(tmp_path / "no" / "t.json"),
                           "--frames", "1"], capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == 2 and f"--trace {tmp_path}/no/t.json: folder" in proc.stderr
