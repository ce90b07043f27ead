"""A problem in a snippet: where (an offset into its text), what, and what to do."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Problem:
    offset: int  # into the snippet's text
    message: str
    hint: str = ""


class SnippetError(Exception):
    """The first problem that stops reading a snippet (lexing or parsing)."""

    def __init__(self, offset: int, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.problem = Problem(offset, message, hint)
