"""Diagnostics: problems are values, collected across a whole model, printed by the CLI.

A diagnostic prints in the compiler style editors turn into links::

    models/x.yaml:12:5: error: unknown port 'merger.frame3'
      hint: did you mean 'merger.frame2'?
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass, field


@dataclass(frozen=True, order=True)
class Diagnostic:
    file: str
    line: int  # 1-based; 0 when the problem has no position
    col: int  # 1-based
    severity: str  # "error" | "warning"
    message: str
    hint: str = ""

    def format(self) -> str:
        where = self.file if self.line == 0 else f"{self.file}:{self.line}:{self.col}"
        text = f"{where}: {self.severity}: {self.message}"
        if self.hint:
            text += f"\n  hint: {self.hint}"
        return text


class OutputError(Exception):
    """An output path that cannot take what gpucompgen writes (a usage error, exit 2)."""


class UsageError(Exception):
    """A command-line option that does not fit the model, e.g. --place of an unknown
    component (a usage error, exit 2)."""


class GpucompgenError(Exception):
    """The project's one error type: carries one or more diagnostics."""

    def __init__(self, diagnostics: Iterable[Diagnostic]):
        self.diagnostics = sorted(diagnostics)
        super().__init__("\n".join(d.format() for d in self.diagnostics))

    @property
    def errors(self) -> list[Diagnostic]:
        return [d for d in self.diagnostics if d.severity == "error"]


@dataclass
class Reporter:
    """Collects diagnostics for one model; raise_if_errors() ends a phase."""

    diagnostics: list[Diagnostic] = field(default_factory=list)

    def error(self, pos: Pos, message: str, hint: str = "") -> None:
        self.diagnostics.append(Diagnostic(pos.file, pos.line, pos.col, "error", message, hint))

    def warning(self, pos: Pos, message: str, hint: str = "") -> None:
        self.diagnostics.append(Diagnostic(pos.file, pos.line, pos.col, "warning", message, hint))

    @property
    def has_errors(self) -> bool:
        return any(d.severity == "error" for d in self.diagnostics)

    def raise_if_errors(self) -> None:
        if self.has_errors:
            raise GpucompgenError(self.diagnostics)

    @property
    def warnings(self) -> list[Diagnostic]:
        return sorted(d for d in self.diagnostics if d.severity == "warning")


@dataclass(frozen=True)
class Pos:
    """A place in a file, 1-based (PyYAML marks are 0-based: add 1 when making one)."""

    file: str
    line: int = 0
    col: int = 0


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """A hint naming the closest choice, or listing the choices when none is close."""
    choices = sorted(set(choices))
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if close:
        return f"did you mean '{close[0]}'?"
    if not choices:
        return ""
    shown = ", ".join(f"'{c}'" for c in choices[:12])
    more = "" if len(choices) <= 12 else f" (and {len(choices) - 12} more)"
    return f"expected one of {shown}{more}"
