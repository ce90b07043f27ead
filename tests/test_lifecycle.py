"""The generated program's lifecycle: failures, signals, freeing, device limits, inputs.

Each test runs a generated program the way a user does (a subprocess) and checks the exit
code, the message and that no traceback is shown.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen import runtime
from gpucompgen.build import compile_model, write
from gpucompgen.runtime import Monitor, PipelineError, check_device_memory, free_all

DATA = ROOT / "tests" / "data"


def build_model(tmp_path: Path, text: str, name: str = "s") -> Path:
    """Write a model into tmp_path, build it there; returns the program's path."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    model = tmp_path / f"{name}.yaml"
    model.write_text(textwrap.dedent(text), encoding="utf-8")
    out = tmp_path / "out"
    result = compile_model(model, out, fusion="off")
    write(result, out)
    return out / f"{result.system.model.name}.py"


def run_program(program: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(program), *args], capture_output=True,
                          text=True, timeout=300, check=False, env=dict(os.environ))


def lifecycle_model(tmp_path: Path, fail_at: int = -1, fail_free: bool = False,
                    frames: int = 6, fail_init: bool = False,
                    fail_initialize: bool = False) -> tuple[Path, Path]:
    log = tmp_path / "free.log"
    program = build_model(tmp_path, f"""\
        system: lifecycle
        types: [{(DATA / "lifecycle" / "types.yaml").as_posix()}]
        components:
          camera: {{type: Camera, params: {{width: 48, height: 32, frames: {frames}}}}}
          flaky: {{type: Flaky, params: {{fail_at: {fail_at}, log: "{log.as_posix()}",
                                         fail_initialize: {str(fail_initialize).lower()}}}}}
          detector: {{type: ObjectDetector}}
          recorder: {{type: Recorder, params: {{fail_free: {str(fail_free).lower()},
                                               fail_init: {str(fail_init).lower()},
                                               log: "{log.as_posix()}"}}}}
        connections:
          - camera.image -> flaky.image
          - flaky.image_out -> detector.frame
          - detector.mask -> recorder.mask
        """)
    return program, log


def test_end_of_stream_frees_everything_in_reverse_order(tmp_path):
    require_opencl()
    program, log = lifecycle_model(tmp_path, frames=5)
    proc = run_program(program)
    assert proc.returncode == 0, proc.stderr
    assert "processed 5 frame(s)" in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]


def test_component_failing_at_frame_k_is_named_and_everything_is_freed(tmp_path):
    require_opencl()
    program, log = lifecycle_model(tmp_path, fail_at=3)
    proc = run_program(program)
    assert proc.returncode == 1
    assert "error: flaky failed at frame 3: RuntimeError: injected failure at frame 3" \
        in proc.stderr
    assert "Traceback" not in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]
    debug = run_program(program, "--debug")
    assert debug.returncode == 1 and "Traceback" in debug.stderr


def test_a_failing_constructor_is_named_and_what_was_built_is_freed(tmp_path):
    require_opencl()
    program, log = lifecycle_model(tmp_path, fail_init=True)
    proc = run_program(program)
    assert proc.returncode == 1
    assert ("error: recorder failed while constructing: ValueError: injected failure to "
            "construct") in proc.stderr
    assert "Traceback" not in proc.stderr
    # flaky (and the camera, detector and adapters) were built before it, but none was
    # initialized (that comes after every part is built): nothing to free
    assert not log.exists()


def test_one_failing_free_does_not_stop_the_others(tmp_path):
    require_opencl()
    program, log = lifecycle_model(tmp_path, fail_free=True, frames=2)
    proc = run_program(program)
    assert proc.returncode == 1
    assert "recorder.free_memory() failed: OSError: injected failure to free" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]
    # when the run already failed, the first error stays the one reported
    program, log = lifecycle_model(tmp_path / "both", fail_at=1, fail_free=True)
    proc = run_program(program)
    assert proc.returncode == 1
    assert "error: flaky failed at frame 1" in proc.stderr
    assert "note: recorder.free_memory() failed" in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]


def test_free_memory_is_safe_twice(build):
    require_opencl()
    for mode in ("gpu-aware", "standard"):
        _, out = build(ROOT / "models" / "vision_system.yaml", mode)
        module = load_generated(out / "vision_system.py", f"vision_twice_{mode[:3]}")
        result = module.run(frames=2)
        free_all(result.components)  # run() freed them already
        for part in result.components.values():
            part.free_memory()


def test_free_all_goes_in_reverse_order_past_a_failure():
    freed = []

    class Part:
        def __init__(self, name, fail=False):
            self.name, self.fail = name, fail

        def free_memory(self):
            freed.append(self.name)
            if self.fail:
                raise ValueError("cannot")

    parts = {"a": Part("a"), "b": Part("b", fail=True), "c": Part("c")}
    with pytest.raises(PipelineError, match=r"b.free_memory\(\) failed: ValueError: cannot"):
        free_all(parts)
    assert freed == ["c", "b", "a"]


@pytest.mark.parametrize("signum,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_stops_a_running_pipeline_cleanly(signum, code):
    require_opencl()
    # the synthetic cameras never end: only the signal stops this run
    proc = subprocess.Popen([sys.executable, str(ROOT / "generated" / "vision_system.py")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ))
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        assert all(line.startswith("frame ") for line in lines), lines
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, err
    name = signal.Signals(signum).name
    assert f"stopped by {name} after " in err and "every component was freed" in err
    assert "Traceback" not in err


def test_broken_kernel_is_reported_before_the_first_frame(tmp_path):
    require_opencl()
    out = tmp_path / "out"
    write(compile_model(DATA / "broken_kernel" / "broken.yaml", out), out)
    proc = run_program(out / "broken.py", "--frames", "3")
    assert proc.returncode == 1
    assert "error: shaper (Broken): kernel file broken.cl failed to build" in proc.stderr
    assert "undeclared_variable" in proc.stderr  # from the OpenCL build log
    assert "frame 0" not in proc.stdout
    assert "Traceback" not in proc.stderr


def test_device_memory_check_states_bytes_needed_and_available():
    device = SimpleNamespace(name="tiny device ", max_mem_alloc_size=1000,
                             global_mem_size=2500)
    check_device_memory(device, {"a.out": 1000, "b.out": 1000})
    with pytest.raises(PipelineError, match=r"b.out needs a device buffer of 1,001 bytes, but "
                                            r"device 'tiny device' allows at most 1,000"):
        check_device_memory(device, {"a.out": 10, "b.out": 1001})
    with pytest.raises(PipelineError, match=r"needs 3,000 bytes of device memory .* has 2,500"):
        check_device_memory(device, {"a": 1000, "b": 1000, "c": 1000})


def test_oversized_frame_is_refused_before_streaming(tmp_path):
    """Built for a described device with room for it; run on one without."""
    require_opencl()
    import pyopencl as cl

    device = cl.create_some_context(interactive=False).devices[0]
    side = 16384
    per_merge = side * side * 4 * 3  # merger2.merged: four side x side RGB frames
    if per_merge <= device.max_mem_alloc_size:
        pytest.skip(f"device allows {device.max_mem_alloc_size} bytes in one buffer")
    program = build_model(tmp_path, f"""\
        system: huge
        platform:
          device: {{profile: portable, max_mem_alloc_size: {per_merge * 2},
                   global_mem_size: {per_merge * 8}}}
        components:
          camera: {{type: Camera, params: {{width: {side}, height: {side}}}}}
          merger: {{type: ImageMerger}}
          merger2: {{type: ImageMerger}}
          detector: {{type: ObjectDetector}}
          manager: {{type: VisionManager}}
        connections:
          - camera.image -> merger.left
          - camera.image -> merger.right
          - merger.merged -> merger2.left
          - merger.merged -> merger2.right
          - merger2.merged -> detector.frame
          - detector.mask -> manager.mask
        """)
    proc = run_program(program, "--frames", "1")
    assert proc.returncode == 1
    assert f"merger2.merged needs a device buffer of {per_merge:,} bytes" in proc.stderr
    assert f"allows at most {device.max_mem_alloc_size:,} bytes" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_missing_input_folder_is_named(tmp_path):
    require_opencl()
    missing = tmp_path / "no-such-folder"
    program = build_model(tmp_path, f"""\
        system: from_folder
        components:
          camera: {{type: Camera, params: {{width: 32, height: 16,
                                           folder: "{missing.as_posix()}"}}}}
          detector: {{type: ObjectDetector}}
          manager: {{type: VisionManager}}
        connections:
          - camera.image -> detector.frame
          - detector.mask -> manager.mask
        """)
    proc = run_program(program)
    assert proc.returncode == 1
    assert (f"error: camera failed while initializing: image folder '{missing.as_posix()}' "
            "does not exist") in proc.stderr
    assert "Traceback" not in proc.stderr


def test_unknown_runtime_option_is_refused(tmp_path):
    require_opencl()
    program, _ = lifecycle_model(tmp_path)
    proc = run_program(program, "--decisions", str(tmp_path / "d.txt"))
    assert proc.returncode == 1
    assert "no component of this system takes --decisions" in proc.stderr


class _Terminal:
    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, text):
        self.text += text

    def flush(self):
        pass


def test_progress_shows_on_a_terminal_only():
    term = _Terminal()
    monitor = Monitor(stream=term)
    monitor.attach({})
    monitor.frame_done(1)
    monitor.close()
    assert "1 frames, " in term.text and "frames/s" in term.text
    assert Monitor(stream=SimpleNamespace(isatty=lambda: False)).progress is False
    assert Monitor(stream=term, progress=False).progress is False


def test_gpucompgen_run_forwards_sigterm_to_the_program(tmp_path):
    require_opencl()
    proc = subprocess.Popen([sys.executable, "-m", "gpucompgen", "run",
                             str(ROOT / "models" / "vision_system.yaml")], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ))
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert all(line.startswith("frame ") for line in lines), lines
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, err
    assert "stopped by SIGTERM" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


# --- each part freed exactly once, only if initialized (issue 22) --------------------------

def test_a_failure_in_initialize_frees_only_the_parts_initialized(tmp_path):
    """flaky.initialize() raises: flaky and the recorder after it were never initialized,
    so neither is freed (before, both were); the error names flaky."""
    require_opencl()
    program, log = lifecycle_model(tmp_path, fail_initialize=True)
    text = program.read_text()
    assert text.index("flaky.initialize(") < text.index("recorder.initialize(")
    proc = run_program(program)
    assert proc.returncode == 1, proc.stderr
    assert "flaky failed while initializing: RuntimeError: injected failure to initialize" \
        in proc.stderr
    assert not log.exists()


def test_parts_are_freed_once_whoever_frees_them(tmp_path):
    """free_all after run(), and the signal path's free_what_can_be_freed after that,
    free nothing again."""
    require_opencl()
    from gpucompgen.runtime.signals import free_what_can_be_freed

    program, log = lifecycle_model(tmp_path, frames=2)
    module = load_generated(program, "lifecycle_once")
    result = module.run(monitor=Monitor(progress=False, options={"quiet": True}))
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]
    free_all(result.components)
    assert free_what_can_be_freed(result.components, 0.5) == ([], [])
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]


def test_stats_json_to_a_fifo_nobody_reads_ends_with_an_error(tmp_path):
    """Before: the run blocked after its frames opening the FIFO, ignored SIGTERM and then
    freed every component a second time."""
    require_opencl()
    program, log = lifecycle_model(tmp_path, frames=2)
    fifo = tmp_path / "stats.fifo"
    os.mkfifo(fifo)
    proc = run_program(program, "--stats-json", str(fifo))
    assert proc.returncode == 1, proc.stderr
    assert f"cannot write stats to {fifo}: it is a FIFO that no process reads" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert log.read_text().splitlines() == ["free recorder", "free flaky"]


def test_stats_json_to_a_fifo_with_a_reader_is_written(tmp_path):
    require_opencl()
    import json
    import threading

    program, _ = lifecycle_model(tmp_path, frames=2)
    fifo = tmp_path / "stats.fifo"
    os.mkfifo(fifo)
    got = []

    def read():
        with open(fifo, encoding="utf-8") as f:
            got.append(f.read())

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    proc = run_program(program, "--stats-json", str(fifo))
    reader.join(30)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(got[0])["frames"] == 2


class _Part:
    """A part of a hand-made session: records when it is freed, fails when told."""

    def __init__(self, name, freed, fail=None):
        self.name, self.freed, self.fail = name, freed, fail

    def initialize(self):
        return None

    def execute(self):
        if self.fail is not None:
            raise self.fail

    def free_memory(self):
        self.freed.append(self.name)


def _session_run(fail_b, frames_before=1):
    """A run() as generated programs write it, around three parts; b fails at its
    execute() after frames_before frames; (the exception run() raised, freed, monitor)."""
    freed = []
    monitor = runtime.Monitor(progress=False)
    session = runtime.Session({}, None, monitor, False, ["a", "b", "c"])
    try:
        with session:
            parts = session.parts
            a = parts["a"] = _Part("a", freed)
            b = parts["b"] = _Part("b", freed)
            parts["c"] = _Part("c", freed)  # constructed, never initialized: not freed
            session.start()
            a.initialize()
            b.initialize()
            session.frame = 0
            for _ in range(frames_before):
                a.execute()
                b.execute()
                session.frame_done()
            b.fail = fail_b
            b.execute()
    except BaseException as exc:
        return exc, freed, monitor
    return None, freed, monitor


def test_a_session_names_the_failing_part_and_frame_and_frees_what_was_initialized():
    exc, freed, monitor = _session_run(ValueError("bad pixel"), frames_before=2)
    assert isinstance(exc, runtime.PipelineError)
    assert str(exc) == "b failed at frame 2: ValueError: bad pixel"
    assert isinstance(exc.__cause__, ValueError)
    assert freed == ["b", "a"]  # reverse order, once each; c was never initialized
    assert monitor._closed


def test_a_session_lets_an_interrupt_through_after_freeing():
    exc, freed, monitor = _session_run(KeyboardInterrupt())
    assert type(exc) is KeyboardInterrupt
    assert freed == ["b", "a"] and monitor._closed


def test_a_session_that_ends_returns_its_frames_and_parts():
    freed = []
    session = runtime.Session({"a.k": runtime.Param("int", 3)}, {"a.k": 5}, None, False,
                              ["a"])
    with session:
        a = session.parts["a"] = _Part("a", freed)
        session.start()
        a.initialize()
        session.frame = 0
        for _ in range(4):
            session.frame_done()
    result = session.result()
    assert (result.frames, list(result.components), freed) == (4, ["a"], ["a"])
    assert session.params == {"a.k": 5}
