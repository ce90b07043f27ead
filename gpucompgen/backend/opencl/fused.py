"""The OpenCL kernel of a group (passes/fuse.py): members' snippets composed and scheduled.

One readable file per group (a group may have one member: a lone component of a fusable
type runs the kernel generated from its form).  A header names the members; then, per
member in run order, its snippet as a ``static inline`` function computing one element
(y, x, c) of its output.  Around each function, each input port's accessor
``<port>(y, x, c)`` is a macro: the producing member's function when the producer is in
the group (index maps compose back to front, values apply front to back), else a load
from the group's input buffer.

Names.  Every identifier the generator itself makes starts with an underscore (``_m0_blur``,
``_in0``, ``_ARGS``, ``_y``, ``_row``, ``_reflect101``); model names (components, ports,
parameters) start with a letter, so the two never meet, whatever the model calls its
components.  Inside a member's function the snippet sees only its own language: y, x, c,
its ports' accessors and sizes, its parameters.

The schedule (what makes it fast; Halide's algorithm vs schedule, Intel's guide for CPU
OpenCL devices):

- Every size is a constant (the system fixed them at build time), every parameter a
  macro the program defines when it builds the kernel (-D, after --set; the model's
  values are the file's defaults), every function is visible and inlined: a chain of
  index maps folds to one index expression, a rule chosen by a parameter is chosen once.
  (A pointwise chain with Threshold's thresh_type a kernel argument took 3.05 ms a
  640x360 frame on PoCL, its selects keeping the row loop scalar; a constant: 0.28 ms.)
- Borders outside the hot path.  A stencil's reads outside its input follow its border
  rule (clamp, reflect101, reflect, constant; or the one a parameter picks by OpenCV's
  code, fixed at build time) in the accessor; where the group has stencils and no index
  map, each member has a second, interior version whose accessors read without any
  border rule, and the kernel runs it on the output elements whose every read is inside
  the frame (``margin``: the radii summed along the deepest path), the border version on
  the rest of the row.
- Channel-flat groups.  Where every member computes each channel alike (it reads inputs
  only as ``port(..., x + k, c)`` and uses x and c nowhere else) a frame of C channels
  is a row of W x C elements computed alike: the kernel stores one element at a time, a
  loop the compiler turns into vector loads and stores (a read k pixels away is k x C
  elements away).  Otherwise a work-item computes
  a pixel's channels together, one store statement a channel (the compiler turns the
  row loop into interleaved vector stores; it leaves a loop of vstore3 scalar).
- Rows together.  On a CPU device a work-item computes ROWS_TOGETHER rows of a stencil
  group's interior in one loop over x: their windows overlap, and the compiler loads the
  rows they share once and shares what the snippets compute from them alike (a 640x360
  frame, load 9 to 13: GaussianBlurGray k5 0.255 -> 0.144 ms, MedianBlurGray 0.100 ->
  0.064, MorphologyExGray open k3 0.247 -> 0.189).  The members' functions are
  always_inline: called that many times, PoCL otherwise kept them calls, and scalar.
  The rows' borders are computed a row at a time (one call site of the border version).
- Bounded compile time.  What the compiler is given follows the reads a kernel inlines
  with every loop unrolled (``unrolled_reads``: each member's ``reads_of``, a producer's
  counted at every read of its consumer), not the window: rows together and forced
  inline only where the rows' inlined bodies read at most MAX_UNROLLED_READS elements
  (and every window is at most MAX_TAPS_TOGETHER, 5x5, where rows together pay); a
  member's loops unrolled only where it reads at most MAX_UNROLLED_LOOPS.  A snippet that
  nests windows states its reads (MorphologyEx's opening: a window of windows).
- Work split from device facts (schedule()): work-groups cover ``tile`` whole rows.  On
  a CPU device a work-item takes whole rows, the work-group's items in turn: a CPU runs
  a work-group's items one after another on one core, so splitting a row among them
  only shortens the loop the compiler vectorizes (AVX-512 takes 64 to 256 bytes an
  iteration: a run of 80 pixels ran mostly in the scalar remainder; ErodeGray 0.076 ->
  0.036 ms a 640x360 frame, MedianBlurGray 0.158 -> 0.099).  The loop bounds are then
  constants.  On a GPU its block_y threads take the rows in turn and adjacent block_x
  threads adjacent elements (coalesced).
"""

from __future__ import annotations

import re

from ...ir import GroupNode
from ...model import DTYPES, Endpoint
from ...snippet import accessor_calls, is_name, is_shifted, uses_outside_calls

MAX_UNROLLED_CHANNELS = 4  # a pixel of at most this many channels: one store statement each
# On a CPU a work-item computes this many rows of a stencil group's interior in one loop, so
# that the compiler shares the reads their windows have in common (loads, and whatever the
# snippets compute from them alike: Erode's row minima), where every stencil member's
# window is at most MAX_TAPS_TOGETHER elements (5x5): beyond, what the rows share outgrows
# the registers (BlurGray k9 at 640x360: 0.71 ms a row at a time, 9.5 ms 4 rows together;
# k7 alike either way).
ROWS_TOGETHER = 4
MAX_TAPS_TOGETHER = 25
# What the compiler is given to inline and unroll, in input reads (unrolled_reads: the
# members' reads with their loops unrolled, a producer's counted at every read of its
# consumer): rows together, and the members' functions forced inline, where the rows'
# inlined bodies read at most this many elements (4 rows of a 5x5 window, 100, or of a 3x3
# opening's 9 x 9, 324); else one row, forced inline where that row's body stays within
# it.  Compile time follows the inlined reads, not the window: a 640x360
# frame, PoCL 3.0 (LLVM 14), build and first launch at load 6 to 7 (docs/benchmarks.md):
# 4 x 25 reads 1.4 to 2.2 s, 4 x 81 (an opening 3x3) 3.5 to 4.4 s, 4 x 225 (GaussianBlur
# k3 fused into an Erode) 6.3 s, 4 x 625 (an opening 5x5) 35 s and a kernel 36 times
# slower (1.85 -> 66 ms).
MAX_UNROLLED_READS = 400
# A member's loops are unrolled (#pragma unroll) where it reads at most this many
# elements with them unrolled; beyond, the compiler decides: a 31x31 Blur (961 reads) builds
# in about 9 s at load 7, an opening of 15x15 (50,625 reads) in 20 s unrolled (measured
# at merge), about 2 s not (and runs 8.7 s a 640x360 frame: a window of windows that
# large needs two passes).
MAX_UNROLLED_LOOPS = 1024

BORDER_RULES = {
    "reflect101": [
        "// OpenCV's BORDER_REFLECT_101 (gfedcb|abcdefgh|gfedcba) of position p in 0..n-1",
        "static inline int _reflect101(int p, const int n)",
        "{",
        "    if (n == 1)",
        "        return 0;",
        "    const int period = 2 * (n - 1);",
        "    p = (p < 0 ? -p : p) % period;",
        "    return p < n ? p : period - p;",
        "}",
        ""],
    "reflect": [
        "// OpenCV's BORDER_REFLECT (fedcba|abcdefgh|hgfedcb) of position p in 0..n-1",
        "static inline int _reflect(int p, const int n)",
        "{",
        "    const int period = 2 * n;",
        "    p = (p < 0 ? -p - 1 : p) % period;",
        "    return p < n ? p : period - 1 - p;",
        "}",
        ""],
    "clamp": [
        "// the nearest position in 0..n-1 (BORDER_REPLICATE)",
        "static inline int _clamp(const int p, const int n)",
        "{",
        "    return p < 0 ? 0 : p >= n ? n - 1 : p;",
        "}",
        ""],
}

# Built-in functions a snippet calls, as inline code the compiler sees through.  On a CPU
# device (PoCL) a call to the library's min(), max(), fabs(), fma() or convert_*_sat_rte()
# keeps the loop over a row from being vectorized: ErodeGray with min() took 2.8 ms a
# 640x360 frame, the same with these 0.05 ms.  Same results as the built-ins: fma stays
# fused (the compiler's own fma intrinsic), rounding is to nearest even, NaN converts to 0.
_SCALARS = ("uchar", "char", "ushort", "short", "uint", "int", "float")
_OVERLOADED = "static inline __attribute__((overloadable))"
HELPERS: dict[str, list[str]] = {
    "min": [f"{_OVERLOADED} {t} _min(const {t} a, const {t} b) {{ return a < b ? a : b; }}"
            for t in _SCALARS],
    "max": [f"{_OVERLOADED} {t} _max(const {t} a, const {t} b) {{ return a > b ? a : b; }}"
            for t in _SCALARS],
    "clamp": [f"{_OVERLOADED} {t} _clamp3(const {t} v, const {t} lo, const {t} hi) "
              "{ return v < lo ? lo : v > hi ? hi : v; }" for t in _SCALARS],
    "fabs": ["static inline float _fabs(const float v) { return v < 0.0f ? -v : v; }"],
    "fma": ["#ifdef __clang__",
            "#define _fma(a, b, c) __builtin_fmaf((a), (b), (c))",
            "#else",
            "#define _fma(a, b, c) fma((a), (b), (c))",
            "#endif"],
    "convert_uchar_sat_rte": [
        "#ifdef __clang__",
        "#define _rint(v) __builtin_rintf(v)",
        "#else",
        "#define _rint(v) rint(v)",
        "#endif",
        "static inline uchar _convert_uchar_sat_rte(float v)",
        "{",
        "    v = v >= 0.0f ? v : 0.0f;  /* NaN too */",
        "    return (uchar)_rint(v <= 255.0f ? v : 255.0f);",
        "}"],
}
HELPER_NAMES = {"min": "_min", "max": "_max", "clamp": "_clamp3", "fabs": "_fabs",
                "fma": "_fma", "convert_uchar_sat_rte": "_convert_uchar_sat_rte"}
_CALL = re.compile(r"//[^\n]*|/\*.*?\*/|\b(" + "|".join(HELPER_NAMES) + r")(?=\s*\()",
                   re.DOTALL)


def inline_builtins(body: str, used: set[str]) -> str:
    """The snippet with calls of HELPERS' built-ins renamed to the inline versions (words
    in comments left alone); adds the names it renamed to used."""
    def swap(m):
        if m.group(1) is None:
            return m.group(0)
        used.add(m.group(1))
        return HELPER_NAMES[m.group(1)]
    return _CALL.sub(swap, body)


def is_cpu(device) -> bool:
    """Whether to schedule for a CPU OpenCL device (PoCL, Intel's runtime), from its facts:
    a CPU keeps resident as many threads as one work-group holds (runtime/facts.py), a GPU
    thousands.  No facts, or the 'portable' profile (any OpenCL 1.2 device, which the
    default build runs on PoCL as often as on a GPU): the CPU schedule, correct on both."""
    from ...device import PROFILES

    if device is None or device == PROFILES["portable"]:
        return True
    return device.threads_per_compute_unit <= device.max_work_group_size


def schedule(device) -> str:
    """'runs' (a work-item whole rows) on CPUs, 'strided' on GPUs."""
    return "runs" if is_cpu(device) else "strided"


def kernel_name(group: GroupNode) -> str:
    """The entry point's name in the group's file (passes/fuse.py entry_name)."""
    return group.type.kernel_function if group.type is not None else group.name


def preferred_settings(group: GroupNode, device) -> tuple[int, int, int, int]:
    """(tile, block_x, block_y, block_z) the system prefers for the group's kernel."""
    from ...passes.fuse import group_gpu_decl

    return group_gpu_decl(device).prefer


def launch_geometry(group: GroupNode, tile: int, bx: int, by: int):
    """(global size, local size) of the group kernel's launch, as passes/lower.py makes it:
    work-groups cover whole rows of the output."""
    (out,) = group.outputs.values()
    return (bx, -(-out.data.height // tile) * by, 1), (bx, by, 1)


def group_of_one(ctype, params: dict, shapes: dict[str, tuple[int, int]], member: str = "m",
                 name: str = "only") -> GroupNode:
    """The group of one component (named member) of a fusable type, for ports of the
    given (height, width) sizes: what the generator writes for the operation alone (the
    tests and benchmarks/kernels.py run it)."""
    from ...ir import ComponentNode, Data, Port
    from ...runtime.sizes import Size

    def port(p, direction, d):
        h, w = shapes[p]
        return Port(p, direction, "gpu", d.dtype, d.channels,
                    Data(Size(h, w, d.channels), d.dtype))

    ins = {p: port(p, "in", d) for p, d in ctype.inputs.items()}
    outs = {p: port(p, "out", d) for p, d in ctype.outputs.items()}
    params = {**{p: d.default for p, d in ctype.params.items() if d.default is not None},
              **params}  # a parameter not given takes its default, as in a model
    node = ComponentNode(member, None, ins, outs, type=ctype, params=params, placement="gpu")
    return GroupNode(name, None, {f"{member}_{p}": q for p, q in ins.items()}, outs,
                     members=[node], feeds={f"{member}_{p}": Endpoint(member, p) for p in ins})


def launch_arguments(group: GroupNode, inputs: dict, output, tile: int) -> list:
    """The kernel arguments of a group of one (group_of_one) launched by hand, in the
    calling convention's order (convention.group_parameters): inputs by the member's port
    name, the output buffer and the tile.  The member's parameters are constants of the
    kernel text (its defaults: the values group_of_one was given)."""
    import numpy as np

    from .convention import group_parameters

    assert len(group.members) == 1, group.name
    args = []
    for p in group_parameters(group):
        if p.kind == "buffer":
            args.append(output if p.role == "output" else
                        inputs[group.feeds[p.port].port])
        else:
            args.append(np.int32(tile))
    return args


def channel_flat(group: GroupNode) -> bool:
    """Every member computes each channel alike, from the same channel of its inputs: a
    row of W pixels of C channels is W x C elements computed alike.  True where every
    member is pointwise or a stencil, all ports have the same size and channels, every
    read is port(..., ..., c) and the snippet uses x and c nowhere but in its reads."""
    channels = {p.channels for m in group.members for p in (*m.inputs.values(),
                                                              *m.outputs.values())}
    sizes = {(p.data.height, p.data.width) for m in group.members
             for p in (*m.inputs.values(), *m.outputs.values())}
    if len(channels) != 1 or len(sizes) != 1:
        return False
    for m in group.members:
        decl = m.type.fusable
        calls = accessor_calls(decl.tree, list(m.inputs))
        if any(len(args) != 3 or not is_name(args[2], "c") or not is_shifted(args[1], "x")
               for found in calls.values() for args in found):
            return False
        if uses_outside_calls(decl.tree, list(m.inputs), {"x", "c"}):
            return False
    return True


def margin(group: GroupNode) -> int | None:
    """How far from the output's edges every read of the group is in range without
    border rules (the stencil radii summed along the deepest path), or None where no
    interior fast path applies: no stencil, an index map (it moves positions), or ports
    of different sizes."""
    forms = {m.type.fusable.form for m in group.members}
    if "stencil" not in forms or "index_map" in forms:
        return None
    sizes = {(p.data.height, p.data.width) for m in group.members
             for p in (*m.inputs.values(), *m.outputs.values())}
    if len(sizes) != 1:
        return None
    depth: dict[str, int] = {}
    for m in reversed(group.members):
        consumers = [depth[e.target.component] for e in group.internal
                     if e.source.component == m.name]
        depth[m.name] = _radius(m) + max(consumers, default=0)
    return max(depth.values())


def _radius(m) -> int:
    return m.type.fusable.radius_of(m.params)


def unrolled_reads(group: GroupNode) -> int:
    """Input elements one output element of the group reads with every member inlined and
    its loops unrolled: the root's reads, each read of a producer in the group counted as
    that producer's own (an upper bound where a member reads several producers)."""
    producers: dict[str, list[str]] = {}
    for e in group.internal:
        producers.setdefault(e.target.component, []).append(e.source.component)
    count: dict[str, int] = {}
    for m in group.members:  # in run order: producers first
        inner = max((count[p] for p in producers.get(m.name, ())), default=1)
        count[m.name] = m.type.fusable.reads_of(m.params) * inner
    return count[group.root.name]


def rows_together(group: GroupNode, how: str) -> int:
    """How many rows of the group's interior a work-item computes in one loop: ROWS_TOGETHER
    on a CPU ('runs') for a stencil group of windows of at most MAX_TAPS_TOGETHER elements
    whose rows' inlined bodies read at most MAX_UNROLLED_READS elements, else 1."""
    if how != "runs" or margin(group) is None:
        return 1
    small = all(m.type.fusable.taps(m.params) <= MAX_TAPS_TOGETHER for m in group.members)
    fits = ROWS_TOGETHER * unrolled_reads(group) <= MAX_UNROLLED_READS
    return ROWS_TOGETHER if small and fits else 1


def forced_inline(group: GroupNode, how: str) -> bool:
    """Whether the members' functions are always_inline: where the body a work-item's
    loop inlines, its rows together, reads at most MAX_UNROLLED_READS elements."""
    return rows_together(group, how) * unrolled_reads(group) <= MAX_UNROLLED_READS


def group_kernel(group: GroupNode, header: str, device=None) -> str:
    from .convention import group_constants, group_parameters

    params = group_parameters(group)
    constants = group_constants(group)
    index = {m.name: i for i, m in enumerate(group.members)}
    names = _param_names(params)
    names.update({p.param: p.name for p in constants})  # 'member.param' -> its macro
    decls = [_declaration(p, names[p.name]) for p in params if p.role != "tile"]
    args = [names[p.name] for p in params if p.role != "tile"]
    root = group.root
    (out_name, out_port), = group.outputs.items()
    edge = margin(group)
    stencils = any(m.type.fusable.form == "stencil" for m in group.members)
    # flat stencils need the interior path: border rules apply to pixel positions
    flat = channel_flat(group) and (edge is not None or not stencils)
    lines = [f"// {header}",
             *_comment(f"Group {group.name}: one kernel for "
                       + ", ".join(f"{m.name} ({m.type.name}, {m.type.fusable.form})"
                                   for m in group.members) + "."),
             (f"// It computes {root.name}.{out_name} from the group's inputs directly: no "
              "buffers between members."),
             "// Each member's snippet is a function of the element (y, x, c) it computes;",
             "// an input read <port>(y, x, c) calls the producing member, or loads from a",
             "// group input.  Sizes are constants: the system fixed them at build time.",
             *_comment("Kernel arguments, in the calling convention's order: "
                       + ", ".join(f"{names[p.name]} = {p.name}" for p in params
                                   if p.role != "tile") + "."),
             "",
             *_constants(group, constants),
             *[line for rule, text in BORDER_RULES.items()
               if any(m.type.fusable.form == "stencil"
                      and m.type.fusable.border_of(m.params) == rule
                      for m in group.members) for line in text],
             "#define _PARAMS \\",
             *(f"    {d}, \\" if i < len(decls) - 1 else f"    {d}" for i, d in enumerate(decls)),
             "",
             "#define _ARGS \\",
             *(f"    {a}, \\" if i < len(args) - 1 else f"    {a}" for i, a in enumerate(args)),
             ""]
    feeds = {end: port for port, end in group.feeds.items()}
    producer = {e.target: e.source for e in group.internal}
    # (interior, channel-flat) versions of every member: without stencils one version,
    # with them a border version in pixel coordinates and an interior one
    versions = [(False, flat)] if edge is None else [(False, False), (True, flat)]
    used: set[str] = set()
    members = []
    # forced inline where the bodies stay small (see _member)
    forced = forced_inline(group, schedule(device))
    for interior, flat_version in versions:
        for m in group.members:
            members += _member(m, feeds, producer, index, names, flat_version, interior,
                               used, inline=forced)
    helpers = [line for name in HELPERS if name in used for line in HELPERS[name]]
    if helpers:
        lines += ["// built-ins the snippets call, inline (see fused.py: HELPERS)", *helpers, ""]
    lines += members
    lines += _kernel(group, out_name, out_port, names, flat, edge, schedule(device))
    return "\n".join(lines)


def _param_names(params) -> dict[str, str]:
    """Each kernel parameter's name in the kernel text: generator namespace."""
    names, inputs = {}, 0
    for p in params:
        if p.role == "input":
            names[p.name] = f"_in{inputs}"
            inputs += 1
        elif p.role == "output":
            names[p.name] = "_out"
        else:
            names[p.name] = "_tile"
    return names


def _constants(group: GroupNode, constants) -> list[str]:
    """The members' parameters as macros: the program builds the file with -D NAME=VALUE
    (runtime.build_program's defines, after --set); the model's values are the defaults of
    a build without them (tests, tune, benchmarks)."""
    from ...convention import c_literal

    if not constants:
        return []
    lines = _comment("Parameters: constants of the build, so that the compiler folds them "
                     "(a rule chosen by a parameter is chosen once, not per element).  The "
                     "program builds this file with -D NAME=VALUE, its values after --set; "
                     "below, the model's values, for a build without them.")
    for p in constants:
        member, pname = p.param.split(".", 1)
        value = group.member(member).params[pname]
        lines += [f"#ifndef {p.name}", f"#define {p.name} {c_literal(value, p.c_type)}",
                  "#endif"]
    return [*lines, ""]


def _declaration(p, name: str) -> str:
    if p.kind == "buffer":
        const = "const " if p.role == "input" else ""
        return f"__global {const}{p.c_type} *restrict {name}"
    return f"const {p.c_type} {name}"


def _function(name: str, index, interior: bool) -> str:
    """The generated function of member name: its interior version ends '_in'.  '_f',
    not '_m' (the members' parameters): member 'thresh' of a type whose parameter is
    'thresh' gets _f0_thresh and _m0_thresh, never one name for both."""
    return f"_f{index[name]}_{name}" + ("_in" if interior else "")


def _member(m, feeds: dict[Endpoint, str], producer: dict[Endpoint, Endpoint], index,
            names, flat: bool, interior: bool, used: set[str], inline: bool) -> list[str]:
    """A member's snippet as a function, between the macros of its input accessors.

    inline: forced inline (always_inline), which the row loop needs to vectorize: PoCL's
    inliner left WarpAffine's bilinear snippet (cost 410 > 337) a call per element, 29 ms
    a 320x240 frame, 0.8 ms inlined, and left stencil members called once per row of the
    rows-together loop (about 20x slower).  Not a group beyond MAX_UNROLLED_READS
    (forced_inline): compile time exploded.  A member's loops are unrolled where it reads
    at most MAX_UNROLLED_LOOPS elements so."""
    decl = m.type.fusable
    ctype = DTYPES[next(iter(m.outputs.values())).dtype][1]
    what = "interior: no border rule" if interior else "every element"
    border = decl.border_of(m.params) if decl.form == "stencil" else None
    lines = [f"// {m.name}: {m.type.name} ({decl.form}"
             + (f", radius {decl.radius}, border {border}" if border else "") + f"); {what}"]
    macros = []
    for pname, port in m.inputs.items():
        src = producer.get(Endpoint(m.name, pname))
        h, w = port.data.height, port.data.width
        yy, xx = "(y_)", "(x_)"
        outside_zero = border == "constant" and not interior
        if border and border != "constant" and not interior:
            yy, xx = f"_{border}((y_), {h})", f"_{border}((x_), {w})"
        if flat and port.channels > 1:
            # x is the element's place in the row of W x C: a read dx pixels away is
            # dx x C elements away, the same channel
            xx = f"(x + ((x_) - x) * {port.channels})"
        if src is not None:
            body = f"{_function(src.component, index, interior)}(_ARGS, {yy}, {xx}, (c_))"
        else:
            buf = names[feeds[Endpoint(m.name, pname)]]
            if flat:
                body = f"{buf}[(size_t){yy} * {w * port.channels} + {xx}]"
            else:
                body = (f"{buf}[{port.channels} * ((size_t){yy} * {w} + {xx}) + (c_)]"
                        if port.channels > 1 else f"{buf}[(size_t){yy} * {w} + {xx}]")
        if outside_zero:  # BORDER_CONSTANT: a read outside the input is 0
            body = f"((unsigned)(y_) < {h}u && (unsigned)(x_) < {w}u ? {body} : 0)"
        macros.append(pname)
        lines.append(f"#define {pname}(y_, x_, c_) {body}")
    tables, locals_ = _tables(m, index[m.name])
    if not interior:  # once, before the member's first version
        lines[1:1] = tables
    attribute = " __attribute__((always_inline))" if inline else ""
    lines.append(f"static inline{attribute} {ctype} {_function(m.name, index, interior)}(_PARAMS, "
                 "const int y, const int x, const int c)")
    lines.append("{")
    lines += _port_constants(m)
    lines += locals_
    for pname, pdecl in m.type.params.items():
        c = "float" if pdecl.element == "float" else "int"
        if pdecl.shape:
            continue
        if pname in decl.radius_names():
            # the window is fixed at build time (the interior's margin is): a constant, so
            # that the compiler unrolls a loop over it
            value = m.params[pname]
            lines.append(f"    const {c} {pname} = "
                         f"{_float_literal(value) if c == 'float' else int(value)};")
            continue
        lines.append(f"    const {c} {pname} = {names[f'{m.name}.{pname}']};")
    # printed from the parsed snippet; built-in calls swapped for their inline versions
    unroll = decl.reads_of(m.params) <= MAX_UNROLLED_LOOPS
    for line in inline_builtins("\n".join(decl.lines()), used).splitlines():
        if unroll and line.lstrip().startswith("for ("):
            # sizes and a stencil's radius are constants: a loop over a window unrolls
            # (PoCL left BoxBlur's 3x3 loop rolled: 9 ms a 1280x720 frame, unrolled 0.6)
            lines.append(f"    {line[:len(line) - len(line.lstrip())]}#pragma unroll")
        lines.append(f"    {line}".rstrip())
    lines.append("}")
    lines += [f"#undef {p}" for p in macros]
    lines.append("")
    return lines


def _port_constants(m) -> list[str]:
    """What the snippet is given of each port: its sizes (its channels where named), and its element type and that
    type's least and greatest values where the snippet names them (src_t, src_min)."""
    names, lines = m.type.fusable.names, []
    for pname, port in {**m.inputs, **m.outputs}.items():
        lines.append(f"    const int {pname}_height = {port.data.height}, "
                     f"{pname}_width = {port.data.width};")
        if names.get(f"{pname}_channels") == "size":  # only where named (InRange's)
            lines.append(f"    const int {pname}_channels = {port.channels};")
        ctype = DTYPES[port.dtype][1]
        if names.get(f"{pname}_t") == "type":
            lines.append(f"    typedef {ctype} {pname}_t;")
        limits = [f"{pname}_{end} = {_limit(port.dtype, end)}" for end in ("min", "max")
                  if names.get(f"{pname}_{end}") == "limit"]
        if limits:
            lines.append(f"    const {ctype} {', '.join(limits)};")
    return lines


def _limit(dtype: str, end: str) -> str:
    """The least ('min') or greatest ('max') value of an element type, as a C literal."""
    import numpy as np

    if dtype == "float32":
        return ("-" if end == "min" else "") + _float_literal(np.finfo(np.float32).max)
    info = np.iinfo(DTYPES[dtype][0])
    value = int(info.min if end == "min" else info.max)
    if value == -(1 << 31):
        return "(-2147483647 - 1)"
    return f"{value}u" if value >= 1 << 31 else str(value)


def _tables(m, i: int) -> tuple[list[str], list[str]]:
    """A member's arrays: its array parameters and the tables its stencil computes from
    parameters, as program-scope __constant tables and the lines of its function that
    name them (and the arrays' lengths the snippet names)."""
    decl = m.type.fusable
    arrays = {p: (d.element, m.params[p]) for p, d in m.type.params.items() if d.shape}
    tables = decl.tables_of(m.params) if decl.form == "stencil" else {}
    arrays.update((t, ("int", v)) for t, v in tables.items())
    program = [line for p, (element, v) in arrays.items()
               for line in _constant_table(f"_m{i}_{p}", element, v)]
    local = []
    for pname, (element, value) in arrays.items():
        # the snippet reads the program's table by the parameter's (or table's) name
        c = "float" if element == "float" else "int"
        inner = "".join(f"[{d}]" for d in _dims(value)[1:])
        local.append(f"    __constant const {c} (*{pname}){inner} = _m{i}_{pname};" if inner
                     else f"    __constant const {c} *{pname} = _m{i}_{pname};")
    lengths = {n: v for n, v in decl.lengths_of(m.params).items() if n in decl.names}
    if lengths:
        local.append("    const int " + ", ".join(f"{n} = {v}" for n, v in lengths.items())
                     + ";")
    return program, local


def _dims(value) -> list[int]:
    """The lengths of a (rectangular) nested tuple, outermost first."""
    dims = []
    while isinstance(value, tuple):
        dims.append(len(value))
        value = value[0] if value else None
    return dims


def _constant_table(name: str, element: str, value) -> list[str]:
    """An array parameter's value as a program-scope __constant table, 12 values a line
    (floats printed so that they read back as the same float32)."""
    c = "float" if element == "float" else "int"

    def flat(v):
        return [x for item in v for x in flat(item)] if isinstance(v, tuple) else [v]

    numbers = [str(int(v)) if c == "int" else _float_literal(v) for v in flat(value)]
    dims = "".join(f"[{d}]" for d in _dims(value))
    rows = [", ".join(numbers[i:i + 12]) for i in range(0, len(numbers), 12)]
    return [f"__constant {c} {name}{dims} = {{",
            *(f"    {r}," if i < len(rows) - 1 else f"    {r}" for i, r in enumerate(rows)),
            "};"]


def _float_literal(v: float) -> str:
    """A finite number as a C float literal that reads back as its float32 ('3.0f',
    '0.1f', '1e+30f'): 9 significant digits round-trip a float32."""
    text = f"{float(v):.9g}"
    return (text if any(ch in text for ch in ".e") else text + ".0") + "f"


def _kernel(group: GroupNode, out_name: str, out_port, names, flat: bool,
            edge: int | None, how: str) -> list[str]:
    """The kernel: rows of the output; the row's elements split among block_x threads."""
    index = {m.name: i for i, m in enumerate(group.members)}
    root = group.root
    channels = out_port.channels
    out_c = DTYPES[out_port.dtype][1]
    h, w = out_port.data.height, out_port.data.width
    per_row = w * channels if flat else w
    stride = w * channels

    def store(fn: str, pixel: bool = False) -> list[str]:
        """The statements storing element (or pixel) _x of the row."""
        call = f"{fn}(_ARGS, _y, _x, {{c}})"
        if flat and pixel and channels > 1:  # an element of the flat row, by pixel
            return [f"_row[_x] = {fn}(_ARGS, _y, _x / {channels}, _x % {channels});"]
        if flat or channels == 1:
            return ["_row[_x] = " + call.format(c=0) + ";"]
        if channels <= MAX_UNROLLED_CHANNELS:
            # one store a channel, not one vstoreN a pixel: PoCL vectorizes the row loop
            # of these (interleaved stores) and not of a vstore3 (FlipHorizontal on RGB:
            # 0.34 ms a 640x360 frame with vstore3, 0.10 ms so)
            return [f"_row[{channels} * _x + {c}] = " + call.format(c=c) + ";"
                    for c in range(channels)]
        return [f"for (int _c = 0; _c < {channels}; _c++)",
                f"    _row[{channels} * _x + _c] = " + call.format(c="_c") + ";"]

    def block(head: str, fn: str, depth: int, pixel: bool = False,
              rows: int = 1) -> list[str]:
        """head (a loop or a branch) over the store statements, at depth levels: of row
        _y, and of the rows - 1 next ones (_y + r, r rows further in the output)."""
        pad, body = "    " * depth, store(fn, pixel)
        body += [b.replace("_row[", f"_row[{r * stride} + ").replace("(_ARGS, _y,",
                                                                     f"(_ARGS, _y + {r},")
                 for r in range(1, rows) for b in body]
        if len(body) == 1:
            return [pad + head, f"{pad}    {body[0]}"]
        return [f"{pad}{head} {{", *(f"{pad}    {b}" for b in body), pad + "}"]

    border = _function(root.name, index, False)
    inner = _function(root.name, index, True)
    if flat:
        what = f"{channels} channel{'s' if channels > 1 else ''} as {per_row} elements a row"
    elif channels == 1:
        what = "one channel"
    else:
        what = f"{channels} channels a pixel"
    split = ("its threads take them in turn, each a whole row (a CPU runs a work-group's "
             "threads one after another: a row is the longest loop, which the compiler "
             "vectorizes)" if how == "runs" else
             "its block_y threads take them in turn, its block_x threads adjacent elements "
             "of the row, in turn")
    lines = _comment(f"{h} rows of {w} pixels, {what}.  Work-group g computes the rows "
                     f"[g * tile, g * tile + tile); {split}.")
    if edge is not None:
        lines += _comment(f"Elements {edge} or more from every edge read inside the frame: "
                          "the interior version, without border rules, computes them.")
    together = rows_together(group, how)
    if together > 1:
        lines += _comment(f"A work-item computes {together} interior rows in one loop: the "
                          "compiler shares the reads their windows have in common.")
    lines += [
        f"__kernel void {kernel_name(group)}(_PARAMS, const int _tile)",
        "{",
        "    const int _y0 = get_group_id(1) * _tile;",
        f"    const int _y1 = min(_y0 + _tile, {h});"]
    k = channels if flat else 1  # elements a pixel
    if how == "runs":
        loop = "for (int _x = {a}; _x < {b}; _x++)"
        # the left border, the interior and the right border of a row: on a row narrower
        # than two borders, the left border is the whole row
        left = min(edge or 0, w)
        right = max(left, w - (edge or 0))

        def row(depth: int, rows: int = 1) -> list[str]:
            """Row _y (and the rows - 1 next ones, all interior rows) at depth levels."""
            if edge is None:
                return block(loop.format(a=0, b=per_row), border, depth)
            if rows > 1:
                # the rows' borders a row at a time (a few columns each: one call site of
                # the border version, not one a row), then their interiors together
                pad = "    " * depth
                ends = [line.replace("_row[", f"_row[_r * {stride} + ").replace(
                    "(_ARGS, _y,", "(_ARGS, _y + _r,") for line in [
                        *block(loop.format(a=0, b=left * k), border, depth + 1, True),
                        *block(loop.format(a=right * k, b=per_row), border, depth + 1, True)]]
                return [f"{pad}for (int _r = 0; _r < {rows}; _r++) {{", *ends, pad + "}",
                        *block(loop.format(a=left * k, b=right * k), inner, depth, False,
                               rows)]
            parts = [*block(loop.format(a=0, b=left * k), border, depth, True),
                     *block(loop.format(a=left * k, b=right * k), inner, depth),
                     *block(loop.format(a=right * k, b=per_row), border, depth, True)]
            pad = "    " * (depth - 1)
            return [f"{pad}if (_y >= {edge} && _y < {h - edge}) {{", *parts,
                    f"{pad}}} else {{",
                    *block(loop.format(a=0, b=per_row), border, depth, True), f"{pad}}}"]

        out_row = f"__global {out_c} *_row = _out + (size_t)_y * {stride};"
        lines += ["    const int _k = get_local_id(1) * get_local_size(0) + get_local_id(0);",
                  "    const int _n = get_local_size(0) * get_local_size(1);"]
        if together == 1:
            lines += ["    for (int _y = _y0 + _k; _y < _y1; _y += _n) {", f"        {out_row}",
                      *row(3 if edge is not None else 2)]
        else:
            t = together
            lines += [f"    for (int _p = _y0 + {t} * _k; _p < _y1; _p += {t} * _n) {{",
                      f"        if (_p >= {edge} && _p + {t - 1} < min(_y1, {h - edge})) {{",
                      f"            // rows _p to _p + {t - 1}, every one in the interior",
                      "            const int _y = _p;", f"            {out_row}",
                      *row(3, t),
                      "            continue;",
                      "        }",
                      f"        for (int _y = _p; _y < min(_p + {t}, _y1); _y++) {{",
                      f"            {out_row}",
                      *row(4),
                      "        }"]
    else:
        lines += ["    const int _nx = get_local_size(0);",
                  "    for (int _y = _y0 + get_local_id(1); _y < _y1; _y += get_local_size(1)) {",
                  f"        __global {out_c} *_row = _out + (size_t)_y * {stride};"]
        loop = f"for (int _x = get_local_id(0); _x < {per_row}; _x += _nx)"
        if edge is None:
            lines += block(loop, border, 2)
        else:
            lines += [f"        const bool _inside = _y >= {edge} && _y < {h - edge};",
                      "        " + loop + " {",
                      *block(f"if (_inside && _x >= {edge * k} && _x < {(w - edge) * k})",
                             inner, 3),
                      *block("else", border, 3, True),
                      "        }"]
    lines += ["    }", "}", ""]
    return lines


def _comment(text: str, width: int = 92) -> list[str]:
    """A '//' comment over lines of at most width characters."""
    import textwrap

    return ["// " + line for line in textwrap.wrap(text, width - 3, break_on_hyphens=False)]
