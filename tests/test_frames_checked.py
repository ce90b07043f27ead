"""Frames are checked where a standard component's output enters another part (issue 12).

Before these checks only byte counts were compared: a transposed frame with the right byte
count, a float32 frame between two standard components, a narrower frame in standard mode
(the device kept the previous frame's bytes) and a None returned mid-stream all passed or
failed obscurely. Each case runs a generated program the way a user does and expects one
error line naming the producing component and port, the frame, what was expected and what
came, exit code 1 and no traceback — in every mode and adapter form.
"""

from __future__ import annotations

import pytest
from conftest import ROOT, require_opencl
from test_lifecycle import build_model, run_program

TYPES = (ROOT / "tests" / "data" / "frames" / "types.yaml").as_posix()

# fault -> what the message must say about the frame that came
FAULTS = {
    "transpose": "returned a 48x32x3 uint8 frame where the system was built for 32x48x3 "
                 "uint8 (transposed?",
    "float32": "returned a 32x48x3 float32 frame where the system was built for 32x48x3 uint8"
               " (convert with .astype(np.uint8))",
    "narrow": "returned a 32x47x3 uint8 frame where the system was built for 32x48x3 uint8",
    "none": "execute() returned None mid-stream where a 32x48x3 uint8 frame was expected",
    "list": "execute() returned list where a numpy array 32x48x3 uint8 was expected",
    "extra_axis": "returned a 1x32x48x3 uint8 frame",
}


def model(fault: str, consumer: str, mode_key: str = "") -> str:
    """camera -> shaper -> consumer: a GPU-aware ObjectDetector (through an adapter) or a
    standard Swallow (no adapter at all)."""
    consumer_type = "ObjectDetector" if consumer == "gpu" else "Swallow"
    port = "frame" if consumer == "gpu" else "image"
    return f"""\
        system: frame_checks
        types: [{TYPES}]
        {mode_key}
        components:
          camera: {{type: Camera, params: {{width: 48, height: 32, frames: 4}}}}
          shaper: {{type: Misshaper, params: {{fault: "{fault}", fault_at: 2}}}}
          consumer: {{type: {consumer_type}}}
        connections:
          - camera.image -> shaper.image
          - shaper.image_out -> consumer.{port}
        """


def assert_reported(proc, fault: str) -> None:
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    line = proc.stderr.strip().splitlines()[0]
    assert line.startswith("error: shaper failed at frame 2: shaper.image_out: "), line
    assert FAULTS[fault] in line, line


@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("consumer", ["gpu", "cpu"])
def test_a_wrong_frame_is_named_where_it_leaves_its_producer(tmp_path, fault, consumer):
    if consumer == "gpu":
        require_opencl()
    program = build_model(tmp_path, model(fault, consumer))
    assert_reported(run_program(program), fault)


@pytest.mark.parametrize("platform", [
    "platform: {zero_copy: on}",
    "platform: {zero_copy: off, execution: sequential}",
])
@pytest.mark.parametrize("fault", ["transpose", "narrow", "float32"])
def test_every_adapter_form_checks_the_frame(tmp_path, platform, fault):
    require_opencl()
    program = build_model(tmp_path, model(fault, "gpu", platform))
    assert_reported(run_program(program), fault)


@pytest.mark.parametrize("fault", ["narrow", "transpose"])
def test_standard_mode_checks_the_frame_a_gpu_component_copies_itself(tmp_path, fault):
    """--mode standard: no adapter, the component copies its own input: a narrower frame
    used to leave the device with the previous frame's bytes."""
    require_opencl()
    from gpucompgen.build import compile_model, write

    path = tmp_path / "m.yaml"
    import textwrap

    path.write_text(textwrap.dedent(model(fault, "gpu")), encoding="utf-8")
    out = tmp_path / "std"
    write(compile_model(path, out, mode="standard"), out)
    assert_reported(run_program(out / "frame_checks.py"), fault)


def test_frames_that_are_right_pass_and_a_source_may_still_end_the_stream(tmp_path):
    require_opencl()
    program = build_model(tmp_path, model("", "gpu"))
    proc = run_program(program)
    assert proc.returncode == 0, proc.stderr
    assert "processed 4 frame(s)" in proc.stderr


def test_check_frame_directly():
    import numpy as np

    from gpucompgen.runtime import PipelineError, check_frame

    good = np.zeros((4, 5), np.uint8)
    checked = check_frame("a.b", good, (4, 5), np.uint8)
    assert checked.base is good and not checked.flags.writeable  # a read-only view
    # one channel as height x width x 1 (issue 22): handed on as height x width, a view
    deep = np.arange(20, dtype=np.uint8).reshape(4, 5, 1)
    flat = check_frame("a.b", deep, (4, 5), np.uint8)
    assert flat.shape == (4, 5) and np.shares_memory(flat, deep)
    assert not flat.flags.writeable
    np.testing.assert_array_equal(flat, deep[..., 0])
    strided = np.zeros((4, 10, 1), np.uint8)[:, ::2]  # not contiguous: still no copy
    assert np.shares_memory(check_frame("a.b", strided, (4, 5), np.uint8), strided)
    for wrong in (np.zeros((4, 5, 2), np.uint8), np.zeros((1, 4, 5), np.uint8),
                  np.zeros((4, 5, 1, 1), np.uint8)):
        with pytest.raises(PipelineError, match=r"a\.b: execute\(\) returned a .* uint8 "
                                                r"frame where the system was built for 4x5 "
                                                r"uint8 \(or 4x5x1\)"):
            check_frame("a.b", wrong, (4, 5), np.uint8)
    with pytest.raises(PipelineError, match=r"built for 4x5x3 uint8$"):  # three channels
        check_frame("a.b", deep, (4, 5, 3), np.uint8)
    with pytest.raises(PipelineError, match=r"4x5x1 float32 frame .*\(convert with"):
        check_frame("a.b", deep.astype(np.float32), (4, 5), np.uint8)
    with pytest.raises(PipelineError, match="returned int where a numpy array 4x5 uint8"):
        check_frame("a.b", 3, (4, 5), np.uint8)


DEEP = (ROOT / "tests" / "data" / "deep_gray" / "types.yaml").as_posix()


@pytest.mark.parametrize("variant", ["gpu", "cpu", "standard"])
def test_one_channel_frames_as_height_width_1_run_through(tmp_path, variant):
    """(issue 22) A source and a standard component that return one-channel frames as
    height x width x 1 feed a threshold and an erode on the GPU (through adapters), on
    the CPU (their CPU forms) and in standard mode (the components copy their own data):
    every frame arrives, equal to numpy's."""
    import numpy as np

    if variant != "cpu":
        require_opencl()
    import textwrap

    from gpucompgen.build import compile_model, write

    record = tmp_path / "frames.npy"
    path = tmp_path / "deep.yaml"
    path.write_text(textwrap.dedent(f"""\
        system: deep_gray
        types: [{DEEP}]
        platform: {{placement: {"cpu" if variant == "cpu" else "gpu"}}}
        components:
          source: {{type: DeepGraySource, params: {{width: 10, height: 9, frames: 3}}}}
          invert: {{type: DeepInvert}}
          thresh: {{type: ThresholdGray, params: {{thresh: 100, maxval: 255, thresh_type: 0}}}}
          erode: {{type: ErodeGray}}
          rec: {{type: GrayRecorder, params: {{path: "{record.as_posix()}"}}}}
        connections:
          - source.gray -> invert.image
          - invert.inverted -> thresh.image
          - thresh.thresholded -> erode.image
          - erode.eroded -> rec.image
        """), encoding="utf-8")
    out = tmp_path / "out"
    mode = "standard" if variant == "standard" else "gpu-aware"
    write(compile_model(path, out, mode=mode, fusion="off"), out)
    proc = run_program(out / "deep_gray.py")
    assert proc.returncode == 0, proc.stderr
    got = np.load(record)
    assert got.shape == (3, 9, 10)
    for i in range(3):
        frame = np.random.default_rng(i).integers(0, 256, (9, 10, 1), dtype=np.uint8)[..., 0]
        mask = np.where(255 - frame > 100, 255, 0)
        padded = np.pad(mask, 1, mode="edge")
        eroded = np.min([padded[dy:dy + 9, dx:dx + 10] for dy in range(3) for dx in range(3)],
                        axis=0)
        np.testing.assert_array_equal(got[i], eroded, err_msg=f"frame {i}")
