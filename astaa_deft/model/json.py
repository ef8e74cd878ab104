"""The JSON a record's ``to_json`` writes and its ``from_json`` reads, and the plain data of a decoded message.

Each record type of the model owns its JSON form (as ``mcap``'s records own
their wire form); these aliases name that form in signatures instead of
``Any``. A ``from_json`` takes a ``JsonObject`` it did not write (a log, a
journal, a pipe), so it checks what it reads and raises the caller's error
type with the place, rather than trusting the shape.

A decoded message is the same kind of tree plus byte strings (CBOR and CDR
carry them; see ``astaa_deft.io.codecs.base``): ``FieldValue`` is any value a
field path can name in it, ``DecodedMessage`` the message itself (an object
at the top). Its floats may be NaN or infinite and its strings may hold lone
surrogates, which strict JSON cannot; ``astaa_deft.model.tagged`` writes such
a value as a ``JsonValue`` and reads it back. A ``FieldValue``'s containers
are typed read-only (``Sequence``, ``Mapping``; at run time they are the
lists and dicts the codec built), so that every ``JsonValue`` is a
``FieldValue`` too (``list`` and ``dict`` are invariant); a message's fields
are changed through ``astaa_deft.model.fields.set_field``, which checks the
shape it walks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TypeAlias

JsonValue: TypeAlias = None | bool | int | float | str | list["JsonValue"] | dict[str, "JsonValue"]
JsonObject: TypeAlias = dict[str, JsonValue]

FieldValue: TypeAlias = (None | bool | int | float | str | bytes
                         | Sequence["FieldValue"] | Mapping[str, "FieldValue"])
DecodedMessage: TypeAlias = dict[str, FieldValue]
