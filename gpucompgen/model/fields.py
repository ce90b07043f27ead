"""Reading one value of a positioned YAML mapping: each helper reports what is wrong at
the value's position and returns something to go on with, so that one run shows every
problem."""

from __future__ import annotations

from typing import Any

from ..errors import Reporter, did_you_mean
from ..loader import Document


def _expect_map(doc: Document, rep: Reporter, path: tuple, value: Any, what: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        rep.error(doc.pos(*path), f"{what} must be a mapping, not {_kind(value)}")
        return {}
    return value


def _named(value: Any, choices) -> bool:
    """value is a string among choices (a YAML list or mapping is never a choice)."""
    return isinstance(value, str) and value in choices


def _kind(value: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a mapping", type(None): "empty"}.get(type(value),
                                                                         type(value).__name__)


def _unknown_keys(doc: Document, rep: Reporter, path: tuple, mapping: dict,
                  allowed: tuple[str, ...], what: str) -> None:
    for key in mapping:
        if key not in allowed:
            rep.error(doc.key_pos(*path, key), f"unknown key '{key}' in {what}",
                      did_you_mean(key, allowed))


def _text(doc: Document, rep: Reporter, path: tuple, value: Any, what: str) -> str:
    if value is None:
        return ""
    if not isinstance(value, str):
        rep.error(doc.pos(*path), f"{what} must be a string, not {_kind(value)}",
                  "quote the value")
        return ""
    return value


def _positive_int(doc: Document, rep: Reporter, path: tuple, value: Any, what: str,
                  default: int | None = None) -> int | None:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        rep.error(doc.pos(*path), f"{what} must be a positive integer, not {value!r}")
        return default
    return value
