"""The CUDA backend (docs/cuda.md).

Without a GPU (CI): every .cu file a build writes (library kernels, single-operation and
fused-group kernels, for every model in models/ and every variant) compiles with NVRTC
from PyPI: the CUDA 12 NVRTC JetPack 6 boards have, for sm_72 (Xavier) and sm_87 (Orin),
and the current one for sm_87 and sm_90 (H100).  No driver is needed: NVRTC is loaded
through ctypes (gpucompgen.backend.cuda.nvrtc), both majors in one process.  The CUDA
program is the OpenCL program with only its runtime and kernel file names changed, and a
kernel with OpenCL-only code is an error that says what to write.

With an NVIDIA GPU and its driver (skipped otherwise, also under CI=true): every library
operation through the CUDA runtime equals the CPU form, the numpy reference and OpenCV on
photographs, and every model's program run with CUDA gives the OpenCL program's frames.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
from conftest import ROOT, require_opencl

from gpucompgen.backend.cuda import nvrtc, prelude
from gpucompgen.build import compile_model, write
from gpucompgen.errors import GpucompgenError

MODELS = sorted((ROOT / "models").glob("*.yaml"))
LIBRARY_KERNELS = sorted((ROOT / "gpucompgen" / "library").glob("*.cl"))
# (NVRTC major, architecture): JetPack 6's CUDA 12 for Xavier and Orin, the current
# CUDA for Orin and Hopper
TARGETS = [(12, 72), (12, 87), (13, 87), (13, 90)]
VARIANTS = {"default": {}, "standard": {"mode": "standard"},
            "zero-copy": {"zero_copy": "on"}, "sequential": {"execution": "sequential"},
            "unfused": {"fusion": "off"}, "in-flight": {"frames_in_flight": 2}}


def nvrtc_of(major: int) -> nvrtc.Nvrtc:
    found = nvrtc.available().get(major)
    if found is None:
        why = (f"no NVRTC {major} (pip install "
               f"{'nvidia-cuda-nvrtc-cu12' if major == 12 else 'nvidia-cuda-nvrtc'})")
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI=true but {why}")
        pytest.skip(why)
    return found


@pytest.fixture(scope="module")
def cuda_builds(tmp_path_factory):
    """Every model in every variant, built with --backend cuda: {(model, variant): dir}."""
    out = {}
    for model in MODELS:
        for variant, options in VARIANTS.items():
            folder = tmp_path_factory.mktemp(f"{model.stem}-{variant}")
            write(compile_model(model, folder, backend="cuda", **options), folder)
            out[(model.stem, variant)] = folder
    return out


def _errors(compiled: nvrtc.Compiled) -> str:
    return compiled.log if not compiled.ok else ""


@pytest.mark.parametrize(("major", "arch"), TARGETS, ids=lambda v: str(v))
def test_every_library_kernel_compiles(major, arch):
    lib = nvrtc_of(major)
    for path in LIBRARY_KERNELS:
        compiled = lib.compile(prelude.cuda_source(path.read_text()), path.stem + ".cu", arch)
        assert compiled.ok, f"{path.name} for sm_{arch}:\n{compiled.log}"
        assert compiled.cubin[:4] == b"\x7fELF"


@pytest.mark.parametrize(("major", "arch"), TARGETS, ids=lambda v: str(v))
def test_every_generated_kernel_compiles(major, arch, cuda_builds):
    """Every .cu file of every example model's CUDA build in every variant compiles; a
    kernel the variants share (most: the variants differ in the program, not the
    kernels) is compiled once."""
    lib = nvrtc_of(major)
    files, distinct = 0, {}
    for (model, variant), folder in sorted(cuda_builds.items()):
        assert not list(folder.rglob("*.cl")), "a CUDA build writes no .cl files"
        for path in sorted(folder.rglob("*.cu")):
            distinct.setdefault(path.read_text(), (f"{model} ({variant})", path.name))
            files += 1
    assert files >= len(MODELS) * len(VARIANTS)
    for text, (build, name) in distinct.items():
        compiled = lib.compile(text, name, arch)
        assert compiled.ok, f"{build} {name} for sm_{arch}:\n{compiled.log}"


def library_operation_kernels() -> dict[str, str]:
    """The kernel the generator writes for each fusable library type alone (a group of one,
    what a lone component runs), with its default parameters on a 37x53 frame and on
    a one-pixel frame, as the CUDA backend writes it: {type and size: .cu text}."""
    from gpucompgen.kernelgen.fused import group_kernel, group_of_one
    from gpucompgen.model import library_types

    out = {}
    for name, ctype in sorted(library_types().items()):
        if ctype.fusable is None:
            continue
        params = {p: d.default for p, d in ctype.params.items()}
        for h, w in ((37, 53), (1, 1)):
            shapes = dict.fromkeys([*ctype.inputs, *ctype.outputs], (h, w))
            text = group_kernel(group_of_one(ctype, params, shapes), "test")
            out[f"{name}-{h}x{w}"] = prelude.cuda_source(text)
    return out


@pytest.mark.parametrize(("major", "arch"), TARGETS, ids=lambda v: str(v))
def test_every_library_operation_kernel_compiles(major, arch):
    """Every fusable library type's generated kernel, not only those the example models
    use, compiles for every target: a type no model uses still runs on a Jetson."""
    lib = nvrtc_of(major)
    kernels = library_operation_kernels()
    assert len(kernels) >= 2 * 20
    for key, text in kernels.items():
        compiled = lib.compile(text, key + ".cu", arch)
        assert compiled.ok, f"{key} for sm_{arch}:\n{compiled.log}"
        assert compiled.cubin[:4] == b"\x7fELF"


def test_the_cuda_program_is_the_opencl_program_on_the_cuda_runtime(tmp_path):
    """Line for line the same program (every transfer, launch and size) but the runtime
    import, the device named in the docstring and the kernel file names."""
    for model in MODELS:
        for options in VARIANTS.values():
            opencl = compile_model(model, tmp_path / "cl", **options).files
            cuda = compile_model(model, tmp_path / "cu", backend="cuda", **options).files
            assert [str(f.path).replace(".cl", ".cu") for f in opencl] == \
                [str(f.path) for f in cuda]
            # the runtime import moves to where an import sorter puts it; pyopencl's one
            # use becomes the runtime's
            a = [line for line in opencl[0].text.splitlines()
                 if line not in ("import pyopencl as cl", "from gpucompgen import runtime")]
            b = cuda[0].text.splitlines()
            assert "from gpucompgen import runtime" in opencl[0].text.splitlines()
            assert b.count("from gpucompgen.runtime import cuda as runtime") == 1
            b.remove("from gpucompgen.runtime import cuda as runtime")
            assert len(a) == len(b)
            changed = [(x, y) for x, y in zip(a, b) if x != y]
            for x, y in changed:
                assert re.sub(r"\.cl\b", ".cu", x) == y or "runtime" in y \
                    or "OpenCL" in x or "PYOPENCL_CTX" in x, (x, y)
            assert "pyopencl" not in cuda[0].text and "PYOPENCL" not in cuda[0].text
            for f in cuda[1:]:
                if f.path.suffix == ".cu":
                    assert f.text.startswith("// Code generated by gpucompgen from ")
                    assert prelude.PRELUDE in f.text


@pytest.mark.parametrize(("code", "token", "what"), [
    ("__local int tile[64];", "__local", "local (shared) memory"),
    ("barrier(CLK_LOCAL_MEM_FENCE);", "barrier", "work-group barriers"),
    ("float4 v = read_imagef(img, s, p);", "read_imagef", "OpenCL images and samplers"),
    ("atomic_add(count, 1);", "atomic_add", "OpenCL atomics"),
    ("vstore8(v, 0, out);", "vstore8", "8- and 16-wide vector loads and stores"),
    ("int x = convert_int_rtz(f);", "convert_int_rtz", "OpenCL conversion functions"),
    ("out[i] = v.xyz.x;", ".xyz", "vector swizzles"),
    ("out[i] = v.s0;", ".s0", "vector swizzles"),
    ("#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable", "#pragma",
     "OpenCL extensions"),
])
def test_opencl_only_code_is_found_with_its_place(code, token, what):
    source = f"// a comment with barrier( and __local words\n__kernel void k()\n{{\n    {code}\n}}\n"
    found = prelude.unportable(source)
    assert [(u.line, u.column, u.what) for u in found][:1] == \
        [(4, 5 + code.index(token), what)]
    assert found[0].hint


@pytest.mark.parametrize("code", [
    "out[i] = convert_uchar_sat_rte(f);", "uchar3 p = (uchar3)(1, 2, 3); out[i] = p.x;",
    "vstore3((uchar3)(v), i, out);", "int local_size = 3; out[i] = local_size;",
    "#pragma OPENCL EXTENSION cl_khr_fp64 : enable",
])
def test_the_portable_subset_is_not_reported(code):
    assert prelude.unportable(f"__kernel void k(__global uchar *out)\n{{\n{code}\n}}\n") == []


def test_a_user_type_with_opencl_only_code_is_a_clear_error(tmp_path):
    """The user model's kernel with a barrier: an error at the kernel's line and column
    that says what to write, nothing written."""
    import shutil

    src = ROOT / "tests" / "data" / "user_model"
    dst = tmp_path / "user_model"
    shutil.copytree(src, dst)
    kernel = dst / "brighten.cl"
    text = kernel.read_text()
    body = text.index("{", text.index("__kernel")) + 1
    kernel.write_text(text[:body] + "\n    barrier(CLK_GLOBAL_MEM_FENCE);" + text[body:])
    line = kernel.read_text()[:body].count("\n") + 2
    with pytest.raises(GpucompgenError) as info:
        compile_model(dst / "bright.yaml", tmp_path / "out", backend="cuda")
    (d,) = info.value.errors
    assert (Path_name(d.file), d.line, d.col) == ("brighten.cl", line, 5)
    assert "barrier" in d.message and "OpenCL-only" in d.message
    assert "do not wait for each other" in d.hint
    assert not (tmp_path / "out").exists()
    compile_model(dst / "bright.yaml", tmp_path / "out")  # OpenCL still builds it


def test_platform_backend_in_the_model_and_its_override(tmp_path):
    model = tmp_path / "m.yaml"
    text = (ROOT / "models" / "mirror_chain.yaml").read_text()
    model.write_text(text.replace("\ncomponents:", "\nplatform: {backend: cuda}\ncomponents:"))
    files = compile_model(model, tmp_path / "out").files
    assert [f.path.suffix for f in files[1:]] == [".cu"]
    files = compile_model(model, tmp_path / "out", backend="opencl").files
    assert [f.path.suffix for f in files[1:]] == [".cl"]
    model.write_text(text.replace("\ncomponents:", "\nplatform: {backend: cdua}\ncomponents:"))
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "out")
    (d,) = info.value.errors
    assert d.line > 0 and "platform.backend must be one of opencl, cuda" in d.message
    assert "cuda" in d.hint


def Path_name(file: str) -> str:
    return file.replace("\\", "/").rsplit("/", 1)[-1]


# --- with an NVIDIA GPU ----------------------------------------------------------------

def _cuda_device():
    try:
        from gpucompgen.runtime import cuda
    except ImportError as exc:
        return None, str(exc)
    devices = cuda.survey_devices()
    if not any(problem is None for _, _, problem in devices):
        return None, "no usable CUDA device (NVIDIA driver and cuda-python)"
    return cuda, ""


@pytest.fixture(scope="module")
def cuda_runtime():
    runtime, why = _cuda_device()
    if runtime is None:
        pytest.skip(why)
    return runtime


class CudaKernels:
    """A library type's kernel as a .cu file, launched through the CUDA runtime with the
    same arguments and settings as test_imgproc.Kernels launches the OpenCL one."""

    def __init__(self, cuda, tmp_path):
        self.cuda, self.tmp = cuda, tmp_path
        self.context = cuda.create_context()
        self.queue = cuda.create_queue(self.context)
        self.programs = {}

    def run(self, type_name, arrays, params, setting=(16, 16, 16)):
        """The type's kernel on arrays: the generated one of a fusable type (what a lone
        component runs), else its hand-written kernel (Resize, Crop)."""
        from test_imgproc import imgproc_types

        ctype = imgproc_types()[type_name]
        if ctype.fusable is not None:
            return self._generated(ctype, arrays, params, setting)
        return self._hand(ctype, arrays, params, setting)

    def _one_shot(self, component, inputs: dict, shape, dtype, channels):
        """Upload inputs, run component once, download its output; free everything."""
        cuda = self.cuda
        uploads = []
        for array in inputs.values():
            size = cuda.Size(array.shape[0], array.shape[1],
                             array.shape[2] if array.ndim == 3 else 1)
            adapter = cuda.CpuToGpuAdapter(self.context, self.queue, array.nbytes)
            adapter.initialize(size, array.dtype)
            uploads.append(adapter)
        down = cuda.GpuToCpuAdapter(self.context, self.queue,
                                    int(np.prod(shape)) * dtype.itemsize)
        down.initialize(cuda.Size(shape[0], shape[1], channels), dtype)
        buffers = [a.transfer(np.ascontiguousarray(x)) for a, x in zip(uploads, inputs.values())]
        result = down.transfer(component.execute(*buffers)).reshape(shape).copy()
        for part in (*uploads, component, down):
            part.free_memory()
        return result

    def _generated(self, ctype, arrays, params, setting):
        from gpucompgen.kernelgen import fused
        from gpucompgen.model import DTYPES

        cuda = self.cuda
        (oname, oport), = ctype.outputs.items()
        shapes = {p: a.shape[:2] for p, a in zip(ctype.inputs, arrays, strict=True)}
        shapes[oname] = shapes[next(iter(ctype.inputs))]
        group = fused.group_of_one(ctype, params, shapes)
        cu = self.tmp / f"{ctype.name}-{len(self.programs)}.cu"
        cu.write_text(prelude.cuda_source(fused.group_kernel(group, "test")))
        program = cuda.build_program(self.context, cu, ctype.name)
        self.programs[cu] = program
        ports = {p: f"m_{p}" for p in ctype.inputs}
        tile, bx, by = setting
        global_size, local_size = fused.launch_geometry(group, tile, bx, by)
        arguments = fused.launch_arguments(group, ports, oname, tile)
        dtype = np.dtype(DTYPES[oport.dtype][0])
        shape = shapes[oname] + ((oport.channels,) if oport.channels > 1 else ())

        class One(cuda.KernelComponent):
            function = fused.kernel_name(group)
            inputs = tuple((ports[p], np.dtype(DTYPES[d.dtype][0])) for p, d in
                           ctype.inputs.items())
            outputs = ((oname, dtype),)

            def output_sizes(self, *ins):
                return [cuda.Size(shape[0], shape[1], oport.channels)]

        component = One(self.context, self.queue, program)
        component.initialize(*[cuda.Size(1, 1, 1) for _ in arrays])
        component.config_gpu(tile, local_size, global_size, arguments)
        return self._one_shot(component, dict(zip(ctype.inputs, arrays)), shape, dtype,
                              oport.channels)

    def _hand(self, ctype, arrays, params, setting):
        from gpucompgen import sizeexpr
        from gpucompgen.c_convention import kernel_parameters
        from gpucompgen.model import DTYPES

        cuda = self.cuda
        path = ctype.kernel_file
        if path not in self.programs:
            cu = self.tmp / (path.stem + ".cu")
            cu.write_text(prelude.cuda_source(path.read_text()))
            self.programs[path] = cuda.build_program(self.context, cu, ctype.name)
        inputs = dict(zip(ctype.inputs, arrays))
        sizes = {k: v.shape[:2] for k, v in inputs.items()}
        ints = {k: v for k, v in params.items() if ctype.params[k].type == "int"}
        (oname, oport), = ctype.outputs.items()
        shape = (sizeexpr.evaluate(oport.height, sizes, ints),
                 sizeexpr.evaluate(oport.width, sizes, ints))
        if oport.channels > 1:
            shape += (oport.channels,)
        dtype = np.dtype(DTYPES[oport.dtype][0])
        all_sizes = {**sizes, oname: shape[:2]}
        arguments = []
        for p in kernel_parameters(ctype):
            if p.kind == "buffer":
                arguments.append(p.port)
            elif p.role == "size":
                arguments.append(np.int32(all_sizes[p.port][0 if p.dim == "height" else 1]))
            elif p.role == "param":
                value = params[p.param]
                arguments.append(np.float32(value) if p.c_type == "float" else np.int32(value))
            else:
                arguments.append(np.int32(setting[0]))

        class One(cuda.KernelComponent):
            function = ctype.kernel_function
            inputs = tuple((k, np.uint8) for k in ctype.inputs)
            outputs = ((oname, dtype),)

            def output_sizes(self, *ins):
                return [cuda.Size(shape[0], shape[1], oport.channels)]

        component = One(self.context, self.queue, self.programs[path])
        component.initialize(*[cuda.Size(1, 1, 1) for _ in inputs])
        tile, bx, by = setting
        component.config_gpu(tile, (bx, by, 1),
                             (-(-shape[1] // tile) * bx, -(-shape[0] // tile) * by, 1),
                             arguments)
        return self._one_shot(component, inputs, shape, dtype, oport.channels)


def test_every_library_operation_on_cuda_equals_cpu_and_opencv(cuda_runtime, tmp_path):
    """Each imgproc type on the photographs, two parameter sets and two GPU settings: the
    CUDA kernel equals the CPU form byte for byte, within the documented difference of
    OpenCV (0 but for bilinear Resize).  test_imgproc holds the OpenCL kernel equal to
    the same CPU form, so CUDA equals OpenCL (not compared in one process: see
    frames_of_program.py)."""
    import test_imgproc as ti

    from gpucompgen.library import cpu_kernels

    ours = CudaKernels(cuda_runtime, tmp_path)
    photos = {name: {3: np.ascontiguousarray(load()),
                     1: ti.cv2.cvtColor(np.ascontiguousarray(load()), ti.cv2.COLOR_RGB2GRAY)}
              for name, load in ti.PHOTOS.items()}
    for type_name in ti.TYPES:
        spec = ti.SPECS[type_name]
        for name, versions in photos.items():
            arrays = ti.inputs_for(type_name, versions[ti.channels_of(type_name)])
            for params in spec.cases[:2]:
                cpu = cpu_kernels.CPU_IMPLEMENTATIONS[type_name](*arrays, **params)
                for setting in ((16, 16, 16), (7, 4, 2)):
                    gpu = ours.run(type_name, arrays, params, setting)
                    np.testing.assert_array_equal(gpu, cpu, f"{type_name} {name} {params}")
                assert ti.largest_difference(cpu, spec.opencv(*arrays, **params)) \
                    <= spec.max_diff


def _frames_of(program, frames: int, out) -> dict:
    """The frames of one program run in a process of its own (tests/frames_of_program.py)."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "frames_of_program.py"),
                           str(program), str(frames), str(out)],
                          capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, f"{program}: " + proc.stderr[-3000:]
    try:
        with np.load(out) as saved:
            return dict(saved)
    except Exception as exc:  # seen once on an H100 machine: say which run's file it was
        raise AssertionError(f"{out} (written by {program}) cannot be read: {exc}") from exc


@pytest.mark.parametrize("variant", sorted(VARIANTS))
@pytest.mark.parametrize("model", MODELS, ids=lambda p: p.stem)
def test_every_model_on_cuda_gives_the_opencl_frames(cuda_runtime, model, variant, tmp_path):
    """Each model and variant built for both backends, each run for 4 frames in its own
    process: every frame handed to the CPU is the same, byte for byte."""
    require_opencl()
    runs = []
    for backend in ("opencl", "cuda"):
        out = tmp_path / backend
        write(compile_model(model, out, backend=backend, **VARIANTS[variant]), out)
        runs.append(_frames_of(out / f"{model.stem}.py", 4, tmp_path / f"{backend}.npz"))
    opencl, cuda = runs
    assert opencl, "the program hands no frames to the CPU"
    assert sorted(opencl) == sorted(cuda)
    for key, frame in opencl.items():
        np.testing.assert_array_equal(cuda[key], frame, f"{model.stem} {variant} {key}")
