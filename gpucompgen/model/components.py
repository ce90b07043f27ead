"""A model's 'components:' section: each instance, its type, parameter values (sizes read
from an input's header), placement and fusion, and the names the generated program gives
classes; check's notes on deprecated names."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

from ..errors import Diagnostic, Pos, Reporter, did_you_mean
from ..loader import Document
from ..names import fold, name_hint, name_problem, snake
from .decls import MAX_COMPONENTS, PLACEMENTS, ComponentType, Instance
from .fields import _expect_map, _named, _unknown_keys
from .params import _array_problem, _value_fits, _value_problem_at, param_value, py_yaml
from .type_files import LIBRARY_PREFIX, ModelTypes

INSTANCE_KEYS = ("type", "params", "description", "placement", "fuse")


def _check_class_names(doc: Document, rep: Reporter, components: dict[str, Instance]) -> None:
    """Names the generated program gives classes: those of the types the model uses.

    A component is a variable of run(): it must not hide a class the program defines or
    imports (a GPU-aware type's own class, or a standard type's Python class).  Only the
    types used count, so a type the library adds can never collide with a model's names.
    Two types used under names that differ only by case and underscores (the user's own
    'AbsDiff' and the library's 'lib.AbsDiff') would be two classes of one name.
    """
    used: dict[str, ComponentType] = {}
    for inst in components.values():
        first = used.setdefault(fold(inst.type.name), inst.type)
        if first is not inst.type:
            rep.error(inst.pos, f"component '{inst.name}' uses the library's type "
                      f"'{LIBRARY_PREFIX}{inst.type.name}' and the model also uses its own "
                      f"'{first.name}'" if inst.type.origin == "library" else
                      f"component '{inst.name}' uses the model's own type '{inst.type.name}' "
                      f"and the model also uses the library's '{LIBRARY_PREFIX}{first.name}'",
                      "the generated program names a class after each type: rename your own "
                      "type to use both")
    class_names = {t.python_class or t.name: t.name for t in used.values()}
    class_names.update({t.name: t.name for t in used.values()})
    for inst in components.values():
        clash = class_names.get(inst.name)  # `Camera = Camera()` would shadow the class
        if clash is not None:
            rep.error(doc.key_pos("components", inst.name),
                      f"component name '{inst.name}' collides with "
                      + (f"component type '{clash}'" if clash == inst.name else
                         f"the Python class of component type '{clash}'"),
                      "the generated program uses type names as class names: name the "
                      f"component after its role, e.g. '{snake(clash)}1'")


def placement_problem(rep: Reporter, pos: Pos, cname: str, ctype: ComponentType,
                      where: Any) -> str:
    """The placement asked for a component, or "" after reporting why it cannot be."""
    if not _named(where, PLACEMENTS):
        rep.error(pos, f"placement of '{cname}' must be 'gpu', 'cpu' or 'auto', not {where!r}",
                  did_you_mean(str(where), PLACEMENTS))
        return ""
    side = {"gpu-aware": "gpu", "standard": "cpu"}.get(ctype.kind)
    if side is not None and where != side:
        shown = "automatically ('auto')" if where == "auto" else f"on the {where.upper()}"
        rep.error(pos, f"'{cname}' cannot be placed {shown}: its type '{ctype.name}' is "
                  f"{ctype.kind} and runs on the {side.upper()} only",
                  "only flexible types (kind: flexible, with a kernel and a 'cpu:' function) "
                  "can be placed; remove 'placement:'")
        return ""
    return where


def _instance_params(doc, rep, cpath, ctype: ComponentType, given) -> dict[str, Any]:
    given = _expect_map(doc, rep, cpath + ("params",), given, "params")
    params: dict[str, Any] = {}
    for written, value in given.items():
        pname = ctype.canonical_param(written) or written  # an old name: the parameter's
        decl = ctype.params.get(pname)
        if pname != written and pname in given:
            rep.error(doc.key_pos(*cpath, "params", written),
                      f"'{written}' is an old name of parameter '{pname}', given too",
                      f"keep '{pname}' only")
            continue
        if decl is None:  # (pname is written: no alias named it)
            rep.error(doc.key_pos(*cpath, "params", pname),
                      f"'{ctype.name}' has no parameter '{pname}'",
                      did_you_mean(pname, ctype.params) or f"'{ctype.name}' takes no parameters")
            continue
        problem, at = _value_problem_at(value, decl, ctype.gpu_aware)
        if problem:
            hint = ""
            if decl.invertible and _array_problem(value, decl, ctype.gpu_aware) is None:
                hint = ("give an invertible matrix: no row a combination of the others "
                        "(of a 2x3, of its left 2x2)")
            elif decl.shape:
                hint = (f"give {decl.type}: nested lists of {decl.element} values within "
                        "the parameter's range"
                        + (f", e.g. '{pname}: {py_yaml(decl.default)}'"
                           if decl.default is not None and len(str(decl.default)) <= 60
                           else ""))
            elif isinstance(value, bool) and decl.type in ("str", "path", "input"):
                hint = "YAML 1.1 reads yes/no/on/off as booleans: quote the value"
            elif decl.type in ("int", "float") and _value_fits(value, decl.type):
                hint = "give a value within the parameter's range"
            else:
                example = decl.default if decl.default not in (None, "") else \
                    {"int": 1, "float": 1.0, "bool": True, "str": "text", "path": "images",
                     "input": "shots/"}[decl.type]
                wanted = {"int": "an integer", "float": "a number", "bool": "true or false",
                          "str": "a string (quoted if it looks like a number or boolean)",
                          "path": "a path, relative to the model file or absolute",
                          "input": "an input URI or a path relative to the model file"}
                hint = f"give {wanted[decl.type]}, e.g. '{pname}: {py_yaml(example)}'"
            rep.error(doc.pos(*cpath, "params", written, *at),
                      f"parameter '{written}' of '{ctype.name}' {problem}", hint)
            continue
        params[pname] = param_value(value, decl)
    for pname, decl in ctype.params.items():
        if pname not in params and pname not in given:
            if decl.required:
                rep.error(doc.key_pos(*cpath), f"component '{cpath[-1]}' of type "
                          f"'{ctype.name}' needs parameter '{pname}' ({decl.type})",
                          f"add 'params: {{{pname}: ...}}'")
            else:
                params[pname] = decl.default
    return params


def _sizes_from_input(doc, rep, cpath, ctype: ComponentType, params: dict, given,
                      model_dir: Path) -> None:
    """A source's 'input' parameter names images, a video or a recording: its frame size is
    read from the header (never user code) into the size parameters the model left out,
    and checked against those it gave.  A missing or empty input is an error where the
    size depends on it, else a warning (the program may be run with --input elsewhere)."""
    given = given if isinstance(given, dict) else {}
    inputs = [p for p, d in ctype.params.items() if d.type == "input" and params.get(p)]
    if len(inputs) > 1:
        rep.error(doc.pos(*cpath, "params", inputs[1]),
                  f"'{cpath[-1]}' sets {' and '.join(repr(p) for p in inputs)}: one input only",
                  f"keep one of them ('{inputs[0]}' or '{inputs[1]}')")
        return
    if not inputs or not isinstance(params[inputs[0]], str):
        return
    pname = inputs[0]
    dims = {}  # 'height'/'width' -> the parameter an output's size is
    for port in ctype.outputs.values():
        for dim in ("height", "width"):
            expr = getattr(port, dim)
            if expr is not None and isinstance(expr.body, ast.Name) \
                    and expr.body.id in ctype.params:
                dims[dim] = expr.body.id
    if not dims:
        return
    from ..io.probe import probe_size
    from ..runtime.errors import PipelineError

    missing = [p for p in dims.values() if p not in given]
    where = doc.pos(*cpath, "params", pname)
    try:
        size = probe_size(params[pname], model_dir)
    except PipelineError as exc:
        if missing:
            rep.error(where, f"input of '{cpath[-1]}': {exc}",
                      f"fix '{pname}', or give {' and '.join(missing)} (then the program "
                      "can be run with --input)")
        else:
            rep.warning(where, f"input of '{cpath[-1]}': {exc}",
                        f"the program will need --input {cpath[-1]}=URI")
        return
    if size is None:
        if missing:
            rep.error(where, f"the frame size of '{params[pname]}' (a live camera or stream) "
                      "is not known before it runs",
                      f"give {' and '.join(missing)} in 'params'")
        return
    for dim, value in zip(("height", "width"), size):
        p = dims.get(dim)
        if p is None:
            continue
        if p not in given:
            params[p] = value
        elif given[p] != value:
            rep.error(doc.pos(*cpath, "params", p),
                      f"'{p}' of '{cpath[-1]}' is {given[p]}, but '{params[pname]}' has frames "
                      f"of {size[1]}x{size[0]} (width x height)",
                      f"set '{p}: {value}', or leave it out: it is read from the input")


def _deprecation_notes(doc: Document, components: dict[str, Instance],
                       types: dict[str, ComponentType], renamed: dict[str, tuple[Pos, dict[str, str]]]) -> list[Diagnostic]:
    """check's notes on deprecated names the model uses: a type alias ('ErodeGray'), old
    port names ('erode.eroded').  Both keep working; the notes say what to write."""
    notes = []
    for inst in components.values():
        t = inst.type
        if t.alias_of:
            pos = doc.pos("components", inst.name, "type") if isinstance(
                doc.data["components"][inst.name], dict) else doc.pos("components", inst.name)
            notes.append(Diagnostic(pos.file, pos.line, pos.col, "note",
                                    f"'{t.name}' of '{inst.name}' is a deprecated name of "
                                    f"'{t.alias_of}' with {_alias_channels(t)}",
                                    f"write 'type: {t.alias_of}': it takes "
                                    f"{_generic_channels(types.get(t.alias_of))} channels, "
                                    "from what feeds it"))
        spec = doc.data["components"][inst.name]
        given = spec.get("params") if isinstance(spec, dict) else None
        old_params = {p: t.canonical_param(p) for p in given or ()
                      if p not in t.params and t.canonical_param(p)} \
            if isinstance(given, dict) else {}
        if old_params:
            pos = doc.key_pos("components", inst.name, "params", next(iter(old_params)))
            notes.append(Diagnostic(pos.file, pos.line, pos.col, "note",
                                    f"'{inst.name}' ({t.name}) sets parameters by old names: "
                                    + ", ".join(f"'{o}' is now '{n}'"
                                                for o, n in old_params.items()),
                                    "the old names work for now; write "
                                    + ", ".join(f"'{n}'" for n in old_params.values())))
        if inst.name in renamed:
            pos, old = renamed[inst.name]
            notes.append(Diagnostic(pos.file, pos.line, pos.col, "note",
                                    f"'{inst.name}' ({t.name}) is connected by old port "
                                    f"names: " + ", ".join(f"'{o}' is now '{n}'"
                                                           for o, n in old.items()),
                                    "the old names work for now; write "
                                    + ", ".join(f"'{inst.name}.{n}'" for n in old.values())))
    return notes


def _alias_channels(t: ComponentType) -> str:
    n = t.alias_channels
    return f"{n} channel{'s' if n != 1 else ''}" if n else "the same ports"


def _generic_channels(real: ComponentType | None) -> str:
    port = next(iter(real.inputs.values()), None) if real is not None else None
    return port.channels_text().replace("|", " or ") if port is not None else "any"


def load_components(doc: Document, rep: Reporter, root: dict, found: ModelTypes,
                    model_dir: Path) -> tuple[dict, dict[str, Instance]]:
    """The model's 'components:' as written (name -> spec) and the instances loaded."""
    components: dict[str, Instance] = {}
    comps = _expect_map(doc, rep, ("components",), root.get("components"), "components")
    if not comps:
        rep.error(doc.pos("components") if "components" in root else doc.pos(),
                  "the system has no components", "add 'components:' with named instances")
    elif len(comps) > MAX_COMPONENTS:
        rep.error(doc.key_pos("components"),
                  f"the system has {len(comps):,} components; at most {MAX_COMPONENTS:,} "
                  "are allowed", "split it into several systems")
        rep.raise_if_errors()
    folded: dict[str, str] = {}
    for order, (cname, written) in enumerate(comps.items()):
        inst = _load_instance(doc, rep, cname, written, order, folded, found, model_dir)
        if inst is not None:
            components[cname] = inst
    _check_class_names(doc, rep, components)
    return comps, components


def _load_instance(doc: Document, rep: Reporter, cname: str, written: Any, order: int,
                   folded: dict[str, str], found: ModelTypes,
                   model_dir: Path) -> Instance | None:
    """One component: 'name: Type' or 'name: {type, params, description, placement,
    fuse}' (folded: the names so far, by fold)."""
    cpath = ("components", cname)
    problem = name_problem(cname, "component name", top_level=True)
    if problem:
        rep.error(doc.key_pos(*cpath), problem, name_hint(cname, "use a name such as 'camera1'"))
        return None
    if fold(cname) in folded:
        rep.error(doc.key_pos(*cpath),
                  f"component name '{cname}' collides with '{folded[fold(cname)]}'",
                  "names must differ by more than case and underscores")
        return None
    folded[fold(cname)] = cname
    cspec = _expect_map(doc, rep, cpath, {"type": written} if isinstance(written, str)
                        else written, f"component '{cname}'")
    _unknown_keys(doc, rep, cpath, cspec, INSTANCE_KEYS, f"component '{cname}'")
    ctype = _instance_type(doc, rep, cpath, cspec, found)
    if ctype is None:
        return None
    params = _instance_params(doc, rep, cpath, ctype, cspec.get("params"))
    _sizes_from_input(doc, rep, cpath, ctype, params, cspec.get("params"), model_dir)
    fuse = cspec.get("fuse", True)
    if not isinstance(fuse, bool):
        rep.error(doc.pos(*cpath, "fuse"), f"fuse of '{cname}' must be true or false, "
                  f"not {fuse!r}", "'fuse: false' keeps the component out of every "
                  "group (it runs its kernel alone)")
        fuse = True
    where, where_pos = cspec.get("placement", ""), None
    if "placement" in cspec:
        where_pos = doc.pos(*cpath, "placement")
        where = placement_problem(rep, where_pos, cname, ctype, where)
    return Instance(cname, ctype, params, doc.key_pos(*cpath), order, where, where_pos,
                    fuse=fuse)


def _instance_type(doc: Document, rep: Reporter, cpath: tuple, cspec: dict,
                   found: ModelTypes) -> ComponentType | None:
    """The type a component names ('lib.Name': the library's, even if shadowed), or None
    (reported, unless a type file that failed to load may have had it)."""
    tname = cspec.get("type")
    library, types = found.library, found.types
    if isinstance(tname, str) and tname.startswith(LIBRARY_PREFIX) and \
            tname[len(LIBRARY_PREFIX):] in library:
        return library[tname[len(LIBRARY_PREFIX):]]
    if not _named(tname, types):
        if found.failed and isinstance(tname, str):
            return None
        rep.error(doc.pos(*cpath, "type") if "type" in cspec else doc.key_pos(*cpath),
                  f"unknown component type {tname!r} for '{cpath[-1]}'",
                  did_you_mean(str(tname), types))
        return None
    return types[tname]
