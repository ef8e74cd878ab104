"""JSON Schema (draft 2020-12) for a spec message type.

Recorded MCAP channels carry it as their schema (``encoding="jsonschema"``)
so Foxglove and the ``mcap`` CLI can show and plot the messages.

Nested structs are written inline, as Foxglove's own JSON schemas are, since
viewers do not all resolve ``$ref``; only a type that contains itself is
referenced through ``$defs``. The schema describes *nominal* messages:
declared bounds become ``minimum``/``maximum``, so a mutated message
(NaN, out of range, empty array) deliberately does not validate.
``bytes`` fields are described as base64 text, i.e. as they travel in JSON.
"""

from __future__ import annotations

from collections.abc import Mapping

from astaa_deft.model.fields import message_type
from astaa_deft.model.sut import INT_RANGES, FieldType, MessageType

DRAFT_2020_12 = "https://json-schema.org/draft/2020-12/schema"

_SCALAR_SCHEMAS: dict[str, dict[str, object]] = {
    "float32": {"type": "number"},
    "float64": {"type": "number"},
    "bool": {"type": "boolean"},
    "string": {"type": "string"},
    "time": {"type": "number", "description": "seconds"},
    "bytes": {"type": "string", "contentEncoding": "base64"},
}


def json_schema(types: Mapping[str, MessageType], type_name: str) -> dict[str, object]:
    """The schema of ``type_name`` messages: an object titled with the type name."""
    builder = _SchemaBuilder(types, type_name)
    schema: dict[str, object] = {"$schema": DRAFT_2020_12}
    schema.update(builder.struct(type_name, frozenset()))
    # A recursive type's definition can reference further recursive types.
    defs: dict[str, object] = {}
    while builder.referenced.keys() - defs.keys():
        name = min(builder.referenced.keys() - defs.keys())
        defs[name] = builder.struct(name, frozenset({name}))
    if defs:
        schema["$defs"] = defs
    return schema


class _SchemaBuilder:
    def __init__(self, types: Mapping[str, MessageType], root: str):
        self.types = types
        self.root = root
        self.referenced: dict[str, None] = {}  # struct names written as "$ref" (ordered set)

    def struct(self, name: str, open_structs: frozenset[str]) -> dict[str, object]:
        fields = message_type(self.types, name).fields
        inner = open_structs | {name}
        return {
            "title": name,
            "type": "object",
            "properties": {field: self.field(ftype, inner) for field, ftype in fields.items()},
            "required": list(fields),
        }

    def field(self, ftype: FieldType, open_structs: frozenset[str]) -> dict[str, object]:
        if ftype.kind == "struct":
            assert ftype.ref is not None
            if ftype.ref in open_structs:  # recursion: inline expansion would never end
                if ftype.ref == self.root:
                    return {"$ref": "#"}
                self.referenced[ftype.ref] = None
                return {"$ref": f"#/$defs/{ftype.ref}"}
            return self.struct(ftype.ref, open_structs)
        if ftype.kind == "array":
            assert ftype.items is not None
            schema: dict[str, object] = {"type": "array", "items": self.field(ftype.items, open_structs)}
            if ftype.min_length is not None:
                schema["minItems"] = ftype.min_length
            if ftype.max_length is not None:
                schema["maxItems"] = ftype.max_length
            return schema
        if ftype.kind == "enum":
            return {"enum": list(ftype.values)}
        if ftype.kind in INT_RANGES:
            return _integer(ftype)
        return _with_bounds(dict(_SCALAR_SCHEMAS[ftype.kind]), ftype)


def _integer(ftype: FieldType) -> dict[str, object]:
    low: float
    high: float
    low, high = INT_RANGES[ftype.kind]
    # The width bounds what the field can hold; declared bounds can narrow it.
    if ftype.minimum is not None:
        low = max(low, ftype.minimum)
    if ftype.maximum is not None:
        high = min(high, ftype.maximum)
    return {"type": "integer", "minimum": low, "maximum": high}


def _with_bounds(schema: dict[str, object], ftype: FieldType) -> dict[str, object]:
    if schema.get("type") == "number":
        if ftype.minimum is not None:
            schema["minimum"] = ftype.minimum
        if ftype.maximum is not None:
            schema["maximum"] = ftype.maximum
    return schema
