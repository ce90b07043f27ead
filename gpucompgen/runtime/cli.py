"""The command line of every generated program."""

from __future__ import annotations

import argparse
import faulthandler
import functools
import os
import sys
import threading
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path

from .errors import PipelineError, Stopped
from .lifecycle import Result
from .monitor import Monitor
from .overrides import OverrideError, Param, parse_overrides
from .signals import GRACE_SECONDS, StopOnSignals, running_kernels


def add_program_options(parser: argparse.ArgumentParser) -> None:
    """The generated program's options; 'gpucompgen run' offers the same and passes them on."""
    parser.add_argument("--frames", type=int, default=None, metavar="N",
                        help="stop after N frames (default: until a source ends its stream)")
    parser.add_argument("-q", "--quiet", action=_Quiet, nargs=0, default=False,
                        help="print nothing but errors (no progress, decisions, summary "
                             "or warnings)")
    parser.add_argument("--stats-json", metavar="FILE", type=_file_name,
                        help="time every execute() and transfer() and write frames, "
                             "per-frame and per-component timings to FILE as JSON")
    parser.add_argument("--decisions", metavar="FILE", type=_file_name,
                        help="write the sinks' decisions to FILE: JSON lines if it ends in "
                             ".jsonl or .json, else one text line per frame")
    parser.add_argument("--save-images", metavar="DIR", type=_file_name,
                        help="write the sinks' images (masks, annotated frames) as PNG to DIR")
    parser.add_argument("--digests", metavar="FILE",
                        help="write, per frame, a digest of what every sink received and "
                             "what it reported, as JSON lines to FILE (gpucompgen replay "
                             "compares runs with them)")
    parser.add_argument("--profile", action="store_true",
                        help="time every kernel and copy with OpenCL profiling events and "
                             "count the bytes moved between CPU and GPU (printed at the end)")
    parser.add_argument("--drop", action="store_true",
                        help="sources read in their own thread and keep only the newest "
                             "frame: frames the pipeline cannot keep up with are dropped "
                             "(counted in the summary and --stats-json), as live cameras do")
    parser.add_argument("--trace", metavar="FILE",
                        help="write a Chrome trace-event JSON of the run to FILE (open it in "
                             "ui.perfetto.dev or chrome://tracing): a track per component "
                             "and per device queue, each frame followable")
    parser.add_argument("--input", action="append", default=[], metavar="NAME=URI",
                        help="read source NAME from URI: a folder or glob of images, a video "
                             "file, v4l2:///dev/videoN, csi://N, device:N, rtsp://..., "
                             "mcap://FILE?topic=T or a ROS 2 bag folder; repeatable")
    parser.add_argument("--output", action="append", default=[], metavar="NAME=URI",
                        help="write sink NAME's frames to URI: display://, a video file "
                             "(out.mp4), a folder (out/) or mcap://FILE; repeatable")
    parser.add_argument("--set", action="append", default=[], metavar="NAME.PARAM=VALUE",
                        dest="set_params",
                        help="change a parameter that no size depends on (a threshold) "
                             "without a rebuild, checked against its type; repeatable")


class _Quiet(argparse.Action):
    """-q: print nothing but errors, so also no Python warnings (numpy's RuntimeWarning of
    a component's arithmetic printed under -q); set as the option is read."""

    def __call__(self, parser, namespace, values, option_string=None):
        warnings.simplefilter("ignore")
        setattr(namespace, self.dest, True)


def _file_name(text: str) -> str:
    """A file or folder name given to an option: an empty one names nothing (Path('') is
    the current folder, which was then refused as 'is a folder')."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty name; name a file")
    return text


def output_file_problem(path: Path) -> str:
    """Why a file could not be written there, or '' (the folder exists, the path is not one)."""
    if path.is_dir():
        return "is a folder; name a file"
    folder = path.parent
    if not folder.is_dir():
        return f"folder {folder} does not exist"
    if not os.access(folder, os.W_OK):
        return f"folder {folder} is not writable"
    return ""


def main(run: Callable[..., Result], description: str, argv: list[str] | None = None,
         params: dict[str, Param] | None = None) -> int:
    """Command line of a generated program: run it, print errors without tracebacks.

    Exit codes: 0 done, 1 a component or the device failed, 2 usage, 130 SIGINT,
    143 SIGTERM (128 + the signal's number).  params: the program's PARAMS table, which
    --set, --input and --output are checked against.
    """
    parser = argparse.ArgumentParser(
        description=description,
        epilog="Exit codes: 0 done, 1 a component or the device failed, 2 usage, "
               "130 on SIGINT, 143 on SIGTERM (a run blocked in OpenCL, e.g. by a kernel "
               f"that never ends, is given up {GRACE_SECONDS:g} s after the signal). Select "
               "the OpenCL device with PYOPENCL_CTX.")
    add_program_options(parser)
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    args = parser.parse_args(argv)
    if args.frames is not None and args.frames < 0:
        parser.error("--frames must be 0 or more")
    for flag, value in (("--stats-json", args.stats_json), ("--trace", args.trace),
                        ("--digests", args.digests)):
        if value is not None:  # found out before the run, not after it
            problem = output_file_problem(Path(value))
            if problem:
                parser.error(f"{flag} {value}: {problem}")
    try:
        overrides = parse_overrides(params or {}, args.set_params, args.input, args.output)
    except OverrideError as exc:
        parser.error(str(exc))
    monitor = Monitor(progress=False if args.quiet else None, stats_path=args.stats_json,
                      options={"decisions": args.decisions, "save_images": args.save_images,
                               "quiet": args.quiet, "drop": args.drop,
                               "digests": args.digests},
                      trace_path=args.trace)
    if args.debug:
        faulthandler.enable()  # a crash (SIGSEGV in a kernel) prints where the host was
    # a trace needs the device's profiling events
    call = functools.partial(run, frames=args.frames, monitor=monitor,
                             profile=args.profile or bool(args.trace),
                             **({"params": overrides} if overrides else {}))
    try:
        if threading.current_thread() is threading.main_thread():
            stopper = StopOnSignals(monitor)
            stopper.install()
            try:
                result = stopper.run(call)
            finally:
                stopper.restore()
        else:  # signal handlers can only be set in the main thread
            result = call()
    except Stopped as exc:
        freed = ("every other component was freed" if getattr(exc, "free_failures", 0)
                 else "every component was freed")
        print(f"stopped by {exc} after {monitor.frames} frame(s); {freed}", file=sys.stderr)
        _exit_now_if_something_would_wait(monitor, 128 + exc.signum)
        return 128 + exc.signum
    except KeyboardInterrupt:  # raised by a component itself: SIGINT is handled above
        print(f"interrupted after {monitor.frames} frame(s)", file=sys.stderr)
        return 130
    except PipelineError as exc:
        if args.debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except (Exception, GeneratorExit) as exc:  # a bug outside any component: no traceback
        if args.debug:
            traceback.print_exc()
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        print("  (run with --debug for the traceback)", file=sys.stderr)
        return 1
    if args.profile and result.profile is not None:
        print(result.profile.report(result.frames), file=sys.stderr)
    if not args.quiet:
        dropped = monitor.dropped_frames()
        print(f"processed {result.frames} frame(s)"
              + (f"; dropped {sum(dropped.values())} ("
                 + ", ".join(f"{k} {v}" for k, v in dropped.items()) + ")" if args.drop else ""),
              file=sys.stderr)
    return 1 if monitor.stats_failed else 0


def _exit_now_if_something_would_wait(monitor: Monitor, code: int) -> None:
    """After a stop by a signal the program must end now: with a kernel still running (a
    driver may wait for it as the interpreter releases the queue) or a thread a component
    started and left running (the interpreter waits for those), exit without waiting."""
    running = running_kernels(monitor.parts)
    threads = [t.name for t in threading.enumerate()
               if t is not threading.current_thread() and not t.daemon and t.is_alive()]
    if not running and not threads:
        return
    if running:
        print(f"note: the last command of {', '.join(running)} is still running on the "
              "device (a kernel that never ends?); exiting without waiting for it",
              file=sys.stderr)
    if threads:
        print(f"note: thread(s) {', '.join(threads)} started by a component are still "
              "running; exiting without waiting for them", file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
