"""Building kernel files into OpenCL programs with readable errors."""

from __future__ import annotations

import contextlib
import os
import warnings
from pathlib import Path

from .errors import PipelineError


@contextlib.contextmanager
def quiet_compiler():
    """Keep a successful build's compiler chatter off the user's terminal.

    NVIDIA's OpenCL compiler returns a non-empty log for kernels that build fine, which
    pyopencl turns into a CompilerWarning on stderr every run. As in pyopencl, setting
    PYOPENCL_COMPILER_OUTPUT=1 shows it; a failed build always shows its log.
    """
    import pyopencl as cl

    with warnings.catch_warnings():
        if os.environ.get("PYOPENCL_COMPILER_OUTPUT") != "1":
            warnings.simplefilter("ignore", cl.CompilerWarning)
        yield


def build_program(context, path: Path, component: str, options: tuple[str, ...] = ()):
    """Build one kernel file once; a failure names the component, file and build log."""
    import pyopencl as cl

    try:
        source = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise PipelineError(f"{component}: cannot read kernel file {path}: {exc.strerror}") \
            from None
    try:
        with quiet_compiler():
            return cl.Program(context, source).build(options=list(options))
    except cl.RuntimeError as exc:
        log = str(exc).strip()
        raise PipelineError(f"{component}: kernel file {Path(path).name} failed to build:\n"
                            f"{log}") from None
