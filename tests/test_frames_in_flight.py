"""Frames in flight: N = 1, 2, 3 give the same outputs and decisions, frame for frame.

With N >= 2 the generated program runs its stages (sources, device work, sinks) in threads
of their own, over N sets of the buffers that cross stages.  A buffer set reused too early
would hand a sink another frame's data: every mask the VisionManager sees is compared with
an independent numpy reference, and the decisions with the one-frame-at-a-time program's,
over many frames, with zero-copy adapters on and off and with pinned and pageable staging.
Failure at frame k and SIGINT/SIGTERM are tested with N = 3.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.build import compile_model, write
from gpucompgen.library.camera import Camera
from gpucompgen.runtime import Monitor
from gpucompgen.runtime.monitor import latency_summary, percentile

VISION = ROOT / "models" / "vision_system.yaml"
BRANCHES = ROOT / "models" / "parallel_branches.yaml"
DATA = ROOT / "tests" / "data"
FRAMES = 30


def _build(tmp: Path, model: Path, n: int, zero_copy: str = "off", staging: str = "auto",
           execution: str | None = None, places: dict[str, str] | None = None,
           fusion: str | None = None):
    where = "-".join(f"{k}_{v}" for k, v in sorted((places or {}).items()))
    out = tmp / f"out-{model.stem}-{n}-{zero_copy}-{staging}-{execution}-{where}-{fusion}"
    result = compile_model(model, out, zero_copy=zero_copy, frames_in_flight=n,
                           staging=staging, execution=execution, places=places,
                           fusion=fusion)
    write(result, out)
    return result, out / f"{result.system.model.name}.py"


def _masks_and_decisions(program: Path, tag: str, frames: int, tmp: Path):
    """Run in this process; every mask the VisionManager got (copied) and its decisions."""
    module = load_generated(program, f"flight_{tag}")
    masks: list[np.ndarray] = []
    original = module.VisionManager.execute

    def spy(self, mask):
        masks.append(np.array(mask, copy=True))
        return original(self, mask)

    decisions = tmp / f"{tag}.jsonl"
    module.VisionManager.execute = spy
    try:
        monitor = Monitor(progress=False, options={"decisions": str(decisions), "quiet": True})
        assert module.run(frames=frames, monitor=monitor).frames == frames
    finally:
        module.VisionManager.execute = original
    return masks, decisions.read_text().splitlines()


def detect(frame: np.ndarray, red_min=150, margin=80) -> np.ndarray:
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return np.where((r >= red_min) & (r - g >= margin) & (r - b >= margin), 255, 0
                    ).astype(np.uint8)


@pytest.fixture(scope="module")
def vision_runs(tmp_path_factory):
    require_opencl()
    tmp = tmp_path_factory.mktemp("flight")
    runs = {}
    for n in (1, 2, 3):
        for zero_copy, staging, place in PLATFORMS:
            places = dict(p.split("=") for p in place.split(",")) if place else None
            result, program = _build(tmp, VISION, n, zero_copy, staging, places=places)
            for name in places or ():  # a CPU-placed component runs in a CPU stage
                assert n == 1 or "device" not in [
                    st.runs for st in result.system.plan.stages if name in st.parts], name
            tag = f"{n}_{zero_copy}_{staging}_{place.replace('=', '_').replace(',', '_')}"
            runs[n, zero_copy, staging, place] = _masks_and_decisions(program, tag, FRAMES, tmp)
    return runs


# (zero-copy, staging, --place): copying and zero-copy adapters; flexible components on the
# CPU, where they join the CPU stages (the detector alone: its mask is uploaded by nobody,
# the manager reads it; both: the merged frame is made on the CPU, uploaded, detected)
PLATFORMS = (("off", "pinned", ""), ("off", "pageable", ""), ("on", "auto", ""),
             ("off", "auto", "detector=cpu"), ("on", "auto", "merger=cpu"))


def test_masks_match_numpy_for_every_n_zero_copy_and_staging(vision_runs):
    cam1, cam2 = Camera(seed=1), Camera(seed=2)
    cam1.initialize()
    cam2.initialize()
    expected = [detect(np.hstack([cam1.execute(), cam2.execute()])) for _ in range(FRAMES)]
    assert sum(bool(m.any()) for m in expected) > FRAMES // 2, "the scene has buoys"
    assert len({m.tobytes() for m in expected}) > FRAMES // 2, "frames differ"
    for key, (masks, _) in vision_runs.items():
        assert len(masks) == FRAMES, key
        for f, (got, want) in enumerate(zip(masks, expected)):
            np.testing.assert_array_equal(got, want, err_msg=f"{key} frame {f}")


def test_decisions_are_identical_for_every_n(vision_runs):
    reference = vision_runs[1, "off", "pageable", ""][1]
    assert len(reference) == FRAMES
    assert [json.loads(line)["frame"] for line in reference] == list(range(FRAMES))
    for key, (_, decisions) in vision_runs.items():
        assert decisions == reference, key


def test_branches_with_sequential_execution_and_three_frames_in_flight(tmp_path):
    """The two-branch model (two device lanes) and sequential execution: same masks."""
    require_opencl()
    runs = {}
    for n, execution, zero_copy in ((1, "parallel", "off"), (3, "parallel", "off"),
                                    (3, "sequential", "off"), (2, "parallel", "on")):
        _, program = _build(tmp_path, BRANCHES, n, zero_copy, execution=execution)
        runs[n, execution, zero_copy] = _masks_and_decisions(
            program, f"branches_{n}_{execution}_{zero_copy}", 12, tmp_path)
    reference = runs[1, "parallel", "off"]
    for key, (masks, decisions) in runs.items():
        assert decisions == reference[1], key
        for f, (a, b) in enumerate(zip(masks, reference[0])):
            np.testing.assert_array_equal(a, b, err_msg=f"{key} frame {f}")


def test_plan_shows_stages_n_buffer_sets_and_their_cost(tmp_path):
    result, program = _build(tmp_path, VISION, 3, "off", "pinned", fusion="off")
    plan = result.system.plan
    assert [st.parts for st in plan.stages] == [
        ("camera1", "camera2", "adapter1_cpu2gpu", "adapter2_cpu2gpu"),
        ("merger", "detector", "adapter3_gpu2cpu"), ("manager",)]
    assert [part for part, _ in plan.buffer_sets] == [
        "adapter1_cpu2gpu", "adapter2_cpu2gpu", "adapter3_gpu2cpu"]
    sets = {b.what: b.sets for b in plan.buffers}
    # merger.merged and detector.mask are written and read by the device stage alone
    assert sets["merger.merged"] == sets["detector.mask"] == 1
    assert sets["adapter3_gpu2cpu (detector.mask)"] == 3
    # 2 more sets of two 921,600-byte uploads on the device; on the host 2 more sets of
    # the two pinned staging arrays and of the 614,400-byte mask
    assert plan.extra_set_bytes("device") == 2 * 2 * 921_600
    assert plan.extra_set_bytes("host") == 2 * (2 * 921_600 + 614_400)
    text = program.read_text()
    assert "memory 3 frames in flight cost beyond one frame: 3,686,400 device bytes, " \
           "4,915,200 host bytes" in text
    assert "frame = runtime.stream_in_flight(" in text and "frames_in_flight=3" in text


def test_zero_copy_maps_need_sets_of_the_mapped_buffer(tmp_path):
    result, _ = _build(tmp_path, VISION, 2, "on", fusion="off")
    plan = result.system.plan
    assert dict(plan.buffer_sets).keys() == {"adapter1_cpu2gpu", "adapter2_cpu2gpu",
                                             "adapter3_gpu2cpu", "detector"}
    assert {b.what: b.sets for b in plan.buffers}["detector.mask"] == 2


def test_a_fused_group_that_writes_a_mapped_buffer_keeps_sets_of_it(tmp_path):
    """Fused, the mask is written by the merger_detector group: the group keeps N sets."""
    result, _ = _build(tmp_path, VISION, 2, "on")
    plan = result.system.plan
    assert [st.parts for st in plan.stages][1] == ("merger_detector", "adapter3_gpu2cpu")
    assert dict(plan.buffer_sets).keys() == {"adapter1_cpu2gpu", "adapter2_cpu2gpu",
                                             "adapter3_gpu2cpu", "merger_detector"}
    sets = {b.what: b.sets for b in plan.buffers}
    assert "merger.merged" not in sets and sets["merger_detector.mask"] == 2


def test_one_frame_in_flight_generates_the_same_program(tmp_path):
    default = compile_model(VISION, tmp_path / "a").files[0].text
    assert compile_model(VISION, tmp_path / "b", frames_in_flight=1).files[0].text == default
    assert "stream_in_flight" not in default and "while frames is None" in default


def test_a_standard_output_read_in_a_later_stage_merges_the_stages(tmp_path):
    """camera -> gpu -> manager, and camera -> a CPU sink as well: the camera's array is
    read in a later stage, so the stages up to that sink become one."""
    model = tmp_path / "m.yaml"
    model.write_text(textwrap.dedent("""\
        system: skip
        components:
          camera: {type: Camera, params: {width: 64, height: 48}}
          mirror: {type: VerticalMirror}
          sink: {type: FrameSink}
          late: {type: FrameSink}
        connections:
          - camera.image -> mirror.image
          - mirror.mirrored -> sink.image
          - camera.image -> late.image
        """), encoding="utf-8")
    result = compile_model(model, tmp_path / "out", frames_in_flight=2)
    system = result.system
    where = {n: i for i, names in enumerate(system.flight_stages) for n in names}
    assert where["late"] == where["camera"]
    assert any("camera.image is read by late" in n for n in result.system.plan.flight_notes)


# --- failures and signals with N = 3 --------------------------------------------------------

def _lifecycle(tmp_path: Path, fail_at: int = -1, frames: int = 8) -> tuple[Path, Path]:
    log = tmp_path / "free.log"
    model = tmp_path / "lifecycle.yaml"
    model.write_text(textwrap.dedent(f"""\
        system: lifecycle
        types: [{(DATA / "lifecycle" / "types.yaml").as_posix()}]
        platform: {{frames_in_flight: 3}}
        components:
          camera: {{type: Camera, params: {{width: 48, height: 32, frames: {frames}}}}}
          flaky: {{type: Flaky, params: {{fail_at: {fail_at}, log: "{log.as_posix()}"}}}}
          detector: {{type: ObjectDetector}}
          recorder: {{type: Recorder, params: {{log: "{log.as_posix()}"}}}}
        connections:
          - camera.image -> flaky.image
          - flaky.image_out -> detector.frame
          - detector.mask -> recorder.mask
        """), encoding="utf-8")
    out = tmp_path / "out"
    write(compile_model(model, out), out)
    return out / "lifecycle.py", log


def _run(program: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(program), *args], capture_output=True,
                          text=True, timeout=300, check=False, env=dict(os.environ))


def test_end_of_stream_with_three_in_flight_processes_every_frame(tmp_path):
    require_opencl()
    program, log = _lifecycle(tmp_path, frames=7)
    assert "stream_in_flight" in program.read_text()
    proc = _run(program)
    assert proc.returncode == 0, proc.stderr
    assert "processed 7 frame(s)" in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]


@pytest.mark.parametrize("fail_at", [0, 3])
def test_failure_at_frame_k_with_three_in_flight(tmp_path, fail_at):
    require_opencl()
    program, log = _lifecycle(tmp_path, fail_at=fail_at, frames=50)
    proc = _run(program)
    assert proc.returncode == 1
    assert (f"error: flaky failed at frame {fail_at}: RuntimeError: injected failure at "
            f"frame {fail_at}") in proc.stderr
    assert "Traceback" not in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]
    debug = _run(program, "--debug")
    assert debug.returncode == 1 and "Traceback" in debug.stderr


def test_failure_in_the_last_stage_names_its_frame(tmp_path, monkeypatch):
    """A sink failing at frame 4 while earlier stages are ahead of it: frame 4 is named."""
    require_opencl()
    _, program = _build(tmp_path, VISION, 3)
    module = load_generated(program, "flight_sink_failure")
    calls = []
    original = module.VisionManager.execute

    def failing(self, mask):
        calls.append(1)
        if len(calls) == 5:
            raise ValueError("sink broke")
        return original(self, mask)

    monkeypatch.setattr(module.VisionManager, "execute", failing)
    from gpucompgen.runtime import PipelineError

    with pytest.raises(PipelineError, match=r"^manager failed at frame 4: ValueError: sink "
                                            r"broke$"):
        module.run(frames=40, monitor=Monitor(progress=False, options={"quiet": True}))


@pytest.mark.parametrize("signum,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_stops_three_frames_in_flight_cleanly(tmp_path, signum, code):
    require_opencl()
    _, program = _build(tmp_path, VISION, 3)
    # the synthetic cameras never end: only the signal stops this run
    proc = subprocess.Popen([sys.executable, str(program)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        assert all(line.startswith("frame ") for line in lines), lines
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, err
    name = signal.Signals(signum).name
    assert f"stopped by {name} after " in err and "every component was freed" in err
    assert "Traceback" not in err


# --- latency in --stats-json ------------------------------------------------------------------

def test_percentiles_on_hand_computed_values():
    assert percentile([3.0, 1.0, 2.0], 50) == 2.0
    assert percentile([1.0, 2.0, 3.0, 4.0], 50) == 2.5
    assert percentile(list(map(float, range(101))), 95) == 95.0
    assert percentile([], 95) == 0.0
    summary = latency_summary([0.01, 0.02, 0.03, 0.04])
    assert summary["median"] == pytest.approx(0.025) and summary["max"] == 0.04
    assert summary["p95"] == pytest.approx(0.0385)


@pytest.mark.parametrize("n", [1, 3])
def test_stats_json_reports_latency_beside_frames_per_second(tmp_path, n):
    require_opencl()
    _, program = _build(tmp_path, VISION, n)
    stats = tmp_path / "stats.json"
    proc = _run(program, "--frames", "12", "-q", "--stats-json", str(stats))
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(stats.read_text())
    assert doc["frames"] == 12 and doc["frames_in_flight"] == n
    assert len(doc["frame_seconds"]) == 12
    lat = doc["latency_seconds"]
    assert 0 < lat["median"] <= lat["p95"] <= lat["max"]
    assert lat["median"] == pytest.approx(float(np.median(doc["frame_seconds"])))
    # a frame's latency is at most the whole run's time
    assert lat["max"] <= doc["wall_seconds"]
    assert doc["components"]["manager"]["calls"] == 12


# --- the demo's camera: water rendered once, the same frames ---------------------------------

def _render_by_adding_and_clipping(cam: Camera, frame: int) -> np.ndarray:
    """The camera's former render: add the noise field to the background, draw each buoy
    as colour plus the next noise field, clip once."""
    img = cam.background + cam.noise[frame % len(cam.noise)]
    for b in cam.ground_truth(frame):
        y0, y1 = b.y - b.radius, b.y + b.radius + 1
        x0, x1 = b.x - b.radius, b.x + b.radius + 1
        yy, xx = np.ogrid[y0:y1, x0:x1]
        disk = (yy - b.y) ** 2 + (xx - b.x) ** 2 <= b.radius ** 2
        patch = img[y0:y1, x0:x1]
        patch[disk] = (210, 30, 35) + cam.noise[(frame + 1) % len(cam.noise)][y0:y1, x0:x1][disk]
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed,width,height,buoys", [(1, 640, 480, 2), (2, 640, 480, 2),
                                                     (5, 97, 61, 3), (3, 1152, 864, 5)])
def test_camera_frames_are_those_of_adding_and_clipping_every_frame(seed, width, height,
                                                                    buoys):
    cam = Camera(seed=seed, width=width, height=height, buoys=buoys)
    cam.initialize()
    for frame in range(0, 240, 7):
        np.testing.assert_array_equal(cam.render(frame),
                                      _render_by_adding_and_clipping(cam, frame))


# --- buffer sets for every kind of node ---------------------------------------------------

TWO_FUSED_BRANCHES = """\
system: two_fused_branches
types: [keep.yaml]
platform: {device: portable}
components:
  camera: {type: Camera, params: {seed: 3, width: 21, height: 17}}
  in1: {type: InRange, params: {lowerb_0: 100}}
  erode1: {type: ErodeGray}
  in2: {type: InRange, params: {lowerb_1: 80}}
  erode2: {type: ErodeGray}
  keep1: {type: Keep1}
  keep2: {type: Keep1}
connections:
  - camera.image -> in1.image
  - camera.image -> in2.image
  - in1.mask -> erode1.image
  - in2.mask -> erode2.image
  - erode1.eroded -> keep1.image
  - erode2.eroded -> keep2.image
"""


def _kept(program: Path, tag: str, frames: int) -> dict[str, list[np.ndarray]]:
    """Every frame each Keep sink got, in order (run in this process)."""
    result = load_generated(program, f"flight_{tag}").run(
        frames=frames, monitor=Monitor(progress=False, options={"quiet": True}))
    return {name: comp.frames for name, comp in result.components.items()
            if hasattr(comp, "frames") and isinstance(comp.frames, list)}


@pytest.mark.parametrize("n,execution", [(2, "parallel"), (3, "parallel"), (3, "sequential")])
def test_two_fused_branches_each_downloaded_get_their_own_frames(tmp_path, n, execution):
    """Issue 22: each branch fused into a group (InRange -> ErodeGray), each downloaded to
    its own sink by a copying adapter (no zero-copy: a device without unified memory).  The
    second group's output is written in the device stage and downloaded in a later one; with
    one set of it the second sink got frame f+1's mask as frame f."""
    from conftest import write_keep_types

    require_opencl()
    write_keep_types(tmp_path)
    model = tmp_path / "branches.yaml"
    model.write_text(TWO_FUSED_BRANCHES, encoding="utf-8")
    _, reference = _build(tmp_path, model, 1, "off", execution="sequential", fusion="off")
    result, program = _build(tmp_path, model, n, "off", execution=execution)
    assert len(result.system.plan.groups) == 2
    want = _kept(reference, f"fused_branches_ref_{n}_{execution}", 12)
    got = _kept(program, f"fused_branches_{n}_{execution}", 12)
    assert want.keys() == got.keys() == {"keep1", "keep2"}
    for sink in want:
        assert len(got[sink]) == len(want[sink]) == 12
        for f, (a, b) in enumerate(zip(got[sink], want[sink])):
            np.testing.assert_array_equal(a, b, err_msg=f"{sink} frame {f}")


@pytest.mark.parametrize("zero_copy", ["off", "on"])
def test_plan_says_why_every_buffer_has_its_sets_fused_or_not(tmp_path, zero_copy):
    """The fused group's output read by a download in a later stage keeps N sets, as the
    unfused component's does; every buffer says why it has its number of sets."""
    from conftest import write_keep_types

    write_keep_types(tmp_path)
    model = tmp_path / "branches.yaml"
    model.write_text(TWO_FUSED_BRANCHES, encoding="utf-8")
    sets = {}
    for fusion in ("auto", "off"):
        result, program = _build(tmp_path, model, 2, zero_copy, fusion=fusion)
        plan = result.system.plan
        assert all(b.sets_why for b in plan.buffers), plan.buffers
        sets[fusion] = {b.what: b.sets for b in plan.buffers}
        text = program.read_text()
        assert "buffer sets (2, one a frame in flight" in text
    assert sets["auto"]["in2_erode2.dst"] == sets["off"]["erode2.dst"] == 2
    assert "written in stage2, read in stage4 by adapter3_gpu2cpu" in text
