"""Test case XML: valid files load into typed objects and write back unchanged;
hostile or malformed files are refused with file, line, column and a fix,
without reading local files or opening sockets."""

from __future__ import annotations

import json
import math
import re
import socket
from pathlib import Path

import pytest
from lxml import etree

from astaa_deft.cli.commands import policy_check
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept import Interceptor, load_dictionary
from astaa_deft.engine.intercept.actions import ACTIONS
from astaa_deft.engine.intercept.actions.corrupt import Corrupt
from astaa_deft.engine.intercept.actions.delay import Delay
from astaa_deft.engine.intercept.actions.drop import Drop
from astaa_deft.engine.intercept.actions.duplicate import Duplicate
from astaa_deft.engine.intercept.actions.interleave import Interleave
from astaa_deft.engine.intercept.actions.reorder import Reorder
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.testcase import (
    SCHEMA_PATH, Policy, Selection, TestCase, Window, load_testcase, parse_testcase,
)
from astaa_deft.engine.intercept.testcase.xml_format import hardened_parser, parse_xml, schema_document
from astaa_deft.engine.spec.loader import load_spec

ROOT = Path(__file__).resolve().parent.parent
ECHO = load_spec(ROOT / "tests" / "sut" / "echo.yaml")
BAD = ROOT / "tests" / "data" / "policies_bad"
EXAMPLES = ROOT / "astaa_deft" / "data" / "policies" / "examples"

# file -> (line, a fragment of the message) for every hostile or malformed file
EXPECTED = {
    "not_xml.xml": (1, "not well-formed XML"),
    "unclosed_tag.xml": (7, "Opening and ending tag mismatch"),
    "empty.xml": (1, "Document is empty"),
    "billion_laughs.xml": (2, "<!DOCTYPE declarations are refused"),
    "xxe_file.xml": (2, "<!DOCTYPE declarations are refused"),
    "xxe_http.xml": (2, "<!DOCTYPE declarations are refused"),
    "parameter_entity.xml": (2, "<!DOCTYPE declarations are refused"),
    "external_dtd.xml": (2, "<!DOCTYPE declarations are refused"),
    "latin1_encoding.xml": (1, "encoding ISO-8859-1 is not supported"),
    "xinclude.xml": (4, "XInclude}include': This element is not expected"),
    "wrong_root.xml": (2, "No matching global declaration"),
    "missing_seed.xml": (2, "'seed' is required"),
    "negative_seed.xml": (2, "'-5' is not a valid value"),
    "no_policy.xml": (2, "Expected is ( policy )"),
    "two_actions.xml": (7, "Element 'delay': This element is not expected"),
    "unknown_action.xml": (6, "Element 'explode': This element is not expected"),
    "window_nan.xml": (6, "'NaN' is not a valid value of the atomic type 'Seconds'"),
    "window_reversed.xml": (6, "the window ends (2 s) before it starts (5 s)"),
    "probability_above_one.xml": (6, "greater than the maximum value allowed"),
    "delay_words.xml": (6, "'two hundred' is not a valid value"),
    "duplicate_policy_id.xml": (5, "Duplicate key-sequence ['p']"),
    "unknown_channel.xml": (5, "unknown channel 'dta'; did you mean 'data'?"),
    "unknown_type.xml": (5, "unknown message type 'Sampel'; did you mean 'Sample'?"),
    "unknown_consumer.xml": (6, "'listner' does not consume data; did you mean 'listener'?"),
    "unknown_anchor.xml": (6, "unknown channel 'odometry'"),
    "unknown_field.xml": (7, "Header has no field 'sequence'"),
    "bad_path_syntax.xml": (7, "'[' is never closed"),
    "wrong_value_type.xml": (7, "'fast' is not a number"),
    "bool_into_int.xml": (7, "'true' is not a whole number"),
    "unknown_dictionary_entry.xml": (7, "did you mean 'dict:float.nan'?"),
    "rule_not_applicable.xml": (7, "dict:float.below_min: the field declares no min"),
    "corrupt_mixed_options.xml": (6, "'keep' belongs to mode=\"truncate\""),
    "set_without_fields.xml": (6, "Expected is ( field )"),
    "unknown_attribute.xml": (6, "The attribute 'sometimes' is not allowed"),
    "huge_integer.xml": (7, "integer too long"),
    "deeply_nested_json.xml": (7, "JSON nested too deeply"),
    "deep_elements.xml": (3, "Excessive depth in document"),
}


def test_every_bad_file_has_an_expectation():
    on_disk = {p.name for p in BAD.glob("*.xml")}
    assert on_disk == set(EXPECTED)
    assert len(on_disk) >= 20


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_file_is_refused_with_place_and_fix(name):
    line, fragment = EXPECTED[name]
    path = BAD / name
    with pytest.raises(InputError) as caught:
        load_testcase(path, ECHO)
    problems = caught.value.problems
    assert len(problems) == 1, problems
    problem = problems[0]
    assert problem.file == str(path)
    assert problem.line == line, problem
    assert problem.column is not None and problem.column >= 1
    assert fragment in problem.message, problem
    assert problem.fix


def test_columns_point_at_the_offending_attribute_value():
    with pytest.raises(InputError) as caught:
        load_testcase(BAD / "bad_path_syntax.xml", ECHO)
    problem = caught.value.problems[0]
    line = (BAD / "bad_path_syntax.xml").read_text().splitlines()[problem.line - 1]
    # The caret lands on the '[' that is never closed, inside path="header[x".
    assert line[problem.column - 1:] .startswith('[x"')


def test_all_problems_of_a_file_are_reported_together(tmp_path):
    path = tmp_path / "many.xml"
    path.write_text(_testcase("""
      <policy id="a"><channel>dta</channel><drop/></policy>
      <policy id="b"><channel>data</channel><set><field path="vlue" value="1"/></set></policy>
    """))
    with pytest.raises(InputError) as caught:
        load_testcase(path, ECHO)
    messages = [p.message for p in caught.value.problems]
    assert len(messages) == 2
    assert "did you mean 'data'" in messages[0]
    assert "did you mean 'value'" in messages[1]


# ---------------------------------------------------------------- hostile input never leaks or connects

SECRET = "s3cr3t-token-7f1d2e"


@pytest.fixture
def secret_file(tmp_path):
    path = tmp_path / "secret.txt"
    path.write_text(SECRET)
    return path


@pytest.fixture
def listener():
    """A TCP listener on loopback: a test asserts nothing ever connects to it."""
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(5)
    server.settimeout(0.3)
    yield server
    server.close()


def _assert_no_connection(server: socket.socket) -> None:
    with pytest.raises(socket.timeout):
        connection, _ = server.accept()
        connection.close()


def _hostile_documents(secret: Path, port: int) -> dict[str, str]:
    url = f"http://127.0.0.1:{port}"
    body = '<testcase id="t" seed="1"><description>&x;</description></testcase>'
    return {
        "file entity": f'<!DOCTYPE testcase [<!ENTITY x SYSTEM "{secret.as_uri()}">]>{body}',
        "http entity": f'<!DOCTYPE testcase [<!ENTITY x SYSTEM "{url}/entity">]>{body}',
        "parameter entity": f'<!DOCTYPE testcase [<!ENTITY % p SYSTEM "{url}/p.dtd"> %p;]>{body}',
        "external dtd": f'<!DOCTYPE testcase SYSTEM "{url}/testcase.dtd">{body}',
        "xinclude": f'<testcase id="t" seed="1" xmlns:xi="http://www.w3.org/2001/XInclude"><description/>'
                    f'<xi:include href="{url}/x" parse="text"/><xi:include href="{secret.as_uri()}" parse="text"/>'
                    f'</testcase>',
    }


def test_external_entities_never_read_files_nor_connect(secret_file, listener):
    port = listener.getsockname()[1]
    for what, document in _hostile_documents(secret_file, port).items():
        with pytest.raises(InputError) as caught:
            parse_testcase(document.encode(), what, ECHO)
        assert SECRET not in str(caught.value), what
    _assert_no_connection(listener)


def test_the_parser_itself_is_hardened(secret_file, listener):
    """Even without the pre-check, lxml expands nothing, reads nothing, fetches nothing: each hostile document
    parses with its entity left a bare reference (no DTD loaded) and its XIncludes left unprocessed elements."""
    port = listener.getsockname()[1]
    for what, document in _hostile_documents(secret_file, port).items():
        root = etree.fromstring(document.encode(), hardened_parser())
        text = etree.tostring(root, encoding="unicode")
        assert SECRET not in text, what
        assert root.getroottree().docinfo.externalDTD is None, what
        if what == "xinclude":
            includes = root.findall("{http://www.w3.org/2001/XInclude}include")
            assert [i.get("href") for i in includes] == [f"http://127.0.0.1:{port}/x", secret_file.as_uri()]
        else:
            [reference] = root.find("description")
            assert (reference.tag, reference.text) == (etree.Entity, "&x;"), what  # not resolved, not replaced
    _assert_no_connection(listener)


def test_billion_laughs_is_refused_quickly():
    laughs = (BAD / "billion_laughs.xml").read_bytes()
    with pytest.raises(InputError):
        parse_testcase(laughs, "laughs")
    # And the hardened parser alone refuses to expand it too (libxml2's amplification limit).
    body = laughs.replace(b"<testcase", b"<!-- -->\n<testcase")
    with pytest.raises(etree.XMLSyntaxError, match="amplification"):
        etree.fromstring(body, hardened_parser())


def test_doctype_slipping_past_the_text_check_is_still_refused():
    """parse_xml refuses any DOCTYPE the parser saw (defence in depth)."""
    with pytest.raises(InputError, match="DOCTYPE"):
        parse_xml(b'<!DOCTYPE testcase><testcase id="t" seed="1"/>', "x")


def test_utf16_and_invalid_utf8_are_refused():
    utf16 = '<?xml version="1.0" encoding="UTF-16"?><!DOCTYPE a [<!ENTITY x "y">]><testcase/>'.encode("utf-16")
    with pytest.raises(InputError, match="UTF-8"):
        parse_testcase(utf16, "utf16.xml")
    with pytest.raises(InputError) as caught:
        parse_testcase(b'<testcase id="t" seed="1">\n<description>\xff</description></testcase>', "bad.xml")
    assert caught.value.problems[0].line == 2


def test_oversized_file_is_refused_without_parsing(tmp_path):
    path = tmp_path / "big.xml"
    path.write_bytes(b"<testcase>" + b" " * (11 * 1024 * 1024) + b"</testcase>")
    with pytest.raises(InputError, match="larger than"):
        load_testcase(path)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        load_testcase(tmp_path / "nope.xml")
    with pytest.raises(InputError, match="is a directory"):
        load_testcase(tmp_path)


# ---------------------------------------------------------------- valid test cases

def _testcase(policies: str, seed: int = 1) -> str:
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<testcase id="t" seed="{seed}">\n'
            f"<description>d</description>{policies}</testcase>\n")


EVERY_ACTION = _testcase("""
  <policy id="set-it">
    <channel>data</channel>
    <consumer>listener</consumer>
    <window from="1.5" to="4"><after channel="data" message="3"/></window>
    <select every="2" probability="0.5" limit="10"/>
    <set><field path="value" value="dict:float.nan"/><field path="header.seq" value="18446744073709551616"/></set>
  </policy>
  <policy id="drop-it"><type>Sample</type><drop/></policy>
  <policy id="delay-it"><channel>data</channel><delay ms="250.5"/></policy>
  <policy id="dup-it"><channel>data</channel><duplicate copies="3"/></policy>
  <policy id="swap-it"><channel>data</channel><reorder max-hold-ms="50"/></policy>
  <policy id="inject-it"><channel>data</channel><interleave rate="20">
    <field path="header.stamp" value="dict:time.jump_back"/></interleave></policy>
  <policy id="flip-it"><channel>data</channel><corrupt mode="flip" bytes="2"/></policy>
  <policy id="cut-it"><channel>data</channel><corrupt mode="truncate" keep="0.25"/></policy>
""", seed=18446744073709551615)


def test_every_action_loads_into_typed_objects():
    testcase = parse_testcase(EVERY_ACTION.encode(), "all.xml", ECHO)
    assert testcase.id == "t" and testcase.seed == 2**64 - 1 and testcase.description == "d"
    first = testcase.policies[0]
    assert first == Policy(id="set-it",
        action=Set((Assignment("value", "dict:float.nan"), Assignment("header.seq", "18446744073709551616"))),
        channels=("data",), consumers=("listener",), window=Window(1.5, 4.0, "data", 3),
        selection=Selection(every=2, probability=0.5, limit=10))
    assert [p.action for p in testcase.policies[1:]] == [
        Drop(), Delay(250.5), Duplicate(3), Reorder(50.0),
        Interleave(20.0, (Assignment("header.stamp", "dict:time.jump_back"),)),
        Corrupt("flip", bytes=2), Corrupt("truncate", keep=0.25)]
    assert testcase.policies[1].message_type == "Sample"


def test_to_xml_round_trips_and_is_schema_valid():
    testcase = parse_testcase(EVERY_ACTION.encode(), "all.xml", ECHO)
    written = testcase.to_xml()
    assert parse_testcase(written, "written.xml", ECHO) == testcase
    assert written.startswith(b'<?xml version="1.0" encoding="UTF-8"?>')
    assert testcase.to_xml() == written  # deterministic


def test_to_xml_writes_defaults_compactly_and_escapes_values():
    testcase = TestCase(id="x", seed=3, description='quotes " and <tags> & more', policies=(
        Policy(id="p", action=Set((Assignment("value", 'json:"<&\'\\">"'),)), channels=("data",)),))
    written = testcase.to_xml()
    assert b"<window" not in written and b"<select" not in written
    assert parse_testcase(written, "x.xml", ECHO) == testcase


def test_values_and_names_are_only_checked_against_a_spec_when_given():
    loose = _testcase('<policy id="p"><channel>nowhere</channel><set><field path="x.y" value="1"/></set></policy>')
    assert parse_testcase(loose.encode(), "loose.xml").policies[0].channels == ("nowhere",)
    with pytest.raises(InputError):
        parse_testcase(loose.encode(), "loose.xml", ECHO)
    # Dictionary references are checked even without a spec.
    typo = _testcase('<policy id="p"><channel>c</channel><set><field path="x" value="dict:float.nann"/></set></policy>')
    with pytest.raises(InputError, match="did you mean 'dict:float.nan'"):
        parse_testcase(typo.encode(), "typo.xml")


@pytest.mark.parametrize("value", ["nan", "-inf", "1e16", "-0.0", "json:\"fast\"", "json:null", "str:dict:x",
                                   "dict:float.pi", "dict:string.long_A"])
def test_accepted_values_for_a_float_field(value):
    """Each form is accepted, kept as written, and sets what it says on a real message."""
    xml = _testcase(f'<policy id="p"><channel>data</channel><set><field path="value" value=\'{value}\'/></set>'
                    f"</policy>")
    testcase = parse_testcase(xml.encode(), "v.xml", ECHO)
    assert testcase.policies[0].action.fields == (Assignment(path="value", value=value),)
    [delivery] = Interceptor(testcase, ECHO, load_dictionary()).on_message(
        "data", ("listener",), json.dumps({"header": {"seq": 1, "stamp": 0.5}, "value": 2.0}).encode(), 0.1)
    got = json.loads(delivery.payload)["value"]
    expected = {"nan": math.nan, "-inf": -math.inf, "1e16": 1e16, "-0.0": -0.0, 'json:"fast"': "fast",
                "json:null": None, "str:dict:x": "dict:x", "dict:float.pi": math.pi,
                "dict:string.long_A": "A" * 8192}[value]
    assert json.dumps(got) == json.dumps(expected) and type(got) is type(expected), (value, got)


@pytest.mark.parametrize("prefix,spec", [("echo_", ROOT / "tests" / "sut" / "echo.yaml"),
                                         ("demo_", ROOT / "specs" / "demo_av.yaml")])
def test_shipped_examples_are_valid(capsys, prefix, spec):
    files = sorted(EXAMPLES.glob(f"{prefix}*.xml"))
    assert files
    assert policy_check.check_policies(files, spec) == 0
    assert capsys.readouterr().out.count(": ok") == len(files)


def test_every_shipped_example_is_checked():
    assert {p.name[:5] for p in EXAMPLES.glob("*.xml")} == {"echo_", "demo_"}


def test_policy_check_command_reports_every_bad_file(tmp_path):
    with pytest.raises(InputError) as caught:
        policy_check.check_policies([BAD], ROOT / "tests" / "sut" / "echo.yaml")
    assert {Path(p.file).name for p in caught.value.problems} == set(EXPECTED)


def test_every_action_module_has_its_schema_element():
    ns = {"xs": "http://www.w3.org/2001/XMLSchema"}
    as_written = etree.parse(str(SCHEMA_PATH)).xpath("//xs:group[@name='Action']//xs:element/@name", namespaces=ns)
    assert as_written == []  # the actions' elements come from their own modules, not from the file
    schema = schema_document()
    in_schema = set(schema.xpath("//xs:group[@name='Action']/xs:choice/xs:element/@name", namespaces=ns))
    assert in_schema == set(ACTIONS) == {"set", "drop", "delay", "duplicate", "reorder", "interleave", "corrupt",
                                         "participant", "remove", "swap", "hold"}


def test_the_documented_example_is_valid():
    text = (ROOT / "docs" / "policies.md").read_text()
    example = re.search(r"```xml\n(.*?)```", text, re.S).group(1)
    testcase = parse_testcase(example.encode(), "docs/policies.md")
    assert [p.id for p in testcase.policies] == ["nan-speed", "stale-copies", "lossy"]


# ---------------------------------------------------------------- indices and non-finite values

DEMO = load_spec(ROOT / "astaa_deft" / "data" / "specs" / "demo_av.yaml")  # trajectory: points max_length 200


def _set_on_trajectory(path: str, value: str = "1.5") -> bytes:
    return _testcase(f'<policy id="p"><channel>trajectory</channel><set><field path="{path}" value="{value}"/>'
                     f"</set></policy>").encode()


@pytest.mark.parametrize("path,says", [
    ("points[99999999999999999999999].v", "index 99999999999999999999999 is beyond any array (at most 2147483647)"),
    ("points[200].v", "index [200] is outside 'points'"),
    ("points[-9999].v", "index [-9999] is outside 'points'"),
    ("points[-201].v", "valid indices are 0..199, or -200..-1 from the end"),
])
def test_an_index_beyond_the_arrays_max_length_is_refused(path, says):
    with pytest.raises(InputError) as caught:
        parse_testcase(_set_on_trajectory(path), "idx.xml", DEMO)
    [problem] = caught.value.problems
    assert says in problem.message, problem
    assert problem.line == 3 and problem.column  # the policy's line in _testcase


@pytest.mark.parametrize("path", ["points[199].v", "points[-200].v", "points[-1].v", "points[0].v", "points[*].v"])
def test_indices_within_max_length_are_accepted(path):
    """Accepted, and on a full trajectory (200 points, its max_length) they set the point they name."""
    testcase = parse_testcase(_set_on_trajectory(path), "idx.xml", DEMO)
    points = [{"t": i / 10, "x": float(i), "y": 0.0, "heading": 0.0, "v": 5.0, "a": 0.0} for i in range(200)]
    message = {"header": {"seq": 1, "stamp": 0.5}, "points": points, "decision": {"lane": 0}, "debug": {}}
    [delivery] = Interceptor(testcase, DEMO, load_dictionary()).on_message(
        "trajectory", ("control",), json.dumps(message).encode(), 0.1)
    speeds = [p["v"] for p in json.loads(delivery.payload)["points"]]
    index = path[len("points["):path.index("]")]
    named = set(range(200)) if index == "*" else {int(index) % 200}
    assert speeds == [1.5 if i in named else 5.0 for i in range(200)], path


def test_a_float_literal_that_overflows_is_refused_but_inf_on_purpose_is_not():
    with pytest.raises(InputError, match=r"'1e999' is beyond the largest float .* write inf or -inf"):
        parse_testcase(_set_on_trajectory("points[1].v", "1e999"), "inf.xml", DEMO)
    for spelled in ("inf", "-inf", "Infinity", "nan"):
        parse_testcase(_set_on_trajectory("points[1].v", spelled), "inf.xml", DEMO)


@pytest.mark.parametrize("value", ["nan", "inf", "1e999", "1.5"])
def test_an_int_field_never_takes_a_non_integer(value):
    xml = _testcase(f'<policy id="p"><channel>data</channel><set><field path="header.seq" value="{value}"/>'
                    f"</set></policy>")
    with pytest.raises(InputError, match="is not a whole number"):
        parse_testcase(xml.encode(), "int.xml", ECHO)
