"""An installed gpucompgen renders what a checkout renders.

The wheel's layout is derived from pyproject.toml (packages, package-dir, package-data), the
way setuptools lays it out, into a folder that is then the only place gpucompgen is imported
from: a template or data file the package data misses makes the build there fail or differ.
(Building the real wheel needs setuptools>=68 from the network; done by hand for issue 23:
`pip wheel --no-deps -w DIR .`, unpacked, renders models/vision_system.yaml byte for byte.)
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _wheel_layout(target: Path) -> list[str]:
    """Copy what the wheel holds into target; returns its files (relative, posix)."""
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    tool = config["tool"]["setuptools"]
    package_dir = tool.get("package-dir", {})
    data = tool.get("package-data", {})
    files = []
    for package in tool["packages"]:
        source = ROOT / package_dir.get(package, package.replace(".", "/"))
        dest = target / package.replace(".", "/")
        chosen = set(source.glob("*.py"))
        for pattern in data.get(package, []):
            chosen |= set(source.glob(pattern))
        for path in sorted(chosen):
            out = dest / path.relative_to(source)
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, out)
            files.append(out.relative_to(target).as_posix())
    return files


def test_every_package_is_in_the_wheel():
    """A package added under gpucompgen/ (model/ was a module once) is listed in
    pyproject.toml's packages, or the installed tool cannot import it."""
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(config["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts)
             for p in (ROOT / "gpucompgen").rglob("__init__.py")}
    assert "gpucompgen.model" in found
    assert sorted(found - listed) == []


def test_every_template_is_package_data(tmp_path):
    files = _wheel_layout(tmp_path / "site")
    templates = sorted(p.relative_to(ROOT / "templates").as_posix()
                       for p in (ROOT / "templates").rglob("*.j2"))
    assert templates, "no templates in templates/"
    for name in templates:
        assert f"gpucompgen/templates/{name}" in files


def test_the_installed_layout_renders_the_checked_in_program(tmp_path):
    site = tmp_path / "site"
    _wheel_layout(site)
    work = tmp_path / "work"
    shutil.copytree(ROOT / "models", work / "models")
    code = ("import sys\n"
            f"sys.path.insert(0, {str(site)!r})\n"
            "import gpucompgen\n"
            f"assert gpucompgen.__file__.startswith({str(site)!r}), gpucompgen.__file__\n"
            "from gpucompgen.cli import main\n"
            "rc = main(['build', 'models/vision_system.yaml', '-o', 'generated'])\n"
            # an editable install's finder would serve a module the layout lacks
            "elsewhere = sorted(n for n, m in sys.modules.items() if n.startswith('gpucompgen')"
            f" and not (getattr(m, '__file__', None) or {str(site)!r}).startswith({str(site)!r}))\n"
            "assert not elsewhere, f'imported from outside the wheel: {elsewhere}'\n"
            "sys.exit(rc)\n")
    # -I: neither PYTHONPATH nor the working directory puts the checkout on the path
    done = subprocess.run([sys.executable, "-I", "-c", code], cwd=work, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    for path in sorted((work / "generated").rglob("*")):
        if path.is_file():
            rel = path.relative_to(work / "generated")
            assert path.read_bytes() == (ROOT / "generated" / rel).read_bytes(), rel
