"""Stencil borders an int parameter picks (OpenCV's codes) and the CPU schedule's rows
computed together (kernelgen/fused.py), against a numpy reference of their own: the
positions OpenCV's borderInterpolate reads, reflected step by step as it does (the kernel
reflects by a modulo)."""

from __future__ import annotations

import conftest
import numpy as np
import pytest
from conftest import require_opencl, run_generated

from gpucompgen.kernelgen import fused
from gpucompgen.model import library_types

BORDER_CODES = (0, 1, 2, 4)  # BORDER_CONSTANT, _REPLICATE, _REFLECT, _REFLECT_101


def _source(p: int, n: int, border_type: int) -> int | None:
    """Where position p of a row of n reads under OpenCV's border_type (None: outside, 0)."""
    if 0 <= p < n:
        return p
    if border_type == 0:
        return None
    if border_type == 1 or n == 1:
        return min(max(p, 0), n - 1)
    delta = 1 if border_type == 4 else 0
    while not 0 <= p < n:
        p = -p - 1 + delta if p < 0 else n - 1 - (p - n) - delta
    return p


def _blur_reference(image: np.ndarray, ksize: int, border_type: int) -> np.ndarray:
    """The ksize x ksize mean, rounded to nearest, with border_type's reads outside."""
    r = ksize // 2
    h, w = image.shape[:2]
    total = np.zeros(image.shape, np.int64)
    for y in range(h):
        for x in range(w):
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    v, u = _source(y + dy, h, border_type), _source(x + dx, w, border_type)
                    if v is not None and u is not None:
                        total[y, x] += image[v, u]
    return ((total + ksize * ksize // 2) // (ksize * ksize)).astype(np.uint8)


def test_a_border_parameter_is_a_constant_of_the_build():
    from gpucompgen.convention import group_constants
    from gpucompgen.passes.program_facts import size_names

    blur = library_types()["Blur"]
    decl = blur.fusable
    assert decl.border == "border_type"
    assert decl.radius_names() == {"ksize", "border_type"}
    assert {code: decl.border_of({"border_type": code}) for code in (0, 1, 2, 4)} == \
        {0: "constant", 1: "clamp", 2: "reflect", 4: "reflect101"}
    with pytest.raises(ValueError, match="border code"):
        decl.border_of({"border_type": 3})
    assert "border_type" in size_names(blur)  # not settable at run time: the accessors
    group = fused.group_of_one(blur.specialized("uint8", 1), {"ksize": 3, "border_type": 2},
                               {"src": (5, 7), "dst": (5, 7)})
    assert not [p for p in group_constants(group) if p.param.endswith("border_type")]
    assert "_reflect((y_), 5)" in fused.group_kernel(group, "test")


# (frame, window) pairs: windows wider than the frame (reflected more than once), rows and
# columns of one pixel, a frame with an interior; one build each (sizes are constants)
BORDER_CASES = (((1, 1), 3), ((3, 1), 5), ((2, 3), 9), ((5, 7), 3), ((9, 4), 9),
                ((12, 11), 5))


@pytest.mark.parametrize("border_type,channels", [(b, 1) for b in BORDER_CODES]
                         + [(0, 3), (2, 3)])
def test_every_border_rule_equals_numpy_pad(cl_context, cl_queue, border_type, channels):
    """The rules over one channel, and over three (channel-flat: a read k pixels away is
    3k elements away) for the constant rule and a reflection."""
    require_opencl()
    rng = np.random.default_rng(border_type * 10 + channels)
    blur = library_types()["Blur"]
    for (h, w), ksize in BORDER_CASES:
        shape = (h, w) if channels == 1 else (h, w, channels)
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        params = {"ksize": ksize, "border_type": border_type}
        got = run_generated(cl_context, cl_queue, blur, params, [image], shape, (4, 1, 2, 1))
        np.testing.assert_array_equal(got, _blur_reference(image, ksize, border_type),
                                      err_msg=f"{shape} {params}")


def _group(name, params, h=20, w=30):
    t = library_types()[name]
    t = t.specialized("uint8", 1) if t.generic else t
    return fused.group_of_one(t, params, {"src": (h, w), "dst": (h, w)})


def _morph(op, ksize, shape=0, iterations=1):
    return {"op": op, "shape": shape, "ksize": ksize, "iterations": iterations}


def test_rows_together_for_small_windows_and_bodies_on_a_cpu():
    together = fused.ROWS_TOGETHER
    assert fused.rows_together(_group("Erode", {}), "runs") == together
    assert fused.rows_together(_group("Erode", {}), "strided") == 1  # a GPU
    assert fused.rows_together(_group("Threshold", {"thresh": 1, "maxval": 2,
                                                    "thresh_type": 0}), "runs") == 1
    # 5x5 windows, and an opening of 3x3 (9 x 9 reads inline): together, forced inline;
    # where the kernel stages a piece (tests/test_tile_schedule.py), its every pass
    for name, params in (("Blur", {"ksize": 5, "border_type": 4}),
                         ("GaussianBlur", {"ksize": 5}), ("MorphologyEx", _morph(4, 5)),
                         ("MorphologyEx", _morph(2, 3, shape=2))):
        group = _group(name, params)
        assert fused.rows_together(group, "runs") == together, (name, params)
        staged, _ = fused.staged_pieces(group, "runs")
        for root in [*staged, None]:
            assert fused.rows_together(group, "runs", staged, root) == together
        text = fused.group_kernel(group, "test")
        assert f"_p += {together} * " in text and "always_inline" in text
    # a 9x9 window (more than 25 taps) inline; an opening of 5x5 inline (25 x 25 reads:
    # 4 rows of it took 35 s to compile): one row, the latter not forced inline
    assert fused.rows_together(_group("GaussianBlur", {"ksize": 7}), "runs") == 1
    big = _group("MorphologyEx", _morph(2, 5))
    assert fused.rows_together(big, "runs") == 1
    assert not fused.forced_inline(big, "runs")
    # staged, its erosion then its dilation: 25 reads each, 4 rows together
    staged, _ = fused.staged_pieces(big, "runs")
    assert staged == {"m.inner"} and fused.forced_inline(big, "runs", staged)
    assert fused.rows_together(big, "runs", staged) == together


def _valid_params(ctype):
    """Every value a user may give a stencil's int parameters (each from its minimum to
    its maximum; the others at their defaults) that the type's requirements accept."""
    import itertools

    from gpucompgen import sizeexpr

    # an output's element type (ddepth) changes no read: at its default (each of its
    # values is a build of the derivatives' tests)
    typing = {d.dtype_param for d in ctype.outputs.values() if d.dtype_param}
    ints = {p: d for p, d in ctype.params.items() if d.type == "int" and not d.shape}
    free = sorted(p for p, d in ints.items() if d.minimum is not None and p not in typing
                  and d.maximum is not None and d.maximum - d.minimum <= 40)
    ranges = [range(int(ints[p].minimum), int(ints[p].maximum) + 1) for p in free]
    base = {p: d.default for p, d in ctype.params.items()}
    for values in itertools.product(*ranges):
        params = {**base, **dict(zip(free, values))}
        numbers = {p: v for p, v in params.items() if p in ints}
        if all(sizeexpr.evaluate(tree, {"src": (64, 64, 1, 1)}, numbers)
               for tree, _ in ctype.requires):
            yield params


def test_what_the_compiler_is_given_to_unroll_stays_bounded_for_every_parameter_value():
    """The compile-time criterion: for every library stencil and every parameter value a
    user may give (Blur's ksize up to 31, MorphologyEx's op, shape, ksize up to 15 and
    iterations up to 4), the kernel forces inline only bodies whose rows read at most
    MAX_UNROLLED_READS elements with their loops unrolled, and asks to unroll the loops
    only of members reading at most MAX_UNROLLED_LOOPS so.  Bounds measured on PoCL 3.0
    (fused.py): 4 rows of 81 reads built in about 2 s, of 625 reads in 35 s.  The reads
    counted here are checked against the snippets' own counts in the next test."""
    checked = 0
    for name, ctype in sorted(library_types().items()):
        if ctype.alias_of or ctype.fusable is None or ctype.fusable.form != "stencil":
            continue
        for params in _valid_params(ctype):
            group = _group(name, params, 24, 40)
            text = fused.group_kernel(group, "test")
            # each pass of the kernel: the root's, and each staged piece's
            staged, _ = fused.staged_pieces(group, "runs")
            for root in [*staged, None]:
                reads = fused.unrolled_reads(group, staged, root)
                if "always_inline" in text:
                    assert fused.rows_together(group, "runs", staged, root) * reads <= \
                        fused.MAX_UNROLLED_READS, (name, params, root)
            for m in fused.expand(group)[0].members:  # each function's own loops
                function = text.split(f"\n// {m.name}: ")[1].split("\n}\n")[0]
                if "#pragma unroll" in function:
                    assert fused.member_reads(m) <= fused.MAX_UNROLLED_LOOPS
            checked += 1
    assert checked > 300  # MorphologyEx: 7 ops x 3 shapes x 8 sizes, iterations (rect)


# a snippet run as one element of a kernel whose accessors count their calls
_COUNTING = """
#define src(y_, x_, c_) (++*_reads, (uchar)(((y_) * 7 + (x_) * 3) & 255))
{program}
static int _count(__global int *_reads)
{{
    const int y = 40, x = 40, c = 0;
{params}
{body}
}}
__kernel void count(__global int *_out, __global int *_reads)
{{
    *_reads = 0;
    _out[0] = _count(_reads);
}}
"""


@pytest.mark.parametrize("name,params", [
    ("Blur", {"ksize": 3, "border_type": 4}), ("Blur", {"ksize": 31, "border_type": 4}),
    ("GaussianBlur", {"ksize": 3}), ("MedianBlur", {}), ("Erode", {}),
    *[("MorphologyEx", _morph(op, k, shape, it)) for op, k, shape, it in (
        (0, 3, 0, 1), (1, 5, 2, 1), (4, 15, 0, 4), (2, 3, 0, 1), (3, 5, 2, 1),
        (5, 3, 1, 1), (6, 3, 0, 3), (2, 15, 0, 1))]])
def test_the_reads_a_stencil_states_bound_what_its_snippet_reads(cl_context, cl_queue,
                                                                  name, params):
    """reads_of (the declared 'reads', or the counted window) is at least what the
    snippet reads when it runs (its accessor counting its calls), and within 2.5x of it
    for a rectangular window: the bound the generator's compile-time criterion rests on,
    checked against the snippet itself, and against each of its stages (a read of a
    stage counted as one)."""
    import pyopencl as cl

    require_opencl()
    ctype = library_types()[name]
    params = {**{p: d.default for p, d in ctype.params.items()}, **params}
    # what the generator gives a member's snippet (and each stage's): its port sizes,
    # element types and bounds, its tables and array lengths (fused.py's own helpers),
    # then the parameters
    group = fused.group_of_one(ctype, params, {"src": (81, 81), "dst": (81, 81)})
    for member in fused.expand(group)[0].members:
        decl = member.type.fusable
        everything = set(decl.names)  # the whole snippet is run here, every branch
        program, local = fused._tables(member, 0, everything)
        lines = [*fused._port_constants(member, everything), *local]
        lines += [f"    const {'float' if isinstance(v, float) else 'int'} {p} = {v};"
                  for p, v in params.items() if not isinstance(v, tuple)]
        # a read with a fill value counted as a read
        fills = {p: f"_fill_{p}" for p in member.inputs}
        body = "\n".join("    " + line for line in decl.lines(fills=fills))
        stages = "".join(f"#define {p}(y_, x_, c_) (++*_reads, (int)(((y_) * 5 + (x_)) & 255))\n"
                         for p in member.inputs if p != "src")
        stages += "".join(f"#define {f}(y_, x_, c_, v_) {p}(y_, x_, c_)\n"
                          for p, f in fills.items())
        program = cl.Program(cl_context, stages + _COUNTING.format(
            program="\n".join(program), params="\n".join(lines), body=body)).build(
            options=["-w"])  # the whole snippet, every branch: constant conditions
        out, reads = (cl.Buffer(cl_context, cl.mem_flags.READ_WRITE, 4) for _ in range(2))
        program.count(cl_queue, (1,), None, out, reads)
        counted = np.zeros(1, np.int32)
        cl.enqueue_copy(cl_queue, counted, reads)
        cl_queue.finish()
        declared = decl.reads_of(params)
        assert counted[0] <= declared, (member.name, params, counted[0], declared)
        if params.get("shape", 0) == 0:
            assert declared <= 2.5 * counted[0], (member.name, params, counted[0], declared)


@pytest.mark.parametrize("name,params", [
    ("Blur", {"ksize": 5, "border_type": 4}), ("MorphologyEx", _morph(2, 3, 2))])
def test_rows_together_compute_what_one_row_at_a_time_computes(
        cl_context, cl_queue, monkeypatch, name, params):
    """Heights around the groups of rows, work-groups' tiles, 1 and 3 channels: the kernel
    that computes rows together equals the one that computes a row at a time (generated
    with ROWS_TOGETHER 1), element for element: a 5x5 window, and a window of windows
    (an elliptic opening)."""
    require_opencl()

    t = library_types()[name]
    rng = np.random.default_rng(7)
    default = fused.ROWS_TOGETHER
    # 11 rows: groups of 4 rows, the rows left over, the borders; 5 rows: one group at most
    for shape in ((11, 23, 3), (5, 23)):
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        results = []
        for together in (default, 1):
            monkeypatch.setattr(fused, "ROWS_TOGETHER", together)
            conftest._GENERATED.clear()
            # PoCL compiles a kernel again for each work-group size: two of them (one
            # thread a work-group; six sharing tiles of 5 rows, groups of 4 split)
            for setting in ((8, 1, 1, 1), (5, 2, 3, 1)):
                results.append(run_generated(cl_context, cl_queue, t, params, [image],
                                             shape, setting))
        for r in results[1:]:
            np.testing.assert_array_equal(r, results[0], err_msg=f"{name} {shape}")
    conftest._GENERATED.clear()


@pytest.mark.parametrize("op,ksize,iterations,ok", [
    (2, 15, 1, True), (3, 5, 3, True), (3, 15, 2, False), (5, 9, 4, False),
    (0, 15, 4, True), (4, 15, 4, True)])
def test_a_window_of_windows_too_large_for_one_kernel_is_refused(tmp_path, op, ksize,
                                                                  iterations, ok):
    """Open, close, top hat and black hat of (ksize // 2) * iterations above 7 would read
    more than 15^4 elements an output (ksize 15, 4 iterations: not compiled in 5 minutes):
    check refuses them, saying what to chain instead."""
    from gpucompgen.build import compile_model
    from gpucompgen.errors import GpucompgenError

    model = tmp_path / "m.yaml"
    model.write_text(
        "system: morph\ncomponents:\n"
        "  src: {type: StillImage, params: {width: 64, height: 48}}\n"
        f"  morph: {{type: MorphologyEx, params: {{op: {op}, ksize: {ksize}, "
        f"iterations: {iterations}}}}}\n"
        "  sink: {type: FrameSink}\n"
        "connections:\n  - src.image -> morph.src\n  - morph.dst -> sink.image\n")
    if ok:
        compile_model(model, tmp_path / "out")
        return
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "out")
    text = str(info.value)
    assert "m.yaml:4:3" in text and "window of windows" in text and "op 0 then op 1" in text


# a user's flexible type over one or three uint8 channels, for the tests below
USER_TYPE = """
  {name}:
    kind: flexible{params}
    inputs:
      src: {{dtype: uint8, channels: [1, 3]}}
    outputs:
      dst: {{dtype: uint8, channels: src.channels, height: src.height, width: src.width}}
    cpu: {{file: cpu.py, function: {function}}}
    fusable:
{fusable}"""
FILL_PARAM = """
    params:
      fill: {type: int, default: 7, min: 0, max: 255}"""
FILL_TYPES = "component_types:" + USER_TYPE.format(
    name="FillMin", params=FILL_PARAM, function="fill_min", fusable="""\
      form: stencil
      radius: 2
      border: clamp
      value: |
        uchar v = 255;
        for (int dy = -2; dy <= 2; dy++)
            for (int dx = -2; dx <= 2; dx++)
                v = min(v, src(y + dy, x + dx, c, (uchar)fill));
        return v;
""") + USER_TYPE.format(name="FillShift", params=FILL_PARAM, function="fill_min",
                         fusable="""\
      form: index_map
      value: src(y - 2, x + 3, c, fill)
""")


def _fill_type(tmp_path, name="FillMin"):
    from gpucompgen.errors import Reporter
    from gpucompgen.model import load_types_file

    (tmp_path / "cpu.py").write_text("def fill_min(src, *, fill):\n    return src\n")
    (tmp_path / "types.yaml").write_text(FILL_TYPES)
    rep = Reporter()
    types = load_types_file(tmp_path / "types.yaml", "types.yaml", "user", rep)
    rep.raise_if_errors()
    return types[name]


def test_a_read_with_a_fill_value_is_tested_in_the_border_version_only(tmp_path):
    """src(y, x, c, fill): the border version tests the position, the interior version
    (every read inside) reads."""
    ctype = _fill_type(tmp_path).specialized("uint8", 1)
    text = fused.group_kernel(fused.group_of_one(ctype, {"fill": 7},
                                                 {"src": (20, 30), "dst": (20, 30)}), "test")
    border, interior = [line for line in text.splitlines()
                        if line.startswith("#define _fill_src")]
    assert "(unsigned)(y_) < 20u && (unsigned)(x_) < 30u" in border and "(v_)" in border
    assert interior == "#define _fill_src(y_, x_, c_, v_) src(y_, x_, c_)"
    assert text.count("_fill_src(y + dy, x + dx, c, (uchar)fill)") == 2


@pytest.mark.parametrize("channels", (1, 3))
def test_a_read_with_a_fill_value_equals_numpy_pad(cl_context, cl_queue, tmp_path, channels):
    """The minimum over a 5x5 window whose reads outside the frame are the fill value:
    numpy's constant pad, on frames with and without an interior, one and three channels
    (the interior channel-flat)."""
    require_opencl()
    ctype = _fill_type(tmp_path)
    rng = np.random.default_rng(channels)
    for h, w in ((1, 1), (3, 8), (9, 4), (12, 23)):
        shape = (h, w) if channels == 1 else (h, w, channels)
        image = rng.integers(0, 256, shape, dtype=np.uint8)
        fill = int(rng.integers(0, 256))
        pad = ((2, 2), (2, 2)) + ((0, 0),) * (channels > 1)
        padded = np.pad(image, pad, constant_values=fill)
        expected = np.min([padded[dy:dy + h, dx:dx + w]
                           for dy in range(5) for dx in range(5)], axis=0)
        got = run_generated(cl_context, cl_queue, ctype, {"fill": fill}, [image], shape,
                            (4, 1, 2, 1))
        np.testing.assert_array_equal(got, expected, err_msg=f"{shape} fill {fill}")


@pytest.mark.parametrize("channels", (1, 3))
def test_an_index_maps_read_with_a_fill_value_tests_every_position(cl_context, cl_queue,
                                                                    tmp_path, channels):
    """An index map has one version: its reads with a fill value test pixel positions
    there, so its group is not channel-flat (x would count elements)."""
    require_opencl()
    ctype = _fill_type(tmp_path, "FillShift")
    group = fused.group_of_one(ctype.specialized("uint8", channels), {"fill": 9},
                               {"src": (6, 7), "dst": (6, 7)})
    assert not fused.channel_flat(group)
    shape = (6, 7) if channels == 1 else (6, 7, channels)
    image = np.random.default_rng(channels).integers(0, 256, shape, dtype=np.uint8)
    expected = np.full_like(image, 9)
    expected[2:, :-3] = image[:-2, 3:]
    got = run_generated(cl_context, cl_queue, ctype, {"fill": 9}, [image], shape)
    np.testing.assert_array_equal(got, expected)


def test_every_library_stencil_reads_within_its_radius_at_every_parameter_value():
    """check-reads (snippet/reach.py) follows each library stencil and stage through its
    loops at every parameter value a user may give: every read is y and x plus numbers
    within the stated radius, so none is refused and the interior needs no border rule."""
    count = 0
    for name, t in sorted(library_types().items()):
        if t.alias_of or t.fusable is None or t.fusable.form != "stencil":
            continue
        port = next(iter(t.inputs.values()))
        ctype = t.specialized((port.dtypes or (port.dtype,))[0], 1) if t.generic else t
        for params in _valid_params(ctype):
            shapes = {p: (40, 50) for p in [*ctype.inputs, *ctype.outputs]}
            for m in fused.expand(fused.group_of_one(ctype, params, shapes))[0].members:
                found = fused.member_reach(m)
                assert found.unbounded is None, (name, m.name, params)
                ry, rx = m.type.fusable.radii_of(m.params)
                assert all(found.rows[p] <= ry and found.cols[p] <= rx for p in m.inputs), \
                    (name, m.name, params, found)
                count += 1
    assert count > 1000  # every stencil, its stages, over their parameter ranges


READ_CASES = {
    # value, radius, what check says (None: accepted)
    "constant offsets beyond": ("return src(y + 5, x - 40, c);", "1",
                                "reads src(y + 5, x - 40, c), 5 row(s) and 40 column(s) "
                                "away, beyond its radius (1 rows, 1 columns)"),
    "a loop one too far": ("int s = 0;\nfor (int d = -r; d <= r + 1; d++)\n"
                           "    s += src(y, x + d, c);\nreturn s / (2 * r + 2);", "r",
                           "reads src(y, x + d, c), 0 row(s) and 3 column(s) away, beyond "
                           "its radius (2 rows, 2 columns)"),
    "a position from an element": ("return src(y + src(y, x, c) % 3, x, c);", "1",
                                   "reads src(y + src(y, x, c) % 3, x, c), at a position "
                                   "that is not y and x plus numbers"),
    "a loop the element bounds": ("int s = 0;\nfor (int i = 0; i < src(y, x, c) % 3; i++)\n"
                                  "    s += src(y, x + i, c);\nreturn s;", "2",
                                  "has a loop whose course depends on the element's values"),
    "a loop within": ("int s = 0;\nfor (int d = -r; d <= r; d++)\n"
                      "    s += src(y + d, x - d, c);\nreturn s / (2 * r + 1);", "r", None),
    "a branch on the element": ("const int v = src(y, x, c);\n"
                                "return v > 9 ? src(y - 2, x, c) : src(y + 2, x + 1, c);",
                                "2", None),
}


@pytest.mark.parametrize("case", sorted(READ_CASES))
def test_check_refuses_a_stencil_that_reads_beyond_its_radius(tmp_path, case):
    """A user's stencil read farther than its radius (or where no radius bounds it) would
    load memory outside the input in the interior the kernel reads without border rules:
    check says so at the component, naming the read."""
    from gpucompgen.build import compile_model
    from gpucompgen.errors import GpucompgenError

    value, radius, message = READ_CASES[case]
    body = "".join(f"        {line}\n" for line in value.splitlines())
    (tmp_path / "cpu.py").write_text("def reads(src, *, r):\n    return src\n")
    (tmp_path / "types.yaml").write_text(
        "component_types:\n  Reads:\n    kind: flexible\n"
        "    params:\n      r: {type: int, default: 2, min: 0, max: 4}\n"
        "    inputs:\n      src: {dtype: uint8, channels: [1, 3]}\n"
        "    outputs:\n      dst: {dtype: uint8, channels: src.channels, "
        "height: src.height, width: src.width}\n"
        "    cpu: {file: cpu.py, function: reads}\n"
        f"    fusable:\n      form: stencil\n      radius: {radius}\n      border: clamp\n"
        f"      value: |\n{body}")
    model = tmp_path / "m.yaml"
    model.write_text("system: reads\ntypes: [types.yaml]\ncomponents:\n"
                     "  src: {type: StillImage, params: {width: 32, height: 24}}\n"
                     "  k: {type: Reads}\n  sink: {type: FrameSink}\n"
                     "connections:\n  - src.image -> k.src\n  - k.dst -> sink.image\n")
    if message is None:
        compile_model(model, tmp_path / "out")
        return
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "out")
    text = str(info.value)
    assert "m.yaml:5:3: error: 'k' (Reads): its stencil " in text, text
    assert message in text, text
    assert not (tmp_path / "out").exists()  # nothing half-written


SHIFT_TYPES = "component_types:" + USER_TYPE.format(
    name="Shift", function="shift", fusable="""\
      form: index_map
      value: src(y + dy, x + dx, c)
""", params="""
    params:
      dy: {type: int, default: 0, min: -100, max: 100}
      dx: {type: int, default: 0, min: -100, max: 100}""") + USER_TYPE.format(
    name="Mirror", function="shift", params="", fusable="""\
      form: index_map
      value: "x < src_width / 2 ? src(y, x, c) : src(src_height - 1 - y, src_width - 1 - x, c)"
""")


@pytest.mark.parametrize("channels", (1, 3))
def test_a_users_index_map_reads_the_nearest_pixel_where_it_is_not_shown_inside(
        cl_context, cl_queue, tmp_path, channels):
    """A user's index map computes its positions: where the walk of its snippet cannot
    show a read inside its input (here a shift past the edges), the read gets the nearest
    pixel (BORDER_REPLICATE) instead of memory outside the input; where it can (a mirror
    whose halves are chosen by x), no border rule is added."""
    from gpucompgen.errors import Reporter
    from gpucompgen.model import load_types_file

    require_opencl()
    (tmp_path / "cpu.py").write_text("def shift(src, **params):\n    return src\n")
    (tmp_path / "types.yaml").write_text(SHIFT_TYPES)
    rep = Reporter()
    types = load_types_file(tmp_path / "types.yaml", "types.yaml", "user", rep)
    rep.raise_if_errors()
    shape = (9, 13) if channels == 1 else (9, 13, channels)
    image = np.random.default_rng(channels).integers(0, 256, shape, dtype=np.uint8)
    rows, cols = np.arange(9)[:, None], np.arange(13)[None, :]
    for dy, dx in ((5, 40), (-3, 2), (0, 0), (-100, -100)):
        expected = image[np.clip(rows + dy, 0, 8), np.clip(cols + dx, 0, 12)]
        got = run_generated(cl_context, cl_queue, types["Shift"], {"dy": dy, "dx": dx},
                            [image], shape)
        np.testing.assert_array_equal(got, expected, err_msg=f"{dy}, {dx}")
    mirror = types["Mirror"].specialized("uint8", channels)
    text = fused.group_kernel(fused.group_of_one(mirror, {}, {"src": (9, 13),
                                                                "dst": (9, 13)}), "test")
    assert "_clamp" not in text
    half = cols < 13 // 2
    expected = np.where(half[..., None] if channels == 3 else half, image,
                        image[::-1, ::-1])
    got = run_generated(cl_context, cl_queue, types["Mirror"], {}, [image], shape)
    np.testing.assert_array_equal(got, expected)
    shift = types["Shift"].specialized("uint8", channels)
    text = fused.group_kernel(fused.group_of_one(shift, {"dy": 0, "dx": 0},
                                                 {"src": (9, 13), "dst": (9, 13)}), "test")
    assert "_clamp" not in text  # shifted by nothing: every read inside
    text = fused.group_kernel(fused.group_of_one(shift, {"dy": 5, "dx": 40},
                                                 {"src": (9, 13), "dst": (9, 13)}), "test")
    assert "_clamp((y_), 9)" in text and "_clamp((x_), 13)" in text


def test_the_plan_names_the_index_map_reads_given_the_nearest_pixel(tmp_path):
    """What check and plan print: which inputs of which components read the nearest pixel
    (a decision the system takes for the user is shown)."""
    from gpucompgen.build import compile_model
    from gpucompgen.plan import fusion_lines

    (tmp_path / "cpu.py").write_text("def shift(src, **params):\n    return src\n")
    (tmp_path / "types.yaml").write_text(SHIFT_TYPES)
    model = tmp_path / "m.yaml"
    model.write_text("system: shifts\ntypes: [types.yaml]\ncomponents:\n"
                     "  src: {type: StillImage, params: {width: 32, height: 24}}\n"
                     "  far: {type: Shift, params: {dy: 5, dx: 40}}\n"
                     "  mirror: {type: Mirror}\n  sink: {type: FrameSink}\n"
                     "connections:\n  - src.image -> far.src\n  - far.dst -> mirror.src\n"
                     "  - mirror.dst -> sink.image\n")
    for fusion in ("off", "auto"):
        plan = compile_model(model, tmp_path / "out", fusion=fusion).system.plan
        assert plan.guarded == (("far", ("src",)),)
        text = " ".join(" ".join(fusion_lines(plan)).split())
        assert "given the nearest pixel there (BORDER_REPLICATE): far.src" in text


@pytest.mark.parametrize("text,bounded", [
    ("const long k = 1L << 2000000000; return src(y, x, c);", True),  # C: undefined
    ("long v = 3; for (int i = 0; i < 100000; i++) v = v * v; "
     "return src(y + (int)v, x, c);", False),  # grows past 64 bits: unknown
    ("for (;;) {} return src(y, x, c);", False),  # never ends: given up
    ("int s = 0; while (1) { s++; if (s > 5) break; } return src(y + s - 6, x, c);", True),
])
def test_the_walk_of_a_snippet_stays_small_whatever_it_computes(text, bounded):
    """snippet.reach computes the snippet's numbers as C would, 64 bits at most and a
    bounded number of steps: a shift by two billion or a square taken in a loop cannot make
    the check's memory or time explode."""
    import time

    from gpucompgen.snippet import analyse
    from gpucompgen.snippet.reach import reach

    result = analyse(text, "stencil", ["src"], ["dst"], [])
    assert result.problems == []
    start = time.perf_counter()
    found = reach(result.tree, {"src_height": 10, "src_width": 10}, ["src"])
    assert time.perf_counter() - start < 10
    assert (found.unbounded is None) == bounded


def test_check_refuses_a_pointwise_type_whose_output_is_larger_than_its_input(tmp_path):
    """A pointwise snippet reads its inputs at its output's (y, x): an output declared
    larger than an input would read outside that input."""
    from gpucompgen.build import compile_model
    from gpucompgen.errors import GpucompgenError

    (tmp_path / "cpu.py").write_text("def big(src):\n    return src\n")
    (tmp_path / "types.yaml").write_text(
        "component_types:" + USER_TYPE.format(name="Big", params="", function="big",
                                              fusable="      form: pointwise\n"
                                                      "      value: src(y, x, c)\n")
        .replace("height: src.height, width: src.width", "height: src.height * 2, "
                 "width: src.width"))
    model = tmp_path / "m.yaml"
    model.write_text("system: big\ntypes: [types.yaml]\ncomponents:\n"
                     "  src: {type: StillImage, params: {width: 16, height: 8}}\n"
                     "  k: {type: Big}\n  sink: {type: FrameSink}\n"
                     "connections:\n  - src.image -> k.src\n  - k.dst -> sink.image\n")
    with pytest.raises(GpucompgenError) as info:
        compile_model(model, tmp_path / "out")
    assert "m.yaml:5:3: error: 'k' (Big): its pointwise snippet reads src at every (y, x) " \
           "of its 16x16 output, but src is 8x16: it would read outside it" in str(info.value)
