"""Field paths: syntax, get/set on messages, and paths against the declared types."""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from astaa_deft.io.codecs import same_value
from astaa_deft.model.fields import (
    WILDCARD, FieldPath, FieldPathError, check_brittle_pattern, get, is_brittle, leaf_fields,
    parse_brittle_pattern, set_field, type_at,
)
from astaa_deft.model.sut import FieldType, MessageType

FAST = settings(max_examples=100, deadline=None)


def struct(ref: str) -> FieldType:
    return FieldType(kind="struct", ref=ref)


def array(items: FieldType, **bounds) -> FieldType:
    return FieldType(kind="array", items=items, **bounds)


def scalar(kind: str, **bounds) -> FieldType:
    return FieldType(kind=kind, **bounds)


def message_types(**types: dict[str, FieldType]) -> dict[str, MessageType]:
    return {name: MessageType(name, fields) for name, fields in types.items()}


# A spec-like type set: nested structs, arrays of structs, an array of
# arrays, enums, a ROS-style struct stamp, and a recursive type.
TYPES = message_types(
    Time={"sec": scalar("int32"), "nanosec": scalar("uint32")},
    Header={"seq": scalar("uint64"), "stamp": struct("Time"), "frame_id": scalar("string")},
    Point={"x": scalar("float64"), "y": scalar("float64")},
    Obstacle={"header": struct("Header"), "position": struct("Point"), "speed": scalar("float32", minimum=0),
              "kind": FieldType(kind="enum", values=("car", "pedestrian"))},
    Scene={"header": struct("Header"), "obstacles": array(struct("Obstacle"), max_length=64),
           "grid": array(array(scalar("float64"))), "mode": FieldType(kind="enum", values=("auto", "manual"))},
    Tree={"label": scalar("string"), "children": array(struct("Tree"))},
)

SCENE = {
    "header": {"seq": 7, "stamp": {"sec": 1, "nanosec": 5}, "frame_id": "map"},
    "obstacles": [
        {"position": {"x": 1.0, "y": 2.0}, "speed": 3.0},
        {"position": {"x": 4.0, "y": 5.0}, "speed": 6.0},
        {"position": {"x": 7.0}, "speed": 9.0},
    ],
    "grid": [[1.0, 2.0], [3.0]],
    "mode": "auto",
}


def scene() -> dict:
    return pickle.loads(pickle.dumps(SCENE))  # a fresh deep copy per test


# ---------------------------------------------------------------- syntax

@pytest.mark.parametrize("text, segments", [
    ("header.stamp", ("header", "stamp")),
    ("obstacles[2].position.x", ("obstacles", 2, "position", "x")),
    ("obstacles[*].speed", ("obstacles", WILDCARD, "speed")),
    ("points[-1].v", ("points", -1, "v")),
    ("obstacles", ("obstacles",)),
    ("grid[0][*]", ("grid", 0, WILDCARD)),
    ("frame-id.@type", ("frame-id", "@type")),
])
def test_parse_and_str_round_trip(text, segments):
    path = FieldPath.parse(text)
    assert path.segments == segments
    assert str(path) == text


@pytest.mark.parametrize("text, position, hint", [
    ("", 0, "empty"),
    ("[0].x", 0, "starts with a field name"),
    ("a..b", 2, "field name after '.'"),
    ("a.", 2, "field name after '.'"),
    ("a[", 1, "never closed"),
    ("a[x]", 1, "integer or *"),
    ("a[]", 1, "integer or *"),
    ("a[01]", 1, "write [1], not [01]"),
    ("a[-0]", 1, "write [0]"),
    ("a[+1]", 1, "write [1]"),
    ("a.*", 2, "write [*]"),
    ("a.b*", 3, "write [*]"),
    ("a b", 1, "whitespace"),
    ("a]", 1, "without a matching '['"),
    ("a[0]b", 4, "expected '.' or '['"),
])
def test_bad_syntax_names_the_position(text, position, hint):
    with pytest.raises(FieldPathError) as caught:
        FieldPath.parse(text)
    assert caught.value.position == position and caught.value.text == text
    assert hint in str(caught.value) and f"(char {position})" in str(caught.value)


def test_field_path_error_is_a_value_error():
    assert issubclass(FieldPathError, ValueError)
    with pytest.raises(FieldPathError):
        FieldPath(())
    with pytest.raises(FieldPathError):
        FieldPath(("a", True))


def test_paths_are_frozen_hashable_and_picklable():
    path = FieldPath.parse("obstacles[*].speed")
    assert {path: 1}[FieldPath.parse("obstacles[*].speed")] == 1
    with pytest.raises(AttributeError):
        path.segments = ()  # type: ignore[misc]
    copied = pickle.loads(pickle.dumps(path))
    assert copied == path and copied.segments[1] is WILDCARD


def test_concreteness_generalization_and_offsets():
    assert FieldPath.parse("a[2].b").is_concrete
    assert not FieldPath.parse("a[-1].b").is_concrete and not FieldPath.parse("a[*]").is_concrete
    assert str(FieldPath.parse("a[2].b[-1]").generalized()) == "a[*].b[*]"
    path = FieldPath.parse("obstacles[2].position")
    assert [path.offset_of(i) for i in range(3)] == [0, 9, 13]


SEGMENTS = st.lists(
    st.text(alphabet="abz_-@0", min_size=1, max_size=4) | st.integers(-20, 20) | st.just(WILDCARD),
    max_size=5,
).map(tuple)


@FAST
@given(first=st.text(alphabet="abz_", min_size=1, max_size=4), rest=SEGMENTS)
def test_any_path_round_trips_through_text(first, rest):
    path = FieldPath((first,) + rest)
    assert FieldPath.parse(str(path)) == path
    assert str(FieldPath.parse(str(path))) == str(path)


# ---------------------------------------------------------------- get / set_field

def paths_of(matches) -> list[str]:
    return [str(path) for path, _ in matches]


def test_get_resolves_wildcards_and_negative_indices_to_concrete_paths():
    message = scene()
    assert get(message, "obstacles[*].speed") == [
        (FieldPath.parse("obstacles[0].speed"), 3.0),
        (FieldPath.parse("obstacles[1].speed"), 6.0),
        (FieldPath.parse("obstacles[2].speed"), 9.0),
    ]
    assert get(message, "obstacles[-1].position.x") == [(FieldPath.parse("obstacles[2].position.x"), 7.0)]
    assert paths_of(get(message, "grid[*][*]")) == ["grid[0][0]", "grid[0][1]", "grid[1][0]"]
    assert get(message, "obstacles")[0][1] is message["obstacles"]


@pytest.mark.parametrize("path", [
    "missing", "obstacles[3].speed", "obstacles[-4].speed", "header.seq.deeper",
    "header[0]", "obstacles.speed", "grid[1][1]",
])
def test_what_does_not_exist_does_not_match(path):
    assert get(scene(), path) == []
    message = scene()
    assert set_field(message, path, 0.0) == []
    assert same_value(message, scene())


def test_wildcard_skips_elements_missing_the_field():
    assert paths_of(get(scene(), "obstacles[*].position.y")) == ["obstacles[0].position.y", "obstacles[1].position.y"]


def test_set_field_sets_every_match_and_returns_the_old_values():
    message = scene()
    replaced = set_field(message, "obstacles[*].speed", float("inf"))
    assert [(str(p), old) for p, old in replaced] == [
        ("obstacles[0].speed", 3.0), ("obstacles[1].speed", 6.0), ("obstacles[2].speed", 9.0)]
    assert [o["speed"] for o in message["obstacles"]] == [float("inf")] * 3


def test_set_field_can_empty_an_array_and_never_aliases_the_new_value():
    message = scene()
    [(path, old)] = set_field(message, "obstacles", [])
    assert str(path) == "obstacles" and len(old) == 3 and message["obstacles"] == []

    replacement = {"x": 0.0}
    set_field(message, "grid", [replacement])
    set_field(message, "header.stamp", replacement)
    message["grid"][0]["x"] = 1.0
    assert replacement == {"x": 0.0} and message["header"]["stamp"] == {"x": 0.0}


def test_negative_index_sets_from_the_end():
    message = scene()
    [(path, old)] = set_field(message, "grid[0][-1]", -0.0)
    assert (str(path), old) == ("grid[0][1]", 2.0)
    assert message["grid"][0] == [1.0, -0.0]


def every_concrete_path(value, prefix=()):
    children = value.items() if type(value) is dict else enumerate(value) if type(value) is list else ()
    for slot, child in children:
        yield FieldPath(prefix + (slot,))
        yield from every_concrete_path(child, prefix + (slot,))


NESTED = st.dictionaries(
    st.text(alphabet="abc", min_size=1, max_size=2),
    st.recursive(
        st.integers() | st.floats(allow_nan=False) | st.text(max_size=3) | st.none(),
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(alphabet="abc", min_size=1, max_size=2),
                                                                    inner, max_size=3),
        max_leaves=12,
    ),
    min_size=1, max_size=4,
)


@FAST
@given(data=st.data())
def test_get_and_set_agree_on_random_nested_values(data):
    message = data.draw(NESTED)
    path = data.draw(st.sampled_from(list(every_concrete_path(message))))
    [(found_path, found)] = get(message, path)
    assert found_path == path

    *parent, last = path.segments
    if type(last) is int:  # the same element counted from the end, and among all elements
        length = len(get(message, FieldPath(tuple(parent)))[0][1])
        assert get(message, FieldPath(tuple(parent) + (last - length,))) == [(path, found)]
        assert (path, found) in get(message, FieldPath(tuple(parent) + (WILDCARD,)))

    before = pickle.loads(pickle.dumps(message))
    assert set_field(message, path, "NEW") == [(path, found)]
    assert get(message, path) == [(path, "NEW")]
    set_field(message, path, found)
    assert same_value(message, before)


# ---------------------------------------------------------------- declared types

def test_leaf_fields_lists_leaves_and_arrays_in_declaration_order():
    listed = [(str(path), ftype.describe()) for path, ftype in leaf_fields(TYPES, "Scene")]
    header = [("header.seq", "uint64"), ("header.stamp.sec", "int32"),
              ("header.stamp.nanosec", "uint32"), ("header.frame_id", "string")]
    assert listed == header + [
        ("obstacles", "Obstacle[]"),
        *[(f"obstacles[*].{path}", kind) for path, kind in header],
        ("obstacles[*].position.x", "float64"),
        ("obstacles[*].position.y", "float64"),
        ("obstacles[*].speed", "float32"),
        ("obstacles[*].kind", "enum(car, pedestrian)"),
        ("grid", "float64[][]"),
        ("grid[*]", "float64[]"),
        ("grid[*][*]", "float64"),
        ("mode", "enum(auto, manual)"),
    ]


def test_leaf_fields_keeps_declared_bounds():
    declared = dict(leaf_fields(TYPES, "Scene"))
    assert declared[FieldPath.parse("obstacles")].max_length == 64
    assert declared[FieldPath.parse("obstacles[*].speed")].minimum == 0


def test_leaf_fields_stops_at_recursive_types():
    assert [str(p) for p, _ in leaf_fields(TYPES, "Tree")] == ["label", "children"]
    mutual = message_types(A={"b": struct("B"), "n": scalar("int8")}, B={"a": struct("A"), "m": scalar("bool")})
    assert [str(p) for p, _ in leaf_fields(mutual, "A")] == ["b.m", "n"]


def test_type_at_accepts_concrete_and_wildcard_paths():
    assert type_at(TYPES, "Scene", "obstacles[3].position.x").kind == "float64"
    assert type_at(TYPES, "Scene", "obstacles[-1].kind").values == ("car", "pedestrian")
    assert type_at(TYPES, "Scene", "grid[*]").describe() == "float64[]"
    assert type_at(TYPES, "Scene", FieldPath.parse("header.stamp")).ref == "Time"


@pytest.mark.parametrize("path, position, message", [
    ("obstacles[0].positon.x", 13, "Obstacle has no field 'positon'; did you mean 'position'?"),
    ("heade.seq", 0, "Scene has no field 'heade'; did you mean 'header'?"),
    ("mode.zzz", 5, "'mode' is enum(auto, manual), which has no field 'zzz'"),
    ("obstacles.speed", 10, "'obstacles' is an array (Obstacle[]); pick elements first, e.g. obstacles[*].speed"),
    ("header[0]", 6, "'header' is Header, not an array"),
    ("qqq", 0, "(it has: header, obstacles, grid, mode)"),
])
def test_type_at_names_the_first_unknown_segment(path, position, message):
    with pytest.raises(FieldPathError) as caught:
        type_at(TYPES, "Scene", path)
    assert message in str(caught.value)
    assert caught.value.position == position


def test_type_at_rejects_unknown_message_types():
    with pytest.raises(KeyError, match="did you mean 'Scene'"):
        type_at(TYPES, "Scen", "mode")


# ---------------------------------------------------------------- brittle fields

BRITTLE = ["Header.stamp", "Obstacle.kind"]


@pytest.mark.parametrize("path, brittle", [
    ("header.stamp", True),
    ("header.stamp.sec", True),  # inside a brittle struct
    ("obstacles[*].header.stamp.nanosec", True),
    ("obstacles[5].header.stamp", True),
    ("obstacles[-1].kind", True),
    ("header.seq", False),
    ("header", False),  # the struct around it is not itself brittle
    ("obstacles", False),
    ("obstacles[*].speed", False),
    ("mode", False),
])
def test_brittle_patterns_match_wherever_their_type_occurs(path, brittle):
    assert is_brittle(TYPES, "Scene", path, BRITTLE) is brittle


def test_brittle_patterns_on_the_message_type_itself_and_with_wildcards():
    assert is_brittle(TYPES, "Scene", "grid[1][0]", ["Scene.grid[*][*]"])
    assert not is_brittle(TYPES, "Scene", "grid[1]", ["Scene.grid[*][*]"])
    assert is_brittle(TYPES, "Scene", "grid[1]", ["Scene.grid"])
    assert not is_brittle(TYPES, "Scene", "header.stamp", [])


@pytest.mark.parametrize("pattern, hint", [
    ("stamp", "TypeName.field"),
    (".stamp", "TypeName.field"),
    ("Header.", "field name after '.'"),
    ("Scene.grid[0]", "write [*]"),
])
def test_bad_brittle_patterns_are_explained(pattern, hint):
    with pytest.raises(FieldPathError, match=hint.replace("[", r"\[").replace("*", r"\*")):
        parse_brittle_pattern(pattern)


def test_check_brittle_pattern_validates_against_the_types():
    assert check_brittle_pattern(TYPES, "Header.stamp.sec") == ("Header", FieldPath.parse("stamp.sec"))
    with pytest.raises(FieldPathError, match="unknown type 'Headr'; did you mean 'Header'"):
        check_brittle_pattern(TYPES, "Headr.stamp")
    with pytest.raises(FieldPathError, match="did you mean 'stamp'") as caught:
        check_brittle_pattern(TYPES, "Header.stmp")
    assert caught.value.position == len("Header.")
