"""JSON Schema of spec types, checked by structure and against example messages.

The ``jsonschema`` library is not a dependency, so ``conforms`` below
implements exactly the keywords ``json_schema`` emits.
"""

from __future__ import annotations

import base64
import json
import math
from typing import Any

import pytest

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.jsonschema import DRAFT_2020_12, json_schema
from astaa_deft.model.sut import FieldType, MessageType


def struct(ref: str) -> FieldType:
    return FieldType(kind="struct", ref=ref)


def message_types(**types: dict[str, FieldType]) -> dict[str, MessageType]:
    return {name: MessageType(name, fields) for name, fields in types.items()}


# The example types of docs/spec.md, plus a bytes field and bounded ints.
TYPES = message_types(
    Header={"seq": FieldType(kind="uint64"), "stamp": FieldType(kind="time")},
    TrajectoryPoint={"x": FieldType(kind="float64"), "y": FieldType(kind="float64"),
                     "v": FieldType(kind="float64", minimum=0, maximum=40)},
    Trajectory={
        "header": struct("Header"),
        "points": FieldType(kind="array", items=struct("TrajectoryPoint"), min_length=1, max_length=200),
        "gear": FieldType(kind="enum", values=("drive", "reverse", "park")),
        "tags": FieldType(kind="array", items=FieldType(kind="string")),
        "blob": FieldType(kind="bytes"),
        "level": FieldType(kind="int8", minimum=-5),
        "ok": FieldType(kind="bool"),
    },
)

MESSAGE = {
    "header": {"seq": 3, "stamp": 1712.5},
    "points": [{"x": 1.0, "y": 2.0, "v": 3.5}, {"x": -1.0, "y": 0.0, "v": 0}],
    "gear": "drive",
    "tags": ["lane"],
    "blob": base64.b64encode(b"\x00\x01").decode(),
    "level": 4,
    "ok": True,
}


def conforms(value: Any, schema: dict, root: dict) -> bool:
    """A minimal validator for the keywords json_schema emits."""
    if "$ref" in schema:
        ref = schema["$ref"]
        return conforms(value, root if ref == "#" else root["$defs"][ref.rsplit("/", 1)[1]], root)
    if "enum" in schema and value not in schema["enum"]:
        return False
    kind = schema.get("type")
    checks = {
        "object": lambda v: type(v) is dict,
        "array": lambda v: type(v) is list,
        "string": lambda v: type(v) is str,
        "boolean": lambda v: type(v) is bool,
        "integer": lambda v: type(v) is int or (type(v) is float and v.is_integer()),
        "number": lambda v: type(v) in (int, float) and math.isfinite(v),
    }
    if kind and not checks[kind](value):
        return False
    if "minimum" in schema and value < schema["minimum"]:
        return False
    if "maximum" in schema and value > schema["maximum"]:
        return False
    if kind == "array":
        if len(value) < schema.get("minItems", 0) or len(value) > schema.get("maxItems", math.inf):
            return False
        return all(conforms(item, schema["items"], root) for item in value)
    if kind == "object":
        if any(name not in value for name in schema.get("required", ())):
            return False
        return all(conforms(value[name], sub, root)
                   for name, sub in schema.get("properties", {}).items() if name in value)
    return True


def valid(message: Any, schema: dict) -> bool:
    return conforms(message, schema, schema)


def test_top_level_is_a_titled_object_of_the_spec_fields():
    schema = json_schema(TYPES, "Trajectory")
    assert schema["$schema"] == DRAFT_2020_12
    assert schema["type"] == "object" and schema["title"] == "Trajectory"
    assert list(schema["properties"]) == list(TYPES["Trajectory"].fields)
    assert schema["required"] == list(TYPES["Trajectory"].fields)
    assert "$defs" not in schema  # nothing recursive: everything inline


def test_field_kinds_map_to_json_schema_types():
    properties = json_schema(TYPES, "Trajectory")["properties"]
    assert properties["header"]["title"] == "Header"
    assert properties["header"]["properties"]["seq"] == {"type": "integer", "minimum": 0, "maximum": 2**64 - 1}
    assert properties["header"]["properties"]["stamp"]["type"] == "number"
    assert properties["points"]["type"] == "array"
    assert (properties["points"]["minItems"], properties["points"]["maxItems"]) == (1, 200)
    point = properties["points"]["items"]
    assert point["title"] == "TrajectoryPoint" and point["properties"]["x"] == {"type": "number"}
    assert point["properties"]["v"] == {"type": "number", "minimum": 0, "maximum": 40}
    assert properties["gear"] == {"enum": ["drive", "reverse", "park"]}
    assert properties["tags"] == {"type": "array", "items": {"type": "string"}}
    assert properties["blob"] == {"type": "string", "contentEncoding": "base64"}
    assert properties["level"] == {"type": "integer", "minimum": -5, "maximum": 127}
    assert properties["ok"] == {"type": "boolean"}


def test_schema_is_plain_json_for_the_mcap_schema_record():
    schema = json_schema(TYPES, "Trajectory")
    assert json.loads(json.dumps(schema, allow_nan=False)) == schema


def test_example_messages_validate_after_a_codec_round_trip():
    schema = json_schema(TYPES, "Trajectory")
    codec = get_codec("json")
    assert valid(codec.decode(codec.encode(MESSAGE)), schema)


@pytest.mark.parametrize("field, value", [
    ("gear", "neutral"),
    ("points", []),
    ("level", -6),
    ("level", 1.5),
    ("ok", 1),
    ("tags", ["a", 1]),
    ("header", {"seq": -1, "stamp": 0.0}),
    ("header", {"seq": 1}),
    ("points", [{"x": 1.0, "y": 2.0, "v": float("nan")}]),  # mutated messages do not validate
    ("points", [{"x": 1.0, "y": 2.0, "v": 41.0}]),
])
def test_messages_breaking_the_declared_types_do_not_validate(field, value):
    schema = json_schema(TYPES, "Trajectory")
    assert not valid({**MESSAGE, field: value}, schema)


def test_recursive_types_use_references():
    types = message_types(
        Tree={"label": FieldType(kind="string"), "children": FieldType(kind="array", items=struct("Tree"))},
        Graph={"root": struct("Node")},
        Node={"next": FieldType(kind="array", items=struct("Node")), "id": FieldType(kind="int32")},
    )
    tree = json_schema(types, "Tree")
    assert tree["properties"]["children"]["items"] == {"$ref": "#"}
    assert valid({"label": "a", "children": [{"label": "b", "children": []}]}, tree)
    assert not valid({"label": "a", "children": [{"label": 3, "children": []}]}, tree)

    graph = json_schema(types, "Graph")
    assert graph["properties"]["root"]["properties"]["next"]["items"] == {"$ref": "#/$defs/Node"}
    assert graph["$defs"]["Node"]["title"] == "Node"
    assert valid({"root": {"id": 1, "next": [{"id": 2, "next": []}]}}, graph)
    assert not valid({"root": {"id": 1, "next": [{"id": "x", "next": []}]}}, graph)


def test_unknown_type_is_a_key_error():
    with pytest.raises(KeyError, match="Trajectory"):
        json_schema(TYPES, "Trajectry")
