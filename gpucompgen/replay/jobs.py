"""One recording replayed by one process: the job, the worker and what it leaves behind.

A job runs the program built once for the whole replay (`<out>/program/`) over one
recording, in a process of its own (so each recording has its own device context and a
crash stays local), with the recording as the source's input (`--input SOURCE=URI`), and
leaves in its folder:

- digests.jsonl: what every sink received and reported, frame by frame (--digests);
- stats.json: the run's timings (--stats-json), when the run got far enough to write it;
- stderr.txt: what the program printed on stderr;
- images/: the sinks' images, with --save-outputs;
- summary.json: written last, from the above (see summarise); its presence with
  "complete": true is what a resumed replay skips.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

SUMMARY = "summary.json"
DIGESTS = "digests.jsonl"
STATS = "stats.json"
STDERR = "stderr.txt"
MAX_REASON = 2000  # characters of the program's stderr kept as a failure's reason


@dataclass(frozen=True)
class Job:
    """What one worker needs; plain data, so it travels to a Ray worker as it is."""

    recording: str  # as the user gave it: a path or a URI
    uri: str  # what the program's --input gets
    folder: str  # this recording's output folder (relative to the replay's --out)
    source: str  # the source component fed with the recording
    frames: int | None = None
    save_outputs: bool = False
    timeout: float | None = None  # seconds for the whole recording


def recording_uri(recording: str, topic: str | None) -> str:
    """The --input URI of a recording: a URI as given; a path made absolute (the program runs
    in another folder); ?topic= added for recordings when --topic is given."""
    if "://" in recording or recording.startswith("device:"):
        uri = recording
    else:
        uri = str(Path(recording).expanduser().absolute())
        if topic and uri.endswith(".mcap"):
            uri = "mcap://" + uri
        elif topic and (uri.endswith(".db3") or Path(uri, "metadata.yaml").is_file()):
            uri = "rosbag://" + uri
    if topic and "topic=" not in uri:
        uri += ("&" if "?" in uri else "?") + f"topic={topic}"
    return uri


def folder_name(recording: str, taken: set[str]) -> str:
    """A readable, unique folder name: the recording's file name, made safe, and a short
    digest of the whole recording string (two 'run1/cam.mcap' in different folders differ)."""
    base = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(recording.rstrip("/")).name)[:60] or "recording"
    digest = hashlib.blake2b(recording.encode("utf-8"), digest_size=4).hexdigest()
    name = f"{base}-{digest}"
    while name in taken:  # the same recording given twice
        name += "x"
    taken.add(name)
    return name


@dataclass
class Outcome:
    """How the process ended, for summarise()."""

    returncode: int | None
    seconds: float
    stderr: str
    timed_out: bool = False
    interrupted: bool = False
    attempts: int = 1

    @property
    def died(self) -> bool:
        """Killed by a signal it did not ask for (not our Ctrl-C, not our timeout): a crash
        of the worker, retried once."""
        if self.interrupted or self.timed_out or self.returncode is None:
            return False
        return self.returncode < 0 and -self.returncode not in (signal.SIGINT, signal.SIGTERM)


def run_job(program: Path, job: Job, out: Path, stop=None) -> Outcome:
    """Run the program over one recording into out/job.folder; a worker that dies is tried
    once more. stop: a threading.Event; when set, the process is interrupted (SIGINT, then
    SIGKILL)."""
    folder = out / job.folder
    folder.mkdir(parents=True, exist_ok=True)
    attempts = 0
    while True:
        attempts += 1
        outcome = _run_once(program, job, folder, stop)
        outcome.attempts = attempts
        if not outcome.died or attempts >= 2:
            return outcome


def _command(program: Path, job: Job, folder: Path) -> list[str]:
    cmd = [sys.executable, str(program), "--input", f"{job.source}={job.uri}", "--quiet",
           "--digests", str(folder / DIGESTS), "--stats-json", str(folder / STATS)]
    if job.frames is not None:
        cmd += ["--frames", str(job.frames)]
    if job.save_outputs:
        (folder / "images").mkdir(exist_ok=True)
        cmd += ["--save-images", str(folder / "images")]
    return cmd


def _run_once(program: Path, job: Job, folder: Path, stop) -> Outcome:
    for stale in (DIGESTS, STATS, SUMMARY):
        (folder / stale).unlink(missing_ok=True)
    started = time.monotonic()
    with open(folder / STDERR, "w+", encoding="utf-8", errors="replace") as err:
        proc = subprocess.Popen(_command(program, job, folder), stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=err, cwd=folder,
                                env=dict(os.environ), start_new_session=True)
        timed_out = interrupted = False
        deadline = None if job.timeout is None else started + job.timeout
        while proc.poll() is None:
            if stop is not None and stop.is_set() and not interrupted:
                interrupted = True
                _end(proc)
            elif deadline is not None and time.monotonic() > deadline and not timed_out:
                timed_out = True
                _end(proc)
            else:
                try:
                    proc.wait(timeout=0.1)
                except subprocess.TimeoutExpired:
                    pass
        err.seek(0)
        text = err.read()
    return Outcome(proc.returncode, time.monotonic() - started, text, timed_out, interrupted)


def _end(proc: subprocess.Popen, grace: float = 5.0) -> None:
    """SIGINT (the program stops cleanly and keeps what it wrote), SIGKILL if it lingers."""
    try:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    except ProcessLookupError:
        pass


def read_digests(path: Path) -> dict[str, dict[str, list]]:
    """{sink: {"inputs": [per frame], "reports": [per frame]}} from a digests file; a line cut
    short by a crash is the end of the file."""
    sinks: dict[str, dict[str, list]] = {}
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return sinks
    for text in lines:
        try:
            line = json.loads(text)
            part, inputs = line["part"], line["inputs"]
        except (ValueError, KeyError, TypeError):
            break
        sink = sinks.setdefault(part, {"inputs": [], "reports": []})
        sink["inputs"].append(inputs)
        if "report" in line:
            sink["reports"].append(line["report"])
    return sinks


def summarise(job: Job, outcome: Outcome, out: Path, build_digest: str) -> dict[str, Any]:
    """The recording's summary.json: status, reason, frames, timings and the sinks' outputs
    reduced to digests and reports, frame by frame."""
    folder = out / job.folder
    sinks = read_digests(folder / DIGESTS)
    frames = min((len(s["inputs"]) for s in sinks.values()), default=0)
    stats: dict[str, Any] = {}
    try:
        stats = json.loads((folder / STATS).read_text(encoding="utf-8"))
        frames = max(frames, int(stats.get("frames", 0)))
    except (OSError, ValueError, TypeError, AttributeError):
        pass
    reason = _reason(outcome)
    if outcome.returncode == 0 and not outcome.timed_out:
        status = "complete"
    elif outcome.interrupted:
        status = "stopped"
    elif frames > 0:
        status = f"partial({frames})"
    else:
        status = "failed"
    latency = stats.get("latency_seconds", {}) if isinstance(stats, dict) else {}
    return {
        "recording": job.recording,
        "uri": job.uri,
        "source": job.source,
        "status": status,
        "complete": status == "complete",
        "reason": reason,
        "returncode": outcome.returncode,
        "attempts": outcome.attempts,
        "frames": frames,
        "seconds": round(outcome.seconds, 3),
        "frames_per_second": round(frames / outcome.seconds, 2) if outcome.seconds > 0 else 0,
        "latency_median_seconds": latency.get("median"),
        "build": build_digest,
        "sinks": {name: {"frames": len(s["inputs"]), "inputs": s["inputs"],
                         "reports": s["reports"]} for name, s in sorted(sinks.items())},
        "job": asdict(job),
    }


def _reason(outcome: Outcome) -> str:
    if outcome.returncode == 0 and not outcome.timed_out:
        return ""
    if outcome.timed_out:
        return "timed out (--timeout)"
    if outcome.interrupted:
        return "stopped by Ctrl-C"
    lines = [line for line in outcome.stderr.splitlines() if line.strip()]
    first_error = next((i for i, line in enumerate(lines) if line.startswith("error:")), None)
    if first_error is not None:  # the program's own message, not native libraries' chatter
        lines = lines[first_error:]
    text = "\n".join(lines[-8:])[-MAX_REASON:]
    if outcome.returncode is not None and outcome.returncode < 0:
        name = signal.Signals(-outcome.returncode).name if -outcome.returncode in \
            signal.valid_signals() else str(-outcome.returncode)
        text = (f"the worker died ({name}) twice" if outcome.attempts > 1
                else f"the worker died ({name})") + (f": {text}" if text else "")
    return text or f"exit code {outcome.returncode}"


def write_summary(summary: dict[str, Any], out: Path) -> None:
    """Written whole or not at all (a replace), last: a summary on disk is a finished job."""
    folder = out / summary["job"]["folder"]
    tmp = folder / (SUMMARY + ".tmp")
    tmp.write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    tmp.replace(folder / SUMMARY)


def read_summary(out: Path, job: Job) -> dict[str, Any] | None:
    try:
        summary = json.loads((out / job.folder / SUMMARY).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) else None
