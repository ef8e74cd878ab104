"""Lossless strict JSON for message values JSON cannot hold exactly (NaN, bytes, lone surrogates).

``to_tagged`` writes such a value as a one-key object naming its kind;
``from_tagged`` reads it back. Pure functions, thread-safe. A mutation's
field changes and detail use this form in the log (``model.records.Mutation``).
"""

from __future__ import annotations

import base64
import json
import math
from typing import Any

# A value JSON cannot hold exactly becomes a one-key object naming its kind.
# A real object with exactly one of these keys is wrapped in {"object": ...},
# so a reader never mistakes message data for a tag.
TAGS = ("float", "base64", "str_escaped", "object")


def to_tagged(value: Any) -> Any:
    """``value`` as strict JSON data (RFC 8259, valid UTF-8), losslessly.

    NaN/inf -> {"float": "nan" | "inf" | "-inf"}; bytes -> {"base64": ...};
    a string with lone surrogates -> {"str_escaped": its JSON escape text}.
    """
    kind = type(value)
    if kind is float and not math.isfinite(value):
        return {"float": "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")}
    if kind is bytes:
        return {"base64": base64.b64encode(value).decode("ascii")}
    if kind is str:
        try:
            value.encode("utf-8")
            return value
        except UnicodeEncodeError:
            return {"str_escaped": json.dumps(value)[1:-1]}
    if kind is list or kind is tuple:
        return [to_tagged(item) for item in value]
    if kind is dict:
        tagged = {str(k): to_tagged(v) for k, v in value.items()}
        return {"object": tagged} if len(tagged) == 1 and next(iter(tagged)) in TAGS else tagged
    return value


def from_tagged(value: Any) -> Any:
    """The inverse of ``to_tagged``."""
    if type(value) is list:
        return [from_tagged(item) for item in value]
    if type(value) is not dict:
        return value
    if len(value) == 1:
        (tag, inner), = value.items()
        if tag == "float":
            return float(inner)
        if tag == "base64":
            return base64.b64decode(inner)
        if tag == "str_escaped":
            return json.loads(f'"{inner}"')
        if tag == "object":
            return {k: from_tagged(v) for k, v in inner.items()}
    return {k: from_tagged(v) for k, v in value.items()}
