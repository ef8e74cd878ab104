"""Field paths: naming fields of decoded messages and of the spec's types.

Syntax (see docs/codecs.md)::

    header.stamp              a field of a nested struct
    obstacles[2].position.x   an array element (0-based)
    points[-1].v              counted from the end (-1 is the last element)
    obstacles[*].speed        every element
    obstacles                 the array itself (e.g. to replace it by [])

A path always starts with a field name, since a message is an object. A
field name is any run of characters other than ``.``, ``[``, ``]``, ``*`` and
whitespace. Indices are written canonically (no ``+``, no leading zeros, no
``-0``), so ``str(FieldPath.parse(text)) == text`` for every valid text.

Two halves: ``get``/``set_field`` work on plain data (a decoded message);
``leaf_fields``/``type_at``/``is_brittle`` work on the declared types.
Pure logic, no I/O.
"""

from __future__ import annotations

import copy
import difflib
import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any
from collections.abc import Iterator, Mapping, Sequence

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.json import FieldValue
from astaa_deft.model.sut import FieldType, MessageType


class _Wildcard:
    """The ``[*]`` segment: every element of an array. Use the ``WILDCARD`` singleton."""

    def __repr__(self) -> str:
        return "WILDCARD"

    def __reduce__(self) -> str:
        return "WILDCARD"  # unpickles as the module's singleton, so `is` checks hold


WILDCARD = _Wildcard()

# A field name (str), an element index (int, negative counts from the end) or WILDCARD.
Segment = str | int | _Wildcard

_KEY = re.compile(r"[^.\[\]*\s]+")
_INDEX = re.compile(r"\[(?:(\*)|(-?[1-9][0-9]*|0))\]")


class FieldPathError(AstaaDeftError, ValueError):
    """A path that does not parse, or does not exist in a declared type.

    ``text`` is the path as written and ``position`` the 0-based offset of
    the offending character or segment in it, when known (for carets);
    ``reason`` is the message without the path, for callers that quote it.
    """

    def __init__(self, message: str, *, text: str | None = None, position: int | None = None,
                 reason: str | None = None):
        super().__init__(message)
        self.text = text
        self.position = position
        self.reason = reason or message


@dataclass(frozen=True)
class FieldPath:
    segments: tuple[Segment, ...]

    def __post_init__(self) -> None:
        if not self.segments or type(self.segments[0]) is not str:
            raise FieldPathError(f"a field path starts with a field name, got {self.segments!r}")
        for segment in self.segments:
            if type(segment) is str:
                if not _KEY.fullmatch(segment):
                    raise FieldPathError(f"invalid field name {segment!r} in a field path")
            elif type(segment) is not int and segment is not WILDCARD:
                raise FieldPathError(f"invalid field path segment {segment!r}")

    @classmethod
    def parse(cls, text: str) -> FieldPath:
        if not isinstance(text, str):
            raise FieldPathError(f"a field path is a string, got {type(text).__name__}")
        return _parse_cached(text)

    @classmethod
    def _trusted(cls, segments: tuple[Segment, ...]) -> FieldPath:
        """Skip validation for segments derived from a valid path: get() builds
        one path per match, and a wildcard over a big array has many."""
        path = object.__new__(cls)
        object.__setattr__(path, "segments", segments)
        return path

    def __str__(self) -> str:
        return _render(self.segments)

    def __repr__(self) -> str:
        return f"FieldPath({str(self)!r})"

    @property
    def is_concrete(self) -> bool:
        """True if the path names exactly one place (no ``[*]``, no negative index)."""
        return all(isinstance(s, str) or (isinstance(s, int) and s >= 0) for s in self.segments)

    def generalized(self) -> FieldPath:
        """Every index replaced by ``[*]``: ``obstacles[2].x`` -> ``obstacles[*].x``.

        Maps a concrete match back to the declared field it is an instance of.
        """
        return FieldPath._trusted(tuple(s if type(s) is str else WILDCARD for s in self.segments))

    def offset_of(self, index: int) -> int:
        """Where segment ``index`` starts in ``str(self)`` (for error carets)."""
        before = _render(self.segments[:index])
        return len(before) + (1 if index > 0 and type(self.segments[index]) is str else 0)


def _render(segments: Sequence[Segment]) -> str:
    parts: list[str] = []
    for segment in segments:
        if type(segment) is str:
            parts.append(f".{segment}" if parts else segment)
        else:
            parts.append("[*]" if segment is WILDCARD else f"[{segment}]")
    return "".join(parts)


PathLike = FieldPath | str


def as_path(path: PathLike) -> FieldPath:
    return path if isinstance(path, FieldPath) else FieldPath.parse(path)


# ---------------------------------------------------------------- parsing

@lru_cache(maxsize=4096)  # policies and invariants name the same few paths over and over
def _parse_cached(text: str) -> FieldPath:
    return FieldPath(tuple(_scan(text)))


def _scan(text: str) -> Iterator[Segment]:
    def fail(reason: str, position: int) -> FieldPathError:
        return FieldPathError(f"invalid field path {text!r}: {reason} (char {position})",
                              text=text, position=position, reason=reason)

    if not text:
        raise fail("empty path", 0)
    key = _KEY.match(text)
    if not key:
        raise fail("a path starts with a field name (a message is an object)", 0)
    yield key.group()
    position = key.end()
    while position < len(text):
        char = text[position]
        if char == ".":
            key = _KEY.match(text, position + 1)
            if not key:
                if text.startswith("*", position + 1):
                    raise fail("'*' is only allowed as an index: write [*] for every element", position + 1)
                raise fail("expected a field name after '.'", position + 1)
            yield key.group()
            position = key.end()
        elif char == "[":
            index = _INDEX.match(text, position)
            if not index:
                raise fail(_bad_index_reason(text, position), position)
            digits = index.group(2)
            if digits is not None and (len(digits.lstrip("-")) > len(str(MAX_INDEX)) or abs(int(digits)) > MAX_INDEX):
                raise fail(f"index {_shown_digits(digits)} is beyond any array (at most {MAX_INDEX})", position + 1)
            yield WILDCARD if index.group(1) else int(digits)
            position = index.end()
        elif char == "*":
            raise fail("'*' is only allowed as an index: write [*] for every element", position)
        elif char.isspace():
            raise fail("unexpected whitespace", position)
        elif char == "]":
            raise fail("']' without a matching '['", position)
        else:
            raise fail("expected '.' or '[' after ']'", position)


MAX_INDEX = 2**31 - 1  # no codec carries a longer array


def _shown_digits(digits: str) -> str:
    return digits if len(digits) <= 30 else f"{digits[:12]}…({len(digits)} digits)"


def _bad_index_reason(text: str, position: int) -> str:
    close = text.find("]", position)
    if close < 0:
        return "'[' is never closed"
    inside = text[position + 1:close]
    if re.fullmatch(r"[+-]?[0-9]+", inside) and len(inside) <= 30:
        return f"write [{int(inside)}], not [{inside}] (indices have no '+', leading zeros or -0)"
    return f"an index is an integer or *, got {inside!r}"


# ---------------------------------------------------------------- values

def get(value: object, path: PathLike) -> list[tuple[FieldPath, Any]]:
    """Every place ``path`` names in ``value``, as (concrete path, value), in document order.

    Missing fields, out-of-range indices and type mismatches (indexing an
    object, a field of a list) simply do not match.

    The values found are ``Any``, not ``FieldValue``: what a path names in a
    message is whatever the sender put there, and the readers (monitors,
    oracles, trajectory readers) use it as the shape they expect and take a
    TypeError/KeyError/ValueError as "not that shape"; a union would make
    each of them restate a check its ``except`` already makes.
    """
    path = as_path(path)
    return [(FieldPath._trusted(where), found) for where, found in _resolve(value, path.segments)]


def set_field(value: FieldValue, path: PathLike, new: FieldValue) -> list[tuple[FieldPath, FieldValue]]:
    """Replace what ``path`` names in ``value`` (in place) by ``new``; (concrete path, old value) per place.

    Only existing places are set: a missing field is not created. Each place
    gets its own copy of a list or dict ``new``, so places never alias each
    other or the caller's object.
    """
    path = as_path(path)
    *parent_segments, last = path.segments
    replaced: list[tuple[FieldPath, FieldValue]] = []
    for where, parent in _resolve(value, parent_segments):
        for slot in _slots(parent, last):
            replaced.append((FieldPath._trusted(where + (slot,)), parent[slot]))
            parent[slot] = copy.deepcopy(new) if isinstance(new, (dict, list)) else new
    return replaced


def _resolve(value: Any, segments: Sequence[Segment]) -> list[tuple[tuple[Segment, ...], Any]]:
    matches: list[tuple[tuple[Segment, ...], Any]] = [((), value)]
    for segment in segments:
        matches = [(where + (slot,), node[slot]) for where, node in matches for slot in _slots(node, segment)]
        if not matches:
            break
    return matches


def _slots(node: Any, segment: Segment) -> list[Any]:
    """The concrete keys/indices of ``node`` that ``segment`` names (0 or more)."""
    if isinstance(segment, str):
        return [segment] if type(node) is dict and segment in node else []
    if type(node) is not list:
        return []
    if not isinstance(segment, int):  # the wildcard
        return list(range(len(node)))
    index = segment if segment >= 0 else len(node) + segment
    return [index] if 0 <= index < len(node) else []


# ---------------------------------------------------------------- declared types

def leaf_fields(types: Mapping[str, MessageType], type_name: str) -> list[tuple[FieldPath, FieldType]]:
    """Every mutation target of ``type_name`` with its declared type, in declaration order.

    That is every leaf (scalar or enum) and every array itself (it may be
    replaced, e.g. by an empty list); array elements are written ``[*]``. A
    struct that contains itself (directly or not) is not expanded again: its
    fields are already listed one level up, and expanding would never end.
    """
    found: list[tuple[FieldPath, FieldType]] = []

    def visit(field_type: FieldType, where: tuple[Segment, ...], open_structs: frozenset[str]) -> None:
        if field_type.kind == "struct":
            assert field_type.ref is not None
            if field_type.ref not in open_structs:
                for name, child in message_type(types, field_type.ref).fields.items():
                    visit(child, where + (name,), open_structs | {field_type.ref})
        elif field_type.kind == "array":
            assert field_type.items is not None
            found.append((FieldPath(where), field_type))
            visit(field_type.items, where + (WILDCARD,), open_structs)
        else:
            found.append((FieldPath(where), field_type))

    visit(FieldType(kind="struct", ref=type_name), (), frozenset())
    return found


def type_at(types: Mapping[str, MessageType], type_name: str, path: PathLike) -> FieldType:
    """The declared type of ``path`` in ``type_name`` (concrete indices allowed).

    Raises ``FieldPathError`` naming the first segment that does not exist,
    with close field names as suggestions.
    """
    *_, last = _declared_types_along(types, type_name, as_path(path))
    return last


def _declared_types_along(types: Mapping[str, MessageType], type_name: str,
                          path: FieldPath) -> list[FieldType]:
    """The declared type before each segment of ``path`` and after the last one."""
    current = FieldType(kind="struct", ref=type_name)
    along = [current]
    for index, segment in enumerate(path.segments):
        step = _step_into(types, current, segment, where=_render(path.segments[:index]) or type_name)
        if isinstance(step, str):
            raise FieldPathError(f"field path {str(path)!r}: {step}", text=str(path),
                                 position=path.offset_of(index), reason=step)
        current = step
        along.append(current)
    return along


def _step_into(types: Mapping[str, MessageType], current: FieldType, segment: Segment,
               where: str) -> FieldType | str:
    """The declared type one segment below ``current`` (found at ``where``), or why there is none."""
    if type(segment) is str:
        if current.kind == "struct":
            fields = message_type(types, current.ref).fields
            if segment in fields:
                return fields[segment]
            return f"{current.ref} has no field {segment!r}{_suggest(segment, fields)}"
        if current.kind == "array":
            return f"{where!r} is an array ({current.describe()}); pick elements first, e.g. {where}[*].{segment}"
        return f"{where!r} is {current.describe()}, which has no field {segment!r}"
    if current.kind != "array" or current.items is None:
        return f"{where!r} is {current.describe()}, not an array, so it cannot be indexed"
    limit = current.max_length
    if segment is not WILDCARD and limit is not None and not -limit <= segment < limit:  # type: ignore[operator]
        return (f"index [{segment}] is outside {where!r} ({current.describe()}): "
                f"valid indices are 0..{limit - 1}, or -{limit}..-1 from the end" if limit else
                f"index [{segment}] is outside {where!r}, which is always empty ({current.describe()})")
    return current.items


def _suggest(name: str, known: Sequence[str] | Mapping[str, Any]) -> str:
    close = difflib.get_close_matches(name, list(known), n=3, cutoff=0.6)
    if close:
        return "; did you mean " + " or ".join(repr(c) for c in close) + "?"
    listed = list(known)
    shown = ", ".join(listed[:12]) + (", ..." if len(listed) > 12 else "")
    return f" (it has: {shown})" if listed else ""


def message_type(types: Mapping[str, MessageType], name: str | None) -> MessageType:
    try:
        return types[name]  # type: ignore[index]
    except KeyError:
        raise KeyError(f"unknown message type {name!r}{_suggest(str(name), types)}") from None


# ---------------------------------------------------------------- brittle fields

def parse_brittle_pattern(text: str) -> tuple[str, FieldPath]:
    """``"Header.stamp"`` -> ``("Header", FieldPath("stamp"))``.

    Patterns name declared fields, so the only index they may use is ``[*]``.
    """
    def fail(reason: str, position: int) -> FieldPathError:
        return FieldPathError(f"invalid brittle pattern {text!r}: {reason} (char {position})",
                              text=text, position=position, reason=reason)

    try:
        whole = FieldPath.parse(text)  # TypeName.sub.path is itself path syntax
    except FieldPathError as exc:
        if not exc.position:  # nothing usable as a type name
            raise fail("write TypeName.field, e.g. Header.stamp", 0) from None
        raise fail(exc.reason, exc.position) from None
    type_name, *sub_segments = whole.segments
    if not sub_segments or type(sub_segments[0]) is not str:
        raise fail("write TypeName.field, e.g. Header.stamp", len(str(type_name)))
    for index, segment in enumerate(whole.segments):
        if type(segment) is int:
            raise fail("patterns name fields, not elements: write [*] instead of an index",
                       whole.offset_of(index))
    return str(type_name), FieldPath(tuple(sub_segments))


def check_brittle_pattern(types: Mapping[str, MessageType], text: str) -> tuple[str, FieldPath]:
    """Parse a pattern and check that its type and path exist (for spec validation)."""
    type_name, sub_path = parse_brittle_pattern(text)
    if type_name not in types:
        raise FieldPathError(f"brittle pattern {text!r}: unknown type {type_name!r}{_suggest(type_name, types)}",
                             text=text, position=0)
    try:
        type_at(types, type_name, sub_path)
    except FieldPathError as exc:
        raise FieldPathError(f"brittle pattern {text!r}: {exc.reason}", text=text, reason=exc.reason,
                             position=len(type_name) + 1 + (exc.position or 0)) from None
    return type_name, sub_path


def is_brittle(types: Mapping[str, MessageType], type_name: str, path: PathLike,
               brittle_patterns: Sequence[str]) -> bool:
    """Whether ``path`` (in a ``type_name`` message) falls under a brittle pattern.

    ``TypeName.sub.path`` matches wherever a ``TypeName`` struct occurs,
    including the message itself; it covers that field and everything inside
    it (``Header.stamp`` also covers ``header.stamp.sec`` when a stamp is a
    struct). ``[*]`` in a pattern matches any index in the path. Raises
    ``FieldPathError`` if ``path`` does not exist in ``type_name``.
    """
    if not brittle_patterns:
        return False
    path = as_path(path)
    patterns = [_parse_brittle_cached(p) for p in brittle_patterns]
    declared = _declared_types_along(types, type_name, path)
    for start, owner in enumerate(declared[:-1]):
        if owner.kind != "struct":
            continue
        rest = path.segments[start:]
        for pattern_type, pattern_path in patterns:
            if pattern_type == owner.ref and _covers(pattern_path.segments, rest):
                return True
    return False


@lru_cache(maxsize=1024)
def _parse_brittle_cached(text: str) -> tuple[str, FieldPath]:
    return parse_brittle_pattern(text)


def _covers(pattern: Sequence[Segment], segments: Sequence[Segment]) -> bool:
    if len(pattern) > len(segments):
        return False
    for wanted, actual in zip(pattern, segments, strict=False):
        if type(wanted) is str:
            if wanted != actual:
                return False
        elif type(actual) is str:  # pattern indexes ([*]) where the path names a field
            return False
    return True
