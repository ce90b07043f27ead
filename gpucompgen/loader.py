"""Safe YAML loading that keeps every node's position for error messages.

Only the safe subset of YAML is accepted: no anchors or aliases, no merge keys, no
explicit tags, no duplicate keys, bounded size and nesting.  The result is plain Python
data (dict/list/str/int/float/bool/None) plus a table from each value's path to its
position, so later passes can point at the exact line and column of any value.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import Diagnostic, GpucompgenError, Pos

MAX_FILE_BYTES = 1 << 20
MAX_DEPTH = 32

PathKey = tuple  # a tuple of str keys and int indices


@dataclass
class Document:
    """A loaded YAML file: its data and where each value (and each key) came from."""

    file: str
    data: Any
    positions: dict[PathKey, Pos] = field(default_factory=dict)
    key_positions: dict[PathKey, Pos] = field(default_factory=dict)

    def pos(self, *path: Any) -> Pos:
        """Position of the value at path, or of its nearest ancestor that has one."""
        path = tuple(path)
        while path:
            if path in self.positions:
                return self.positions[path]
            path = path[:-1]
        return self.positions.get((), Pos(self.file, 1, 1))

    def key_pos(self, *path: Any) -> Pos:
        """Position of the mapping key that ends path (falls back to the value)."""
        return self.key_positions.get(tuple(path)) or self.pos(*path)


def _fail(file: str, mark: Any, message: str, hint: str = "") -> GpucompgenError:
    line = (mark.line + 1) if mark is not None else 0
    col = (mark.column + 1) if mark is not None else 0
    return GpucompgenError([Diagnostic(file, line, col, "error", message, hint)])


def load_text(text: str, file: str) -> Document:
    """Parse YAML text into a Document, or raise GpucompgenError with every problem found.

    A syntax error stops parsing, so it is reported alone; the safe-subset problems
    (anchors, aliases, tags, merge and duplicate keys, YAML 1.1 numbers) are collected
    over the whole file and reported together.
    """
    if len(text.encode("utf-8", "surrogatepass")) > MAX_FILE_BYTES:
        raise _fail(file, None, f"file is larger than {MAX_FILE_BYTES} bytes",
                    "a model file should be a few kilobytes; split component types into files")
    problems: list[Diagnostic] = []

    def problem(mark: Any, message: str, hint: str = "") -> None:
        problems.extend(_fail(file, mark, message, hint).diagnostics)

    try:
        # Reject anchors, aliases and explicit tags at the event level, before composing.
        depth = 0
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.AliasEvent):
                problem(event.start_mark, f"alias '*{event.anchor}' is not allowed",
                        "write the value out in full; anchors and aliases are rejected")
            anchor = getattr(event, "anchor", None)
            if anchor is not None and not isinstance(event, yaml.AliasEvent):
                problem(event.start_mark, f"anchor '&{anchor}' is not allowed",
                        "write the value out in full; anchors and aliases are rejected")
            tag = getattr(event, "tag", None)
            if isinstance(event, yaml.ScalarEvent) and tag is not None and \
                    event.implicit == (False, False):
                problem(event.start_mark, f"explicit tag '{tag}' is not allowed",
                        "remove the tag; quote the value if it should be a string")
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                if tag is not None and not event.implicit:
                    problem(event.start_mark, f"explicit tag '{tag}' is not allowed",
                            "remove the tag")
                depth += 1
                if depth > MAX_DEPTH:  # stop at once: deeper input is not even composed
                    raise _fail(file, event.start_mark,
                                f"nesting is deeper than {MAX_DEPTH} levels", "flatten the model")
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = exc.problem or exc.context or "invalid YAML"
        raise _fail(file, mark, f"invalid YAML: {what}",
                    "check indentation, colons and quotes near this place") from None
    except yaml.reader.ReaderError as exc:
        # A character YAML does not allow (a control character, a lone surrogate...).
        line = text.count("\n", 0, exc.position)
        col = exc.position - (text.rfind("\n", 0, exc.position) + 1)
        raise _fail(file, yaml.Mark(file, exc.position, line, col, None, None),
                    f"invalid YAML: character {_char(exc.character)} is not allowed",
                    "remove the character or write it as an escape in a double-quoted "
                    "string") from None
    except yaml.YAMLError as exc:  # pragma: no cover - PyYAML raises marked errors in practice
        raise _fail(file, None, f"invalid YAML: {exc}") from None
    doc = Document(file, None)
    if node is None:
        doc.data = None
        doc.positions[()] = Pos(file, 1, 1)
    else:
        doc.data = _convert(node, (), doc, problems)
    if problems:
        raise GpucompgenError(problems)
    return doc


def _char(c: object) -> str:
    code = c if isinstance(c, int) else ord(c) if isinstance(c, str) and len(c) == 1 else None
    return f"U+{code:04X}" if code is not None else repr(c)


def load_file(path: Path, display: str | None = None) -> Document:
    """Read and parse a YAML file; display is the name used in messages."""
    shown = display or str(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise _fail(shown, None, f"file is larger than {MAX_FILE_BYTES} bytes")
        raw = path.read_bytes()
        text = raw.decode("utf-8")
    except FileNotFoundError:
        raise GpucompgenError([Diagnostic(shown, 0, 0, "error", "file not found",
                                          "check the path")]) from None
    except IsADirectoryError:
        raise GpucompgenError([Diagnostic(shown, 0, 0, "error", "is a directory, not a file",
                                          "give the path of a .yaml file")]) from None
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        col = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1
        raise GpucompgenError([Diagnostic(
            shown, line, col, "error",
            f"file is not UTF-8 text: byte 0x{raw[exc.start]:02x} ({exc.reason})",
            "save the file as UTF-8")]) from None
    except OSError as exc:
        raise GpucompgenError([Diagnostic(shown, 0, 0, "error",
                                          f"cannot read file: {exc.strerror}")]) from None
    return load_text(text, shown)


INT_TAG = "tag:yaml.org,2002:int"
FLOAT_TAG = "tag:yaml.org,2002:float"
PLAIN_INT = re.compile(r"[-+]?(0|[1-9][0-9]*)\Z")


def _scalar(node: yaml.ScalarNode, doc: Document, problems: list[Diagnostic]) -> Any:
    """A scalar's value, constructed the safe way, without reading the text again."""
    try:
        value = yaml.constructor.SafeConstructor().construct_object(node, deep=True)
    except yaml.constructor.ConstructorError as exc:
        problems.extend(_fail(doc.file, node.start_mark,
                              f"invalid value: {exc.problem}").diagnostics)
        return None
    except (ValueError, OverflowError) as exc:  # e.g. a timestamp like 2001-13-45
        problems.extend(_fail(doc.file, node.start_mark, f"invalid value {node.value!r}: {exc}",
                              "quote it if it is meant as a string").diagnostics)
        return None
    # YAML 1.1 reads 010 as 8 (octal), 0x40 as 64, 1:00 as 60 (base 60) and 1_000 as
    # 1000: a model says what it means in plain decimal, or quotes a string.
    surprising = (node.tag == INT_TAG and not PLAIN_INT.match(node.value)) or (
        node.tag == FLOAT_TAG and ":" in node.value)
    if surprising and node.style is None:
        problems.extend(_fail(doc.file, node.start_mark,
                              f"{node.value!r} is read by YAML 1.1 as the number {value!r}",
                              f"write {value!r} if that is meant, or quote '{node.value}' if it "
                              "is a string").diagnostics)
        return None
    return value


def _convert(node: yaml.Node, path: PathKey, doc: Document,
             problems: list[Diagnostic]) -> Any:
    doc.positions[path] = Pos(doc.file, node.start_mark.line + 1, node.start_mark.column + 1)
    if isinstance(node, yaml.ScalarNode):
        return _scalar(node, doc, problems)
    if isinstance(node, yaml.SequenceNode):
        return [_convert(item, path + (i,), doc, problems) for i, item in enumerate(node.value)]
    if isinstance(node, yaml.MappingNode):
        result: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                problems.extend(_fail(doc.file, key_node.start_mark,
                                      "merge key '<<' is not allowed",
                                      "write the keys out in full").diagnostics)
                continue
            if not isinstance(key_node, yaml.ScalarNode):
                problems.extend(_fail(doc.file, key_node.start_mark,
                                      "mapping keys must be plain scalars").diagnostics)
                continue
            key = _scalar(key_node, doc, problems)
            if key is None:
                continue
            if not isinstance(key, (str, int)) or isinstance(key, bool):
                problems.extend(_fail(
                    doc.file, key_node.start_mark,
                    f"mapping key {key_node.value!r} is read as {type(key).__name__}, "
                    "not a string",
                    f"quote it: '{key_node.value}' (YAML 1.1 reads on/off/yes/no as booleans)"
                ).diagnostics)
                continue
            key = str(key)
            if key in result:
                first = doc.key_positions[path + (key,)]
                problems.extend(_fail(
                    doc.file, key_node.start_mark, f"duplicate key '{key}'",
                    f"'{key}' is already defined at line {first.line}; remove one of them"
                ).diagnostics)
                continue
            doc.key_positions[path + (key,)] = Pos(doc.file, key_node.start_mark.line + 1,
                                                   key_node.start_mark.column + 1)
            result[key] = _convert(value_node, path + (key,), doc, problems)
        return result
    raise _fail(doc.file, node.start_mark, "unsupported YAML node")  # pragma: no cover
