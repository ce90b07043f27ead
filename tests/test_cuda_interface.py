"""The CUDA runtime as a device API (runtime/device_api.py), tested without a GPU.

- NVRTC through cuda-python (the runtime's own compile path, not the ctypes one of
  tests/test_cuda.py): a clean compile leaves the interpreter's bytes alone, and the
  kernels `gpucompgen bench` builds compile for sm_72, sm_87 and sm_90;
- both device API modules declare every function of the interface, with compatible
  signatures (inspect);
- `tune` and `bench` take --backend; without cuda-python, a driver or a device they say so
  in one line and exit non-zero, with no traceback;
- the CUDA module's copies, maps, launches and events on a fake driver (FakeDriver, below)
  whose streams run their commands only when the host waits for them: every ordering the
  interface promises is held, or a test sees stale bytes.
"""

from __future__ import annotations

import ctypes
import enum
import gc
import inspect
import os
import subprocess
import sys
import threading
import weakref
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from conftest import ROOT

from gpucompgen.runtime import cuda, device_api, opencl
from gpucompgen.runtime.errors import PipelineError
from gpucompgen.runtime.sizes import Size

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


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize(("major", "arch"), [(12, 72), (12, 87), (13, 87), (13, 90)],
                         ids=lambda v: str(v))
def test_the_bench_kernel_compiles_for_cuda(major, arch, channels):
    """`gpucompgen bench --backend cuda` builds its hand-written reference from the
    generator's VerticalMirror kernel, through the registry's kernel_text: it compiles
    for Xavier, Orin (CUDA 12 and 13) and Hopper."""
    from test_cuda import nvrtc_of

    from gpucompgen.backend import kernel_text
    from gpucompgen.kernelgen.fused import group_kernel, group_of_one
    from gpucompgen.model import library_types

    mirror = library_types()["VerticalMirror"].specialized("uint8", channels)
    group = group_of_one(mirror, {}, {"src": (48, 64), "dst": (48, 64)}, "m",
                         "vertical_mirror")
    suffix, text = kernel_text("cuda", group_kernel(group, "bench"))
    assert suffix == ".cu" and 'extern "C" __global__' in text
    compiled = nvrtc_of(major).compile(text, "vertical_mirror.cu", arch)
    assert compiled.ok, compiled.log
    assert kernel_text("opencl", "k") == (".cl", "k")


# --- the interface: both modules declare it ---------------------------------------------

def _declared() -> dict[str, inspect.Signature | None]:
    """The interface's names: functions with their signatures (self left out), and the
    plain names it annotates (NAME)."""
    out: dict[str, inspect.Signature | None] = {}
    for name, function in inspect.getmembers(device_api.DeviceAPI, inspect.isfunction):
        if not name.startswith("_"):
            sig = inspect.signature(function)
            out[name] = sig.replace(parameters=list(sig.parameters.values())[1:])
    for name in device_api.DeviceAPI.__annotations__:
        out.setdefault(name, None)
    return out


def _incompatible(declared: inspect.Signature, given: inspect.Signature) -> str:
    """Why a module's function cannot be called as the interface declares it ('' if it
    can): every declared parameter by name and position, optional where declared optional;
    any further parameter of the module's has a default."""
    want = list(declared.parameters.values())
    have = list(given.parameters.values())
    if any(p.kind is p.VAR_POSITIONAL for p in want):
        if not any(p.kind is p.VAR_POSITIONAL for p in have):
            return "takes no *args"
        want = [p for p in want if p.kind is not p.VAR_POSITIONAL]
        have = [p for p in have if p.kind is not p.VAR_POSITIONAL]
    if [p.name for p in have[:len(want)]] != [p.name for p in want]:
        return f"parameters {[p.name for p in have]}, declared {[p.name for p in want]}"
    for w, h in zip(want, have):
        if w.default is not w.empty and h.default is h.empty:
            return f"'{h.name}' has no default"
    extra = [p.name for p in have[len(want):] if p.default is p.empty]
    return f"further parameters without default: {extra}" if extra else ""


@pytest.mark.parametrize("module", [opencl, cuda], ids=["opencl", "cuda"])
def test_every_device_api_module_implements_the_interface(module):
    declared = _declared()
    assert len(declared) >= 35
    missing = sorted(name for name in declared if not hasattr(module, name))
    assert not missing
    problems = {name: _incompatible(sig, inspect.signature(getattr(module, name)))
                for name, sig in declared.items() if sig is not None}
    assert not {k: v for k, v in problems.items() if v}
    assert isinstance(module.NAME, str) and module.NAME
    assert device_api.get(device_api.name_of(module)) is module


def test_the_incompatibility_check_can_fail():
    def declared(self, queue, dst, src, blocking: bool = True): ...

    sig = inspect.signature(declared)
    sig = sig.replace(parameters=list(sig.parameters.values())[1:])
    assert _incompatible(sig, inspect.signature(lambda queue, dst, src, blocking=True,
                                                  wait_for=None: 0)) == ""
    assert "declared" in _incompatible(sig, inspect.signature(lambda q, dst, src,
                                                                   blocking=True: 0))
    assert "default" in _incompatible(sig, inspect.signature(lambda queue, dst, src,
                                                                  blocking: 0))
    assert "further" in _incompatible(sig, inspect.signature(
        lambda queue, dst, src, blocking=True, *, need: 0))


def test_device_api_picks_by_name_and_by_context():
    assert device_api.get() is opencl and device_api.get("cuda") is cuda
    with pytest.raises(ValueError, match="one of opencl, cuda"):
        device_api.get("metal")
    assert device_api.of(object()) is opencl
    assert device_api.of(cuda.CudaContext.__new__(cuda.CudaContext)) is cuda
    assert device_api.name_of(cuda) == "cuda"


# --- the command line ------------------------------------------------------------------

def test_tune_and_bench_take_backend():
    from gpucompgen.cli import parser

    assert parser().parse_args(["tune", "m.yaml"]).backend is None  # platform.backend
    assert parser().parse_args(["tune", "m.yaml", "--backend", "cuda"]).backend == "cuda"
    assert parser().parse_args(["bench"]).backend == "opencl"
    assert parser().parse_args(["bench", "--backend", "cuda"]).backend == "cuda"
    for argv in (["tune", "m.yaml", "--backend", "metal"], ["bench", "--backend", "cl"]):
        with pytest.raises(SystemExit) as exit_:
            parser().parse_args(argv)
        assert exit_.value.code == 2


_BLOCK_CUDA = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name == "cuda" or name.startswith("cuda."):
            raise ImportError(f"{name} blocked by the test")
sys.meta_path.insert(0, _Block())
from gpucompgen.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("command", ["tune", "bench"])
def test_without_cuda_python_tune_and_bench_say_what_to_install(command, tmp_path):
    argv = (["tune", str(ROOT / "models" / "mirror_chain.yaml"), "-o",
             str(tmp_path / "p.yaml")] if command == "tune" else
            ["bench", "--sizes", "64x48", "--lengths", "1", "--frames", "1", "--no-opencv",
             "-o", str(tmp_path / "b")])
    proc = subprocess.run([sys.executable, "-c", _BLOCK_CUDA, *argv, "--backend", "cuda"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert lines[0].startswith(f"gpucompgen {command}: error: the CUDA backend needs "
                               "NVIDIA's cuda-python: pip install 'gpucompgen[cuda]'")
    assert not (tmp_path / "p.yaml").exists() and not (tmp_path / "b").exists()


# --- a fake CUDA driver: streams that run only when the host waits ---------------------

class CUresult(enum.IntEnum):
    CUDA_SUCCESS = 0
    CUDA_ERROR_INVALID_VALUE = 1
    CUDA_ERROR_NO_DEVICE = 100
    CUDA_ERROR_NOT_READY = 600


OK = CUresult.CUDA_SUCCESS


class _Names:
    """cu.CUdevice_attribute.X and cu.CUfunction_attribute.X: the name itself."""

    def __getattr__(self, name: str) -> str:
        return name


_RUN = threading.RLock()  # stages of frames in flight wait from their own threads


class _Stream:
    """Commands in order; run only up to where the host waits (an event or the stream)."""

    def __init__(self):
        self.commands: list = []
        self.done = 0

    def run(self, upto: int) -> None:
        with _RUN:
            while self.done < upto:
                command = self.commands[self.done]
                self.done += 1
                command()


class _Event:
    def __init__(self):
        self.stream, self.position = None, 0

    def ready(self) -> bool:
        return self.stream is None or self.stream.done >= self.position


class FakeDriver:
    """The driver calls runtime/cuda.py makes, over host memory: device allocations are
    ctypes buffers, mapped host memory is its own device pointer (unified addressing),
    and kernels are Python functions (KERNELS) given their packed arguments.  Nothing a
    stream holds runs before the host waits for it, so a missing wait shows as stale
    bytes; memory a command touches after it was freed fails the test."""

    CUresult = CUresult
    CUdevice_attribute = _Names()
    CUfunction_attribute = _Names()
    ATTRIBUTES: ClassVar[dict[str, int]] = {"COMPUTE_CAPABILITY_MAJOR": 8, "COMPUTE_CAPABILITY_MINOR": 7,
        "MULTIPROCESSOR_COUNT": 16, "MAX_THREADS_PER_BLOCK": 1024, "MAX_BLOCK_DIM_X": 1024,
        "MAX_BLOCK_DIM_Y": 1024, "MAX_BLOCK_DIM_Z": 64, "MAX_THREADS_PER_MULTIPROCESSOR": 2048,
        "MAX_SHARED_MEMORY_PER_BLOCK": 49152, "INTEGRATED": 1, "CAN_MAP_HOST_MEMORY": 1}

    def __init__(self, devices: int = 1, init: CUresult = OK, kernel_threads: int = 1024):
        self.devices, self.init, self.kernel_threads = devices, init, kernel_threads
        self.memory: dict[int, ctypes.Array] = {}  # live allocations by address
        self.freed: list[ctypes.Array] = []  # kept: a stale view reads, but never crashes
        self.registered: set[int] = set()
        self.launches: list[tuple] = []  # (kernel, grid, block)
        self.null = _Stream()

    # devices and contexts
    def cuInit(self, flags):
        return (self.init,)

    def cuDeviceGetCount(self):
        return OK, self.devices

    def cuDeviceGet(self, ordinal):
        return OK, ordinal

    def cuDeviceGetName(self, size, device):
        return OK, b"Fake Orin\0" + b"\0" * (size - 10)

    def cuDeviceGetAttribute(self, attribute, device):
        return OK, self.ATTRIBUTES[attribute.removeprefix("CU_DEVICE_ATTRIBUTE_")]

    def cuDeviceTotalMem(self, device):
        return OK, 8 << 30

    def cuDevicePrimaryCtxRetain(self, device):
        return OK, "context"

    def cuCtxSetCurrent(self, context):
        return (OK,)

    def cuGetErrorString(self, err):
        return OK, b"fake error"

    # memory
    def _allocate(self, nbytes: int) -> int:
        block = ctypes.create_string_buffer(nbytes)
        address = ctypes.addressof(block)
        self.memory[address] = block
        return address

    def _live(self, address: int, nbytes: int) -> None:
        for start, block in self.memory.items():
            if start <= address and address + nbytes <= start + len(block):
                return
        raise AssertionError(f"a command touched {nbytes} bytes at {address:#x}, which is "
                             "not allocated (freed, or never)")

    def cuMemAlloc(self, nbytes):
        return OK, self._allocate(nbytes)

    def cuMemHostAlloc(self, nbytes, flags):
        return OK, self._allocate(nbytes)

    def cuMemHostGetDevicePointer(self, pointer, flags):
        return OK, pointer

    def cuMemFree(self, pointer):
        self.freed.append(self.memory.pop(pointer))
        return (OK,)

    cuMemFreeHost = cuMemFree

    def cuMemHostRegister(self, pointer, nbytes, flags):
        self.registered.add(pointer)
        self.memory[pointer] = (ctypes.c_char * nbytes).from_address(pointer)
        return (OK,)

    def cuMemHostUnregister(self, pointer):
        self.registered.discard(pointer)
        del self.memory[pointer]
        return (OK,)

    def _copy(self, dst: int, src: int, nbytes: int, device: tuple[int, ...]) -> None:
        for address in device:
            self._live(address, nbytes)
        ctypes.memmove(dst, src, nbytes)

    def cuMemcpyHtoD(self, dst, src, nbytes):
        self._copy(dst, src, nbytes, (dst,))
        return (OK,)

    def cuMemcpyHtoDAsync(self, dst, src, nbytes, stream):
        stream.commands.append(lambda: self._copy(dst, src, nbytes, (dst,)))
        return (OK,)

    def cuMemcpyDtoHAsync(self, dst, src, nbytes, stream):
        stream.commands.append(lambda: self._copy(dst, src, nbytes, (src,)))
        return (OK,)

    def cuMemcpyDtoDAsync(self, dst, src, nbytes, stream):
        stream.commands.append(lambda: self._copy(dst, src, nbytes, (dst, src)))
        return (OK,)

    def cuMemsetD8Async(self, dst, byte, nbytes, stream):
        def fill():
            self._live(dst, nbytes)
            ctypes.memset(dst, byte, nbytes)
        stream.commands.append(fill)
        return (OK,)

    # streams and events
    def cuStreamCreate(self, flags):
        return OK, _Stream()

    def cuStreamSynchronize(self, stream):
        stream.run(len(stream.commands))
        return (OK,)

    def cuStreamWaitEvent(self, stream, event, flags):
        other, position = event.stream, event.position  # as recorded when waited for
        stream.commands.append(lambda: other and other.run(position))
        return (OK,)

    def cuEventCreate(self, flags):
        return OK, _Event()

    def cuEventDestroy(self, event):
        return (OK,)

    def cuEventRecord(self, event, stream):
        stream = stream or self.null
        event.stream, event.position = stream, len(stream.commands)
        return (OK,)

    def cuEventSynchronize(self, event):
        if event.stream is not None:
            event.stream.run(event.position)
        return (OK,)

    def cuEventQuery(self, event):
        return (OK if event.ready() else CUresult.CUDA_ERROR_NOT_READY,)

    def cuEventElapsedTime(self, start, end):
        return OK, 0.25 * (end.position - (start.position if start.stream else 0))

    # programs and launches
    def cuModuleLoadData(self, image):
        assert image == b"fake cubin"
        return OK, "module"

    def cuModuleGetFunction(self, module, name):
        return OK, name.decode()

    def cuFuncGetAttribute(self, attribute, function):
        assert attribute == "CU_FUNC_ATTRIBUTE_MAX_THREADS_PER_BLOCK"
        return OK, self.kernel_threads

    def cuLaunchKernel(self, function, gx, gy, gz, bx, by, bz, shared, stream, params,
                       extra):
        kernel, types = KERNELS[function]
        pointers = (ctypes.c_uint64 * len(types)).from_address(params)
        args = [t.from_address(p).value for t, p in zip(types, pointers)]  # copied now
        self.launches.append((function, (gx, gy, gz), (bx, by, bz)))
        stream.commands.append(lambda: kernel(self, *args))
        return (OK,)


def _add(driver, src, dst, n, value):
    """dst[i] = src[i] + value for n bytes (uint8, wrapping)."""
    driver._live(src, n)
    driver._live(dst, n)
    a = np.ctypeslib.as_array((ctypes.c_uint8 * n).from_address(src))
    b = np.ctypeslib.as_array((ctypes.c_uint8 * n).from_address(dst))
    b[:] = a + np.uint8(value)


KERNELS = {"add": (_add, [ctypes.c_uint64, ctypes.c_uint64, ctypes.c_int32,
                          ctypes.c_int32])}


@pytest.fixture
def fake(monkeypatch, tmp_path):
    """The CUDA module on a FakeDriver (kernel files 'compile' to a fake cubin)."""
    driver = FakeDriver()
    driver.folder = tmp_path  # where _kernel_file writes
    monkeypatch.setattr(cuda, "_driver", lambda: driver)
    monkeypatch.setattr(cuda, "_initialized", False)
    monkeypatch.setattr(cuda, "nvrtc_version", lambda: (12, 9))
    monkeypatch.setattr(cuda, "compile_cubin",
                        lambda source, name, arch, options=(): (b"fake cubin", ""))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("CUDA_DEVICE", raising=False)
    return driver


def _context_queue(profile=False):
    context = cuda.create_context()
    return context, cuda.create_queue(context, profile)


def test_the_fake_driver_runs_nothing_before_a_wait(fake):
    """The harness itself: a copy not waited for has not happened."""
    context, queue = _context_queue()
    buffer = cuda.device_buffer(context, 16)
    host = np.arange(16, dtype=np.uint8)
    out = np.zeros(16, np.uint8)
    cuda.copy(queue, buffer, host, blocking=False)
    cuda.copy(queue, out, buffer, blocking=False)
    assert not out.any()
    cuda.finish(queue)
    np.testing.assert_array_equal(out, host)


def test_copies_both_ways_and_between_buffers(fake):
    context, queue = _context_queue()
    a, b = cuda.device_buffer(context, 16), cuda.device_buffer(context, 16)
    host = np.arange(16, dtype=np.uint8)
    cuda.copy(queue, a, host, blocking=False)
    event = cuda.copy(queue, b, a)  # buffer to buffer: never blocking
    assert cuda.is_running(event)
    out = np.zeros(16, np.uint8)
    cuda.copy(queue, out, b)  # blocking: done on return
    np.testing.assert_array_equal(out, host)
    assert not cuda.is_running(event)
    cuda.fill(queue, a, 7, 16)
    cuda.copy(queue, out, a)
    assert (out == 7).all()
    filled = cuda.filled_buffer(context, host[::-1])
    cuda.copy(queue, out, filled)
    np.testing.assert_array_equal(out, host[::-1])
    assert cuda.nbytes(filled) == 16
    with pytest.raises(PipelineError, match="C-contiguous"):
        cuda.copy(queue, a, np.zeros((4, 8), np.uint8)[:, ::2])
    with pytest.raises(PipelineError, match="32 bytes into or out of a buffer of 16"):
        cuda.copy(queue, a, np.zeros(32, np.uint8))
    with pytest.raises(PipelineError, match="two host arrays"):
        cuda.copy(queue, out, host)
    for buffer in (a, b, filled):
        cuda.release(buffer)
    assert not fake.memory


def test_a_copy_not_waited_for_keeps_its_host_array_alive(fake, monkeypatch):
    """A non-blocking copy from a temporary array: the array lives until the copy ran
    (on a real GPU a pinned source is read by DMA after the call returns); the queue's
    ring waits for such a copy before it reuses its event."""
    monkeypatch.setattr(cuda, "EVENT_RING", 2)
    context, queue = _context_queue()
    buffer = cuda.device_buffer(context, 16)
    source = np.full(16, 9, np.uint8)
    alive = weakref.ref(source)
    cuda.copy(queue, buffer, source, blocking=False)
    del source
    gc.collect()
    assert alive() is not None
    stream = queue.handle
    cuda.fill(queue, cuda.device_buffer(context, 4), 0, 4)
    assert stream.done == 0
    cuda.fill(queue, cuda.device_buffer(context, 4), 0, 4)  # reuses the copy's event
    assert stream.done >= 1  # the copy ran before its event was reused
    gc.collect()
    assert alive() is None
    out = np.zeros(16, np.uint8)
    cuda.copy(queue, out, buffer)
    assert (out == 9).all()


def test_a_non_blocking_upload_does_not_overwrite_its_pinned_array_too_early(fake):
    """CpuToGpuAdapter(blocking=False, staging='pinned'), one buffer set: the second
    frame waits for the first frame's copy before it writes the pinned array, so what
    the device read for frame 1 is frame 1."""
    context, queue = _context_queue()
    up = cuda.CpuToGpuAdapter(context, queue, nbytes=16, blocking=False, staging="pinned")
    up.initialize(Size(4, 4, 1), np.uint8)
    snapshot = cuda.device_buffer(context, 16)
    first, second = np.full((4, 4), 1, np.uint8), np.full((4, 4), 2, np.uint8)
    cuda.copy(queue, snapshot, up.transfer(first))  # what a kernel would read of frame 1
    up.transfer(second)
    out = np.zeros(16, np.uint8)
    cuda.copy(queue, out, snapshot)
    assert (out == 1).all()
    up.free_memory()


class _Add(cuda.KernelComponent):
    """A component of the fake driver's 'add' kernel: dst = src + value."""

    function = "add"
    inputs = (("src", np.uint8),)
    outputs = (("dst", np.uint8),)

    def output_sizes(self, src):
        return [Size(*src)]


@pytest.mark.parametrize("staging", ["pageable", "pinned"])
def test_a_kernel_component_between_adapters(fake, staging):
    """The neutral KernelComponent on the CUDA interface: arguments packed once per set,
    the input pointer filled in per frame, grid = global / block (rounded up)."""
    context, queue = _context_queue()
    program = cuda.build_program(context, _kernel_file(fake), "adder (Add)")

    up = cuda.CpuToGpuAdapter(context, queue, 12, blocking=False, staging=staging)
    add = _Add(context, queue, program, buffer_sets=2)
    down = cuda.GpuToCpuAdapter(context, queue, 12, staging=staging)
    size = up.initialize(Size(3, 4, 1), np.uint8)
    down.initialize(add.initialize(size), np.uint8)
    add.config_gpu(1, (2, 2, 1), (5, 3, 1), ["src", "dst", np.int32(12), np.int32(5)])
    for frame in range(4):
        host = np.arange(12, dtype=np.uint8).reshape(3, 4) + frame
        got = down.transfer(add.execute(up.transfer(host)))
        np.testing.assert_array_equal(got, host + 5)
        assert not got.flags.writeable  # as OpenCL's: every reader gets the same frame
    assert fake.launches[-1] == ("add", (3, 2, 1), (2, 2, 1))
    for part in (down, add, up):
        part.free_memory()
    del got  # the last frame, a view of the adapter's host memory: its last user
    assert not fake.memory


def test_a_standard_kernel_component_copies_its_own_data(fake):
    context, queue = _context_queue(profile=True)
    program = cuda.build_program(context, _kernel_file(fake), "adder (Add)")

    add = _Add(context, queue, program, copies_own_data=True)
    add.initialize(Size(2, 3, 1))
    add.config_gpu(1, (1, 1, 1), (6, 1, 1), ["src", "dst", np.int32(6), np.int32(250)])
    host = np.arange(6, dtype=np.uint8).reshape(2, 3)
    np.testing.assert_array_equal(add.execute(host), host + np.uint8(250))
    add.free_memory()
    event = cuda.copy(queue, cuda.device_buffer(context, 6), host)
    assert cuda.event_seconds(event) > 0  # a profiled queue's events have times
    with pytest.raises(PipelineError, match="without profile"):
        cuda.event_seconds(cuda.copy(cuda.create_queue(context),
                                     cuda.device_buffer(context, 6), host))


def test_a_block_too_big_for_the_kernel_is_the_neutral_error(fake):
    fake.kernel_threads = 256
    context, queue = _context_queue()
    program = cuda.build_program(context, _kernel_file(fake), "adder (Add)")
    kernel = cuda.kernel(program, "add")
    with pytest.raises(PipelineError, match=r"adder: GPU settings \(32, 16, 1\) \(512 "
                                            r"threads\) do not fit device 'Fake Orin'"):
        cuda.check_work_group(kernel, cuda.device_of(queue), (32, 16, 1), "adder")
    assert cuda.kernel_limits(kernel, cuda.device_of(queue)).work_group_size == 256
    with pytest.raises(PipelineError, match="before set_args"):
        cuda.launch(queue, kernel, (4, 1, 1), (4, 1, 1))


def test_a_zero_copy_read_waits_for_its_own_lane_and_the_others(fake):
    """ZeroCopyGpuToCpuAdapter given another lane's event: the kernel that wrote the
    buffer on the adapter's own lane is waited for too (it was not: the host read the
    mapped memory before the kernel ran)."""
    context, lane = _context_queue()
    other = cuda.side_queue(lane)
    program = cuda.build_program(context, _kernel_file(fake), "adder (Add)")
    kernel = cuda.kernel(program, "add")
    src = cuda.device_buffer(context, 8)
    dst = cuda.device_buffer(context, 8, host_visible=True)
    cuda.copy(lane, src, np.full(8, 40, np.uint8), blocking=False)
    cuda.set_args(kernel, src, dst, np.int32(8), np.int32(2))
    cuda.launch(lane, kernel, (8, 1, 1), (8, 1, 1))
    elsewhere = cuda.fill(other, cuda.device_buffer(context, 4), 0, 4)
    down = cuda.ZeroCopyGpuToCpuAdapter(context, lane, 8)
    down.initialize(Size(1, 8, 1), np.uint8)
    view = down.transfer(dst, wait_for=[elsewhere])
    assert (view == 42).all()
    assert not view.flags.writeable
    down.unmap()
    down.free_memory()


def test_map_and_unmap_of_device_memory(fake):
    context, queue = _context_queue()
    buffer = cuda.device_buffer(context, 6)
    cuda.copy(queue, buffer, np.arange(6, dtype=np.uint8), blocking=False)
    view, event = cuda.map(queue, buffer, (2, 3), np.uint8, "read_write")
    np.testing.assert_array_equal(view.ravel(), np.arange(6))
    view += 10
    cuda.wait([cuda.unmap(queue, view)])
    out = np.zeros(6, np.uint8)
    cuda.copy(queue, out, buffer)
    np.testing.assert_array_equal(out, np.arange(6) + 10)
    view, _ = cuda.map(queue, buffer, (6,), np.uint8, "read")
    view[:] = 0  # mapped for reading: not copied back
    cuda.unmap(queue, view)
    cuda.copy(queue, out, buffer)
    np.testing.assert_array_equal(out, np.arange(6) + 10)


def test_host_and_pinned_buffers(fake):
    context, queue = _context_queue()
    array = np.arange(8, dtype=np.uint8)
    registered = cuda.host_buffer(context, array)
    assert registered.ptr == array.ctypes.data and registered.ptr in fake.registered
    out = cuda.device_buffer(context, 8)
    cuda.copy(queue, out, registered)
    check = np.zeros(8, np.uint8)
    cuda.copy(queue, check, out)
    np.testing.assert_array_equal(check, array)
    cuda.release(registered)
    assert not fake.registered
    pinned = [cuda.pinned(context, queue, (2, 2), np.uint16)]
    assert pinned[0][1].shape == (2, 2) and pinned[0][1].dtype == np.uint16
    cuda.release_pinned(queue, pinned)


def test_a_frame_kept_past_free_memory_keeps_its_pinned_memory(fake):
    """FrameSink keeps the last frame, a view of the GPU-to-CPU adapter's pinned array,
    and bench reads it after the program freed everything: the memory goes with the
    last view, not before."""
    context, queue = _context_queue()
    buffer = cuda.filled_buffer(context, np.full((2, 4), 5, np.uint8))
    down = cuda.GpuToCpuAdapter(context, queue, 8, staging="pinned")
    down.initialize(Size(2, 4, 1), np.uint8)
    kept = down.transfer(buffer)
    address = kept.ctypes.data
    down.free_memory()
    cuda.release(buffer)
    assert address in fake.memory  # still allocated: the kept frame is its last user
    assert (kept == 5).all()
    del kept
    gc.collect()
    assert address not in fake.memory and not fake.memory
    mapped = cuda.device_buffer(context, 8, host_visible=True)
    view = mapped.view((8,), np.uint8)
    cuda.release(mapped)
    assert view.ctypes.data in fake.memory
    del view
    assert not fake.memory


def _mirror_kernels(monkeypatch) -> None:
    """mirror_chain's kernels on the fake driver: each mirror, and the five fused."""
    import functools

    for name, times in (("mirror1_to_mirror5", 5), *((f"mirror{i}", 1) for i in range(1, 6))):
        monkeypatch.setitem(KERNELS, name, (functools.partial(_flip, times=times),
                                            [ctypes.c_uint64, ctypes.c_uint64,
                                             ctypes.c_int32]))


def _flip(driver, src, dst, tile, rows=864, row_bytes=1152 * 3, times=1):
    """VerticalMirror `times` over (a fused chain) on mirror_chain's frames."""
    for address in (src, dst):
        driver._live(address, rows * row_bytes)
    a = np.ctypeslib.as_array((ctypes.c_uint8 * (rows * row_bytes)).from_address(src))
    b = np.ctypeslib.as_array((ctypes.c_uint8 * (rows * row_bytes)).from_address(dst))
    b.reshape(rows, row_bytes)[:] = a.reshape(rows, row_bytes)[::(-1) ** times]


@pytest.mark.parametrize("options", [
    {}, {"fusion": "off"}, {"mode": "standard"}, {"zero_copy": "on"},
    {"frames_in_flight": 2}, {"execution": "sequential"}, {"staging": "pageable"}],
    ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "default")
def test_the_generated_cuda_program_runs_on_the_fake_driver(fake, options, tmp_path,
                                                            monkeypatch):
    """mirror_chain built with --backend cuda, run for 3 frames on the fake driver (its
    kernels flip as VerticalMirror does): the sink's last frame is the photograph
    flipped, and once the program's result is dropped every allocation is freed."""
    from gpucompgen.build import compile_model, write
    from gpucompgen.library.still_image import still_frame
    from gpucompgen.runtime import Monitor, load_module

    _mirror_kernels(monkeypatch)
    out = tmp_path / "out"
    write(compile_model(ROOT / "models" / "mirror_chain.yaml", out, backend="cuda",
                        **options), out)
    module = load_module(out / "mirror_chain.py", f"fake_cuda_{len(options)}")
    result = module.run(frames=3, monitor=Monitor(progress=False))
    sink = result.components["sink"]
    assert result.frames == 3
    np.testing.assert_array_equal(sink.last, still_frame(1152, 864)[::-1])
    del result, sink
    gc.collect()
    assert not fake.memory and not fake.registered


def test_tune_measures_on_the_cuda_device_the_model_names(fake, tmp_path, monkeypatch):
    """platform.backend: cuda and no --backend: tune times every mirror's kernel and the
    group the fuse pass chose on the (fake) CUDA device, through the device interface."""
    from gpucompgen.tune import tune

    _mirror_kernels(monkeypatch)
    model = tmp_path / "mirror_chain.yaml"
    model.write_text((ROOT / "models" / "mirror_chain.yaml").read_text()
                     + "platform:\n  backend: cuda\n")
    groups: list = []
    text, rows = tune(model, frames=2, groups_out=groups)
    assert "on the CUDA device" in text and 'device: "Fake Orin"' in text
    assert [r[0] for r in rows] == [f"mirror{i}" for i in range(1, 6)]
    assert all(gpu_us > 0 for *_, gpu_us in rows)
    assert [g[1] for g in groups] == [[f"mirror{i}" for i in range(1, 6)]]
    assert any(launch[0] == "mirror1_to_mirror5" for launch in fake.launches)
    gc.collect()
    assert not fake.memory


def test_bench_runs_every_variant_on_the_cuda_device(fake, tmp_path, monkeypatch):
    """gpucompgen bench --backend cuda on the (fake) CUDA device: the generated chains
    (standard, GPU-aware, zero-copy, fused), the hand-written loop and the copy bound, each
    output checked against the flipped image, the table naming the CUDA device."""
    import functools

    from gpucompgen.cli import main

    for name, times in (("vertical_mirror", 1), ("mirror1", 1), ("mirror2", 1),
                        ("mirror1_mirror2", 2)):  # a frame of 512x384
        flip = functools.partial(_flip, rows=384, row_bytes=512 * 3, times=times)
        monkeypatch.setitem(KERNELS, name, (flip, [ctypes.c_uint64, ctypes.c_uint64,
                                                   ctypes.c_int32]))
    monkeypatch.chdir(tmp_path)
    # 512x384: the copy bound's ring of 64 MiB is 114 buffers (at 64x48 it is 7,282)
    assert main(["bench", "--backend", "cuda", "--sizes", "512x384", "--lengths", "2",
                 "--frames", "4", "--no-opencv", "-o", "out"]) == 0
    table = (tmp_path / "out" / "bench.csv").read_text()
    for variant in ("standard", "gpu-aware", "zero-copy", "fused", "hand-written", "bound"):
        assert f",2,{variant}," in table
    assert any(launch[0] == "mirror1_mirror2" for launch in fake.launches)


def _kernel_file(fake) -> Path:
    """A kernel file for build_program (the fake's compile_cubin does not read it)."""
    path = fake.folder / "add.cu"
    path.write_text('extern "C" __global__ void add() {}\n')
    return path


# --- what tune and bench say without a driver or a device -----------------------------

@pytest.mark.parametrize(("driver", "said"), [
    (FakeDriver(init=CUresult.CUDA_ERROR_NO_DEVICE), "no CUDA device found"),
    (FakeDriver(devices=0), "no CUDA device found"),
    (None, "no NVIDIA driver (libcuda) found")])
@pytest.mark.parametrize("command", ["tune", "bench"])
def test_without_a_driver_or_device_tune_and_bench_say_so(command, driver, said, monkeypatch,
                                                           tmp_path, capsys):
    from gpucompgen.cli import main

    class NoLibcuda(FakeDriver):
        def cuInit(self, flags):
            raise RuntimeError('"cuda" is an NVIDIA driver library and can only be found')

    monkeypatch.setattr(cuda, "_driver", lambda: driver or NoLibcuda())
    monkeypatch.setattr(cuda, "_initialized", False)
    monkeypatch.chdir(tmp_path)
    argv = (["tune", str(ROOT / "models" / "mirror_chain.yaml"), "-o", "p.yaml"]
            if command == "tune" else
            ["bench", "--sizes", "64x48", "--lengths", "1", "--frames", "1", "--no-opencv"])
    assert main([*argv, "--backend", "cuda"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"gpucompgen {command}: error: {said}")
    assert "'gpucompgen devices' lists the devices" in err[0]
    assert not list(tmp_path.iterdir())
