"""`gpucompgen bench` with tiny settings: its table, CSV and PNG (never its timings)."""

from __future__ import annotations

import csv
import importlib.util
import subprocess
import sys

import pytest
from conftest import require_opencl

from gpucompgen import bench


def test_bench_writes_table_csv_and_plot(tmp_path):
    require_opencl()
    out = tmp_path / "results"
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "bench", "--sizes",
                           "48x32,33x17", "--lengths", "1,2", "--frames", "3", "-o", str(out)],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr == "", "no progress bar when stderr is not a terminal"
    has_cv2 = importlib.util.find_spec("cv2") is not None
    with (out / "bench.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["width", "height", "components", "variant", "samples",
                             "median_ms", "q1_ms", "q3_ms"]
    found = {(r["width"], r["height"], r["components"], r["variant"]) for r in rows}
    for w, h in (("48", "32"), ("33", "17")):
        for n in ("1", "2"):
            for variant in ("standard", "gpu-aware", "zero-copy", "hand-written", "bound"):
                assert (w, h, n, variant) in found
            if has_cv2:
                assert (w, h, n, "opencv-cpu") in found
    for r in rows:
        assert r["variant"] in bench.VARIANTS
        q1, med, q3 = float(r["q1_ms"]), float(r["median_ms"]), float(r["q3_ms"])
        assert 0 <= q1 <= med <= q3
        if r["variant"] in ("standard", "gpu-aware", "zero-copy", "fused", "hand-written"):
            assert int(r["samples"]) == 3  # 3 frames timed, in rounds
    png = (out / "bench.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    import matplotlib.image

    height, width = matplotlib.image.imread(out / "bench.png").shape[:2]
    assert (width, height) == (1200, 450)  # two panels, one per size
    text = proc.stdout
    assert "ms per frame, median [q1-q3], 3 frames per variant" in text
    assert "\n33x17 pixels\n" in text and "\n48x32 pixels\n" in text
    header = next(line for line in text.splitlines() if line.lstrip().startswith("N "))
    assert header.split()[:7] == ["N", "standard", "gpu-aware", "zero-copy", "fused",
                                  "hand-written", "bound"]
    for ratio in ("std/aware", "aware/zero", "aware/fused", "aware/hand", "aware/bound"):
        assert ratio in header
    assert "48x32 N=2: standard / gpu-aware = " in text
    assert "(target >= 3.00x)" in text and "(target <= 1.10x)" in text
    assert f"wrote {out / 'bench.csv'}" in text


@pytest.mark.parametrize("variant,adapters", [
    ("standard", set()),
    ("gpu-aware", {"CpuToGpuAdapter", "GpuToCpuAdapter"}),
    ("zero-copy", {"ZeroCopyCpuToGpuAdapter", "ZeroCopyGpuToCpuAdapter"}),
])
def test_each_generated_variant_has_its_own_adapters(tmp_path, variant, adapters):
    """The zero-copy line times zero-copy adapters and the gpu-aware line copying ones,
    whatever the device planned for (the profile 'portable' has no unified memory)."""
    import re

    bench.Generated(tmp_path, 2, (40, 30), variant, context=None)
    source = (tmp_path / f"{variant}_2_40x30" / "mirror_chain_2.py").read_text()
    used = set(re.findall(r"= runtime\.(\w*Adapter)\(", source))
    assert used == adapters


def test_chain_model_is_a_valid_system(tmp_path):
    from gpucompgen.build import compile_model

    model = tmp_path / "c.yaml"
    model.write_text(bench.chain_model(3, 40, 30))
    result = compile_model(model, tmp_path / "out", fusion="off")
    assert list(result.system.components) == ["source", "mirror1", "mirror2", "mirror3", "sink"]
    assert result.system.order == ["source", "adapter1_cpu2gpu", "mirror1", "mirror2",
                                   "mirror3", "adapter2_gpu2cpu", "sink"]
    assert [a.direction for a in result.system.adapters] == ["cpu2gpu", "gpu2cpu"]
    standard = compile_model(model, tmp_path / "out", mode="standard")
    assert standard.system.adapters == []


@pytest.mark.parametrize("args,message", [
    (["--sizes", "1152by864"], "cannot read size '1152by864': write WIDTHxHEIGHT"),
    (["--lengths", "0,5"], "chain lengths must be 1 or more"),
    (["--lengths", "5,499"], "chain lengths must be at most 498 (a system has at most 500 "),
    (["--sizes", "16x16,1x99999999"], "size '1x99999999': width and height must be at most "
                                      "16,384 (StillImage's range)"),
    (["--frames", "0"], "--frames must be 1 or more"),
    (["--frames", "-1"], "--frames must be 1 or more"),  # once "0 or more", from run's rule
    (["-o", "/dev/null/results"], "cannot create output folder /dev/null/results: Not a directory"),
])
def test_bad_options_are_errors_without_traceback(tmp_path, args, message):
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "bench", "--lengths", "1",
                           "--sizes", "16x16", "--frames", "1", "-o", str(tmp_path)] + args,
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 2
    assert f"gpucompgen bench: error: {message}" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_missing_extras_say_what_to_install(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "tqdm" else real(name, *a))
    with pytest.raises(bench.BenchError, match=r"needs tqdm: pip install 'gpucompgen\[bench\]'"):
        bench.run_bench([(16, 16)], [1], 1, bench.Path("unused"))


def test_bench_bounds_agree_with_the_library():
    """bench refuses sizes and lengths up front, by the bounds the models it writes obey."""
    from gpucompgen.model import library_types
    still = library_types()["StillImage"]
    assert bench.MAX_SIDE == still.params["width"].maximum == still.params["height"].maximum


def _benchmark(tmp_path, script: str, *args: str) -> str:
    from conftest import ROOT

    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    return proc.stdout


def test_pipelines_benchmark_outputs_equal_opencv_in_every_variant(tmp_path):
    """benchmarks/pipelines.py at an odd tiny size: every pipeline, every variant (default,
    on the device fused and not, all on the CPU, auto after tune, on the device after
    tune) gives cv2's bytes (it exits 1 otherwise) and prints its table, the machine, the
    device and the load."""
    require_opencl()
    out = _benchmark(tmp_path, "pipelines.py", "--sizes", "33x17", "--rounds", "1",
                     "--frames", "2", "--tune-frames", "1")
    assert "OpenCL device:" in out and "load average before:" in out
    for name in ("lanes", "colour", "edges", "motion", "pointwise"):
        assert f"| {name} | 33x17 |" in out
    assert "| pipeline | size | cv2 | default | device | device fusion off | all CPU | " \
           "auto after tune | device after tune |" in out


def test_frame_cost_and_cpu_forms_benchmarks_run(tmp_path):
    require_opencl()
    out = _benchmark(tmp_path, "frame_cost.py", "--lengths", "1,2", "--frames", "5",
                     "--rounds", "1")
    for variant in ("GPU unfused", "GPU fused", "CPU"):
        assert f"  2 {variant}" in out
    # cpu_forms.py asserts each form's bytes equal its cv2 call before timing it
    out = _benchmark(tmp_path, "cpu_forms.py", "--size", "33x17", "--rounds", "1")
    assert "MedianBlurGray" in out and "RgbToHsv" in out
