"""The JSON a record's ``to_json`` writes and its ``from_json`` reads.

Each record type of the model owns its JSON form (as ``mcap``'s records own
their wire form); these aliases name that form in signatures instead of
``Any``. A ``from_json`` takes a ``JsonObject`` it did not write (a log, a
journal, a pipe), so it checks what it reads and raises the caller's error
type with the place, rather than trusting the shape.
"""

from __future__ import annotations

from typing import TypeAlias

JsonValue: TypeAlias = None | bool | int | float | str | list["JsonValue"] | dict[str, "JsonValue"]
JsonObject: TypeAlias = dict[str, JsonValue]
