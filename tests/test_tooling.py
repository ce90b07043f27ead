"""Everyday tooling: --check/--diff, ruff-clean output, graph, run options, help."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
from conftest import IN_CI, ROOT, require_opencl

from gpucompgen.build import compile_model, write
from gpucompgen.graph import dot_text, quote

MODELS = sorted((ROOT / "models").glob("*.yaml"))
VISION = ROOT / "models" / "vision_system.yaml"


def gpucompgen(*args, cwd=ROOT, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpucompgen", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, check=False, timeout=300,
                          env=env or dict(os.environ))


@pytest.mark.parametrize("model", MODELS, ids=lambda p: p.stem)
def test_check_passes_on_the_repository(model):
    proc = gpucompgen("build", model.relative_to(ROOT), "-o", "generated", "--check")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout == "" and "up to date" in proc.stderr


def test_check_fails_after_a_model_edit_and_diff_writes_nothing(tmp_path):
    (tmp_path / "models").mkdir()
    shutil.copytree(ROOT / "generated", tmp_path / "generated")
    model = tmp_path / "models" / "vision_system.yaml"
    model.write_text(VISION.read_text().replace("red_min: 150", "red_min: 140"))
    before = (tmp_path / "generated" / "vision_system.py").read_bytes()

    proc = gpucompgen("build", "models/vision_system.yaml", "--check", cwd=tmp_path)
    assert proc.returncode == 1
    assert "is stale" in proc.stderr
    assert "--- a/vision_system.py\n+++ b/vision_system.py\n" in proc.stdout
    # the detector's parameter is a kernel argument of the fused merger_detector group, read
    # from the PARAMS table (where --set can change it)
    assert "-    'detector.red_min': runtime.Param('int', 150, minimum=0, maximum=255),\n" \
        in proc.stdout
    assert "+    'detector.red_min': runtime.Param('int', 140, minimum=0, maximum=255),\n" \
        in proc.stdout

    proc = gpucompgen("build", "models/vision_system.yaml", "--diff", cwd=tmp_path)
    assert proc.returncode == 0 and "runtime.Param('int', 140" in proc.stdout
    assert (tmp_path / "generated" / "vision_system.py").read_bytes() == before

    assert gpucompgen("build", "models/vision_system.yaml", cwd=tmp_path).returncode == 0
    proc = gpucompgen("build", "models/vision_system.yaml", "--check", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout == ""


def test_check_ignores_the_bytecode_cache_a_run_of_the_program_writes(tmp_path):
    """Running a generated program imports its lib folder's modules, and Python caches
    their bytecode there (lib/__pycache__/, as CI's Python does): that is not output, so
    `build --check` stays current, while a stray file of the build's own is stale."""
    for part in ("golden/every_branch", "data/user_model"):  # the model reads its types
        shutil.copytree(ROOT / "tests" / part, tmp_path / part)
    where = tmp_path / "golden" / "every_branch"
    lib = where / "default" / "every_branch_lib"
    modules = sorted(lib.glob("*.py"))
    assert modules, "the model has Python modules in its lib folder"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    subprocess.run([sys.executable, "-c", "import sys, importlib; sys.path.insert(0, sys.argv[1]);"
                    " [importlib.import_module(m) for m in sys.argv[2:]]", str(lib),
                    *(m.stem for m in modules)], check=True, env=env, timeout=120)
    assert list((lib / "__pycache__").glob("*.pyc")), "Python wrote no bytecode"
    check = ("build", "every_branch.yaml", "-o", "default", "--check")
    proc = gpucompgen(*check, cwd=where)
    assert proc.returncode == 0 and proc.stdout == "", proc.stdout + proc.stderr

    (lib / "stray.cl").write_text("// not the build's\n")
    proc = gpucompgen(*check, cwd=where)
    assert proc.returncode == 1 and "stray.cl" in proc.stdout


def test_generated_code_passes_ruff(tmp_path):
    """Every model, the tests' user models too (types without descriptions, user Python
    components), in both modes and with copying or zero-copy adapters."""
    systems = MODELS + sorted(p for p in (ROOT / "tests" / "data").glob("*/*.yaml")
                              if p.read_text().startswith("system:"))
    out = tmp_path / "builds"
    for model in systems:
        for mode, zero_copy in (("gpu-aware", "off"), ("gpu-aware", "on"), ("standard", "off")):
            target = out / f"{model.stem}-{mode}-{zero_copy}"
            write(compile_model(model, target, mode=mode, zero_copy=zero_copy), target)
    assert len(list(out.glob("*/*.py"))) == 3 * len(systems)
    for target in (ROOT / "generated", out):
        # the project's ruff settings, plus pycodestyle warnings (trailing whitespace)
        proc = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache",
                               "--extend-select", "W", str(target)], cwd=ROOT,
                              capture_output=True, text=True, check=False)
        assert proc.returncode == 0, proc.stdout + proc.stderr


def test_the_whole_repository_passes_ruff():
    proc = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], cwd=ROOT,
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_graph_shows_the_three_generated_adapters_and_sizes():
    system = compile_model(VISION, ROOT / "generated").system
    text = dot_text(system)
    for adapter in ("adapter1_cpu2gpu", "adapter2_cpu2gpu", "adapter3_gpu2cpu"):
        assert f'"{adapter}" [label="{adapter}\\ngenerated adapter' in text
    assert '"camera1" -> "adapter1_cpu2gpu" [label="480x640x3 uint8"' in text
    assert '"adapter1_cpu2gpu" -> "merger" [label="480x640x3 uint8", headlabel="left [GPU]"]' \
        in text
    # fused (the default): the group is a cluster and the edge inside it carries no buffer
    assert 'subgraph "cluster_merger_detector" {' in text
    assert '"merger" -> "detector" [style=dashed, label="fused", taillabel="merged [GPU]", ' \
           'headlabel="frame [GPU]"]' in text
    unfused = dot_text(compile_model(VISION, ROOT / "generated", fusion="off").system)
    assert "cluster" not in unfused
    assert '"merger" -> "detector" [label="480x1280x3 uint8", taillabel="merged [GPU]", ' \
           'headlabel="frame [GPU]"]' in unfused
    assert '"merger" [label="merger\\nImageMerger\\nGPU-aware", peripheries=2' in text
    assert text == dot_text(compile_model(VISION, ROOT / "generated").system)

    standard = dot_text(compile_model(VISION, ROOT / "generated", mode="standard").system)
    assert "adapter" not in standard and "[GPU]" not in standard
    assert '"camera1" -> "merger" [label="480x640x3 uint8"' in standard


def test_dot_names_are_quoted_and_escaped():
    assert quote('a "b"\\c\nd') == '"a \\"b\\"\\\\c\\nd"'


@pytest.mark.parametrize("suffix", [".dot", ".svg", ".png"])
def test_graph_command_writes_each_format(tmp_path, suffix):
    if suffix != ".dot" and shutil.which("dot") is None:
        if IN_CI:
            pytest.fail("CI=true but Graphviz's dot is missing: .ci/run installs graphviz")
        pytest.skip("Graphviz's dot is not installed (apt-get install graphviz)")
    target = tmp_path / f"vision{suffix}"
    proc = gpucompgen("graph", VISION, "-o", target)
    assert proc.returncode == 0, proc.stderr
    data = target.read_bytes()
    magic = {".dot": b'digraph "vision_system"', ".svg": b"<?xml", ".png": b"\x89PNG"}[suffix]
    assert data.startswith(magic)
    if suffix == ".svg":
        assert b"adapter3_gpu2cpu" in data


def test_graph_without_dot_says_what_to_install(tmp_path):
    env = dict(os.environ, PATH=str(tmp_path))  # no dot here
    proc = subprocess.run([sys.executable, "-m", "gpucompgen", "graph", str(VISION), "-o",
                           str(tmp_path / "v.svg")], capture_output=True, text=True,
                          check=False, env=env, cwd=ROOT)
    assert proc.returncode == 2
    assert "needs Graphviz's 'dot' program" in proc.stderr and "Traceback" not in proc.stderr
    assert gpucompgen("graph", VISION, "-o", tmp_path / "v.txt").returncode == 2


def test_stats_json_has_the_promised_fields(tmp_path):
    require_opencl()
    stats = tmp_path / "stats.json"
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "vision_system.py"),
                           "--frames", "3", "--quiet", "--stats-json", str(stats)],
                          capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""  # --quiet, and no terminal: no progress
    doc = json.loads(stats.read_text())
    assert doc["frames"] == 3
    assert len(doc["frame_seconds"]) == 3 and all(t > 0 for t in doc["frame_seconds"])
    assert doc["wall_seconds"] > 0 and doc["frames_per_second"] > 0
    assert list(doc["components"]) == [  # merger and detector run as one fused group
        "camera1", "camera2", "adapter1_cpu2gpu", "adapter2_cpu2gpu", "merger_detector",
        "adapter3_gpu2cpu", "manager"]
    for name, c in doc["components"].items():
        assert set(c) == {"calls", "total_seconds", "mean_seconds", "max_seconds"}, name
        assert c["calls"] == 3 and c["max_seconds"] <= c["total_seconds"], name


def _on_a_terminal(cmd: list[str], timeout: float = 300) -> tuple[int, str]:
    """Run cmd with stdout and stderr on a pseudo-terminal; (exit code, all it wrote)."""
    import pty
    import select

    master, slave = pty.openpty()
    proc = subprocess.Popen(cmd, stdout=slave, stderr=slave, stdin=subprocess.DEVNULL,
                            close_fds=True)
    os.close(slave)
    chunks = []
    try:
        while True:
            ready, _, _ = select.select([master], [], [], timeout)
            if not ready:
                proc.kill()
                raise AssertionError(f"no output for {timeout} s")
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the program closed the terminal
                break
            if not data:
                break
            chunks.append(data)
    finally:
        os.close(master)
    return proc.wait(timeout=timeout), b"".join(chunks).decode("utf-8", "replace")


def _screen_lines(output: str) -> list[str]:
    """What each line shows: a carriage return starts the line over, ESC[K clears it."""
    return [line.replace("\r\n", "").split("\r")[-1].replace("\x1b[K", "")
            for line in output.replace("\r\n", "\n").split("\n")]


def test_progress_on_a_terminal_never_shares_a_line_with_decisions():
    """The progress line (stderr) is cleared before a component prints (stdout)."""
    require_opencl()
    code, output = _on_a_terminal([sys.executable, str(ROOT / "generated" / "vision_system.py"),
                                   "--frames", "6"])
    assert code == 0, output
    assert "frames/s" in output, "a terminal shows progress"
    shown = [line for line in _screen_lines(output) if line.strip()]
    decisions = [line for line in shown if line.startswith("frame ")]
    assert [d.split(":")[0] for d in decisions] == [f"frame {i}" for i in range(6)]
    assert not [line for line in shown if "frames/s" in line and "frame " in
                line.replace("frames", "")], shown


def test_run_passes_the_program_options_through(tmp_path):
    require_opencl()
    proc = gpucompgen("run", VISION, "--frames", "2", "--quiet", "--decisions",
                      tmp_path / "d.txt", "--save-images", tmp_path / "img",
                      "--stats-json", tmp_path / "s.json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ""
    lines = (tmp_path / "d.txt").read_text().splitlines()
    assert [line.split(":")[0] for line in lines] == ["frame 0", "frame 1"]
    assert sorted(p.name for p in (tmp_path / "img").iterdir()) == [
        "annotated_000000.png", "annotated_000001.png", "mask_000000.png", "mask_000001.png"]
    assert json.loads((tmp_path / "s.json").read_text())["frames"] == 2


def test_decisions_as_json_lines(tmp_path):
    require_opencl()
    target = tmp_path / "d.jsonl"
    proc = subprocess.run([sys.executable, str(ROOT / "generated" / "vision_system.py"),
                           "--frames", "2", "--decisions", str(target)],
                          capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(line) for line in target.read_text().splitlines()]
    assert [r["frame"] for r in rows] == [0, 1]
    assert rows[0]["action"] in ("forward", "turn_left", "turn_right", "stop", "search")
    assert set(rows[0]["sightings"][0]) == {"x", "y", "area", "radius"}


@pytest.mark.parametrize("command", [None, "build", "run", "check", "plan", "graph"])
def test_help_reads_well(command):
    proc = gpucompgen(*([command] if command else []), "--help")
    assert proc.returncode == 0
    assert proc.stdout.startswith("usage: gpucompgen")
    if command is None:
        assert "exit codes:" in proc.stdout and "examples:" in proc.stdout
    else:
        assert "MODEL" in proc.stdout


def test_version():
    proc = gpucompgen("--version")
    assert proc.returncode == 0 and proc.stdout.startswith("gpucompgen ")


def test_the_runtime_pins_pocl_threads_unless_told_otherwise():
    """Importing the runtime sets POCL_AFFINITY=1 (PoCL's worker threads one a core: see
    runtime/opencl.py for the measurement), and leaves a value the user gave."""
    probe = "import os, gpucompgen.runtime; print(os.environ.get('POCL_AFFINITY'))"
    env = {k: v for k, v in os.environ.items() if k != "POCL_AFFINITY"}
    for given, expected in ((None, "1"), ("0", "0"), ("1", "1")):
        run_env = env if given is None else {**env, "POCL_AFFINITY": given}
        proc = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=run_env,
                              capture_output=True, text=True, check=False, timeout=120)
        assert proc.returncode == 0 and proc.stdout.strip() == expected, proc.stderr
