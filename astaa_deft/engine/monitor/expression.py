"""The safe expression language of invariants: parsed once, checked, compiled to closures.

An expression is Python expression *syntax* over the fields of one message,
with a deliberately tiny meaning:

* field paths: ``speed``, ``header.stamp``, ``points[0].v``, ``points[-1].v``,
  ``field("odd-name.x")`` for names that are not identifiers;
* constants: numbers, strings, ``True``/``False``;
* arithmetic ``+ - * / % **`` and unary ``-``/``+`` on numbers (``/`` by zero
  gives ±inf or NaN, like IEEE floats, instead of stopping the monitor);
* comparisons (chains allowed), ``in``/``not in`` a literal tuple or list;
* ``and``, ``or``, ``not`` on booleans, ``a if cond else b``;
* the pure functions in ``language.FUNCTIONS``.

Nothing else parses into a monitor: no attribute of a Python object (a dot
always means a message field), no calls but the listed functions, no
lambdas, comprehensions, names outside the message, or subscripts other
than constant indices. Everything is type-checked against the channel's
declared message type before the run, so a typo or ``speed == 'fast'`` is a
spec error with its column, never a crash mid-run.

At run time a message may not match its declared type (a mutated or
malformed message): evaluation then raises one of ``RUNTIME_ERRORS``, which
monitors report as a violation ("cannot evaluate ...").
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from typing import Any
from collections.abc import Callable, Mapping, Sequence

from astaa_deft.model.errors import AstaaDeftError, did_you_mean
from astaa_deft.model.fields import WILDCARD, FieldPath, FieldPathError
from astaa_deft.model.sut import FieldType, MessageType
from astaa_deft.engine.monitor.language import (
    ARITHMETIC,
    BOOL,
    COMPARISONS,
    FIELD_FUNCTION,
    FUNCTIONS,
    NUMBER,
    ORDERINGS,
    REFUSED,
    STRING,
    Ty,
    comparable,
    is_text,
    symbol,
    ty_of,
)
from astaa_deft.engine.monitor.paths import EvaluationError, Evaluator, compile_getter, follow

MAX_LENGTH = 2000  # characters; a monitor expression longer than this is a mistake
MAX_DEPTH = 40  # nesting; keeps compile and evaluation recursion far from Python's limit

class ExpressionError(AstaaDeftError, ValueError):
    """An expression that is not allowed or does not type-check.

    ``position`` is the 0-based character offset in the expression text of
    the offending part; ``fix`` says what to write instead.
    """

    def __init__(self, message: str, position: int = 0, fix: str = ""):
        super().__init__(message)
        self.message = message
        self.position = position
        self.fix = fix


RUNTIME_ERRORS = (EvaluationError, KeyError, IndexError, TypeError, ValueError, OverflowError,
                  ZeroDivisionError, RecursionError)


def describe_runtime_error(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"missing field {exc.args[0]!r}" if exc.args else "missing field"
    if isinstance(exc, IndexError):
        return "index out of range"
    return str(exc) or type(exc).__name__


# ---------------------------------------------------------------- compiled form

@dataclass(frozen=True)
class CompiledExpression:
    text: str
    type: Ty
    fields: tuple[FieldPath, ...]  # every field the expression reads
    evaluate: Evaluator  # raises one of RUNTIME_ERRORS on a message of the wrong shape


@dataclass(frozen=True)
class _Part:
    ty: Ty
    fn: Evaluator
    constant: bool = False
    value: Any = None


def compile_expression(text: str, types: Mapping[str, MessageType], type_name: str,
                       want: Sequence[str] = ("bool",)) -> CompiledExpression:
    """Check ``text`` against ``type_name`` and compile it; ``want`` lists the accepted result kinds.

    Raises ``ExpressionError`` (with the offending position) for anything
    outside the language or not type-correct.
    """
    if not isinstance(text, str) or not text.strip():
        raise ExpressionError("the expression is empty", 0, 'write a condition, e.g. "speed <= 30"')
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"the expression is longer than {MAX_LENGTH} characters", MAX_LENGTH,
                              "split it into several invariants")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        # offset 0 means "at the end": the expression stops before it is complete
        position = (_offset(text, exc.lineno or 1, exc.offset - 1, byte_offset=False) if exc.offset
                    else len(text.rstrip()))
        raise ExpressionError(f"not a valid expression: {exc.msg}", position,
                              "write a Python-style condition, e.g. \"speed <= limit + 0.5\"") from None
    except (ValueError, RecursionError, MemoryError) as exc:
        raise ExpressionError(f"not a valid expression: {exc}", 0, "simplify it") from None
    compiler = _Compiler(text, types, type_name)
    part = compiler.node(tree.body, 0)
    if part.ty.kind not in want:
        wanted = " or ".join({"bool": "a condition (true/false)", "number": "a number"}.get(w, w) for w in want)
        raise ExpressionError(f"the expression gives {part.ty.describe()}, but {wanted} is needed",
                              0, "compare it, e.g. 'x > 0'" if "bool" in want else "give a numeric expression")
    return CompiledExpression(text, part.ty, tuple(compiler.fields), part.fn)


def _offset(text: str, lineno: int, col: int, byte_offset: bool = True) -> int:
    """Character offset in ``text`` of (1-based line, column) as ``ast`` reports it (UTF-8 bytes)."""
    stripped_lead = len(text) - len(text.lstrip())
    lines = text.strip().split("\n")
    line = lines[min(max(lineno, 1), len(lines)) - 1]
    if byte_offset:
        col = len(line.encode()[:col].decode(errors="ignore"))
    return stripped_lead + sum(len(text) + 1 for text in lines[:lineno - 1]) + max(col, 0)


class _Compiler:
    def __init__(self, text: str, types: Mapping[str, MessageType], type_name: str):
        self.text = text
        self.types = types
        self.type_name = type_name
        self.fields: list[FieldPath] = []

    def fail(self, node: ast.AST, message: str, fix: str = "") -> ExpressionError:
        column = getattr(node, "col_offset", 0)
        if isinstance(node, ast.Attribute) and node.end_col_offset is not None:
            column = node.end_col_offset - len(node.attr.encode())  # point at the field name, not the owner
        elif isinstance(node, ast.Subscript):
            column = getattr(node.slice, "col_offset", column)
        position = _offset(self.text, getattr(node, "lineno", 1), column)
        return ExpressionError(message, position, fix)

    # -- dispatch ----------------------------------------------------------
    def node(self, node: ast.AST, depth: int) -> _Part:
        if depth > MAX_DEPTH:
            raise self.fail(node, f"the expression is nested more than {MAX_DEPTH} levels deep", "simplify it")
        handler = getattr(self, "_" + type(node).__name__, None)
        if handler is None:
            what = REFUSED.get(type(node)) or f"'{type(node).__name__}' expressions"
            raise self.fail(node, f"{what} are not allowed in a monitor expression",
                            "use field paths, constants, comparisons, and/or/not, arithmetic and "
                            + ", ".join(sorted(FUNCTIONS)) + "()")
        return handler(node, depth + 1)

    # -- leaves ------------------------------------------------------------
    def _Constant(self, node: ast.Constant, depth: int) -> _Part:
        value = node.value
        if isinstance(value, bool):
            ty = BOOL
        elif isinstance(value, (int, float)):
            ty = NUMBER
        elif isinstance(value, str):
            ty = STRING
        else:
            raise self.fail(node, f"the constant {value!r} is not allowed",
                            "use numbers, strings, True or False")
        return _Part(ty, _constant(value), constant=True, value=value)

    def _Name(self, node: ast.Name, depth: int) -> _Part:
        return self._path(node, [(node.id, node)], depth)

    def _Attribute(self, node: ast.Attribute, depth: int) -> _Part:
        return self._path(node, self._chain(node), depth)

    def _Subscript(self, node: ast.Subscript, depth: int) -> _Part:
        return self._path(node, self._chain(node), depth)

    def _chain(self, node: ast.AST) -> list[tuple[str | int, ast.AST]]:
        """``points[0].v`` -> [("points", n), (0, n), ("v", n)]: the field path a node chain names."""
        if isinstance(node, ast.Name):
            return [(node.id, node)]
        if isinstance(node, ast.Attribute):
            return self._chain(node.value) + [(node.attr, node)]
        if isinstance(node, ast.Subscript):
            return self._chain(node.value) + [(self._index(node.slice, node), node)]
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == FIELD_FUNCTION:
            return [(s, node) for s in self._field_call_segments(node)]
        raise self.fail(node, "'.' and '[...]' apply to message fields only",
                        "write a field path such as points[0].v")

    def _index(self, index: ast.AST, owner: ast.AST) -> str | int:
        if isinstance(index, ast.Constant) and isinstance(index.value, str):
            return index.value  # header["stamp"]: a field named by a string
        sign = 1
        if isinstance(index, ast.UnaryOp) and isinstance(index.op, ast.USub):
            sign, index = -1, index.operand
        if isinstance(index, ast.Constant) and type(index.value) is int:
            return sign * index.value
        raise self.fail(owner, "an index must be a constant integer (e.g. points[0] or points[-1])",
                        "use a bound invariant with points[*] to check every element")

    def _field_call_segments(self, node: ast.Call) -> tuple:
        if len(node.args) != 1 or node.keywords or not (
                isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            raise self.fail(node, "field() takes one constant string, a field path",
                            'e.g. field("sensor-data.x")')
        try:
            path = FieldPath.parse(node.args[0].value)
        except FieldPathError as exc:
            raise self.fail(node.args[0], f"field(): {exc.reason}", "write a field path such as a.b[0].c") from None
        if not path.is_concrete and any(s is WILDCARD for s in path.segments):
            raise self.fail(node.args[0], "field() names one value; [*] is not allowed here",
                            "use a bound invariant to check every element")
        return path.segments

    def _path(self, node: ast.AST, chain: list[tuple[str | int, ast.AST]], depth: int) -> _Part:
        current = FieldType(kind="struct", ref=self.type_name)
        walked: list[str | int] = []
        for segment, seg_node in chain:
            if isinstance(segment, str) and segment.startswith("__"):
                raise self.fail(seg_node, f"'{segment}' is not allowed (names starting with '__' are reserved)",
                                "name a field of the message")
            where = str(FieldPath(tuple(walked))) if walked else self.type_name
            current = self._step(current, segment, seg_node, where)
            walked.append(segment)
        segments = tuple(walked)
        self.fields.append(FieldPath(segments))
        return _Part(ty_of(current), compile_getter(segments))

    def _step(self, current: FieldType, segment: str | int, node: ast.AST, where: str) -> FieldType:
        if isinstance(segment, str):
            if current.kind != "struct":
                raise self.fail(node, f"'{where}' is {ty_of(current).describe()}, which has no field '{segment}'",
                                f"index it first, e.g. {where}[0].{segment}" if current.kind == "array" else
                                "check the field path against the spec's types")
            declared = self.types.get(current.ref or "")
            fields = declared.fields if declared is not None else {}
            if segment not in fields:
                hint = did_you_mean(segment, fields) or f"{current.ref} has: {', '.join(fields)}"
                if segment in FUNCTIONS:
                    hint = f"call it: {FUNCTIONS[segment].help}"
                raise self.fail(node, f"unknown field '{segment}' in {current.ref}", hint)
            return fields[segment]
        if current.kind != "array" or current.items is None:
            raise self.fail(node, f"'{where}' is {ty_of(current).describe()}, not an array; it cannot be indexed",
                            "remove the [index]")
        return current.items

    # -- operators ---------------------------------------------------------
    def _BinOp(self, node: ast.BinOp, depth: int) -> _Part:
        op = ARITHMETIC.get(type(node.op))
        if op is None:
            raise self.fail(node, f"the operator {symbol(node.op)} is not allowed",
                            "use + - * / % ** on numbers")
        left, right = self.node(node.left, depth), self.node(node.right, depth)
        for side, part in (("left", left), ("right", right)):
            if part.ty.kind != "number":
                raise self.fail(node, f"{symbol(node.op)} needs numbers, but its {side} side is "
                                      f"{part.ty.describe()}", "arithmetic works on numeric fields only")
        lf, rf = left.fn, right.fn
        if right.constant:
            rv = right.value
            return _Part(NUMBER, lambda m: op(lf(m), rv))
        return _Part(NUMBER, lambda m: op(lf(m), rf(m)))

    def _UnaryOp(self, node: ast.UnaryOp, depth: int) -> _Part:
        operand = self.node(node.operand, depth)
        f = operand.fn
        if isinstance(node.op, ast.Not):
            self._need(operand, BOOL, node, "'not'")
            return _Part(BOOL, lambda m: not f(m))
        if isinstance(node.op, (ast.USub, ast.UAdd)):
            self._need(operand, NUMBER, node, f"unary {symbol(node.op)}")
            if operand.constant:
                value = -operand.value if isinstance(node.op, ast.USub) else operand.value
                return _Part(NUMBER, _constant(value), constant=True, value=value)
            return _Part(NUMBER, (lambda m: -f(m)) if isinstance(node.op, ast.USub) else f)
        raise self.fail(node, f"the operator {symbol(node.op)} is not allowed", "use -, + or not")

    def _BoolOp(self, node: ast.BoolOp, depth: int) -> _Part:
        parts = [self.node(v, depth) for v in node.values]
        name = "and" if isinstance(node.op, ast.And) else "or"
        for part, value in zip(parts, node.values, strict=False):
            self._need(part, BOOL, value, f"'{name}'")
        fns = tuple(p.fn for p in parts)
        if len(fns) == 2:
            a, b = fns
            return _Part(BOOL, (lambda m: a(m) and b(m)) if name == "and" else (lambda m: a(m) or b(m)))
        if name == "and":
            return _Part(BOOL, lambda m: all(f(m) for f in fns))
        return _Part(BOOL, lambda m: any(f(m) for f in fns))

    def _Compare(self, node: ast.Compare, depth: int) -> _Part:
        operands = [self.node(node.left, depth)]
        steps: list[tuple[Callable[[Any, Any], Any], _Part]] = []
        for op, comparator in zip(node.ops, node.comparators, strict=False):
            left = operands[-1]
            if isinstance(op, (ast.In, ast.NotIn)):
                right = self._member_set(comparator, left, node)
                fn = _membership(right.value, negated=isinstance(op, ast.NotIn))
            elif type(op) in COMPARISONS:
                right = self.node(comparator, depth)
                self._check_comparison(op, left, right, node)
                fn = COMPARISONS[type(op)]
            else:
                raise self.fail(node, f"the comparison {symbol(op)} is not allowed",
                                "use ==, !=, <, <=, >, >=, in, not in")
            operands.append(right)
            steps.append((fn, right))
        first = operands[0].fn
        if len(steps) == 1:
            fn, right = steps[0]
            if right.constant:
                rv = right.value
                return _Part(BOOL, lambda m: fn(first(m), rv))
            rf = right.fn
            return _Part(BOOL, lambda m: fn(first(m), rf(m)))
        chain = tuple((fn, right.fn) for fn, right in steps)

        def compare_chain(m: Mapping[str, Any]) -> bool:
            left_value = first(m)
            for fn, rf in chain:
                right_value = rf(m)
                if not fn(left_value, right_value):
                    return False
                left_value = right_value
            return True

        return _Part(BOOL, compare_chain)

    def _check_comparison(self, op: ast.cmpop, left: _Part, right: _Part, node: ast.AST) -> None:
        if isinstance(op, ORDERINGS):
            ok = (left.ty.kind == right.ty.kind == "number") or (is_text(left.ty) and is_text(right.ty))
            if not ok:
                raise self.fail(node, f"cannot order {left.ty.describe()} and {right.ty.describe()} "
                                      f"with {symbol(op)}", "compare numbers with numbers")
            return
        if not comparable(left.ty, right.ty):
            raise self.fail(node, f"{left.ty.describe()} is never equal to {right.ty.describe()}",
                            "compare values of the same type (quote strings, e.g. state == 'red')")
        for enum, other in ((left, right), (right, left)):
            if enum.ty.kind == "enum" and other.constant and other.value not in enum.ty.values:
                raise self.fail(node, f"{other.value!r} is not one of the enum's values "
                                      f"({', '.join(map(repr, enum.ty.values))})", "use one of those values")

    def _member_set(self, node: ast.AST, left: _Part, owner: ast.AST) -> _Part:
        if not isinstance(node, (ast.Tuple, ast.List)):
            raise self.fail(node, "'in' needs a literal list of constants on its right",
                            "e.g. state in ('red', 'yellow')")
        values = []
        for element in node.elts:
            part = self.node(element, 0)
            if not part.constant:
                raise self.fail(element, "'in' lists must hold constants only", "e.g. state in ('red', 'yellow')")
            self._check_comparison(ast.Eq(), left, part, element)
            values.append(part.value)
        return _Part(Ty("tuple"), lambda m: None, constant=True, value=tuple(values))

    def _IfExp(self, node: ast.IfExp, depth: int) -> _Part:
        test, body, orelse = (self.node(n, depth) for n in (node.test, node.body, node.orelse))
        self._need(test, BOOL, node.test, "the condition of 'if ... else'")
        if body.ty.kind != orelse.ty.kind:
            raise self.fail(node, f"both branches of 'if ... else' must have one type, not "
                                  f"{body.ty.describe()} and {orelse.ty.describe()}", "make them the same type")
        t, b, o = test.fn, body.fn, orelse.fn
        return _Part(body.ty, lambda m: b(m) if t(m) else o(m))

    def _Call(self, node: ast.Call, depth: int) -> _Part:
        if not isinstance(node.func, ast.Name):
            raise self.fail(node, "only the built-in functions can be called",
                            "available: " + ", ".join(f.help for f in FUNCTIONS.values()))
        name = node.func.id
        if name == FIELD_FUNCTION:
            return self._path(node, self._chain(node), depth)
        function = FUNCTIONS.get(name)
        if function is None:
            hint = did_you_mean(name, FUNCTIONS) or "available: " + ", ".join(f.help for f in FUNCTIONS.values())
            prefix = f"'{name}' is not allowed; " if name.startswith("__") else ""
            raise self.fail(node, f"{prefix}unknown function '{name}'", hint)
        if node.keywords:
            raise self.fail(node, f"{name}() takes no keyword arguments", function.help)
        args = [self.node(a, depth) for a in node.args]
        kinds = function.args
        variadic = kinds[-1] == "..."
        fixed = kinds[:-1] if variadic else kinds
        if len(args) < len(fixed) or (not variadic and len(args) > len(fixed)):
            raise self.fail(node, f"{name}() takes {'at least ' if variadic else ''}{len(fixed)} "
                                  f"argument{'s' if len(fixed) != 1 else ''}, got {len(args)}", function.help)
        for index, (arg, arg_node) in enumerate(zip(args, node.args, strict=False)):
            kind = fixed[min(index, len(fixed) - 1)]
            ok = arg.ty.kind in ("array", "string", "bytes") if kind == "sized" else arg.ty.kind == kind
            if not ok:
                wanted = "an array or a string" if kind == "sized" else "a number"
                raise self.fail(arg_node, f"{name}() needs {wanted}, got {arg.ty.describe()}", function.help)
        impl = function.impl
        fns = tuple(a.fn for a in args)
        if len(fns) == 1:
            (f,) = fns
            return _Part(function.result, lambda m: impl(f(m)))
        if len(fns) == 2:
            f, g = fns
            return _Part(function.result, lambda m: impl(f(m), g(m)))
        return _Part(function.result, lambda m: impl(*[f(m) for f in fns]))

    # -- helpers -----------------------------------------------------------
    def _need(self, part: _Part, ty: Ty, node: ast.AST, what: str) -> None:
        if part.ty.kind != ty.kind:
            raise self.fail(node, f"{what} needs {ty.describe()}, got {part.ty.describe()}",
                            "compare it to get a boolean, e.g. x > 0" if ty is BOOL else "use a numeric field")


def _constant(value: Any) -> Evaluator:
    return lambda message: value


def _membership(values: tuple, negated: bool) -> Callable[[Any, Any], bool]:
    """``a in (...)`` as a comparison step; the right operand is the literal list itself."""
    if negated:
        return lambda left, _right: left not in values
    return lambda left, _right: left in values


__all__ = ["RUNTIME_ERRORS", "CompiledExpression", "EvaluationError", "ExpressionError", "Ty",
           "compile_expression", "describe_runtime_error", "follow", "ty_of"]
