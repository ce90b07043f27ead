"""Every bad model in tests/bad_models/ gets exactly its expected diagnostics, no traceback.

Each model starts with comment lines: what it tests, optionally ``# args: ...`` (extra
arguments for ``gpucompgen check``) and ``# expect: ...`` lines, one per line that
``gpucompgen check`` prints for a problem (``file:line:col: severity: message`` and its
``  hint: ...``).  The test compares those lines exactly: every problem is found, in the
right place, and nothing else is reported.

After a deliberate change of messages, rewrite the expectations and review the diff:
``python tests/test_bad_models.py --regen``.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

FOLDER = Path(__file__).resolve().parent / "bad_models"
CASES = sorted(FOLDER.glob("*.yaml"))
DIAGNOSTIC = re.compile(r"^(\S+?(:\d+:\d+)?: (error|warning): |  hint: )")
EXPECT = "# expect: "
ARGS = "# args: "


def split(path: Path) -> tuple[list[str], list[str], list[str], str]:
    """(description lines, extra args, expected lines, body) of a bad model."""
    text = path.read_bytes().decode("utf-8", "surrogateescape")
    lines = text.splitlines(keepends=True)
    head: list[str] = []
    while lines and lines[0].startswith("#"):
        head.append(lines.pop(0).rstrip("\n"))
    described = [h for h in head if not h.startswith((EXPECT, ARGS))]
    args = [a for h in head if h.startswith(ARGS) for a in h[len(ARGS):].split()]
    expected = [h[len(EXPECT):] for h in head if h.startswith(EXPECT)]
    return described, args, expected, "".join(lines)


def check(path: Path, args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gpucompgen", "check", path.name, *args],
                          check=False, capture_output=True, text=True, cwd=FOLDER,
                          encoding="utf-8", errors="surrogateescape")


def diagnostics(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if DIAGNOSTIC.match(line)]


@pytest.mark.parametrize("path", CASES, ids=lambda p: p.stem)
def test_bad_model(path):
    described, args, expected, _ = split(path)
    assert described, f"{path.name}: say in a first comment line what it tests"
    assert expected, f"{path.name} has no '# expect:' lines"
    proc = check(path, args)
    assert "Traceback" not in proc.stderr + proc.stdout
    assert proc.returncode == 1, proc.stderr
    assert diagnostics(proc.stderr) == expected, proc.stderr
    # every case reports at least one problem with its position
    assert any(re.match(r"\S+:\d+:\d+: ", e) for e in expected)
    assert re.search(r"^\d+ errors? found", proc.stderr, re.MULTILINE) or "--strict" in args


def regen() -> None:
    """Rewrite every case's '# expect:' lines from what gpucompgen prints now."""
    for path in CASES:
        described, args, expected, body = split(path)
        for _ in range(3):  # the header's length moves the body: repeat until stable
            head = described + [ARGS + " ".join(args)] * bool(args) + \
                [EXPECT + e for e in expected]
            path.write_bytes(("\n".join(head) + "\n" + body).encode("utf-8", "surrogateescape"))
            new = diagnostics(check(path, args).stderr)
            if new == expected:
                break
            expected = new
        print(f"{path.name}: {len(expected)} line(s)")


if __name__ == "__main__" and sys.argv[1:] == ["--regen"]:
    regen()
