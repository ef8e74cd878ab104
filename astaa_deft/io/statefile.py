"""The one way the tool reads back state it wrote itself: schema-checked, or one ``InputError``.

A checkpoint (``extraction.json``), a campaign journal's rows and settings,
a run's metadata: the tool wrote them, but they sit on a disk anyone may
edit, so reading one back is reading input. Each is read here: JSON text
within a size cap and a nesting depth (``load_json``: no ``RecursionError``,
no ``JSONDecodeError`` escapes), then field by field through a
:class:`StateReader` that checks each value's type and range (integers
bounded, numbers finite unless stated, texts and lists of bounded length,
versions this one knows). Any mismatch is one ``InputError`` naming the
file, the field (``decided[3].choice.pose``) and the fix — exit 2, never a
traceback and never a silently wrong value.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from typing import NoReturn, TypeVar

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import JsonObject, JsonValue

MAX_DEPTH = 32  # nesting of any state value: the tool writes at most ~6
MAX_TEXT = 16 << 20  # characters of one JSON text (a journal cell, a checkpoint: far more than real ones)
MAX_INT = 2**63 - 1  # what SQLite, MCAP and nanosecond times hold
MAX_ITEMS = 10_000_000  # items of one list or object (more than any real state file has)
MAX_NAME = 1000  # characters of a field name (a channel, an invariant, a param)

T = TypeVar("T")


def load_json(text: str | bytes, file: str, field: str, fix: str, *, max_chars: int = MAX_TEXT,
              max_depth: int = MAX_DEPTH) -> JsonValue:
    """``text`` parsed as JSON (NaN/Infinity as Python reads them); InputError naming ``file`` and ``field``
    when it is too long, not JSON, or nested deeper than ``max_depth``."""
    if len(text) > max_chars:
        _fail(file, field, f"is {len(text):,} characters long (at most {max_chars:,})", fix)
    try:
        value = json.loads(text)
    except RecursionError:  # the C decoder gives up at the interpreter's depth: deeper than any real state
        _fail(file, field, f"is nested deeper than {max_depth} levels", fix)
    except (ValueError, TypeError) as exc:  # not UTF-8, not JSON
        _fail(file, field, f"is not JSON ({_short(exc)})", fix)
    depth = nesting(value)
    if depth > max_depth:
        _fail(file, field, f"is nested {depth} levels deep (at most {max_depth})", fix)
    return value


def nesting(value: object) -> int:
    """How deep lists and objects nest in ``value`` (a scalar: 0), without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (list, dict)):
            deepest = max(deepest, depth)
            stack.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def _short(exc: BaseException) -> str:
    text = str(exc)
    return text if len(text) <= 120 else text[:120] + "…"


def _fail(file: str, field: str, what: str, fix: str) -> NoReturn:
    name = f"field '{field}'" if field else "the content"
    raise InputError(Problem(file, None, None, f"{name} {what}", fix))


def _kind(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, int):
        return "a whole number"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "text"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


class StateReader:
    """One value of a state file, at ``field`` of ``file``: read as a given type, or an InputError with ``fix``.

    ``StateReader(file, value, fix, field=...).obj()`` checks the value is an object; ``get(name)`` steps into a field
    (a missing one reads as absent: ``present``; ``fields(*names)`` several), ``integer``, ``number``, ``text``,
    ``flag``, ``items``, ``entries`` read it.
    """

    __slots__ = ("file", "value", "fix", "field", "present")

    def __init__(self, file: str, value: object, fix: str, *, field: str = "", present: bool = True) -> None:
        self.file, self.value, self.fix, self.field, self.present = file, value, fix, field, present

    def fail(self, what: str) -> NoReturn:
        _fail(self.file, self.field, what, self.fix)

    def _expected(self, what: str) -> NoReturn:
        self.fail(f"is missing ({what} expected)" if not self.present
                  else f"must be {what}, not {_kind(self.value)}")

    def _child(self, name: str) -> str:
        return f"{self.field}.{name}" if self.field else name

    # -- structure -----------------------------------------------------------
    def obj(self) -> StateReader:
        """This value, checked to be an object."""
        if not isinstance(self.value, dict):
            self._expected("an object")
        if len(self.value) > MAX_ITEMS:
            self.fail(f"has {len(self.value):,} fields (at most {MAX_ITEMS:,})")
        return self

    def json_object(self) -> JsonObject:
        """This value, checked to be an object, as it is: for a record's ``from_json``, which reads its fields."""
        value = self.obj().value
        assert isinstance(value, dict)
        return value

    def get(self, name: str) -> StateReader:
        """The field ``name`` of this object (absent: ``present`` False, value None)."""
        assert isinstance(self.value, dict)
        return StateReader(self.file, self.value.get(name), self.fix, field=self._child(name),
                           present=name in self.value)

    def fields(self, *names: str) -> tuple[StateReader, ...]:
        """The fields ``names`` of this object, checked to be one, in that order (each as :meth:`get`): a
        record's decoder names its fields once."""
        self.obj()
        return tuple(self.get(name) for name in names)

    def has(self, name: str) -> bool:
        return isinstance(self.value, dict) and name in self.value

    def items(self, max_items: int = MAX_ITEMS) -> Iterator[StateReader]:
        """The items of this list (at most ``max_items``)."""
        if not isinstance(self.value, list):
            self._expected("a list")
        if len(self.value) > max_items:
            self.fail(f"has {len(self.value):,} items (at most {max_items:,})")
        return (StateReader(self.file, item, self.fix, field=f"{self.field}[{n}]") for n, item in enumerate(self.value))

    def entries(self, max_items: int = MAX_ITEMS, max_name: int = MAX_NAME) -> Iterator[tuple[str, StateReader]]:
        """The (name, value) pairs of this object (at most ``max_items``, names of at most ``max_name``)."""
        value = self.obj().value
        assert isinstance(value, dict)
        if len(value) > max_items:
            self.fail(f"has {len(value):,} fields (at most {max_items:,})")
        for k in value:
            if len(k) > max_name:
                self.fail(f"has a field name {len(k):,} characters long (at most {max_name:,})")
        return ((str(k), StateReader(self.file, v, self.fix, field=self._child(str(k)))) for k, v in value.items())

    # -- scalars -------------------------------------------------------------
    def integer(self, low: int = 0, high: int = MAX_INT, *, optional: bool = False) -> int | None:
        """A whole number in [low, high] (``optional``: null or absent read as None)."""
        value = self.value
        if optional and value is None:
            return None
        if not isinstance(value, int) or isinstance(value, bool):
            if isinstance(value, float) and value.is_integer() and low <= value <= high:
                return int(value)  # 3.0: what a JSON writer may make of 3
            self._expected("a whole number")
        if not low <= value <= high:
            self.fail(f"is {_clip(value)}, outside {low}…{high}")
        return value

    def whole(self, low: int = 0, high: int = MAX_INT) -> int:
        """A whole number in [low, high], required."""
        value = self.integer(low, high)
        assert value is not None
        return value

    def number(self, low: float = -math.inf, high: float = math.inf, *, infinite: bool = False,
               optional: bool = False) -> float | None:
        """A number in [low, high]; finite unless ``infinite``; never NaN (``optional``: null/absent → None)."""
        value = self.value
        if optional and value is None:
            return None
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            self._expected("a number")
        number = float(value) if not isinstance(value, int) or abs(value) < 2**1023 else math.inf
        if math.isnan(number) or (math.isinf(number) and not infinite):
            self.fail(f"is {value!r:.40}, not a finite number")
        if not low <= number <= high:
            self.fail(f"is {_clip(value)}, outside {low:g}…{high:g}")
        return number

    def real(self, low: float = -math.inf, high: float = math.inf, *, infinite: bool = False) -> float:
        """A number, required (see :meth:`number`)."""
        value = self.number(low, high, infinite=infinite)
        assert value is not None
        return value

    def text(self, max_chars: int = 100_000, *, optional: bool = False,
             choices: tuple[str, ...] | None = None) -> str | None:
        """Text of at most ``max_chars`` (``optional``: null/absent → None; ``choices``: one of these)."""
        value = self.value
        if optional and value is None:
            return None
        if not isinstance(value, str):
            self._expected("text")
        if len(value) > max_chars:
            self.fail(f"is {len(value):,} characters long (at most {max_chars:,})")
        if choices is not None and value not in choices:
            self.fail(f"is '{_clip(value)}', not one of: {', '.join(choices)}")
        return value

    def string(self, max_chars: int = 100_000, choices: tuple[str, ...] | None = None) -> str:
        """Text, required (see :meth:`text`)."""
        value = self.text(max_chars, choices=choices)
        assert value is not None
        return value

    def flag(self, *, optional: bool = False, numeric: bool = False) -> bool | None:
        """true/false (``numeric``: SQLite's 0/1 too; ``optional``: null/absent → None)."""
        value = self.value
        if optional and value is None:
            return None
        if isinstance(value, bool):
            return value
        if numeric and isinstance(value, int) and value in (0, 1):
            return bool(value)
        self._expected("0 or 1" if numeric else "true or false")

    def map(self, read: Callable[[StateReader], T], max_items: int = MAX_ITEMS) -> dict[str, T]:
        """This object with each value read by ``read``."""
        return {name: read(value) for name, value in self.entries(max_items)}

    def each(self, read: Callable[[StateReader], T], max_items: int = MAX_ITEMS) -> list[T]:
        """This list with each item read by ``read``."""
        return [read(item) for item in self.items(max_items)]


def _clip(value: object) -> str:
    text = str(value)
    return text if len(text) <= 40 else text[:40] + "…"
