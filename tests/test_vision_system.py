"""The generated vision system, end to end on the OpenCL device, against ground truth."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.library.camera import Camera

MODEL = ROOT / "models" / "vision_system.yaml"


def expected_decision(buoys, width, stop_radius):
    """Independent reference: head for the largest buoy (ties: leftmost)."""
    if not buoys:
        return "search", None
    target = max(buoys, key=lambda b: (b[2], -b[0]))
    if target[2] >= stop_radius:
        return "stop", target
    if target[0] < width / 3:
        return "turn_left", target
    if target[0] >= 2 * width / 3:
        return "turn_right", target
    return "forward", target


@pytest.mark.parametrize("mode", ["gpu-aware", "standard"])
def test_detections_match_synthetic_ground_truth(build, mode):
    require_opencl()
    result, out = build(MODEL, mode)
    module = load_generated(out / "vision_system.py", f"vision_{mode.replace('-', '_')}")
    frames = 60  # the quick start's demo
    run = module.run(frames=frames)
    assert run.frames == frames
    manager = run.components["manager"]
    cam1 = Camera(seed=1, width=640, height=480)
    cam2 = Camera(seed=2, width=640, height=480)
    assert len(manager.history) == frames
    for f, decision in enumerate(manager.history):
        truth = [(b.x, b.y, b.radius) for b in cam1.ground_truth(f)]
        truth += [(b.x + 640, b.y, b.radius) for b in cam2.ground_truth(f)]
        seen = sorted((s.x, s.y, s.radius) for s in decision.sightings)
        assert len(seen) == len(truth), f"frame {f}"
        for (sx, sy, sr), (tx, ty, tr) in zip(seen, sorted(truth)):
            # a digital disk centred on a pixel has its centroid exactly there
            assert (sx, sy) == (tx, ty), f"frame {f}"
            assert sr == tr, f"frame {f}"  # half the bounding box of a digital disk
        action, target = expected_decision(sorted(truth), 1280, 60)
        assert decision.action == action, f"frame {f}"
    # the scene makes the robot change course: buoys drift nearer and farther, so the
    # largest one moves between the thirds of the frame, and one comes close enough to stop
    actions = {d.action for d in manager.history}
    assert actions == {"forward", "turn_left", "turn_right", "stop"}, actions


def test_generated_program_runs_from_the_command_line(tmp_path):
    require_opencl()
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "vision_system.py"),
                           "--frames", "3"], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert [line.split(":")[0] for line in lines] == ["frame 0", "frame 1", "frame 2"]
    assert "buoys: (" in lines[0]
    assert "processed 3 frame(s)" in proc.stderr


def test_gpucompgen_run_builds_into_a_temporary_folder(tmp_path):
    require_opencl()
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(MODEL),
                           "--frames", "2"], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("\n") == 2 and proc.stdout.startswith("frame 0:")
    assert not list(tmp_path.iterdir()), "run must not write into the working folder"


def test_merged_mask_is_bit_exact_against_numpy(build):
    """The GPU path (adapters, merger, detector, adapter) equals numpy on the same frames."""
    require_opencl()
    _, out = build(MODEL)
    module = load_generated(out / "vision_system.py", "vision_bitexact")
    masks = []
    original = module.VisionManager.execute

    def spy(self, mask):
        masks.append(mask.copy())
        return original(self, mask)

    module.VisionManager.execute = spy
    module.run(frames=3)
    cam1, cam2 = Camera(seed=1), Camera(seed=2)
    cam1.initialize()
    cam2.initialize()
    for mask in masks:
        frame = np.hstack([cam1.execute(), cam2.execute()]).astype(int)
        r, g, b = frame[..., 0], frame[..., 1], frame[..., 2]
        ref = np.where((r >= 150) & (r - g >= 80) & (r - b >= 80), 255, 0).astype(np.uint8)
        np.testing.assert_array_equal(mask, ref)


def test_run_plans_for_the_device_it_runs_on():
    """gpucompgen run builds for the real device: on a unified-memory device (PoCL) its
    adapters are zero-copy and nothing is copied between CPU and GPU."""
    require_opencl()
    from gpucompgen.device import query_device

    unified = query_device().host_unified_memory
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(MODEL),
                           "--frames", "2", "--quiet", "--profile"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    if unified:
        assert "CPU->GPU 0 copies 0 bytes" in proc.stderr, proc.stderr
    else:
        assert "CPU->GPU 2 copies 1,843,200 bytes" in proc.stderr, proc.stderr
