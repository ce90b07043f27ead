"""Constructing, checking and freeing the parts of a running system; user modules."""

from __future__ import annotations

import contextlib
import importlib.util
import sys
import threading
import traceback
from pathlib import Path
from typing import Any, NamedTuple

from .errors import PipelineError
from .frames import READ_ONLY_HINT
from .pipeline import FrameFailure
from .profiling import Profile
from .signals import freeing
from .sizes import Size


def expect_size(component: str, got: Any, expected: Size) -> Size:
    """initialize() must give the size the system propagated at build time."""
    if tuple(got) != tuple(expected):
        raise PipelineError(f"{component}: initialize() gave size {tuple(got)}, but the system "
                            f"was built for {tuple(expected)} (height, width, channels)")
    return Size(*got)


def load_module(path: Path, module_name: str, fresh: bool = True):
    """Import a Python file as a module: a generated program, or a user's component file.

    With fresh=False a module already imported from the same file is reused. A file that
    cannot be imported (missing, a syntax error, an exception while it runs) raises
    PipelineError with one line naming the file and the problem, file:line where known;
    the original exception is its __cause__.
    """
    path = Path(path)
    module = sys.modules.get(module_name)
    if not fresh and module is not None and getattr(module, "__file__", None) == str(path):
        return module
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise PipelineError(f"{path}: error: cannot load it as a Python module "
                            "(the file name must end in .py)")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except PipelineError:  # already says which file (a user module the program loads)
        sys.modules.pop(module_name, None)
        raise
    except (Exception, SystemExit) as exc:
        sys.modules.pop(module_name, None)
        raise PipelineError(_import_problem(path, exc)) from exc
    return module


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _import_problem(path: Path, exc: BaseException) -> str:
    """file[:line[:col]]: error: what went wrong importing path, on one line."""
    if isinstance(exc, FileNotFoundError) and Path(exc.filename or "") == path:
        return f"{path}: error: cannot import it: no such file"
    if isinstance(exc, OSError) and Path(exc.filename or "") == path:
        return f"{path}: error: cannot read it: {exc.strerror}"
    if isinstance(exc, SyntaxError) and exc.filename and Path(exc.filename) == path:
        where = f"{path}:{exc.lineno}" + (f":{exc.offset}" if exc.offset else "")
        return f"{where}: error: {type(exc).__name__}: {_one_line(exc.msg)}"
    line = None
    tb = exc.__traceback__
    while tb is not None:  # the innermost line of the file itself
        if Path(tb.tb_frame.f_code.co_filename) == path:
            line = tb.tb_lineno
        tb = tb.tb_next
    where = f"{path}:{line}" if line else str(path)
    if isinstance(exc, SystemExit):
        return f"{where}: error: it exits while being imported (sys.exit({exc.code!r}))"
    what = f"{type(exc).__name__}: {_one_line(exc)}" if str(exc) else type(exc).__name__
    return f"{where}: error: importing it raised {what}"


def load_class(path: Path, name: str) -> type:
    """Load a user's standard component class from a file copied beside the program.

    A file that cannot be imported, or defines no class of that name, raises PipelineError.
    Called at the top of a program run as a script (outside main()), it prints that
    error as one line instead, with no traceback (unless --debug is on the command
    line), and exits 1.
    """
    path = Path(path)
    try:
        module = load_module(path, f"gpucompgen_user_{path.stem}", fresh=False)
        found = getattr(module, name, None)
        if found is None:
            raise PipelineError(f"{path}: error: defines no class {name}; the component type "
                                "names it in its 'python: {class: ...}'")
        if not isinstance(found, type):
            raise PipelineError(f"{path}: error: {name} is a {type(found).__name__}, not a "
                                "class")
        return found
    except (PipelineError, KeyboardInterrupt) as exc:
        if sys._getframe(1).f_globals.get("__name__") != "__main__":
            raise
        if "--debug" in sys.argv[1:]:
            traceback.print_exception(exc.__cause__ or exc)
        if isinstance(exc, KeyboardInterrupt):
            print(f"{path}: interrupted while importing it", file=sys.stderr)
            raise SystemExit(130) from None
        print(exc, file=sys.stderr)
        raise SystemExit(1) from None


def load_function(path: Path, name: str):
    """Load a flexible type's CPU function from a file copied beside the program."""
    module = load_module(path, f"gpucompgen_user_{Path(path).stem}", fresh=False)
    function = getattr(module, name, None)
    if not callable(function):
        raise PipelineError(f"{path.name} defines no function {name}")
    return function


class Result(NamedTuple):
    """What run() returns: frames processed and the (freed) components, for inspection."""

    frames: int
    components: dict[str, Any]
    profile: Profile | None = None  # with run(profile=True)


def failing_component(exc: BaseException, components: dict[str, Any]) -> str | None:
    """Name of the component whose method raised exc (innermost wins)."""
    by_id = {id(obj): name for name, obj in components.items()}
    found = None
    tb = exc.__traceback__
    while tb is not None:
        owner = tb.tb_frame.f_locals.get("self")
        if owner is not None and id(owner) in by_id:
            found = by_id[id(owner)]
        tb = tb.tb_next
    return found


def component_failure(exc: BaseException, frame: int | None,
                      parts: dict[str, Any]) -> PipelineError:
    """Turn an exception raised by run() into a message naming who and when.

    frame is None while the components are being constructed, initialized and
    configured; parts maps every planned name to its object, None until constructed, so
    a constructor that raises is the first name still None.  With frames in flight, the
    stages' runner raises a FrameFailure that carries the frame the failing stage was on.
    """
    if isinstance(exc, FrameFailure):
        exc, frame = exc.exc, exc.frame
    # a check of what a part returned names that part (runtime.check_frame)
    who = failing_component(exc, parts) or getattr(exc, "component", None)
    when = "while initializing" if frame is None else f"at frame {frame}"
    if who is None and frame is None:
        unbuilt = next((name for name, obj in parts.items() if obj is None), None)
        if unbuilt is not None:
            who, when = unbuilt, "while constructing"
    if isinstance(exc, PipelineError):
        text = str(exc)
        if who is None or text.startswith((f"{who}:", f"{who} ")):
            return exc
        return PipelineError(f"{who} failed {when}: {text}")
    return PipelineError(f"{who or 'a component'} failed {when}: {type(exc).__name__}: {exc}"
                         + _device_fault_hint(exc) + _read_only_hint(exc))


def _read_only_hint(exc: BaseException) -> str:
    """A component wrote into a frame it was given (runtime.frames.read_only)."""
    if isinstance(exc, ValueError) and "read-only" in str(exc):
        return f"\n  hint: {READ_ONLY_HINT}"
    return ""


# OpenCL errors a GPU gives at the command after a kernel that faulted (NVIDIA:
# OUT_OF_RESOURCES at the next read; a lost queue; events of a wait list that failed).
_DEVICE_FAULT_CODES = {-5: "OUT_OF_RESOURCES", -36: "INVALID_COMMAND_QUEUE",
                       -14: "EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST", -9999: "-9999"}


def _device_fault_hint(exc: BaseException) -> str:
    code = getattr(exc, "code", None)
    if not isinstance(code, int) or code not in _DEVICE_FAULT_CODES:
        return ""
    return ("\nhint: a GPU reports a kernel that failed (most often one that read or wrote out "
            "of bounds) at the next command on its queue, so the command named here may not be "
            "the culprit: check the index computations of the kernels launched before it")


class Parts(dict):
    """Every component and adapter of a run by name, None until constructed, and where
    each is in its life: run() stores each part as it constructs it; a part counts as
    initialized once its initialize() has returned; each initialized part is freed
    exactly once, by whoever claims it first (free_all at the end of run(), or the main
    thread freeing what it can of a run blocked past a signal)."""

    def __init__(self, names):
        super().__init__(dict.fromkeys(names))
        self.initialized: set[str] = set()
        self._claimed: set[str] = set()
        self._lock = threading.Lock()

    def __setitem__(self, name: str, part: Any) -> None:
        super().__setitem__(name, part)
        if part is None:
            return
        initialize = getattr(part, "initialize", None)
        if initialize is None:
            return

        def initialized(*args, **kwargs):
            result = initialize(*args, **kwargs)
            self.initialized.add(name)
            return result

        try:
            part.initialize = initialized
        except AttributeError:  # a class with __slots__: initialized once constructed
            self.initialized.add(name)

    def claim(self, name: str) -> bool:
        """True once for each initialized part: the caller frees it; False for a part
        never initialized or already claimed."""
        with self._lock:
            if name not in self.initialized or name in self._claimed:
                return False
            self._claimed.add(name)
            return True


def claim(parts: dict[str, Any], name: str) -> bool:
    """Whether to free parts[name] now (a plain dict: every constructed part)."""
    if isinstance(parts, Parts):
        return parts.claim(name)
    return parts[name] is not None


def free_all(parts: dict[str, Any]) -> None:
    """free_memory() on every part in reverse order; one failing does not stop the others.

    With a Parts (what run() makes), only the parts whose initialize() returned, and each
    only once: a second free_all frees nothing.  When run() is already failing, failures
    to free are printed as notes so the first error stays the one reported; otherwise
    they raise one PipelineError naming them all.
    """
    freeing()  # a signal from now on does not cut freeing short
    failed = []
    escaping: BaseException | None = None  # SystemExit, KeyboardInterrupt: after the rest
    for name in reversed(list(parts)):
        if not claim(parts, name):  # never constructed or initialized, or freed already
            continue
        try:
            parts[name].free_memory()
        except Exception as exc:
            failed.append(f"{name}.free_memory() failed: {type(exc).__name__}: {exc}")
        except BaseException as exc:
            escaping = escaping or exc
    if escaping is not None:
        raise escaping
    if not failed:
        return
    in_flight = sys.exc_info()[1]
    if in_flight is not None:
        for line in failed:
            print(f"note: {line}", file=sys.stderr)
        with contextlib.suppress(AttributeError):  # for the report of a stop (runtime.main)
            in_flight.free_failures = len(failed)
        return
    raise PipelineError("; ".join(failed) + " (every other component was freed)")


def model_path(program_file: str, relative: str) -> str:
    """A 'path' parameter of the model: written relative to the model's folder, stored in
    the program relative to the program's folder, resolved here to an absolute path (so
    errors name the path that was looked at, whatever the working directory).  An input
    URI's path is resolved the same way: 'mcap://../drive.mcap?topic=/cam'."""
    scheme, sep, rest = relative.partition("://")
    if sep and scheme.isalpha():
        path, q, query = rest.partition("?")
        return f"{scheme}://{model_path(program_file, path)}{q}{query}"
    return str((Path(program_file).resolve().parent / relative).resolve())
