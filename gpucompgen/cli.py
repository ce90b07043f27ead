"""gpucompgen's command line: build, run, check, plan, graph, bench, devices, schema.

Exit codes as in black and datamodel-codegen: 0 ok, 1 problems found (or stale output with
--check), 2 usage or internal error.  A user sees a traceback only with --debug.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

from . import __version__
from .errors import GpucompgenError, OutputError
from .ir import MODES
from .model import EXECUTIONS, FUSION, ZERO_COPY
from .runtime import add_program_options

EPILOG = """\
exit codes: 0 ok; 1 problems in the model, stale output with --check, or a failed run;
2 usage or internal error (and a missing Graphviz for graph).
A run stopped by SIGINT or SIGTERM exits 130 or 143.

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
                        f"kernels; see 'gpucompgen devices'); default: {device_default}")
    p.add_argument("--execution", choices=EXECUTIONS,
                   help="parallel: independent GPU work on separate queues, waiting only where "
                        "the host reads a result; sequential: one queue, blocking copies "
                        "(default: the model's platform.execution, else parallel)")
    p.add_argument("--zero-copy", choices=ZERO_COPY, dest="zero_copy",
                   help="zero-copy adapters (map host-visible memory instead of copying): auto "
                        "follows the device's unified host memory (default: the model's "
                        "platform.zero_copy, else auto)")
    p.add_argument("--fusion", choices=FUSION,
                   help="auto: chains of fusable GPU components run as one kernel; off: one "
                        "kernel per component (default: the model's platform.fusion, else auto)")


def _sub(sub, name: str, summary: str, description: str) -> argparse.ArgumentParser:
    return sub.add_parser(name, help=summary, description=description,
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="gpucompgen",
        description="Generate GPU-aware pipe-and-filter systems (Campeanu et al.) as readable "
                    "Python + pyopencl programs: check a YAML system model, propagate sizes, "
                    "insert CPU<->GPU adapters, choose GPU settings, render the program.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    top.add_argument("--version", action="version", version=f"gpucompgen {__version__}")
    top.add_argument("--debug", action="store_true",
                     help="show tracebacks (of internal errors, and of a failing run)")
    sub = top.add_subparsers(dest="command", metavar="COMMAND", required=True,
                             title="commands")

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
                    "on the OpenCL device (PYOPENCL_CTX), and compare with a hand-written "
                    "pyopencl loop, the device's copy-bandwidth bound and OpenCV. Prints a "
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

    dv = sub.add_parser(
        "devices", help="list the OpenCL devices and which one a program would use",
        description="List every OpenCL platform and device, whether each compiles OpenCL C "
                    "(a trivial kernel is built on each), the PYOPENCL_CTX value that selects "
                    "it, and the device generated programs use by default. Exit 1 when no "
                    "device can compile kernels.")
    dv.add_argument("-q", "--quiet", action="store_true",
                    help="print nothing; only the exit code says whether a device is usable")

    sc = sub.add_parser("schema", help="print the JSON Schema of model files",
                        description="Print the JSON Schema of system models (or, with "
                                    "--types, of component-type files) for editors and tools.")
    sc.add_argument("--types", action="store_true", help="the schema of component-type files")
    return top


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if getattr(args, "frames", None) is not None and args.frames < 0:
        parser().error("--frames must be 0 or more")
    try:
        model = getattr(args, "model", None)
        if model is not None and not model.is_file():
            # The command line names no model file: a usage error, like argparse's own.
            what = "is a directory, not a model file" if model.is_dir() else "no such file"
            print(f"gpucompgen {args.command}: error: {model}: {what}", file=sys.stderr)
            return 2
        return COMMANDS[args.command](args)
    except OutputError as exc:
        print(f"gpucompgen {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except GpucompgenError as exc:
        for d in exc.diagnostics:
            print(d.format(), file=sys.stderr)
        print(_counts(len(exc.errors), len(exc.diagnostics) - len(exc.errors)),
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # an internal error: a bug in gpucompgen
        if args.debug:
            traceback.print_exc()
        print(f"gpucompgen: internal error: {type(exc).__name__}: {exc}\n"
              "  rerun with --debug for the traceback and please report it", file=sys.stderr)
        return 2


def _counts(errors: int, warnings: int) -> str:
    text = f"{errors} error{'s' if errors != 1 else ''} found"
    if warnings:
        text += f", {warnings} warning{'s' if warnings != 1 else ''}"
    return text


def _compile(args, out_dir: Path):
    from .build import compile_model

    dump = None
    if getattr(args, "print_between_passes", False):
        def dump(text):
            print(text, file=sys.stderr)
    result = compile_model(args.model, out_dir, args.mode, args.device, dump,
                           execution=args.execution, zero_copy=args.zero_copy,
                           verify=True if args.debug else None,
                           fusion=getattr(args, "fusion", None))
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
    from .build import write

    with tempfile.TemporaryDirectory(prefix="gpucompgen-run-") as tmp:
        out = Path(tmp)
        result = _compile(args, out)
        write(result, out)
        program = out / f"{result.system.name}.py"
        cmd = [sys.executable, str(program)]
        for flag, value in (("--frames", args.frames), ("--stats-json", args.stats_json),
                            ("--decisions", args.decisions),
                            ("--save-images", args.save_images)):
            if value is not None:
                cmd += [flag, str(value)]
        if args.quiet:
            cmd.append("--quiet")
        if args.debug:
            cmd.append("--debug")
        if args.profile:
            cmd.append("--profile")
        # The program stops cleanly on SIGINT (which a terminal sends it too) and SIGTERM
        # (forwarded here); wait for it to free everything and take its exit code.
        with subprocess.Popen(cmd, env=dict(os.environ)) as proc:
            previous = signal.signal(signal.SIGTERM,
                                     lambda signum, frame: proc.send_signal(signum))
            try:
                while True:
                    try:
                        return proc.wait()
                    except KeyboardInterrupt:
                        continue
            finally:
                signal.signal(signal.SIGTERM, previous)


def cmd_check(args) -> int:
    """Every check, nothing written: all problems (main prints them) or a summary."""
    from .plan import summary_lines

    result = _compile(args, Path("generated"))
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
                        args.frames, args.output, opencv=not args.no_opencv)
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
    return 1 if problem else 0


def cmd_schema(args) -> int:
    from .schema import MODEL, TYPES, schema_text

    sys.stdout.write(schema_text(TYPES if args.types else MODEL))
    return 0


COMMANDS = {"build": cmd_build, "run": cmd_run, "check": cmd_check, "plan": cmd_plan,
            "graph": cmd_graph, "bench": cmd_bench, "devices": cmd_devices, "schema": cmd_schema}
