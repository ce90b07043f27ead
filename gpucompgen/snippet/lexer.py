"""The snippet lexer: C's translation phases 1 to 3, for the few characters a snippet has.

A snippet is read the way an OpenCL C compiler reads it, so that what the checker sees is
what the compiler would see, and then more strictly where the two could disagree:

- phase 1: trigraphs (``??=`` is ``#``, ``??/`` a backslash) are refused, in comments too:
  a compiler that maps them would read another program;
- line breaks are only the ones C knows (LF, CR LF, CR).  A character Python reads as a
  line break and C does not (U+2028, U+2029, U+0085, VT, FF, FS, GS, RS) is refused
  wherever it is: a checker that splits lines where the compiler does not ends a ``//``
  comment early and checks code the compiler never reads, or the reverse;
- phase 2: a backslash at the end of a line joins the lines in C (a ``//`` comment then
  swallows the next line).  Refused, in comments too;
- phase 3: comments are removed here (a comment is a space) and never reach the kernel:
  the kernel is printed from the parsed snippet.  Digraphs (``<%``, ``%>``, ``<:``,
  ``:>``, ``%:``) are refused: C reads them as braces, brackets and ``#``;
- no preprocessing: ``#`` is refused, so no line of a snippet can define a macro.

Tokens keep their offset in the snippet's text, for errors at the exact place.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .problems import SnippetError

# characters Python's str.splitlines() breaks at and C does not (C: \n, \r, \r\n)
FOREIGN_BREAKS = {"\v": "VT (vertical tab)", "\f": "FF (form feed)",
                  "\x1c": "FS", "\x1d": "GS", "\x1e": "RS", "\x85": "U+0085 (NEL)",
                  "\u2028": "U+2028 (LINE SEPARATOR)", "\u2029": "U+2029 (PARAGRAPH SEPARATOR)"}
TRIGRAPHS = {"=": "#", "(": "[", "/": "\\", ")": "]", "'": "^", "<": "{", "!": "|",
             ">": "}", "-": "~"}
DIGRAPHS = {"<%": "{", "%>": "}", "<:": "[", ":>": "]", "%:": "#"}
PUNCTUATORS = sorted(
    ["<<=", ">>=", "...", "->", "++", "--", "&&", "||", "<<", ">>", "<=", ">=", "==", "!=",
     "+=", "-=", "*=", "/=", "%=", "&=", "|=", "^=", "##",
     *"+-*/%<>=!&|^~?:;,.(){}[]#"], key=len, reverse=True)
_PUNCT = re.compile("|".join(re.escape(p) for p in PUNCTUATORS))
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
# a C preprocessing number: digits, letters, '_', '.', and a sign after an exponent letter
_PPNUMBER = re.compile(r"\.?[0-9](?:[eEpP][+-]|[0-9A-Za-z_.])*")
_SPACE = " \t\n\r"


@dataclass(frozen=True)
class Token:
    kind: str  # 'id', 'num', 'op', 'end'
    text: str
    offset: int  # in the snippet's text


def tokens(text: str) -> list[Token]:
    """The snippet's tokens, ending with an 'end' token; SnippetError at the first
    character C would read otherwise than this lexer, or that is not a snippet's."""
    _screen(text)
    found: list[Token] = []
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch in _SPACE:
            i += 1
        elif text.startswith("//", i):
            end = text.find("\n", i)
            cr = text.find("\r", i)
            ends = [e for e in (end, cr) if e >= 0]
            i = min(ends) if ends else n
        elif text.startswith("/*", i):
            end = text.find("*/", i + 2)
            if end < 0:
                raise SnippetError(i, "comment '/*' is never closed", "close it with '*/'")
            i = end + 2
        elif ch.isascii() and (ch.isalpha() or ch == "_"):
            m = _IDENT.match(text, i)
            found.append(Token("id", m.group(), i))
            i = m.end()
        elif ch.isascii() and (ch.isdigit() or (ch == "." and text[i + 1:i + 2].isdigit())):
            m = _PPNUMBER.match(text, i)
            found.append(Token("num", m.group(), i))
            i = m.end()
        elif (d := text[i:i + 2]) in DIGRAPHS:
            raise SnippetError(i, f"digraph '{d}' is not allowed in a snippet: C reads it "
                               f"as '{DIGRAPHS[d]}'", f"write '{DIGRAPHS[d]}' if that is meant"
                               if DIGRAPHS[d] != "#" else "a snippet has no preprocessor lines")
        elif (m := _PUNCT.match(text, i)) is not None:
            p = m.group()
            if p in ("#", "##"):
                raise SnippetError(i, "preprocessor lines ('#') are not allowed in a snippet",
                                   "use a const local or a parameter instead of a macro")
            found.append(Token("op", p, i))
            i = m.end()
        elif ch in "\"'":
            raise SnippetError(i, "string and character literals are not part of a snippet",
                               "a snippet computes a number; write it as a number")
        else:
            raise SnippetError(i, f"character {_shown(ch)} is not part of a snippet's OpenCL C",
                               "a snippet is ASCII OpenCL C code (comments may hold any text)")
    found.append(Token("end", "", n))
    return found


def _screen(text: str) -> None:
    """Phases 1 and 2, and line breaks: refused wherever they are, comments included."""
    for i, ch in enumerate(text):
        if ch in FOREIGN_BREAKS:
            raise SnippetError(i, f"character {FOREIGN_BREAKS[ch]} is not allowed in a snippet"
                               ": C does not read it as a line break where other tools do",
                               "end lines with a plain newline")
        if ch == "\x00":
            raise SnippetError(i, "a NUL character is not allowed in a snippet",
                               "remove it")
        if ch == "?" and text[i + 1:i + 2] == "?" and text[i + 2:i + 3] in TRIGRAPHS:
            t = text[i:i + 3]
            raise SnippetError(i, f"trigraph '{t}' is not allowed in a snippet: C may read it "
                               f"as '{TRIGRAPHS[t[2]]}'", "write the '?' characters apart")
        if ch == "\\":
            rest = text[i + 1:]
            stripped = rest.lstrip(" \t")
            if stripped[:1] in ("\n", "\r") or not stripped:
                raise SnippetError(i, "a backslash at the end of a line joins it with the next "
                                   "line in C (after '//' the next line is comment too)",
                                   "remove the backslash")


def _shown(ch: str) -> str:
    return repr(ch) if ch.isprintable() else f"U+{ord(ch):04X}"
