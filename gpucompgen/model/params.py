"""Parameters: their types (scalars and arrays, with shapes), the checks of a value against
a declaration (a default, a component's value) and the loader of a type's 'params:'."""

from __future__ import annotations

import math
import re
from typing import Any

from ..errors import Reporter
from ..loader import Document
from ..names import name_problem
from .decls import MAX_PARAMS, ComponentType, ParamDecl
from .fields import _expect_map, _kind, _named, _text, _unknown_keys

# "path": a string naming a file or folder; a relative one is relative to the model file
# "input": a source URI (gpucompgen.io: images, video, camera, stream, recording); a plain
# path in it is relative to the model file, and the frame size is read from its header
PARAM_TYPES = {"int": int, "float": float, "bool": bool, "str": str, "path": str, "input": str}
# array parameters: 'int' or 'float' and one to three dimensions, each a length N or a
# range of lengths A..B ('int[256]', 'float[2][3]', 'int[3..64][2]', 'float[1..15][1..15]'):
# a lookup table, a structuring element, a warp matrix, a polygon, a filter's kernel;
# rectangular (the rows of one value have one length)
ARRAY_TYPE_PATTERN = r"(int|float)((?:\[\d{1,6}(?:\.\.\d{1,6})?\]){1,3})"
ARRAY_TYPE = re.compile(ARRAY_TYPE_PATTERN)
MAX_ARRAY_ELEMENTS = 65536  # of one array parameter (a 256 x 256 table)


PARAM_KEYS = ("type", "default", "min", "max", "description", "invertible", "aliases")


def gpu_kernel_param_problem(kind: str, ptype: str) -> bool:
    return kind in ("gpu-aware", "flexible") and ptype in ("str", "path", "input")


def _int_params(ctype: ComponentType) -> list[str]:
    return [p.name for p in ctype.params.values() if p.type == "int"]


INT32 = (-(1 << 31), (1 << 31) - 1)
FLOAT32_MAX = 3.4028234663852886e38


def array_shape(ptype: str) -> tuple[tuple[tuple[int, int], ...], str]:
    """The dimensions of an array type such as 'int[3..64][2]' ((3, 64), (2, 2)), and ''
    or why the text is no array type."""
    m = ARRAY_TYPE.fullmatch(ptype)
    if m is None:
        return (), "not an array type"
    shape = []
    for dim in m.group(2)[1:-1].split("]["):
        low, _, high = dim.partition("..")
        lo, hi = int(low), int(high or low)
        if lo < 1 or hi < lo:
            return (), (f"dimension [{dim}] must be a length of 1 or more, or a range "
                        "A..B with 1 <= A <= B")
        shape.append((lo, hi))
    if math.prod(hi for _, hi in shape) > MAX_ARRAY_ELEMENTS:
        return (), f"it may hold more than {MAX_ARRAY_ELEMENTS:,} values"
    return tuple(shape), ""


def _array_problem(value: Any, decl: ParamDecl, kernel: bool,
                   index: tuple[int, ...] = ()) -> tuple[str, tuple[int, ...]] | None:
    """Why value is no array of decl's shape, element type and bounds, and the index of
    the element (or list) where that was found, so that the error points at it."""
    depth = len(index)
    where = "".join(f"[{i}]" for i in index)
    what = f"element {where} " if where else ""
    if depth == len(decl.shape):
        element = ParamDecl(decl.name, decl.element, minimum=decl.minimum,
                            maximum=decl.maximum)
        problem = _param_value_problem(value, element, kernel)
        return None if problem is None else (f"{what}{problem}", index)
    lo, hi = decl.shape[depth]
    if not isinstance(value, (list, tuple)):
        return (f"{what}must be a list of {lo}" + (f" to {hi}" if hi != lo else "")
                + f" values, not {_kind(value)}", index)
    if not lo <= len(value) <= hi:
        length = f"{lo}" if lo == hi else f"{lo} to {hi}"
        return f"{what}has {len(value)} values where {decl.type} takes {length}", index
    rows = {len(v) for v in value if isinstance(v, (list, tuple))}
    ranged = depth + 1 < len(decl.shape) and len(set(decl.shape[depth + 1])) > 1
    if ranged and len(rows) > 1:  # rows of one length: a rectangular table
        lengths = " and ".join(map(str, sorted(rows)))
        return f"{what}has rows of {lengths} values: all must have one length", index
    for i, item in enumerate(value):
        found = _array_problem(item, decl, kernel, index + (i,))
        if found:
            return found
    return None


def _value_problem_at(value: Any, decl: ParamDecl,
                      kernel: bool) -> tuple[str | None, tuple[int, ...]]:
    """_param_value_problem, and for an array the index of the element at fault."""
    if decl.shape:
        found = _array_problem(value, decl, kernel)
        if found is None and decl.invertible:
            return _singular(value), ()
        return found or (None, ())
    return _param_value_problem(value, decl, kernel), ()


def _matrix(ptype: str, shape: tuple[tuple[int, int], ...]) -> bool:
    """Whether an array type is a matrix 'invertible:' can apply to."""
    return ptype.startswith("float") and shape in (((2, 2), (2, 2)), ((3, 3), (3, 3)),
                                                   ((2, 2), (3, 3)))


def _singular(value) -> str | None:
    """Why a matrix (2x3: its left 2x2) is not invertible, or None: its determinant is 0
    within float32's precision, relative to its rows' sizes."""
    a = [[float(v) for v in row[:len(value)]] for row in value]
    if len(a) == 2:
        det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
    else:
        det = (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
               - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
               + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
    scale = math.prod(max(abs(v) for v in row) for row in a)
    if abs(det) > 1e-6 * scale:
        return None
    return (f"is a singular matrix (determinant {det:.3g}): it maps the whole frame onto a "
            "line or a point, and has no inverse")


def param_value(value: Any, decl: ParamDecl) -> Any:
    """A checked value as the program keeps it: a float parameter's number as float, an
    array as nested tuples (immutable, hashable) of its element type's numbers."""
    if value is None:
        return None
    if decl.shape:
        def freeze(v: Any) -> Any:
            if isinstance(v, (list, tuple)):
                return tuple(freeze(i) for i in v)
            return float(v) if decl.element == "float" else v
        return freeze(value)
    return float(value) if decl.type == "float" else value


def _param_value_problem(value: Any, decl: ParamDecl, kernel: bool) -> str | None:
    """Why value cannot be given to parameter decl, or None when it can."""
    if decl.shape:
        return _value_problem_at(value, decl, kernel)[0]
    if not _value_fits(value, decl.type):
        return f"must be {decl.type}, not {_kind(value)} ({value!r})"
    if decl.type in ("int", "float"):
        if not math.isfinite(value):
            return f"must be a finite number, not {value!r}"
        if decl.minimum is not None and value < decl.minimum or \
                decl.maximum is not None and value > decl.maximum:
            return f"is {value!r}, outside [{decl.minimum}, {decl.maximum}]"
        if kernel and decl.type == "int" and not INT32[0] <= value <= INT32[1]:
            return f"is {value}, which does not fit the kernel's 32-bit int"
        if kernel and decl.type == "float" and abs(value) > FLOAT32_MAX:
            return f"is {value!r}, which does not fit the kernel's 32-bit float"
    return None


def py_yaml(value: Any) -> str:
    """A value as it would be written in YAML (for hints)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):  # an array parameter's value
        return "[" + ", ".join(py_yaml(v) for v in value) + "]"
    return repr(value) if isinstance(value, str) else str(value)


def _value_fits(value: Any, ptype: str) -> bool:
    if ptype == "float":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if ptype == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, PARAM_TYPES[ptype])


def _load_params(doc: Document, rep: Reporter, base: tuple, ctype: ComponentType,
                 spec: dict) -> bool:
    """A type's 'params:' into ctype.params; False when there are too many to load."""
    params = _expect_map(doc, rep, base + ("params",), spec.get("params"), "params")
    if len(params) > MAX_PARAMS:
        rep.error(doc.key_pos(*base, "params"),
                  f"component type '{ctype.name}' has {len(params):,} parameters; at most "
                  f"{MAX_PARAMS:,} are allowed", "pass fewer, larger values")
        return False
    for pname, written in params.items():
        decl = _load_param(doc, rep, base + ("params", pname), ctype, pname, written)
        if decl is not None:
            ctype.params[pname] = decl
    seen: dict[str, str] = {}
    for pname, decl in ctype.params.items():
        for alias in decl.aliases:
            other = pname if alias in ctype.params else seen.get(alias)
            if other is not None:
                rep.error(doc.pos(*base, "params", pname, "aliases"),
                          f"alias '{alias}' of parameter '{pname}' is also "
                          + (f"parameter '{alias}'" if alias in ctype.params
                             else f"an alias of '{other}'"),
                          "an old name stands for one parameter: remove or rename it")
            seen.setdefault(alias, pname)
    return True


def _load_param(doc: Document, rep: Reporter, ppath: tuple, ctype: ComponentType, pname: str,
                written: Any) -> ParamDecl | None:
    """One parameter ('name: int' or 'name: {type, default, min, max, description}')."""
    problem = name_problem(pname, "parameter name")
    if problem:
        rep.error(doc.key_pos(*ppath), problem)
        return None
    pspec = _expect_map(doc, rep, ppath, {"type": written} if isinstance(written, str)
                        else written, f"parameter '{pname}'")
    _unknown_keys(doc, rep, ppath, pspec, PARAM_KEYS, f"parameter '{pname}'")
    ptype = pspec.get("type")
    shape = _param_type(doc, rep, ppath, ctype, pname, ptype)
    if shape is None:
        return None
    bounds = _param_bounds(doc, rep, ppath, pname, pspec, ptype, shape)
    default = pspec.get("default")
    if "default" in pspec and default is None:
        rep.error(doc.pos(*ppath, "default"), f"default of '{pname}' is empty (null)",
                  f"give {'an' if ptype == 'int' else 'a'} {ptype} default, or remove "
                  "'default:' to make the parameter required")
    invertible = pspec.get("invertible", False)
    if invertible is not False and (invertible is not True or not _matrix(ptype, shape)):
        rep.error(doc.pos(*ppath, "invertible"), f"'invertible' of parameter '{pname}' "
                  "is only 'true', on a float matrix (float[2][2], float[3][3] or "
                  f"float[2][3]), not {py_yaml(invertible)} on {ptype}",
                  "remove 'invertible', or make the parameter such a matrix")
        invertible = False
    decl = ParamDecl(pname, ptype, minimum=bounds["min"], maximum=bounds["max"],
                     shape=shape, invertible=invertible)
    problem, at = (None, ()) if default is None else _value_problem_at(
        default, decl, ctype.kind in ("gpu-aware", "flexible"))
    if problem:
        rep.error(doc.pos(*ppath, "default", *at),
                  f"default of '{pname}' {problem}",
                  f"give a {ptype} default within min and max, or none to make "
                  "the parameter required")
        default = None
    aliases = pspec.get("aliases", [])
    if not isinstance(aliases, list) or any(not isinstance(a, str)
                                            or name_problem(a, "parameter alias")
                                            for a in aliases):
        rep.error(doc.pos(*ppath, "aliases"), f"aliases of parameter '{pname}' must be a "
                  "list of parameter names", "e.g. 'aliases: [x]': old names still accepted")
        aliases = []
    return ParamDecl(pname, ptype, param_value(default, decl), "default" not in pspec,
                     bounds["min"], bounds["max"],
                     _text(doc, rep, ppath + ("description",), pspec.get("description"),
                           "description"),
                     shape, invertible, tuple(aliases))


def _param_type(doc: Document, rep: Reporter, ppath: tuple, ctype: ComponentType, pname: str,
                ptype: Any) -> tuple[tuple[int, int], ...] | None:
    """A parameter's type checked: its array shape (() for a scalar), or None after
    reporting why the type cannot be."""
    shape: tuple[tuple[int, int], ...] = ()
    if isinstance(ptype, str) and "[" in ptype:
        shape, problem = array_shape(ptype)
        if problem:
            rep.error(doc.pos(*ppath, "type"), f"parameter '{pname}' has type {ptype!r}: "
                      f"{problem}", "an array is 'int[N]' or 'float[N]' with one to three "
                      "dimensions, each a length or a range of lengths, e.g. 'int[256]', "
                      "'float[2][3]', 'int[3..64][2]'")
            return None
    elif not _named(ptype, PARAM_TYPES):
        rep.error(doc.pos(*ppath, "type"), f"parameter '{pname}' has type {ptype!r}",
                  "use one of 'int', 'float', 'bool', 'str', or an array such as "
                  "'int[256]'")
        return None
    if gpu_kernel_param_problem(ctype.kind, ptype):
        rep.error(doc.pos(*ppath, "type"),
                  f"parameter '{pname}' of GPU-aware type '{ctype.name}' is {ptype}: "
                  "kernel parameters must be int, float or bool")
        return None
    return shape


def _param_bounds(doc: Document, rep: Reporter, ppath: tuple, pname: str, pspec: dict,
                  ptype: str, shape: tuple) -> dict[str, Any]:
    """'min' and 'max' of a parameter (None where not given or not a finite number)."""
    bounds = {}
    for key in ("min", "max"):
        bound = pspec.get(key)
        numeric = ptype in ("int", "float") or bool(shape)
        if bound is not None and (not numeric or not _value_fits(
                bound, "float") or not math.isfinite(bound)):
            rep.error(doc.pos(*ppath, key),
                      f"'{key}' of parameter '{pname}' must be a finite number"
                      + ("" if numeric else f", and only for int or "
                         f"float parameters, not {ptype}"),
                      f"remove '{key}' or give a number such as {key}: 0")
            bound = None
        bounds[key] = bound
    return bounds
