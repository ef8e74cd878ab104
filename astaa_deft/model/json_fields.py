"""Typed reads of the fields of a JSON object a record did not write itself (a log, a journal, a pipe).

A record's ``from_json`` reads its fields through :class:`JsonFields`, so
each field is read with its type checked in one place: a field that is
absent or of the wrong type yields the stated default (never a value of the
wrong type), as logs have always been read. Pure and stateless apart from
the object read; safe to use from any thread.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from astaa_deft.model.json import JsonObject, JsonValue


def _integer(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


class JsonFields:
    """The fields of one JSON object, each read as a given type."""

    __slots__ = ("_obj",)

    def __init__(self, obj: Mapping[str, JsonValue]) -> None:
        self._obj = obj

    def raw(self, name: str) -> JsonValue:
        """The value as it is (None if absent): for fields whose shape is the reader's business."""
        return self._obj.get(name)

    def text(self, name: str, default: str = "") -> str:
        """The value as text (``str()`` of what is there), ``default`` if absent."""
        return str(self._obj.get(name, default))

    def optional_text(self, name: str) -> str | None:
        """The value if it is a string, else None."""
        value = self._obj.get(name)
        return value if isinstance(value, str) else None

    def integer(self, name: str, default: int = 0) -> int:
        """The value if it is an integer (not a bool), else ``default``."""
        value = _integer(self._obj.get(name))
        return default if value is None else value

    def optional_integer(self, name: str) -> int | None:
        """The value if it is an integer (not a bool), else None."""
        return _integer(self._obj.get(name))

    def number(self, name: str, default: float = 0.0) -> float:
        """The value as a float if it is a number, else ``default``."""
        value = self._obj.get(name)
        return float(value) if isinstance(value, (int, float)) else default

    def flag(self, name: str, default: bool = False) -> bool:
        """The value's truth (``default`` if absent)."""
        return bool(self._obj.get(name, default))

    def texts(self, name: str) -> tuple[str, ...]:
        """The items of a list as text (an absent or empty field: ())."""
        return tuple(str(item) for item in self._list(name))

    def objects(self, name: str) -> tuple[JsonObject, ...]:
        """The JSON objects among the items of a list (others skipped)."""
        return tuple(item for item in self._list(name) if isinstance(item, dict))

    def object(self, name: str) -> JsonObject | None:
        """The value if it is a JSON object, else None."""
        value = self._obj.get(name)
        return value if isinstance(value, dict) else None

    def _list(self, name: str) -> Sequence[JsonValue]:
        """The items of a list (a tuple too: an object built in the process); any other value: none."""
        value = self._obj.get(name)
        return value if isinstance(value, (list, tuple)) else ()
