"""`gpucompgen tune MODEL`: measure each flexible component on the CPU and on the device.

Every flexible component of the model runs its real implementations at the model's sizes
(propagated as for a build): its CPU function on camera-like frames (the synthetic
camera's water, noise and buoys, in each port's shape and element type: branchy code runs
as fast on uniform noise as it never does on images), and its kernel with the
launch settings a build would give it, on the device programs use (the model's
platform.backend or --backend: the OpenCL device PYOPENCL_CTX selects, or the CUDA device
CUDA_DEVICE selects), through the device interface (runtime/device_api.py).
Each is timed for a few frames after one warm-up, and the median kept — a kernel from
enqueue to finish, so the launch cost counts.  One copy each way between host and device
gives the transfer latency (a 64-byte copy) and bandwidth (the largest port's bytes).

The profile is a small YAML file that the model names (``platform.profile``) and that is
checked in; the place pass reads it for ``placement: auto``.  Running the components is
what this command is for: like ``run``, and unlike ``check`` and ``build``, it imports
the types' CPU functions.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import statistics
import tempfile
import time
import traceback
from pathlib import Path

from .backend import device_query, kernel_text
from .ir import GroupNode
from .passes.place import default_profile, sizes_text
from .runtime import device_api

TRANSFER_PROBE_BYTES = 64
# a group and its members apart are timed in turn, this many rounds of `frames` each, and
# each side's median kept: a burst of load falls on both sides, not on one
GROUP_ROUNDS = 3


def default_profile_path(model_path: Path, model) -> Path:
    """The model's platform.profile, else tune/<system>.yaml beside the model: the file
    placement: auto reads without platform.profile (passes/place.py profile_path)."""
    return model.profile or default_profile(model)


class FunctionFailed(Exception):
    """A component's own CPU function raised while being timed (the user's code, exit 1)."""


def output_path(model_path: Path, model, asked: Path | None) -> Path:
    """Where the profile goes, checked before anything is measured: OutputError when it is
    an input of the build (the model, its type, kernel, Python or CPU files, a path
    parameter: a profile written there replaced it), a folder, or no regular file."""
    from .build import build_inputs
    from .errors import OutputError

    out = asked or default_profile_path(model_path, model)
    try:
        resolved = out.resolve()
    except (OSError, RuntimeError) as exc:
        raise OutputError(f"{out}: cannot use it for the profile: {exc}") from None
    if resolved in build_inputs(model):
        raise OutputError(f"{out} is an input of the build of {model_path}; writing the "
                          "profile there would replace it\n  hint: give platform.profile "
                          "(or -o) a file of its own, e.g. tune/"
                          f"{model.name}.yaml")
    if out.is_dir():
        raise OutputError(f"{out} is a folder\n  hint: give the path of the profile file, "
                          f"e.g. {out / (model.name + '.yaml')}")
    if out.exists() and not out.is_file():
        raise OutputError(f"{out} is not a regular file\n  hint: give the path of a .yaml "
                          "file; the profile is written to a temporary file and renamed")
    parent = out.parent
    if parent.exists() and not parent.is_dir():
        raise OutputError(f"{parent} is a file, where the profile's folder would go")
    if parent.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write into {parent}: permission denied")
    return out


def write_profile(out: Path, text: str) -> None:
    """Write the profile whole or not at all (a temporary file beside it, then renamed);
    a failure is an OutputError."""
    from .errors import OutputError

    tmp = None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, out)
        tmp = None
    except OSError as exc:
        raise OutputError(f"cannot write the profile {out}: {exc.strerror or exc}") from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def tune(model_path: Path, frames: int = 20, display: str | None = None,
         groups_out: list | None = None, backend: str | None = None) -> tuple[str, list]:
    """Measure; return the profile's text and rows (name, type, sizes, cpu_us, gpu_us);
    groups_out, where given, gets a row (name, members, fused_us, apart_us) for every
    group measured against its members apart.  backend ("opencl" | "cuda"; None: the
    model's platform.backend) picks the device API."""
    from . import device as device_mod
    from .errors import Reporter
    from .model import load_system
    from .passes import run_passes

    model = load_system(model_path, display)
    flexible = [n for n, inst in model.components.items() if inst.type.flexible]
    backend = backend or model.backend
    api = device_api.get(backend)  # the device interface (runtime/device_api.py)
    # first: no device API package, driver or device is a PipelineError saying so
    context = api.create_context()
    queue = api.create_queue(context)
    rep = Reporter()
    facts = device_mod.resolve("auto", model.device_pos, rep, None,
                               query=device_query(backend))
    rep.raise_if_errors()
    system, _ = run_passes(model, facts, places=dict.fromkeys(flexible, "gpu"),
                           zero_copy="off", fusion="off")  # each component's own kernel
    plan = system.plan
    rows = []
    for name in flexible:
        node = system.nodes[name]  # a fusable type's: a group of one, its generated kernel
        member = node.root if isinstance(node, GroupNode) else node
        t = member.type
        inputs = {p: camera_frame(port.data.size.shape, port.data.dtype, i)
                  for i, (p, port) in enumerate(node.inputs.items())}
        function, kwargs = _cpu_function(t), {**inputs, **member.params}
        cpu_s = _median(frames, lambda f=function, k=kwargs, n=name, t=t: _call(n, t, f, k))
        gpu_s = _gpu_time(context, queue, system, plan, node, inputs, frames)
        rows.append((name, t.name, sizes_text(system, node), cpu_s * 1e6, gpu_s * 1e6))
    groups = measure_groups(model, facts, context, queue, system, frames)
    if groups_out is not None:
        groups_out += groups
    biggest = max((p.data.nbytes for n in flexible for p in system.nodes[n].ports), default=1)
    latency, bandwidth = _transfer(context, queue, biggest, frames)
    device = api.facts(api.device_of(queue)).name
    label = {"opencl": "OpenCL", "cuda": "CUDA"}[backend]
    lines = [f"# Written by 'gpucompgen tune {display or model_path}' on the {label} device",
             f"# '{device}': the median of {frames} frames of each flexible component at the",
             "# model's sizes, on the CPU (its function) and on the device (its kernel, enqueue",
             "# to finish), and the cost of one copy between host and device; each group the",
             "# fuse pass chose, as one kernel and its members' kernels apart (a group that is",
             "# no faster is refused, and the next choice measured). Placement and fusion read",
             "# this file (platform.profile, else tune/<system>.yaml); rerun after changing",
             "# sizes, device or implementations.",
             f"system: {model.name}",
             f"device: {_quote(device)}",
             f"frames: {frames}",
             f"transfer: {{latency_us: {latency * 1e6:.1f}, bandwidth_mb_s: {bandwidth / 1e6:.1f}}}",
             "components:" + ("" if rows else " {}")]
    for name, tname, sizes, cpu_us, gpu_us in rows:
        lines.append(f"  {name}: {{type: {tname}, sizes: {_quote(sizes)}, "
                     f"cpu_us: {cpu_us:.1f}, gpu_us: {gpu_us:.1f}}}")
    if groups:
        lines.append("groups:")
    for name, members, sizes, fused_us, apart_us in groups:
        lines.append(f"  {name}: {{members: [{', '.join(members)}], sizes: {_quote(sizes)}, "
                     f"fused_us: {fused_us:.1f}, apart_us: {apart_us:.1f}}}")
    return "\n".join(lines) + "\n", rows


def measure_groups(model, facts, context, queue, apart_system, frames: int) -> list:
    """Every group the fuse pass chooses with every flexible component on the device, as
    one kernel and as its members' kernels apart (each timed as above, on camera frames of
    its inputs' shapes): rows (name, members, sizes, fused_us, apart_us).  A group measured
    no faster is refused on the next build, which may choose another (a smaller one):
    that one is measured too, until no new group is chosen."""
    from .passes.fuse import group_sizes_text
    from .passes.pipeline import PIPELINE, new_system, run_pipeline

    flexible = [n for n, inst in model.components.items() if inst.type.flexible]

    def kernel(stack, system, node):
        inputs = {p: camera_frame(port.data.size.shape, port.data.dtype, i)
                  for i, (p, port) in enumerate(node.inputs.items())}
        return stack.enter_context(_kernel(context, queue, system, system.plan, node, inputs))

    measured: dict[frozenset, tuple[float, float]] = {}
    rows = []
    for _ in range(len(model.components)):
        system = new_system(model, facts, places=dict.fromkeys(flexible, "gpu"),
                            zero_copy="off", fusion="auto")
        system.measured_groups = dict(measured)
        system, _ = run_pipeline(system, PIPELINE)
        new = [g for g in system.groups if frozenset(m.name for m in g.members) not in measured]
        if not new:
            break
        for g in new:
            names = [m.name for m in g.members]
            with contextlib.ExitStack() as stack:  # rounds alternate: load hits both alike
                one = kernel(stack, system, g)
                members = [kernel(stack, apart_system, apart_system.nodes[n]) for n in names]
                rounds = [(one(frames), sum(m(frames) for m in members))
                          for _ in range(GROUP_ROUNDS)]
            fused = statistics.median(f for f, _ in rounds)
            apart = statistics.median(a for _, a in rounds)
            measured[frozenset(names)] = (fused, apart)
            label = g.name  # two groups may share first and last member: the label differs
            while label in {r[0] for r in rows}:
                label += "_"
            rows.append((label, names, group_sizes_text(apart_system, set(names)),
                         fused * 1e6, apart * 1e6))
    return rows


def camera_frame(shape: tuple[int, ...], dtype: str, index: int = 0):
    """Frame index of the library's synthetic camera in shape and dtype: RGB for three
    channels (repeated for more), OpenCV's gray for one; signed types centred on 0
    (int16 and int32 at a gradient's scale, -512..508), float32 in 0..1. Every byte of
    the port's frame is there (an int16 port gets twice a uint8 port's bytes)."""
    import numpy as np

    from .library.camera import Camera

    height, width = shape[:2]
    channels = shape[2] if len(shape) == 3 else 1
    camera = Camera(width=width, height=height, seed=1)
    camera.initialize()
    rgb = camera.render(index)
    camera.free_memory()
    if channels == 1:  # RGB2GRAY's fixed-point weights
        weights = np.array([19596, 38470, 7470], np.uint32)
        values = ((rgb.astype(np.uint32) @ weights + (1 << 15)) >> 16).astype(np.int32)
    else:
        values = rgb[..., [c % 3 for c in range(channels)]].astype(np.int32)
    kind = np.dtype(dtype)
    if kind == np.int8:
        values = values - 128
    elif kind.kind == "i":
        values = (values - 128) * 4
    elif kind.kind == "f":
        values = values / np.float32(255)
    return np.ascontiguousarray(values.astype(kind).reshape(shape))


def _quote(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _cpu_function(t):
    if t.origin == "library":
        module = importlib.import_module(f"gpucompgen.library.{t.cpu_file.stem}")
        return getattr(module, t.cpu_function)
    from .runtime import load_function
    return load_function(t.cpu_file, t.cpu_function)


def _call(name: str, t, function, kwargs):
    """Call a component's CPU function; its exception becomes FunctionFailed, naming the
    component, the function and the line of its file that raised."""
    try:
        return function(**kwargs)
    except Exception as exc:
        where = str(t.cpu_file)
        line = next((f.lineno for f in reversed(traceback.extract_tb(exc.__traceback__))
                     if Path(f.filename).resolve() == Path(where).resolve()), None)
        place = f"{t.cpu_file.name}:{line}" if line else t.cpu_file.name
        raise FunctionFailed(f"{name} ({t.name}): its CPU function '{t.cpu_function}' "
                             f"raised {type(exc).__name__}: {exc} (at {place})") from exc


def _median(frames: int, call, finish=None) -> float:
    call()
    if finish:
        finish()
    times = []
    for _ in range(max(frames, 1)):
        start = time.perf_counter()
        call()
        if finish:
            finish()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _gpu_time(context, queue, system, plan, node, inputs, frames) -> float:
    with _kernel(context, queue, system, plan, node, inputs) as run:
        return run(frames)


@contextlib.contextmanager
def _kernel(context, queue, system, plan, node, inputs):
    """The node's kernel built and configured as a build would, with its inputs on the
    device: yields run(frames) -> the median seconds of a launch, enqueue to finish."""
    import numpy as np

    from . import runtime

    api = device_api.of(context)
    t = node.type
    la = plan.launch(node.name)
    out_sizes = [p.data.size for p in node.outputs.values()]
    cls = type(t.name, (runtime.KernelComponent,), {
        "function": t.kernel_function,
        "inputs": tuple((p, np.dtype(d.dtype).type) for p, d in t.inputs.items()),
        "outputs": tuple((p, np.dtype(d.dtype).type) for p, d in t.outputs.items()),
        "output_sizes": lambda self, *sizes: out_sizes, "api": api})
    program = _program(api, context, system, node)
    comp = cls(context, queue, program, **node.params)
    buffers: list = []
    try:
        comp.initialize(*(p.data.size for p in node.inputs.values()))
        arguments = [a.port if a.kind == "buffer" else getattr(np, a.host_type)(a.value)
                     for a in la.arguments]
        comp.config_gpu(la.tile, la.local_size, la.global_size, arguments, la.settings_source)
        buffers += [api.filled_buffer(context, x) for x in inputs.values()]
        yield lambda frames: _median(frames, lambda: comp.execute(*buffers),
                                     lambda: api.finish(queue))
    finally:
        comp.free_memory()
        for buffer in buffers:  # CUDA frees nothing a garbage collector drops
            api.release(buffer)


def _program(api, context, system, node):
    """The node's kernel as a build writes it for the device API's backend (a group's
    from the type's form, else the type's kernel file), built."""
    t = node.type
    backend = device_api.name_of(api)
    if isinstance(node, GroupNode):  # the kernel the build writes from the type's form
        from .kernelgen.fused import group_kernel

        text = group_kernel(node, "tune", system.device)
    elif backend == "opencl":  # the type's kernel file as it is
        return api.build_program(context, t.kernel_file, f"{node.name} ({t.name})")
    else:
        text = t.kernel_file.read_text(encoding="utf-8")
    suffix, text = kernel_text(backend, text)
    with tempfile.TemporaryDirectory() as folder:
        name = node.name if isinstance(node, GroupNode) else t.kernel_file.stem
        path = Path(folder) / f"{name}{suffix}"
        path.write_text(text, encoding="utf-8")
        return api.build_program(context, path, f"{node.name} ({t.name})")


def _transfer(context, queue, nbytes: int, frames: int) -> tuple[float, float]:
    """(seconds per copy, bytes per second): a tiny copy's time, and the largest port's."""
    import numpy as np

    api = device_api.of(context)
    small = np.zeros(TRANSFER_PROBE_BYTES, np.uint8)
    big = np.zeros(nbytes, np.uint8)
    dsmall = api.device_buffer(context, small.nbytes)
    dbig = api.device_buffer(context, big.nbytes)

    def both(host, dev):
        api.copy(queue, dev, host)
        api.copy(queue, host, dev)
        api.finish(queue)

    latency = _median(frames, lambda: both(small, dsmall)) / 2
    per_copy = _median(frames, lambda: both(big, dbig)) / 2
    bandwidth = nbytes / max(per_copy - latency, 1e-9)
    api.release(dsmall)
    api.release(dbig)
    return latency, bandwidth
