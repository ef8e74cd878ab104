"""Lossless strict JSON for message values JSON cannot hold exactly (NaN, bytes, lone surrogates).

``to_tagged`` writes such a value as a one-key object naming its kind;
``from_tagged`` reads it back. Pure functions, thread-safe. A mutation's
field changes and detail use this form in the log (``model.records.Mutation``).
"""

from __future__ import annotations

import base64
import json
import math

from astaa_deft.model.json import FieldValue, JsonValue

# A value JSON cannot hold exactly becomes a one-key object naming its kind.
# A real object with exactly one of these keys is wrapped in {"object": ...},
# so a reader never mistakes message data for a tag.
TAGS = ("float", "base64", "str_escaped", "object")


def to_tagged(value: object) -> JsonValue:
    """``value`` as strict JSON data (RFC 8259, valid UTF-8), losslessly.

    NaN/inf -> {"float": "nan" | "inf" | "-inf"}; bytes -> {"base64": ...};
    a string with lone surrogates -> {"str_escaped": its JSON escape text}.
    A value of none of a message's types becomes its text, as the log's
    writer (``json.dumps(..., default=str)``) has always written it.
    """
    # The most common types first: the recorder tags every value a mutation changed.
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        return {"float": "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")}
    if value is None or isinstance(value, int):  # bool included
        return value
    if isinstance(value, str):
        try:
            value.encode("utf-8")
            return value
        except UnicodeEncodeError:
            return {"str_escaped": json.dumps(value)[1:-1]}
    if isinstance(value, bytes):
        return {"base64": base64.b64encode(value).decode("ascii")}
    if isinstance(value, (list, tuple)):
        return [to_tagged(item) for item in value]
    if isinstance(value, dict):
        tagged = {str(k): to_tagged(v) for k, v in value.items()}
        return {"object": tagged} if len(tagged) == 1 and next(iter(tagged)) in TAGS else tagged
    return str(value)


def from_tagged(value: JsonValue) -> FieldValue:
    """The inverse of ``to_tagged``."""
    if type(value) is list:
        return [from_tagged(item) for item in value]
    if type(value) is not dict:
        return value
    if len(value) == 1:
        (tag, inner), = value.items()
        if tag == "float":
            if isinstance(inner, (str, int, float)):
                return float(inner)
            raise _damaged(tag, inner)
        if tag == "base64":
            if isinstance(inner, str):
                return base64.b64decode(inner)
            raise _damaged(tag, inner)
        if tag == "str_escaped":
            return str(json.loads(f'"{inner}"'))
        if tag == "object":
            if isinstance(inner, dict):
                return {k: from_tagged(v) for k, v in inner.items()}
            raise _damaged(tag, inner)
    return {k: from_tagged(v) for k, v in value.items()}


def _damaged(tag: str, inner: JsonValue) -> TypeError:
    """A tag whose content is not of its kind (a damaged log): the TypeError reading it would raise."""
    return TypeError(f"a damaged {tag!r} tag: {inner!r}")
