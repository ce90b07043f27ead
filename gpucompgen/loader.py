"""Safe YAML loading that keeps every node's position for error messages.

Only the safe subset of YAML is accepted: no anchors or aliases, no merge keys, no
explicit tags, no duplicate keys, bounded size and nesting.  The result is plain Python
data (dict/list/str/int/float/bool/None) plus a table from each value's path to its
position, so later passes can point at the exact line and column of any value.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import Diagnostic, GpucompgenError, Pos

MAX_FILE_BYTES = 1 << 18  # a model or component-type file (the largest library file is 25 KB)
MAX_SOURCE_BYTES = 1 << 20  # a kernel (.cl) or Python file of a component type
MAX_DEPTH = 32
MAX_PROBLEMS = 100  # problems of the safe subset reported before reading stops

PathKey = tuple  # a tuple of str keys and int indices


@dataclass
class Document:
    """A loaded YAML file: its data and where each value (and each key) came from."""

    file: str
    data: Any
    positions: dict[PathKey, Pos] = field(default_factory=dict)
    key_positions: dict[PathKey, Pos] = field(default_factory=dict)
    # each string value as written (quotes, escapes, indentation) and its style (None:
    # plain, '"', "'", '|', '>'), to point inside a string (fusable.snippet_position)
    sources: dict[PathKey, tuple[str, str | None]] = field(default_factory=dict)

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


_C_LOADER = getattr(yaml, "CSafeLoader", None)  # None where PyYAML was built without libyaml


def _event_problems(text: str, loader: Any, fast: bool = False):
    """What the reader refuses in text, from its parser's events, before anything is
    composed: (mark, message, hint, fatal) for each alias, anchor, explicit tag and a
    nesting deeper than MAX_DEPTH (fatal: the walk stops there, deeper input is never
    composed).  fast: the walk _fast makes with libyaml, which also refuses an empty
    plain value (libyaml places it a column further than the pure-Python parser) and any
    tag at all.  Raises yaml.YAMLError where the text is not YAML."""
    depth = 0
    for event in yaml.parse(text, Loader=loader):
        mark = event.start_mark
        anchor = getattr(event, "anchor", None)
        tag = getattr(event, "tag", None)
        if isinstance(event, yaml.AliasEvent):
            yield (mark, f"alias '*{anchor}' is not allowed",
                   "write the value out in full; anchors and aliases are rejected", False)
        elif anchor is not None:
            yield (mark, f"anchor '&{anchor}' is not allowed",
                   "write the value out in full; anchors and aliases are rejected", False)
        if isinstance(event, yaml.ScalarEvent):
            if tag is not None and (fast or event.implicit == (False, False)):
                yield (mark, f"explicit tag '{tag}' is not allowed",
                       "remove the tag; quote the value if it should be a string", False)
            if fast and not event.value and not event.style:
                yield mark, "an empty value", "", False
        elif isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            if tag is not None and (fast or not event.implicit):
                yield mark, f"explicit tag '{tag}' is not allowed", "remove the tag", False
            depth += 1
            if depth > MAX_DEPTH:
                yield mark, f"nesting is deeper than {MAX_DEPTH} levels", "flatten the model", True
                return
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1


def _fast(text: str, file: str) -> Document | None:
    """The Document of an ASCII text read with libyaml (PyYAML's C parser, 15x faster),
    or None where load_text must read it.

    Only the library's own type files are read so (load_file(fast=True)), as every
    command reads all sixteen: libyaml accepts texts the pure-Python parser refuses
    (a tab after a value, '|#'), so a user's file is always read by load_text, which
    alone writes the messages: any problem of the event walk (_event_problems, the one
    load_text makes) sends the text there.  tests/test_fuzz_loader.py checks that both
    readings give the same Document for every shipped file, and wherever both accept a
    text.
    """
    if _C_LOADER is None or not text.isascii() or len(text) > MAX_FILE_BYTES:
        return None
    try:
        if next(_event_problems(text, _C_LOADER, fast=True), None) is not None:
            return None
        node = yaml.compose(text, Loader=_C_LOADER)
    except yaml.YAMLError:
        return None
    problems: list[Diagnostic] = []
    doc = Document(file, None)
    if node is None:
        doc.positions[()] = Pos(file, 1, 1)
        return doc
    doc.data = _convert(node, (), doc, problems, text)
    return None if problems else doc


def load_text(text: str, file: str) -> Document:
    """Parse YAML text into a Document, or raise GpucompgenError with every problem found.

    A syntax error stops parsing, so it is reported alone.  Anchors, aliases and tags are
    found first, from the parser's events (_event_problems), and reported together; only
    a file without them is composed, and then merge and duplicate keys and YAML 1.1
    numbers are reported together.
    """
    if len(text.encode("utf-8", "surrogatepass")) > MAX_FILE_BYTES:
        raise _fail(file, None, f"file is larger than {MAX_FILE_BYTES:,} bytes",
                    "a model file should be a few kilobytes; split component types into files")
    problems: list[Diagnostic] = []
    try:
        for mark, message, hint, fatal in _event_problems(text, yaml.SafeLoader):
            if fatal:  # stop at once: deeper input is not even composed
                raise _fail(file, mark, message, hint)
            problems.extend(_fail(file, mark, message, hint).diagnostics)
            if len(problems) >= MAX_PROBLEMS:
                problems.append(Diagnostic(file, 0, 0, "error", f"more than {MAX_PROBLEMS} "
                                           "problems: stopped reading the file"))
                break
        if problems:
            # A file known to be bad is never composed: aliases (an "alias bomb" of nested
            # [*a, *a, ...]) would be expanded exponentially by composing and converting.
            raise GpucompgenError(problems)
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
        doc.data = _convert(node, (), doc, problems, text)
    if problems:
        raise GpucompgenError(problems)
    return doc


def _char(c: object) -> str:
    code = c if isinstance(c, int) else ord(c) if isinstance(c, str) and len(c) == 1 else None
    return f"U+{code:04X}" if code is not None else repr(c)


class FileProblem(Exception):
    """Why a file cannot be read as text; line and col > 0 place it inside the file."""

    def __init__(self, message: str, hint: str = "", line: int = 0, col: int = 0,
                 prefix: str = ""):
        super().__init__(message)
        self.message, self.hint, self.line, self.col = message, hint, line, col
        self.prefix = prefix  # the text before a byte that is not UTF-8


def read_text(path: Path, limit: int, what: str = "file") -> str:
    """Read a UTF-8 text file of at most limit bytes, or raise FileProblem.

    Only regular files are read: the path is looked at (``stat``) before it is opened, so
    a FIFO, a directory or a device node is refused without blocking on it, and the file
    opened is checked again (``fstat``) in case it changed in between.  No more than
    limit + 1 bytes are ever read, whatever the file's size.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise FileProblem(f"{what} not found", "check the path") from None
    except OSError as exc:
        raise FileProblem(f"cannot read {what}: {exc.strerror}") from None
    _regular(info.st_mode, what)
    _small(info.st_size, limit, what)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) |
                     getattr(os, "O_NOCTTY", 0))
    except OSError as exc:
        raise FileProblem(f"cannot read {what}: {exc.strerror}") from None
    try:
        _regular(os.fstat(fd).st_mode, what)
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, limit + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise FileProblem(f"cannot read {what}: {exc.strerror}") from None
    finally:
        os.close(fd)
    raw = b"".join(chunks)
    _small(len(raw), limit, what)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        col = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1
        raise FileProblem(f"{what} is not UTF-8 text: byte 0x{raw[exc.start]:02x} "
                          f"({exc.reason})", "save the file as UTF-8", line, col,
                          raw[:exc.start].decode("utf-8")) from None


def _regular(mode: int, what: str) -> None:
    if stat.S_ISDIR(mode):
        raise FileProblem(f"{what} is a directory, not a regular file",
                          "give the path of a file")
    if not stat.S_ISREG(mode):
        kind = ("a FIFO" if stat.S_ISFIFO(mode) else "a device node"
                if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket"
                if stat.S_ISSOCK(mode) else "special")
        raise FileProblem(f"{what} is {kind}, not a regular file", "give the path of a file")


def _small(size: int, limit: int, what: str) -> None:
    if size > limit:
        raise FileProblem(f"{what} is larger than {limit:,} bytes ({size:,} bytes)",
                          "keep it smaller: split it into several files")


def starts_with_key(text: str, key: str) -> bool:
    """The YAML text is a mapping whose first key is key (read no further than that key,
    so nothing of a file that is not what it should be gets quoted in messages)."""
    expected = (yaml.StreamStartEvent, yaml.DocumentStartEvent, yaml.MappingStartEvent)
    try:
        for i, event in enumerate(yaml.parse(text, Loader=yaml.SafeLoader)):
            if i < len(expected):
                if not isinstance(event, expected[i]) or getattr(event, "anchor", None) \
                        or (i == 2 and event.tag is not None and not event.implicit):
                    return False
                continue
            return isinstance(event, yaml.ScalarEvent) and event.value == key and \
                event.anchor is None and event.tag is None
    except yaml.YAMLError:
        return False
    return False


def load_file(path: Path, display: str | None = None, what: str = "file",
              fast: bool = False) -> Document:
    """Read and parse a YAML file; display is the name used in messages; fast: a file
    shipped with gpucompgen, read with libyaml where _fast can."""
    shown = display or str(path)
    try:
        text = read_text(path, MAX_FILE_BYTES, what)
    except FileProblem as exc:
        raise GpucompgenError([Diagnostic(shown, exc.line, exc.col, "error", exc.message,
                                          exc.hint)]) from None
    return (fast and _fast(text, shown)) or load_text(text, shown)


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
    if surprising and not node.style:  # plain (libyaml: "", Python: None)
        problems.extend(_fail(doc.file, node.start_mark,
                              f"{node.value!r} is read by YAML 1.1 as the number {value!r}",
                              f"write {value!r} if that is meant, or quote '{node.value}' if it "
                              "is a string").diagnostics)
        return None
    return value


def _convert(node: yaml.Node, path: PathKey, doc: Document,
             problems: list[Diagnostic], text: str) -> Any:
    doc.positions[path] = Pos(doc.file, node.start_mark.line + 1, node.start_mark.column + 1)
    if isinstance(node, yaml.ScalarNode):
        value = _scalar(node, doc, problems)
        if isinstance(value, str):  # marks count characters of the text (both parsers)
            doc.sources[path] = (text[node.start_mark.index:node.end_mark.index],
                                 node.style or None)  # libyaml: "" for plain
        return value
    if isinstance(node, yaml.SequenceNode):
        return [_convert(item, path + (i,), doc, problems, text)
                for i, item in enumerate(node.value)]
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
            result[key] = _convert(value_node, path + (key,), doc, problems, text)
        return result
    raise _fail(doc.file, node.start_mark, "unsupported YAML node")  # pragma: no cover
