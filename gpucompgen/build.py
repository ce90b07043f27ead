"""Build: model file → checked System → rendered files → written atomically.

The tool owns what it writes for a system: ``<system>.py`` and the folder
``<system>_lib/``.  A rebuild replaces both (stale files go), and it refuses to overwrite
files it did not generate unless told to.
"""

from __future__ import annotations

import difflib
import os
import re
import shutil
import stat
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import device as device_mod
from .backend import device_query, renderer
from .errors import Diagnostic, OutputError, Reporter
from .ir import MODES, System
from .model import SystemModel, load_system
from .options import BuildOptions, build_options
from .output import HEADER_PREFIX, OutputFile, source_path
from .passes import run_passes
from .passes.lower import lib_dir_name


@dataclass
class BuildResult:
    system: System
    files: list[OutputFile]
    warnings: list[Diagnostic]


def compile_model(model_path: Path, out_dir: Path, options: BuildOptions | None = None,
                  **overrides: Any) -> BuildResult:
    """Everything but writing: raises GpucompgenError with all problems found.

    options (gpucompgen.options.BuildOptions: mode, device, backend, the platform settings
    the command line overrides, placements, kernel compilation, verification, dumps), with
    the fields given as keywords replaced: ``compile_model(path, out, fusion="off")``.
    """
    options = build_options(options, **overrides)
    if options.mode not in MODES:
        raise ValueError(options.mode)
    model = load_system(model_path, options.display)
    backend = options.backend if options.backend is not None else model.backend
    rep = Reporter()
    spec = options.device if options.device is not None else model.device
    facts = device_mod.resolve(spec, model.device_pos, rep,
                               model.device_positions if options.device is None else None,
                               query=device_query(backend))
    if options.compile_kernels and spec == "auto" and not rep.has_errors \
            and backend == "opencl":
        compile_on_device(model, rep)
    rep.raise_if_errors()
    system, warnings = run_passes(model, facts, options)
    model_dir = Path(os.path.relpath(model_path.resolve().parent, out_dir.resolve())).as_posix()
    files = renderer(backend)(system, source_path(model_path, out_dir), model_dir)
    _must_compile(files[0])
    return BuildResult(system, files, warnings)


def compile_on_device(model: SystemModel, rep: Reporter) -> None:
    """Build every kernel file of the user's that a component's type names on the device
    programs use, as the program does at start-up (the library's are the test suite's)."""
    from .runtime import PipelineError, build_program, create_context

    try:
        context = create_context()
    except PipelineError as exc:
        rep.error(model.device_pos, f"device 'auto': {exc}")
        return
    built: set[Path] = set()
    for inst in model.components.values():
        t = inst.type
        if not t.gpu_aware or t.origin != "user" or t.kernel_file in built:
            continue
        built.add(t.kernel_file)
        try:
            build_program(context, t.kernel_file, f"{t.name}")
        except PipelineError as exc:
            rep.error(t.pos, str(exc), "every kernel a model names is built on the device, "
                      "also that of a type whose components are fused or on the CPU")


def _must_compile(program: OutputFile) -> None:
    """The last line of defence of the name checks: a program Python cannot compile is a
    bug in gpucompgen, reported before anything is written."""
    try:
        compile(program.text, str(program.path), "exec")
    except SyntaxError as exc:
        raise RuntimeError(f"the generated program does not compile: {exc.msg} at line "
                           f"{exc.lineno}: {(exc.text or '').strip()!r}") from None


def owned_paths(system_name: str, out_dir: Path) -> tuple[Path, Path]:
    return out_dir / f"{system_name}.py", out_dir / f"{system_name}_lib"


def check_ownership(result: BuildResult, out_dir: Path) -> None:
    """Refuse to replace files that gpucompgen did not write."""
    refuse_replacing_inputs(result, out_dir)  # never to be replaced, even with --overwrite
    program, lib = owned_paths(result.system.name, out_dir)
    foreign = []
    if program.exists() and not _generated(program):
        foreign.append(program)
    if lib.exists():
        if not lib.is_dir():
            foreign.append(lib)
        else:
            foreign += [p for p in sorted(lib.rglob("*")) if p.is_file() and not _generated(p)]
    if foreign:  # an output problem, a usage error (exit 2) like the others
        raise OutputError(
            f"{foreign[0]}: refusing to overwrite {len(foreign)} file(s) that gpucompgen did "
            "not generate\n  hint: choose another output folder with -o, or pass --overwrite")


def _generated(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            head = f.read(200).decode("utf-8", "replace")
    except OSError:
        return False
    return head.startswith((HEADER_PREFIX, "// Code generated by gpucompgen"))


STAGING_PREFIX = ".gpucompgen-staging-"
STAGING_RE = re.compile(re.escape(STAGING_PREFIX) + r"(\d+)-[A-Za-z0-9_]+\Z")
STALE_AFTER_S = 60  # a staging folder this old whose build process is gone is left over


def _staging_folder(out_dir: Path) -> Path:
    """A new staging folder in out_dir, named with this process's id so that a later build
    can tell a folder left by a killed build from one still in use."""
    return Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=out_dir))


def remove_stale_staging(out_dir: Path, now: float | None = None) -> list[Path]:
    """Remove staging folders that builds killed before cleaning up (e.g. by SIGKILL) left
    in out_dir: only folders named by _staging_folder, owned by this user, not links, older
    than STALE_AFTER_S and whose process no longer runs.  Returns what was removed."""
    removed = []
    now = time.time() if now is None else now
    try:
        entries = list(os.scandir(out_dir))
    except OSError:
        return removed
    for entry in entries:
        m = STAGING_RE.match(entry.name)
        if not m or int(m[1]) == os.getpid():
            continue
        try:
            info = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid() or \
                now - info.st_mtime < STALE_AFTER_S or _running(int(m[1])):
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        removed.append(Path(entry.path))
    return removed


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # someone else's process, or not a pid we can ask about: keep it
    return True


def build_inputs(model: SystemModel) -> list[Path]:
    """Every file the build reads (model.inputs: the model, type files, kernel, Python and
    CPU files, the profile once read; the library's files of the types it uses) and every
    path or input parameter's file or folder, resolved."""
    paths = list(model.inputs)
    for inst in model.components.values():
        t = inst.type
        paths += [f.resolve() for f in (t.decl_file, t.kernel_file, t.python_file, t.cpu_file)
                  if f is not None]
        for pname, value in inst.params.items():
            decl = inst.type.params.get(pname)
            if decl is not None and decl.type in ("path", "input") and \
                    isinstance(value, str) and value:
                local = _local_path(value)
                if local:
                    paths.append((model.file.parent / local).resolve())
    return paths


FILE_SCHEMES = re.compile(r"(file|mcap|rosbag)://")
OTHER_URI = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")  # device:0, rtsp://, v4l2://...


def _local_path(value: str) -> str:
    """The file or folder a path or input parameter names ('' for a camera, a stream):
    a file URI's path without its query, a glob's folder."""
    m = FILE_SCHEMES.match(value)
    if m:
        value = value[m.end():].split("?", 1)[0]
    elif OTHER_URI.match(value):
        return ""
    if any(c in value for c in "*?["):
        value = os.path.dirname(value[:min(value.find(c) for c in "*?[" if c in value)])
    return value or "."


def refuse_replacing_inputs(result: BuildResult, out_dir: Path) -> None:
    """A build replaces <system>.py and the whole <system>_lib/: refuse (a usage error)
    when an input of the build is one of them or lies inside, whatever --overwrite says."""
    program, lib = (p.resolve() for p in owned_paths(result.system.name, out_dir))
    for path in build_inputs(result.system.model):
        if path == program or path == lib or lib in path.parents:
            try:
                shown = os.path.relpath(path)
            except ValueError:
                shown = str(path)
            raise OutputError(
                f"building into {out_dir} would replace {shown}, an input of the build "
                f"(the build owns {program.name} and {lib.name}/ there); choose another "
                "output folder with -o, or move the file")


def write(result: BuildResult, out_dir: Path) -> list[Path]:
    """Write all files, all or nothing: everything is staged first, then the lib folder and
    the program replace the old ones; if that fails, the old lib folder is put back.

    The staging folder holds the new files under new/ and the replaced lib folder under
    previous/, so no system name can make them collide."""
    name = result.system.name
    program, lib = owned_paths(name, out_dir)
    refuse_replacing_inputs(result, out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f"output folder {out_dir} is a file")
    if program.is_dir():
        raise OutputError(f"{program} is a folder, where the program would go")
    if lib.exists() and not lib.is_dir():
        raise OutputError(f"{lib} is a file, where the kernels folder would go")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        remove_stale_staging(out_dir)
        staging = _staging_folder(out_dir)
    except OSError as exc:
        raise OutputError(f"cannot create output folder {out_dir}: {exc.strerror}") from None
    try:
        new = staging / "new"
        for f in result.files:
            target = new / f.path
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(f.text, encoding="utf-8", newline="\n")
        staged_lib = new / lib_dir_name(result.system.name)
        staged_lib.mkdir(parents=True, exist_ok=True)
        old = staging / "previous"
        if lib.exists():
            os.replace(lib, old)
        try:
            os.replace(staged_lib, lib)
            os.replace(new / program.name, program)
        except OSError:
            if old.exists():
                shutil.rmtree(lib, ignore_errors=True)
                os.replace(old, lib)
            raise
    except OSError as exc:
        raise OutputError(f"cannot write into {out_dir}: {exc.strerror}") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return [out_dir / f.path for f in result.files]


MAX_DIFF_FILE_BYTES = 1 << 20  # a file larger than this is compared, never shown line by line
MAX_DIFF_LINES = 5000  # lines of diff printed at most (the rest are counted)


def diff(result: BuildResult, out_dir: Path) -> str:
    """Unified diff from what is in out_dir to what a build would write ('' when current).

    Files are compared by size, then streamed in blocks: whatever lies in the folder, no
    more than MAX_DIFF_FILE_BYTES of one file is ever held in memory, a larger (or binary)
    file is named with its size instead of shown, and the diff stops after MAX_DIFF_LINES
    lines."""
    program, lib = owned_paths(result.system.name, out_dir)
    wanted = {out_dir / f.path: f.text.encode("utf-8") for f in result.files}
    # Python's bytecode cache of the lib folder's modules (written when the program runs)
    # is not output: a program run before `build --check` leaves the build current
    existing = {program} | ({p for p in lib.rglob("*") if p.is_file()
                             and "__pycache__" not in p.relative_to(lib).parts}
                            if lib.is_dir() else set())
    lines: list[str] = []
    for path in sorted(set(wanted) | existing):
        new = wanted.get(path)
        if _same(path, new):
            continue
        rel = path.relative_to(out_dir).as_posix()
        old = _small_text(path)
        fromfile = f"a/{rel}" if path.is_file() else "/dev/null"
        tofile = f"b/{rel}" if new is not None else "/dev/null"
        if old is None:  # too large or not text: say so in place of its lines
            size = _size(path)
            lines += [f"--- {fromfile}\n", f"+++ {tofile}\n",
                      f"@@ {rel}: {size:,} bytes, not shown (larger than "
                      f"{MAX_DIFF_FILE_BYTES:,} bytes or not UTF-8 text); a build "
                      + ("replaces it" if new is not None else "removes it") + " @@\n"]
            continue
        lines += difflib.unified_diff(old.splitlines(keepends=True),
                                      (new or b"").decode("utf-8").splitlines(keepends=True),
                                      fromfile=fromfile, tofile=tofile)
    if len(lines) > MAX_DIFF_LINES:
        more = len(lines) - MAX_DIFF_LINES
        lines = lines[:MAX_DIFF_LINES] + [f"... {more:,} more lines of diff not shown\n"]
    return "".join(line if line.endswith("\n") else line + "\n\\ No newline at end of file\n"
                   for line in lines)


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _same(path: Path, new: bytes | None) -> bool:
    """The file at path holds exactly new (None: a file no build writes), read in blocks."""
    if new is None or not path.is_file() or _size(path) != len(new):
        return False
    try:
        with path.open("rb") as f:
            offset = 0
            while block := f.read(1 << 16):
                if block != new[offset:offset + len(block)]:
                    return False
                offset += len(block)
            return offset == len(new)
    except OSError:
        return False


def _small_text(path: Path) -> str | None:
    """The file's text for a diff: '' when there is none, None when too large or binary."""
    if not path.is_file():
        return ""
    if _size(path) > MAX_DIFF_FILE_BYTES:
        return None
    try:
        with path.open("rb") as f:
            data = f.read(MAX_DIFF_FILE_BYTES + 1)
    except OSError:
        return None
    if len(data) > MAX_DIFF_FILE_BYTES or b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None
