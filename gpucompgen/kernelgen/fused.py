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
- Staged pieces (staged_pieces()).  A type's stages (fusable.Stage: Blur's row sums,
  MorphologyEx's inner erosion) are members of their own before it (expand()).  A
  stencil piece read by a stencil, whose reads through it inline would exceed
  MIN_STAGED_READS an output element, is computed once a tile instead: on a CPU each
  work-item takes strips of rows in turn, each strip in tiles of columns (whole rows
  where they fit in STAGED_BYTES); per tile it computes each staged piece over the tile
  and its halo (the readers' radii, along y and x, inside the frame) into an array of its
  own, then the root from them (a Blur of 31x31: 85 -> 2.1 ms a 640x360 frame; an opening
  of 5x5: 1.9 -> 0.66).  No barrier, no __local (with them PoCL took 30-100 s to compile
  an opening); the border versions are calls, not inlined (28 s -> 1.8 s to compile).
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
from dataclasses import dataclass, replace

from ..fusable import unrolled_calls
from ..ir import GroupNode
from ..model import DTYPES, Endpoint
from ..snippet import accessor_calls, is_name, is_shifted, uses_outside_calls
from ..snippet.printer import names_in, print_lines
from ..snippet.prune import prune

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
# The staged schedule (staged_pieces): a stage of a stencil (fusable.Stage), or a stencil
# member, read by a stencil whose inlined reads of it would exceed this many input
# elements an output element is computed once a tile into an array instead.  A 640x360
# frame, PoCL, load 3 to 5 (docs/benchmarks.md): BlurGray k5 (25 reads) 0.163 ms inline,
# 0.174 staged; k7 (49) 0.345 -> 0.239; k15 (225) 2.07 -> 0.66; k31 (961) 85 -> 2.1; an
# opening 3x3 (81) 0.185 -> 0.197, of 5x5 (625) 1.87 -> 0.67.
MIN_STAGED_READS = 25
# The tiles of output a staged kernel computes a piece at a time (rows, and columns: the
# whole row where it fits), the one whose staged pieces, with their halos, compute the
# fewest elements an output element, among those whose arrays take at most STAGED_BYTES
# (a work-item's own: a CPU keeps them in its cache).
STRIP_ROWS = (32, 16, 8)
TILE_COLUMNS = (512, 256, 128, 64, 32, 16)
STAGED_BYTES = 16 << 10  # 64 KiB crashed PoCL workers now and then (3-channel Blur, openings)

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
    from ..device import PROFILES

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
    from ..passes.fuse import group_gpu_decl

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
    from ..ir import ComponentNode, Data, Port
    from ..runtime.sizes import Size

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

    from ..c_convention import group_parameters

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
        # a read with a fill value tests pixel positions: a stencil's interior version
        # has none to test (flat), an index map's only version would
        if any(not is_name(args[2], "c") or not is_shifted(args[1], "x")
               or len(args) == 4 and decl.form != "stencil"
               for found in calls.values() for args in found):
            return False
        if uses_outside_calls(decl.tree, list(m.inputs), {"x", "c"}):
            return False
        if guarded_ports(m):  # its reads clamp pixel positions
            return False
    return True


def margin(group: GroupNode, staged: frozenset = frozenset()) -> int | None:
    """How far from the output's edges every read of the group is in range without
    border rules (the stencil radii summed along the deepest path; a member's stages
    count as members), or None where no interior fast path applies: no stencil, an
    index map (it moves positions), or ports of different sizes.  With staged pieces
    (stages computed into local memory first) the margin of the root's own pass: a read
    of a staged piece is a load."""
    group = expand(group)[0]
    forms = {m.type.fusable.form for m in group.members}
    if "stencil" not in forms or "index_map" in forms:
        return None
    sizes = {(p.data.height, p.data.width) for m in group.members
             for p in (*m.inputs.values(), *m.outputs.values())}
    if len(sizes) != 1:
        return None
    return max(_edges(group, staged)[group.root.name])


def _edges(group: GroupNode, staged: frozenset) -> dict[str, tuple[int, int]]:
    """Each piece's margins along y and x computed where it stands (an expanded group):
    its radii plus the largest margins of the producers it inlines (a staged producer
    is a load)."""
    edge: dict[str, tuple[int, int]] = {}
    for m in group.members:  # in run order: producers first
        inlined = [edge[e.source.component] for e in group.internal
                   if e.target.component == m.name and e.source.component not in staged]
        ry, rx = _radii(m)
        edge[m.name] = (ry + max((e[0] for e in inlined), default=0),
                        rx + max((e[1] for e in inlined), default=0))
    return edge


def _radius(m) -> int:
    return m.type.fusable.radius_of(m.params)


def _radii(m) -> tuple[int, int]:
    """A piece's window radius along y and along x."""
    return m.type.fusable.radii_of(m.params)


def unrolled_reads(group: GroupNode, staged: frozenset = frozenset(),
                   root: str | None = None) -> int:
    """Input elements one output element of the group (of piece root) reads with every
    member (and stage) inlined and its loops unrolled: the root's reads, each read of a
    producer in the group counted as that producer's own (an upper bound where a member
    reads several producers), a read of a staged piece as one load."""
    group = expand(group)[0]
    producers: dict[str, list[str]] = {}
    for e in group.internal:
        producers.setdefault(e.target.component, []).append(e.source.component)
    count: dict[str, int] = {}
    for m in group.members:  # in run order: producers first
        inner = max((1 if p in staged else count[p] for p in producers.get(m.name, ())),
                    default=1)
        count[m.name] = member_reads(m) * inner
    return count[root or group.root.name]


def rows_together(group: GroupNode, how: str, staged: frozenset = frozenset(),
                  root: str | None = None) -> int:
    """How many rows of the group's interior (of piece root's pass) a work-item computes
    in one loop: ROWS_TOGETHER on a CPU ('runs') for a stencil group of windows of at
    most MAX_TAPS_TOGETHER elements whose rows' inlined bodies read at most
    MAX_UNROLLED_READS elements, else 1."""
    if how != "runs" or margin(group) is None:
        return 1
    small = all(m.type.fusable.taps(m.params) <= MAX_TAPS_TOGETHER
                for m in _inlined(expand(group)[0], staged, root))
    fits = ROWS_TOGETHER * unrolled_reads(group, staged, root) <= MAX_UNROLLED_READS
    return ROWS_TOGETHER if small and fits else 1


def _inlined(group: GroupNode, staged: frozenset, root: str | None) -> list:
    """The pieces (of an expanded group) that piece root's pass computes inline: root
    and the producers it reaches through no staged piece."""
    root = root or group.root.name
    found, todo = {root}, [root]
    while todo:
        name = todo.pop()
        for e in group.internal:
            if e.target.component == name and e.source.component not in staged | found:
                found.add(e.source.component)
                todo.append(e.source.component)
    return [m for m in group.members if m.name in found]


def forced_inline(group: GroupNode, how: str, staged: frozenset = frozenset()) -> bool:
    """Whether the members' functions are always_inline: where the body a work-item's
    loop inlines, its rows together, reads at most MAX_UNROLLED_READS elements (in every
    pass, where pieces are staged)."""
    return all(rows_together(group, how, staged, r) * unrolled_reads(group, staged, r)
               <= MAX_UNROLLED_READS for r in [*sorted(staged), None])


# -- stages (fusable.Stage) and the staged schedule ----------------------------------------

def staged_pieces(group: GroupNode, how: str) -> tuple[frozenset, tuple[int, int]]:
    """The pieces of the (expanded) group that the kernel computes first, a tile at a
    time, into arrays its readers then read, and the tile (rows, columns) of output: a
    stencil piece reading more than one element, read by a stencil whose reads of it,
    inlined, would read more than MIN_STAGED_READS input elements an output element (it
    is then computed once a tile, its halo included, not at every read), where the
    arrays fit in STAGED_BYTES.  None on a GPU ('strided') yet, nor where the group has
    no interior."""
    if how != "runs" or margin(group) is None:
        return frozenset(), 0
    group = expand(group)[0]
    staged: set[str] = set()
    for m in group.members:  # producers first: a staged producer is a load to the next
        consumers = [group.member(e.target.component) for e in group.internal
                     if e.source.component == m.name]
        inline = max((member_reads(c) for c in consumers
                      if c.type.fusable.form == "stencil" and _radius(c) > 0), default=0)
        own = unrolled_reads(group, frozenset(staged), m.name)
        if m.type.fusable.form == "stencil" and own > 1 and inline * own > MIN_STAGED_READS:
            staged.add(m.name)
    if not staged:
        return frozenset(), (0, 0)
    halo = _halos(group)
    budget = STAGED_BYTES
    (port,) = group.outputs.values()
    w = port.data.width
    best = None
    for rows, cols in [(r, c) for r in STRIP_ROWS for c in (w, *TILE_COLUMNS) if c <= w]:
        size = sum((rows + 2 * halo[n][0]) * (cols + 2 * halo[n][1]) * _pixel_bytes(
            group.member(n)) for n in staged)
        # each staged piece's elements computed an output element: the halo's share
        work = sum((rows + 2 * halo[n][0]) * (cols + 2 * halo[n][1]) for n in staged) \
            / (rows * cols)
        if size <= budget and (best is None or work < best[0]):
            best = (work, (rows, cols))
    return (frozenset(staged), best[1]) if best else (frozenset(), (0, 0))


def _halos(group: GroupNode) -> dict[str, tuple[int, int]]:
    """How many rows and columns beyond a tile of output each piece (of an expanded
    group) is read at: its consumers' radii summed along the longest path to the root."""
    halo = {group.root.name: (0, 0)}
    for m in reversed(group.members[:-1]):
        reads = [(_radii(group.member(e.target.component)), halo[e.target.component])
                 for e in group.internal if e.source.component == m.name]
        halo[m.name] = (max((r[0] + h[0] for r, h in reads), default=0),
                        max((r[1] + h[1] for r, h in reads), default=0))
    return halo


def _pixel_bytes(m) -> int:
    (port,) = m.outputs.values()
    return port.channels * DTYPES[port.dtype][2]


def _staged_kernel(whole: GroupNode, group: GroupNode, out_port, flat: bool, how: str,
                   staged: frozenset, tile: tuple[int, int],
                   slots: dict[str, tuple[int, int]]) -> list[str]:
    """The kernel of a group with staged pieces (staged_pieces): a work-group's rows in
    tiles of tile = (rows, columns) of output, the work-group's items taking its strips
    of rows in turn; per tile, each staged piece computed over what its readers read (the
    tile and its halo, inside the frame) into a work-item's own array, then the root's
    tile from them.  A CPU runs a work-group's items one after another on one core: an
    item's own arrays need no barrier, and stay in its cache (with barriers between
    passes, PoCL took 30 to 100 s to compile an opening of 5x5 for a work-group size)."""
    index = {m.name: i for i, m in enumerate(group.members)}
    h, w = out_port.data.height, out_port.data.width
    edges, halo = _edges(group, staged), _halos(group)
    rows_, cols = tile
    args = "_ARGS, _LARGS"
    lines = _comment(
        f"{h} rows of {w} pixels.  Work-group g computes the rows [g * tile, g * tile + "
        f"tile), in strips of {rows_} rows that its threads take in turn, each strip in "
        f"tiles of {cols} columns: first "
        + ", then ".join(f"{n} over the tile and {halo[n][0]} rows and {halo[n][1]} "
                         f"columns around it (inside the frame) into the thread's array _s{j}"
                         for n, (j, _) in slots.items())
        + f", then {group.root.name} from them: each computed once, not at every read of "
        "it.")
    lines += [f"__kernel void {kernel_name(whole)}(_PARAMS, const int _tile)", "{"]
    for n, (j, lw) in slots.items():
        m = group.member(n)
        (port,) = m.outputs.values()
        lines.append(f"    {DTYPES[port.dtype][1]} _s{j}[{(rows_ + 2 * halo[n][0]) * lw}"
                     f"{f' * {port.channels}' if port.channels > 1 else ''}];  // "
                     f"{rows_} + 2 x {halo[n][0]} rows of {cols} + 2 x {halo[n][1]} pixels "
                     f"of {n}")
    lines += ["    const int _y0 = get_group_id(1) * _tile;",
              f"    const int _y1 = min(_y0 + _tile, {h});",
              "    const int _k = get_local_id(1) * get_local_size(0) + get_local_id(0);",
              "    const int _n = get_local_size(0) * get_local_size(1);",
              f"    for (int _ys = _y0 + {rows_} * _k; _ys < _y1; _ys += {rows_} * _n)",
              f"    for (int _xs = 0; _xs < {w}; _xs += {cols}) {{",
              f"        const int _ye = min(_ys + {rows_}, _y1), _xe = min(_xs + {cols}, {w});"]
    for n, (j, _) in slots.items():
        hy, hx = halo[n]
        lines.append(f"        const int _a{j} = max(_ys - {hy}, 0), _b{j} = min(_ye + {hy}, "
                     f"{h}), _c{j} = max(_xs - {hx}, 0), _d{j} = min(_xe + {hx}, {w});")
    for n, slot in [*slots.items(), (group.root.name, None)]:
        m = group.member(n)
        (port,) = m.outputs.values()
        ch, c = port.channels, DTYPES[port.dtype][1]
        ey, ex = edges[n]
        plain = ey == ex == 0 and not any(
            m.type.fusable.form == "stencil" for m in _inlined(group, staged, n))
        together = rows_together(whole, how, staged, n)
        if slot is None:
            rows = _Rows(_function(n, index, False), _function(n, index, True),
                         None if plain else ex, h, w, ch, flat, args, ey, ("_xs", "_xe"))
            row_decl = f"__global {c} *_row = _out + (size_t)_y * {w * ch};"
            lines += [f"        // {n}: the tile [_ys, _ye) x [_xs, _xe) of the output",
                      *rows.runs("_ys", "_ye", row_decl, together, 2, split=False)]
        else:
            j, lw = slot
            rows = _Rows(_function(n, index, False), _function(n, index, True),
                         None if plain else ex, h, w, ch, flat, args, ey,
                         (f"_c{j}", f"_d{j}"), f"_c{j}", lw * ch)
            row_decl = f"{c} *_row = _s{j} + (size_t)(_y - _a{j}) * {lw * ch};"
            lines += [(f"        // {n}: rows [_a{j}, _b{j}) and columns [_c{j}, _d{j}) of "
                       f"the frame, into _s{j}"),
                      *rows.runs(f"_a{j}", f"_b{j}", row_decl, together, 2, split=False)]
    lines += ["    }", "}", ""]
    return lines


@dataclass
class _Piece:
    """A member of an expanded group that is a stage of a component (fusable.Stage): it
    reads the component's inputs and earlier stages, and the component's parameters
    (owner's)."""

    name: str
    owner: str
    inputs: dict
    outputs: dict
    type: object
    params: dict


def expand(group: GroupNode) -> tuple[GroupNode, dict[Endpoint, str]]:
    """The group with each member's stages as members of their own before it (named
    '<member>.<stage>': never a model name), and which group input feeds each piece's
    input port (Endpoint -> group port)."""
    feeds = {end: port for port, end in group.feeds.items()}
    if not any(m.type.fusable.stages for m in group.members) or \
            any(isinstance(m, _Piece) for m in group.members):  # none, or expanded
        return group, feeds
    from types import SimpleNamespace

    from ..ir import Data, Edge, Port
    from ..runtime.sizes import Size

    producer = {e.target: e.source for e in group.internal}
    members, internal = [], []
    for m in group.members:
        decl = m.type.fusable
        (out,) = m.outputs.values()
        h, w, ch = out.data.height, out.data.width, out.channels
        made: dict[str, Port] = {}  # stage -> its port, as its readers' input
        for st in decl.stages.values():
            name = f"{m.name}.{st.name}"
            dtype = st.dtype_for(m.inputs)
            port = Port(st.name, "in", "gpu", dtype, ch, Data(Size(h, w, ch), dtype))
            # fixed: the component's parameters fixed at build time (its accessors'
            # border, its windows), constants of the stage's function too
            ctype = SimpleNamespace(name=f"{m.type.name} stage {st.name}", fusable=st.decl,
                                    params=m.type.params, fixed=decl.radius_names())
            members.append(_Piece(name, m.name, {**m.inputs, **made},
                                  {st.name: replace(port, direction="out")}, ctype, m.params))
            for p in m.inputs:
                if Endpoint(m.name, p) in producer:
                    internal.append(Edge(producer[Endpoint(m.name, p)], Endpoint(name, p)))
                elif Endpoint(m.name, p) in feeds:
                    feeds[Endpoint(name, p)] = feeds[Endpoint(m.name, p)]
            internal += [Edge(Endpoint(f"{m.name}.{q}", q), Endpoint(name, q)) for q in made]
            made[st.name] = port
        internal += [Edge(Endpoint(f"{m.name}.{q}", q), Endpoint(m.name, q)) for q in made]
        members.append(replace(m, inputs={**m.inputs, **made}) if made else m)
    internal += list(group.internal)
    return replace(group, members=members, internal=internal), feeds


def group_kernel(group: GroupNode, header: str, device=None) -> str:
    """The group's kernel file: the generated-file header, then its body."""
    return f"// {header}\n" + group_kernel_body(group, device)


def group_kernel_body(group: GroupNode, device=None) -> str:
    """The group's kernel file below the generated-file header: what lowering keeps in
    the plan (LibSource.text), and a printer puts its header above."""
    from ..c_convention import group_constants, group_parameters

    params = group_parameters(group)
    constants = group_constants(group)
    names = _param_names(params)
    names.update({p.param: p.name for p in constants})  # 'member.param' -> its macro
    decls = [_declaration(p, names[p.name]) for p in params if p.role != "tile"]
    args = [names[p.name] for p in params if p.role != "tile"]
    how = schedule(device)
    staged, tile = staged_pieces(group, how)
    whole = group
    group, feeds = expand(group)  # stages are members of their own
    index = {m.name: i for i, m in enumerate(group.members)}
    root = group.root
    (out_name, out_port), = group.outputs.items()
    edge = margin(group, staged)
    guarded = {m.name: guarded_ports(m) for m in group.members}  # walked once a member
    stencils = any(m.type.fusable.form == "stencil" for m in group.members)
    # flat stencils need the interior path: border rules apply to pixel positions
    flat = channel_flat(group) and (edge is not None or not stencils)
    lines = [*_comment(f"Group {group.name}: one kernel for "
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
             *_constants(whole, constants),
             *_border_rules(group, guarded),
             "#define _PARAMS \\",
             *(f"    {d}, \\" if i < len(decls) - 1 else f"    {d}" for i, d in enumerate(decls)),
             "",
             "#define _ARGS \\",
             *(f"    {a}, \\" if i < len(args) - 1 else f"    {a}" for i, a in enumerate(args)),
             ""]
    halo = _halos(group)
    slots = {name: (j, tile[1] + 2 * halo[name][1])
             for j, name in enumerate(sorted(staged, key=index.get))}
    if slots:
        # what every member's function is given of the staged pieces: each one's tile in
        # local memory and the frame row and column its first element is
        local = [f"const {DTYPES[_out_dtype(group.member(n))][1]} *_s{j}, "
                 f"const int _a{j}, const int _c{j}" for n, (j, _) in slots.items()]
        lines += ["#define _LOCALS \\",
                  *(f"    {d}, \\" if i < len(local) - 1 else f"    {d}"
                    for i, d in enumerate(local)), "",
                  "#define _LARGS " + ", ".join(f"_s{j}, _a{j}, _c{j}"
                                                for j, _ in slots.values()), ""]
    producer = {e.target: e.source for e in group.internal}
    # (interior, channel-flat) versions of every member: without stencils one version,
    # with them a border version in pixel coordinates and an interior one
    versions = [(False, flat)] if edge is None else [(False, False), (True, flat)]
    used: set[str] = set()
    members = []
    # forced inline where the bodies stay small (see _member)
    forced = forced_inline(whole, how, staged)
    for interior, flat_version in versions:
        for m in group.members:
            members += _member(m, feeds, producer, index, names, flat_version, interior,
                               used, inline=forced, slots=slots, guarded=guarded[m.name])
    helpers = [line for name in HELPERS if name in used for line in HELPERS[name]]
    if helpers:
        lines += ["// built-ins the snippets call, inline (see fused.py: HELPERS)", *helpers, ""]
    lines += members
    if slots:
        lines += _staged_kernel(whole, group, out_port, flat, how, staged, tile, slots)
    else:
        lines += _kernel(group, out_name, out_port, names, flat, edge, how)
    return "\n".join(lines)


def _out_dtype(m) -> str:
    return next(iter(m.outputs.values())).dtype


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
    from ..convention import c_literal

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
    'thresh' gets _f0_thresh and _m0_thresh, never one name for both.  A stage
    'blur.rows' is _f0_blur_rows (the index keeps it apart from a member 'blur_rows')."""
    return f"_f{index[name]}_{name.replace('.', '_')}" + ("_in" if interior else "")


def _border_rules(group: GroupNode, guarded: dict[str, set[str]]) -> list[str]:
    """The border functions the group's accessors call: its stencils' rules, and the
    clamp where an index map's reads are guarded."""
    return [line for rule, text in BORDER_RULES.items()
            if any(m.type.fusable.form == "stencil" and m.type.fusable.border_of(m.params) == rule
                   or rule == "clamp" and guarded[m.name] for m in group.members)
            for line in text]


def _accessors(m, feeds: dict[Endpoint, str], producer: dict[Endpoint, Endpoint], index,
               names, flat: bool, interior: bool, slots: dict[str, tuple[int, int]],
               fills: dict[str, str], guarded: set[str]) -> tuple[list[str], list[str]]:
    """The macros of a member's input accessors (their names, and their #define lines):
    port(y, x, c) loads from a group input, reads a staged piece or calls the producing
    member, with the border rule in the border version; fills names the macro of each
    port read with a fill value, port(y, x, c, fill); guarded the ports whose reads clamp
    (guarded_ports)."""
    decl = m.type.fusable
    border = decl.border_of(m.params) if decl.form == "stencil" else None
    fargs = "_ARGS, _LARGS" if slots else "_ARGS"
    macros, lines = [], []
    for pname, port in m.inputs.items():
        src = producer.get(Endpoint(m.name, pname))
        h, w = port.data.height, port.data.width
        yy, xx = "(y_)", "(x_)"
        outside_zero = border == "constant" and not interior
        if border and border != "constant" and not interior:
            yy, xx = f"_{border}((y_), {h})", f"_{border}((x_), {w})"
        if pname in guarded:  # an index map's read not shown inside: the nearest pixel
            yy, xx = f"_clamp((y_), {h})", f"_clamp((x_), {w})"
        if flat and port.channels > 1:
            # x is the element's place in the row of W x C: a read dx pixels away is
            # dx x C elements away, the same channel
            xx = f"(x + ((x_) - x) * {port.channels})"
        if src is not None and src.component in slots:
            # a staged piece: its value, stored in an array before this pass (rows from
            # _a<j>, columns from _c<j>, lw a row)
            j, lw = slots[src.component]
            body = _load(f"_s{j}", f"(size_t)({yy} - _a{j})", lw, xx, port.channels, flat,
                         f"_c{j}")
        elif src is not None:
            body = f"{_function(src.component, index, interior)}({fargs}, {yy}, {xx}, (c_))"
        else:
            body = _load(names[feeds[Endpoint(m.name, pname)]], f"(size_t){yy}", w, xx,
                         port.channels, flat)
        if outside_zero:  # BORDER_CONSTANT: a read outside the input is 0
            body = f"((unsigned)(y_) < {h}u && (unsigned)(x_) < {w}u ? {body} : 0)"
        macros.append(pname)
        lines.append(f"#define {pname}(y_, x_, c_) {body}")
        if pname in fills:
            # port(y, x, c, fill): the fill value (as the port's type) outside the input;
            # the interior version's reads are all inside, so no test there
            fill, etype = fills[pname], DTYPES[port.dtype][1]
            macros.append(fill)
            lines.append(f"#define {fill}(y_, x_, c_, v_) " + (
                f"{pname}(y_, x_, c_)" if interior else
                f"(({etype})((unsigned)(y_) < {h}u && (unsigned)(x_) < {w}u ? "
                f"{pname}(y_, x_, c_) : (v_)))"))
    return macros, lines


def _member(m, feeds: dict[Endpoint, str], producer: dict[Endpoint, Endpoint], index,
            names, flat: bool, interior: bool, used: set[str], inline: bool,
            slots: dict[str, tuple[int, int]] | None = None,
            guarded: set[str] = frozenset()) -> list[str]:
    """A member's snippet as a function, between the macros of its input accessors.

    inline: forced inline (always_inline), which the row loop needs to vectorize: PoCL's
    inliner left WarpAffine's bilinear snippet (cost 410 > 337) a call per element, 29 ms
    a 320x240 frame, 0.8 ms inlined, and left stencil members called once per row of the
    rows-together loop (about 20x slower).  Not a group beyond MAX_UNROLLED_READS
    (forced_inline): compile time exploded.  A member's loops are unrolled where it reads
    at most MAX_UNROLLED_LOOPS elements so.  slots: the staged pieces (a read of one
    loads its tile in local memory, _s<slot>), where the kernel stages any; guarded: the
    inputs whose reads clamp (guarded_ports)."""
    decl = m.type.fusable
    slots = slots or {}
    owner = getattr(m, "owner", m.name)  # a stage reads its component's parameters
    fixed = getattr(m.type, "fixed", None) or decl.radius_names()
    fparams = "_PARAMS, _LOCALS" if slots else "_PARAMS"
    ctype = DTYPES[next(iter(m.outputs.values())).dtype][1]
    what = "interior: no border rule" if interior else "every element"
    border = decl.border_of(m.params) if decl.form == "stencil" else None
    lines = [f"// {m.name}: {m.type.name} ({decl.form}"
             + (f", radius {decl.radius}, border {border}" if border else "") + f"); {what}"]
    fills = {p: f"_fill_{p}" for p, found in accessor_calls(decl.tree, list(m.inputs)).items()
             if any(len(args) == 4 for args in found)}
    macros, defines = _accessors(m, feeds, producer, index, names, flat, interior, slots,
                                 fills, guarded)
    lines += defines
    tree = member_tree(m)  # the branches its build's constants decide, taken
    read = names_in(tree)
    tables, locals_ = _tables(m, index[m.name], read)
    if not interior:  # once, before the member's first version
        lines[1:1] = tables
    attribute = " __attribute__((always_inline))" if inline else ""
    if slots and not interior:
        # a staged kernel's border version: a call (it runs on a few columns and rows,
        # element by element); inlined at each of its call sites in every pass, an
        # opening of 5x5 took 28 s to compile for a work-group size
        attribute = " __attribute__((noinline))"
    lines.append(f"static inline{attribute} {ctype} {_function(m.name, index, interior)}"
                 f"({fparams}, const int y, const int x, const int c)")
    lines.append("{")
    lines += _port_constants(m, read)
    lines += locals_
    lines += _param_lines(m, names, owner, fixed)
    # printed from the parsed snippet; built-in calls swapped for their inline versions
    unroll = member_reads(m) <= MAX_UNROLLED_LOOPS
    for line in inline_builtins("\n".join(print_lines(tree, None, fills)), used).splitlines():
        if unroll and line.lstrip().startswith("for ("):
            # sizes and a stencil's radius are constants: a loop over a window unrolls
            # (PoCL left BoxBlur's 3x3 loop rolled: 9 ms a 1280x720 frame, unrolled 0.6)
            lines.append(f"    {line[:len(line) - len(line.lstrip())]}#pragma unroll")
        lines.append(f"    {line}".rstrip())
    lines.append("}")
    lines += [f"#undef {p}" for p in macros]
    lines.append("")
    return lines


def member_tree(m):
    """Member m's snippet with the choices its build decides made (snippet.prune): the
    parameters that fix its window (constants of its kernel; the others --set may change)
    and its ports' sizes, element types and their limits."""
    decl = m.type.fusable
    fixed = getattr(m.type, "fixed", None) or decl.radius_names()
    values = {p: m.params[p] for p in fixed if p in m.params}
    values.update(_port_values(m))
    for pname, port in {**m.inputs, **m.outputs}.items():
        values.update({f"{pname}_min": _limit_value(port.dtype, "min"),
                       f"{pname}_max": _limit_value(port.dtype, "max")})
    types = {f"{p}_t": DTYPES[port.dtype][1] for p, port in {**m.inputs, **m.outputs}.items()}
    return prune(decl.tree, values, types)


def _port_values(m) -> dict[str, int]:
    """The sizes a member's snippet is given of each port (port_height, port_width,
    port_channels): constants of its kernel."""
    return {f"{p}_{what}": v for p, port in {**m.inputs, **m.outputs}.items()
            for what, v in (("height", port.data.height), ("width", port.data.width),
                            ("channels", port.channels))}


def member_reads(m) -> int:
    """Input elements one evaluation of member m reads with its loops unrolled: its
    type's declared count, else its accessor calls in the branches its build takes
    (member_tree), a call inside n loops counted (2 radius + 1)^n times for a stencil."""
    decl = m.type.fusable
    if decl.reads is not None:
        return decl.reads_of(m.params)
    side = 2 * decl.radius_of(m.params) + 1 if decl.form == "stencil" else 1
    return max(1, unrolled_calls(member_tree(m).body, side))


def _param_lines(m, names, owner: str, fixed: set[str]) -> list[str]:
    """A member's parameters as locals of its function: those that fix its window
    (fixed) as numbers, the others from the kernel's macros (of owner's parameters)."""
    lines = []
    for pname, pdecl in m.type.params.items():
        c = "float" if pdecl.element == "float" else "int"
        if pdecl.shape:
            continue
        if pname in fixed:
            # the window is fixed at build time (the interior's margin is): a constant, so
            # that the compiler unrolls a loop over it
            value = m.params[pname]
            lines.append(f"    const {c} {pname} = "
                         f"{_float_literal(value) if c == 'float' else int(value)};")
            continue
        lines.append(f"    const {c} {pname} = {names[f'{owner}.{pname}']};")
    return lines


def _load(array: str, row: str, w: int, xx: str, ch: int, flat: bool,
          first: str | None = None) -> str:
    """Element (row, xx) of array, rows of w pixels of ch channels (flat: xx an element
    of the row, else a pixel, its channel c_), its first column first (None: 0)."""
    if flat:
        shift = "" if first is None else f" - {ch} * {first}" if ch > 1 else f" - {first}"
        return f"{array}[{row} * {w * ch} + {xx}{shift}]"
    at = xx if first is None else f"{xx} - {first}"
    return f"{array}[{ch} * ({row} * {w} + {at}) + (c_)]" if ch > 1 else \
        f"{array}[{row} * {w} + {at}]"


def member_reach(m):
    """Where member m's snippet reads, for its parameters and port sizes (snippet.reach):
    per port, its farthest rows and columns, an unbounded read, the reads not shown
    inside their input."""
    from ..snippet.reach import reach

    decl = m.type.fusable
    values = {k: v for k, v in m.params.items() if isinstance(v, (int, float, tuple))}
    if decl.form == "stencil":  # its tables, whose entries may bound its loops
        values.update(decl.tables_of(m.params))
    values.update(_port_values(m))
    values.update(decl.lengths_of(m.params))
    out = next(iter(m.outputs.values())).data
    return reach(decl.tree, values, list(m.inputs), (out.height, out.width),
                 {p: (q.data.height, q.data.width) for p, q in m.inputs.items()})


def guarded_ports(m) -> set[str]:
    """The inputs of member m whose reads get the border rule (the nearest pixel inside,
    BORDER_REPLICATE) though m is no stencil: a user's index map reading where the walk
    cannot show its positions inside the input (computed, or beyond it), which would
    otherwise load memory outside it.  The library's index maps keep their positions
    inside themselves (tested against OpenCV at every size): none."""
    decl = m.type.fusable
    if decl.form != "index_map" or getattr(m.type, "origin", "library") == "library":
        return set()
    return set(member_reach(m).outside)


def _port_constants(m, used: set[str]) -> list[str]:
    """What the snippet is given of each port: its sizes (its channels where named), and
    its element type and that type's least and greatest values where the snippet (the
    branches its build takes: used) names them (src_t, src_min)."""
    names = {n: kind for n, kind in m.type.fusable.names.items() if n in used}
    lines = []
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


def _limit_value(dtype: str, end: str) -> int | float:
    """The least ('min') or greatest ('max') value of an element type."""
    import numpy as np

    if dtype == "float32":
        top = float(np.finfo(np.float32).max)
        return -top if end == "min" else top
    info = np.iinfo(DTYPES[dtype][0])
    return int(info.min if end == "min" else info.max)


def _limit(dtype: str, end: str) -> str:
    """The least ('min') or greatest ('max') value of an element type, as a C literal."""
    value = _limit_value(dtype, end)
    if isinstance(value, float):
        return ("-" if value < 0 else "") + _float_literal(abs(value))
    if value == -(1 << 31):
        return "(-2147483647 - 1)"
    return f"{value}u" if value >= 1 << 31 else str(value)


def _tables(m, i: int, used: set[str]) -> tuple[list[str], list[str]]:
    """A member's arrays that its snippet (the branches its build takes) reads: its array
    parameters and the tables its stencil computes from parameters, as program-scope
    __constant tables and the lines of its function that name them (and the arrays'
    lengths the snippet names)."""
    decl = m.type.fusable
    arrays = {p: (d.element, m.params[p]) for p, d in m.type.params.items()
              if d.shape and p in used}
    tables = {t: v for t, v in decl.tables_of(m.params).items() if t in used} \
        if decl.form == "stencil" else {}
    arrays.update((t, ("float" if any(isinstance(x, float) for x in v) else "int", v))
                  for t, v in tables.items())
    program = [line for p, (element, v) in arrays.items()
               for line in _constant_table(f"_m{i}_{p}", element, v)]
    local = []
    for pname, (element, value) in arrays.items():
        # the snippet reads the program's table by the parameter's (or table's) name
        c = "float" if element == "float" else "int"
        inner = "".join(f"[{d}]" for d in _dims(value)[1:])
        local.append(f"    __constant const {c} (*{pname}){inner} = _m{i}_{pname};" if inner
                     else f"    __constant const {c} *{pname} = _m{i}_{pname};")
    lengths = {n: v for n, v in decl.lengths_of(m.params).items() if n in used}
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


class _Rows:
    """The statements that compute rows of one pass of a kernel: a piece's border and
    interior versions (fn, inner) stored into _row, for a frame of h x w pixels of
    channels (flat: as w x channels elements), the interior edge_y rows and edge columns
    or more from every edge (None: no interior version); args: what the functions are
    called with.  cols: the pass's columns [a, b) (C expressions, pixels), else the whole
    row; shift: the first column _row holds (a tile in local memory: the store of column
    _x goes to _row[_x - shift]); stride: elements from one row of _row to the next."""

    def __init__(self, fn: str, inner: str, edge: int | None, h: int, w: int, channels: int,
                 flat: bool, args: str = "_ARGS", edge_y: int | None = None,
                 cols: tuple[str, str] | None = None, shift: str | None = None,
                 stride: int | None = None):
        self.fn, self.inner, self.edge, self.h, self.w = fn, inner, edge, h, w
        self.channels, self.flat, self.args = channels, flat, args
        self.edge_y = edge if edge_y is None else edge_y
        self.cols, self.shift = cols, shift
        self.per_row = w * channels if flat else w
        self.stride = stride or w * channels

    def store(self, fn: str, pixel: bool = False) -> list[str]:
        """The statements storing element (or pixel) _x of the row."""
        channels, args = self.channels, self.args
        call = f"{fn}({args}, _y, _x, {{c}})"
        at = "_x"
        if self.shift is not None:
            at = f"(_x - {self.shift})" if not self.flat or channels == 1 else \
                f"(_x - {channels} * {self.shift})"
        if self.flat and pixel and channels > 1:  # an element of the flat row, by pixel
            return [f"_row[{at}] = {fn}({args}, _y, _x / {channels}, _x % {channels});"]
        if self.flat or channels == 1:
            return [f"_row[{at}] = " + call.format(c=0) + ";"]
        if channels <= MAX_UNROLLED_CHANNELS:
            # one store a channel, not one vstoreN a pixel: PoCL vectorizes the row loop
            # of these (interleaved stores) and not of a vstore3 (FlipHorizontal on RGB:
            # 0.34 ms a 640x360 frame with vstore3, 0.10 ms so)
            return [f"_row[{channels} * {at} + {c}] = " + call.format(c=c) + ";"
                    for c in range(channels)]
        return [f"for (int _c = 0; _c < {channels}; _c++)",
                f"    _row[{channels} * {at} + _c] = " + call.format(c="_c") + ";"]

    def block(self, head: str, fn: str, depth: int, pixel: bool = False,
              rows: int = 1) -> list[str]:
        """head (a loop or a branch) over the store statements, at depth levels: of row
        _y, and of the rows - 1 next ones (_y + r, r rows further in the output)."""
        pad, body = "    " * depth, self.store(fn, pixel)
        body += [b.replace("_row[", f"_row[{r * self.stride} + ").replace(
            f"({self.args}, _y,", f"({self.args}, _y + {r},") for r in range(1, rows)
            for b in body]
        if len(body) == 1:
            return [pad + head, f"{pad}    {body[0]}"]
        return [f"{pad}{head} {{", *(f"{pad}    {b}" for b in body), pad + "}"]

    def _spans(self) -> tuple[str, str, str, str]:
        """The loops over the row's left border, interior and right border, and over the
        whole row (its columns in a tile)."""
        loop = "for (int _x = {a}; _x < {b}; _x++)"
        k = self.channels if self.flat else 1  # elements a pixel
        # on a row narrower than two borders, the left border is the whole row
        left = min(self.edge or 0, self.w)
        right = max(left, self.w - (self.edge or 0))
        if self.cols is None:
            return (loop.format(a=0, b=left * k), loop.format(a=left * k, b=right * k),
                    loop.format(a=right * k, b=self.per_row), loop.format(a=0, b=self.per_row))
        a, b = self.cols
        times = (lambda e: e) if k == 1 else (lambda e: f"{k} * {e}")
        return (loop.format(a=times(a), b=times(f"min({b}, {left})")),
                loop.format(a=times(f"max({a}, {left})"), b=times(f"min({b}, {right})")),
                loop.format(a=times(f"max({a}, {right})"), b=times(b)),
                loop.format(a=times(a), b=times(b)))

    def row(self, depth: int, rows: int = 1) -> list[str]:
        """Row _y (and the rows - 1 next ones, all interior rows) at depth levels, a
        work-item's whole row ('runs')."""
        left, middle, right, whole = self._spans()
        block = self.block
        if self.edge is None:
            return block(whole, self.fn, depth)
        if rows > 1:
            # the rows' borders a row at a time (a few columns each: one call site of
            # the border version, not one a row), then their interiors together
            pad = "    " * depth
            ends = [line.replace("_row[", f"_row[_r * {self.stride} + ").replace(
                f"({self.args}, _y,", f"({self.args}, _y + _r,") for line in [
                    *block(left, self.fn, depth + 1, True),
                    *block(right, self.fn, depth + 1, True)]]
            return [f"{pad}for (int _r = 0; _r < {rows}; _r++) {{", *ends, pad + "}",
                    *block(middle, self.inner, depth, False, rows)]
        parts = [*block(left, self.fn, depth, True),
                 *block(middle, self.inner, depth),
                 *block(right, self.fn, depth, True)]
        pad = "    " * (depth - 1)
        return [f"{pad}if (_y >= {self.edge_y} && _y < {self.h - self.edge_y}) {{", *parts,
                f"{pad}}} else {{",
                *block(whole, self.fn, depth, True), f"{pad}}}"]

    def runs(self, lo: str, hi: str, row_decl: str, together: int, depth: int = 1,
             split: bool = True) -> list[str]:
        """The loop over rows [lo, hi) (C expressions), the work-group's items taking them
        in turn ('runs'; split False: all of them this item's), together rows at a time
        where they are interior rows; row_decl declares _row, row _y's first element."""
        pad, edge, h, t = "    " * depth, self.edge_y, self.h, together
        first, step = ("_k", "_n") if split else ("", "1")
        if t == 1:
            start = f"{lo} + _k" if split else lo
            return [f"{pad}for (int _y = {start}; _y < {hi}; _y += {step}) {{",
                    f"{pad}    {row_decl}",
                    *self.row(depth + (2 if self.edge is not None else 1)), pad + "}"]
        start = f"{lo} + {t} * {first}" if split else lo
        return [f"{pad}for (int _p = {start}; _p < {hi}; _p += {t} * {step}) {{",
                f"{pad}    if (_p >= {edge} && _p + {t - 1} < min({hi}, {h - edge})) {{",
                f"{pad}        // rows _p to _p + {t - 1}, every one in the interior",
                f"{pad}        const int _y = _p;", f"{pad}        {row_decl}",
                *self.row(depth + 2, t),
                f"{pad}        continue;",
                f"{pad}    }}",
                f"{pad}    for (int _y = _p; _y < min(_p + {t}, {hi}); _y++) {{",
                f"{pad}        {row_decl}",
                *self.row(depth + 3),
                f"{pad}    }}",
                pad + "}"]


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
    border = _function(root.name, index, False)
    inner = _function(root.name, index, True)
    rows = _Rows(border, inner, edge, h, w, channels, flat)
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
        out_row = f"__global {out_c} *_row = _out + (size_t)_y * {stride};"
        lines += ["    const int _k = get_local_id(1) * get_local_size(0) + get_local_id(0);",
                  "    const int _n = get_local_size(0) * get_local_size(1);",
                  *rows.runs("_y0", "_y1", out_row, together)[:-1]]
    else:
        lines += ["    const int _nx = get_local_size(0);",
                  "    for (int _y = _y0 + get_local_id(1); _y < _y1; _y += get_local_size(1)) {",
                  f"        __global {out_c} *_row = _out + (size_t)_y * {stride};"]
        loop = f"for (int _x = get_local_id(0); _x < {per_row}; _x += _nx)"
        if edge is None:
            lines += rows.block(loop, border, 2)
        else:
            lines += [f"        const bool _inside = _y >= {edge} && _y < {h - edge};",
                      "        " + loop + " {",
                      *rows.block(f"if (_inside && _x >= {edge * k} && _x < "
                                  f"{(w - edge) * k})", inner, 3),
                      *rows.block("else", border, 3, True),
                      "        }"]
    lines += ["    }", "}", ""]
    return lines


def _comment(text: str, width: int = 92) -> list[str]:
    """A '//' comment over lines of at most width characters."""
    import textwrap

    return ["// " + line for line in textwrap.wrap(text, width - 3, break_on_hyphens=False)]
