"""Run-time messages: user modules that fail at import, kernel build errors, work-group
limits that do not fit. Each problem is one clear message naming the file (and line),
without tracebacks or compiler chatter."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT, load_generated, require_opencl

from gpucompgen.build import compile_model, write
from gpucompgen.runtime import PipelineError, build_program, load_class
from gpucompgen.runtime.devices import KernelLimits, check_work_group_fits, fitting_block
from gpucompgen.runtime.facts import DeviceFacts
from gpucompgen.runtime.programs import clean_build_log

DATA = ROOT / "tests" / "data"

# (module text, expected message after the path) for modules that cannot give MeanProbe
BAD_MODULES = {
    "syntax": ("import numpy\n\nclass MeanProbe(\n    pass\n",
               ":3:16: error: SyntaxError: "),
    "indentation": ("class MeanProbe:\n    def f(self):\n    pass\n",
                    ":3:5: error: IndentationError: expected an indented block"),
    "raises": ("import os\n\nraise ValueError('bad\\nsetting')\n",
               ":3: error: importing it raised ValueError: bad setting"),
    "raises_in_function": ("def setup():\n    return {}['missing']\n\nTABLE = setup()\n",
                           ":2: error: importing it raised KeyError: 'missing'"),
    "missing_import": ("import no_such_module_for_gpucompgen\n",
                       ":1: error: importing it raised ModuleNotFoundError: No module named "
                       "'no_such_module_for_gpucompgen'"),
    "exits": ("import sys\nsys.exit(3)\n",
              ":2: error: it exits while being imported (sys.exit(3))"),
    "missing_class": ("class OtherProbe:\n    pass\n",
                      ": error: defines no class MeanProbe"),
    "not_a_class": ("MeanProbe = 42\n", ": error: MeanProbe is a int, not a class"),
    "not_utf8": (b"NAME = 'caf\xe9'\nclass MeanProbe:\n    pass\n",
                 ":1:"),  # the column is Python's: 14 on 3.11, 8 on 3.12
}


def _write(path: Path, text: str | bytes) -> None:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")


@pytest.mark.parametrize("case", sorted(BAD_MODULES))
def test_load_class_names_the_file_and_the_problem_on_one_line(tmp_path, case):
    text, expected = BAD_MODULES[case]
    path = tmp_path / f"probe_{case}.py"
    _write(path, text)
    with pytest.raises(PipelineError) as caught:
        load_class(path, "MeanProbe")
    message = str(caught.value)
    assert message.startswith(f"{path}{expected}"), message
    if case == "not_utf8":
        assert ": error: SyntaxError: (unicode error) 'utf-8' codec can't decode byte" \
            in message, message
    assert "\n" not in message
    if "class" not in case:  # a module that failed to import is not kept
        assert f"gpucompgen_user_{path.stem}" not in sys.modules


def test_load_class_of_a_missing_file(tmp_path):
    path = tmp_path / "gone.py"
    with pytest.raises(PipelineError, match=r"gone\.py: error: cannot import it: no such file"):
        load_class(path, "MeanProbe")


def test_load_class_still_loads_a_good_module_once(tmp_path):
    path = tmp_path / "probe_good.py"
    path.write_text("class MeanProbe:\n    pass\n", encoding="utf-8")
    first = load_class(path, "MeanProbe")
    assert first.__name__ == "MeanProbe" and load_class(path, "MeanProbe") is first


@pytest.fixture(scope="module")
def bright(tmp_path_factory):
    """The user model built once; each test copies the output and spoils probe.py."""
    out = tmp_path_factory.mktemp("bright") / "out"
    write(compile_model(DATA / "user_model" / "bright.yaml", out), out)
    return out


@pytest.mark.parametrize("case", ["syntax", "raises", "missing_class", "exits", "not_a_class"])
def test_a_program_whose_user_module_fails_at_import_says_so_in_one_line(tmp_path, bright,
                                                                          case):
    require_opencl()
    out = tmp_path / "out"
    shutil.copytree(bright, out)
    probe = out / "bright_lib" / "probe.py"
    text, expected = BAD_MODULES[case]
    _write(probe, text)
    proc = subprocess.run([sys.executable, str(out / "bright.py"), "--frames", "2"],
                          capture_output=True, text=True, timeout=300, check=False,
                          env=dict(os.environ))
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"{probe.resolve()}{expected}"), lines
    with pytest.raises(PipelineError) as caught:  # imported, not run: the same error
        load_generated(out / "bright.py", f"bright_{case}")
    assert str(caught.value) == lines[0]
    debug = subprocess.run([sys.executable, str(out / "bright.py"), "--debug"],
                           capture_output=True, text=True, timeout=300, check=False,
                           env=dict(os.environ))
    assert debug.returncode == 1
    assert "Traceback" in debug.stderr and lines[0] in debug.stderr


# -- kernel build errors ---------------------------------------------------------------------

def _build(context, tmp_path: Path, source: str, name: str = "k.cl"):
    path = tmp_path / name
    path.write_text(source, encoding="utf-8")
    return build_program(context, path, "shaper (Broken)")


KERNEL_ERRORS = {
    "undeclared": ("__kernel void k(__global int *x)\n{\n    x[0] = nope;\n}\n",
                   ["k.cl:3:12: error: use of undeclared identifier 'nope'"]),
    "two_errors": ("__kernel void k(__global int *x)\n{\n    x[0] = a;\n    x[1] = b;\n}\n",
                   ["k.cl:3:12: error: use of undeclared identifier 'a'",
                    "k.cl:4:12: error: use of undeclared identifier 'b'"]),
    "generated_header": ("// Code generated by gpucompgen from m.yaml. DO NOT EDIT.\n"
                         "// Kernel of component type Broken.\n\n"
                         "__kernel void k(__global int *x)\n{\n    x[0] = nope;\n}\n",
                         # the line of the user's own file, not of the copy
                         ["k.cl:3:12: error: use of undeclared identifier 'nope'"]),
}


@pytest.mark.parametrize("case", sorted(KERNEL_ERRORS))
def test_a_kernel_build_error_is_the_compilers_message_once(cl_context, tmp_path, capfd,
                                                              case):
    source, expected = KERNEL_ERRORS[case]
    with pytest.raises(PipelineError) as caught:
        _build(cl_context, tmp_path, source)
    message = str(caught.value)
    lines = message.splitlines()
    assert lines[0] == "shaper (Broken): kernel file k.cl failed to build:"
    if "Portable Computing Language" in cl_context.devices[0].platform.name:
        assert [line.strip() for line in lines[1:]] == expected, message
    for noise in ("BUILD_PROGRAM_FAILURE", "generated.", "Build on", "(options:",
                  "failed to build the program"):
        assert noise not in "\n".join(lines[1:]), message
    out, err = capfd.readouterr()
    assert "error generated" not in err  # PoCL's chatter on file descriptor 2
    assert "nope" not in out + err


def test_a_kernel_that_builds_still_builds(cl_context, tmp_path):
    program = _build(cl_context, tmp_path, "__kernel void k(__global int *x) { x[0] = 1; }\n")
    assert program.k is not None


def test_an_unreadable_kernel_file_is_named(cl_context, tmp_path):
    with pytest.raises(PipelineError, match=r"shaper \(Broken\): cannot read kernel file"):
        build_program(cl_context, tmp_path / "missing.cl", "shaper (Broken)")
    bad = tmp_path / "latin1.cl"
    bad.write_bytes(b"// caf\xe9\n__kernel void k(__global int *x) { x[0] = 1; }\n")
    with pytest.raises(PipelineError, match=r"latin1\.cl is not UTF-8 text \(byte 6\)"):
        build_program(cl_context, bad, "shaper (Broken)")


def test_clean_build_log_drops_chatter_and_repeats():
    log = ("error: k.cl:3:12: use of undeclared identifier 'nope'\n"
           "1 error generated.\n"
           "Device pthread-haswell-AMD EPYC failed to build the program\n"
           "error: k.cl:3:12: use of undeclared identifier 'nope'\n"
           "k.cl(4): warning: unused variable\n"
           "2 errors and 1 warning generated.\n\n")
    assert clean_build_log(log) == ["k.cl:3:12: error: use of undeclared identifier 'nope'",
                                    "k.cl(4): warning: unused variable"]
    many = "\n".join(f"k.cl:{i}:1: error: e{i}" for i in range(100))
    cleaned = clean_build_log(many)
    assert len(cleaned) == 41 and cleaned[-1] == "... (60 more lines)"


def test_the_broken_kernel_program_reports_its_log_once(tmp_path):
    require_opencl()
    out = tmp_path / "out"
    write(compile_model(DATA / "broken_kernel" / "broken.yaml", out), out)
    proc = subprocess.run([sys.executable, str(out / "broken.py"), "--frames", "3"],
                          capture_output=True, text=True, timeout=300, check=False,
                          env=dict(os.environ))
    assert proc.returncode == 1
    lines = proc.stderr.splitlines()
    assert lines[0] == "error: shaper (Broken): kernel file broken.cl failed to build:", lines
    assert "1 error generated." not in proc.stderr
    # once: one message (NVIDIA's compiler also echoes the source line under it)
    assert len([line for line in lines if "error:" in line and "undeclared" in line]) == 1
    # the kernel file's own line, whatever the compiler does with #line (NVIDIA ignores it)
    assert lines[1].strip().startswith("broken.cl:5:"), lines


# -- work-group limits -------------------------------------------------------------------------

# The check is the runtime core's: the kernel's limits and the device's facts in, no device
# (the OpenCL module's check_work_group queries them; test_parallel_and_zero_copy.py).

def fake_facts(max_work_item_sizes=(1024, 1024, 64)):
    return DeviceFacts(name="Fake GPU", compute_units=8, max_work_group_size=1024,
                       max_work_item_sizes=max_work_item_sizes, local_mem_size=48 * 1024,
                       global_mem_size=4 * 2**30, max_mem_alloc_size=2**30,
                       host_unified_memory=False)


def test_settings_that_fit_pass():
    limits = check_work_group_fits(KernelLimits(256, 32), fake_facts(), (16, 16, 1),
                                   "detector")
    assert limits.work_group_size == 256
    check_work_group_fits(KernelLimits(256, 32), fake_facts(), (16, 16, 1), "detector",
                          settings_source="model")


@pytest.mark.parametrize("local,wg,dims,fit", [
    ((32, 32, 1), 256, (1024, 1024, 64), (16, 16, 1)),
    ((64, 4, 1), 128, (1024, 1024, 64), (32, 4, 1)),
    ((16, 16, 8), 1024, (1024, 1024, 4), (16, 16, 4)),
    ((8, 8, 1), 1, (1024, 1024, 64), (1, 1, 1)),
])
def test_settings_from_the_model_say_what_to_change_there(local, wg, dims, fit):
    threads = local[0] * local[1] * local[2]
    with pytest.raises(PipelineError) as caught:
        check_work_group_fits(KernelLimits(wg, 32), fake_facts(dims), local, "detector",
                              settings_source="model")
    message = str(caught.value)
    assert message.startswith(f"detector: GPU settings {local} ({threads:,} threads) do not "
                              f"fit device 'Fake GPU' (kernel limit {wg:,} threads")
    assert ("the settings come from the model: change platform.gpu_settings.detector there "
            f"to fit, e.g. block_x: {fit[0]}, block_y: {fit[1]}, block_z: {fit[2]}") in message
    assert "--device auto" not in message
    # the suggestion really fits, and the default advice stays the rebuild
    assert fit[0] * fit[1] * fit[2] <= wg and all(v <= d for v, d in zip(fit, dims))
    with pytest.raises(PipelineError, match=r"rebuild for this device with 'gpucompgen build "
                                            r"--device auto'$"):
        check_work_group_fits(KernelLimits(wg, 32), fake_facts(dims), local, "detector")


def test_fitting_block_keeps_what_fits_and_halves_the_largest():
    assert fitting_block((8, 8, 1), 1024, (1024, 1024, 64)) == (8, 8, 1)
    assert fitting_block((2048, 1, 1), 1024, (1024, 1024, 64)) == (1024, 1, 1)
    assert fitting_block((100, 100, 1), 1000, (1024, 1024, 64)) == (25, 25, 1)
    assert fitting_block((7,), 4, (1024,)) == (3,)


@pytest.mark.parametrize("where,message", [
    ("folder", "--stats-json {tmp}: is a folder; name a file"),
    ("missing", "--stats-json {tmp}/no/s.json: folder {tmp}/no does not exist"),
])
def test_a_stats_file_that_cannot_be_written_is_a_usage_error_before_the_run(tmp_path, where,
                                                                             message):
    target = tmp_path if where == "folder" else tmp_path / "no" / "s.json"
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "vision_system.py"),
                           "--frames", "2", "--stats-json", str(target)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2
    assert message.format(tmp=tmp_path) in proc.stderr
    assert "frame 0" not in proc.stdout, "nothing ran"


def test_stats_that_fail_to_be_written_after_the_run_fail_the_run(tmp_path):
    """The folder checked before the run can still go away during it: exit 1, not 0."""
    require_opencl()
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(f"""\
        import sys
        from gpucompgen.runtime import monitor
        real = monitor.Monitor.write_stats
        def write(self, path):
            real(self, path / "x" / "y")  # a path whose folder does not exist
        monitor.Monitor.write_stats = write
        sys.argv = ["p", "--frames", "1", "-q", "--stats-json", {str(tmp_path / 'ok.json')!r}]
        import runpy
        runpy.run_path({str(ROOT / 'generated' / 'vision_system.py')!r}, run_name="__main__")
        """)], capture_output=True, text=True, timeout=120, check=False, cwd=ROOT)
    assert proc.returncode == 1, proc.stderr
    assert "error: cannot write stats to " in proc.stderr


# -- a kernel that faulted on a GPU surfaces at the next command -------------------------------

class _DeviceError(RuntimeError):
    def __init__(self, code):
        super().__init__("clEnqueueReadBuffer failed: OUT_OF_RESOURCES")
        self.code = code


@pytest.mark.parametrize("code,hinted", [(-5, True), (-36, True), (-14, True), (-4, False),
                                         (None, False)])
def test_a_device_fault_at_the_next_command_points_at_the_kernels_before_it(code, hinted):
    from gpucompgen.runtime.lifecycle import component_failure

    message = str(component_failure(_DeviceError(code), 3, {"adapter2_gpu2cpu": object()}))
    assert message.startswith("a component failed at frame 3: _DeviceError: clEnqueueReadBuffer")
    assert ("out of bounds" in message) is hinted, message
