"""gpucompgen's command line: build, run, check, plan.

Exit codes as in black and datamodel-codegen: 0 ok, 1 problems found (or stale output with
--check), 2 usage or internal error.  A user sees a traceback only with --debug.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

from . import __version__
from .errors import GpucompgenError
from .model import EXECUTIONS, ZERO_COPY
from .passes import MODES


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", type=Path, help="system model (.yaml)")
    p.add_argument("--mode", choices=MODES, default="gpu-aware",
                   help="gpu-aware: GPU ports and generated adapters (default); standard: every "
                        "GPU-aware component copies its own data, as in the paper's Section II")
    p.add_argument("--device", metavar="PROFILE",
                   help="device facts to plan for: a profile name, or 'auto' for the OpenCL "
                        "device PYOPENCL_CTX selects (default: the model's platform.device)")
    p.add_argument("--execution", choices=EXECUTIONS,
                   help="parallel: independent GPU work on separate queues, waiting only where "
                        "the host reads a result; sequential: one queue, blocking copies "
                        "(default: the model's platform.execution, else parallel)")
    p.add_argument("--zero-copy", choices=ZERO_COPY, dest="zero_copy",
                   help="zero-copy adapters (map host-visible memory instead of copying): auto "
                        "follows the device's unified host memory (default: the model's "
                        "platform.zero_copy, else auto)")


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="gpucompgen",
        description="Generate GPU-aware pipe-and-filter systems (Campeanu et al.) as readable "
                    "Python + pyopencl programs.")
    top.add_argument("--version", action="version", version=f"gpucompgen {__version__}")
    top.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    sub = top.add_subparsers(dest="command", metavar="COMMAND", required=True)

    b = sub.add_parser("build", help="check a model and generate its program",
                       description="Check MODEL and write <system>.py and <system>_lib/ "
                                   "into the output folder.")
    _common(b)
    b.add_argument("-o", "--output", type=Path, default=Path("generated"),
                   help="output folder (default: generated)")
    b.add_argument("--check", action="store_true",
                   help="write nothing; exit 1 and show a diff when the output is stale")
    b.add_argument("--diff", action="store_true", help="show what would change; write nothing")
    b.add_argument("--overwrite", action="store_true",
                   help="replace files in the output folder that gpucompgen did not write")
    b.add_argument("--print-between-passes", action="store_true",
                   help="dump the system after each pass (to stderr)")

    r = sub.add_parser("run", help="build into a temporary folder and run",
                       description="Build MODEL into a temporary folder and run the program.")
    _common(r)
    r.add_argument("--frames", type=int, default=None, metavar="N",
                   help="stop after N frames (default: until a source ends its stream)")

    c = sub.add_parser("check", help="run every check, generate nothing",
                       description="Check MODEL and print every problem and a summary.")
    _common(c)
    c.add_argument("--strict", action="store_true", help="warnings fail too")

    pl = sub.add_parser("plan", help="show the system plan: order, sizes, adapters, settings")
    _common(pl)
    return top


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except GpucompgenError as exc:
        for d in exc.diagnostics:
            print(d.format(), file=sys.stderr)
        n = len(exc.errors)
        print(f"{n} error{'s' if n != 1 else ''} found", file=sys.stderr)
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


def _compile(args, out_dir: Path):
    from .build import compile_model

    dump = None
    if getattr(args, "print_between_passes", False):
        def dump(text):
            print(text, file=sys.stderr)
    result = compile_model(args.model, out_dir, args.mode, args.device, dump,
                           execution=args.execution, zero_copy=args.zero_copy)
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
        program = out / f"{result.system.model.name}.py"
        cmd = [sys.executable, str(program)]
        if args.frames is not None:
            cmd += ["--frames", str(args.frames)]
        if args.debug:
            cmd.append("--debug")
        env = dict(os.environ)
        return subprocess.call(cmd, env=env)


def cmd_check(args) -> int:
    result = _compile(args, Path("generated"))
    from .render import plan_lines

    print(f"{args.model}: ok: system '{result.system.model.name}'")
    for line in plan_lines(result.system):
        print(f"  {line}")
    if args.strict and result.warnings:
        print(f"{len(result.warnings)} warning(s) with --strict", file=sys.stderr)
        return 1
    return 0


def cmd_plan(args) -> int:
    from .render import plan_lines

    result = _compile(args, Path("generated"))
    for line in plan_lines(result.system):
        print(line)
    return 0


COMMANDS = {"build": cmd_build, "run": cmd_run, "check": cmd_check, "plan": cmd_plan}
