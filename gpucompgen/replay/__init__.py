"""gpucompgen replay: one model over many recordings, a summary each, compared with a baseline.

    gpucompgen replay MODEL REC... --out DIR [--source NAME] [--topic T] [--slots N]
                      [--baseline OLD_DIR] [--engine local|ray] [--address ADDR]

The model is built once (into DIR/program) for the device the recordings are replayed on;
then every recording runs through it in a process of its own (engines.py), several at a
time, and leaves DIR/<recording>/summary.json (jobs.py). DIR/summary.json lists them all
with totals; with --baseline, what diverged from an earlier replay (compare.py). A re-run
with the same DIR skips the recordings whose summary is complete for the same build.

Exit codes: 0 every recording complete (and, with --baseline, nothing diverged); 1 a
recording failed or was partial, or something diverged; 2 usage; 130 Ctrl-C.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from .compare import compare_runs, load_run
from .jobs import Job, folder_name, read_summary, recording_uri

RUN_SUMMARY = "summary.json"


@dataclass
class ReplayOptions:
    recordings: list[str]
    out: Path
    source: str
    topic: str | None = None
    slots: int = 1
    frames: int | None = None
    timeout: float | None = None
    save_outputs: bool = False
    baseline: Path | None = None
    engine: str = "local"
    address: str | None = None
    num_gpus: float = 0.0
    resources: dict[str, float] = field(default_factory=dict)


def build_digest(program: Path) -> str:
    """A digest of the program and its lib folder: a summary made by another build is stale."""
    digest = hashlib.blake2b(digest_size=8)
    files = [program, *sorted((program.parent / f"{program.stem}_lib").rglob("*"))]
    for path in files:
        if path.is_file():
            digest.update(path.relative_to(program.parent).as_posix().encode() + b"\0")
            digest.update(path.read_bytes())
    return digest.hexdigest()


def plan_jobs(options: ReplayOptions) -> list[Job]:
    taken: set[str] = set()
    return [Job(recording=rec, uri=recording_uri(rec, options.topic),
                folder=folder_name(rec, taken), source=options.source, frames=options.frames,
                save_outputs=options.save_outputs, timeout=options.timeout)
            for rec in options.recordings]


class Progress:
    """A bar with the recordings done and an ETA on a terminal; a line per recording else."""

    def __init__(self, total: int, stream: TextIO | None = None):
        self.total, self.done = total, 0
        self.stream = stream if stream is not None else sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.started = time.monotonic()

    def skipped(self, summary: dict[str, Any]) -> None:
        self.total -= 1
        self._line(f"skipped {summary['recording']}: complete in an earlier run")

    def finished(self, summary: dict[str, Any]) -> None:
        self.done += 1
        elapsed = time.monotonic() - self.started
        eta = elapsed / self.done * (self.total - self.done) if self.done else 0.0
        status = summary["status"]
        reason = summary.get("reason", "").splitlines()
        why = f" ({reason[-1][:120]})" if reason and status != "complete" else ""
        width = 24
        filled = width * self.done // max(self.total, 1)
        bar = "#" * filled + "-" * (width - filled)
        self._line(f"[{bar}] {self.done}/{self.total} {summary['recording']}: {status}, "
                   f"{summary['frames']} frames in {summary['seconds']:.1f} s{why}; "
                   f"ETA {_clock(eta)}")

    def _line(self, text: str) -> None:
        self.stream.write(("\r\033[K" if self.tty else "") + text + "\n")
        self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = round(seconds)
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def replay(program: Path, options: ReplayOptions, stream: TextIO | None = None) -> int:
    """Run every recording through the built program; write the summaries; the exit code."""
    from .engines import Interrupted, run_local, run_ray

    stream = stream if stream is not None else sys.stderr
    build = build_digest(program)
    jobs = plan_jobs(options)
    progress = Progress(len(jobs), stream)
    summaries: dict[str, dict[str, Any]] = {}
    todo = []
    for job in jobs:
        earlier = read_summary(options.out, job)
        if earlier and earlier.get("complete") and earlier.get("build") == build:
            summaries[job.recording] = earlier
            progress.skipped(earlier)
        else:
            todo.append(job)

    def done(summary: dict[str, Any]) -> None:
        summaries[summary["recording"]] = summary
        progress.finished(summary)

    started = time.monotonic()
    interrupted = False
    try:
        if options.engine == "ray":
            run_ray(program, todo, options.out, build, options.slots, done, options.address,
                    options.num_gpus, options.resources)
        else:
            run_local(program, todo, options.out, build, options.slots, done)
    except Interrupted:
        interrupted = True
    divergences = []
    if options.baseline is not None and not interrupted:
        divergences = compare_runs({job.recording: summaries[job.recording] for job in jobs
                                    if job.recording in summaries}, load_run(options.baseline))
    run = _run_summary(jobs, summaries, options, build, time.monotonic() - started,
                       divergences, interrupted)
    (options.out / RUN_SUMMARY).write_text(json.dumps(run, indent=1) + "\n", encoding="utf-8")
    _report(run, divergences, stream)
    if interrupted:
        return 130
    return 0 if run["totals"]["complete"] == len(jobs) and not divergences else 1


def _run_summary(jobs, summaries, options, build, seconds, divergences, interrupted) -> dict:
    rows = []
    for job in jobs:
        summary = summaries.get(job.recording)
        rows.append({"recording": job.recording, "folder": job.folder,
                     "status": summary["status"] if summary else "not run",
                     "frames": summary["frames"] if summary else 0,
                     "seconds": summary["seconds"] if summary else 0.0,
                     "reason": summary.get("reason", "") if summary else ""})
    statuses = [row["status"] for row in rows]
    return {
        "build": build,
        "engine": options.engine,
        "slots": options.slots,
        "source": options.source,
        "interrupted": interrupted,
        "recordings": rows,
        "totals": {
            "recordings": len(rows),
            "complete": statuses.count("complete"),
            "partial": sum(s.startswith("partial") for s in statuses),
            "failed": statuses.count("failed"),
            "not_complete": sum(s != "complete" for s in statuses),
            "frames": sum(row["frames"] for row in rows),
            "seconds": round(seconds, 3),
        },
        "baseline": str(options.baseline) if options.baseline else None,
        "divergences": [d.line() for d in divergences],
    }


def _report(run: dict, divergences: list, stream: TextIO) -> None:
    totals = run["totals"]
    for row in run["recordings"]:
        if row["status"] != "complete":
            reason = row["reason"].splitlines()
            stream.write(f"{row['recording']}: {row['status']}"
                         + (f": {reason[-1]}" if reason else "") + "\n")
    stream.writelines(f"diverged: {d.line()}\n" for d in divergences)
    stream.write(f"replayed {totals['recordings']} recording(s) in {totals['seconds']:.1f} s: "
                 f"{totals['complete']} complete, {totals['partial']} partial, "
                 f"{totals['failed']} failed, {totals['frames']:,} frames"
                 + (f"; {len(divergences)} divergence(s) from the baseline"
                    if run["baseline"] else "")
                 + ("; stopped by Ctrl-C" if run["interrupted"] else "") + "\n")
    stream.flush()
