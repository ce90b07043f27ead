"""Component types: a file of them ('component_types:'), each loaded section by section
(parameters, ports, requirements, implementation), deprecated aliases, and the library's
types."""

from __future__ import annotations

import ast
import copy
from dataclasses import replace
from pathlib import Path
from typing import Any

from .. import sizeexpr
from ..errors import Reporter, did_you_mean
from ..loader import Document, load_file
from ..names import CLASS_RESERVED, member_names, name_problem
from .decls import FAMILIES, KINDS, ComponentType, PortDecl
from .fields import _expect_map, _named, _positive_int, _text, _unknown_keys
from .kernel import _load_fusable, _load_kernel
from .params import _int_params, _load_params
from .ports import _check_generic, _load_ports, _port_sizes
from .sources import _load_cpu, _load_python

TYPE_KEYS = ("kind", "description", "family", "params", "inputs", "outputs", "requires",
             "kernel", "python", "gpu", "cpu", "fusable")


REQUIRE_KEYS = ("check", "message")


def load_types_file(path: Path, display: str, origin: str, rep: Reporter,
                    doc: Document | None = None) -> dict[str, ComponentType]:
    """Load one file of component types: ``component_types: {Name: {...}, ...}`` (doc:
    the file, already loaded)."""
    if doc is None:
        doc = load_file(path, display)
    if doc.data is None:
        rep.error(doc.pos(), "the component-type file is empty",
                  "start it with 'component_types:' and one or more types")
    root = _expect_map(doc, rep, (), doc.data, "a component-type file")
    _unknown_keys(doc, rep, (), root, ("component_types",), "a component-type file")
    types_map = _expect_map(doc, rep, ("component_types",), root.get("component_types"),
                            "component_types")
    if not types_map and not rep.has_errors:
        rep.error(doc.pos(), "no component types defined",
                  "add 'component_types:' with one or more types")
    result = {}
    for tname, spec in types_map.items():
        if isinstance(spec, dict) and "alias" in spec:
            continue
        ctype = _load_type(doc, rep, path, origin, tname, spec)
        if ctype is not None:
            result[tname] = ctype
    for tname, spec in types_map.items():
        if isinstance(spec, dict) and "alias" in spec:
            ctype = _load_alias(doc, rep, tname, spec, result)
            if ctype is not None:
                result[tname] = ctype
    return result


ALIAS_KEYS = ("alias", "channels", "description")


def _load_alias(doc: Document, rep: Reporter, tname: str, spec: dict,
                types: dict[str, ComponentType]) -> ComponentType | None:
    """A deprecated name of a type of the same file: ``GaussianBlurGray: {alias:
    GaussianBlur, channels: 1}`` is GaussianBlur with every port whose channels are generic
    fixed to 1 (the ports that follow them too).  Components of the alias build and run
    as before; check notes the type to use instead."""
    base = ("component_types", tname)
    problem = name_problem(tname, "component type name", top_level=True)
    if problem:
        rep.error(doc.key_pos(*base), problem, "use a CamelCase name such as 'ImageMerger'")
        return None
    _unknown_keys(doc, rep, base, spec, ALIAS_KEYS, f"alias '{tname}'")
    target = spec.get("alias")
    if not _named(target, types) or types[target].alias_of:
        rep.error(doc.pos(*base, "alias"), f"alias '{tname}' names {target!r}, which is no "
                  "type of this file", did_you_mean(str(target), [
                      n for n, t in types.items() if not t.alias_of])
                  or "an alias names a type declared in the same file")
        return None
    real = types[target]
    channels = spec.get("channels")
    twin = copy.copy(real)
    twin.name, twin.alias_of, twin.pos = tname, target, doc.key_pos(*base)
    twin.description = _text(doc, rep, base + ("description",), spec.get("description"),
                             "description") or real.description
    if channels is not None:
        pinned = _positive_int(doc, rep, base + ("channels",), channels, "channels")
        counts = {c for p in (*real.inputs.values(), *real.outputs.values())
                  for c in p.channel_counts}
        if pinned is None:
            return None
        if counts and pinned not in counts:
            rep.error(doc.pos(*base, "channels"), f"alias '{tname}' fixes {pinned} channels; "
                      f"'{target}' takes {' or '.join(map(str, sorted(counts)))}",
                      "give one of them")
            return None

        def pin(port: PortDecl) -> PortDecl:
            if port.channel_counts or port.any_channels or port.channels_of:
                return replace(port, channels=pinned, channel_counts=(), any_channels=False,
                               channels_of="")
            return port
        twin.alias_channels = pinned
        twin.inputs = {p: pin(d) for p, d in real.inputs.items()}
        twin.outputs = {p: pin(d) for p, d in real.outputs.items()}
    return twin


def _load_type(doc: Document, rep: Reporter, path: Path, origin: str, tname: str,
               spec: Any) -> ComponentType | None:
    """One component type, section by section; None when it cannot be loaded at all."""
    base = ("component_types", tname)
    seen = len(rep.diagnostics)
    loaded = _type_header(doc, rep, path, origin, tname, spec)
    if loaded is None:
        return None
    ctype, spec = loaded
    if not _load_params(doc, rep, base, ctype, spec):
        return None
    failed_inputs = _load_ports(doc, rep, base, ctype, spec)
    if failed_inputs is None:
        return None
    _check_generic(doc, rep, base, ctype, spec)
    if not ctype.inputs and not ctype.outputs:
        rep.error(ctype.pos, f"component type '{tname}' has no ports",
                  "declare 'inputs:' and/or 'outputs:'")
    if ctype.kind in ("gpu-aware", "flexible"):
        _check_class_members(doc, rep, base, ctype)
    # output sizes need the input ports, so parse them after all ports are known
    for pname, port in list(ctype.outputs.items()):
        ctype.outputs[pname] = _port_sizes(doc, rep, base + ("outputs", pname), ctype, port,
                                           quiet=failed_inputs > 0)
    _load_requires(doc, rep, base, ctype, spec)
    # a kernel's signature is checked only when the type so far is sound
    _load_implementation(doc, rep, base, ctype, spec, len(rep.diagnostics) == seen)
    return ctype


def _type_header(doc: Document, rep: Reporter, path: Path, origin: str, tname: str,
                 spec: Any) -> tuple[ComponentType, dict] | None:
    """The type's name, keys, kind, description and family: the type with no parameters,
    ports or implementation yet, and its spec as a mapping."""
    base = ("component_types", tname)
    # a GPU-aware type becomes a class of the generated program: a module-level name
    problem = name_problem(tname, "component type name", top_level=True)
    if problem:
        rep.error(doc.key_pos(*base), problem, "use a CamelCase name such as 'ImageMerger'")
        return None
    spec = _expect_map(doc, rep, base, spec, f"component type '{tname}'")
    _unknown_keys(doc, rep, base, spec, TYPE_KEYS, f"component type '{tname}'")
    kind = spec.get("kind")
    if kind not in KINDS:
        rep.error(doc.pos(*base, "kind") if "kind" in spec else doc.key_pos(*base),
                  f"component type '{tname}' needs kind 'standard', 'gpu-aware' or "
                  f"'flexible', not {kind!r}",
                  "add 'kind: gpu-aware', 'kind: standard' or 'kind: flexible'")
        return None
    ctype = ComponentType(
        name=tname, kind=kind,
        description=_text(doc, rep, base + ("description",), spec.get("description"),
                          "description"),
        params={}, inputs={}, outputs={}, requires=[], decl_file=path, origin=origin,
        pos=doc.key_pos(*base))
    if "family" in spec:
        if _named(spec["family"], FAMILIES):
            ctype.family = spec["family"]
        else:
            rep.error(doc.pos(*base, "family"), f"family of '{tname}' must be one of "
                      f"{', '.join(FAMILIES)}, not {spec['family']!r}",
                      did_you_mean(str(spec["family"]), FAMILIES) or
                      "it groups the type in 'gpucompgen types'")
    return ctype, spec


def _load_requires(doc: Document, rep: Reporter, base: tuple, ctype: ComponentType,
                   spec: dict) -> None:
    """'requires:': conditions between input sizes (and int parameters)."""
    requires = spec.get("requires") or []
    if not isinstance(requires, list):
        rep.error(doc.pos(*base, "requires"), "requires must be a list of conditions")
        requires = []
    for i, written in enumerate(requires):
        rpath = base + ("requires", i)
        message, req = "", written
        if isinstance(written, dict):
            _unknown_keys(doc, rep, rpath, written, REQUIRE_KEYS, "a requirement")
            message = _text(doc, rep, rpath + ("message",), written.get("message"), "message")
            req = written.get("check")
        try:
            tree = sizeexpr.parse(req, set(ctype.inputs), set(_int_params(ctype)),
                                  condition=True)
        except sizeexpr.SizeExprError as exc:
            rep.error(doc.pos(*rpath), f"requirement of '{ctype.name}': {exc}")
            continue
        ctype.requires.append((tree, message or f"requires {ast.unparse(tree.body)}"))


def _load_implementation(doc: Document, rep: Reporter, base: tuple, ctype: ComponentType,
                         spec: dict, signature_check: bool) -> None:
    """What runs the type, by kind: a flexible type's kernel (or fusable form) and CPU
    function, a GPU-aware type's kernel (or fusable form), a standard type's Python class;
    the keys of another kind are errors."""
    tname = ctype.name
    if ctype.kind == "flexible":
        _load_kernel(doc, rep, base, ctype, spec, signature_check=signature_check)
        _load_cpu(doc, rep, base, ctype, spec)
        if "fusable" in spec:
            _load_fusable(doc, rep, base, ctype, spec["fusable"])
        if "python" in spec:
            rep.error(doc.key_pos(*base, "python"),
                      "a flexible type's CPU side is a function, 'cpu: {file, function}', "
                      "not 'python'", "write 'cpu: {file: x.py, function: f}'")
    elif ctype.kind == "gpu-aware":
        _load_kernel(doc, rep, base, ctype, spec, signature_check=signature_check)
        if "cpu" in spec:
            rep.error(doc.key_pos(*base, "cpu"),
                      f"'cpu' is only for flexible types; '{tname}' is gpu-aware",
                      "set 'kind: flexible' (and remove 'memory:' from its ports) or "
                      "remove 'cpu:'")
        if "fusable" in spec:
            _load_fusable(doc, rep, base, ctype, spec["fusable"])
        if "python" in spec:
            rep.error(doc.key_pos(*base, "python"),
                      "a GPU-aware type is implemented by its OpenCL kernel, not 'python'",
                      "remove 'python:' or make the type 'kind: standard'")
    else:
        _load_python(doc, rep, base, ctype, spec)
        for key in ("kernel", "gpu", "cpu", "fusable"):
            if key in spec:
                rep.error(doc.key_pos(*base, key),
                          f"'{key}' is only for GPU-aware or flexible types; '{tname}' is "
                          "standard", "set 'kind: gpu-aware' or 'kind: flexible', or remove "
                          "the key")


def _check_class_members(doc: Document, rep: Reporter, base: tuple,
                         ctype: ComponentType) -> None:
    """A GPU-aware type's parameters and ports become members and locals of one generated
    class (self.<param>, self.<port>_size, ...): none may clash with another or with what
    the class itself uses."""
    owners: dict[str, tuple[str, str]] = {}  # member -> (what made it, the declared name)
    declared = ([(p, "param", ("params", p)) for p in ctype.params]
                + [(p, "in", ("inputs", p)) for p in ctype.inputs]
                + [(p, "out", ("outputs", p)) for p in ctype.outputs])
    what = {"param": "parameter", "in": "input port", "out": "output port"}
    for pname, role, key in declared:
        this = f"{what[role]} '{pname}'"
        members = member_names(pname, role)
        member = next((m for m in members if m in CLASS_RESERVED or m in owners), None)
        if member is None:
            owners.update(dict.fromkeys(members, (this, pname)))
            continue
        made = "" if member == pname else f" (it makes '{member}')"
        if member in CLASS_RESERVED:
            clash = f"'{member}', a name the generated component class uses itself"
        else:
            other, other_name = owners[member]
            clash = other + ("" if member == other_name else f", which makes '{member}' too")
        rep.error(doc.key_pos(*base, *key),
                  f"{this} of '{ctype.name}'{made} clashes with {clash}",
                  "rename it: parameters and ports of a GPU-aware type share the generated "
                  "class's names")


LIBRARY_DIR = Path(__file__).resolve().parent.parent / "library"


_LIBRARY_CACHE: dict[str, ComponentType] | None = None


def library_types() -> dict[str, ComponentType]:
    """Component types shipped with gpucompgen (gpucompgen/library/*.yaml)."""
    global _LIBRARY_CACHE
    if _LIBRARY_CACHE is None:
        rep = Reporter()
        types: dict[str, ComponentType] = {}
        for path in sorted(LIBRARY_DIR.glob("*.yaml")):
            shown = f"<gpucompgen>/library/{path.name}"
            types.update(load_types_file(path, shown, "library", rep,
                                         load_file(path, shown, fast=True)))
        rep.raise_if_errors()
        _LIBRARY_CACHE = types
    return dict(_LIBRARY_CACHE)
