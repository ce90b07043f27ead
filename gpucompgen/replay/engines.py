"""Where the jobs run: processes on this machine, or tasks on a Ray cluster.

Both engines run the same job function (jobs.run_job) over the same program, so their
summaries are identical but for timings. Each calls done(summary) as a recording ends.

- local: `slots` recordings at a time, each a process of its own (its own device
  context); Ctrl-C interrupts the running ones (they keep what they wrote), and no new
  one starts.
- ray: one Ray task per recording. The task carries the program's files (a worker may
  be another machine) and returns the recording's summary and files, written here as
  they arrive; the recordings and the model's own folder must be readable at the same
  path on every node. The device is a resource of the task (`num_gpus`, or a custom
  resource such as `opencl` that the cluster's nodes declare). A worker that dies is
  retried once by Ray; every wait has a timeout.
"""

from __future__ import annotations

import base64
import tempfile
import threading
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any

from .jobs import DIGESTS, STATS, STDERR, Job, run_job, summarise, write_summary

Done = Callable[[dict[str, Any]], None]


class Interrupted(Exception):
    """Ctrl-C: the engine stopped; the summaries written so far stay."""


def run_local(program: Path, jobs: list[Job], out: Path, build: str, slots: int,
              done: Done) -> None:
    stop = threading.Event()

    def one(job: Job) -> dict[str, Any]:
        outcome = run_job(program, job, out, stop)
        summary = summarise(job, outcome, out, build)
        write_summary(summary, out)
        return summary

    pool = ThreadPoolExecutor(max_workers=max(1, slots), thread_name_prefix="replay")
    pending = set()
    try:
        queue = list(jobs)
        while queue or pending:
            while queue and len(pending) < max(1, slots):
                pending.add(pool.submit(one, queue.pop(0)))
            finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for future in finished:
                done(future.result())
    except KeyboardInterrupt:
        stop.set()
        for future in pending:
            done(future.result())  # interrupted: 'stopped', with what it wrote
        raise Interrupted() from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


# -- Ray ----------------------------------------------------------------------------------

WAIT_SECONDS = 1.0  # each ray.wait: Ctrl-C and deadlines are looked at in between
GET_SECONDS = 120.0  # fetching one finished task's result
TASK_MARGIN_SECONDS = 300.0  # beyond a job's own --timeout, before a task is given up


def ray_missing_message() -> str:
    return ("--engine ray needs Ray: pip install 'gpucompgen[ray]' "
            "(or leave --engine out to replay on this machine)")


def run_ray(program: Path, jobs: list[Job], out: Path, build: str, slots: int, done: Done,
            address: str | None = None, num_gpus: float = 0.0,
            resources: dict[str, float] | None = None) -> None:
    try:
        import ray
    except ImportError:
        raise RuntimeError(ray_missing_message()) from None
    started_here = not ray.is_initialized()
    if started_here:
        if address:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(num_cpus=max(1, slots), include_dashboard=False, log_to_driver=False)
    try:
        _run_on_ray(ray, program, jobs, out, build, done, num_gpus, resources or {})
    finally:
        if started_here:
            ray.shutdown()


def _program_files(program: Path) -> dict[str, str]:
    """The program and its lib folder, as {relative path: base64}: what a remote worker
    writes into a folder of its own."""
    root = program.parent
    files = {program.name: program}
    lib = root / f"{program.stem}_lib"
    if lib.is_dir():
        files.update({p.relative_to(root).as_posix(): p for p in sorted(lib.rglob("*"))
                      if p.is_file()})
    return {name: base64.b64encode(p.read_bytes()).decode("ascii") for name, p in files.items()}


def _remote_job(files: dict[str, str], program_name: str, program_home: str, job: Job,
                build: str) -> tuple[dict[str, Any], dict[str, str]]:
    """Runs on a Ray worker: the job in a folder of its own; returns (summary, files).

    Where the program's folder is there (this machine, or a shared file system) the
    program runs from it, so the model's relative paths resolve as they do locally; else
    the files the task carries are written into a temporary folder."""
    with tempfile.TemporaryDirectory(prefix="gpucompgen-replay-") as tmp:
        program = Path(program_home) / program_name
        if not program.is_file():
            program = Path(tmp) / "program" / program_name
            for name, data in files.items():
                path = program.parent / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(base64.b64decode(data))
        out = Path(tmp) / "out"
        outcome = run_job(program, job, out)
        summary = summarise(job, outcome, out, build)
        folder = out / job.folder
        produced = {p.relative_to(folder).as_posix():
                    base64.b64encode(p.read_bytes()).decode("ascii")
                    for p in sorted(folder.rglob("*")) if p.is_file()}
        return summary, produced


def _run_on_ray(ray, program, jobs, out, build, done, num_gpus, resources) -> None:
    files = _program_files(program)
    task = ray.remote(_remote_job).options(num_cpus=1, num_gpus=num_gpus, resources=resources,
                                          max_retries=1, retry_exceptions=False)
    refs = {task.remote(files, program.name, str(program.parent), job, build): job
            for job in jobs}
    started = {ref: time.monotonic() for ref in refs}
    try:
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1, timeout=WAIT_SECONDS)
            for ref in ready:
                job = refs.pop(ref)
                done(_collect(ray, ref, job, out, build))
            for ref, job in list(refs.items()):
                limit = (job.timeout or 0) + TASK_MARGIN_SECONDS if job.timeout else None
                if limit is not None and time.monotonic() - started[ref] > limit:
                    ray.cancel(ref, force=True)
                    refs.pop(ref)
                    done(_lost(job, out, build, "the Ray task did not finish in time"))
    except KeyboardInterrupt:
        for ref in refs:
            ray.cancel(ref, force=True)
        raise Interrupted() from None


def _collect(ray, ref, job: Job, out: Path, build: str) -> dict[str, Any]:
    try:
        summary, produced = ray.get(ref, timeout=GET_SECONDS)
    except Exception as exc:  # the task failed twice, or its result could not be fetched
        return _lost(job, out, build, f"the Ray task failed: {type(exc).__name__}: {exc}")
    folder = out / job.folder
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in produced.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(data))
    write_summary(summary, out)
    return summary


def _lost(job: Job, out: Path, build: str, reason: str) -> dict[str, Any]:
    from .jobs import Outcome

    (out / job.folder).mkdir(parents=True, exist_ok=True)
    for stale in (DIGESTS, STATS, STDERR):
        (out / job.folder / stale).unlink(missing_ok=True)
    summary = summarise(job, Outcome(None, 0.0, reason), out, build)
    summary["reason"] = reason
    write_summary(summary, out)
    return summary
