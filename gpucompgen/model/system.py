"""A system model: its file loaded section by section (name and description, types,
platform, components, connections) into a SystemModel."""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..errors import Pos, Reporter
from ..loader import Document, load_file
from ..names import MODULE_NAMES, name_hint, name_problem
from .components import _deprecation_notes, load_components
from .connections import load_connections
from .decls import SystemModel
from .fields import _kind, _text, _unknown_keys
from .platform import check_gpu_settings, load_platform
from .type_files import ModelTypes, load_type_files

SYSTEM_KEYS = ("system", "description", "types", "platform", "components", "connections")


def load_system(path: Path, display: str | None = None) -> SystemModel:
    """Load a system model and everything it refers to; raise GpucompgenError on problems."""
    display = display or str(path)
    doc = load_file(path, display)
    rep = Reporter()
    root = _root(doc, rep)
    name = _system_name(doc, rep, root)
    description = _text(doc, rep, ("description",), root.get("description"), "description")
    found = load_type_files(doc, rep, path, display, root)
    platform = load_platform(doc, rep, path, root)
    comps, components = load_components(doc, rep, root, found, path.parent)
    check_gpu_settings(rep, platform["gpu_overrides"], comps, components)
    renamed: dict[str, tuple[Pos, dict[str, str]]] = {}  # component -> old port names used
    connections = load_connections(doc, rep, root, comps, components, renamed)
    rep.raise_if_errors()
    notes = found.notes + sorted(_deprecation_notes(doc, components,
                                                    found.library | found.types, renamed))
    model_bytes = path.read_bytes()
    model = SystemModel(name=name, description=description, file=path, display=display,
                        text_sha256=hashlib.sha256(model_bytes).hexdigest(),
                        components=components, connections=connections, types=found.types,
                        notes=notes, load_warnings=rep.warnings, **platform)
    _record_inputs(model, path, model_bytes, found)
    return model


def _root(doc: Document, rep: Reporter) -> dict:
    """The model's top-level mapping, its keys checked (raises when there is none)."""
    if doc.data is None:
        rep.error(doc.pos(), "the model is empty",
                  "a model starts with 'system: <name>' and lists 'components:'")
    elif not isinstance(doc.data, dict):
        rep.error(doc.pos(), f"a system model must be a mapping, not {_kind(doc.data)}",
                  "a model is a mapping of keys: 'system: <name>', 'components:', ...")
    rep.raise_if_errors()
    _unknown_keys(doc, rep, (), doc.data, SYSTEM_KEYS, "the system model")
    return doc.data


def _system_name(doc: Document, rep: Reporter, root: dict) -> str:
    """'system:', the name of the generated program ("system" after reporting a bad one)."""
    name = root.get("system")
    problem = name_problem(name, "system name", top_level=True)
    if not problem and name in MODULE_NAMES:
        problem = (f"system name '{name}' would make {name}.py, which hides the module "
                   f"'{name}' that generated programs import")
    if problem:
        rep.error(doc.pos("system") if "system" in root else doc.pos(), problem,
                  "start the model with 'system: my_system'" if name in MODULE_NAMES
                  else name_hint(name, "start the model with 'system: my_system'"))
        name = "system"
    return name


def _record_inputs(model: SystemModel, path: Path, model_bytes: bytes,
                   found: ModelTypes) -> None:
    """Every file of the user's that feeds the build, with its digest: the model, its
    type files, and their kernel, Python and CPU files."""
    model.add_input(path, model_bytes)
    for tpath, text in found.texts.items():
        model.add_input(tpath, text)
    for t in found.types.values():
        if t.origin != "user":
            continue
        for source, text in ((t.kernel_file, t.kernel_text), (t.python_file, t.python_text),
                             (t.cpu_file, t.cpu_text)):
            if source is not None:
                model.add_input(source, text)
