"""Shared test setup: pin the OpenCL device, give each xdist worker its own PoCL cache.

Without an OpenCL device, OpenCL tests skip on a developer's machine but FAIL when
CI=true: CI installs PoCL, so a missing device there is a broken install, not a skip.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")

# Every build in the tests (also in subprocesses) verifies the IR after every pass.
os.environ["GPUCOMPGEN_VERIFY"] = "1"
# PoCL's worker threads unpinned (the runtime pins them: runtime/opencl.py): the tests time
# nothing, and two test workers, each with PoCL threads pinned to the same cores, waited
# on each other (a CI rehearsal took 16:15 pinned, with 80 worker-s of tests less)
os.environ.setdefault("POCL_AFFINITY", "0")

_worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
os.environ.setdefault("POCL_CACHE_DIR", str(Path(os.environ.get("TMPDIR", "/tmp"))
                                             / f"gpucompgen-pocl-cache-{os.getuid()}-{_worker}"))


def _pin_device() -> str | None:
    """Pin PYOPENCL_CTX (inherited by generated programs run as subprocesses).

    Only a device that compiles a kernel counts: a machine can have a PoCL whose LLVM does
    not know the host CPU beside one that works, and the order of platforms is the ICD
    loader's. PoCL is preferred, so a developer's GPU does not change what the tests see.
    """
    if os.environ.get("PYOPENCL_CTX"):
        return None
    try:
        from gpucompgen.runtime import survey_devices, unusable_message
    except ImportError as exc:  # pyopencl or numpy missing
        return f"no OpenCL: {exc}"
    statuses = survey_devices()
    usable = [s for s in statuses if s.problem is None]
    if not usable:
        return unusable_message(statuses)
    pocl = [s for s in usable if "portable" in s.device.platform.name.lower()]
    os.environ["PYOPENCL_CTX"] = (pocl or usable)[0].ctx
    return None


_NO_DEVICE = _pin_device()


def opencv_fuses_multiply_adds() -> bool:
    """OpenCV's AVX2 code (with FMA3) runs here: its float sums fuse each multiply-add
    (Filter2D's, RgbToGray's float32), as the generated kernels do."""
    import cv2

    return "*AVX2" in cv2.getCPUFeaturesLine().split() and cv2.checkHardwareSupport(12)


def require_opencl():
    if _NO_DEVICE:
        if IN_CI:
            pytest.fail(f"CI=true but {_NO_DEVICE}")
        pytest.skip(_NO_DEVICE)


@pytest.fixture(scope="session")
def cl_context():
    require_opencl()
    import pyopencl as cl

    return cl.create_some_context(interactive=False)


@pytest.fixture(scope="session")
def cl_queue(cl_context):
    import pyopencl as cl

    return cl.CommandQueue(cl_context)


def load_generated(path: Path, name: str):
    """Import a generated program as a module (a fresh one each time)."""
    from gpucompgen.runtime import load_module

    return load_module(path, name)


@pytest.fixture
def build(tmp_path):
    """Build a model into a temporary folder; returns (result, out_dir)."""
    from gpucompgen.build import compile_model, write

    def _build(model: Path, mode: str = "gpu-aware", device: str | None = None):
        out = tmp_path / f"out-{mode}"
        result = compile_model(Path(model), out, mode=mode, device=device)
        write(result, out)
        return result, out

    return _build


_GENERATED: dict = {}  # (type, port shapes) -> (program, group): sizes are constants


@pytest.fixture(scope="session")
def run_alone(cl_context, cl_queue):
    """run(type_name, image, params): the kernel the generator writes for a library type's
    lone component, run on one frame (run_generated), its output of the frame's shape."""
    require_opencl()
    from gpucompgen.model import library_types

    types = library_types()

    def run(type_name, image, params):
        return run_generated(cl_context, cl_queue, types[type_name], params, [image],
                             image.shape)
    return run


def run_generated(context, queue, ctype, params: dict, arrays, out_shape: tuple,
                  settings=(16, 16, 16, 1)):
    """Run the kernel the generator writes for a component of fusable type ctype alone
    (what a lone component runs: a group of one) on arrays, with any settings (tile,
    block_x, block_y, block_z): work-group g computes output rows [g * tile, g * tile +
    tile), its block_x x block_y threads sharing them.  The output buffer starts with junk
    (0xA5), so an element the kernel misses shows.  Returns the output array."""
    import numpy as np
    import pyopencl as cl

    from gpucompgen.kernelgen.fused import (
        group_kernel,
        group_of_one,
        kernel_name,
        launch_arguments,
    )
    from gpucompgen.model import DTYPES

    if ctype.generic:  # the ports a component fed these arrays gets (resolve-types)
        first = np.asarray(arrays[0])
        ctype = ctype.specialized(first.dtype.name, first.shape[2] if first.ndim == 3 else 1,
                                  params)
    (oname, oport), = ctype.outputs.items()
    shapes = {p: a.shape[:2] for p, a in zip(ctype.inputs, arrays, strict=True)}
    shapes[oname] = tuple(out_shape[:2])
    # sizes and parameters are constants of the kernel: one build for each (and for each
    # element type and channel count of a generic type's ports)
    key = (ctype.name, tuple(sorted(shapes.items())), tuple(sorted(params.items())),
           tuple((p.dtype, p.channels) for p in ctype.inputs.values()))
    if key not in _GENERATED:
        group = group_of_one(ctype, params, shapes)
        _GENERATED[key] = cl.Program(context, group_kernel(group, "test")).build(), group
    program, group = _GENERATED[key]
    tile, bx, by, bz = settings
    mf = cl.mem_flags
    buffers = {p: cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                            hostbuf=np.ascontiguousarray(a))
               for p, a in zip(ctype.inputs, arrays, strict=True)}
    result = np.empty(out_shape, np.dtype(DTYPES[oport.dtype][0]))
    out = cl.Buffer(context, mf.READ_WRITE, max(result.nbytes, 1))
    cl.enqueue_fill_buffer(queue, out, np.uint8(0xA5), 0, max(result.nbytes, 1))
    kernel = cl.Kernel(program, kernel_name(group))
    kernel.set_args(*launch_arguments(group, buffers, out, tile))
    rows = -(-shapes[oname][0] // tile)
    cl.enqueue_nd_range_kernel(queue, kernel, (bx, rows * by, bz), (bx, by, bz))
    cl.enqueue_copy(queue, result, out)
    queue.finish()
    for b in [*buffers.values(), out]:
        b.release()
    return result


# Collectors for tests that build models, keeping a copy of every frame: Keep takes any
# element type and channels (a generic port, resolved from what feeds it); the types of
# one element type and channel count each (Keep3, Keep1, KeepS3, KeepS1) came first, and
# KeepI4, KeepI5 take the int32 tables of things found (features.yaml).
KEEP_TYPES = "component_types:\n" + "".join(f"""
  {name}:
    kind: standard
    description: Keeps a copy of every frame it gets.
    inputs:
      image: {{memory: cpu, dtype: {dtype}, channels: {channels}}}
    python: {{file: keep.py, class: Keep}}
""" for name, dtype, channels in (("Keep3", "uint8", 3), ("Keep1", "uint8", 1),
                                  ("KeepS3", "int16", 3), ("KeepS1", "int16", 1),
                                  # tables of things found (features.yaml): int32 rows
                                  ("KeepI4", "int32", 4), ("KeepI5", "int32", 5),
                                  ("Keep", "any", "any")))
KEEP_PY = """import numpy as np


class Keep:
    def __init__(self):
        self.frames = []

    def initialize(self, image):
        self.size = image

    def execute(self, image):
        self.frames.append(np.array(image, copy=True))

    def free_memory(self):
        pass
"""


def write_keep_types(folder: Path) -> None:
    """keep.yaml and keep.py in folder: a model there lists 'types: [keep.yaml]'."""
    (folder / "keep.yaml").write_text(KEEP_TYPES)
    (folder / "keep.py").write_text(KEEP_PY)


def keep_type_for(port) -> str:
    """The Keep type that takes what a port (a PortDecl) carries: Keep, for a generic one."""
    if port.generic:
        return "Keep"
    prefix = {"int16": "KeepS", "int32": "KeepI"}.get(port.dtype, "Keep")
    return prefix + str(port.channels)
