"""Parallel queues and zero-copy adapters: same outputs as the sequential, copying program.

Every variant (parallel or sequential execution, copying or zero-copy adapters) of the
two-branch model is run over many frames and compared with the others and with an
independent numpy reference; adapters are checked not to hand out a frame the device may
still be writing, and zero-copy views to be unmapped before the device writes again.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.build import compile_model, write
from gpucompgen.library.camera import Camera

BRANCHES = ROOT / "models" / "parallel_branches.yaml"
VARIANTS = list(itertools.product(["parallel", "sequential"], ["off", "on"]))


def _module(tmp_path: Path, model: Path, execution: str, zero_copy: str, tag: str = ""):
    out = tmp_path / f"out-{execution}-{zero_copy}{tag}"
    result = compile_model(model, out, execution=execution, zero_copy=zero_copy, fusion="off")
    write(result, out)
    name = f"{result.system.model.name}_{execution}_{zero_copy}{tag}"
    return result, load_generated(out / f"{result.system.model.name}.py", name)


def _run_collecting_masks(module, frames: int) -> list[np.ndarray]:
    """Run; return a copy of every mask the VisionManager got (a library class shared by
    all generated modules, so the spy is removed again)."""
    masks: list[np.ndarray] = []
    original = module.VisionManager.execute

    def spy(self, mask):
        masks.append(np.array(mask, copy=True))
        return original(self, mask)

    module.VisionManager.execute = spy
    try:
        assert module.run(frames=frames).frames == frames
    finally:
        module.VisionManager.execute = original
    return masks


def box_blur(image: np.ndarray, radius: int) -> np.ndarray:
    """Reference: mean of the (2r+1)^2 window, edges clamped, rounded half up."""
    n = (2 * radius + 1) ** 2
    padded = np.pad(image.astype(np.int64), ((radius, radius), (radius, radius), (0, 0)),
                    mode="edge")
    h, w = image.shape[:2]
    total = sum(padded[dy:dy + h, dx:dx + w] for dy in range(2 * radius + 1)
                for dx in range(2 * radius + 1))
    return ((total + n // 2) // n).astype(np.uint8)


def detect(frame: np.ndarray, red_min=150, margin=80) -> np.ndarray:
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return np.where((r >= red_min) & (r - g >= margin) & (r - b >= margin), 255, 0
                    ).astype(np.uint8)


def test_box_blur_reference_on_hand_computed_values():
    img = np.zeros((3, 3, 3), np.uint8)
    img[1, 1] = (9, 10, 4)
    out = box_blur(img, 1)
    # the centre sees all nine pixels: 9/9 = 1, (10 + 4) // 9 = 1, (4 + 4) // 9 = 0
    assert tuple(out[1, 1]) == (1, 1, 0)
    # a corner, edges clamped, still sees the centre once: (9 + 4) // 9 = 1
    assert tuple(out[0, 0]) == (1, 1, 0)
    assert (box_blur(img, 0) == img).all()


@pytest.fixture(scope="module")
def branch_runs(tmp_path_factory):
    require_opencl()
    tmp = tmp_path_factory.mktemp("branches")
    runs = {}
    for execution, zero_copy in VARIANTS:
        _, module = _module(tmp, BRANCHES, execution, zero_copy)
        runs[execution, zero_copy] = _run_collecting_masks(module, 24)
    return runs


def test_all_variants_give_identical_masks_over_many_frames(branch_runs):
    reference = branch_runs["sequential", "off"]
    assert len(reference) == 24
    for key, masks in branch_runs.items():
        assert len(masks) == 24, key
        for f, (a, b) in enumerate(zip(masks, reference)):
            np.testing.assert_array_equal(a, b, err_msg=f"{key} frame {f}")


def test_parallel_zero_copy_masks_match_numpy(branch_runs):
    masks = branch_runs["parallel", "on"]
    cam1, cam2 = Camera(seed=1), Camera(seed=2)
    cam1.initialize()
    cam2.initialize()
    for f, mask in enumerate(masks):
        a, b = cam1.execute(), cam2.execute()
        if f % 6:  # the numpy reference is slow; every sixth frame
            continue
        expected = detect(np.hstack([box_blur(a, 2), box_blur(b, 2)]))
        np.testing.assert_array_equal(mask, expected, err_msg=f"frame {f}")
    assert any(m.any() for m in masks), "the scene has buoys to detect"


def test_the_vision_system_is_identical_in_every_variant(tmp_path):
    require_opencl()
    runs = []
    for execution, zero_copy in VARIANTS:
        _, module = _module(tmp_path, ROOT / "models" / "vision_system.yaml", execution,
                            zero_copy)
        runs.append(_run_collecting_masks(module, 12))
    cam1, cam2 = Camera(seed=1), Camera(seed=2)
    cam1.initialize()
    cam2.initialize()
    for f in range(12):
        expected = detect(np.hstack([cam1.execute(), cam2.execute()]))
        for masks in runs:
            np.testing.assert_array_equal(masks[f], expected)


def test_zero_copy_view_is_unmapped_before_the_device_writes_again(tmp_path, monkeypatch):
    """The producer of a mapped buffer never runs while its view is still mapped."""
    require_opencl()
    import pyopencl as cl

    from gpucompgen import runtime

    _, module = _module(tmp_path, BRANCHES, "parallel", "on", tag="unmap")
    adapters = []
    init = runtime.ZeroCopyGpuToCpuAdapter.__init__

    def record(self, *args, **kwargs):
        init(self, *args, **kwargs)
        adapters.append(self)

    monkeypatch.setattr(runtime.ZeroCopyGpuToCpuAdapter, "__init__", record)
    produced = []
    original = module.ObjectDetector.execute

    def map_count(buffer) -> int:
        # OpenCL's own count of the buffer's live mappings: catches an unmap() that forgets
        # to release the mapping, which the Python attribute alone would not show
        return buffer.get_info(cl.mem_info.MAP_COUNT)

    def detector_execute(self, *args, **kwargs):
        assert adapters and all(a.view is None for a in adapters), \
            "the detector writes its mask while a zero-copy view of it is mapped"
        if "mask" in self.buffers:  # allocated: every frame
            assert map_count(self.buffers["mask"]) == 0, "the mask is still mapped on the device"
        produced.append(self)
        return original(self, *args, **kwargs)

    module.ObjectDetector.execute = detector_execute
    result = module.run(frames=5)
    assert len(produced) == 5
    assert all(a.view is None for a in adapters), "free_memory unmaps"
    assert result.frames == 5


SLOW_FILL = """
__kernel void slow_fill(__global uchar *out, const int rounds)
{
    const int i = get_global_id(0);
    uint h = (uint)i;
    for (int r = 0; r < rounds; r++)
        h = h * 1664525u + 1013904223u;
    /* h is never 0xdeadbeef for these inputs: the loop only delays the write */
    out[i] = (uchar)(i * 7 + 3 + (h == 0xdeadbeefu && rounds < 0));
}
"""


@pytest.mark.parametrize("zero_copy", ["off", "on"])
@pytest.mark.parametrize("same_queue", [True, False])
def test_gpu_to_cpu_adapter_never_hands_out_a_frame_still_being_written(
        tmp_path, cl_context, zero_copy, same_queue):
    """A slow kernel writes the buffer; the adapter's result must be its final contents."""
    import pyopencl as cl

    from gpucompgen import runtime
    from gpucompgen.runtime import Size

    cls = runtime.ZeroCopyGpuToCpuAdapter if zero_copy == "on" else runtime.GpuToCpuAdapter
    producer_queue = cl.CommandQueue(cl_context)
    adapter_queue = producer_queue if same_queue else cl.CommandQueue(cl_context)
    size = Size(64, 256, 1)
    adapter = cls(cl_context, adapter_queue, nbytes=size.nbytes(np.uint8))
    adapter.initialize(size, np.uint8)
    n = size.height * size.width
    expected = ((np.arange(n) * 7 + 3) % 256).astype(np.uint8).reshape(size.shape)
    kernel = cl.Program(cl_context, SLOW_FILL).build().slow_fill
    buf = cl.Buffer(cl_context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, n)
    for frame in range(3):
        cl.enqueue_fill_buffer(producer_queue, buf, np.uint8(0), 0, n).wait()
        event = kernel(producer_queue, (n,), None, buf, np.int32(20000))
        view = adapter.transfer(buf, wait_for=None if same_queue else [event])
        np.testing.assert_array_equal(view, expected, err_msg=f"frame {frame}")
        if zero_copy == "on":
            adapter.unmap()
    adapter.free_memory()


def test_zero_copy_follows_the_device_facts():
    vision = ROOT / "models" / "vision_system.yaml"
    for profile, unified in [("portable", False), ("nvidia-kepler", False),
                             ("pocl-cpu", True), ("embedded-igpu", True)]:
        system = compile_model(vision, ROOT / "generated", device=profile, fusion="off").system
        assert system.zero_copy is unified, profile
        assert all(a.zero_copy is unified for a in system.adapters), profile
    # forced either way
    assert compile_model(vision, ROOT / "generated", device="portable",
                         zero_copy="on", fusion="off").system.zero_copy
    assert not compile_model(vision, ROOT / "generated", device="pocl-cpu",
                             zero_copy="off", fusion="off").system.zero_copy


def test_zero_copy_is_recorded_in_the_code_and_the_plan(tmp_path):
    result = compile_model(BRANCHES, tmp_path, zero_copy="on", fusion="off")
    text = result.files[0].text
    assert "adapter1_cpu2gpu = parts['adapter1_cpu2gpu'] = runtime.ZeroCopyCpuToGpuAdapter(" \
        in text
    assert "adapter3_gpu2cpu = parts['adapter3_gpu2cpu'] = runtime.ZeroCopyGpuToCpuAdapter(" \
        in text
    assert "adapter3_gpu2cpu.unmap()  # the device may write detector.mask again" in text
    assert "runtime.CpuToGpuAdapter" not in text and "runtime.GpuToCpuAdapter" not in text
    # the outputs the adapters map are allocated in host-visible memory
    assert "host_visible=True" in text
    assert "#   bytes copied between CPU and GPU per frame: 0\n" in text
    assert "#   zero-copy adapters: on (forced by the model or the command line)" in text
    copying = compile_model(BRANCHES, tmp_path, fusion="off").files[0].text
    assert "ZeroCopy" not in copying
    # 2 uploads of 480x640x3 and one download of 480x1280x1
    assert f"#   bytes copied between CPU and GPU per frame: {2 * 921600 + 614400:,}\n" \
        in copying


def test_platform_zero_copy_and_execution_in_the_model(tmp_path):
    text = BRANCHES.read_text().replace(
        "  device: portable\n", "  device: pocl-cpu\n  zero_copy: off\n  execution: sequential\n"
        "  placement: gpu\n")  # lanes are for GPU work: not the CPU a pocl-cpu default picks
    model = tmp_path / "m.yaml"
    model.write_text(text)
    system = compile_model(model, tmp_path / "o", fusion="off").system
    assert not system.zero_copy and system.execution == "sequential"
    assert set(system.lanes.values()) == {0}
    # the command line wins over the model
    system = compile_model(model, tmp_path / "o", execution="parallel", zero_copy="on",
                           fusion="off").system
    assert system.zero_copy and system.execution == "parallel"


def test_bad_platform_values_are_positioned_errors(tmp_path):
    import subprocess
    import sys

    text = BRANCHES.read_text().replace(
        "  device: portable\n", "  device: portable\n  zero_copy: maybe\n  execution: fast\n")
    model = tmp_path / "bad.yaml"
    model.write_text(text)
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "plan", str(model)],
                          capture_output=True, text=True)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "bad.yaml:11:14: error: platform.zero_copy must be 'auto', 'on' or 'off', " \
           "not 'maybe'" in proc.stderr, proc.stderr
    assert "bad.yaml:12:14: error: platform.execution must be 'parallel' or 'sequential'" \
        in proc.stderr


def test_parallel_program_uses_one_queue_per_branch(tmp_path):
    system = compile_model(BRANCHES, tmp_path, fusion="off").system
    lanes = system.lanes
    assert lanes["adapter1_cpu2gpu"] == lanes["blur1"] == lanes["merger"] == lanes["detector"]
    assert lanes["adapter2_cpu2gpu"] == lanes["blur2"] != lanes["blur1"]
    assert system.waits["merger"] == ["blur2"]
    assert system.waits["blur1"] == system.waits["blur2"] == []
    text = compile_model(BRANCHES, tmp_path, fusion="off").files[0].text
    assert ("queue0 = runtime.create_queue(context, profile)\n"
            "    queue1 = runtime.create_queue(context, profile)") in text
    assert "merger.execute(blur1_dst, blur2_dst, wait_for=[blur2.event])" in text
    assert "blocking=False" in text
    seq = compile_model(BRANCHES, tmp_path, execution="sequential", fusion="off").files[0].text
    assert "wait_for" not in seq and "queue1" not in seq and "blocking=False" not in seq


def test_lane_ends_no_host_read_covers_are_waited_for_at_frame_end(tmp_path):
    """A GPU branch whose result no GPU-to-CPU adapter reads still completes every frame."""
    text = BRANCHES.read_text() + "  - camera1.image -> blur3.image\n"
    text = text.replace("  merger: {type: ImageMerger}\n",
                        "  merger: {type: ImageMerger}\n  blur3: {type: BoxBlur}\n")
    model = tmp_path / "m.yaml"
    model.write_text(text)
    result = compile_model(model, tmp_path / "o", fusion="off")
    assert result.system.frame_end_waits == ["blur3"]
    assert "cl.wait_for_events([blur3.event])  # frame complete\n" in result.files[0].text
    # its output is assigned to no variable the program never uses (pyflakes' F841)
    assert "\n            blur3.execute(camera1_image_gpu, wait_for=" in result.files[0].text
    require_opencl()
    write(result, tmp_path / "o")
    module = load_generated(tmp_path / "o" / "parallel_branches.py", "branches_dangling")
    assert len(_run_collecting_masks(module, 2)) == 2


def test_runtime_reports_kernel_limits(cl_context):
    import pyopencl as cl

    from gpucompgen import runtime

    device = cl_context.devices[0]
    kernel = cl.Program(cl_context, SLOW_FILL).build().slow_fill
    limits = runtime.check_work_group(kernel, device, (1, 1, 1), "Probe")
    info = cl.kernel_work_group_info
    assert limits.work_group_size == kernel.get_work_group_info(info.WORK_GROUP_SIZE, device)
    assert limits.preferred_multiple == kernel.get_work_group_info(
        info.PREFERRED_WORK_GROUP_SIZE_MULTIPLE, device)
    assert runtime.device_limits(device) is runtime.device_limits(device)  # queried once
    assert runtime.device_limits(device).max_work_group_size == device.max_work_group_size
    with pytest.raises(runtime.PipelineError, match="Probe: GPU settings"):
        runtime.check_work_group(kernel, device, (limits.work_group_size + 1, 1, 1), "Probe")


@pytest.mark.parametrize("model", sorted((ROOT / "models").glob("*.yaml")), ids=lambda p: p.stem)
@pytest.mark.parametrize("mode,zero_copy", [("gpu-aware", "off"), ("gpu-aware", "on"),
                                            ("standard", "off")])
def test_memory_check_counts_what_the_plan_says_is_on_the_device(tmp_path, model, mode,
                                                                 zero_copy):
    """A zero-copy upload wraps host memory: the check before the first frame must not
    count it, or a system that fits would be refused."""
    import re

    from gpucompgen.build import compile_model
    from gpucompgen.plan import plan_lines

    result = compile_model(model, tmp_path, mode, zero_copy=zero_copy, fusion="off")
    plan = result.system.plan
    text = "\n".join(plan_lines(plan))
    peak = int(re.search(r"peak device memory: ([\d,]+) bytes", text).group(1).replace(",", ""))
    # the program's start-up check lists the same buffers the plan counts
    checked = re.search(r"check_device_memory\(context.devices\[0\], \{(.*?)\}\)",
                        result.files[0].text, re.DOTALL)
    listed = sum(int(n.replace("_", "")) for n in re.findall(r": ([\d_]+),", checked.group(1))) \
        if checked else 0
    assert sum(b.nbytes for b in plan.device_buffers()) == peak == listed


class _DeferredCopies:
    """A device API whose host-to-device copies read their source only when waited for
    (as a device that has not run the copy yet): a host write into a staging array that
    an earlier copy still has to read shows up as the wrong frame moved."""

    class Event:
        def __init__(self, src):
            self.src, self.moved = src, None

        def wait(self):
            if self.moved is None:
                self.moved = np.array(self.src)  # the device reads the source now

    def device_buffer(self, context, nbytes, access="read_write"):
        return object()

    def pinned(self, context, queue, shape, dtype):
        return object(), np.zeros(shape, dtype)

    def copy(self, queue, dst, src, blocking=True, wait_for=None):
        event = self.Event(src)
        if blocking:
            event.wait()
        return event

    def wait(self, events):
        for event in events:
            event.wait()

    def release_pinned(self, queue, pinned):
        pass

    def release(self, buffer):
        pass


@pytest.mark.parametrize("sets", [1, 2, 3])
def test_a_staged_copy_is_read_before_the_next_frame_is_staged_in_its_set(sets):
    """CpuToGpuAdapter, not blocking, pinned staging: the next frame written into a set's
    pinned array waits for that set's previous copy, so every copy moves its own frame."""
    from gpucompgen.runtime import CpuToGpuAdapter

    adapter = CpuToGpuAdapter(None, None, nbytes=12, blocking=False, buffer_sets=sets,
                              staging="pinned")
    adapter._api = _DeferredCopies()
    adapter.initialize((2, 2, 3), np.uint8)
    events = []
    for frame in range(3 * sets + 1):
        adapter.transfer(np.full((2, 2, 3), frame, np.uint8))
        events.append(adapter.event)  # the device runs none of them until waited for
    for frame, event in enumerate(events):
        event.wait()
        assert event.moved.min() == event.moved.max() == frame
