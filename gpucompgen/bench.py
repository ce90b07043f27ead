"""``gpucompgen bench``: the paper's evaluation (Section V, Figures 9 and 10), reproduced.

Chains of N VerticalMirror components (StillImage -> N mirrors -> FrameSink) are generated
in both modes, built and run on the device of the backend asked for (``--backend opencl``,
the default: the OpenCL device PYOPENCL_CTX selects; ``--backend cuda``: the CUDA device
CUDA_DEVICE selects), through the device interface (runtime/device_api.py); the time per
frame is the time between consecutive frames arriving at the sink.  The GPU-aware chain runs twice: with copying
adapters (``gpu-aware``) and with zero-copy adapters forced on (``zero-copy``: the source's
frame wrapped in a USE_HOST_PTR buffer, the last output mapped for the sink), so a user
sees what zero-copy gains or loses on this device.  In the same run, the references a reader needs
to judge the result:

- hand-written: the same kernel in a plain loop of copies and launches, no framework (one
  buffer per stage, like the generated program), so generated / hand-written is the
  framework's cost;
- bound: N times the time the device takes to read and write one frame, from its copy
  bandwidth measured with buffer-to-buffer copies along a ring of buffers
  larger than the CPU's caches, sampled in the same rounds as the pipelines (the
  adapters' two copies are not counted: it is a bound on the components alone);
- opencv-cpu and opencv-ocl: the same chain of ``cv2.flip(image, 0)`` on numpy arrays and
  on UMat (OpenCV's OpenCL path, on the device ``OPENCV_OPENCL_DEVICE`` selects), when
  OpenCV is installed.  opencv-cpu is interleaved with the generated programs; opencv-ocl
  runs afterwards in a child process, because a broken OpenCL setup in OpenCV can crash
  the process that loads it.

Variants are interleaved: each runs its frames in rounds, round-robin with the others, so
load from other programs on a shared machine spreads over all of them.  Every figure is a
median with its interquartile range.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .backend import kernel_text
from .model import MAX_COMPONENTS
from .runtime import device_api, load_module

DEFAULT_SIZES = ((1152, 864), (1152, 1782))  # width x height, as in the paper
DEFAULT_LENGTHS = (5, 10, 15, 20, 25)
VARIANTS = ("standard", "gpu-aware", "zero-copy", "fused", "hand-written", "bound",
            "opencv-cpu", "opencv-ocl")
TARGETS = (  # (numerator, denominator, limit, "<=" or ">=")
    ("gpu-aware", "hand-written", 1.10, "<="),
    ("gpu-aware", "bound", 1.30, "<="),
    ("standard", "gpu-aware", 3.0, ">="),
    ("opencv-cpu", "gpu-aware", 1.0, ">="),
    ("opencv-ocl", "gpu-aware", 1.0, ">="),
    ("gpu-aware", "fused", 5.0, ">="),
)
# the fused chain against one unfused mirror (N=1): fusion makes length nearly free
FUSED_VS_ONE = 1.30
ROUNDS = 4
MAX_SIDE = 16384  # StillImage's largest width and height (library/mirror.yaml; tested)
MAX_LENGTH = MAX_COMPONENTS - 2  # the mirrors, a source and a sink


class BenchError(Exception):
    """A problem the user can act on (missing extra, bad option, no device)."""


@dataclass
class Figure:
    size: tuple[int, int]  # width, height
    components: int
    variant: str
    samples: list[float]  # seconds per frame

    @property
    def median(self) -> float:
        return float(np.median(self.samples))

    @property
    def q1(self) -> float:
        return float(np.percentile(self.samples, 25))

    @property
    def q3(self) -> float:
        return float(np.percentile(self.samples, 75))


def parse_sizes(text: str) -> list[tuple[int, int]]:
    sizes = []
    for part in text.split(","):
        try:
            w, h = (int(v) for v in part.lower().strip().split("x"))
        except ValueError:
            raise BenchError(f"cannot read size {part.strip()!r}: write WIDTHxHEIGHT, "
                             "e.g. 1152x864") from None
        if w < 1 or h < 1:
            raise BenchError(f"size {part.strip()!r} must be positive")
        if w > MAX_SIDE or h > MAX_SIDE:
            raise BenchError(f"size {part.strip()!r}: width and height must be at most "
                             f"{MAX_SIDE:,} (StillImage's range)")
        sizes.append((w, h))
    return sizes


def parse_lengths(text: str) -> list[int]:
    try:
        lengths = sorted({int(v) for v in text.split(",")})
    except ValueError:
        raise BenchError(f"cannot read lengths {text!r}: write e.g. 5,10,15") from None
    if not lengths or lengths[0] < 1:
        raise BenchError("chain lengths must be 1 or more")
    if lengths[-1] > MAX_LENGTH:
        raise BenchError(f"chain lengths must be at most {MAX_LENGTH:,} (a system has at most "
                         f"{MAX_COMPONENTS:,} components: the mirrors, a source and a sink)")
    return lengths


def chain_model(n: int, width: int, height: int) -> str:
    """The YAML system model of a chain of n VerticalMirror components."""
    lines = [f"system: mirror_chain_{n}",
             f"description: StillImage -> {n} VerticalMirror -> FrameSink ({width}x{height})",
             "components:",
             f"  source: {{type: StillImage, params: {{width: {width}, height: {height}}}}}"]
    lines += [f"  mirror{i}: {{type: VerticalMirror}}" for i in range(1, n + 1)]
    lines += ["  sink: {type: FrameSink}", "connections:", "  - source.image -> mirror1.image"]
    lines += [f"  - mirror{i}.mirrored -> mirror{i + 1}.image" for i in range(1, n)]
    lines += [f"  - mirror{n}.mirrored -> sink.image"]
    return "\n".join(lines) + "\n"


def expected_output(image: np.ndarray, n: int) -> np.ndarray:
    return image[::-1] if n % 2 else image


class Generated:
    """One generated chain program, run in rounds."""

    def __init__(self, folder: Path, n: int, size: tuple[int, int], variant: str, context):
        from .build import compile_model, write

        model = folder / f"chain_{n}_{size[0]}x{size[1]}.yaml"
        model.write_text(chain_model(n, *size), encoding="utf-8")
        out = folder / f"{variant}_{n}_{size[0]}x{size[1]}"
        mode = "standard" if variant == "standard" else "gpu-aware"
        # 'fused-zero-copy' is both: what --device auto builds on a device sharing host memory
        zero_copy = "on" if "zero-copy" in variant else "off"
        # every variant but the fused ones runs one kernel per mirror, as in the paper
        fusion = "auto" if "fused" in variant else "off"
        backend = device_api.name_of(device_api.of(context))  # the context's device API
        write(compile_model(model, out, mode=mode, zero_copy=zero_copy, fusion=fusion,
                            backend=backend), out)
        name = f"gpucompgen_bench_{variant.replace('-', '_')}_{n}_{size[0]}x{size[1]}"
        self.module = load_module(out / f"mirror_chain_{n}.py", name)
        self.context, self.n = context, n

    def run(self, frames: int) -> tuple[list[float], np.ndarray]:
        result = self.module.run(frames=frames + 1, context=self.context)
        sink = result.components["sink"]
        return list(sink.frame_times()), sink.last


class HandWritten:
    """The same kernel in a plain loop of copies and launches (the device interface's
    calls, one each, as a programmer would write them by hand with the device's API)."""

    def __init__(self, n: int, image: np.ndarray, context):
        from .kernelgen.fused import group_kernel, group_of_one, launch_geometry
        from .model import library_types
        from .passes.fuse import GROUP_GPU

        api = self.api = device_api.of(context)
        self.n, self.image = n, image
        self.context = context
        self.queue = api.create_queue(context)
        h, w = image.shape[:2]
        # VerticalMirror's kernel: the one the generator writes from its form for a mirror
        # alone, with the settings the generated program gives it (work-groups of rows)
        # (a mirror fed these frames: VerticalMirror over uint8 of their channels)
        mirror = library_types()["VerticalMirror"].specialized(
            "uint8", image.shape[2] if image.ndim == 3 else 1)
        group = group_of_one(mirror, {}, {"src": (h, w), "dst": (h, w)}, "m",
                             "vertical_mirror")
        _, source = kernel_text(device_api.name_of(api), group_kernel(group, "bench"))
        program = api.build_source(context, source)
        self.kernel = api.kernel(program, "vertical_mirror")
        tile, bx, by, _ = GROUP_GPU.prefer
        self.global_size, self.local_size = launch_geometry(group, tile, bx, by)
        self.args = [np.int32(tile)]
        self.buffers = [api.device_buffer(context, image.nbytes) for _ in range(n + 1)]
        self.host = np.empty_like(image)

    def run(self, frames: int) -> tuple[list[float], np.ndarray]:
        api, q, k = self.api, self.queue, self.kernel
        arrivals = []
        for _ in range(frames + 1):
            api.copy(q, self.buffers[0], self.image)
            for i in range(self.n):
                api.set_args(k, self.buffers[i], self.buffers[i + 1], *self.args)
                api.launch(q, k, self.global_size, self.local_size)
            api.copy(q, self.host, self.buffers[self.n])
            arrivals.append(time.perf_counter())
        return list(np.diff(arrivals)), self.host

    def release(self) -> None:
        for b in self.buffers:
            self.api.release(b)


class OpenCvCpu:
    """The chain as OpenCV on the CPU: cv2.flip into preallocated arrays."""

    def __init__(self, n: int, image: np.ndarray):
        import cv2

        self.flip, self.image = cv2.flip, image
        self.arrays = [np.empty_like(image) for _ in range(n)]

    def run(self, frames: int) -> tuple[list[float], np.ndarray]:
        arrivals = []
        for _ in range(frames + 1):
            src = self.image
            for dst in self.arrays:
                self.flip(src, 0, dst)
                src = dst
            arrivals.append(time.perf_counter())
        return list(np.diff(arrivals)), src

    def release(self) -> None:
        self.arrays = []


class CopyRing:
    """The device's copy bandwidth, for the bound: buffer-to-buffer copies.

    The copies go along a ring of distinct buffers at least 64 MiB in all, as a chain of
    components goes through distinct buffers: two buffers copied back and forth would stay
    in the CPU's cache and promise a bandwidth no long chain can reach.  Sampled in the
    same rounds as the pipelines, so it sees the same load.
    """

    def __init__(self, context, nbytes: int):
        api = self.api = device_api.of(context)
        self.nbytes = nbytes
        self.queue = api.create_queue(context)
        count = max(8, -(-(64 << 20) // nbytes))
        self.ring = [api.device_buffer(context, nbytes) for _ in range(count)]
        for b in self.ring:
            api.fill(self.queue, b, 7, nbytes)
        api.finish(self.queue)

    def seconds_per_frame_copy(self, samples: int) -> list[float]:
        """Time to read and write one frame once, from `samples` runs along the ring."""
        result = []
        for _ in range(samples):
            t = time.perf_counter()
            for i in range(len(self.ring) - 1):
                self.api.copy(self.queue, self.ring[i + 1], self.ring[i])
            self.api.finish(self.queue)
            result.append((time.perf_counter() - t) / (len(self.ring) - 1))
        return result

    def release(self) -> None:
        for b in self.ring:
            self.api.release(b)
        self.ring = []


class Bound:
    """N components each reading and writing one frame once at the copy bandwidth."""

    def __init__(self, n: int, ring: CopyRing):
        self.n, self.ring = n, ring

    def run(self, frames: int) -> tuple[list[float], None]:
        return [self.n * s for s in self.ring.seconds_per_frame_copy(frames)], None


# ------------------------------------------------------------------ OpenCV (child process)

def _opencv_env() -> dict[str, str]:
    """OpenCV's OpenCL on the device the runtime uses (the OpenCL module names the loader
    library its binding ships, with PoCL)."""
    env = dict(os.environ)
    env.setdefault("OPENCV_OPENCL_DEVICE", ":CPU:")
    if "OPENCV_OPENCL_RUNTIME" not in env:
        library = device_api.get().loader_library()
        if library:
            env["OPENCV_OPENCL_RUNTIME"] = library
    return env


def opencv_worker(spec: dict) -> dict:
    """Run in the child: times per frame of cv2.flip chains on UMat (OpenCL)."""
    # the OpenCL binding first: it tells the ICD loader where the PoCL it ships is
    device_api.get().load()
    import cv2

    from .library.still_image import still_frame

    w, h = spec["size"]
    image = still_frame(w, h)
    ocl = cv2.ocl.haveOpenCL()
    if ocl:
        cv2.ocl.setUseOpenCL(True)
    out: dict = {"ocl": bool(ocl), "device": cv2.ocl.Device.getDefault().name() if ocl else "",
                 "times": {}}
    if not ocl:
        return out
    for n in spec["lengths"]:
        umats = [cv2.UMat(image) for _ in range(n + 1)]
        arrivals = []
        host = image
        for _ in range(spec["frames"] + 1):
            umats[0] = cv2.UMat(image)
            for i in range(n):
                cv2.flip(umats[i], 0, umats[i + 1])
            host = umats[n].get()
            arrivals.append(time.perf_counter())
        if not np.array_equal(host, expected_output(image, n)):
            raise RuntimeError(f"OpenCV chain of {n} flips on UMat gave a wrong image")
        out["times"][str(n)] = {"opencv-ocl": list(np.diff(arrivals))}
    return out


def opencv_ocl_reference(size, lengths, frames) -> tuple[dict, str]:
    """Times from the child process, or ({}, why not)."""
    spec = json.dumps({"size": list(size), "lengths": list(lengths), "frames": frames})
    proc = subprocess.run([sys.executable, "-m", "gpucompgen.bench", "--opencv-worker", spec],
                          capture_output=True, text=True, env=_opencv_env(), timeout=3600,
                          check=False)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
        return {}, f"OpenCV reference failed: {last}"
    data = json.loads(proc.stdout)
    note = "" if data["ocl"] else "OpenCV has no OpenCL device: opencv-ocl left out"
    return data, note


# ------------------------------------------------------------------ the benchmark

def _need_extras():
    missing = [m for m in ("matplotlib", "tqdm") if importlib.util.find_spec(m) is None]
    if missing:
        raise BenchError(f"gpucompgen bench needs {' and '.join(missing)}: "
                         "pip install 'gpucompgen[bench]'")


def run_bench(sizes, lengths, frames: int, out_dir: Path, opencv: bool = True,
              rounds: int = ROUNDS, stdout=None, backend: str = "opencl") -> dict:
    """Run everything, write bench.csv and bench.png into out_dir, print the table;
    backend ("opencl" | "cuda") picks the device API the chains are built for and run on."""
    _need_extras()
    stdout = stdout or sys.stdout
    if frames < 1:
        raise BenchError("--frames must be 1 or more")
    rounds = max(1, min(rounds, frames))
    from tqdm import tqdm

    from .library.still_image import still_frame
    api = device_api.get(backend)
    context = api.create_context()
    device = api.context_device(context)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BenchError(f"cannot create output folder {out_dir}: {exc.strerror}") from None
    figures: list[Figure] = []
    notes: list[str] = []
    if opencv and importlib.util.find_spec("cv2") is None:
        opencv = False
        notes.append("OpenCV is not installed (pip install 'gpucompgen[video]'): "
                     "no OpenCV references")
    per_round = 7 if opencv else 6
    total = len(sizes) * (len(lengths) * per_round * rounds + 1 + (1 if opencv else 0))
    bar = tqdm(total=total, desc="bench", unit="run", disable=not sys.stderr.isatty(),
               file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="gpucompgen-bench-") as tmp:
        for size in sizes:
            image = still_frame(*size)
            ring = CopyRing(context, image.nbytes)
            bar.update(1)
            for n in lengths:
                figures += _time_chain(n, size, image, Path(tmp), context, ring, opencv,
                                       frames, rounds, bar)
            ring.release()
            if opencv:
                bar.set_postfix_str(f"{size[0]}x{size[1]} OpenCV")
                data, note = opencv_ocl_reference(size, lengths, frames)
                if note and note not in notes:
                    notes.append(note)
                for n_text, by_variant in data.get("times", {}).items():
                    for variant, s in by_variant.items():
                        figures.append(Figure(size, int(n_text), variant, s))
                bar.update(1)
    bar.close()
    device_name = api.device_name(device)
    csv_path = out_dir / "bench.csv"
    png_path = out_dir / "bench.png"
    try:
        write_csv(figures, csv_path, frames)
        plot(figures, png_path, device_name, frames)
    except OSError as exc:
        raise BenchError(f"cannot write results into {out_dir}: {exc.strerror}") from None
    text = table(figures, device_name, frames, notes)
    print(text, file=stdout)
    print(f"wrote {csv_path}\nwrote {png_path}", file=stdout)
    return {"figures": figures, "csv": csv_path, "png": png_path, "text": text}


def _time_chain(n: int, size, image, tmp: Path, context, ring: CopyRing, opencv: bool,
                frames: int, rounds: int, bar) -> list[Figure]:
    """Every variant of a chain of n mirrors at one size, timed in rounds taking turns
    (each output checked against the expected image)."""
    runners = {"standard": Generated(tmp, n, size, "standard", context),
               "gpu-aware": Generated(tmp, n, size, "gpu-aware", context),
               "zero-copy": Generated(tmp, n, size, "zero-copy", context),
               "fused": Generated(tmp, n, size, "fused", context),
               "hand-written": HandWritten(n, image, context),
               "bound": Bound(n, ring)}
    if opencv:
        runners["opencv-cpu"] = OpenCvCpu(n, image)
    samples: dict[str, list[float]] = {v: [] for v in runners}
    want = expected_output(image, n)
    for r in range(rounds):
        k = frames // rounds + (1 if r < frames % rounds else 0)
        for variant, runner in runners.items():
            bar.set_postfix_str(f"{size[0]}x{size[1]} N={n} {variant}")
            times, last = runner.run(k)
            if last is not None and not np.array_equal(last, want):
                raise BenchError(f"{variant} chain of {n} at {size[0]}x{size[1]} "
                                 "gave a wrong image")
            samples[variant] += times
            bar.update(1)
    for variant in ("hand-written", "opencv-cpu"):
        if variant in runners:
            runners[variant].release()
    return [Figure(size, n, variant, s) for variant, s in samples.items()]


def _key(f: Figure):
    return (f.size[1] * f.size[0], f.size, f.components, VARIANTS.index(f.variant))


class CsvFigure:
    """A row of bench.csv, read back (for plotting a saved run again)."""

    def __init__(self, row: dict):
        self.size = (int(row["width"]), int(row["height"]))
        self.components, self.variant = int(row["components"]), row["variant"]
        self.median, self.q1, self.q3 = (float(row[k]) / 1e3 for k in
                                         ("median_ms", "q1_ms", "q3_ms"))


def read_csv(path: Path) -> list[CsvFigure]:
    with path.open(newline="", encoding="utf-8") as fh:
        return [CsvFigure(row) for row in csv.DictReader(fh)]


def write_csv(figures: list[Figure], path: Path, frames: int) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["width", "height", "components", "variant", "samples", "median_ms",
                    "q1_ms", "q3_ms"])
        for f in sorted(figures, key=_key):
            w.writerow([f.size[0], f.size[1], f.components, f.variant, len(f.samples),
                        f"{f.median * 1e3:.4f}", f"{f.q1 * 1e3:.4f}", f"{f.q3 * 1e3:.4f}"])


def _index(figures):
    return {(f.size, f.components, f.variant): f for f in figures}


def table(figures: list[Figure], device: str, frames: int, notes: list[str]) -> str:
    """Time per frame (median [IQR]) per size and chain length, ratios, targets."""
    idx = _index(figures)
    variants = [v for v in VARIANTS if any(f.variant == v for f in figures)]
    lines = [f"gpucompgen bench on {device}: ms per frame, median [q1-q3], {frames} frames "
             + "per variant"]
    sizes = sorted({f.size for f in figures}, key=lambda s: s[0] * s[1])
    for size in sizes:
        lines.append("")
        lines.append(f"{size[0]}x{size[1]} pixels")
        rows = [["N"] + variants + ["std/aware", "aware/zero", "aware/fused", "aware/hand",
                                    "aware/bound"]]
        for n in sorted({f.components for f in figures if f.size == size}):
            row = [str(n)]
            for v in variants:
                f = idx.get((size, n, v))
                row.append(f"{f.median * 1e3:.2f} [{f.q1 * 1e3:.2f}-{f.q3 * 1e3:.2f}]"
                           if f else "-")
            for a, b in (("standard", "gpu-aware"), ("gpu-aware", "zero-copy"),
                         ("gpu-aware", "fused"), ("gpu-aware", "hand-written"),
                         ("gpu-aware", "bound")):
                fa, fb = idx.get((size, n, a)), idx.get((size, n, b))
                row.append(f"{fa.median / fb.median:.2f}x" if fa and fb else "-")
            rows.append(row)
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        lines += ["  ".join(c.rjust(wd) for c, wd in zip(r, widths)) for r in rows]
    lines.append("")
    lines.append("targets, at the longest chain:")
    for size in sizes:
        n = max(f.components for f in figures if f.size == size)
        for a, b, limit, op in TARGETS:
            fa, fb = idx.get((size, n, a)), idx.get((size, n, b))
            if not (fa and fb):
                continue
            ratio = fa.median / fb.median
            met = ratio <= limit if op == "<=" else ratio >= limit
            lines.append(f"  {size[0]}x{size[1]} N={n}: {a} / {b} = {ratio:.2f}x "
                         f"(target {op} {limit:.2f}x): {'met' if met else 'NOT met'}")
        fa, fb = idx.get((size, n, "fused")), idx.get((size, 1, "gpu-aware"))
        if fa and fb and n > 1:
            ratio = fa.median / fb.median
            lines.append(f"  {size[0]}x{size[1]} N={n}: fused / gpu-aware N=1 = {ratio:.2f}x "
                         f"(target <= {FUSED_VS_ONE:.2f}x): "
                         f"{'met' if ratio <= FUSED_VS_ONE else 'NOT met'}")
    for note in notes:
        lines.append(f"note: {note}")
    return "\n".join(lines)


STYLE = {"standard": ("tab:blue", "o", "-"), "gpu-aware": ("tab:red", "s", "-"),
         "zero-copy": ("tab:brown", "x", "-"), "fused": ("tab:cyan", "*", "-"),
         "hand-written": ("tab:green", "^", "--"), "bound": ("black", "", ":"),
         "opencv-cpu": ("tab:purple", "v", "-."), "opencv-ocl": ("tab:orange", "D", "-.")}


def plot(figures: list[Figure], path: Path, device: str, frames: int) -> None:
    """Figures 9 and 10 of the paper: time per frame against chain length, a panel a size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    sizes = sorted({f.size for f in figures}, key=lambda s: s[0] * s[1])
    fig, axes = plt.subplots(1, len(sizes), figsize=(6 * len(sizes), 4.5), squeeze=False)
    for ax, size in zip(axes[0], sizes):
        for variant in VARIANTS:
            fs = sorted((f for f in figures if f.size == size and f.variant == variant),
                        key=lambda f: f.components)
            if not fs:
                continue
            x = [f.components for f in fs]
            y = np.array([f.median * 1e3 for f in fs])
            err = np.array([[f.median * 1e3 - f.q1 * 1e3 for f in fs],
                            [f.q3 * 1e3 - f.median * 1e3 for f in fs]])
            color, marker, style = STYLE[variant]
            ax.errorbar(x, y, yerr=err, color=color, marker=marker or None, linestyle=style,
                        capsize=3, label=variant)
        ax.set_title(f"{size[0]} x {size[1]} pixels")
        ax.set_xlabel("number of VerticalMirror components")
        ax.set_ylabel("time per frame (ms), median and IQR, log scale")
        ax.set_xticks(sorted({f.components for f in figures if f.size == size}))
        # log scale: equal ratios are equal distances, and OpenCV's OpenCL path, many
        # times slower, does not flatten the other lines
        ax.set_yscale("log")
        # plain numbers on the log axis ("3", "20"), not "4x10^0" on some panels only;
        # between the powers of ten only 2, 3 and 5 are labelled
        ax.yaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_formatter(matplotlib.ticker.FuncFormatter(
            lambda v, _: f"{v:g}" if f"{v:g}".lstrip("0.")[:1] in ("2", "3", "5") else ""))
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Standard vs GPU-aware components on {device}, {frames} frames each",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--opencv-worker":
        print(json.dumps(opencv_worker(json.loads(sys.argv[2]))))
        sys.exit(0)
    print("usage: gpucompgen bench [options]", file=sys.stderr)
    sys.exit(2)
