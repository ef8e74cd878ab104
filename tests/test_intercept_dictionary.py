"""The dictionary of exceptional values: the default file, user files merged
over it, derive rules, and filtering by what a codec can carry."""

from __future__ import annotations

import math
import sys
import textwrap

import pytest

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept.dictionary import (
    DYNAMIC, GROUPS, FieldSite, NotApplicable, ValueContext, dictionary_from_text, load_dictionary, wire_value,
)
from astaa_deft.model.sut import INT_RANGES, FieldType, MessageType

DEFAULT = load_dictionary()
JSON, CBOR = get_codec("json"), get_codec("cbor")


def site(kind: str, **declared) -> FieldSite:
    return FieldSite(FieldType(kind=kind, **declared))


def value(key: str, field: FieldSite, current=None, previous=None, container=None, name="ranges"):
    entry = DEFAULT.get(key)
    if entry.static_value(field) is not DYNAMIC:
        return entry.static_value(field)

    def previous_value():
        if previous is None:
            raise NotApplicable("no previous message")
        return previous

    return entry.resolve(ValueContext(site=field, current=current, container=container or {}, key=name,
                                      previous=previous_value))


# ---------------------------------------------------------------- the default dictionary

def test_default_has_every_group_and_the_issue_values():
    assert {entry.group for entry in DEFAULT.entries.values()} == set(GROUPS)
    floats = [DEFAULT.get(f"float.{name}").value for name in
              ("nan", "inf", "neg_inf", "zero", "neg_zero", "max", "neg_max", "smallest_normal",
               "neg_smallest_normal", "subnormal", "two_pow_53", "big_1e16", "minus_one", "pi")]
    assert math.isnan(floats[0]) and floats[1:3] == [math.inf, -math.inf]
    assert math.copysign(1.0, floats[4]) == -1.0
    assert floats[5] == sys.float_info.max and floats[7] == sys.float_info.min
    assert 0 < floats[9] < sys.float_info.min  # subnormal
    assert floats[10:13] == [2.0**53, 1e16, -1.0] and floats[13] == math.pi
    assert all(type(v) is float for v in floats)
    ints = {entry.value for entry in DEFAULT.group("int") if entry.rule is None}
    assert {0, 1, -1, -128, 127, 255, 65535, -2**31, 2**31 - 1, 2**32 - 1, -2**63, 2**63 - 1, 2**64 - 1,
            16, 32, 64, 100, -129, 128, 256, 512, 1000, 1024, 4096, -32769, 32768, 65536,
            -100663046, 100663045} <= ints
    strings = {entry.name: entry.value for entry in DEFAULT.group("string")}
    assert strings["empty"] == "" and strings["long_A"] == "A" * 8192
    assert strings["nul"] == "\0" and strings["esc"] == "\x1b" and "%n" in strings["format_specifiers"]
    assert strings["lone_surrogate"] == "\udc80"
    assert DEFAULT.get("bool.zero").value == 0 and DEFAULT.get("bool.null").value is None
    assert DEFAULT.get("array.empty").value == []
    assert DEFAULT.get("time.far_future").value > 4e9


def test_every_entry_of_a_group_gives_a_value_or_a_reason_for_its_types():
    """No entry crashes on a field of its group's types: a value, or NotApplicable with a reason."""
    point = MessageType("P", {"ranges": FieldType(kind="array", items=FieldType(kind="float32")),
                              "other": FieldType(kind="array", items=FieldType(kind="float32"))})
    fields = {
        "float": [site("float32", minimum=0, maximum=40), site("float64")],
        "int": [site(kind) for kind in INT_RANGES] + [site("int16", minimum=-3, maximum=3)],
        "bool": [site("bool")], "string": [site("string")], "bytes": [site("bytes")], "time": [site("time")],
        "enum": [site("enum", values=("drive", "park")), site("enum", values=(0, 1))],
        "array": [FieldSite(point.fields["ranges"], point), site("array", items=FieldType(kind="int8"))],
    }
    container = {"ranges": [1.0, 2.0], "other": [3.0]}
    current = {"float": 1.0, "int": 5, "bool": True, "string": "s", "bytes": b"b", "time": 10.0, "enum": "drive",
               "array": container["ranges"]}
    for group, sites in fields.items():
        for field in sites:
            for entry in DEFAULT.group(group):
                if entry.problem(field):
                    continue
                try:
                    value(entry.key, field, current[group], previous=current[group], container=container)
                except NotApplicable as exc:
                    assert str(exc), entry.key


def test_derive_rules():
    bounded = site("float32", minimum=0, maximum=40)
    assert value("float.below_min", bounded) == -5e-324
    assert value("float.above_max", bounded) == math.nextafter(40.0, math.inf) > 40.0
    assert DEFAULT.get("float.below_min").problem(site("float64")) == "the field declares no min"
    assert value("int.below_min", site("int16", minimum=-3, maximum=3)) == -4
    assert value("int.above_max", site("int16", minimum=-3.5, maximum=3.5)) == 4
    assert [value(f"int.{n}", site("int8")) for n in ("width_min", "width_max", "width_underflow", "width_overflow")] \
        == [-128, 127, -129, 128]
    assert value("int.width_overflow", site("uint64")) == 2**64
    assert value("enum.undefined", site("enum", values=("drive", "park"))) == "UNDEFINED"
    assert value("enum.undefined", site("enum", values=("UNDEFINED",))) == "UNDEFINED_"
    assert value("enum.undefined", site("enum", values=(0, 1, 7))) == 8
    assert value("enum.case_swapped", site("enum", values=("drive",))) == "DRIVE"
    assert DEFAULT.get("enum.case_swapped").problem(site("enum", values=(0, 1)))
    assert value("bool.negated", site("bool"), current=True) is False
    assert value("time.jump_back", site("time"), previous=100.5) == 99.5
    assert value("time.repeat_previous", site("time"), previous=100.5) == 100.5
    with pytest.raises(NotApplicable, match="no previous message"):
        value("time.repeat_previous", site("time"))
    items = [{"x": 1}, {"x": 2}]
    assert value("array.one_element", site("array"), current=items) == [{"x": 1}]
    longer = value("array.ten_times_longer", site("array"), current=items)
    assert len(longer) == 20 and longer[0] is not longer[2] and longer[0] is not items[0]
    with pytest.raises(NotApplicable, match="empty"):
        value("array.one_element", site("array"), current=[])


def test_sibling_length_mismatch_makes_parallel_arrays_disagree():
    scan = MessageType("Scan", {"ranges": FieldType(kind="array", items=FieldType(kind="float32")),
                                "intensities": FieldType(kind="array", items=FieldType(kind="float32"))})
    message = {"ranges": [1.0, 2.0, 3.0], "intensities": [4.0, 5.0, 6.0]}
    field = FieldSite(scan.fields["ranges"], scan)
    mismatched = value("array.sibling_mismatch", field, current=message["ranges"], container=message)
    assert mismatched == [1.0, 2.0, 3.0, 1.0]
    lonely = MessageType("L", {"ranges": scan.fields["ranges"]})
    with pytest.raises(NotApplicable, match="no sibling array"):
        value("array.sibling_mismatch", FieldSite(scan.fields["ranges"], lonely), current=[1.0],
              container={"ranges": [1.0]})


def test_usable_filters_what_the_codec_cannot_carry():
    string = site("string")
    json_usable, json_skipped = DEFAULT.usable(string, JSON)
    _, cbor_skipped = DEFAULT.usable(string, CBOR)
    assert "lone_surrogate" in {e.name for e in json_usable}
    assert [(e.name, reason) for e, reason in cbor_skipped] == [
        ("lone_surrogate", "CBOR text must be valid UTF-8 (it contains a lone surrogate)")]
    assert not json_skipped
    _, unbounded_skipped = DEFAULT.usable(site("float64"), JSON)
    assert {e.name for e, _ in unbounded_skipped} == {"below_min", "above_max", "at_min", "at_max"}


def test_bytes_travel_as_base64_in_json():
    assert wire_value(b"\x00\xff", FieldType(kind="bytes"), JSON) == "AP8="
    assert wire_value(b"\x00\xff", FieldType(kind="bytes"), CBOR) == b"\x00\xff"
    assert wire_value(b"\x00\xff", FieldType(kind="string"), JSON) == b"\x00\xff"


def test_lookup_and_suggestions():
    assert DEFAULT.lookup("dict:float.nan").key == "float.nan"
    assert DEFAULT.suggest("dict:float.nann") == "did you mean 'dict:float.nan'?"
    with pytest.raises(KeyError):
        DEFAULT.lookup("float.nan")


# ---------------------------------------------------------------- user files

def user(text: str):
    return dictionary_from_text(textwrap.dedent(text), "mine.yaml")


def test_user_files_add_override_and_remove_entries(tmp_path):
    merged = user("""
        float:
          nan: 42            # override (an int in the float group becomes a float)
          huge: "1e300"      # a numeric string too
        string:
          greeting: hello
          raw: {value: {"not": "a rule"}}
          sixteen_b: {repeat: b, times: 16}
        int:
          afl_100: {remove: true}
        """)
    assert merged.get("float.nan").value == 42.0 and type(merged.get("float.nan").value) is float
    assert merged.get("float.huge").value == 1e300
    assert merged.get("string.raw").value == {"not": "a rule"}
    assert merged.get("string.sixteen_b").value == "b" * 16
    assert "int.afl_100" not in merged and "int.afl_128" in merged
    assert merged.get("string.greeting").origin == "mine.yaml:6"
    path = tmp_path / "mine.yaml"
    path.write_text("time:\n  epoch_2038: 2147483648\n")
    assert load_dictionary([path]).get("time.epoch_2038").value == 2147483648.0
    assert len(load_dictionary([path])) == len(DEFAULT) + 1


BAD_USER_FILES = {
    "floats:\n  x: 1.0\n": (1, "unknown group 'floats'; did you mean 'float'?"),
    "float:\n  x: not-a-number\n": (2, "'not-a-number' is not a number"),
    "float:\n  x: {derive: below_mni}\n": (2, "unknown derive rule 'below_mni'; did you mean 'below_min'?"),
    "float:\n  x: {derive: negated}\n": (2, "rule 'negated' does not apply to the float group"),
    "string:\n  x: {repeat: A, times: 99999999}\n": (2, "'times' must be an integer"),
    "string:\n  x: {repeat: 5, times: 2}\n": (2, "'repeat' takes a string"),
    "string:\n  x: {vlue: 1}\n": (2, "unknown form"),
    "string:\n  x: 2001-01-01\n": (2, "YAML read this as date"),
    "string:\n  bad-name: x\n": (2, "not a plain identifier"),
    "string: [1, 2]\n": (1, "must be a mapping"),
    "int:\n  x: {remove: yes please}\n": (2, "'remove' takes true"),
    "- a\n- b\n": (1, "a dictionary is a mapping of groups"),
    # the int group takes whole numbers only
    'int:\n  x: "nan"\n': (2, "the int group takes whole numbers, not str 'nan'"),
    'int:\n  x: "1e999"\n': (2, "the int group takes whole numbers, not str '1e999'"),
    'int:\n  x: ".inf"\n': (2, "the int group takes whole numbers, not str '.inf'"),
    "int:\n  x: .inf\n": (2, "the int group takes whole numbers, not float inf"),
    "int:\n  x: 1e999\n": (2, "the int group takes whole numbers, not float inf"),
    "int:\n  x: 2.5\n": (2, "the int group takes whole numbers, not float 2.5"),
    "int:\n  x: true\n": (2, "the int group takes whole numbers, not the boolean true"),
}


@pytest.mark.parametrize("text", sorted(BAD_USER_FILES))
def test_bad_user_files_are_reported_with_place_and_fix(text):
    line, fragment = BAD_USER_FILES[text]
    with pytest.raises(InputError) as caught:
        dictionary_from_text(text, "mine.yaml")
    [problem] = caught.value.problems
    assert problem.file == "mine.yaml" and problem.line == line and problem.column
    assert fragment in problem.message, problem
    assert problem.fix


def test_missing_user_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        load_dictionary([tmp_path / "nope.yaml"])


def test_a_field_value_is_plain_data_a_codec_can_carry():
    """``is_field_value``: what a dictionary entry or a literal may put in a field (JSON's values and bytes)."""
    import datetime

    from astaa_deft.engine.intercept.dictionary import is_field_value

    for plain in (None, True, 3, -0.5, math.nan, "text", b"\x00", [1, [b"x"]], {"a": {"b": [None]}}):
        assert is_field_value(plain), plain
    for other in (datetime.date(2024, 1, 1), (1, 2), {1: "key not text"}, [object()], {"a": {1, 2}}):
        assert not is_field_value(other), other


def test_a_set_literal_naming_an_enum_value_yaml_read_as_a_date_is_refused_with_its_reason():
    import datetime

    from astaa_deft.engine.intercept.actions.set import ValueProblem, parse_literal

    enum = FieldType(kind="enum", values=(datetime.date(2024, 1, 1), "idle"))
    assert parse_literal("idle", enum) == "idle"
    with pytest.raises(ValueProblem, match="YAML date, which no message encoding carries"):
        parse_literal("2024-01-01", enum)
