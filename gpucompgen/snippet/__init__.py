"""The fusable snippet language: a lexer, a grammar, a resolver and a printer.

A type's ``fusable: value`` (docs/fusion.md) is OpenCL C for one output element.  It is
read once, at check time, the way a C compiler reads it (lexer.py: translation phases 1
to 3, stricter where tools could disagree), parsed by a whitelist grammar (syntax.py),
its names resolved and constants checked (check.py), and kept as a tree in the type
(``FusableDecl.tree``).  A kernel gets the tree printed (printer.py), with the names the
kernel generator chooses; the text as written never reaches a kernel.

Why a hand-written parser and not pycparser: a snippet is a few lines of a small subset,
but it is OpenCL C (vector types, vector literals ``(float4)(a, b, c, d)``, component
selection ``.s0``, ``half``, ``convert_uchar_sat_rte``), which pycparser reads only with
invented typedefs and reads wrongly for vector literals (as a cast of a comma
expression); pycparser needs preprocessed text (no comments), so its lexer could not be
the one that decides what a comment is, and its positions would be in a rewritten text,
not the snippet; and its tree is all of C99 (pointers, structs, goto, function
definitions), which a whitelist would have to take apart again.  The grammar here is the
whitelist itself, and every error is at an offset in the snippet as written.

API:
    analyse(text, form, inputs, outputs, params) -> Analysis(tree, names, problems)
    port_names(inputs, outputs) -> {name: what}: <port>_height, <port>_width and the
    port's element type <port>_t, which no parameter or port may be named
    print_lines(tree, rename=None) -> list[str]        (print_text: the same, joined)
    expression_text(node, rename=None) -> str
    accessor_calls(tree, ports), uses_outside_calls(tree, funcs, names), is_shifted(node,
    name), operations(tree, names): what fusion and the kernel generator ask of a snippet
    (query.py)
"""

from .check import MAX_SNIPPET, Analysis, analyse, is_builtin, port_names
from .printer import expression_text, names_in, print_lines, print_text
from .problems import Problem, SnippetError
from .query import accessor_calls, is_name, is_shifted, operations, uses_outside_calls
from .syntax import MAX_NESTING, Snippet, parse

__all__ = ["MAX_NESTING", "MAX_SNIPPET", "Analysis", "Problem", "Snippet", "SnippetError",
           "accessor_calls", "analyse", "expression_text", "is_builtin", "is_name",
           "is_shifted", "names_in", "operations", "parse", "port_names", "print_lines", "print_text",
           "uses_outside_calls"]
