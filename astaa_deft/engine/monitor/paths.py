"""Fast reading of one field path (``[*]`` allowed) from decoded messages.

``astaa_deft.model.fields.get`` is general (it returns concrete paths, tolerates
anything); monitors read the same few paths from every message, so they
compile each path once into a closure that returns just the values, and
say precisely where the message stops matching its declared shape.
"""

from __future__ import annotations

from typing import Any, TypeGuard
from collections.abc import Callable, Sequence

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.fields import WILDCARD, FieldPath, Segment


class Missing(AstaaDeftError):
    """The message lacks (part of) the path; ``args[0]`` names the place."""


class EvaluationError(AstaaDeftError):
    """A message that does not have the shape a concrete path or expression reads."""


# A decoded message -> a value. Any, on purpose: an invariant's expression is type-checked by the
# expression language itself (``language.Ty``, when the spec is read), so at run time its closures
# add, compare and index values mypy cannot see the types of; each closure is one operation on the
# hot path, and narrowing there would cost every message what the reader already proved.
Evaluator = Callable[[Any], Any]


ValuesOf = Callable[[Any], list]


def compile_values(path: FieldPath) -> ValuesOf:
    """``message -> [value, ...]``: one value for a concrete path, every element's for ``[*]``.

    Raises ``Missing`` when a field or index the path needs is absent, or a
    value has the wrong shape (an object where an array should be...). An
    empty array under ``[*]`` yields no values: nothing to check.
    """
    segments = path.segments
    if all(type(s) is str for s in segments):
        return _concrete_values(segments)
    return lambda message: _expand(message, segments, 0, [])


def _concrete_values(segments: tuple) -> ValuesOf:
    if len(segments) == 1:
        key = segments[0]

        def top(message: Any) -> list:
            try:
                return [message[key]]
            except KeyError:
                raise Missing(key) from None

        return top

    def nested(message: Any) -> list:
        return [_follow(message, segments)]

    return nested


def _follow(value: Any, segments: Sequence) -> Any:
    for index, segment in enumerate(segments):
        if type(value) is not dict or segment not in value:
            raise Missing(str(FieldPath(tuple(segments[:index + 1]))))
        value = value[segment]
    return value


def _expand(value: Any, segments: tuple, start: int, out: list) -> list:
    for index in range(start, len(segments)):
        segment = segments[index]
        if type(segment) is str:
            if type(value) is not dict or segment not in value:
                raise Missing(str(FieldPath(segments[:index + 1])))
            value = value[segment]
            continue
        if type(value) is not list:
            raise Missing(f"{FieldPath(segments[:index])} (not an array)")
        if segment is WILDCARD:
            for element in value:
                _expand(element, segments, index + 1, out)
            return out
        position = segment if segment >= 0 else len(value) + segment
        if not 0 <= position < len(value):
            raise Missing(str(FieldPath(segments[:index + 1])))
        value = value[position]
    out.append(value)
    return out


def compile_getter(segments: tuple[str | int, ...]) -> Evaluator:
    """A closure reading one concrete field path; strict about shapes (a string is not an array)."""
    if len(segments) == 1 and isinstance(segments[0], str):
        key = segments[0]
        return lambda m: m[key]  # a decoded message is always an object
    if len(segments) == 2 and all(isinstance(s, str) for s in segments):
        k1, k2 = segments

        def get2(m: Any) -> Any:
            inner = m[k1]
            if type(inner) is not dict:
                raise EvaluationError(f"'{k1}' is not an object")
            return inner[k2]

        return get2
    return lambda m: follow(m, segments)


def follow(value: object, segments: Sequence[Segment]) -> object:
    """The value at a concrete path; EvaluationError/KeyError/IndexError when it is not there."""
    for segment in segments:
        if isinstance(segment, str):
            if type(value) is not dict:
                raise EvaluationError(f"expected an object holding '{segment}', got {type(value).__name__}")
            value = value[segment]
        else:
            if type(value) is not list or not isinstance(segment, int):  # a concrete path: no wildcard
                raise EvaluationError(f"expected an array to index [{segment}], got {type(value).__name__}")
            value = value[segment]
    return value


def is_number(value: object) -> TypeGuard[int | float]:
    """An int or a float exactly, as a decoded message holds numbers (not a bool, nor a subclass)."""
    return type(value) in (int, float)
