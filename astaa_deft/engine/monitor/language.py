"""The vocabulary of the expression language: its static types, functions and operators.

``expression.py`` compiles expressions with these; nothing outside this
vocabulary can appear in a monitor expression. The functions are pure, and
where IEEE arithmetic yields NaN or an infinity (``sqrt(-1)``, ``x / 0``)
they do too instead of raising: a strange value in a message leads to a
verdict, not to a stopped monitor.
"""

from __future__ import annotations

import ast
import math
import operator
from dataclasses import dataclass
from typing import Any
from collections.abc import Callable

from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS, FieldType
from astaa_deft.engine.monitor.paths import EvaluationError


@dataclass(frozen=True)
class Ty:
    """The static type of a sub-expression: number, bool, string, bytes, enum, struct, array."""

    kind: str
    ref: str | None = None  # struct: the message type name
    items: Ty | None = None  # array: the element type
    values: tuple[object, ...] = ()  # enum: the allowed values

    def describe(self) -> str:
        if self.kind == "struct":
            return f"a {self.ref} object"
        if self.kind == "array":
            return f"an array of {self.items.plural() if self.items else '?'}"
        if self.kind == "enum":
            return "enum(" + ", ".join(map(str, self.values)) + ")"
        return {"number": "a number", "bool": "a boolean", "string": "a string", "bytes": "bytes"}[self.kind]

    def plural(self) -> str:
        if self.kind == "struct":
            return f"{self.ref} objects"
        return {"number": "numbers", "bool": "booleans", "string": "strings", "bytes": "byte strings",
                "enum": "enum values", "array": "arrays"}[self.kind]


NUMBER, BOOL, STRING = Ty("number"), Ty("bool"), Ty("string")


def ty_of(field_type: FieldType) -> Ty:
    if field_type.kind in FLOAT_KINDS or field_type.kind in INT_KINDS or field_type.kind == "time":
        return NUMBER
    if field_type.kind == "bool":
        return BOOL
    if field_type.kind in ("string", "bytes"):
        return Ty(field_type.kind)
    if field_type.kind == "enum":
        return Ty("enum", values=field_type.values)
    if field_type.kind == "struct":
        return Ty("struct", ref=field_type.ref)
    assert field_type.items is not None
    return Ty("array", items=ty_of(field_type.items))


def is_text(t: Ty) -> bool:
    return t.kind == "string" or (t.kind == "enum" and all(isinstance(v, str) for v in t.values))


def comparable(a: Ty, b: Ty) -> bool:
    """May ``a == b`` ever be true? (enum against its value type, number against number...)"""
    if a.kind == "enum" or b.kind == "enum":
        enum, other = (a, b) if a.kind == "enum" else (b, a)
        if other.kind == "enum":
            return True
        return any(value_ty(v).kind == other.kind for v in enum.values)
    return a.kind == b.kind and a.kind in ("number", "bool", "string", "bytes")


def value_ty(value: object) -> Ty:
    if isinstance(value, bool):
        return BOOL
    if isinstance(value, (int, float)):
        return NUMBER
    return STRING


# ---------------------------------------------------------------- functions

def _sqrt(x: float) -> float:
    return math.sqrt(x) if x >= 0 else math.nan  # IEEE: sqrt of a negative is NaN, not an exception


def _length(x: Any) -> int:
    if type(x) not in (list, str, bytes):
        raise EvaluationError(f"len() of {type(x).__name__}")
    return len(x)


@dataclass(frozen=True)
class Function:
    impl: Callable[..., object]
    args: tuple[str, ...]  # static kind of each argument ("number" or "sized"); "..." = repeat the last
    result: Ty
    help: str


FUNCTIONS: dict[str, Function] = {
    "abs": Function(abs, ("number",), NUMBER, "abs(x)"),
    "min": Function(min, ("number", "number", "..."), NUMBER, "min(a, b, ...)"),
    "max": Function(max, ("number", "number", "..."), NUMBER, "max(a, b, ...)"),
    "len": Function(_length, ("sized",), NUMBER, "len(array or string)"),
    "isfinite": Function(math.isfinite, ("number",), BOOL, "isfinite(x)"),
    "isnan": Function(math.isnan, ("number",), BOOL, "isnan(x)"),
    "sqrt": Function(_sqrt, ("number",), NUMBER, "sqrt(x)"),
    "hypot": Function(math.hypot, ("number", "number", "..."), NUMBER, "hypot(x, y, ...)"),
    "sin": Function(math.sin, ("number",), NUMBER, "sin(radians)"),
    "cos": Function(math.cos, ("number",), NUMBER, "cos(radians)"),
    "atan2": Function(math.atan2, ("number", "number"), NUMBER, "atan2(y, x)"),
    "floor": Function(math.floor, ("number",), NUMBER, "floor(x)"),
    "ceil": Function(math.ceil, ("number",), NUMBER, "ceil(x)"),
}
FIELD_FUNCTION = "field"  # field("any.path[0]"): a path whose names are not Python identifiers


def _divide(a: float, b: float) -> float:
    try:
        return a / b
    except ZeroDivisionError:
        if math.isnan(a) or a == 0:
            return math.nan
        return math.copysign(math.inf, a) * math.copysign(1.0, b)


def _modulo(a: float, b: float) -> float:
    try:
        return a % b
    except ZeroDivisionError:
        return math.nan


def _power(a: float, b: float) -> float:
    # math.pow keeps huge operands from turning into hour-long big-int arithmetic
    return math.pow(a, b)


ARITHMETIC = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
              ast.Div: _divide, ast.Mod: _modulo, ast.Pow: _power}
COMPARISONS = {ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
               ast.Gt: operator.gt, ast.GtE: operator.ge}
ORDERINGS = (ast.Lt, ast.LtE, ast.Gt, ast.GtE)

# What a user meant by a construct we refuse, for the error message.
REFUSED = {
    ast.Lambda: "lambdas", ast.ListComp: "comprehensions", ast.SetComp: "comprehensions",
    ast.DictComp: "comprehensions", ast.GeneratorExp: "generator expressions", ast.Await: "await",
    ast.Yield: "yield", ast.YieldFrom: "yield", ast.NamedExpr: "assignments (:=)", ast.Starred: "* unpacking",
    ast.JoinedStr: "f-strings", ast.Dict: "dict literals", ast.Set: "set literals", ast.Slice: "slices",
}


def symbol(op: ast.AST) -> str:
    symbols = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Mod: "%", ast.Pow: "**",
               ast.FloorDiv: "//", ast.MatMult: "@", ast.BitAnd: "&", ast.BitOr: "|", ast.BitXor: "^",
               ast.LShift: "<<", ast.RShift: ">>", ast.USub: "-", ast.UAdd: "+", ast.Invert: "~", ast.Not: "not",
               ast.Is: "is", ast.IsNot: "is not", ast.Eq: "==", ast.NotEq: "!=", ast.Lt: "<", ast.LtE: "<=",
               ast.Gt: ">", ast.GtE: ">="}
    return "'" + symbols.get(type(op), type(op).__name__) + "'"
