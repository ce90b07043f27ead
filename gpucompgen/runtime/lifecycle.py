"""Constructing, checking and freeing the parts of a running system; user modules."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any, NamedTuple

from .errors import PipelineError
from .pipeline import FrameFailure
from .profiling import Profile
from .sizes import Size


def expect_size(component: str, got: Any, expected: Size) -> Size:
    """initialize() must give the size the system propagated at build time."""
    if tuple(got) != tuple(expected):
        raise PipelineError(f"{component}: initialize() gave size {tuple(got)}, but the system "
                            f"was built for {tuple(expected)} (height, width, channels)")
    return Size(*got)


def load_module(path: Path, module_name: str, fresh: bool = True):
    """Import a Python file as a module: a generated program, or a user's component file.

    With fresh=False a module already imported from the same file is reused.
    """
    module = sys.modules.get(module_name)
    if not fresh and module is not None and getattr(module, "__file__", None) == str(path):
        return module
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise PipelineError(f"cannot load module {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module


def load_class(path: Path, name: str) -> type:
    """Load a user's standard component class from a file copied beside the program."""
    module = load_module(path, f"gpucompgen_user_{Path(path).stem}", fresh=False)
    try:
        return getattr(module, name)
    except AttributeError:
        raise PipelineError(f"{path.name} defines no class {name}") from None


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
    who = failing_component(exc, parts)
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
    return PipelineError(f"{who or 'a component'} failed {when}: {type(exc).__name__}: {exc}")


def free_all(parts: dict[str, Any]) -> None:
    """free_memory() on every part in reverse order; one failing does not stop the others.

    When run() is already failing, failures to free are printed as notes so the first
    error stays the one reported; otherwise they raise one PipelineError naming them all.
    """
    failed = []
    for name in reversed(list(parts)):
        if parts[name] is None:  # never constructed
            continue
        try:
            parts[name].free_memory()
        except Exception as exc:
            failed.append(f"{name}.free_memory() failed: {type(exc).__name__}: {exc}")
    if not failed:
        return
    if sys.exc_info()[1] is not None:
        for line in failed:
            print(f"note: {line}", file=sys.stderr)
        return
    raise PipelineError("; ".join(failed) + " (every other component was freed)")
