"""The CUDA runtime as a device API (runtime/device_api.py), tested without a GPU.

- NVRTC through cuda-python (the runtime's own compile path, not the ctypes one of
  tests/test_cuda.py): a clean compile leaves the interpreter's bytes alone, and the
  kernels `gpucompgen bench` builds compile for sm_72, sm_87 and sm_90;
- both device API modules declare every function of the interface, with compatible
  signatures (inspect);
- `tune` and `bench` take --backend; without cuda-python, a driver or a device they say so
  in one line and exit non-zero, with no traceback;
- the CUDA module's copies, maps, launches and events on a fake driver whose streams run
  only when the host waits for them (tests/fake_cuda_driver.py): every ordering the
  interface promises is held, or a test sees the stale bytes.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from conftest import ROOT

IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def _cuda_bindings_nvrtc() -> None:
    """Skip without cuda-python's NVRTC (fail under CI=true, where the test extra has it)."""
    try:
        from cuda.bindings import nvrtc

        err, *_ = nvrtc.nvrtcVersion()
        if int(err) != 0:
            raise ImportError(f"nvrtcVersion: {err}")
    except Exception as exc:  # no cuda-bindings, or no NVRTC library for it
        why = f"cuda-python's NVRTC is not usable ({type(exc).__name__}: {exc})"
        if IN_CI:
            pytest.fail(f"CI=true but {why}")
        pytest.skip(why)


def _python(code: str, **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT), **env},
                          timeout=300, check=False)


# --- NVRTC through cuda-python ------------------------------------------------------

def test_a_clean_nvrtc_compile_leaves_the_interpreters_bytes_alone(tmp_path):
    """A kernel that compiles without a message has a one-byte log (its NUL).  Read into
    b" " * 1, that is the interpreter's shared b" ", and NVRTC's NUL turned every one-byte
    space of the process into b"\\0": bytes([32]), " ".encode(), a one-byte read of a
    space (the corrupt .npz files of the H100 runs).  Run in a process of its own: the
    bug, were it back, would poison this one."""
    _cuda_bindings_nvrtc()
    code = """
from gpucompgen.runtime import cuda
cubin, log = cuda.compile_cubin('extern "C" __global__ void k(int *x) { x[0] = 1; }',
                                'k.cu', 'sm_87')
assert cubin[:4] == b'\\x7fELF', cubin[:4]
assert log == '', repr(log)
print(bytes([32])[0], ' '.encode()[0], b'a b'[1:2][0])
"""
    proc = _python(code, XDG_CACHE_HOME=str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["32", "32", "32"]


def test_a_failed_nvrtc_compile_gives_its_log():
    _cuda_bindings_nvrtc()
    from gpucompgen.runtime import cuda

    cubin, log = cuda.compile_cubin('extern "C" __global__ void k(int *x) { x[0] = y; }',
                                    "k.cu", "sm_87")
    assert cubin is None
    assert "k.cu(1)" in log and '"y"' in log and "undefined" in log
