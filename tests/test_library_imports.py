"""Every Python module of the library imports on its own, first, in a fresh interpreter:
a generated program imports only the modules of the types it places on the CPU, in the
order of its import lines, so any of them may be the first.  (A program whose only
CPU-placed library type was a warp died at its import: warp_ops -> cpu_ops ->
cpu_kernels -> warp_ops, which had not yet defined what cpu_kernels takes from it.)"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

LIBRARY = Path(__file__).resolve().parent.parent / "gpucompgen" / "library"
MODULES = sorted(p.stem for p in LIBRARY.glob("*.py") if p.stem != "__init__")


def test_the_library_has_python_modules():
    assert {"cpu_kernels", "cpu_ops", "warp_ops"} <= set(MODULES)


def test_each_library_module_imports_first_on_its_own():
    """One interpreter per module (a module imported earlier would hide the cycle)."""
    failed = {}
    for module in MODULES:
        proc = subprocess.run([sys.executable, "-c", f"import gpucompgen.library.{module}"],
                              capture_output=True, text=True, timeout=120, check=False)
        if proc.returncode != 0:
            failed[module] = proc.stderr.strip().splitlines()[-1]
    assert not failed, failed


def test_every_name_a_type_gives_is_importable_from_its_module_first():
    """The names a generated program imports (a type's cpu: function, a standard type's
    python: class) exist in their module, each module imported first."""
    from gpucompgen.model import library_types

    wanted: dict[str, set[str]] = {}
    for t in library_types().values():
        if t.cpu_file is not None:
            wanted.setdefault(t.cpu_file.stem, set()).add(t.cpu_function)
        if t.python_file is not None:
            wanted.setdefault(t.python_file.stem, set()).add(t.python_class)
    assert {"cpu_kernels", "warp_ops", "camera"} <= set(wanted)
    failed = {}
    for module, names in sorted(wanted.items()):
        proc = subprocess.run([sys.executable, "-c", f"from gpucompgen.library.{module} "
                               f"import {', '.join(sorted(names))}"],
                              capture_output=True, text=True, timeout=120, check=False)
        if proc.returncode != 0:
            failed[module] = proc.stderr.strip().splitlines()[-1]
    assert not failed, failed
