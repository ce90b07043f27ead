"""Hostile and confused inputs that static bad models cannot hold: FIFOs, device nodes,
directories and links given as files, files beyond the size caps, an alias bomb (in
time), kernel signatures parsed against hand-written expectations, size expressions
against hand-computed values, and the build's staging folders."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from gpucompgen import build as build_mod
from gpucompgen import sizeexpr
from gpucompgen.backend.opencl import signature
from gpucompgen.loader import MAX_FILE_BYTES, MAX_SOURCE_BYTES, FileProblem, read_text
from gpucompgen.model import library_types

TYPES = """\
component_types:
  Show:
    kind: standard
    inputs: {image: {channels: 3}}
    python: {file: show.py}
  Tint:
    kind: gpu-aware
    params: {gain: {type: float, default: 1.0}}
    inputs: {image: {memory: gpu, channels: 3}}
    outputs: {tinted: {memory: gpu, channels: 3}}
    kernel: {file: tint.cl, function: tint}
"""
KERNEL = """\
__kernel void tint(__global const uchar *image, __global uchar *tinted,
                   const int image_height, const int image_width,
                   const int tinted_height, const int tinted_width,
                   const float gain, const int tile)
{
}
"""
MODEL = """\
system: s
types: [types/t.yaml]
components:
  camera: {type: Camera, params: {width: 64, height: 48, frames: 1}}
  tint: {type: Tint}
  show: {type: Show}
connections: [camera.image -> tint.image, tint.tinted -> show.image]
"""


def gpucompgen(*args, cwd=None, timeout=60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpucompgen", *map(str, args)],
                          check=False, capture_output=True, text=True, cwd=cwd,
                          timeout=timeout)


@pytest.fixture
def project(tmp_path):
    """A working user model; tests break one of its files."""
    (tmp_path / "types").mkdir()
    (tmp_path / "types" / "t.yaml").write_text(TYPES)
    (tmp_path / "types" / "tint.cl").write_text(KERNEL)
    (tmp_path / "types" / "show.py").write_text("class Show:\n    pass\n")
    (tmp_path / "m.yaml").write_text(MODEL)
    return tmp_path


def check(project: Path, *args) -> subprocess.CompletedProcess:
    return gpucompgen("check", "m.yaml", *args, cwd=project)


def test_the_project_is_good(project):
    proc = check(project)
    assert proc.returncode == 0, proc.stderr


# ---------------------------------------------------------------- not regular files

@pytest.mark.parametrize("which", ["types/tint.cl", "types/show.py", "types/t.yaml"])
def test_a_fifo_is_refused_without_blocking(project, which):
    path = project / which
    text = path.read_text()
    path.unlink()
    os.mkfifo(path)
    start = time.monotonic()
    proc = check(project)
    assert time.monotonic() - start < 30, "check blocked on the FIFO"
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "is a FIFO, not a regular file" in proc.stderr, proc.stderr
    assert "not found" not in proc.stderr
    path.unlink()
    path.write_text(text)


@pytest.mark.parametrize("which", ["types/tint.cl", "types/show.py", "types/t.yaml"])
def test_a_directory_is_not_a_regular_file(project, which):
    path = project / which
    path.unlink()
    path.mkdir()
    proc = check(project)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "is a directory, not a regular file" in proc.stderr, proc.stderr


def test_a_device_node_is_not_a_regular_file(tmp_path):
    with pytest.raises(FileProblem, match="is a device node, not a regular file"):
        read_text(Path("/dev/zero"), 100, "kernel file")
    with pytest.raises(FileProblem, match="is a device node, not a regular file"):
        read_text(Path("/dev/null"), 100, "kernel file")


def test_a_type_file_that_is_a_device_node(project):
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", "/dev/null"))
    proc = check(project)
    assert "must be a .yaml or .yml file" in proc.stderr
    link = project / "null.yaml"
    link.symlink_to("/dev/null")
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", "null.yaml"))
    proc = check(project)
    assert proc.returncode == 1 and "is a device node, not a regular file" in proc.stderr


def test_a_model_that_is_a_fifo(tmp_path):
    fifo = tmp_path / "m.yaml"
    os.mkfifo(fifo)
    proc = gpucompgen("check", fifo, timeout=30)
    assert proc.returncode in (1, 2) and "not a regular file" in proc.stderr, proc.stderr
    assert "no such file" not in proc.stderr


# ---------------------------------------------------------------- size caps

@pytest.mark.parametrize("which,limit", [("types/tint.cl", MAX_SOURCE_BYTES),
                                         ("types/show.py", MAX_SOURCE_BYTES),
                                         ("types/t.yaml", MAX_FILE_BYTES)])
def test_files_beyond_the_cap_are_refused_and_never_copied(project, which, limit):
    path = project / which
    comment = "//" if which.endswith(".cl") else "#"
    path.write_text(path.read_text() + "\n" + comment + "x" * limit + "\n")
    proc = gpucompgen("build", "m.yaml", "-o", "out", cwd=project)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert f"is larger than {limit:,} bytes" in proc.stderr, proc.stderr
    assert not (project / "out").exists()


def test_reading_stops_at_the_cap_even_if_the_file_lies_about_its_size(tmp_path):
    path = tmp_path / "k.cl"
    path.write_text("x" * 5000)
    with pytest.raises(FileProblem, match="larger than 100 bytes"):
        read_text(path, 100, "kernel file")
    assert read_text(path, 5000, "kernel file") == "x" * 5000


# ---------------------------------------------------------------- links and paths

def test_a_link_out_of_the_type_folder_is_refused(project, tmp_path_factory):
    outside = tmp_path_factory.mktemp("elsewhere") / "tint.cl"
    outside.write_text(KERNEL)
    for name in ("tint.cl", "show.py"):
        target = outside.with_name(name)
        target.write_text((project / "types" / name).read_text())
        (project / "types" / name).unlink()
        (project / "types" / name).symlink_to(target)
    proc = gpucompgen("build", "m.yaml", "-o", "out", cwd=project)
    assert proc.returncode == 1
    assert proc.stderr.count("is a link to a file outside the folder of the type file") == 2
    assert not (project / "out").exists()


def test_a_link_inside_the_type_folder_is_fine(project):
    real = project / "types" / "impl"
    real.mkdir()
    os.replace(project / "types" / "tint.cl", real / "tint.cl")
    (project / "types" / "tint.cl").symlink_to(Path("impl") / "tint.cl")
    assert check(project).returncode == 0


def test_a_link_through_a_linked_folder_is_resolved(project, tmp_path_factory):
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    (elsewhere / "tint.cl").write_text(KERNEL)
    (project / "types" / "tint.cl").unlink()
    (project / "types" / "sub").symlink_to(elsewhere)
    (project / "types" / "t.yaml").write_text(TYPES.replace("file: tint.cl", "file: sub/tint.cl"))
    proc = check(project)
    assert proc.returncode == 1 and "outside the folder of the type file" in proc.stderr


def test_type_files_may_be_shared_by_relative_and_absolute_paths(project, tmp_path_factory):
    shared = tmp_path_factory.mktemp("shared")
    for name in ("t.yaml", "tint.cl", "show.py"):
        os.replace(project / "types" / name, shared / name)
    relative = os.path.relpath(shared / "t.yaml", project)
    assert relative.startswith("..")
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", relative))
    assert check(project).returncode == 0
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", str(shared / "t.yaml")))
    assert check(project).returncode == 0
    os.replace(shared / "t.yaml", shared / "t.yml")
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", str(shared / "t.yml")))
    assert check(project).returncode == 0


@pytest.mark.parametrize("secret", [
    "root:$6$S3cretHash$abc:19000:0:99999:7:::\n",
    "password: hunter2-S3cretHash\nother: 1\n",
    "- S3cretHash\n- two\n",
    "S3cretHash\n",
    "component_type: S3cretHash\n",
    "{S3cretHash: 1, S3cretHash: 2}\n",
    "&S3cretHash a: 1\n",
    "key: [S3cretHash\n",
])
def test_a_file_that_is_not_a_type_file_is_never_quoted(project, secret):
    (project / "secret.yaml").write_text(secret)
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", "secret.yaml"))
    proc = check(project)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "S3cretHash" not in proc.stderr + proc.stdout
    assert "is not a component-type file" in proc.stderr, proc.stderr


def test_a_binary_file_is_not_a_type_file(project):
    (project / "blob.yaml").write_bytes(b"\x7fELF\x02\x01\x01S3cretHash\xff\xfe")
    (project / "m.yaml").write_text(MODEL.replace("types/t.yaml", "blob.yaml"))
    proc = check(project)
    assert proc.returncode == 1 and "S3cretHash" not in proc.stderr
    assert "is not a component-type file (it is not UTF-8 text)" in proc.stderr


def test_a_type_file_with_a_bad_byte_later_is_reported_in_it(project):
    path = project / "types" / "t.yaml"
    path.write_bytes(path.read_bytes() + b"# caf\xe9\n")
    proc = check(project)
    assert "types/t.yaml:12:6: error: component-type file 'types/t.yaml' is not UTF-8 text" \
        in proc.stderr, proc.stderr
    assert "unknown component type" not in proc.stderr, "no errors that follow from it"


# ---------------------------------------------------------------- YAML alias bomb

def test_an_alias_bomb_is_refused_at_once(tmp_path):
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    for where in ("m.yaml", "types/t.yaml"):
        (tmp_path / "types").mkdir(exist_ok=True)
        (tmp_path / "types" / "t.yaml").write_text("component_types:\n  X: {}\n")
        (tmp_path / "m.yaml").write_text("system: s\ntypes: [types/t.yaml]\n")
        path = tmp_path / where
        path.write_text(path.read_text() + "\n".join(lines) + "\n")
        start = time.monotonic()
        proc = gpucompgen("check", "m.yaml", cwd=tmp_path, timeout=60)
        assert time.monotonic() - start < 20
        assert proc.returncode == 1 and "alias '*a8' is not allowed" in proc.stderr


def test_a_file_of_only_aliases_stops_after_a_hundred_problems(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("a: &a 1\nb: [" + ", ".join(["*a"] * 5000) + "]\n")
    proc = gpucompgen("check", path)
    assert proc.returncode == 1
    assert "more than 100 problems: stopped reading the file" in proc.stderr
    assert proc.stderr.count("error:") == 101


# ---------------------------------------------------------------- system size

def _fan(n: int) -> str:
    """A source feeding n mirrors, each into its own sink: 2n + 1 components."""
    lines = ["system: fan", "components:", "  source: {type: StillImage, params: {width: 16, height: 16}}"]
    lines += [f"  m{i}: VerticalMirror\n  s{i}: FrameSink" for i in range(n)]
    lines += ["connections:"]
    lines += [f"  - source.image -> m{i}.image\n  - m{i}.mirrored -> s{i}.image" for i in range(n)]
    return "\n".join(lines) + "\n"


def test_the_largest_system_allowed_builds(tmp_path):
    (tmp_path / "m.yaml").write_text(_fan(249))  # 499 components, 498 connections
    proc = gpucompgen("build", "m.yaml", "-o", "out", cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    # each mirror alone runs the kernel generated for it (class VerticalMirror<Name>)
    assert (tmp_path / "out" / "fan.py").read_text().count(" = VerticalMirror") == 249


def test_too_many_components_is_one_error_at_the_key(tmp_path):
    # scanning ports made checking a 12,000-component chain (a 1 MiB file) take minutes
    (tmp_path / "m.yaml").write_text(_fan(250))
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 1
    assert proc.stderr.startswith("m.yaml:2:1: error: the system has 501 components; "
                                  "at most 500 are allowed\n  hint: split it into several")
    assert proc.stderr.count("error:") == 1


def test_too_many_connections_is_one_error_at_the_key(tmp_path):
    text = _fan(2) + "".join(f"  - source.image -> m{i % 2}.image\n" for i in range(1997))
    (tmp_path / "m.yaml").write_text(text)
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 1
    assert "m.yaml:8:1: error: the system has 2,001 connections; at most 2,000 are allowed" \
        in proc.stderr
    assert proc.stderr.count("error:") == 1


def test_a_flood_of_errors_shows_the_first_two_hundred_and_counts_all(tmp_path):
    comps = "".join(f"  c{i}: Nope{i}\n" for i in range(450))
    (tmp_path / "m.yaml").write_text("system: s\ncomponents:\n" + comps)
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 1
    assert proc.stderr.count("error: unknown component type") == 200
    assert "m.yaml:3:7: error: unknown component type 'Nope0' for 'c0'" in proc.stderr
    assert proc.stderr.endswith("450 errors found (250 more not shown)\n")


@pytest.mark.parametrize("key,count,message", [
    ("params", 257, "component type 'Big' has 257 parameters; at most 256 are allowed"),
    ("inputs", 65, "component type 'Big' has 65 inputs; at most 64 are allowed"),
    ("outputs", 65, "component type 'Big' has 65 outputs; at most 64 are allowed"),
])
def test_a_type_with_too_many_ports_or_parameters(tmp_path, key, count, message):
    entry = {"params": "      p{i}: {{type: int, default: 1}}",
             "inputs": "      i{i}: {{memory: cpu, dtype: uint8}}",
             "outputs": "      o{i}: {{memory: cpu, dtype: uint8, height: 2, width: 2}}"}[key]
    lines = ["component_types:", "  Big:", "    kind: standard", f"    {key}:"]
    lines += [entry.format(i=i) for i in range(count)]
    lines += ["    python: {file: big.py, class: Big}"]
    (tmp_path / "t.yaml").write_text("\n".join(lines) + "\n")
    (tmp_path / "big.py").write_text("class Big:\n    pass\n")
    (tmp_path / "m.yaml").write_text("system: s\ntypes: [t.yaml]\ncomponents:\n  a: Big\n")
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 1
    assert f"t.yaml:4:5: error: {message}" in proc.stderr, proc.stderr


def test_a_type_file_listed_twice_is_read_once(project):
    model = project / "m.yaml"
    text = model.read_text()
    assert "types: [types/t.yaml]" in text
    model.write_text(text.replace("types: [types/t.yaml]",
                                  "types: [types/t.yaml, ./types/t.yaml]"))
    proc = check(project)
    assert proc.returncode == 1
    assert "error: component-type file './types/t.yaml' is listed twice (also entry 1 of " \
        "'types:')" in proc.stderr
    assert proc.stderr.count("error:") == 1, "no 'already defined' for each of its types"


def test_too_many_type_files(tmp_path):
    files = ", ".join(f"t{i}.yaml" for i in range(33))
    (tmp_path / "m.yaml").write_text(f"system: s\ntypes: [{files}]\ncomponents: {{a: Camera}}\n")
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 1
    assert "m.yaml:2:1: error: the model lists 33 type files; at most 32 are allowed" \
        in proc.stderr


def test_the_type_files_of_a_model_are_bounded_together(tmp_path):
    # 6 files of about 200 KB: each under its cap, not together (the bytes are what is
    # bounded: a comment of 200 KB counts as 200 KB of types would, and parses fast)
    padding = "".join(f"# {'x' * 76}\n" for _ in range(2600))
    for i in range(6):
        (tmp_path / f"t{i}.yaml").write_text(
            f"component_types:\n  T{i}: {{kind: standard, python: {{file: p.py, class: P}}}}\n"
            + padding)
    files = ", ".join(f"t{i}.yaml" for i in range(6))
    (tmp_path / "m.yaml").write_text(f"system: s\ntypes: [{files}]\ncomponents: {{a: Camera}}\n")
    proc = gpucompgen("check", "m.yaml", cwd=tmp_path)
    assert proc.returncode == 1
    assert "error: the model's type files come to " in proc.stderr
    assert "bytes with 't5.yaml'; at most 1,048,576 are allowed" in proc.stderr


# ---------------------------------------------------------------- user code

def test_user_code_is_never_run_by_check_or_build(project):
    marker = project / "ran"
    (project / "types" / "show.py").write_text(
        f"open({str(marker)!r}, 'w').close()\n\n\nclass Show:\n    pass\n")
    assert check(project).returncode == 0
    assert gpucompgen("build", "m.yaml", "-o", "out", cwd=project).returncode == 0
    assert not marker.exists()


@pytest.mark.parametrize("source,ok", [
    ("class Show:\n    pass\n", True),
    ("from impl import Show\n", True),
    ("from impl import Window as Show\n", True),
    ("try:\n    from fast import Show\nexcept ImportError:\n    class Show:\n        pass\n", True),
    ("def Show(**params):\n    return object()\n", True),
    ("Show = type('Show', (), {})\n", True),
    ("class Window:\n    class Show:\n        pass\n", False),
    ("def make():\n    class Show:\n        pass\n", False),
    ("# class Show:\nshow = 1\n", False),
    ("'''\nclass Show:\n'''\n", False),
    ("", False),
])
def test_the_class_is_found_by_reading_the_module(project, source, ok):
    (project / "types" / "show.py").write_text(source)
    proc = check(project)
    assert (proc.returncode == 0) == ok, proc.stderr
    if not ok:
        assert "class 'Show' is not defined in types/show.py" in proc.stderr


@pytest.mark.parametrize("source,where", [
    ("class Show:\n    def f(self)\n        pass\n", "types/show.py:2:"),
    ("class Show:\n\tpass\n  x = 1\n", "types/show.py:3:"),
    ("x = (1,\n", "types/show.py:1:"),
    ("x = 1\0\n", "types/show.py:1:"),
])
def test_a_module_that_is_not_python_is_a_positioned_error(project, source, where):
    (project / "types" / "show.py").write_text(source)
    proc = check(project)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert where in proc.stderr, proc.stderr


# ---------------------------------------------------------------- kernel signatures

GOOD_TINT = [
    KERNEL,
    KERNEL.replace("__global", "global").replace("__kernel", "kernel"),
    "/* a comment */\n#define X 1\n" + KERNEL.replace(
        "__kernel void", "__kernel __attribute__((reqd_work_group_size(16, 16, 1))) void"),
    KERNEL.replace("__global const uchar *image", "__global const uchar * restrict image")
          .replace("const int tile", "int tile"),
    KERNEL.replace("__global const uchar *image", "const __global uchar *image"),
    KERNEL.replace("__global const uchar *image", "__global uchar *image"),  # const optional
    KERNEL.replace("__global const uchar *image", "__global unsigned char *image"),
    "typedef unsigned char pixel;\n" + KERNEL.replace("uchar *tinted", "pixel *tinted"),
    "// __kernel void tint(int a) {\n" + KERNEL,
    "__kernel void tint(__global uchar *a);\n" + KERNEL,  # a prototype, then the definition
    KERNEL.replace("{\n}", "{\n    const char *s = \"}\"; /* ) */\n}"),
]
BAD_TINT = [
    ("__kernel void tint_other(int a) {}\n", "defines no '__kernel void tint(...)'"),
    ("// " + KERNEL.replace("\n", "\n// "), "defines no '__kernel void tint(...)'"),
    ("/*\n" + KERNEL + "*/\n", "defines no '__kernel void tint(...)'"),
    ("#define S \"" + KERNEL.replace("\n", " ") + "\"\n", "defines no"),
    (KERNEL.replace("__kernel void", "void"), "defines no"),
    (KERNEL.replace("__kernel void", "__kernel int"), "defines no"),
    (KERNEL.replace("const float gain, ", ""), "takes 7 parameter(s), the calling convention "
     "passes 8"),
    (KERNEL.replace("const int tile", "const int tile, const int extra"), "takes 9"),
    (KERNEL.replace("__global uchar *tinted", "__global const uchar *tinted"), "is const"),
    (KERNEL.replace("__global uchar *tinted", "__global float *tinted"), "points to float"),
    (KERNEL.replace("__global uchar *tinted", "__global uchar4 *tinted"), "points to uchar4"),
    (KERNEL.replace("__global uchar *tinted", "__constant uchar *tinted"),
     "is not a __global pointer"),
    (KERNEL.replace("__global uchar *tinted", "uchar tinted"), "is not a __global pointer"),
    (KERNEL.replace("__global uchar *tinted", "__global uchar **tinted"),
     "is not a __global pointer"),
    (KERNEL.replace("const float gain", "const double gain"), "is double, not float"),
    (KERNEL.replace("const int image_height", "const uint image_height"), "is uint, not int"),
    (KERNEL.replace("const int tile", "__global int *tile"), "must be a scalar"),
    (KERNEL.replace("{\n}", ";"), "is declared but never defined"),
    ("#define K \\\n" + KERNEL.replace("\n", " \\\n"), "defines no"),
    ("#if 0\n#endif\nint tint(int a) {}\n", "defines no"),
]


@pytest.mark.parametrize("source", GOOD_TINT)
def test_kernels_that_follow_the_convention(project, source):
    (project / "types" / "tint.cl").write_text(source)
    proc = check(project)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("source,message", BAD_TINT)
def test_kernels_that_break_the_convention(project, source, message):
    (project / "types" / "tint.cl").write_text(source)
    proc = check(project)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert "types/t.yaml:11:39: error: kernel file types/tint.cl" in proc.stderr, proc.stderr
    assert message in proc.stderr, proc.stderr


def test_a_signature_error_shows_both_parameter_lists(project):
    (project / "types" / "tint.cl").write_text(
        "\n\n__kernel void tint(__global const uchar *image, float gain) {}\n")
    proc = check(project)
    assert proc.stderr.splitlines()[:5] == [
        "types/t.yaml:11:39: error: kernel file types/tint.cl:3: kernel 'tint' takes 2 "
        "parameter(s), the calling convention passes 8",
        "  hint: the calling convention needs",
        "          __kernel void tint(__global const uchar *image, __global uchar *tinted, "
        "const int image_height, const int image_width, const int tinted_height, "
        "const int tinted_width, const float gain, const int tile)",
        "        the kernel has",
        "          __kernel void tint(__global const uchar *image, float gain)"]


def test_a_wrong_kernel_fails_at_check_not_at_frame_0(project):
    (project / "types" / "tint.cl").write_text(KERNEL.replace("const float gain, ", ""))
    proc = gpucompgen("build", "m.yaml", "-o", "out", cwd=project)
    assert proc.returncode == 1 and not (project / "out").exists()


def test_every_library_kernel_follows_the_convention():
    checked = 0
    for ctype in library_types().values():
        if ctype.kernel_file is not None:  # the hand-written ones (others are generated)
            found = signature.check(ctype, ctype.kernel_text, ctype.kernel_function)
            assert found.name == ctype.kernel_function
            checked += 1
    # every library type with a kernel and no fusable form (none since Resize and Crop
    # are generated from forms too); users' kernels are checked above
    assert checked == sum(t.gpu_aware and t.fusable is None for t in library_types().values())


@pytest.mark.parametrize("hostile", [
    "f(" * (1 << 19), "tint(" * (1 << 18), "__kernel void tint(" * (1 << 16), "(" * (1 << 20),
    "/*" * (1 << 19), '"' * (1 << 20), "__attribute__((" * (1 << 16),
    "typedef " + "a " * (1 << 19), "kernel " * (1 << 17)])
def test_hostile_kernel_sources_take_linear_time(hostile):
    start = time.monotonic()
    with pytest.raises(signature.SignatureError):
        signature.find_definition(hostile, "tint")
    assert time.monotonic() - start < 15


def test_strip_keeps_lines_and_removes_comments_and_strings():
    source = 'a // x "y"\nb /* c\nd */ e "f\\"g" \'h\' i\n'
    stripped = signature.strip(source)
    assert stripped.count("\n") == source.count("\n")
    assert stripped.split() == ["a", "b", "e", "i"]


def test_parameters_are_read_as_written():
    found = signature.find_definition(
        "kernel __attribute__((vec_type_hint(float4))) void k(\n"
        "    const __global unsigned char * restrict a, __local float *b, int c[],\n"
        "    __global short * const d, uint e) {}", "k")
    assert found.line == 1
    assert [(p.name, p.c_type, p.pointer, p.space, p.const) for p in found.params] == [
        ("a", "uchar", 1, "global", True), ("b", "float", 1, "local", False),
        ("c", "int", 1, "", False), ("d", "short", 1, "global", False),
        ("e", "uint", 0, "", False)]


# ---------------------------------------------------------------- size expressions

@pytest.mark.parametrize("text,sizes,params,value", [
    ("a.width + b.width", {"a": (4, 5), "b": (4, 7)}, {}, 12),
    ("min(a.height, 3, w)", {"a": (4, 5)}, {"w": 2}, 2),
    ("max(a.height, w) // 2 - -1", {"a": (9, 5)}, {"w": 2}, 5),
    ("(a.width * 3) % 7", {"a": (1, 5)}, {}, 1),
    ("-a.width", {"a": (1, 5)}, {}, -5),
    (1048576, {}, {}, 1048576),
    ("w * w * w * w", {}, {"w": 32}, 1048576),
    ("w * w * w * w * w // (w * w * w)", {}, {"w": 1000}, 1000 ** 2),
    ("(" * 99 + "w" + ")" * 99, {}, {"w": 7}, 7),
    ("-" * 190 + "w", {}, {"w": 7}, 7),
])
def test_sizes_evaluate_to_hand_computed_values(text, sizes, params, value):
    tree = sizeexpr.parse(text, set(sizes), set(params))
    assert sizeexpr.evaluate(tree, sizes, params) == value


@pytest.mark.parametrize("text,message", [
    ("min(3)", "min() takes two or more sizes"),
    ("max(w)", "max() takes two or more sizes"),
    ("min(*w)", "min() takes two or more sizes"),
    ("max(w, k=1)", "only min(...) and max(...) may be called"),
    ("min", "'min' must be called"),
    ("w > 3", "not a comparison"),
    ("(w > 3) + 1", "not a comparison"),
    ("w and 2", "not a comparison"),
    ("not w", "not a comparison"),
    ("True", "is not an integer"),
    ("1.5", "is not an integer"),
    ("'a'", "is not an integer"),
    ("2 ** 63", "uses something a size expression cannot"),
    ("w / 2", "uses something a size expression cannot"),
    ("w << 40", "uses something a size expression cannot"),
    ("w if w else 1", "uses something a size expression cannot"),
    ("__import__('os')", "only min(...) and max(...) may be called"),
    ("a.__class__", "a port has only .height and .width"),
    ("a", "not the port 'a' itself"),
    ("nope", "unknown name 'nope'"),
    ("9" * 30, "is larger than any size"),
    ("(" * 99 + "1", "cannot parse"),
    ("1\0", "cannot parse"),
    ("w" + " + w" * 60, "longer than 200 characters"),
    (True, "must be an integer or a string"),
    (None, "must be an integer or a string"),
    ([1], "must be an integer or a string"),
    (10 ** 30, "is larger than any size"),
])
def test_bad_size_expressions_are_refused_when_parsed(text, message):
    with pytest.raises(sizeexpr.SizeExprError, match=message.replace("(", r"\(")
                       .replace(")", r"\)").replace("*", r"\*").replace(".", r"\.")):
        sizeexpr.parse(text, {"a"}, {"w"})


@pytest.mark.parametrize("text,params,message", [
    ("w // (w - 4)", {"w": 4}, "division by zero"),
    ("w % 0", {"w": 4}, "division by zero"),
    ("w * w * w * w * w * w * w", {"w": 10 ** 10}, "beyond any size"),
    ("w", {"w": 10 ** 60}, "beyond any size"),
    ("w", {"w": None}, "has no integer value"),
    ("w", {"w": True}, "has no integer value"),
    ("w", {"w": 2.5}, "has no integer value"),
    ("w + 1", {"w": 1 << 20}, "larger than any size"),
    ("-w * -w", {"w": 1 << 11}, "larger than any size"),
])
def test_bad_values_are_refused_when_evaluated(text, params, message):
    tree = sizeexpr.parse(text, set(), set(params))
    with pytest.raises(sizeexpr.SizeExprError, match=message):
        sizeexpr.evaluate(tree, {}, params)


def test_requirements_are_comparisons():
    tree = sizeexpr.parse("a.height == b.height and a.width <= 2 * b.width or w != 1",
                          {"a", "b"}, {"w"}, condition=True)
    assert sizeexpr.evaluate(tree, {"a": (4, 6), "b": (4, 3)}, {"w": 1}) is True
    assert sizeexpr.evaluate(tree, {"a": (4, 7), "b": (4, 3)}, {"w": 1}) is False
    assert sizeexpr.evaluate(sizeexpr.parse("1 < w < 3", set(), {"w"}, condition=True),
                             {}, {"w": 3}) is False
    for bad in ("a.height", "a.height + 1", "min(a.height, 2)"):
        with pytest.raises(sizeexpr.SizeExprError, match="must compare sizes"):
            sizeexpr.parse(bad, {"a"}, set(), condition=True)


def test_frame_problem_bounds_bytes_of_any_port():
    assert sizeexpr.frame_problem(480, 640, 3, 1) == ""
    assert "outside 1..1,048,576" in sizeexpr.frame_problem(1 << 21, 1, 1, 1)
    assert "more than any frame may have" in sizeexpr.frame_problem(1 << 20, 1 << 20, 3, 4)


# ---------------------------------------------------------------- staging folders

def test_a_system_named_old_builds_again_and_again(tmp_path):
    (tmp_path / "old.yaml").write_text(
        "system: old\ncomponents:\n  camera: {type: Camera, params: {width: 64, height: 48}}\n"
        "  sink: {type: FrameSink}\nconnections: [camera.image -> sink.image]\n")
    for _ in range(3):
        proc = gpucompgen("build", tmp_path / "old.yaml", "-o", tmp_path / "out")
        assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["old.py", "old_lib"]


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_staging_folders_of_killed_builds_are_removed(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    old = time.time() - 3600
    dead = out / f"{build_mod.STAGING_PREFIX}{_dead_pid()}-abc123"
    alive = out / f"{build_mod.STAGING_PREFIX}{os.getppid()}-abc123"
    young = out / f"{build_mod.STAGING_PREFIX}{_dead_pid()}-young1"
    foreign = out / ".staging-of-someone-else"
    linked = out / f"{build_mod.STAGING_PREFIX}{_dead_pid()}-link12"
    for folder in (dead, alive, young, foreign):
        (folder / "new").mkdir(parents=True)
        (folder / "new" / "file").write_text("x")
    linked.symlink_to(foreign)
    for folder in (dead, alive, foreign):
        os.utime(folder, (old, old))
    os.utime(linked, (old, old), follow_symlinks=False)
    assert build_mod.remove_stale_staging(out) == [dead]
    assert not dead.exists()
    assert alive.exists() and young.exists() and foreign.exists() and linked.is_symlink()


def test_a_build_killed_while_staging_leaves_nothing_after_the_next_build(tmp_path):
    model = tmp_path / "m.yaml"
    model.write_text("system: m\ncomponents:\n  camera: {type: Camera, params: "
                     "{width: 64, height: 48}}\n  sink: {type: FrameSink}\n"
                     "connections: [camera.image -> sink.image]\n")
    out = tmp_path / "out"
    script = textwrap.dedent(f"""
        import os, signal
        from pathlib import Path
        from gpucompgen import build
        result = build.compile_model(Path({str(model)!r}), Path({str(out)!r}))
        real = Path.write_text
        def killed(self, *a, **k):
            os.kill(os.getpid(), signal.SIGKILL)
        Path.write_text = killed
        build.write(result, Path({str(out)!r}))
        """)
    proc = subprocess.run([sys.executable, "-c", script], check=False)
    assert proc.returncode == -9
    left = [p for p in out.iterdir() if p.name.startswith(build_mod.STAGING_PREFIX)]
    assert len(left) == 1
    old = time.time() - 3600
    os.utime(left[0], (old, old))
    assert gpucompgen("build", model, "-o", out).returncode == 0
    assert sorted(p.name for p in out.iterdir()) == ["m.py", "m_lib"]
