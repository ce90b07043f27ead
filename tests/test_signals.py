"""Signals and deaths: a program stops within about 2 s on SIGINT or SIGTERM even when a
kernel never ends or a component blocks; 'gpucompgen run' forwards both and names the
signal a program died of.

Programs run as users run them (subprocesses); the timing checks allow for a loaded
machine: the program gives up GRACE_SECONDS (1.5 s) after the signal.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import ROOT, require_opencl

from gpucompgen.build import compile_model, write
from gpucompgen.runtime import Monitor, PipelineError, Stopped, free_all
from gpucompgen.runtime.signals import GRACE_SECONDS, StopOnSignals

HOSTILE = ROOT / "tests" / "data" / "hostile"
# Exit within this long of the signal: the grace period, freeing, and a loaded machine.
DEADLINE = GRACE_SECONDS + 2.5


def hostile_model(tmp_path: Path, middle: str, name: str = "hostile",
                  **params) -> tuple[Path, Path, Path]:
    """camera -> middle (a type of tests/data/hostile with params) -> Tally, built into
    tmp_path/out; (program, model, log), where Tally and Misbehave log."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    log = tmp_path / "parts.log"
    if middle == "Misbehave":
        params["log"] = log.as_posix()
    model = tmp_path / f"{name}.yaml"
    model.write_text(textwrap.dedent(f"""\
        system: {name}
        types: [{(HOSTILE / "types.yaml").as_posix()}]
        components:
          camera: {{type: Camera, params: {{width: 32, height: 16}}}}
          middle: {{type: {middle}, params: {json.dumps(params)}}}
          sink: {{type: Tally, params: {{log: "{log.as_posix()}"}}}}
        connections:
          - camera.image -> middle.image
          - middle.{"image_out" if middle == "Misbehave" else "out"} -> sink.image
        """), encoding="utf-8")
    out = tmp_path / "out"
    result = compile_model(model, out)
    write(result, out)
    return out / f"{name}.py", model, log


def start(cmd: list[str], cwd: Path | None = None) -> subprocess.Popen:
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ), cwd=cwd)


def wait_for_line(path: Path, line: str, proc: subprocess.Popen, timeout: float = 120):
    """Until `line` is in the file (a component wrote it), or the process ended."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists() and line in path.read_text().splitlines():
            return
        if proc.poll() is not None:
            _, err = proc.communicate()
            pytest.fail(f"the program ended ({proc.returncode}) before '{line}': {err}")
        time.sleep(0.05)
    pytest.fail(f"no '{line}' in {path} within {timeout} s")


def signal_and_time(proc: subprocess.Popen, *signums: int) -> tuple[str, float]:
    """Send the signals (0.1 s apart); (stderr, seconds from the first to the exit)."""
    try:
        sent = time.monotonic()
        for signum in signums:
            proc.send_signal(signum)
            time.sleep(0.1)
        _, err = proc.communicate(timeout=60)
        return err, time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()




@pytest.mark.parametrize("signum,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_kernel_that_never_ends_does_not_keep_the_program_from_stopping(tmp_path, signum,
                                                                           code):
    require_opencl()
    program, _, log = hostile_model(tmp_path, "Spin", forever=1)
    proc = start([sys.executable, str(program)])
    wait_for_line(log, "init tally", proc)
    time.sleep(0.5)  # the kernel is running; the host waits in the GPU-to-CPU copy
    err, seconds = signal_and_time(proc, signum)
    assert proc.returncode == code, err
    assert seconds < DEADLINE, (seconds, err)
    name = signal.Signals(signum).name
    assert (f"stopped by {name} after 0 frame(s), but the run did not stop within "
            f"{GRACE_SECONDS:g} s: it is blocked at hostile.py:") in err
    assert "adapter2_gpu2cpu.transfer()" in err  # where the host waits
    assert "still running on the device: the last command of middle" in err
    assert "  freed: sink, adapter2_gpu2cpu, middle, adapter1_cpu2gpu, camera" in err
    assert "  not freed: the OpenCL context and queue(s)" in err
    assert "Traceback" not in err
    assert log.read_text().splitlines() == ["init tally", "free tally"]


@pytest.mark.parametrize("signum,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_gpucompgen_run_stops_a_kernel_that_never_ends(tmp_path, signum, code):
    require_opencl()
    _, model, log = hostile_model(tmp_path / "m", "Spin", forever=1)
    work = tmp_path / "work"
    work.mkdir()
    proc = start([sys.executable, "-m", "gpucompgen", "run", str(model)], cwd=work)
    wait_for_line(log, "init tally", proc)
    time.sleep(0.5)
    err, seconds = signal_and_time(proc, signum)  # to gpucompgen run, not to the group
    assert proc.returncode == code, err
    assert seconds < DEADLINE + 1, (seconds, err)
    assert f"stopped by {signal.Signals(signum).name} after 0 frame(s)" in err
    assert "Traceback" not in err
    assert not list(work.iterdir())


def test_a_second_signal_while_stopping_is_ignored(tmp_path):
    """A terminal's Ctrl-C reaches the program twice under 'gpucompgen run'."""
    require_opencl()
    program, _, log = hostile_model(tmp_path, "Spin", forever=1)
    proc = start([sys.executable, str(program)])
    wait_for_line(log, "init tally", proc)
    err, seconds = signal_and_time(proc, signal.SIGINT, signal.SIGINT, signal.SIGTERM)
    assert proc.returncode == 130, err  # the first signal decides
    assert seconds < DEADLINE
    assert err.count("stopped by SIGINT") == 1 and "SIGTERM" not in err
    assert "Traceback" not in err


@pytest.mark.parametrize("signums", [(signal.SIGINT,), (signal.SIGINT, signal.SIGINT)])
def test_sigint_to_gpucompgen_run_itself_stops_the_program_cleanly(tmp_path, signums):
    require_opencl()
    proc = start([sys.executable, "-m", "gpucompgen", "run",
                  str(ROOT / "models" / "vision_system.yaml")], cwd=tmp_path)
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert all(line.startswith("frame ") for line in lines), lines
    finally:
        err, _ = signal_and_time(proc, *signums)
    assert proc.returncode == 130, err
    assert "stopped by SIGINT after " in err and "every component was freed" in err
    assert err.count("stopped by") == 1
    assert "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_the_terminals_ctrl_c_reaching_both_processes_stops_cleanly(tmp_path):
    """SIGINT to the process group: 'gpucompgen run' and the program both get it."""
    require_opencl()
    proc = subprocess.Popen([sys.executable, "-m", "gpucompgen", "run",
                             str(ROOT / "models" / "vision_system.yaml")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ), cwd=tmp_path, start_new_session=True)
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert all(line.startswith("frame ") for line in lines), lines
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert err.count("stopped by SIGINT after ") == 1, err
    assert "every component was freed" in err and "Traceback" not in err


def test_a_python_component_looping_forever_is_stopped_and_everything_freed(tmp_path):
    require_opencl()
    program, _, log = hostile_model(tmp_path, "Misbehave", at=2, what="loop")
    proc = start([sys.executable, str(program)])
    wait_for_line(log, "init tally", proc)
    time.sleep(1.0)
    err, seconds = signal_and_time(proc, signal.SIGTERM)
    assert proc.returncode == 143, err
    assert seconds < DEADLINE
    assert "stopped by SIGTERM after 2 frame(s); every component was freed" in err
    assert log.read_text().splitlines()[-2:] == ["free tally", "free misbehave"]


def test_a_thread_a_component_left_running_does_not_keep_a_stopped_program_alive(tmp_path):
    require_opencl()
    program, _, log = hostile_model(tmp_path, "Misbehave", at=1, what="thread")
    proc = start([sys.executable, str(program)])
    wait_for_line(log, "init tally", proc)
    time.sleep(1.0)
    err, seconds = signal_and_time(proc, signal.SIGTERM)
    assert proc.returncode == 143, err
    assert seconds < DEADLINE
    assert "stopped by SIGTERM after " in err and "every component was freed" in err
    assert "note: thread(s) busy-worker started by a component are still running" in err


def test_a_stop_says_which_component_could_not_be_freed(tmp_path):
    require_opencl()
    program, _, log = hostile_model(tmp_path, "Misbehave", at=-1, fail_free=True)
    proc = start([sys.executable, str(program)])
    wait_for_line(log, "init tally", proc)
    err, _ = signal_and_time(proc, signal.SIGINT)
    assert proc.returncode == 130, err
    assert "note: middle.free_memory() failed: OSError: injected failure to free" in err
    assert "; every other component was freed" in err
    assert log.read_text().splitlines()[-2:] == ["free tally", "free misbehave"]


def test_a_component_blocked_outside_python_is_given_up_after_the_grace(tmp_path):
    require_opencl()
    program, _, log = hostile_model(tmp_path, "Misbehave", at=1, what="sleep", seconds=60.0)
    stats = tmp_path / "stats.json"
    proc = start([sys.executable, str(program), "--stats-json", str(stats)])
    wait_for_line(log, "init tally", proc)
    time.sleep(1.0)
    err, seconds = signal_and_time(proc, signal.SIGINT)
    assert proc.returncode == 130, err
    assert seconds < DEADLINE
    assert "stopped by SIGINT after 1 frame(s), but the run did not stop within" in err
    assert "in middle.execute()" in err
    assert "  freed: sink, middle, camera" in err
    assert log.read_text().splitlines()[-2:] == ["free tally", "free misbehave"]
    assert json.loads(stats.read_text())["frames"] == 1  # --stats-json still written


def test_stats_are_written_when_stopped_cleanly(tmp_path):
    require_opencl()
    stats = tmp_path / "stats.json"
    proc = start([sys.executable, str(ROOT / "generated" / "vision_system.py"),
                  "--stats-json", str(stats)])
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        assert all(line.startswith("frame ") for line in lines), lines
    finally:
        err, _ = signal_and_time(proc, signal.SIGTERM)
    assert proc.returncode == 143, err
    frames = json.loads(stats.read_text())["frames"]
    assert f"stopped by SIGTERM after {frames} frame(s); every component was freed" in err


@pytest.mark.parametrize("signum", [signal.SIGSEGV, signal.SIGKILL, signal.SIGABRT,
                                    signal.SIGBUS])
def test_gpucompgen_run_names_the_signal_a_program_died_of(tmp_path, signum):
    require_opencl()
    _, model, _ = hostile_model(tmp_path, "Misbehave", at=1, what="kill", signum=int(signum))
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(model)],
                          capture_output=True, text=True, timeout=300, env=dict(os.environ),
                          cwd=tmp_path, check=False)
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, proc.stderr
    assert (f"gpucompgen run: error: the program was killed by signal {name} ({signum})"
            in proc.stderr)
    if signum in (signal.SIGSEGV, signal.SIGBUS):
        assert "out of bounds" in proc.stderr and "docs/runtime.md" in proc.stderr
    if signum == signal.SIGKILL:
        assert "out-of-memory" in proc.stderr


def test_a_kernel_writing_far_out_of_bounds_is_reported(tmp_path):
    require_opencl()
    _, model, _ = hostile_model(tmp_path, "Scribble")
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(model),
                           "--frames", "3"], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ), cwd=tmp_path, check=False)
    if proc.returncode == 0:
        pytest.skip("this OpenCL device survives a write 64 GiB past a buffer")
    if proc.returncode == 1:  # a GPU: the fault surfaces as an error of the next command
        assert "out of bounds" in proc.stderr and "hint:" in proc.stderr, proc.stderr
        return
    assert proc.returncode in (128 + signal.SIGSEGV, 128 + signal.SIGBUS), proc.stderr
    assert "the program was killed by signal SIG" in proc.stderr
    assert "out of bounds" in proc.stderr


def test_gpucompgen_run_reports_an_ordinary_exit_code_unchanged(tmp_path):
    require_opencl()
    _, model, _ = hostile_model(tmp_path, "Misbehave", at=1, what="raise")
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "run", str(model)],
                          capture_output=True, text=True, timeout=300, env=dict(os.environ),
                          cwd=tmp_path, check=False)
    assert proc.returncode == 1
    assert "error: middle failed at frame 1: RuntimeError: injected failure" in proc.stderr
    assert "killed by signal" not in proc.stderr


# -- StopOnSignals without OpenCL: stop requests arrive from a timer thread ----------------

class _Part:
    def __init__(self, name, log, free_seconds=0.0, fail=False):
        self.name, self.log, self.free_seconds, self.fail = name, log, free_seconds, fail

    def free_memory(self):
        time.sleep(self.free_seconds)
        self.log.append(self.name)
        if self.fail:
            raise OSError("cannot")


def _stopper(monitor=None, **kwargs):
    exits = []
    stream = SimpleNamespace(text="", write=None, flush=lambda: None)

    def write(text):
        stream.text += text

    stream.write = write
    stopper = StopOnSignals(monitor or Monitor(progress=False), exit=exits.append,
                            stream=stream, **kwargs)
    return stopper, exits, stream


def _later(seconds, action):
    timer = threading.Timer(seconds, action)
    timer.start()
    return timer


def test_run_returns_the_result_and_raises_the_runs_own_errors():
    stopper, exits, _ = _stopper()
    assert stopper.run(lambda: 42) == 42

    def fail():
        raise PipelineError("camera failed at frame 3: boom")

    with pytest.raises(PipelineError, match="camera failed at frame 3"):
        stopper.run(fail)

    def interrupt():
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        stopper.run(interrupt)
    assert exits == []


def test_a_stop_interrupts_python_code_and_the_run_frees_everything():
    freed = []
    monitor = Monitor(progress=False)
    parts = {"a": _Part("a", freed), "b": _Part("b", freed)}
    monitor.attach(parts)
    stopper, exits, _ = _stopper(monitor)

    def run():
        try:
            while True:  # a component looping in Python
                pass
        finally:
            free_all(parts)

    timer = _later(0.2, lambda: stopper.request_stop(signal.SIGTERM))
    with pytest.raises(Stopped) as caught:
        stopper.run(run)
    timer.join()
    assert caught.value.signum == signal.SIGTERM and str(caught.value) == "SIGTERM"
    assert freed == ["b", "a"] and exits == []


def test_frame_done_ends_the_stream_loop_once_a_stop_is_requested():
    monitor = Monitor(progress=False)
    monitor.frame_done(1)  # nothing requested: run() called directly is unaffected
    monitor.request_stop(signal.SIGINT)
    with pytest.raises(Stopped):
        monitor.frame_done(2)
    assert monitor.frames == 2


def test_a_stop_while_freeing_does_not_cut_freeing_short():
    freed = []
    parts = {n: _Part(n, freed, free_seconds=0.1) for n in "abcde"}
    stopper, exits, _ = _stopper()

    def run():
        free_all(parts)  # a signal comes in the middle of this
        return "done"

    timer = _later(0.15, lambda: stopper.request_stop(signal.SIGINT))
    with pytest.raises(Stopped):  # the run finished, but the user asked to stop
        stopper.run(run)
    timer.join()
    assert freed == ["e", "d", "c", "b", "a"] and exits == []


def test_a_run_blocked_outside_python_is_given_up_naming_what_was_not_freed():
    freed = []
    monitor = Monitor(progress=False)
    parts = {"camera": _Part("camera", freed), "slow": _Part("slow", freed, free_seconds=5),
             "broken": _Part("broken", freed, fail=True), "never": None}
    monitor.attach(parts)
    monitor.frames = 7
    stopper, exits, stream = _stopper(monitor, grace=0.3, free_seconds=0.3)
    blocker = threading.Event()
    timer = _later(0.1, lambda: stopper.request_stop(signal.SIGINT))
    started = time.monotonic()
    assert stopper.run(lambda: blocker.wait(30)) is None  # blocked in C: Event.wait
    timer.join()
    assert time.monotonic() - started < 2
    assert exits == [130]
    text = stream.text
    assert text.startswith("stopped by SIGINT after 7 frame(s), but the run did not stop "
                           "within 0.3 s: it is blocked at ")
    assert "  freed: camera" in text
    assert "broken (free_memory() failed: OSError: cannot)" in text
    assert "slow (free_memory() did not return)" in text
    assert "never" not in text  # never constructed
    blocker.set()


def test_second_requests_are_ignored():
    stopper, _, _ = _stopper()
    stopper.request_stop(signal.SIGTERM)
    stopper.request_stop(signal.SIGINT)
    assert stopper.signum == signal.SIGTERM


def test_free_all_frees_the_rest_before_a_free_memory_that_exits():
    freed = []

    class Exits(_Part):
        def free_memory(self):
            freed.append(self.name)
            raise SystemExit(4)

    parts = {"a": _Part("a", freed), "b": Exits("b", freed), "c": _Part("c", freed)}
    with pytest.raises(SystemExit):
        free_all(parts)
    assert freed == ["c", "b", "a"]


# -- run_program ('gpucompgen run' waiting on a program), with stand-in programs -------------

def _supervise(child: str, signum: int | None, kill_after: float = 10.0, delay: float = 1.0):
    """Run child (Python code) under run_program in a process of its own; signal that."""
    driver = ("import sys\nfrom gpucompgen.cli import run_program\n"
              f"sys.exit(run_program([sys.executable, '-c', {child!r}], "
              f"kill_after={kill_after}))\n")
    proc = start([sys.executable, "-c", driver])
    if signum is not None:
        assert proc.stdout.readline() == "ready\n"  # the child runs: the driver waits on it
    time.sleep(delay)
    started = time.monotonic()
    if signum is not None:
        proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err, time.monotonic() - started


def test_run_program_kills_a_program_that_does_not_stop():
    child = ("import signal, time\nsignal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
             "print('ready', flush=True)\ntime.sleep(60)")
    code, err, seconds = _supervise(child, signal.SIGTERM, kill_after=1.0)
    assert code == 143, err
    assert "gpucompgen run: error: the program did not stop within 1 s of SIGTERM; killed it" \
        in err
    assert 1.0 <= seconds < 5


def test_run_program_says_a_program_was_stopped_while_starting():
    code, err, _ = _supervise("import time\nprint('ready', flush=True)\ntime.sleep(60)",
                              signal.SIGTERM, delay=0)
    assert code == 143, err
    assert "the program was stopped by SIGTERM (15) while starting" in err


def test_run_program_resends_sigint_until_the_program_takes_it_over():
    """The program starts with SIGINT ignored; it installs a handler only later."""
    child = ("import signal, sys, time\n"
             "assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN\n"
             "print('ready', flush=True)\n"
             "time.sleep(1.5)\n"  # the first SIGINT comes now, and is lost
             "signal.signal(signal.SIGINT, lambda *a: sys.exit(42))\n"
             "time.sleep(30)\n")
    code, err, seconds = _supervise(child, signal.SIGINT, delay=0.5)
    assert code == 42, err
    assert seconds < 5


def test_run_program_passes_exit_codes_through():
    code, err, _ = _supervise("import sys\nsys.exit(3)", None, delay=0)
    assert code == 3 and err == ""


@pytest.mark.parametrize("signums,code,said", [
    ((signal.SIGTERM,), 143, "gpucompgen run: stopped by SIGTERM while building"),
    ((signal.SIGINT,), 130, "interrupted"),
    # a second Ctrl-C while it stops is ignored: it once landed as Python finalized, with
    # SIGINT back to the default, and killed the process (-2)
    ((signal.SIGINT, signal.SIGINT), 130, "interrupted")])
def test_a_signal_while_gpucompgen_run_builds_leaves_no_temporary_folder(tmp_path, signums,
                                                                         code, said):
    signum = signums[0]
    temp = tmp_path / "temp"
    temp.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "gpucompgen", "run",
                             str(ROOT / "models" / "vision_system.yaml")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, TMPDIR=str(temp)), cwd=tmp_path)
    try:
        end = time.monotonic() + 60
        while not any(temp.glob("gpucompgen-run-*")) and time.monotonic() < end:
            time.sleep(0.005)
        assert proc.poll() is None
    finally:
        err, _ = signal_and_time(proc, *signums)
    assert proc.returncode == code, err
    # while building, or (on a fast machine) just after the program started
    assert said in err or f"stopped by {signal.Signals(signum).name}" in err, err
    assert "Traceback" not in err
    assert not list(temp.glob("gpucompgen-run-*"))


@pytest.mark.parametrize("zero_copy", ["on", "off"])
def test_a_stop_at_any_moment_leaves_every_adapter_freeable(tmp_path, zero_copy):
    """A stop lands where the frame ends, not right after the OpenCL call the host waited
    in (where a zero-copy adapter had unmapped its buffer but not yet recorded it, and
    freeing unmapped it again: 'clEnqueueUnmapMemObject failed: INVALID_VALUE')."""
    require_opencl()
    out = tmp_path / "out"
    write(compile_model(ROOT / "models" / "vision_system.yaml", out, zero_copy=zero_copy), out)
    for delay in (0.0, 0.05, 0.13, 0.31):
        proc = start([sys.executable, str(out / "vision_system.py")])
        try:
            assert proc.stdout.readline().startswith("frame ")
            time.sleep(delay)
        finally:
            err, _ = signal_and_time(proc, signal.SIGINT)
        assert proc.returncode == 130, err
        assert "note:" not in err and "every component was freed" in err, (delay, err)


def test_a_stop_while_stats_are_written_to_a_stalled_reader_ends_the_run(tmp_path):
    """--stats-json names a FIFO whose reader never reads and the document fills the pipe:
    the write blocks in the run's thread after every part was freed.  SIGTERM gives up on
    it: the monitor is not closed (written) a second time and no part is freed again."""
    from gpucompgen.runtime import Parts

    freed = []
    fifo = tmp_path / "stats.fifo"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # there, but never reads
    try:
        monitor = Monitor(progress=False, stats_path=fifo)
        parts = Parts(["a", "b"])
        parts["a"], parts["b"] = _Part("a", freed), _Part("b", freed)
        parts.initialized |= {"a", "b"}
        monitor.attach(parts)
        monitor.frame_seconds = [0.125] * 20_000  # far more than a pipe holds
        stopper, exits, stream = _stopper(monitor, grace=0.5)

        def run():
            try:
                return 7
            finally:
                free_all(parts)
                monitor.close()  # blocks writing

        timer = _later(0.3, lambda: stopper.request_stop(signal.SIGTERM))
        done = threading.Event()
        threading.Thread(target=lambda: (stopper.run(run), done.set()), daemon=True).start()
        assert done.wait(20), "the stop did not end the run"
        timer.join()
    finally:
        os.close(reader)
    assert exits == [128 + signal.SIGTERM]
    assert freed == ["b", "a"]  # once, by the run; not again by the stop
    assert "freed: nothing" in stream.text


def test_a_stop_asks_the_device_api_the_parts_use():
    """A CUDA program's parts hold the CUDA module: running_kernels asks it, not OpenCL."""
    from types import SimpleNamespace

    from gpucompgen.runtime.signals import _api_of, running_kernels

    asked = []
    api = SimpleNamespace(is_running=lambda event: asked.append(event) or event == "busy")
    parts = {"source": object(), "blur": SimpleNamespace(_api=api, event="busy"),
             "adapter": SimpleNamespace(_api=api, event="done")}
    assert _api_of(parts) is api
    assert running_kernels(parts) == ["blur"] and asked == ["busy", "done"]
