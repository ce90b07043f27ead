"""The 'gpucompgen replay' command: its options, and building the model once for all."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path

from ..errors import UsageError

DESCRIPTION = """\
Run MODEL over every RECORDING (a folder or glob of images, a video file, an MCAP file,
a ROS 2 bag, or any source URI that --input takes), each in a process of its own,
--slots at a time, and write into DIR:
  DIR/program/              the program, built once for all recordings
  DIR/<recording>/          summary.json (status, frames, timings, per sink and frame a
                            digest of what it received and what it reported),
                            digests.jsonl, stats.json, stderr.txt (images/ with
                            --save-outputs)
  DIR/summary.json          every recording's status and the totals
A re-run with the same DIR skips recordings already complete for the same build. With
--baseline OLD_DIR, prints where each recording diverged from an earlier replay: which
sink, from which frame, and how.
exit codes: 0 all complete and nothing diverged; 1 a recording failed or was partial, or
something diverged; 2 usage; 130 Ctrl-C (the summaries written so far stay)."""


def add_replay_parser(sub, make: Callable, common: Callable) -> argparse.ArgumentParser:
    rp = make(sub, "replay", "run a model over many recordings and compare with a baseline",
              DESCRIPTION)
    common(rp, device_default="auto")
    rp.set_defaults(device="auto")
    rp.add_argument("recordings", nargs="+", metavar="RECORDING",
                    help="recordings to replay: paths or source URIs")
    rp.add_argument("--out", type=Path, required=True, metavar="DIR",
                    help="output folder (created; a re-run resumes it)")
    rp.add_argument("--source", metavar="NAME",
                    help="the source component fed with each recording (default: the model's "
                         "only source)")
    rp.add_argument("--topic", metavar="TOPIC",
                    help="the image topic of MCAP files and ROS 2 bags (default: their only "
                         "image topic)")
    rp.add_argument("--slots", type=_positive_int, default=1, metavar="N",
                    help="recordings replayed at the same time (default: 1; each is a process "
                         "with its own device context)")
    rp.add_argument("--frames", type=_positive_int, metavar="N",
                    help="replay at most N frames of each recording")
    rp.add_argument("--timeout", type=_positive_float, metavar="SECONDS",
                    help="give up a recording after SECONDS (reported as failed or partial)")
    rp.add_argument("--save-outputs", action="store_true",
                    help="also keep the sinks' images (DIR/<recording>/images)")
    rp.add_argument("--baseline", type=Path, metavar="OLD_DIR",
                    help="compare every recording with an earlier replay's output folder")
    rp.add_argument("--engine", choices=("local", "ray"), default="local",
                    help="local: processes on this machine (default); ray: one Ray task per "
                         "recording (pip install 'gpucompgen[ray]')")
    rp.add_argument("--address", metavar="ADDR",
                    help="with --engine ray: the cluster to join (default: a local Ray "
                         "instance with --slots CPUs)")
    rp.add_argument("--num-gpus", type=float, default=0.0, metavar="N",
                    help="with --engine ray: GPUs each task asks for (e.g. 0.5 shares one GPU "
                         "between two tasks)")
    rp.add_argument("--resource", action="append", default=[], type=_resource,
                    metavar="NAME=AMOUNT",
                    help="with --engine ray: a custom resource each task asks for (e.g. "
                         "opencl=1 where the nodes declare an 'opencl' resource); repeatable")
    return rp


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, not {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, not {n}")
    return n


def _positive_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, not {text!r}") from None
    if not x > 0 or x == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, not {text}")
    return x


def _resource(text: str) -> tuple[str, float]:
    name, sep, amount = text.partition("=")
    try:
        value = float(amount)
    except ValueError:
        value = -1.0
    if not sep or not name.strip() or not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: write NAME=AMOUNT, e.g. opencl=1")
    return name.strip(), value


def cmd_replay(args, compile_model: Callable) -> int:
    """compile_model(args, out_dir) -> BuildResult: the CLI's own build (same options)."""
    from ..build import write
    from ..ir import ComponentNode
    from . import ReplayOptions, replay

    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: is a file; name a folder")
    for recording in args.recordings:
        if "://" not in recording and not recording.startswith("device:") \
                and not any(ch in recording for ch in "*?[") and not Path(recording).exists():
            raise UsageError(f"recording {recording}: no such file or folder")
    if args.baseline is not None and not (args.baseline / "summary.json").is_file():
        raise UsageError(f"--baseline {args.baseline}: no summary.json there "
                         "(name the --out folder of an earlier replay)")
    if args.engine == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            from .engines import ray_missing_message

            raise UsageError(ray_missing_message()) from None
    elif args.address or args.num_gpus or args.resource:
        raise UsageError("--address, --num-gpus and --resource go with --engine ray")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out {out}: {exc.strerror}") from None
    result = compile_model(args, out / "program")
    sources = sorted(name for name, node in result.system.nodes.items()
                     if isinstance(node, ComponentNode) and not node.inputs)
    source = args.source
    if source is None:
        if len(sources) != 1:
            raise UsageError(f"the model has {len(sources)} sources ({', '.join(sources)}): "
                             "name the one each recording feeds with --source")
        source = sources[0]
    elif source not in sources:
        raise UsageError(f"--source {source}: not a source of the model; its sources: "
                         f"{', '.join(sources) or 'none'}")
    write(result, out / "program")
    program = out / "program" / f"{result.system.name}.py"
    options = ReplayOptions(
        recordings=list(args.recordings), out=out, source=source, topic=args.topic,
        slots=args.slots, frames=args.frames, timeout=args.timeout,
        save_outputs=args.save_outputs, baseline=args.baseline, engine=args.engine,
        address=args.address, num_gpus=args.num_gpus, resources=dict(args.resource))
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    return replay(program, options, sys.stderr)
