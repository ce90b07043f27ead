"""A type's GPU side: its hand-written kernel ('kernel:' with the calling convention's
signature check), the block shapes it accepts ('gpu:'), and its fusable form
('fusable:'), from which the system generates kernels."""

from __future__ import annotations

from pathlib import Path

from .. import fusable as fusable_forms
from .. import sizeexpr
from ..backend import signature_checker
from ..errors import did_you_mean
from ..names import name_problem
from .decls import COVERS, DTYPES, SETTING_KEYS, ComponentType, GpuDecl
from .fields import _expect_map, _named, _positive_int, _unknown_keys
from .params import _int_params
from .sources import _resolve_file

KERNEL_KEYS = ("file", "function", "grid", "cover")
GPU_KEYS = ("tiles", "block_z", "prefer", "max_threads", "square")


FUSABLE_KEYS = ("form", "value", "radius", "border", "reads", "tables", "stages", "axis")
STAGE_KEYS = ("dtype", "radius", "axis", "reads", "value")


def _check_signature(doc, rep, base, ctype: ComponentType, kspec: dict) -> None:
    """The kernel's real definition takes what the calling convention passes."""
    pos = doc.pos(*base, "kernel", "function") if "function" in kspec else \
        doc.key_pos(*base, "kernel")
    shown = str(Path(doc.file).parent / kspec["file"])
    check, signature_error = signature_checker()  # kernel files are OpenCL C
    try:
        check(ctype, ctype.kernel_text, ctype.kernel_function)
    except signature_error as exc:
        where = f"{shown}:{exc.line}" if exc.line else shown
        rep.error(pos, f"kernel file {where}: {exc.message}", exc.hint)


def _no_array_params(doc, rep, base, ctype: ComponentType) -> None:
    """A hand-written kernel's arguments are numbers (the calling convention): array
    parameters reach generated kernels only."""
    for pname, decl in ctype.params.items():
        if decl.shape:
            rep.error(doc.pos(*base, "params", pname, "type"),
                      f"array parameter '{pname}' of '{ctype.name}' cannot reach a "
                      "hand-written kernel (its arguments are numbers)",
                      "declare a 'fusable:' form instead of 'kernel:' (its generated kernel "
                      "gets the array as a constant table), or pass numbers")


def _load_kernel(doc, rep, base, ctype: ComponentType, spec,
                 signature_check: bool = True) -> None:
    if "kernel" not in spec and "fusable" in spec:
        # the kernel is generated from the fusable form (kernelgen/fused.py), for a
        # component alone as for a fused group: the operation is declared once
        ctype.grid = next(iter(ctype.outputs), "")
        ctype.cover = "rows"
        if "gpu" in spec:
            rep.error(doc.key_pos(*base, "gpu"),
                      f"'gpu' settings of '{ctype.name}' are for a hand-written kernel; its "
                      "kernel is generated from its fusable form, with the system's settings",
                      "remove 'gpu:' (or add 'kernel: {file, function}')")
        return
    kspec = _expect_map(doc, rep, base + ("kernel",), spec.get("kernel"), "kernel")
    if not kspec:
        rep.error(ctype.pos, f"GPU-aware type '{ctype.name}' needs 'kernel: {{file, function}}'",
                  "or a 'fusable:' form, from which the system generates its kernel")
        return
    _unknown_keys(doc, rep, base + ("kernel",), kspec, KERNEL_KEYS, "kernel")
    _no_array_params(doc, rep, base, ctype)
    found = _resolve_file(doc, rep, base + ("kernel", "file"), ctype.decl_file.parent,
                          kspec.get("file"), ".cl", "kernel file")
    if found is not None:
        ctype.kernel_file, ctype.kernel_text = found
    function = kspec.get("function", ctype.snake)
    problem = name_problem(function, "kernel function name")
    if problem:
        rep.error(doc.pos(*base, "kernel", "function"), problem)
    else:
        ctype.kernel_function = function
        if found is not None and signature_check:
            _check_signature(doc, rep, base, ctype, kspec)
    grid = kspec.get("grid", next(iter(ctype.outputs), ""))
    if not _named(grid, ctype.outputs):
        rep.error(doc.pos(*base, "kernel", "grid") if "grid" in kspec else ctype.pos,
                  f"kernel grid {grid!r} of '{ctype.name}' is not an output port",
                  did_you_mean(str(grid), ctype.outputs))
    else:
        ctype.grid = grid
    cover = kspec.get("cover", "squares")
    if cover not in COVERS:
        rep.error(doc.pos(*base, "kernel", "cover"),
                  f"kernel cover {cover!r} of '{ctype.name}' is not one of {list(COVERS)}",
                  "'squares': a work-group covers tile x tile pixels; 'rows': tile whole rows")
    else:
        ctype.cover = cover
    _load_gpu(doc, rep, base, ctype, spec)


def _load_gpu(doc, rep, base, ctype: ComponentType, spec) -> None:
    """'gpu:': the tiles, block_z and preferred block a hand-written kernel accepts, and
    its block constraints (at most max_threads per work-group, square blocks)."""
    gspec = _expect_map(doc, rep, base + ("gpu",), spec.get("gpu"), "gpu")
    _unknown_keys(doc, rep, base + ("gpu",), gspec, GPU_KEYS, "gpu")
    decl = GpuDecl()
    tiles = gspec.get("tiles", list(decl.tiles))
    block_z = gspec.get("block_z", list(decl.block_z))
    for key, values in (("tiles", tiles), ("block_z", block_z)):
        if not isinstance(values, list) or not values or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in values):
            rep.error(doc.pos(*base, "gpu", key), f"gpu.{key} must be a list of positive integers")
            return
    prefer = _expect_map(doc, rep, base + ("gpu", "prefer"), gspec.get("prefer"), "prefer")
    _unknown_keys(doc, rep, base + ("gpu", "prefer"), prefer, SETTING_KEYS, "prefer")
    values = []
    for key, fallback in zip(SETTING_KEYS, decl.prefer):
        v = _positive_int(doc, rep, base + ("gpu", "prefer", key), prefer.get(key), key, fallback)
        values.append(v)
    max_threads = None
    if "max_threads" in gspec:
        max_threads = _positive_int(doc, rep, base + ("gpu", "max_threads"),
                                    gspec["max_threads"], "max_threads", None)
    square = gspec.get("square", False)
    if not isinstance(square, bool):
        rep.error(doc.pos(*base, "gpu", "square"), "gpu.square must be true or false")
        square = False
    if square and values[1] != values[2]:
        rep.error(doc.pos(*base, "gpu", "prefer") if prefer else doc.pos(*base, "gpu"),
                  f"gpu.prefer of '{ctype.name}' has block {values[1]}x{values[2]}, but "
                  "gpu.square asks for block_x == block_y",
                  "prefer a square block such as block_x: 16, block_y: 16")
    ctype.gpu = GpuDecl(tuple(sorted(set(tiles))), tuple(sorted(set(block_z))), tuple(values),
                        max_threads, square)


def _snippet_problems(doc, rep, path, ctype: ComponentType, value: str, problems) -> None:
    """Each problem of the snippet at its place in the YAML string."""
    start = doc.pos(*path, "value")
    raw, style = doc.sources.get(path + ("value",), (None, None))
    for p in problems:
        at = fusable_forms.snippet_position(start, raw, style, value, p.offset)
        where = "" if at is not None else f" (at character {p.offset + 1} of the snippet)"
        rep.error(at or start, f"fusable snippet of '{ctype.name}': {p.message}{where}",
                  p.hint or "a snippet uses y, x, c, its ports as <port>(y, x, c), "
                  "<port>_height, <port>_width, <port>_t (element type), its parameters "
                  "and its own locals")


def _names_taken(doc, rep, base, ctype: ComponentType) -> bool:
    """Whether a parameter or port has a name the type's snippet gets for a port
    (<port>_height, <port>_t, <port>_max, ...): each is an error at its place."""
    given = fusable_forms.port_names(list(ctype.inputs), list(ctype.outputs))
    taken = [(("params", n), "parameter") for n in ctype.params if n in given]
    taken += [((key, n), "port") for key, ports in (("inputs", ctype.inputs),
                                                     ("outputs", ctype.outputs))
              for n in ports if n in given]
    for where, what in taken:
        rep.error(doc.key_pos(*base, *where), f"{what} '{where[1]}' of '{ctype.name}' has "
                  f"the name its fusable snippet gets for {given[where[1]]}",
                  f"rename the {what}: a snippet names each port's height, width, "
                  "element type and its bounds <port>_height, <port>_width, <port>_t, "
                  "<port>_min, <port>_max")
    return bool(taken)


def _load_fusable(doc, rep, base, ctype: ComponentType, fspec) -> None:
    """The type's fusable form (gpucompgen/fusable.py), checked as far as possible without
    a device."""
    path = base + ("fusable",)
    fspec = _expect_map(doc, rep, path, fspec, "fusable")
    _unknown_keys(doc, rep, path, fspec, FUSABLE_KEYS, "fusable")
    form = fspec.get("form")
    if not _named(form, fusable_forms.FORMS):
        rep.error(doc.pos(*path, "form") if "form" in fspec else doc.key_pos(*path),
                  f"fusable form of '{ctype.name}' must be one of "
                  f"{', '.join(fusable_forms.FORMS)}, not {form!r}",
                  "pointwise: inputs read at (y, x); index_map: each input at one computed "
                  "position; stencil: a window of 'radius' with a 'border' rule")
        return
    if len(ctype.outputs) != 1:
        rep.error(doc.key_pos(*path), f"only types with a single output can be fusable; "
                  f"'{ctype.name}' has {len(ctype.outputs)}",
                  "remove 'fusable:' (the type stays opaque: its kernel runs on its own)")
        return
    value = fspec.get("value")
    if not isinstance(value, str) or not value.strip():
        rep.error(doc.pos(*path, "value") if "value" in fspec else doc.key_pos(*path),
                  f"fusable '{ctype.name}' needs 'value': an OpenCL C expression (or "
                  "statements ending in 'return ...;') for output element (y, x, c)",
                  "e.g. value: \"image(image_height - 1 - y, x, c)\"")
        return
    if _names_taken(doc, rep, base, ctype):
        return
    tables = _load_tables(doc, rep, path, ctype, fspec) if form == "stencil" else {}
    if tables is None:
        return
    # an array parameter's lengths: names of the snippet and of the radius
    lengths = [n for p, d in ctype.params.items() if d.shape
               for n in fusable_forms.length_names(p, len(d.shape))]
    stages = _load_stages(doc, rep, path, ctype, fspec, tables, lengths) \
        if form == "stencil" else {}
    if stages is None:
        return
    analysis = fusable_forms.analyse(value, form, [*ctype.inputs, *stages],
                                     list(ctype.outputs), [*ctype.params, *tables, *lengths],
                                     arrays=[*(n for n, d in ctype.params.items() if d.shape),
                                             *tables])
    _snippet_problems(doc, rep, path, ctype, value, analysis.problems)
    radius: int | str = 0
    border = fspec.get("border", "clamp")
    if form == "stencil":
        radius = fspec.get("radius")
        int_params = _int_params(ctype) + lengths
        if not _count(radius, int_params):
            rep.error(doc.pos(*path, "radius") if "radius" in fspec else doc.key_pos(*path),
                      f"stencil '{ctype.name}' needs 'radius': a number of pixels (0 or "
                      f"more), an int parameter or an expression of them, not {radius!r}",
                      did_you_mean(str(radius), int_params) if int_params else
                      "e.g. radius: 1")
            return
        if not _named(border, fusable_forms.BORDERS) and not _named(border, int_params):
            rep.error(doc.pos(*path, "border"), f"stencil border {border!r} of "
                      f"'{ctype.name}' is not one of {list(fusable_forms.BORDERS)} nor an "
                      "int parameter", "clamp: reads outside the input take the nearest edge "
                      "pixel; an int parameter holds OpenCV's border code (0, 1, 2 or 4)")
            return
        reads = fspec.get("reads")
        if reads is not None and not _count(reads, int_params, least=1):
            rep.error(doc.pos(*path, "reads"), f"stencil '{ctype.name}': 'reads' must be a "
                      "number (1 or more), an int parameter or an expression of them, not "
                      f"{reads!r}", "the input elements an output element reads with the "
                      "snippet's loops unrolled, e.g. reads: (2 * r + 1) * (2 * r + 1)")
            return
    else:
        for key in ("radius", "border", "reads", "tables", "stages", "axis"):
            if key in fspec:
                rep.error(doc.key_pos(*path, key), f"'{key}' is only for the stencil form",
                          f"remove '{key}' or use 'form: stencil'")
    if analysis.problems or not _axis_ok(doc, rep, path, ctype, fspec):
        return
    ctype.fusable = fusable_forms.FusableDecl(form, value, analysis.tree, analysis.names,
                                              radius, border,
                                              fspec.get("reads") if form == "stencil" else None,
                                              tables, stages, fspec.get("axis"))


def _axis_ok(doc, rep, path, ctype: ComponentType, spec) -> bool:
    """A stencil's (or stage's) 'axis', where given, is x or y."""
    if "axis" not in spec or _named(spec["axis"], fusable_forms.AXES):
        return True
    rep.error(doc.pos(*path, "axis"), f"stencil '{ctype.name}': 'axis' is x (the window "
              f"is a row: reads at (y, x + d) only) or y (a column), not {spec['axis']!r}",
              "remove 'axis' for a square window")
    return False


def _load_stages(doc, rep, path, ctype: ComponentType, fspec, tables,
                 lengths) -> dict[str, fusable_forms.Stage] | None:
    """A stencil's 'stages:' (fusable.py): name -> {dtype, radius, reads, value}, each a
    stencil over the inputs and the stages before it, with the type's border; None after
    reporting why one cannot be."""
    if "stages" not in fspec:
        return {}
    spec = _expect_map(doc, rep, path + ("stages",), fspec["stages"], "stages")
    int_params = _int_params(ctype) + lengths
    found: dict[str, fusable_forms.Stage] = {}
    for name, given in spec.items():
        where = path + ("stages", name)
        problem = name_problem(name, "stage name")
        taken = [*ctype.params, *ctype.inputs, *ctype.outputs, *tables,
                 *fusable_forms.port_names(list(ctype.inputs), list(ctype.outputs))]
        if problem is None and name in taken:
            problem = f"stage '{name}' has the name of a parameter, port or table of " \
                f"'{ctype.name}'"
        if problem is not None:
            rep.error(doc.key_pos(*path, "stages", name), f"fusable stages of "
                      f"'{ctype.name}': {problem}", "name a stage as a new local would be")
            return None
        sspec = _expect_map(doc, rep, where, given, "stage")
        _unknown_keys(doc, rep, where, sspec, STAGE_KEYS, "stage")
        dtype, value = sspec.get("dtype"), sspec.get("value")
        radius, reads = sspec.get("radius"), sspec.get("reads")
        # a generic type's element type, or the type its sums are kept in
        of_input = [f"{p}.{what}" for p in ctype.inputs for what in ("dtype", "sum_dtype")]
        if not _named(dtype, DTYPES) and dtype not in of_input:
            rep.error(doc.pos(*where, "dtype") if "dtype" in sspec else doc.key_pos(*where),
                      f"stage '{name}' of '{ctype.name}' needs 'dtype', one of "
                      f"{', '.join([*DTYPES, *of_input])}"
                      + (f", not {dtype!r}" if "dtype" in sspec else ""),
                      "the element type of the stage's values, e.g. dtype: int32")
            return None
        for key, what, least in (("radius", radius, 0), ("reads", reads, 1)):
            if (what is not None or key == "radius") and not _count(what, int_params, least):
                rep.error(doc.pos(*where, key) if key in sspec else doc.key_pos(*where),
                          f"stage '{name}' of '{ctype.name}': '{key}' must be a number "
                          f"({least} or more), an int parameter or an expression of them, "
                          f"not {what!r}", "e.g. radius: ksize // 2")
                return None
        if not isinstance(value, str) or not value.strip():
            rep.error(doc.pos(*where, "value") if "value" in sspec else doc.key_pos(*where),
                      f"stage '{name}' of '{ctype.name}' needs 'value': statements ending "
                      "in 'return ...;' for element (y, x, c) of the stage",
                      "e.g. value: \"return src(y, x - 1, c) + src(y, x + 1, c);\"")
            return None
        analysis = fusable_forms.analyse(value, "stencil", [*ctype.inputs, *found], [name],
                                         [*ctype.params, *lengths],
                                         arrays=[n for n, d in ctype.params.items()
                                                 if d.shape])
        _snippet_problems(doc, rep, where, ctype, value, analysis.problems)
        if analysis.problems or not _axis_ok(doc, rep, where, ctype, sspec):
            return None
        decl = fusable_forms.FusableDecl("stencil", value, analysis.tree, analysis.names,
                                         radius, fspec.get("border", "clamp"), reads,
                                         axis=sspec.get("axis"))
        found[name] = fusable_forms.Stage(name, dtype, decl)
    return found


def _count(value, int_params, least: int = 0) -> bool:
    """Whether value is a number (least or more), an int parameter or an expression of
    int parameters (a stencil's radius, its reads)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return value >= least
    if not isinstance(value, str):
        return False
    if _named(value, int_params):
        return True
    try:  # an expression of int parameters, e.g. 'ksize // 2'
        sizeexpr.parse(value, set(), set(int_params))
    except sizeexpr.SizeExprError:
        return False
    return True


def _load_tables(doc, rep, path, ctype: ComponentType,
                 fspec) -> dict[str, tuple[str, tuple[str, ...]]] | None:
    """A stencil's 'tables:' (name: 'function(parameter, ...)'), checked: each name new
    to the snippet, each function one of gpucompgen's table functions, each argument an
    int or float parameter; None after reporting why one cannot be."""
    if "tables" not in fspec:
        return {}
    spec = _expect_map(doc, rep, path + ("tables",), fspec["tables"], "tables")
    types = {p: d.type for p, d in ctype.params.items() if not d.shape}
    found = {}
    for name, text in spec.items():
        problem = name_problem(name, "table name")
        if problem is None and (name in ctype.params or name in ctype.inputs
                                or name in ctype.outputs):
            problem = f"table '{name}' has the name of a parameter or port of '{ctype.name}'"
        call = problem or fusable_forms.table_call(text, types)
        if isinstance(call, str):
            rep.error(doc.pos(*path, "tables", name), f"fusable tables of '{ctype.name}': "
                      f"{call}", f"e.g. tables: {{kx: 'gaussian_q8(ksize, sigma)'}}; table "
                      f"functions: {', '.join(fusable_forms.TABLES)}")
            return None
        found[name] = call
    return found
