"""gpucompgen replay: recordings the tests make (image folders, a video, an MCAP file, a
corrupt one), run locally and on Ray (local mode, 2 CPUs), compared with a baseline.

The scene: a dark frame with red discs at known places; the model is Camera ->
ObjectDetector -> VisionManager, so each sink's per-frame report is a decision whose
ground truth the test knows (which frame first sees the disc only a lower threshold finds).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import IN_CI, require_opencl

cv2 = pytest.importorskip("cv2")

H, W = 48, 64
FRAMES = 6
DIM_FROM = 3  # from this frame on a second, dimmer disc (red 180) is in the scene


def scene(n: int, seed: int = 0) -> list[np.ndarray]:
    """RGB frames: a bright disc (red 250) moving right; from DIM_FROM, a dim one (red 180)."""
    rng = np.random.default_rng(seed)
    shots = []
    for f in range(n):
        frame = np.full((H, W, 3), 20, np.uint8)
        frame += rng.integers(0, 10, frame.shape, dtype=np.uint8)
        cv2.circle(frame, (10 + 4 * f, 16), 6, (250, 30, 30), -1)
        if f >= DIM_FROM:
            cv2.circle(frame, (48, 34), 7, (180, 30, 30), -1)
        shots.append(frame)
    return shots


def write_folder(path: Path, shots) -> Path:
    path.mkdir(parents=True)
    for i, shot in enumerate(shots):
        cv2.imwrite(str(path / f"{i:04d}.png"), cv2.cvtColor(shot, cv2.COLOR_RGB2BGR))
    return path


def write_video(path: Path, shots) -> Path:
    """Lossless enough for the test: FFV1 where OpenCV's FFmpeg has it, else MJPG at 100."""
    for fourcc, name in (("FFV1", path.with_suffix(".avi")), ("MJPG", path.with_suffix(".avi"))):
        writer = cv2.VideoWriter(str(name), cv2.VideoWriter_fourcc(*fourcc), 10, (W, H))
        if writer.isOpened():
            if fourcc == "MJPG":
                writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 100)
            for shot in shots:
                writer.write(cv2.cvtColor(shot, cv2.COLOR_RGB2BGR))
            writer.release()
            return name
    pytest.fail("OpenCV writes no video here")


def write_model(path: Path, red_min: int = 150) -> Path:
    path.write_text(textwrap.dedent(f"""\
        system: replayed
        components:
          camera: {{type: Camera, params: {{width: {W}, height: {H}}}}}
          detector: {{type: ObjectDetector, params: {{red_min: {red_min}, margin: 80}}}}
          manager: {{type: VisionManager, params: {{min_area: 5, print_decisions: false}}}}
        connections:
          - camera.image -> detector.frame
          - detector.mask -> manager.mask
        """), encoding="utf-8")
    return path


def replay(*args, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpucompgen", "replay", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, check=False,
                          env=dict(os.environ))


def summaries(out: Path) -> dict[str, dict]:
    run = json.loads((out / "summary.json").read_text())
    return {row["recording"]: json.loads((out / row["folder"] / "summary.json").read_text())
            for row in run["recordings"] if (out / row["folder"] / "summary.json").is_file()}


TIMINGS = ("seconds", "frames_per_second", "latency_median_seconds", "attempts", "job")


def comparable(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k not in TIMINGS}


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("recordings")
    shots = scene(FRAMES)
    found = {"folder": write_folder(root / "drive1", shots),
             "video": write_video(root / "drive2", shots)}
    try:
        from test_io import write_mcap

        found["mcap"] = root / "drive3.mcap"
        write_mcap(found["mcap"], shots, extra_topics=False)
    except ImportError as exc:  # the recordings extra
        if IN_CI:
            raise
        print(f"no MCAP recording: {exc}")
    corrupt = root / "corrupt.avi"
    corrupt.write_bytes(b"RIFF\x00\x00\x00\x00AVI garbage, not a video" * 20)
    found["corrupt"] = corrupt
    return found


@pytest.fixture(scope="module")
def local_run(recordings, tmp_path_factory):
    require_opencl()
    root = tmp_path_factory.mktemp("local")
    model = write_model(root / "model.yaml")
    out = root / "out"
    proc = replay(model, *recordings.values(), "--out", out, "--slots", "2")
    return model, out, proc


def test_local_replay_summarises_every_recording_and_keeps_faults_local(local_run,
                                                                        recordings):
    _, out, proc = local_run
    assert proc.returncode == 1, proc.stderr  # the corrupt one
    found = summaries(out)
    assert set(found) == {str(p) for p in recordings.values()}
    for kind, path in recordings.items():
        summary = found[str(path)]
        if kind == "corrupt":
            assert summary["status"] == "failed", summary
            assert summary["reason"], summary
            assert f"{path}: failed" in proc.stderr
            continue
        assert summary["status"] == "complete", (kind, summary["reason"])
        assert summary["frames"] == FRAMES
        manager = summary["sinks"]["manager"]
        assert manager["frames"] == FRAMES
        assert [r["frame"] for r in manager["reports"]] == list(range(FRAMES))
        # ground truth: the bright disc is seen in every frame, the dim one from DIM_FROM
        assert [len(r["sightings"]) for r in manager["reports"]] == \
            [1] * DIM_FROM + [2] * (FRAMES - DIM_FROM), kind
    run = json.loads((out / "summary.json").read_text())
    assert run["totals"]["complete"] == len(recordings) - 1
    assert run["totals"]["failed"] == 1
    assert "replayed 4 recording(s)" in proc.stderr or "replayed 3 recording(s)" in proc.stderr
    # the frames a sink received do not depend on the container
    lossless = [found[str(recordings[k])]["sinks"]["manager"]["inputs"]
                for k in ("folder", "mcap") if k in recordings]
    assert all(x == lossless[0] for x in lossless)


def test_a_rerun_resumes_skipping_complete_recordings(local_run, recordings):
    model, out, _ = local_run
    before = {p: (out / f / "summary.json").stat().st_mtime_ns
              for p, f in _folders(out).items()}
    proc = replay(model, *recordings.values(), "--out", out)
    assert proc.returncode == 1
    assert proc.stderr.count("skipped ") == len(recordings) - 1, proc.stderr
    after = {p: (out / f / "summary.json").stat().st_mtime_ns for p, f in _folders(out).items()}
    for kind, path in recordings.items():
        same = before[str(path)] == after[str(path)]
        assert same is (kind != "corrupt"), kind  # only the failed one ran again


def _folders(out: Path) -> dict[str, str]:
    run = json.loads((out / "summary.json").read_text())
    return {row["recording"]: row["folder"] for row in run["recordings"]}


def test_a_baseline_finds_a_changed_threshold_and_its_first_frame(local_run, recordings,
                                                                  tmp_path):
    _, baseline, _ = local_run
    model = write_model(tmp_path / "model.yaml", red_min=200)  # the dim disc is gone
    out = tmp_path / "out"
    folder = recordings["folder"]
    proc = replay(model, folder, "--out", out, "--baseline", baseline)
    assert proc.returncode == 1, proc.stderr
    assert f"diverged: {folder}: sink manager: decision changed from frame {DIM_FROM}" \
        in proc.stderr, proc.stderr
    assert f"diverged: {folder}: sink manager: digest changed from frame {DIM_FROM}" \
        in proc.stderr
    # the same model against the same baseline: nothing diverges, exit 0
    same = tmp_path / "same"
    proc = replay(write_model(tmp_path / "same.yaml"), folder, "--out", same,
                  "--baseline", baseline)
    assert proc.returncode == 0, proc.stderr
    assert "0 divergence(s) from the baseline" in proc.stderr


def test_ray_engine_gives_the_local_engines_summaries(local_run, recordings, tmp_path):
    pytest.importorskip("ray")
    model, local_out, _ = local_run
    out = tmp_path / "ray"
    proc = replay(model, *recordings.values(), "--out", out, "--engine", "ray", "--slots", "2",
                  timeout=400)
    assert proc.returncode == 1, proc.stderr
    local, on_ray = summaries(local_out), summaries(out)
    assert set(local) == set(on_ray)
    for recording in local:
        assert comparable(on_ray[recording]) == comparable(local[recording]), recording
    run = json.loads((out / "summary.json").read_text())
    assert run["engine"] == "ray"


def test_a_worker_that_dies_is_retried_once(tmp_path, recordings):
    """A sink that kills its own process (SIGKILL) the first time it runs: the recording is
    run again and completes; the summary counts two attempts."""
    require_opencl()
    marker = tmp_path / "died-once"
    (tmp_path / "dying.py").write_text(textwrap.dedent(f"""\
        import os, signal
        from pathlib import Path

        class Dying:
            def initialize(self, mask):
                pass

            def execute(self, mask):
                marker = Path({str(marker)!r})
                if not marker.exists():
                    marker.write_text("x")
                    os.kill(os.getpid(), signal.SIGKILL)

            def free_memory(self):
                pass
        """), encoding="utf-8")
    (tmp_path / "types.yaml").write_text(textwrap.dedent("""\
        component_types:
          Dying:
            kind: standard
            inputs:
              mask: {memory: cpu, dtype: uint8, channels: 1}
            python: {file: dying.py, class: Dying}
        """), encoding="utf-8")
    model = tmp_path / "model.yaml"
    model.write_text(textwrap.dedent(f"""\
        system: dying
        types: [types.yaml]
        components:
          camera: {{type: Camera, params: {{width: {W}, height: {H}}}}}
          detector: {{type: ObjectDetector}}
          sink: {{type: Dying}}
        connections:
          - camera.image -> detector.frame
          - detector.mask -> sink.mask
        """), encoding="utf-8")
    out = tmp_path / "out"
    proc = replay(model, recordings["folder"], "--out", out)
    assert proc.returncode == 0, proc.stderr
    (summary,) = summaries(out).values()
    assert summary["attempts"] == 2
    assert summary["status"] == "complete"
    assert summary["sinks"]["sink"]["frames"] == FRAMES


def test_ctrl_c_stops_cleanly_and_keeps_the_summaries_written(tmp_path):
    """Many recordings one at a time; SIGINT once the first is summarised: exit 130, the
    summaries written stay, the run's summary says it was interrupted."""
    require_opencl()
    model = write_model(tmp_path / "model.yaml")
    shots = scene(40)
    recs = [write_folder(tmp_path / f"r{i}", shots) for i in range(6)]
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "gpucompgen", "replay", str(model),
                             *map(str, recs), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        end = time.monotonic() + 240
        while time.monotonic() < end and not list(out.glob("*/summary.json")):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    run = json.loads((out / "summary.json").read_text())
    assert run["interrupted"] is True
    statuses = [row["status"] for row in run["recordings"]]
    assert statuses[0] == "complete"
    assert "not run" in statuses  # the last ones never started
    assert "stopped by Ctrl-C" in err


@pytest.mark.parametrize("args,message", [
    (["--slots", "0"], "--slots: must be 1 or more"),
    (["--address", "x:1"], "--address, --num-gpus and --resource go with --engine ray"),
    (["--resource", "opencl"], "write NAME=AMOUNT"),
])
def test_bad_options_are_usage_errors(tmp_path, args, message):
    model = write_model(tmp_path / "model.yaml")
    folder = write_folder(tmp_path / "r", scene(1))
    proc = replay(model, folder, "--out", tmp_path / "out", *args)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_missing_recording_and_a_bad_baseline_are_usage_errors(tmp_path):
    model = write_model(tmp_path / "model.yaml")
    proc = replay(model, tmp_path / "nowhere", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert f"recording {tmp_path / 'nowhere'}: no such file or folder" in proc.stderr
    folder = write_folder(tmp_path / "r", scene(1))
    proc = replay(model, folder, "--out", tmp_path / "out", "--baseline", tmp_path)
    assert proc.returncode == 2
    assert "no summary.json there" in proc.stderr


# -- compare, on hand-made summaries --------------------------------------------------------

def _summary(status="complete", inputs=("a", "b", "c"), reports=("x", "y", "z")):
    return {"status": status, "sinks": {"s": {"inputs": [[i] for i in inputs],
                                              "reports": list(reports)}}}


def test_compare_names_the_first_frame_of_each_kind_of_change():
    from gpucompgen.replay.compare import compare_summaries

    assert compare_summaries("r", _summary(), _summary()) == []
    lines = [d.line() for d in compare_summaries(
        "r", _summary(inputs="abX", reports="xyQ"), _summary())]
    assert lines == ['r: sink s: decision changed from frame 2: "z" -> "Q"',
                     "r: sink s: digest changed from frame 2: c -> X"]
    lines = [d.line() for d in compare_summaries(
        "r", _summary("partial(2)", inputs="ab", reports="xy"), _summary())]
    assert lines == ["r: status changed: complete -> partial(2)",
                     "r: sink s: frame count changed from frame 2: 3 -> 2 frames"]


def test_digests_of_a_sink_are_the_same_whatever_the_placement(tmp_path):
    """--digests on the red-objects example: the MaskWriter's inputs and the objects it
    reports, frame by frame, are the same on the GPU, on the CPU and unfused."""
    require_opencl()
    model = Path(__file__).resolve().parent.parent / "models" / "red_objects.yaml"
    found = {}
    for name, extra in (("default", []), ("cpu", ["--place", "*=cpu"]),
                        ("unfused", ["--fusion", "off"])):
        digests = tmp_path / f"{name}.jsonl"
        proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(model), *extra,
                               "--frames", "3", "-q", "--digests", str(digests)],
                              capture_output=True, text=True, timeout=300, check=False,
                              env=dict(os.environ), cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        found[name] = [json.loads(line) for line in digests.read_text().splitlines()]
    assert len(found["default"]) == 3
    assert any(line["report"]["objects"] for line in found["default"])
    assert found["cpu"] == found["default"] == found["unfused"]
