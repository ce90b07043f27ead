"""Find a kernel's real definition in OpenCL C source and check it against the convention.

The source is never compiled here: comments, string and character literals are blanked
out first (keeping every newline, so lines still count), then the definition
``__kernel void NAME(...) {`` is found (also written ``kernel void``, with
``__attribute__((...))`` anywhere before the name), and its parameter list is read into
address space, constness, pointer and type, and compared with
:func:`convention.kernel_parameters`.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

from ...c_convention import KernelParam, kernel_parameters

ADDRESS_SPACES = {"__global": "global", "global": "global", "__local": "local",
                  "local": "local", "__constant": "constant", "constant": "constant",
                  "__private": "private", "private": "private"}
QUALIFIERS = {"const", "volatile", "restrict", "__restrict", "__restrict__", "__read_only",
              "read_only", "__write_only", "write_only"}
# multi-word C types and their OpenCL short names
SPELLINGS = {("unsigned", "char"): "uchar", ("signed", "char"): "char",
             ("unsigned", "short"): "ushort", ("signed", "short"): "short",
             ("unsigned", "int"): "uint", ("signed", "int"): "int", ("unsigned",): "uint",
             ("signed",): "int", ("unsigned", "short", "int"): "ushort",
             ("short", "int"): "short", ("unsigned", "long"): "ulong",
             ("long", "int"): "long"}
IDENT = re.compile(r"[A-Za-z_]\w*")
ATTRIBUTE = re.compile(r"\b__attribute__\s*\(\(")


class SignatureError(ValueError):
    """The kernel has no usable definition or its parameters break the convention."""

    def __init__(self, message: str, hint: str = "", line: int = 0):
        super().__init__(message)
        self.message, self.hint, self.line = message, hint, line


@dataclass(frozen=True)
class FoundParam:
    """One parameter as the kernel declares it."""

    text: str  # as written, whitespace collapsed
    name: str
    c_type: str  # the base type, OpenCL spelling ("uchar", "float", ...), or as written
    pointer: int  # number of '*'
    space: str  # "global" | "local" | "constant" | "private" | ""
    const: bool  # the pointed-to (or scalar) value is const


@dataclass(frozen=True)
class Definition:
    name: str
    line: int  # 1-based line of the name
    params: tuple[FoundParam, ...]

    def text(self) -> str:
        return f"__kernel void {self.name}({', '.join(p.text for p in self.params)})"


def strip(source: str) -> str:
    """The source with comments, string and character literals and preprocessor lines
    (``#define ...``, with their continuations) replaced by spaces; line breaks are kept
    so positions still hold."""
    out: list[str] = []
    i, n = 0, len(source)
    line_start = True  # only blanks since the last line break
    while i < n:
        c = source[i]
        two = source[i:i + 2]
        if two == "//" or (c == "#" and line_start):
            j = i
            while j < n and source[j] != "\n":
                if source[j] == "\\" and source[j + 1:j + 2] == "\n":  # continued line
                    j += 1
                j += 1
        elif two == "/*":
            j = source.find("*/", i + 2)
            j = n if j < 0 else j + 2
        elif c in "\"'":
            j = i + 1
            while j < n and source[j] != c and source[j] != "\n":
                j += 2 if source[j] == "\\" else 1
            j = min(j + 1, n)
        else:
            out.append(c)
            line_start = c == "\n" or (line_start and c in " \t")
            i += 1
            continue
        out.append(_blank(source[i:j]))
        i = j
    return "".join(out)


def _blank(text: str) -> str:
    return re.sub(r"[^\n]", " ", text)


def find_definition(source: str, name: str) -> Definition:
    """The definition of kernel name; raise SignatureError when there is none.

    One pass over the tokens: a hostile file of any shape takes linear time."""
    code = strip(source)
    declared_only = None
    other_kernels: list[str] = []
    for kname, at, open_at, close_at, defined in _kernel_declarators(code):
        if kname != name:
            if defined and len(other_kernels) < 10:
                other_kernels.append(kname)
            continue
        line = code.count("\n", 0, at) + 1
        if not defined:
            declared_only = declared_only or line
            continue
        return Definition(name, line, _params(code[open_at + 1:close_at], _typedefs(code),
                                              line))
    if declared_only is not None:
        raise SignatureError(f"'__kernel void {name}(...)' is declared "
                             "but never defined", "give the kernel its body", declared_only)
    hint = ("the file defines " + ", ".join(f"'{k}'" for k in other_kernels)
            if other_kernels else "define '__kernel void " + name + "(...) { ... }' "
            "(comments and strings do not count)")
    raise SignatureError(f"defines no '__kernel void {name}(...)'", hint)


TOKEN = re.compile(r"[A-Za-z_]\w*|[(){};]")


def _kernel_declarators(code: str) -> Iterator[tuple[str, int, int, int, bool]]:
    """(name, offset of the name, of '(', of ')', whether a body follows) of every
    ``[__]kernel ... void NAME(...)`` outside parentheses in code (comments, strings and
    preprocessor lines already blanked)."""
    depth = 0
    has_kernel, last_word, before_last, last_at = False, "", "", 0  # this declaration's
    candidate: tuple[str, int, int] | None = None  # a kernel declarator awaiting its ')'
    closed: tuple[str, int, int, int] | None = None  # what follows decides: body or not
    for m in TOKEN.finditer(code):
        tok = m.group()
        if depth > 0:
            if tok == "(":
                depth += 1
            elif tok == ")":
                depth -= 1
                if depth == 0 and candidate is not None:
                    closed, candidate = (*candidate, m.start()), None
            continue
        if tok == "(":
            if last_word != "__attribute__" and closed is None and has_kernel and \
                    before_last == "void":
                candidate = (last_word, last_at, m.start())
            depth = 1
            continue
        if tok == "__attribute__":  # attributes may stand before the body, or anywhere
            last_word = tok
            continue
        if closed is not None:
            yield (*closed, tok == "{")
            closed = None
        if tok in ("{", "}", ";", ")"):
            has_kernel, last_word, before_last = False, "", ""
        else:
            has_kernel |= tok in ("kernel", "__kernel")
            if last_word != "__attribute__":
                before_last = last_word
            last_word, last_at = tok, m.start()
    if closed is not None:
        yield (*closed, False)


def _drop_attributes(text: str) -> str:
    """text with every __attribute__((...)) removed (nested parentheses included)."""
    while True:
        m = ATTRIBUTE.search(text)
        if not m:
            return text
        close = _matching(text, m.end() - 2)
        text = text[:m.start()] + " " + (text[close + 1:] if close >= 0 else "")


def _matching(code: str, open_at: int) -> int:
    depth = 0
    for i in range(open_at, len(code)):
        if code[i] == "(":
            depth += 1
        elif code[i] == ")":
            depth -= 1
            if depth == 0:
                return i
    return -1


def _typedefs(code: str) -> dict[str, str]:
    """Simple typedefs of scalar types: ``typedef unsigned char pixel;``."""
    found = {}
    for m in re.finditer(r"\btypedef\s+([A-Za-z_][\w \t]{0,100}?)\s+([A-Za-z_]\w*)\s*;",
                         code):
        words = tuple(m[1].split())
        found[m[2]] = SPELLINGS.get(words, " ".join(words))
    return found


def _params(text: str, typedefs: dict[str, str], line: int) -> tuple[FoundParam, ...]:
    text = _drop_attributes(text)
    parts, depth, current = [], 0, []
    for c in text:
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        if c == "," and depth == 0:
            parts.append("".join(current))
            current = []
        else:
            current.append(c)
    parts.append("".join(current))
    parts = [" ".join(p.split()) for p in parts]
    if parts == ["void"] or parts == [""]:
        return ()
    return tuple(_param(p, typedefs, line) for p in parts)


def _param(text: str, typedefs: dict[str, str], line: int) -> FoundParam:
    tokens = re.findall(r"[A-Za-z_]\w*|\*|\[|\]|\S", text)
    space, const, pointer, type_words, name = "", False, 0, [], ""
    for tok in tokens:
        if tok in ADDRESS_SPACES:
            space = ADDRESS_SPACES[tok]
        elif tok == "const":
            if not pointer:  # 'const' after '*' makes the pointer const, not the data
                const = True
        elif tok in QUALIFIERS:
            continue
        elif tok == "*":
            pointer += 1
        elif tok == "[":
            pointer += 1  # an array parameter is a pointer
        elif IDENT.fullmatch(tok):
            if name:
                type_words.append(name)
            name = tok
    if not type_words:  # only a type, no name (allowed in C)
        type_words, name = [name], ""
    words = tuple(type_words)
    c_type = SPELLINGS.get(words) or (typedefs.get(words[0], words[0]) if len(words) == 1
                                      else " ".join(words))
    return FoundParam(text, name, c_type, pointer, space, const)


def check(ctype, source: str, function: str) -> Definition:
    """Check function's definition in source against the convention for ctype; raise
    SignatureError naming the first difference, with both parameter lists."""
    found = find_definition(source, function)
    wanted = kernel_parameters(ctype)
    expected = f"__kernel void {function}({', '.join(p.declaration() for p in wanted)})"
    hint = f"the calling convention needs\n          {expected}\n        the kernel has\n" \
           f"          {found.text()}"
    where = f"'{function}'"
    if len(found.params) != len(wanted):
        raise SignatureError(f"kernel {where} takes {len(found.params)} parameter(s), the "
                             f"calling convention passes {len(wanted)}", hint, found.line)
    for i, (want, have) in enumerate(zip(wanted, found.params), 1):
        problem = _mismatch(want, have)
        if problem:
            raise SignatureError(f"kernel {where}: parameter {i} '{have.text}' {problem}, "
                                 f"expected '{want.declaration()}'", hint, found.line)
    return found


def _mismatch(want: KernelParam, have: FoundParam) -> str:
    if want.kind == "buffer":
        what = f"the {want.role} buffer of port '{want.port}'"
        if have.pointer != 1 or have.space != "global":
            return f"is not a __global pointer ({what})"
        if have.c_type != want.c_type:
            return f"points to {have.c_type}, not {want.c_type} ({what})"
        if have.const and want.role == "output":
            return f"is const, but the kernel writes it ({what})"
        return ""
    what = {"size": f"the {want.dim} of port '{want.port}'",
            "param": f"parameter '{want.param}'", "tile": "the tile"}[want.role]
    if have.pointer or have.space not in ("", "private"):
        return f"must be a scalar ({what})"
    if have.c_type != want.c_type:
        return f"is {have.c_type}, not {want.c_type} ({what})"
    return ""
