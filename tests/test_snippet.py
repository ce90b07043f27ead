"""The fusable snippet language (gpucompgen/snippet/): lexer, grammar, names, printer.

- Round trip (Hypothesis): snippets drawn from the grammar, written with random layout,
  comments and parentheses, parse; their printed form parses to the same tree and prints
  the same again.  Trees built directly (no parentheses) print with the parentheses their
  operators need: parsed back and stripped of parentheses, they are the same tree.
- Any text, however hostile, gives problems, never an exception, and quickly.
- Every library snippet parses, prints and, printed with every name renamed (as the
  kernel generator may), compiles on the device.
- Each finding of the hostile tests, at the snippet's level (the corpus in
  tests/bad_models/snippet_*.yaml has one file per class, checked through the CLI).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpucompgen.errors import Pos
from gpucompgen.fusable import snippet_position
from gpucompgen.model import library_types
from gpucompgen.snippet import (
    MAX_NESTING,
    analyse,
    expression_text,
    is_builtin,
    parse,
    print_lines,
    print_text,
)
from gpucompgen.snippet import syntax as S


def problems(text: str, form: str = "pointwise") -> list[str]:
    return [p.message for p in analyse(text, form, ["image"], ["out"], ["gain"]).problems]


# -- drawn snippets: parse, print, parse gives the same tree ------------------------------
# (a comment is never glued to an operator: '/' then '/**/' is a '//' comment in C too)
SPACE = st.sampled_from([" ", "  ", "\n", "\t", " /* note */ ", " // note\n", "\r\n",
                         " /**/ ", " /* a // b */ "])
NAMES = ["y", "x", "c", "gain", "image_height", "image_width", "a", "b"]
NUMBERS = ["0", "1", "255", "32768u", "0x1F", "0.5f", "1e-3f", "2.", "true", "010"]
BINARY = list(S.BINARY_PREC)


@st.composite
def expressions(draw, depth: int = 0):
    sp = draw(SPACE)
    if depth >= 4 or draw(st.integers(0, 3)) == 0:
        return draw(st.sampled_from(NAMES + NUMBERS))
    kind = draw(st.sampled_from(["binary", "unary", "paren", "cond", "call", "access",
                                 "cast", "vector"]))
    e = lambda: draw(expressions(depth + 1))
    if kind == "binary":
        return f"{e()}{sp}{draw(st.sampled_from(BINARY))}{sp}{e()}"
    if kind == "unary":
        return f"{draw(st.sampled_from(['-', '+', '!', '~']))}{sp}({e()})"
    if kind == "paren":
        return f"({sp}{e()}{sp})"
    if kind == "cond":
        return f"({e()}{sp}?{sp}{e()}{sp}:{sp}{e()})"
    if kind == "call":
        f = draw(st.sampled_from(["min", "max", "abs_diff", "add_sat"]))
        return f"{f}({e()},{sp}{e()})"
    if kind == "access":
        return f"image({e()},{sp}{e()},{sp}c)"
    if kind == "cast":
        return f"({draw(st.sampled_from(['int', 'float', 'uchar', 'unsigned int']))}){sp}({e()})"
    return f"((float4)({e()},{sp}{e()}, 0.0f,{sp}1.0f)).{draw(st.sampled_from(['x', 's1', 'lo']))}"


@st.composite
def statements(draw, depth: int = 0):
    sp = draw(SPACE)
    e = lambda: draw(expressions(2))
    kind = draw(st.sampled_from(["decl", "assign", "if", "for", "while", "block", "return",
                                 "do", "array"] if depth < 2 else ["decl", "assign",
                                                                   "return"]))
    def s() -> str:  # a statement as the body of if/for/while/do: never a declaration
        inner = draw(statements(depth + 1))
        return "{ " + inner + " }" if inner.startswith(("const", "int")) else inner
    if kind == "decl":
        return f"const{sp}int q{depth} = {e()},{sp}r{depth};"
    if kind == "assign":
        return f"a{sp}{draw(st.sampled_from(S.ASSIGN_OPS))}{sp}{e()};"
    if kind == "if":
        other = f"{sp}else{sp}{s()}" if draw(st.booleans()) else ""
        return f"if{sp}({e()}){sp}{s()}{other}"
    if kind == "for":
        return f"for (int i = 0;{sp}i < 3; i++){sp}{s()}"
    if kind == "while":
        return f"while ({e()}){sp}{{{sp}{s()} break; }}"
    if kind == "do":
        return f"do {s()}{sp}while ({e()});"
    if kind == "array":
        return f"int v{depth}[3] = {{1,{sp}{e()}}}; v{depth}[2]++;"
    if kind == "block":
        return "{" + sp.join(draw(statements(depth + 1))
                             for _ in range(draw(st.integers(0, 3)))) + "}"
    return f"return{sp}{e()};"


@st.composite
def snippets(draw):
    if draw(st.booleans()):
        return draw(expressions())
    sp = draw(SPACE)
    body = [draw(statements()) for _ in range(draw(st.integers(0, 4)))]
    return sp.join(["int a = 1, b = 2;", *body, f"return {draw(expressions())};"])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=snippets())
def test_printed_snippet_parses_to_the_same_tree(text):
    tree = parse(text)
    printed = print_text(tree)
    again = parse(printed)
    assert again == tree, (text, printed)
    assert print_text(again) == printed  # printing is a fixed point
    assert "/*" not in printed and "//" not in printed  # comments never reach a kernel


def _strip(node):
    """The tree without the parentheses the author (or the printer) wrote."""
    if isinstance(node, S.Paren):
        return _strip(node.inner)
    if isinstance(node, tuple):
        return tuple(_strip(n) for n in node)
    if isinstance(node, S.Node):
        values = {k: _strip(v) for k, v in vars(node).items() if k != "at"}
        return type(node)(**values)
    return node


@st.composite
def trees(draw, depth: int = 0):
    """Expression trees as a generator could build them: no parentheses at all."""
    if depth >= 4 or draw(st.integers(0, 2)) == 0:
        if draw(st.booleans()):
            return S.Name(draw(st.sampled_from(NAMES)))
        return S.Number(draw(st.sampled_from(NUMBERS)))
    t = lambda: draw(trees(depth + 1))
    kind = draw(st.sampled_from(["binary", "unary", "postfix", "cond", "assign", "cast",
                                 "call", "index", "member"]))
    if kind == "binary":
        return S.Binary(draw(st.sampled_from(BINARY)), t(), t())
    if kind == "unary":
        return S.Unary(draw(st.sampled_from(S.PREFIX_OPS)), t())
    if kind == "postfix":
        return S.Postfix(draw(st.sampled_from(["++", "--"])), t())
    if kind == "cond":
        return S.Conditional(t(), t(), t())
    if kind == "assign":
        return S.Assign(draw(st.sampled_from(S.ASSIGN_OPS)), t(), t())
    if kind == "cast":
        return S.Cast(S.TypeName(draw(st.sampled_from(["int", "float", "ulong"]))), t())
    if kind == "call":
        return S.Call("min", (t(), t()))
    if kind == "index":
        return S.Index(t(), t())
    return S.Member(t(), "x")


@settings(max_examples=400, deadline=None)
@given(tree=trees())
def test_printer_adds_the_parentheses_precedence_needs(tree):
    text = expression_text(tree)
    snippet = parse(f"return {text};")
    assert _strip(snippet.body[0].value) == tree, text


def test_dangling_else_is_printed_with_braces():
    """A generator's tree whose else belongs to the outer if keeps it there."""
    inner = S.If(S.Name("a"), S.Return(S.Number("1")))
    tree = S.Snippet((S.If(S.Name("b"), inner, S.Return(S.Number("2"))),))
    outer = parse(print_text(tree)).body[0]
    assert outer.other == S.Return(S.Number("2"))
    assert outer.then == S.Block((inner,))


# -- hostile text: problems, never an exception -------------------------------------------
ALPHABET = st.sampled_from(list("abcxy_019 ()[]{};,.+-*/%<>=!&|^~?:#\\'\"\n\r\t") +
                           ["\u2028", "\x85", "\f", "??/", "%:", "<%", "//", "/*", "*/",
                            "return ", "int ", "image(", "for (", "if (", "0x", "1e"])


@settings(max_examples=500, deadline=None)
@given(parts=st.lists(ALPHABET, max_size=60))
def test_any_text_gives_problems_not_exceptions(parts):
    text = "".join(parts)
    result = analyse(text, "pointwise", ["image"], ["out"], ["gain"])
    assert (result.tree is None) == bool(result.problems) or result.problems
    for p in result.problems:
        assert 0 <= p.offset <= len(text)


@pytest.mark.parametrize("text", ["(" * 5000, "-" * 3999, "{" * 2000, "a" + "[0]" * 1000,
                                  "x ? " * 999 + "1", "!" * 3999 + "x"])
def test_deep_or_long_input_is_refused_quickly(text):
    start = time.perf_counter()
    found = problems(text)
    assert found and time.perf_counter() - start < 1.0, found


# -- the findings, one class each -----------------------------------------------------------
@pytest.mark.parametrize("text,message,at", [
    ("const int p = image(y, x, c); // brighter \\\nreturn p;", "backslash at the end", 42),
    ("const int p = image(y, x, c); // a \\  \nreturn p;", "backslash at the end", 35),
    ("// \u2028 printf(1);\nreturn image(y, x, c);", "U+2028", 3),
    ("// \u2029\nreturn image(y, x, c);", "U+2029", 3),
    ("// \x85\nreturn image(y, x, c);", "U+0085", 3),
    ("// \v\nreturn image(y, x, c);", "VT", 3),
    ("%:define min(a, b) 0\nreturn image(y, x, c);", "digraph '%:'", 0),
    ("return image(y, x, c); %>", "digraph '%>'", 23),
    ("<% return image(y, x, c); }", "digraph '<%'", 0),
    ("int v<:3:>; return image(y, x, c);", "digraph '<:'", 5),
    ("// ??/\nreturn image(y, x, c);", "trigraph '??/'", 3),
    ("#define A 1\nimage(y, x, c)", "preprocessor lines", 0),
    ("(" * 300 + "image(y, x, c)" + ")" * 300, f"deeper than {MAX_NESTING} levels", 32),
    ("image(y, x, c) / 0", "division by zero", 17),
    ("image(y, x, c) % (3 - 3)", "modulo by zero", 17),
    ("image(y, x, c) / ((int)0.0f)", "division by zero", 17),
    ("int a = image(y, x, c); a %= 1 - 1; return a;", "modulo by zero", 29),
])
def test_finding_classes_are_positioned_problems(text, message, at):
    found = analyse(text, "index_map", ["image"], ["out"], ["gain"]).problems
    assert found and message in found[0].message, found
    assert found[0].offset == at, found


def test_comments_may_hold_any_text_but_what_changes_lines():
    """Comments are removed by the lexer, so what C would never read is no problem there
    ('#define', printf, digraphs, non-ASCII); what changes where lines end is."""
    text = ("/* #define min(a, b) 0  <% %> %: printf(\"x\") \u00e9 */\n"
            "return image(y, x, c);  // barrier(0); 'quoted' ??? \u00a0")
    assert problems(text) == []
    assert print_lines(parse(text)) == ["return image(y, x, c);"]


def test_a_read_with_a_fill_value_prints_under_the_generators_name():
    """A stencil's image(y, x, c, fill) is checked like a read, and prints as the macro
    the generator names (a plain read, and a call of another name, as written)."""
    result = analyse("return image(y - 1, x, c, 7) + image(y, x, c) + min(1, 2);",
                     "stencil", ["image"], ["out"], [])
    assert result.problems == []
    assert print_lines(result.tree, fills={"image": "_fill_image"}) == [
        "return _fill_image(y - 1, x, c, 7) + image(y, x, c) + min(1, 2);"]
    assert print_lines(result.tree) == [
        "return image(y - 1, x, c, 7) + image(y, x, c) + min(1, 2);"]


def test_a_trailing_comment_stays_out_of_the_kernel():
    tree = analyse("image(y, x, c) // the mirror", "pointwise", ["image"], ["out"], []).tree
    assert print_lines(tree) == ["return image(y, x, c);"]


@pytest.mark.parametrize("text,message", [
    ("image(y, x, c) + brightnes", "unknown name 'brightnes'"),
    ("image(y, x)", "takes 3 arguments"),
    ("image(y + 1, x, c)", "reads inputs at (y, x) only"),
    ("out(y, x, c)", "output 'out' is what the snippet returns"),
    ("image", "input 'image' is read as image(y, x, c)"),
    ("min + image(y, x, c)", "'min' is a built-in function"),
    ("y = 1; return image(y, x, c);", "'y' is given to the snippet"),
    ("gain++; return image(y, x, c);", "'gain' is given to the snippet"),
    ("const int a = 1; a = 2; return a;", "'a' is const"),
    ("int a = a; return a;", "unknown name 'a'"),
    ("{ int t = 1; } return t;", "unknown name 't'"),
    ("int a = 1; int a = 2; return a;", "declared twice"),
    ("int gain = 1; return gain;", "hides a name the snippet is given"),
    ("int clamp = 1; return clamp;", "hides an OpenCL C built-in"),
    ("return frobnicate(1);", "unknown function 'frobnicate'"),
    ("break; return 1;", "'break' outside a loop"),
    ("int v[3]; return v[-1];", "index -1 is outside"),
    ("int v[100000]; return 1;", "must be a number from 1 to"),
    ("int v = {1}; return v;", "initializes an array"),
    ("if (c) return 1;", "ends without returning"),
    ("int a = image(y, x, c); a", "statements must end by returning"),
    ("return;", "'return' needs the element's value"),
    ("int *p; return 1;", "pointers"),
    ("return *gain;", "pointers"),
    ("return sizeof(int);", "'sizeof'"),
    ("return (1, 2);", "comma operator"),
    ("goto end; return 1;", "'goto' is not allowed in a snippet"),
    ("return printf(1);", "'printf' is not allowed"),
    ("return get_global_id(0);", "'get_global_id' is not allowed"),
    ("return image(y, x, c).q;", "not a vector component"),
    ("return (float4)(1.0f).x;", "after a vector literal"),
    ("return 08;", "not an OpenCL C number"),
    ("return 1.5.5;", "not an OpenCL C number"),
    ("return 'a';", "string and character literals"),
    ("return @;", "character '@'"),
    ("return ü;", "character 'ü'"),
    ("/* open", "never closed"),
    ("min(1, 2", "'(' is never closed"),
    ("switch (c) { } return 1;", "'switch' is not allowed here"),
    ("if (c) int a = 1; return 1;", "a declaration cannot be the body"),
    ("return " + " + ".join(["y"] * 200) + ";", "deeper than 100 levels"),
])
def test_snippet_problems(text, message):
    found = problems(text)
    assert any(message in f for f in found), found


def test_names_are_resolved_with_their_kinds():
    result = analyse("const float k = 0.5f * gain; int t = image(y, x, c);\n"
                     "return convert_uchar_sat(k * t + image_height + M_PI_F);",
                     "pointwise", ["image"], ["out"], ["gain"])
    assert not result.problems
    assert result.names == {"gain": "param", "k": "local", "y": "coordinate",
                            "x": "coordinate", "c": "coordinate", "image": "accessor",
                            "t": "local", "convert_uchar_sat": "builtin",
                            "image_height": "size", "M_PI_F": "constant"}
    assert is_builtin("convert_uchar4_sat_rte") and not is_builtin("as_uchar_sat")


# -- renaming ------------------------------------------------------------------------------
def test_rename_changes_every_use_and_declaration():
    tree = parse("int a = image(y, x, c); for (int i = 0; i < gain; i++) a += i;\n"
                 "return min(a, 255);")
    lines = print_lines(tree, {"a": "m0_a", "i": "m0_i", "image": "m0_image", "gain": "m0_gain",
                               "y": "yy"})
    assert lines == ["int m0_a = m0_image(yy, x, c);",
                     "for (int m0_i = 0; m0_i < m0_gain; m0_i++)",
                     "    m0_a += m0_i;",
                     "return min(m0_a, 255);"]


@pytest.mark.parametrize("rename,message", [
    ({"a": "b"}, "the same name"),
    ({"a": "int"}, "not a C name"),
    ({"a": "1a"}, "not a C name"),
    ({"min": "my_min"}, "cannot be renamed"),
])
def test_rename_refuses_what_would_change_the_meaning(rename, message):
    tree = parse("int a = 1, b = 2; return min(a, b);")
    with pytest.raises(ValueError, match=message):
        print_lines(tree, rename)


# -- positions inside the YAML string --------------------------------------------------------
@pytest.mark.parametrize("raw,style,value,offset,expected", [
    ("image(y, x) + q", None, "image(y, x) + q", 14, (5, 21)),
    ('"image(y, x) + q"', '"', "image(y, x) + q", 14, (5, 22)),
    ("'it''s + q'", "'", "it's + q", 7, (5, 16)),
    ('"a\\tb\\u2028 q"', '"', "a\tb\u2028 q", 4, (5, 18)),
    ('"a\\\n   b"', '"', "ab", 1, (6, 4)),
    ("|\n  int a = 1;\n  return b;\n", "|", "int a = 1;\nreturn b;\n", 18, (7, 10)),
    ("plain\n    folded q", None, "plain folded q", 13, (6, 12)),
])
def test_snippet_positions_point_inside_the_yaml_string(raw, style, value, offset, expected):
    pos = snippet_position(Pos("t.yaml", 5, 7), raw, style, value, offset)
    assert (pos.line, pos.col) == expected


# -- the library ----------------------------------------------------------------------------
def _library_snippets():
    return {n: t for n, t in sorted(library_types().items()) if t.fusable is not None}


def test_every_library_snippet_parses_and_prints_the_same_tree():
    snippets = _library_snippets()
    assert len(snippets) >= 20
    for name, t in snippets.items():
        tree = t.fusable.tree
        types = {f"{p}_t": p for p in [*t.inputs, *t.outputs]}  # src_t: src's element type
        assert parse(print_text(tree), types) == tree, name


def test_every_library_snippet_compiles_printed_with_every_name_renamed(cl_context):
    """What the kernel generator does: rename the snippet's names (its own prefix here)
    and declare what the snippet is given under the new names."""
    import pyopencl as cl

    functions = []
    for name, t in _library_snippets().items():
        f = t.fusable
        rename = {n: f"{name}_{n}" for n, kind in f.names.items()
                  if kind not in ("builtin", "constant")}
        rename.update({f"{p}_{d}": f"{name}_{p}_{d}" for p in [*t.inputs, *t.outputs]
                       for d in ("height", "width", "channels")})
        rename.update({p: f"{name}_{p}" for p in t.params})
        rename.update({p: f"{name}_{p}" for p in t.inputs})
        rename.update({n: f"{name}_{n}" for n in "yxc"})
        # an input's accessor, and a stage's (read like an input: fusable.Stage)
        lines = [f"#define {name}_{p}(y_, x_, c_) src[3 * ((y_) * 5 + (x_)) + (c_)]"
                 for p in [*t.inputs, *f.stages]]
        # a read with a fill value (the generator's macro tests the position)
        fills = {p: f"{name}_fill_{p}" for p in [*t.inputs, *f.stages]}
        lines += [f"#define {fill}(y_, x_, c_, v_) ((uchar)((unsigned)(y_) < 5u && "
                  f"(unsigned)(x_) < 5u ? {name}_{p}(y_, x_, c_) : (v_)))"
                  for p, fill in fills.items()]
        lines.append(f"static inline int {name}(__global const uchar *src, const int {name}_y, "
                     f"const int {name}_x, const int {name}_c)")
        lines.append("{")
        lines += [f"    const int {name}_{p}_{d} = 5;" for p in [*t.inputs, *t.outputs]
                  for d in ("height", "width")]
        lines += [f"    const int {name}_{p}_channels = 3;" for p in [*t.inputs, *t.outputs]]
        for p in [*t.inputs, *t.outputs]:  # each port's element type and its bounds
            rename.update({f"{p}_{d}": f"{name}_{p}_{d}" for d in ("t", "min", "max")})
            lines += [f"    typedef uchar {name}_{p}_t;",
                      f"    const uchar {name}_{p}_min = 0, {name}_{p}_max = 255;"]
        lines += [f"    const {'float' if d.type == 'float' else 'int'} {name}_{p} = "
                  f"{d.default if not isinstance(d.default, bool) else int(d.default)};"
                  for p, d in t.params.items() if not d.shape]
        lines += [f"    const {'float' if d.element == 'float' else 'int'} {name}_{p}"
                  f"{''.join(f'[{n}]' for n in np.shape(d.default))} = "
                  f"{{{', '.join(map(str, np.ravel(d.default)))}}};"
                  for p, d in t.params.items() if d.shape]  # an array: Lut's table, a matrix
        defaults = {p: d.default for p, d in t.params.items()}
        tables = f.tables_of(defaults) if f.form == "stencil" else {}
        lines += [f"    const int {name}_{n}[{len(v)}] = {{{', '.join(map(str, v))}}};"
                  for n, v in tables.items()]  # GaussianBlur's weights
        lines += [f"    const int {name}_{n} = {v};"  # an array's lengths the snippet names
                  for n, v in f.lengths_of(defaults).items() if n in f.names]
        lines += [f"    {line}" for line in f.lines(rename, fills)]
        lines += ["}"] + [f"#undef {name}_{p}" for p in [*t.inputs, *f.stages]]
        lines += [f"#undef {fill}" for fill in fills.values()]
        functions.append("\n".join(lines))
        printed = "\n".join(f.lines(rename, fills))
        for old in rename:  # nothing of the old names is left
            assert not any(tok == old for tok in _identifiers(printed)), (name, old)
    calls = " + ".join(f"{n}(src, 1, 1, 0)" for n in _library_snippets())
    source = "\n\n".join(functions) + (
        "\n__kernel void all_snippets(__global const uchar *src, __global int *out)\n"
        f"{{\n    out[0] = {calls};\n}}\n")
    cl.Program(cl_context, source).build()


def _identifiers(text: str) -> list[str]:
    import re

    return re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text)


# -- queries the fusion pass and the kernel generator make ------------------------------------

def test_accessor_calls_and_shifted_arguments_are_read_from_the_tree():
    from gpucompgen.snippet import accessor_calls, is_name, is_shifted, parse, uses_outside_calls

    tree = parse("// image(0, 0, 0) in a comment is no call\n"
                 "const int a = image(y, (x + w), c), b = image(y, x - 2 * k, c);\n"
                 "return a + b + other(y, x * 2, 0);")
    calls = accessor_calls(tree, ["image", "other"])
    assert len(calls["image"]) == 2 and len(calls["other"]) == 1
    assert all(is_name(args[2], "c") for args in calls["image"])
    assert [is_shifted(args[1], "x") for args in calls["image"]] == [True, True]
    assert not is_shifted(calls["other"][0][1], "x")  # x * 2 moves the row
    assert not is_shifted(parse("return image(y, x + x, c);").body[0].value.args[1], "x")
    assert not uses_outside_calls(tree, ["image", "other"], {"x", "c"})
    assert uses_outside_calls(parse("return image(y, x, c) + x;"), ["image"], {"x"})


@pytest.mark.parametrize("text, ops", [
    # hand-counted: an operator, cast or built-in on a value of the element is one
    ("return image(y, x, c);", 0),  # a load only (loads are counted apart)
    ("return gain * 2.0f + 1.0f;", 0),  # parameters and constants: computed once
    ("return image(y, x, c) * gain + 1;", 2),
    ("return (float)image(y, x, c) * (gain * 2.0f);", 2),  # the cast; gain * 2 is hoisted
    ("return clamp(image(y, x, c), 0, 255);", 1),
    # a rule picked by a parameter: its dearest branch, one taken everywhere
    ("return gain > 1 ? image(y, x, c) + 1 : image(y, x, c) * 2 - 3;", 2),
    # a choice on the element's value: both branches and the select
    ("return image(y, x, c) > gain ? image(y, x, c) + 1 : image(y, x, c) * 2 - 3;", 5),
    # an 'if' whose body returns: the statements after it are its other branch (a type's
    # rule for float frames before its integer code), priced as the choices above
    ("if (gain > 1) return image(y, x, c) + 1; return image(y, x, c) * 2 - 3;", 2),
    ("if (gain > 1) { const int v = image(y, x, c); return v + 1; } return image(y, x, c);",
     1),
    ("if (image(y, x, c) > gain) return image(y, x, c) + 1; return image(y, x, c) * 2 - 3;",
     5),
    # a local of parameters is computed once; one of the element costs where computed
    ("const float k = gain * gain; const float v = image(y, x, c) * k; return v + k;", 2),
    # a local assigned after its declaration may change per element: never hoisted
    ("float k = gain; if (image(y, x, c) > 0) k = k + 1; return k * 2;", 4),
    ("int s = 0; s += image(y, x, c); return s;", 1),
])
def test_operations_count_the_arithmetic_of_an_element(text, ops):
    from gpucompgen.snippet import operations

    analysis = analyse(text, "pointwise", ["image"], ["out"], ["gain"])
    assert not analysis.problems
    assert operations(analysis.tree, analysis.names) == ops


@pytest.mark.parametrize("name, ops", [
    ("RgbToGray", 7),  # 3 multiplies, 3 adds, the shift; the loads are apart
    ("ThresholdGray", 3),  # the cast and compare of 'above', the select of one rule
    ("ConvertScaleGray", 4),  # cast, fma, fabs, saturating convert
])
def test_operations_of_library_snippets(name, ops):
    from gpucompgen.snippet import operations

    decl = library_types()[name].fusable
    assert operations(decl.tree, decl.names) == ops


# -- prune: the branches a build decides --------------------------------------------------
def _pruned(text: str, values: dict, types: dict) -> str:
    from gpucompgen.snippet.printer import print_text
    from gpucompgen.snippet.prune import prune
    from gpucompgen.snippet.syntax import parse

    tree = parse(text, {"src_t": "uchar"})  # src_t names a type (the port's element type)
    return print_text(prune(tree, values, types)).rstrip("\n")


SUMS = ("const bool whole = (src_t)0.5f == (src_t)0;\n"
        "if (whole) {\n    int s = src(y, x, c);\n    return s + 1;\n}\n"
        "float f = src(y, x, c);\nreturn f * scale;")


def test_prune_takes_the_branch_the_element_type_decides():
    # uint8: the integer branch in place, what follows its return dropped, 'whole' unread
    assert _pruned(SUMS, {}, {"src_t": "uchar"}) == \
        "int s = src(y, x, c);\nreturn s + 1;"
    # float32: the branch dropped, the rest kept; 'scale' (--set may change it) stays
    assert _pruned(SUMS, {}, {"src_t": "float"}) == "float f = src(y, x, c);\nreturn f * scale;"
    # an element type the build does not know: nothing decided
    assert "if (whole)" in _pruned(SUMS, {}, {})


def test_prune_follows_constants_and_keeps_what_it_cannot_decide():
    text = ("const int r = ksize / 2;\nif (r > 1 && src(y, x, c) > 3)\n    return 1;\n"
            "if (ksize == 3 || mode)\n    return 2;\nreturn 3;")
    # ksize 5: r is 2, the first condition still reads an element: kept; the second is
    # decided by ksize alone (|| of a false and an unknown: unknown): kept
    assert _pruned(text, {"ksize": 5}, {}) == text
    # ksize 3: r is 1, the first condition false whatever the element; the second true
    assert _pruned(text, {"ksize": 3}, {}) == "return 2;"
    # C's integer division and conversions: (uchar)300 is 44, -7 / 2 is -3
    assert _pruned("if ((uchar)300 == 44 && -7 / 2 == -3)\n    return 1;\nreturn 0;",
                   {}, {}) == "return 1;"


def test_prune_keeps_a_block_whose_names_the_rest_declares():
    text = "if (k == 1) {\n    int v = 1;\n    x += v;\n}\nint v = 2;\nreturn v + x;"
    assert _pruned(text, {"k": 1}, {}) == \
        "{\n    int v = 1;\n    x += v;\n}\nint v = 2;\nreturn v + x;"
