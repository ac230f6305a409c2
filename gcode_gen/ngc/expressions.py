"""RS274/NGC values: numbers, parameter references, ``[ ]`` expressions and functions.

A value is parsed once into a small tree of tuples and evaluated each time its line runs
(loops run a line many times).  The grammar is LinuxCNC's (interp_read.cc):

* operators, loosest first: ``AND OR XOR`` < ``EQ NE GT GE LT LE`` < ``+ -`` <
  ``* / MOD`` < ``**`` (power); left-associative; only inside ``[ ]``;
* unary ``+``/``-`` before any value;
* functions ``ABS ACOS ASIN COS EXP FIX FUP LN ROUND SIN SQRT TAN`` of a ``[ ]`` argument
  (angles in degrees), ``ATAN[y]/[x]`` (two arguments, degrees), ``EXISTS[#<name>]``;
* ``#n``, ``#[expr]``, ``##n`` numbered parameters, ``#<name>`` named parameters.

Comparisons give 1.0 or 0.0; ``EQ``/``NE`` compare within 1e-4 (LinuxCNC's
``TOLERANCE_EQUAL``); ``a MOD b`` is fmod(a, b) made non-negative by adding |b|, as LinuxCNC.
"""

from __future__ import annotations

import math
from typing import Callable, Union

__all__ = ["Expr", "ExprError", "parse_value", "evaluate"]

#: A parsed value: ("num", v) | ("param", Expr) | ("named", name) | ("neg", Expr) |
#: ("bin", op, Expr, Expr) | ("fn", name, Expr) | ("atan", Expr, Expr) | ("exists", name)
Expr = tuple

TOLERANCE_EQUAL = 1e-4  # LinuxCNC's TOLERANCE_EQUAL


class ExprError(ValueError):
    """A value or expression cannot be read or evaluated; the caller adds the line."""


_BINARY = [  # (token, precedence); longest tokens first so "**" wins over "*"
    ("**", 5), ("*", 4), ("/", 4), ("mod", 4), ("+", 3), ("-", 3),
    ("eq", 2), ("ne", 2), ("gt", 2), ("ge", 2), ("lt", 2), ("le", 2),
    ("and", 1), ("or", 1), ("xor", 1),
]
_UNARY = ("abs", "acos", "asin", "atan", "cos", "exists", "exp", "fix", "fup", "ln", "round", "sin", "sqrt", "tan")


def parse_value(text: str, pos: int) -> tuple[Expr, int]:
    """Parse one real value of normalised (lower-case, no blanks) ``text`` at ``pos``.

    Returns the tree and the position after it.
    """
    if pos >= len(text):
        raise ExprError("value missing at the end of the line")
    ch = text[pos]
    if ch == "[":
        expr, pos = _parse_expression(text, pos + 1)
        return expr, pos
    if ch == "#":
        return _parse_parameter(text, pos + 1)
    if ch in "+-":
        inner, pos = parse_value(text, pos + 1)
        return (inner if ch == "+" else ("neg", inner)), pos
    if ch.isalpha():
        return _parse_function(text, pos)
    end = pos
    while end < len(text) and (text[end].isdigit() or text[end] == "."):
        end += 1
    number = text[pos:end]
    if not number or number.count(".") > 1 or number == ".":
        raise ExprError(f"bad number or value at {text[pos:pos + 12]!r}")
    return ("num", float(number)), end


def _parse_parameter(text: str, pos: int) -> tuple[Expr, int]:
    if pos < len(text) and text[pos] == "<":
        end = text.find(">", pos)
        if end < 0:
            raise ExprError("named parameter '#<' is not closed with '>'")
        name = text[pos + 1:end]
        if not name:
            raise ExprError("empty parameter name '#<>'")
        return ("named", name), end + 1
    index, pos = parse_value(text, pos)
    return ("param", index), pos


def _parse_function(text: str, pos: int) -> tuple[Expr, int]:
    end = pos
    while end < len(text) and text[end].isalpha():
        end += 1
    word = text[pos:end]
    name = next((f for f in _UNARY if word.startswith(f) and word == f), None)
    if name is None:
        raise ExprError(f"unknown function or word {word.upper()!r} in a value")
    if end >= len(text) or text[end] != "[":
        raise ExprError(f"function {name.upper()} needs an argument in [ ]")
    if name == "exists":
        inner_end = text.find("]", end)
        if inner_end < 0 or not text.startswith("#<", end + 1) or text[inner_end - 1] != ">":
            raise ExprError("EXISTS needs a named parameter: EXISTS[#<name>]")
        return ("exists", text[end + 3:inner_end - 1]), inner_end + 1
    arg, pos = _parse_expression(text, end + 1)
    if name == "atan":
        if not text.startswith("/[", pos):
            raise ExprError("ATAN needs two arguments: ATAN[y]/[x]")
        arg2, pos = _parse_expression(text, pos + 2)
        return ("atan", arg, arg2), pos
    return ("fn", name, arg), pos


def _parse_expression(text: str, pos: int) -> tuple[Expr, int]:
    """Parse after an opening ``[`` up to and including its ``]``."""
    values: list[Expr] = []
    ops: list[tuple[str, int]] = []
    value, pos = parse_value(text, pos)
    values.append(value)
    while True:
        if pos >= len(text):
            raise ExprError("expression '[' is not closed with ']'")
        if text[pos] == "]":
            pos += 1
            break
        op = next(((tok, prec) for tok, prec in _BINARY if text.startswith(tok, pos)), None)
        if op is None:
            raise ExprError(f"unknown operator at {text[pos:pos + 8]!r}")
        pos += len(op[0])
        while ops and ops[-1][1] >= op[1]:  # left-associative
            _reduce(values, ops)
        ops.append(op)
        value, pos = parse_value(text, pos)
        values.append(value)
    while ops:
        _reduce(values, ops)
    return values[0], pos


def _reduce(values: list[Expr], ops: list[tuple[str, int]]) -> None:
    b, a = values.pop(), values.pop()
    values.append(("bin", ops.pop()[0], a, b))


Lookup = Callable[[Union[int, str]], float]


def evaluate(expr: Expr, numbered: Callable[[int], float], named: Callable[[str], float],
             exists: Callable[[str], bool]) -> float:
    """Value of ``expr`` with parameters read through the three callbacks."""
    kind = expr[0]
    if kind == "num":
        return expr[1]
    if kind == "neg":
        return -evaluate(expr[1], numbered, named, exists)
    if kind == "param":
        index = evaluate(expr[1], numbered, named, exists)
        if abs(index - round(index)) > 1e-4:
            raise ExprError(f"parameter number #{index:g} is not an integer")
        return numbered(int(round(index)))
    if kind == "named":
        return named(expr[1])
    if kind == "exists":
        return 1.0 if exists(expr[1]) else 0.0
    if kind == "atan":
        y = evaluate(expr[1], numbered, named, exists)
        x = evaluate(expr[2], numbered, named, exists)
        return math.degrees(math.atan2(y, x))
    if kind == "fn":
        return _function(expr[1], evaluate(expr[2], numbered, named, exists))
    a = evaluate(expr[2], numbered, named, exists)
    b = evaluate(expr[3], numbered, named, exists)
    return _binary(expr[1], a, b)


def _function(name: str, x: float) -> float:
    if name in ("acos", "asin") and not -1.0 <= x <= 1.0:
        raise ExprError(f"{name.upper()}[{x:g}]: argument outside [-1, 1]")
    if name == "sqrt" and x < 0:
        raise ExprError(f"SQRT[{x:g}] of a negative number")
    if name == "ln" and x <= 0:
        raise ExprError(f"LN[{x:g}] of a number <= 0")
    table = {
        "abs": abs, "exp": math.exp, "ln": math.log, "sqrt": math.sqrt,
        "fix": math.floor, "fup": math.ceil,
        "round": lambda v: float(math.floor(v + 0.5)) if v >= 0 else -float(math.floor(-v + 0.5)),
        "sin": lambda v: math.sin(math.radians(v)), "cos": lambda v: math.cos(math.radians(v)),
        "tan": lambda v: math.tan(math.radians(v)),
        "asin": lambda v: math.degrees(math.asin(v)), "acos": lambda v: math.degrees(math.acos(v)),
        "atan": lambda v: math.degrees(math.atan(v)),
    }
    return float(table[name](x))


def _binary(op: str, a: float, b: float) -> float:
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "/":
        if b == 0:
            raise ExprError("division by zero")
        return a / b
    if op == "mod":
        if b == 0:
            raise ExprError("MOD by zero")
        r = math.fmod(a, b)
        return r + abs(b) if r < 0 else r
    if op == "**":
        if a < 0 and b != math.floor(b):
            raise ExprError(f"{a:g} ** {b:g}: negative base with a fractional exponent")
        return float(a ** b)
    if op == "eq":
        return float(abs(a - b) < TOLERANCE_EQUAL)
    if op == "ne":
        return float(abs(a - b) >= TOLERANCE_EQUAL)
    if op == "gt":
        return float(a > b)
    if op == "ge":
        return float(a >= b)
    if op == "lt":
        return float(a < b)
    if op == "le":
        return float(a <= b)
    if op == "and":
        return float(a != 0 and b != 0)
    if op == "or":
        return float(a != 0 or b != 0)
    return float((a != 0) != (b != 0))  # xor
