"""gpucompgen's command line: build, run, check, plan, graph, bench, devices, types, schema.

Exit codes as in black and datamodel-codegen: 0 ok, 1 problems found (or stale output with
--check), 2 usage or internal error.  A user sees a traceback only with --debug.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

from . import __version__
from .backend import BACKENDS
from .errors import GpucompgenError, OutputError, UsageError
from .ir import MODES
from .model import EXECUTIONS, FUSION, MAX_FRAMES_IN_FLIGHT, STAGING, ZERO_COPY
from .replay.cli import add_replay_parser, cmd_replay
from .runtime import add_program_options

EPILOG = """\
exit codes: 0 ok; 1 problems in the model, stale output with --check, or a failed run;
2 usage, output (a folder or file that cannot take the output) or internal error (and a
missing Graphviz for graph).
A run stopped by SIGINT or SIGTERM exits 130 or 143; a program killed by a signal
exits 128 + its number (139 for SIGSEGV), and 'run' names the signal.

examples:
  gpucompgen build models/vision_system.yaml              write generated/vision_system.py
  gpucompgen build models/vision_system.yaml --check      is generated/ current? (CI)
  gpucompgen run models/vision_system.yaml --frames 100   build to a temporary folder, run
  gpucompgen graph models/vision_system.yaml -o vs.svg    draw the architecture
"""


def _common(p: argparse.ArgumentParser,
            device_default: str = "the model's platform.device") -> None:
    p.add_argument("model", type=Path, metavar="MODEL", help="the system model (.yaml)")
    p.add_argument("--mode", choices=MODES, default="gpu-aware",
                   help="gpu-aware: GPU ports and generated adapters (default); standard: every "
                        "GPU-aware component copies its own data, as in the paper's Section II")
    p.add_argument("--device", metavar="PROFILE",
                   help="device facts to plan for: a profile name, or 'auto' for the OpenCL "
                        "device programs use (PYOPENCL_CTX, else the first that compiles "
                        "kernels; see 'gpucompgen devices'); its class (cpu, integrated-gpu, "
                        "discrete-gpu) places the flexible components nobody placed and sets "
                        f"the fusion cost model's constants; default: {device_default}")
    p.add_argument("--execution", choices=EXECUTIONS,
                   help="parallel: independent GPU work on separate queues, waiting only where "
                        "the host reads a result; sequential: one queue, blocking copies "
                        "(default: the model's platform.execution, else parallel)")
    p.add_argument("--zero-copy", choices=ZERO_COPY, dest="zero_copy",
                   help="zero-copy adapters (map host-visible memory instead of copying): auto "
                        "follows the device's unified host memory (default: the model's "
                        "platform.zero_copy, else auto)")
    p.add_argument("--frames-in-flight", type=_frames_in_flight, dest="frames_in_flight",
                   metavar="N",
                   help="frames the program works on at the same time: 1 runs one frame at a "
                        "time; 2 or more overlap sources, device work and sinks of "
                        "consecutive frames, one thread a stage (default: the model's "
                        "platform.frames_in_flight, else 1)")
    p.add_argument("--staging", choices=STAGING,
                   help="how copying adapters stage host memory: pinned host buffers or "
                        "pageable arrays; auto is pinned when the device has no unified host "
                        "memory (default: the model's platform.staging, else auto)")
    p.add_argument("--backend", choices=BACKENDS,
                   help="opencl: OpenCL C kernels driven from Python; cuda: cuda-python and the "
                        "same kernels as CUDA C++, for NVIDIA GPUs without OpenCL (Jetson); "
                        "see docs/cuda.md (default: the model's platform.backend, else "
                        "opencl)")
    p.add_argument("--fusion", choices=FUSION,
                   help="auto: chains of fusable GPU components run as one kernel; off: one "
                        "kernel per component (default: the model's platform.fusion, else auto)")
    p.add_argument("--place", action="append", type=_place, default=[], metavar="NAME=SIDE",
                   help="run flexible component NAME on SIDE: gpu, cpu or auto (chosen with "
                        "the others by the cost model); NAME may be a glob ('*=cpu'); "
                        "repeatable, a later option wins; overrides the model")


def _frames_in_flight(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, not {text!r}") from None
    if not 1 <= n <= MAX_FRAMES_IN_FLIGHT:
        raise argparse.ArgumentTypeError(f"must be 1 to {MAX_FRAMES_IN_FLIGHT}, not {n}")
    return n


def _place(text: str) -> tuple[str, str]:
    name, sep, side = text.partition("=")
    if not sep or not name.strip() or side.strip() not in ("gpu", "cpu", "auto"):
        raise argparse.ArgumentTypeError(
            f"{text!r}: write COMPONENT=gpu, COMPONENT=cpu or COMPONENT=auto")
    return name.strip(), side.strip()


def places(args) -> dict[str, str]:
    """--place options as {component or glob: side}, in the order of their last
    occurrence (a later option wins over an earlier glob: '*=cpu' then 'a=gpu')."""
    result: dict[str, str] = {}
    for name, side in getattr(args, "place", None) or []:
        result.pop(name, None)
        result[name] = side
    return result


def _sub(sub, name: str, summary: str, description: str) -> argparse.ArgumentParser:
    return sub.add_parser(name, help=summary, description=description,
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="gpucompgen",
        description="Generate GPU-aware pipe-and-filter systems (Campeanu et al.) as readable "
                    "Python programs over OpenCL (or CUDA): check a YAML system model, propagate sizes, "
                    "insert CPU<->GPU adapters, choose GPU settings, render the program.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    top.add_argument("--version", action="version", version=f"gpucompgen {__version__}")
    top.add_argument("--debug", action="store_true",
                     help="show tracebacks (of internal errors, and of a failing run)")
    sub = top.add_subparsers(dest="command", metavar="COMMAND", required=True,
                             title="commands")

    _add_model_commands(sub)
    _add_tool_commands(sub)
    _add_types_command(sub)
    add_replay_parser(sub, _sub, _common)

    sc = sub.add_parser("schema", help="print the JSON Schema of model files",
                        description="Print the JSON Schema of system models (or, with "
                                    "--types, of component-type files) for editors and tools.")
    sc.add_argument("--types", action="store_true", help="the schema of component-type files")
    return top


def _add_model_commands(sub) -> None:
    """build, run, check and plan: the commands that read a model and plan it."""
    b = _sub(sub, "build", "check a model and generate its program",
             "Check MODEL and write <system>.py and <system>_lib/ into the output folder,\n"
             "replacing what an earlier build wrote there. With --check or --diff nothing\n"
             "is written: they print a unified diff from the folder to a fresh build.")
    _common(b)
    b.add_argument("-o", "--output", type=Path, default=Path("generated"), metavar="DIR",
                   help="output folder (default: generated)")
    b.add_argument("--check", action="store_true",
                   help="write nothing; exit 1 and print the diff when DIR is stale, 0 when "
                        "current")
    b.add_argument("--diff", action="store_true",
                   help="write nothing; print the diff a build would make (exit 0)")
    b.add_argument("--overwrite", action="store_true",
                   help="replace files in the output folder that gpucompgen did not write")
    b.add_argument("--print-between-passes", action="store_true",
                   help="print the whole system IR after each pass (to stderr)")

    r = _sub(sub, "run", "build into a temporary folder and run",
             "Build MODEL into a temporary folder and run the program; the options below\n"
             "are the generated program's own and are passed to it. The build is planned\n"
             "for the OpenCL device it runs on (--device auto): on a device with unified\n"
             "host memory, such as PoCL, adapters are zero-copy.")
    _common(r, device_default="auto")
    # A throwaway build for this machine: plan for the device it runs on, not the model's
    # portable default that keeps checked-in output reproducible.
    r.set_defaults(device="auto")
    add_program_options(r)

    c = _sub(sub, "check", "run every check, generate nothing",
             "Check MODEL, print every problem, and a summary of the system.")
    _common(c)
    c.add_argument("--strict", action="store_true", help="warnings fail too")

    pl = _sub(sub, "plan", "show the system plan: order, sizes, adapters, settings",
              "Print the plan the generated program carries as a comment: the run order,\n"
              "each output's size, the adapters, the GPU settings and the bytes that cross\n"
              "between CPU and GPU per frame.")
    _common(pl)


def _add_tool_commands(sub) -> None:
    """tune, graph, bench and devices."""
    tu = _sub(sub, "tune", "time flexible components on the CPU and the device (profile)",
              "Run every flexible component of MODEL at the model's sizes, its CPU function\n"
              "and its kernel on the device of the model's backend (--backend: the OpenCL\n"
              "device PYOPENCL_CTX selects, or the CUDA device CUDA_DEVICE selects), for a few\n"
              "frames each, and time one copy between host and device. Writes the profile that\n"
              "'placement: auto' reads: the model's platform.profile, else\n"
              "tune/<system>.yaml beside the model.")
    tu.add_argument("model", type=Path, metavar="MODEL", help="the system model (.yaml)")
    tu.add_argument("-o", "--output", type=Path, metavar="FILE",
                    help="where to write the profile (default: the model's platform.profile, "
                         "else tune/<system>.yaml beside the model)")
    tu.add_argument("--frames", type=int, default=20, metavar="N",
                    help="frames timed per component and side (default: 20)")
    tu.add_argument("--backend", choices=BACKENDS,
                    help="the device API the kernels are timed on: opencl or cuda "
                         "(default: the model's platform.backend, else opencl)")

    g = _sub(sub, "graph", "draw the architecture (.dot, .svg, .png)",
             "Draw MODEL's architecture as in the paper's Figure 3: components (GPU-aware\n"
             "ones and their GPU ports marked), the generated adapters as nodes of their own,\n"
             "edges labelled with element type and size. --mode standard draws the\n"
             "Figure 1/2 variant, without adapters. .svg and .png need Graphviz's dot.")
    _common(g)
    g.add_argument("-o", "--output", type=Path, required=True, metavar="FILE",
                   help="where to write: FILE.dot, FILE.svg or FILE.png")

    be = sub.add_parser(
        "bench", help="standard vs GPU-aware chains of VerticalMirror (paper, Figures 9/10)",
        description="Generate chains of N VerticalMirror components in both modes, run them "
                    "on the device of --backend (the OpenCL device PYOPENCL_CTX selects, or "
                    "the CUDA device CUDA_DEVICE selects), and compare with a hand-written "
                    "loop of copies and launches, the device's copy-bandwidth bound and "
                    "OpenCV. Prints a "
                    "table; writes bench.csv and bench.png into the output folder.")
    be.add_argument("--sizes", default="1152x864,1152x1782", metavar="WxH,...",
                    help="frame sizes, width x height (default: the paper's 1152x864,1152x1782)")
    be.add_argument("--lengths", default="5,10,15,20,25", metavar="N,...",
                    help="chain lengths (default: 5,10,15,20,25)")
    be.add_argument("--frames", type=int, default=100, metavar="N",
                    help="frames timed per variant and chain (default: 100)")
    be.add_argument("-o", "--output", type=Path, default=Path("bench-out"),
                    help="folder for bench.csv and bench.png (default: bench-out)")
    be.add_argument("--no-opencv", action="store_true", help="leave out the OpenCV references")
    be.add_argument("--backend", choices=BACKENDS, default="opencl",
                    help="build and run the chains for opencl or cuda (default: opencl)")

    dv = sub.add_parser(
        "devices", help="list the OpenCL devices and which one a program would use",
        description="List every OpenCL platform and device, whether each compiles OpenCL C "
                    "(a trivial kernel is built on each), the PYOPENCL_CTX value that selects "
                    "it, and the device generated programs use by default. Exit 1 when no "
                    "device can compile kernels.")
    dv.add_argument("-q", "--quiet", action="store_true",
                    help="print nothing; only the exit code says whether a device is usable")


def _add_types_command(sub) -> None:
    """types: the component types a model can use (gst-inspect style)."""
    ty = sub.add_parser(
        "types", help="list the component types a model can use, or show one in full",
        description="List every component type available to a model: the library's, plus the "
                    "model's own with --model (name, kind, one line of description). With "
                    "NAME: its ports, parameters (types, defaults, ranges), requirements, the "
                    "forms it runs in and its description, as gst-inspect does for GStreamer.")
    ty.add_argument("name", nargs="?", metavar="NAME", help="the type to show in full")
    ty.add_argument("--model", type=Path, metavar="MODEL",
                    help="also the types this system model declares (its 'types:' files)")


INTERRUPTED = 130  # the exit code of a command stopped by Ctrl-C (128 + SIGINT), as shells give


def entry() -> None:
    """The `gpucompgen` command (and `python -m gpucompgen`): main's exit code.

    Stopped by Ctrl-C, it leaves with os._exit once its output is flushed: everything
    was freed on the way out of main, and Python's own exit, having seen the
    KeyboardInterrupt, sometimes killed the process with SIGINT instead (exit -2 for
    130, 3 runs in 15 that a SIGINT reached 'gpucompgen run' as it made its folder)."""
    code = main()
    if code == INTERRUPTED:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(INTERRUPTED)
    sys.exit(code)


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.command == "run" and args.frames is not None and args.frames < 0:
        parser().error("--frames must be 0 or more")  # tune and bench need 1 or more
    try:
        model = getattr(args, "model", None)
        if model is not None and not model.is_file():
            # The command line names no model file: a usage error, like argparse's own.
            what = "is a directory, not a model file" if model.is_dir() else \
                "not a regular file" if model.exists() else "no such file"
            print(f"gpucompgen {args.command}: error: {model}: {what}", file=sys.stderr)
            return 2
        code = COMMANDS[args.command](args)
        sys.stdout.flush()  # a full disk or closed pipe is found here, not at exit
        return code
    except (OutputError, UsageError) as exc:
        print(f"gpucompgen {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except GpucompgenError as exc:
        shown = _first(exc.diagnostics)
        for d in shown:
            print(d.format(), file=sys.stderr)
        counts = _counts(len(exc.errors), len(exc.diagnostics) - len(exc.errors))
        if len(shown) < len(exc.diagnostics):
            counts += f" ({len(exc.diagnostics) - len(shown):,} more not shown)"
        print(counts, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        # stopping: a repeat is ignored to the end (as run_program and the programs do).
        # Python puts SIGINT back to the default on its way out, so a second Ctrl-C, or
        # a SIGINT still pending, landing then killed this process (exit -2, not 130:
        # seen in CI when SIGINT reached 'gpucompgen run' as it made its folder)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        print("interrupted", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:  # `gpucompgen types | head`: the reader has all it wanted
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so that exiting does not flush into it
        return 0
    except OSError as exc:
        if exc.errno not in OUTPUT_ERRNOS or exc.filename is not None:
            return _internal_error(args, exc)
        # `gpucompgen schema > /dev/full`: an output problem, like any other (exit 2); the
        # writes that fail so are standard output's (files are written through OutputError)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so that exiting does not flush into it
        print(f"gpucompgen {args.command}: error: cannot write the output: "
              f"{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # an internal error: a bug in gpucompgen
        return _internal_error(args, exc)


# what writing to a full, over-quota or failing file or device raises
OUTPUT_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO)


def _internal_error(args, exc: BaseException) -> int:
    """An internal error: a bug in gpucompgen (the traceback with --debug)."""
    if args.debug:
        traceback.print_exc()
    print(f"gpucompgen: internal error: {type(exc).__name__}: {exc}\n"
          "  rerun with --debug for the traceback and please report it", file=sys.stderr)
    return 2


MAX_SHOWN = 200  # diagnostics printed at most (a file stops at 100); the count line counts all


def _first(diagnostics: list) -> list:
    """The first MAX_SHOWN diagnostics in file order, errors before warnings."""
    errors = [d for d in diagnostics if d.severity == "error"][:MAX_SHOWN]
    warnings = [d for d in diagnostics if d.severity != "error"][:MAX_SHOWN - len(errors)]
    return sorted(errors + warnings)


def _counts(errors: int, warnings: int) -> str:
    text = f"{errors:,} error{'s' if errors != 1 else ''} found"
    if warnings:
        text += f", {warnings:,} warning{'s' if warnings != 1 else ''}"
    return text


def _compile(args, out_dir: Path):
    from .build import compile_model
    from .options import BuildOptions

    dump = None
    if getattr(args, "print_between_passes", False):
        def dump(text):
            print(text, file=sys.stderr)
    options = BuildOptions(
        mode=args.mode, device=args.device, dump=dump, execution=args.execution,
        zero_copy=args.zero_copy, frames_in_flight=args.frames_in_flight, staging=args.staging,
        verify=True if args.debug else None, places=places(args),
        fusion=getattr(args, "fusion", None),
        # planned for the device at hand: its compiler checks every kernel file (the
        # programs run and replay start build them)
        compile_kernels=args.command in ("check", "build", "plan"),
        backend=getattr(args, "backend", None))
    result = compile_model(args.model, out_dir, options)
    for w in result.warnings:
        print(w.format(), file=sys.stderr)
    return result


def cmd_build(args) -> int:
    from .build import check_ownership, diff, write

    result = _compile(args, args.output)
    if args.check or args.diff:
        text = diff(result, args.output)
        if text:
            sys.stdout.write(text)
            if args.check:
                print(f"{args.output}: generated code for {args.model} is stale; "
                      f"run 'gpucompgen build {args.model} -o {args.output}'", file=sys.stderr)
                return 1
        elif args.check:
            print(f"{args.output}: up to date with {args.model}", file=sys.stderr)
        return 0
    if not args.overwrite:
        check_ownership(result, args.output)
    written = write(result, args.output)
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_run(args) -> int:
    def stop_building(signum, frame):
        # SIGTERM while building: remove the temporary folder on the way out (SIGINT
        # raises KeyboardInterrupt, which does the same)
        print("gpucompgen run: stopped by SIGTERM while building", file=sys.stderr)
        raise SystemExit(128 + signum)

    # installed before the folder exists and kept until run_program forwards SIGTERM
    previous = signal.signal(signal.SIGTERM, stop_building)
    tmp = None
    try:
        # a signal arriving while the folder is made or removed waits until that is done
        # (with TemporaryDirectory, a SIGINT inside its set-up or clean-up left the folder)
        with _signals_held():
            tmp = tempfile.mkdtemp(prefix="gpucompgen-run-")
        return _build_and_run(args, Path(tmp))
    finally:
        with _signals_held():
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
        # a signal held above lands here: SIGINT as KeyboardInterrupt, SIGTERM in
        # stop_building; both end the command with the folder gone (after a run stopped by
        # a signal, run_program leaves both ignored)
        if signal.getsignal(signal.SIGTERM) is not signal.SIG_IGN:
            signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def _signals_held():
    """SIGINT and SIGTERM are delivered after the block, not inside it."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _build_and_run(args, out: Path) -> int:
    from .build import write

    result = _compile(args, out)
    write(result, out)
    program = out / f"{result.system.name}.py"
    cmd = [sys.executable, str(program)]
    for flag, value in (("--frames", args.frames), ("--stats-json", args.stats_json),
                        ("--trace", args.trace),
                        ("--decisions", args.decisions),
                        ("--save-images", args.save_images), ("--digests", args.digests)):
        if value is not None:
            cmd += [flag, str(value)]
    for flag, values in (("--input", args.input), ("--output", args.output),
                         ("--set", args.set_params)):
        for value in values:
            cmd += [flag, value]
    if args.quiet:
        cmd.append("--quiet")
    if args.debug:
        cmd.append("--debug")
    if args.profile:
        cmd.append("--profile")
    if args.drop:
        cmd.append("--drop")
    return run_program(cmd)


FORWARDED_SIGNALS = (signal.SIGINT, signal.SIGTERM)
# A program still running this long after a forwarded signal is killed: its own limit is
# 1.5 s once its runtime has taken the signal over, after a start that can take seconds.
KILL_AFTER_SECONDS = 10.0

# What a program killed by a signal most likely met, for the message of 'gpucompgen run'.
_DEATHS = {
    signal.SIGSEGV: "a kernel (or other native code) accessed memory out of bounds; see "
                    "'Finding an out-of-bounds kernel' in docs/runtime.md",
    signal.SIGBUS: "a kernel (or other native code) accessed memory out of bounds; see "
                   "'Finding an out-of-bounds kernel' in docs/runtime.md",
    signal.SIGILL: "native code (a kernel or the OpenCL driver) crashed",
    signal.SIGFPE: "native code (a kernel or the OpenCL driver) crashed",
    signal.SIGABRT: "native code (the OpenCL driver?) aborted",
    signal.SIGKILL: "killed from outside, often by the out-of-memory killer (see "
                    "'dmesg')",
}


def _signal_name(signum: int) -> str:
    try:
        return f"{signal.Signals(signum).name} ({signum})"
    except ValueError:
        return f"signal {signum}"


def run_program(cmd: list[str], kill_after: float = KILL_AFTER_SECONDS) -> int:
    """Run a generated program, forward SIGINT and SIGTERM to it, take its exit code.

    The program stops cleanly on either (freeing everything, within about 2 s even when
    a kernel never ends) and ignores repeats while it stops: a terminal's Ctrl-C reaches
    it directly and through here. It starts with SIGINT ignored until its runtime takes
    the signal over (no KeyboardInterrupt traceback while it imports), so a signal is
    forwarded again every half second until it ends, and after kill_after seconds it is
    killed. A program killed by a signal is reported with the signal's name; the exit
    code is then 128 + its number, as a shell gives.
    """
    import contextlib
    import time

    received: list[int] = []
    sent_at = 0.0
    proc = None

    def forward(signum, frame):
        nonlocal sent_at
        if not received:
            received.append(signum)
            sent_at = time.monotonic()
        if proc is not None:  # else sent once it exists (the loop below re-sends)
            with contextlib.suppress(OSError):
                proc.send_signal(signum)

    previous = {s: signal.getsignal(s) for s in FORWARDED_SIGNALS}
    signal.signal(signal.SIGTERM, forward)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the program
    try:
        proc = subprocess.Popen(cmd, env=dict(os.environ))
    except BaseException:
        for s, h in previous.items():
            signal.signal(s, h)
        raise
    signal.signal(signal.SIGINT, forward)
    if received:
        with contextlib.suppress(OSError):
            proc.send_signal(received[0])
    killed = False
    with proc:
        try:
            while True:
                try:
                    code = proc.wait(timeout=0.5)
                    break
                except subprocess.TimeoutExpired:
                    if not received:
                        continue
                    if time.monotonic() - sent_at > kill_after:
                        proc.kill()
                        code, killed = proc.wait(), True
                        break
                    with contextlib.suppress(OSError):
                        proc.send_signal(received[0])
        finally:
            for s, h in previous.items():
                # stopping on a signal: a repeat (a second Ctrl-C) is ignored to the end, as
                # the program ignores it; restored, it would kill this process on its way out
                signal.signal(s, signal.SIG_IGN if received else h)
    if killed:
        print(f"gpucompgen run: error: the program did not stop within {kill_after:g} s of "
              f"{signal.Signals(received[0]).name}; killed it", file=sys.stderr)
        return 128 + received[0]
    if code >= 0:
        return code
    signum = -code
    if received and signum == received[0]:  # it had not taken the signal over yet
        print(f"gpucompgen run: the program was stopped by {_signal_name(signum)} while "
              "starting", file=sys.stderr)
    else:
        why = _DEATHS.get(signum, "")
        print(f"gpucompgen run: error: the program was killed by signal "
              f"{_signal_name(signum)}" + (f": {why}" if why else ""), file=sys.stderr)
    return 128 + signum


def cmd_check(args) -> int:
    """Every check, nothing written: all problems (main prints them) or a summary."""
    from .plan import summary_lines

    result = _compile(args, Path("generated"))
    for note in result.system.model.notes:
        print(note.format(), file=sys.stderr)
    status = "ok" if not result.warnings else "ok with warnings"
    print(f"{args.model}: {status}: system '{result.system.name}'")
    for line in summary_lines(result.system.plan):
        print(f"  {line}")
    if result.warnings:
        print(_counts(0, len(result.warnings)) + (" (--strict: failing)" if args.strict else ""),
              file=sys.stderr)
        if args.strict:
            return 1
    return 0


def cmd_plan(args) -> int:
    from .plan import plan_lines

    result = _compile(args, Path("generated"))
    for line in plan_lines(result.system.plan):
        print(line)
    return 0


def cmd_tune(args) -> int:
    from .model import load_system
    from .runtime import PipelineError
    from .tune import FunctionFailed, output_path, tune, write_profile

    if args.frames < 1:
        print("gpucompgen tune: error: --frames must be 1 or more", file=sys.stderr)
        return 2
    out = output_path(args.model, load_system(args.model), args.output)  # before measuring
    try:
        groups: list = []
        text, rows = tune(args.model, args.frames, str(args.model), groups, args.backend)
    except FunctionFailed as exc:  # the user's code failed, as in a failed run
        print(f"gpucompgen tune: error: {exc}", file=sys.stderr)
        return 1
    except PipelineError as exc:
        print(f"gpucompgen tune: error: {exc}", file=sys.stderr)
        return 2
    write_profile(out, text)
    width = max([len(r[0]) for r in rows] + [9])
    print(f"{'component':<{width}}  {'CPU us':>10}  {'GPU us':>10}")
    for name, _, _, cpu_us, gpu_us in rows:
        print(f"{name:<{width}}  {cpu_us:>10,.1f}  {gpu_us:>10,.1f}")
    for name, members, _, fused_us, apart_us in groups:
        verdict = "kept" if fused_us < apart_us else "refused: no faster than its members"
        print(f"group {name} ({', '.join(members)}): {fused_us:,.1f} us as one kernel, "
              f"{apart_us:,.1f} us apart, {verdict}")
    print(f"wrote {out}")
    return 0


def cmd_graph(args) -> int:
    from .graph import FORMATS, GraphvizMissing, write_graph

    if args.output.suffix.lower() not in FORMATS:
        print(f"gpucompgen graph: error: {args.output}: unknown format; the file name must end "
              f"in {', '.join(FORMATS)}", file=sys.stderr)
        return 2
    result = _compile(args, Path("generated"))
    try:
        write_graph(result.system, args.output)
    except GraphvizMissing as exc:
        print(f"gpucompgen graph: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}")
    return 0


def cmd_bench(args) -> int:
    from . import bench
    from .runtime import PipelineError

    try:
        bench.run_bench(bench.parse_sizes(args.sizes), bench.parse_lengths(args.lengths),
                        args.frames, args.output, opencv=not args.no_opencv,
                        backend=args.backend)
    except (bench.BenchError, PipelineError) as exc:
        print(f"gpucompgen bench: error: {exc}", file=sys.stderr)
        return 2
    return 0


def cmd_devices(args) -> int:
    from .runtime import NO_DEVICE_HINT, PipelineError, select_device, survey_devices

    statuses = survey_devices()
    try:
        chosen = select_device(statuses)
        problem = next((s.problem for s in statuses if s.device == chosen), None)
        if problem:
            problem = (f"PYOPENCL_CTX={os.environ.get('PYOPENCL_CTX')} selects "
                       f"'{chosen.name.strip()}', which cannot compile kernels: {problem}")
    except PipelineError as exc:
        chosen, problem = None, str(exc)
    cuda_devices = _cuda_devices()
    if not args.quiet:
        for s in statuses:
            state = "ok" if s.problem is None else f"cannot compile kernels: {s.problem}"
            mark = "*" if s.device == chosen else " "
            print(f"{mark} PYOPENCL_CTX={s.ctx:<5} {s.device.platform.name.strip()} / "
                  f"{s.device.name.strip()}: {state}")
        if problem:
            print(f"gpucompgen devices: error: {problem}", file=sys.stderr)
        elif chosen is not None:
            how = "PYOPENCL_CTX" if os.environ.get("PYOPENCL_CTX") else "first usable device"
            print(f"generated programs use '{chosen.name.strip()}' ({how}, marked *)")
        if not statuses:
            print(f"no OpenCL device found; {NO_DEVICE_HINT}", file=sys.stderr)
        for ordinal, text, cuda_problem in cuda_devices:
            print(f"  CUDA_DEVICE={ordinal:<3} CUDA / {text}: "
                  f"{'ok' if cuda_problem is None else cuda_problem}")
        if cuda_devices:
            print("programs built with --backend cuda use CUDA_DEVICE (default 0)")
    # No OpenCL device is fine where CUDA is (a Jetson); a PYOPENCL_CTX that selects nothing
    # usable is the user's mistake whatever else there is
    usable_cuda = any(p is None for _, _, p in cuda_devices)
    return 1 if problem and (os.environ.get("PYOPENCL_CTX") or not usable_cuda) else 0


def _cuda_devices() -> list:
    """The CUDA devices (for --backend cuda), [] without cuda-python or a driver."""
    from .backend import runtime_module

    try:
        cuda = runtime_module("cuda")
    except ImportError:
        return []
    return cuda.survey_devices()


def cmd_schema(args) -> int:
    from .schema import MODEL, TYPES, schema_text

    sys.stdout.write(schema_text(TYPES if args.types else MODEL))
    return 0


def cmd_types(args) -> int:
    """The types available (library, and the model's own with --model), or one in full."""
    from .errors import did_you_mean
    from .model import LIBRARY_PREFIX, library_types, load_system
    from .typeinfo import details, listing

    library = library_types()
    types = load_system(args.model).types if args.model else library
    # a library type the model's own shadows is listed as the model writes it: lib.Name
    types = {**types, **{f"{LIBRARY_PREFIX}{n}": t for n, t in library.items()
                         if types.get(n) is not t}}
    name = args.name
    if name is not None and name.startswith(LIBRARY_PREFIX) and \
            name[len(LIBRARY_PREFIX):] in library:
        name = name[len(LIBRARY_PREFIX):]
        types = library  # the library's type, even where a model's own one shadows it
    if name is None:
        lines = listing(types)
    elif name in types:
        lines = details(types[name])
    else:
        where = f"available to {args.model}" if args.model else "in the library"
        # the name as Python writes it: escape sequences and line breaks stay visible
        hint = did_you_mean(name, types)
        if not args.model:
            hint += " (a model's own types are listed with --model MODEL)"
        print(f"gpucompgen types: error: no component type {name!r} {where}\n"
              f"  hint: {hint}", file=sys.stderr)
        return 1
    print("\n".join(lines))
    return 0


COMMANDS = {"build": cmd_build, "run": cmd_run, "check": cmd_check, "plan": cmd_plan,
            "tune": cmd_tune, "types": cmd_types,
            "graph": cmd_graph, "bench": cmd_bench, "devices": cmd_devices, "schema": cmd_schema,
            "replay": lambda args: cmd_replay(args, _compile)}
