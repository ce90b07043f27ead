"""A model's 'types:' section: the user's component-type files, read with the library's
types, and what a user's type that shadows a library type means."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import Diagnostic, GpucompgenError, Reporter
from ..loader import MAX_FILE_BYTES, Document, FileProblem, load_text, read_text, starts_with_key
from ..names import fold
from .decls import MAX_TYPE_BYTES, MAX_TYPE_FILES, ComponentType
from .types import library_types, load_types_file

TYPE_FILE_SUFFIXES = (".yaml", ".yml")
# a model names a library type shadowed by its own type of the same name as lib.Name
LIBRARY_PREFIX = "lib."


def _load_user_types(doc: Document, rep: Reporter, path: Path, display: str, i: int,
                     rel: Any, read: dict[Path, tuple[int, int]], texts: dict[Path, str]
                     ) -> dict[str, ComponentType] | None:
    """The types of entry i of the model's 'types:' list, or None after reporting why not.

    A type file is any .yaml/.yml file, relative to the model (``../shared/types.yaml``)
    or absolute, so models can share type files.  Nothing of a file that does not start
    as a component-type file (``component_types:``) is ever quoted in a message."""
    pos = doc.pos("types", i)
    if not isinstance(rel, str) or not rel:
        rep.error(pos, "expected the path of a component-type .yaml file")
        return None
    if "\0" in rel or not rel.endswith(TYPE_FILE_SUFFIXES):
        rep.error(pos, f"component-type file {rel!r} must be a .yaml or .yml file",
                  "component types are declared in YAML files that start with "
                  "'component_types:'")
        return None
    tpath = path.parent / rel
    shown = str(Path(display).parent / rel)
    what = f"component-type file {rel!r}"
    try:
        first = read.get(tpath.resolve())
    except (OSError, RuntimeError):  # a link loop: read_text says what is wrong
        first = None
    if first is not None:
        rep.error(pos, f"{what} is listed twice (also entry {first[0] + 1} of 'types:')",
                  "list each type file once")
        return {}
    try:
        text = read_text(tpath, MAX_FILE_BYTES, what)
    except FileProblem as exc:
        if exc.line and starts_with_key(exc.prefix, "component_types"):
            rep.diagnostics.append(Diagnostic(shown, exc.line, exc.col, "error",
                                              exc.message, exc.hint))
        elif exc.line:
            rep.error(pos, f"{what} is not a component-type file (it is not UTF-8 text)",
                      "a component-type file starts with 'component_types:'")
        else:
            rep.error(pos, exc.message, "paths are relative to the model file"
                      if exc.message.endswith("not found") else exc.hint)
        return None
    size = len(text.encode("utf-8", "surrogatepass"))
    total = size + sum(n for _, n in read.values())
    if total > MAX_TYPE_BYTES:
        rep.error(pos, f"the model's type files come to {total:,} bytes with {rel!r}; at most "
                  f"{MAX_TYPE_BYTES:,} are allowed", "keep only the types the model uses")
        return None
    read[tpath.resolve()] = (i, size)
    texts[tpath.resolve()] = text
    if not starts_with_key(text, "component_types"):
        rep.error(pos, f"{what} is not a component-type file",
                  "a component-type file starts with 'component_types:' (its content is "
                  "not shown)")
        return None
    try:
        return load_types_file(tpath.resolve(), shown, "user", rep, load_text(text, shown))
    except GpucompgenError as exc:
        rep.diagnostics.extend(exc.diagnostics)
        return None


@dataclass
class ModelTypes:
    """The types a model's components may name, and what reading them found."""
    types: dict[str, ComponentType]  # the library's and the user's (which shadow them)
    library: dict[str, ComponentType]  # the library's, also those shadowed ('lib.Name')
    failed: bool = False  # a type file could not be read: its types are not "unknown"
    notes: list[Diagnostic] = field(default_factory=list)  # a user's type shadows one
    texts: dict[Path, str] = field(default_factory=dict)  # type file read -> its text


def load_type_files(doc: Document, rep: Reporter, path: Path, display: str,
                    root: dict) -> ModelTypes:
    """The model's 'types:': the library's types, then those of the user's files."""
    types = library_types()
    type_files = root.get("types") or []
    if not isinstance(type_files, list):
        rep.error(doc.pos("types"), "types must be a list of component-type files")
        type_files = []
    elif len(type_files) > MAX_TYPE_FILES:
        rep.error(doc.key_pos("types"), f"the model lists {len(type_files):,} type files; "
                  f"at most {MAX_TYPE_FILES} are allowed", "put related types in one file")
        rep.raise_if_errors()
    found = ModelTypes(types, dict(types))
    folded_types = {fold(t): t for t in types}
    read: dict[Path, tuple[int, int]] = {}  # type file read -> (index in the list, bytes)
    for i, rel in enumerate(type_files):
        user = _load_user_types(doc, rep, path, display, i, rel, read, found.texts)
        found.failed |= user is None
        for tname, ctype in (user or {}).items():
            clash = folded_types.get(fold(tname))
            if clash is not None and types[clash].origin == "library":
                # The user's own type is the one their model gets: a type the library adds
                # later never breaks a model that worked before.
                del types[clash]
                found.notes.append(Diagnostic(
                    ctype.pos.file, ctype.pos.line, ctype.pos.col, "note",
                    f"component type '{tname}' shadows the library's '{clash}'",
                    f"the model gets this file's '{tname}'; write '{LIBRARY_PREFIX}{clash}' "
                    "for the library's"))
            elif clash is not None:
                rep.error(ctype.pos, f"component type '{tname}' is already defined elsewhere"
                          + ("" if clash == tname else f" as '{clash}'"),
                          "give your type another name (case and underscores do not count)")
                continue
            types[tname] = ctype
            folded_types[fold(tname)] = tname
    return found
