"""RS274/NGC lines → words, parameter assignments and O-word statements.

LinuxCNC reads a line case-insensitively and ignores blanks outside comments (so
``#<_foo bar>`` is ``#<_foobar>``); ``( )`` comments may not nest and end on the line;
``;`` starts a comment to the end of the line; a leading ``/`` marks a block-delete line
(executed: block delete is off, as rs274's default).  A line is either empty, ``%``, an
O-word statement (``o100 sub``, ``o<name> call [1] [2]``, ``o1 if [#1 gt 0]`` …) or a block
of words whose values are numbers, parameters or expressions, with ``#n=value`` /
``#<name>=value`` assignments.  ``@`` (polar radius) and ``^`` (polar angle) are words.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gcode_gen.ngc.expressions import Expr, ExprError, parse_value

__all__ = ["Line", "lex_line", "OWORD_KEYWORDS", "WORD_LETTERS"]

OWORD_KEYWORDS = ("sub", "endsub", "call", "return", "if", "elseif", "else", "endif", "do", "while",
                  "endwhile", "repeat", "endrepeat", "break", "continue")
#: Word letters LinuxCNC reads (``@`` and ``^`` are polar radius and angle).
WORD_LETTERS = "abcdefghijklmnpqrstuvwxyz@^"


@dataclass
class Line:
    """One program line after lexing.

    kind : "empty", "percent", "oword", "program_number" (a bare ``O1234``) or "block".
    comments : comment texts as written (for the ``key=value`` header).
    n : block number of a leading ``N`` word.
    words : (letter, value) in order, letters lower case.
    assignments : (parameter reference, value): the target is ("param", Expr) or ("named", name).
    label, keyword, args : of an O-word statement (label lower case: "100" or "<name>").
    """

    number: int
    kind: str
    comments: list[str] = field(default_factory=list)
    n: int | None = None
    words: list[tuple[str, Expr]] = field(default_factory=list)
    assignments: list[tuple[Expr, Expr]] = field(default_factory=list)
    label: str = ""
    keyword: str = ""
    args: list[Expr] = field(default_factory=list)


def _normalise(raw: str) -> tuple[str, list[str]]:
    """Code text (lower case, blanks removed) and the comments of one raw line."""
    out: list[str] = []
    comments: list[str] = []
    i = 0
    while i < len(raw):
        ch = raw[i]
        if ch == "(":
            j = raw.find(")", i + 1)
            if j < 0:
                raise ExprError("comment '(' is not closed on the same line")
            if "(" in raw[i + 1:j]:
                raise ExprError("nested comment '(' inside '( )'")
            comments.append(raw[i + 1:j])
            i = j + 1
        elif ch == ";":
            comments.append(raw[i + 1:])
            break
        else:
            if not ch.isspace():
                out.append(ch.lower())
            i += 1
    return "".join(out), comments


def lex_line(raw: str, number: int) -> Line:
    """Lex one raw line (``number`` is its 1-based line number)."""
    code, comments = _normalise(raw)
    if code.startswith("/"):
        code = code[1:]
    if not code:
        return Line(number, "empty", comments)
    if code == "%":
        return Line(number, "percent", comments)
    line = Line(number, "block", comments)
    pos = 0
    if code[0] == "n" and len(code) > 1 and code[1].isdigit():
        end = 1
        while end < len(code) and code[end].isdigit():
            end += 1
        while end < len(code) and (code[end].isdigit() or code[end] == "."):
            end += 1
        line.n = int(float(code[1:end]))
        pos = end
    if code.startswith("o", pos):
        return _lex_oword(code, pos + 1, line)
    while pos < len(code):
        ch = code[pos]
        if ch == "#":
            target, pos = parse_value(code, pos)
            if pos >= len(code) or code[pos] != "=":
                raise ExprError("a parameter reference '#' at the start of a word must be an assignment '#…=value'")
            value, pos = parse_value(code, pos + 1)
            line.assignments.append((target, value))
            continue
        if ch not in WORD_LETTERS:
            raise ExprError(f"unknown word {code[pos:pos + 10].upper()!r}")
        value, pos = parse_value(code, pos + 1)
        line.words.append((ch, value))
    return line


def _lex_oword(code: str, pos: int, line: Line) -> Line:
    line.kind = "oword"
    if code.startswith("<", pos):
        end = code.find(">", pos)
        if end < 0:
            raise ExprError("O-word name 'o<' is not closed with '>'")
        label, pos = code[pos:end + 1], end + 1
    else:
        end = pos
        while end < len(code) and code[end].isdigit():
            end += 1
        if end == pos:
            raise ExprError(f"O-word without a number or <name> at {code[pos - 1:pos + 10].upper()!r}")
        label, pos = str(int(code[pos:end])), end
    keyword = next((k for k in sorted(OWORD_KEYWORDS, key=len, reverse=True) if code.startswith(k, pos)), None)
    if keyword is None and pos == len(code) and label.isdigit():
        line.kind, line.label = "program_number", label
        return line
    if keyword is None:
        raise ExprError(f"O-word o{label} without a keyword (sub, call, if, while, repeat, …): "
                        f"{code[pos:pos + 10].upper()!r}")
    line.label, line.keyword = label, keyword
    pos += len(keyword)
    while pos < len(code):
        if code[pos] != "[":
            raise ExprError(f"unexpected {code[pos:pos + 10].upper()!r} after o{label} {keyword}")
        value, pos = parse_value(code, pos)
        line.args.append(value)
    return line
