"""The README's tour needs nothing the quick start does not install.

The quick start is ``bash scripts/install.sh pocl``: gpucompgen's dependencies and the
``pocl`` extra (and Graphviz, where apt-get can install it).  After it, the tour's
``gpucompgen run models/red_objects.yaml`` failed with "reading camera images needs
Pillow": Pillow was only in an extra the quick start does not install.

Each gpucompgen command the tour shows is run here with an audit hook (inherited by the
program ``run`` starts) that records every module imported; each module from outside the
standard library and gpucompgen must come from a distribution that the dependencies and
the quick start's extras require, directly or through their own requirements.
"""

from __future__ import annotations

import importlib.metadata as md
import os
import re
import shlex
import subprocess
import sys

import pytest
from conftest import ROOT, require_opencl

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

QUICK_START_EXTRAS = {"pocl"}  # scripts/install.sh's default, the quick start's command
# Records the modules that gpucompgen's own code and the generated program import (a
# third-party package's own optional imports are its installer's business).
HOOK = """\
import os, sys
_log = os.environ.get("TOUR_IMPORT_LOG")
_ours = os.environ.get("TOUR_OURS", "")
if _log:
    def _hook(event, args, _log=_log):
        if event != "import":
            return
        frame = sys._getframe(0).f_back
        while frame is not None and (frame.f_code.co_filename.startswith("<") or
                                     frame.f_code.co_filename == __file__):
            frame = frame.f_back
        where = frame.f_code.co_filename if frame is not None else ""
        if where.startswith(_ours) or "gpucompgen-run-" in where:
            with open(_log, "a") as f:
                f.write(args[0].partition(".")[0] + "\\n")
    sys.addaudithook(_hook)
"""


def tour_commands() -> list[str]:
    """Every complete gpucompgen command of the README's quick start and tour that names a
    model of the repository (not the options alone, nor the tests' bad models)."""
    text = (ROOT / "README.md").read_text()
    tour = text[text.index("## Quick start"):text.index("## Documentation")]
    found = [m[1].strip() for m in re.finditer(r"&& \.venv/bin/(gpucompgen [^\n`]+)", tour)]
    tour = re.sub(r"\s*\n\s*", " ", tour)  # commands wrap inside backticks
    for m in re.finditer(r"`(?:\.venv/bin/)?(gpucompgen [^`]+?)`|\$ (gpucompgen [^$`]+?"
                         r"\.yaml)", tour):
        command = (m[1] or m[2]).strip()
        if command.split()[-1] == "NAME":  # a placeholder: one of the library's types
            command = command.replace("NAME", "InRange")
        if re.search(r"\bmodels/\S+\.yaml\b", command) or command.split()[1] == "types":
            found.append(command)
    return sorted(set(found))


def _name(requirement: str) -> str:
    return re.split(r"[\s\[<>=!~;(]", requirement.strip(), maxsplit=1)[0]


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def installed_by_quick_start() -> set[str]:
    """Distributions the quick start installs: the dependencies, the quick start's extras,
    and everything they require in turn (with the extras they ask for)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    wanted = list(project["dependencies"])
    for extra in QUICK_START_EXTRAS:
        wanted += project["optional-dependencies"][extra]
    seen: set[str] = set()
    while wanted:
        req = wanted.pop()
        name = _norm(_name(req))
        extras = set(re.findall(r"[\w-]+", req[req.find("[") + 1:req.find("]")])) \
            if "[" in req.split(";")[0] else set()
        if name in seen and not extras:
            continue
        seen.add(name)
        try:
            requires = md.requires(name) or []
        except md.PackageNotFoundError:
            continue
        for sub in requires:
            marker = sub.partition(";")[2]
            asked = re.findall(r"extra\s*==\s*['\"]([^'\"]+)", marker)
            if asked and not set(asked) & extras:
                continue
            wanted.append(sub.partition(";")[0])
    return seen


def test_the_tour_has_its_commands():
    commands = tour_commands()
    assert any(c.startswith("gpucompgen run models/red_objects.yaml") for c in commands)
    assert any(c.startswith("gpucompgen run models/vision_system.yaml") for c in commands)
    assert any(c.startswith("gpucompgen graph") for c in commands)


def test_pillow_is_installed_by_the_quick_start():
    assert "pillow" in installed_by_quick_start()


def test_every_tour_command_imports_only_what_the_quick_start_installs(tmp_path):
    require_opencl()
    (tmp_path / "hook").mkdir()
    (tmp_path / "hook" / "sitecustomize.py").write_text(HOOK)
    allowed = installed_by_quick_start()
    owners = md.packages_distributions()
    stdlib = set(sys.stdlib_module_names) | {"gpucompgen", "__main__", "sitecustomize"}
    for command in tour_commands():
        argv = shlex.split(command)[1:]
        if argv[0] == "graph":
            argv[argv.index("-o") + 1] = str(tmp_path / "graph.dot")  # Graphviz: install.sh
        if argv[0] == "build":
            argv += ["-o", str(tmp_path / "out")]
        if argv[0] == "run":  # a few frames say what a run imports
            if "--frames" in argv:
                del argv[argv.index("--frames"):argv.index("--frames") + 2]
            argv += ["--frames", "2"]
        log = tmp_path / "imports.txt"
        log.write_text("")
        env = {**os.environ, "TOUR_IMPORT_LOG": str(log),
               "TOUR_OURS": str(ROOT / "gpucompgen"),
               "PYTHONPATH": os.pathsep.join(
                   filter(None, [str(tmp_path / "hook"), str(ROOT), os.environ.get("PYTHONPATH")]))}
        proc = subprocess.run([sys.executable, "-m", "gpucompgen", *argv], cwd=ROOT, env=env,
                              capture_output=True, text=True, check=False, timeout=300)
        assert proc.returncode == 0, f"{command}: {proc.stderr[-2000:]}"
        modules = set(log.read_text().split()) - stdlib
        foreign = {m: owners.get(m) for m in modules
                   if m in owners and not {_norm(d) for d in owners[m]} & allowed}
        assert not foreign, f"'{command}' imports {foreign}, which 'install.sh pocl' " \
            "does not install: add them to the dependencies or the pocl extra"
