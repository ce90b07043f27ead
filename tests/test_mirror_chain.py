"""VerticalMirror against numpy and OpenCV; the paper's two modes on a chain of mirrors:
same output, and data moved on every component (standard) or only at adapters (GPU-aware)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.library.still_image import still_frame

MODEL = ROOT / "models" / "mirror_chain.yaml"
MIRRORS = 5


def _module(build, mode, name):
    require_opencl()
    _, out = build(MODEL, mode)
    return load_generated(out / "mirror_chain.py", name)


@pytest.mark.parametrize("settings", [(32, 8, 8, 1), (8, 1, 1, 1), (16, 64, 2, 1),
                                      (128, 16, 16, 1), (64, 3, 5, 1)])
@pytest.mark.parametrize("shape", [(864, 1152), (37, 23), (1, 1), (5, 1151), (2, 16), (9, 17)])
def test_vertical_mirror_is_bit_exact(cl_context, cl_queue, shape, settings):
    """The kernel a lone mirror runs (generated from VerticalMirror's form), at any
    settings: rows of odd widths and of 16-pixel multiples, rows split among threads."""
    from conftest import run_generated

    from gpucompgen.model import library_types

    image = np.random.default_rng(shape[0] * 31 + shape[1]).integers(
        0, 256, (*shape, 3), dtype=np.uint8)
    out = run_generated(cl_context, cl_queue, library_types()["VerticalMirror"], {}, [image],
                        image.shape, settings)
    np.testing.assert_array_equal(out, np.flipud(image))
    cv2 = pytest.importorskip("cv2")
    np.testing.assert_array_equal(out, cv2.flip(image, 0))


@pytest.fixture(scope="module")
def chains(tmp_path_factory, cl_context):
    """Both modes of models/mirror_chain.yaml, built once for the module."""
    from gpucompgen.build import compile_model, write

    modules = {}
    for mode in ("gpu-aware", "standard"):
        out = tmp_path_factory.mktemp(mode)
        write(compile_model(MODEL, out, mode=mode, fusion="off"), out)
        modules[mode] = load_generated(out / "mirror_chain.py",
                                       f"mirror_chain_{mode.replace('-', '_')}")
    return modules


def test_both_modes_give_identical_outputs(chains, cl_context):
    frame = still_frame(1152, 864)
    outputs = {}
    for mode, module in chains.items():
        result = module.run(frames=3, context=cl_context)
        assert result.frames == 3
        outputs[mode] = result.components["sink"].last.copy()
        assert len(result.components["sink"].arrivals) == 3
    np.testing.assert_array_equal(outputs["gpu-aware"], outputs["standard"])
    np.testing.assert_array_equal(outputs["gpu-aware"], np.flipud(frame))  # 5 flips


@pytest.mark.parametrize("mode,per_frame", [("gpu-aware", (1, 1)),
                                            ("standard", (MIRRORS, MIRRORS))])
def test_transfers_per_frame(chains, cl_context, monkeypatch, mode, per_frame):
    """Counted twice: by wrapping cl.enqueue_copy, and by the --profile counters."""
    import pyopencl as cl

    frames, nbytes = 4, 864 * 1152 * 3
    counts = {"cpu2gpu": 0, "gpu2cpu": 0, "other": 0}
    real_copy = cl.enqueue_copy

    def counting_copy(queue, dest, src, **kwargs):
        if isinstance(dest, cl.Buffer) and isinstance(src, np.ndarray):
            counts["cpu2gpu"] += 1
        elif isinstance(dest, np.ndarray) and isinstance(src, cl.Buffer):
            counts["gpu2cpu"] += 1
        else:
            counts["other"] += 1
        return real_copy(queue, dest, src, **kwargs)

    monkeypatch.setattr(cl, "enqueue_copy", counting_copy)
    result = chains[mode].run(frames=frames, context=cl_context, profile=True)
    monkeypatch.undo()
    assert counts == {"cpu2gpu": per_frame[0] * frames, "gpu2cpu": per_frame[1] * frames,
                      "other": 0}
    profile = result.profile
    assert profile.per_frame(frames) == {
        "copies_cpu2gpu": per_frame[0], "copies_gpu2cpu": per_frame[1],
        "bytes_cpu2gpu": per_frame[0] * nbytes, "bytes_gpu2cpu": per_frame[1] * nbytes}
    profile.collect()
    kernels = {name for (name, what) in profile.seconds if what == "kernel"}
    assert kernels == {f"mirror{i}" for i in range(1, MIRRORS + 1)}
    assert all(len(s) == frames and min(s) >= 0 for s in profile.seconds.values())
    copiers = {name for (name, what) in profile.seconds if what != "kernel"}
    if mode == "standard":
        assert copiers == kernels  # each component copies its own data
    else:
        assert copiers == {"adapter1_cpu2gpu", "adapter2_gpu2cpu"}


def test_zero_copy_chain_copies_nothing_and_profiles_its_maps(tmp_path, cl_context,
                                                              monkeypatch):
    """Zero-copy adapters: no cl.enqueue_copy at all, and --profile shows each map/unmap."""
    import pyopencl as cl

    from gpucompgen.build import compile_model, write

    write(compile_model(MODEL, tmp_path, zero_copy="on", fusion="off"), tmp_path)
    module = load_generated(tmp_path / "mirror_chain.py", "mirror_chain_zero_copy_profile")
    copies = []
    real_copy = cl.enqueue_copy
    monkeypatch.setattr(cl, "enqueue_copy", lambda *a, **k: copies.append(a) or real_copy(*a, **k))
    frames = 4
    result = module.run(frames=frames, context=cl_context, profile=True)
    monkeypatch.undo()
    assert copies == []
    profile = result.profile
    assert profile.per_frame(frames) == {"copies_cpu2gpu": 0, "copies_gpu2cpu": 0,
                                         "bytes_cpu2gpu": 0, "bytes_gpu2cpu": 0}
    assert profile.maps == frames
    report = profile.report(frames)
    profile.collect()
    assert {key: len(secs) for key, secs in profile.seconds.items() if key[1] != "kernel"} == {
        ("adapter2_gpu2cpu", "map"): frames, ("adapter2_gpu2cpu", "unmap"): frames}
    assert "; 1 zero-copy maps" in report
    # the sink got every frame, mirrored an odd number of times
    image = still_frame(1152, 864)
    np.testing.assert_array_equal(result.components["sink"].last, image[::-1])


def test_without_profile_parts_have_no_profile(chains, cl_context):
    result = chains["gpu-aware"].run(frames=1, context=cl_context)
    assert result.profile is None
    assert all(getattr(p, "profile", None) is None for p in result.components.values())


def test_profile_flag_of_the_generated_program():
    require_opencl()
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "mirror_chain.py"),
                           "--frames", "2", "--profile"], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ), check=False)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines[0].split() == ["part", "what", "calls", "median", "ms", "total", "ms"]
    # the five mirrors are fused: the group is timed as one part, one kernel a frame
    assert [line.split()[:3] for line in lines[1:4]] == [
        ["adapter1_cpu2gpu", "cpu2gpu", "2"], ["mirror1_to_mirror5", "kernel", "2"],
        ["adapter2_gpu2cpu", "gpu2cpu", "2"]]
    assert "per frame CPU->GPU 1 copies 2,985,984 bytes, GPU->CPU 1 copies 2,985,984 bytes" \
        in proc.stderr
    assert "processed 2 frame(s)" in proc.stderr


def test_rows_cover_is_printed_and_planned(tmp_path):
    from gpucompgen.build import compile_model, write

    out = tmp_path / "out"
    write(compile_model(MODEL, out, fusion="off"), out)  # the mirrors' own kernels
    text = (out / "mirror_chain.py").read_text()
    assert "covers tile whole rows of\n    'dst'" in text
    # rows: one group across, 864 rows / tile 32 = 27 groups of 8x8 threads down
    assert "tile=32, local_size=(8, 8, 1), global_size=(8, 216, 1)," in text
    assert "mirror1: settings preferred, 1,728 resident threads" in text


def test_bad_kernel_cover_is_a_positioned_error(tmp_path):
    (tmp_path / "k.cl").write_text("__kernel void k(__global uchar *a, const int a_height,\n"
                                   "    const int a_width, const int tile) {}\n")
    (tmp_path / "t.yaml").write_text(
        "component_types:\n  K:\n    kind: gpu-aware\n    outputs:\n"
        "      a: {memory: gpu, height: 4, width: 4}\n"
        "    kernel: {file: k.cl, function: k, cover: columns}\n")
    model = tmp_path / "m.yaml"
    model.write_text("system: s\ntypes: [t.yaml]\ncomponents:\n  k: {type: K}\n")
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "check", str(model)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 1
    assert "t.yaml:6:46: error: kernel cover 'columns' of 'K' is not one of " \
           "['squares', 'rows']" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
