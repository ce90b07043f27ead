"""Device selection: PYOPENCL_CTX when set, else the first device that compiles kernels.

The fakes describe devices the way pyopencl does, so the choice is checked for a broken
first platform (PyPI's PoCL on a CPU its LLVM does not know) without having one.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from conftest import ROOT, require_opencl

from gpucompgen import runtime
from gpucompgen.runtime import DeviceStatus, PipelineError


class FakeDevice:
    def __init__(self, name: str):
        self.name = name


def statuses(*specs: tuple[str, str | None]) -> list[DeviceStatus]:
    return [DeviceStatus(i, 0, FakeDevice(name), problem)
            for i, (name, problem) in enumerate(specs)]


@pytest.fixture
def no_ctx(monkeypatch):
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)


def test_a_device_that_cannot_compile_is_passed_over(monkeypatch, no_ctx):
    found = statuses(("pthread-AMD EPYC", "error: unknown target CPU 'generic'"),
                     ("pthread-skylake-avx512", None))
    monkeypatch.setattr(runtime.opencl, "survey_devices", lambda stop_at_first_usable=False: found)
    assert runtime.select_device() is found[1].device


def test_no_usable_device_names_every_device_and_its_problem(monkeypatch, no_ctx):
    found = statuses(("cpu-a", "error: unknown target CPU 'generic'"),
                     ("gpu-b", "error: out of resources"))
    monkeypatch.setattr(runtime.opencl, "survey_devices", lambda stop_at_first_usable=False: found)
    with pytest.raises(PipelineError) as err:
        runtime.select_device()
    text = str(err.value)
    assert "0:0 cpu-a: error: unknown target CPU 'generic'" in text
    assert "1:0 gpu-b: error: out of resources" in text
    assert "pocl-opencl-icd" in text


def test_no_device_at_all_says_what_to_install(monkeypatch, no_ctx):
    monkeypatch.setattr(runtime.opencl, "survey_devices", lambda stop_at_first_usable=False: [])
    with pytest.raises(PipelineError, match="no OpenCL device found; install"):
        runtime.select_device()


def test_pyopencl_ctx_that_matches_nothing_is_a_clear_error(monkeypatch):
    require_opencl()
    monkeypatch.setenv("PYOPENCL_CTX", "97")
    with pytest.raises(PipelineError, match="PYOPENCL_CTX='97' selects no usable OpenCL"):
        runtime.select_device()


def test_build_problem_is_the_compiler_error_line():
    exc = RuntimeError("clBuildProgram failed: BUILD_PROGRAM_FAILURE\n\nBuild on <dev>:\n\n"
                       "error: unknown target CPU 'generic'\nDevice failed to build")
    assert runtime._build_problem(exc) == "error: unknown target CPU 'generic'"
    assert runtime._build_problem(RuntimeError("")) == "RuntimeError"


def test_the_pinned_device_compiles_and_devices_marks_it():
    """The device the tests run on builds kernels, and 'gpucompgen devices' says so."""
    require_opencl()
    found = runtime.survey_devices()
    ctx = os.environ["PYOPENCL_CTX"]
    pinned = [s for s in found if s.ctx == ctx or f"{s.platform_index}" == ctx]
    assert pinned and pinned[0].problem is None
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "devices"], cwd=ROOT,
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    marked = [line for line in proc.stdout.splitlines() if line.startswith("*")]
    assert len(marked) == 1 and f"PYOPENCL_CTX={pinned[0].ctx}" in marked[0]
    assert marked[0].endswith(": ok")
    assert "generated programs use" in proc.stdout


def test_devices_fails_when_pyopencl_ctx_selects_nothing():
    require_opencl()
    env = dict(os.environ, PYOPENCL_CTX="97")
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "devices"], cwd=ROOT, env=env,
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 1
    assert "gpucompgen devices: error: PYOPENCL_CTX='97'" in proc.stderr
    assert "Traceback" not in proc.stderr
