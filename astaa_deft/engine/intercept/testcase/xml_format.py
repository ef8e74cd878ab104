"""The test case file format: XML read safely, checked against the XSD, and written back.

Reading refuses hostile input before any XML parser sees it (anything but
UTF-8, a DOCTYPE or ENTITY declaration — billion laughs, external entities —,
an oversized file), then lxml parses with entity resolution, DTD loading and
network access off, and the XSD (``astaa_deft/data/policies/testcase.xsd``)
checks the shape. Every problem is reported at its line and column in the
source text (:class:`Checker`, which the checks of :mod:`.loader` and of the
actions report through too), with a fix.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from typing import Protocol, cast

from lxml import etree

from astaa_deft.model.errors import AstaaDeftError, InputError, Problem
from astaa_deft.io.inputfile import POLICY
from astaa_deft.model.sut import Spec
from astaa_deft.engine.intercept.actions.base import ACTIONS, decimal_text
from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.engine.intercept.testcase.model import Selection, TestCase, Window

SCHEMA_PATH = Path(__file__).resolve().parents[3] / "data" / "policies" / "testcase.xsd"
MAX_FILE_BYTES = POLICY.max_bytes or 0  # the cap of a file read, applied to bytes given directly too
DOCS = "docs/policies.md"


def _error(name: str, line: int | None, column: int | None, message: str, *, fix: str) -> InputError:
    return InputError(Problem(name, line, column, message, fix))


_ENCODING_DECL = re.compile(rb"""^<\?xml[^>]*?\bencoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
# Declarations that make a parser expand or fetch things; refused outright.
_DANGEROUS = re.compile(r"<!\s*(DOCTYPE|ENTITY|ELEMENT|ATTLIST|NOTATION)", re.IGNORECASE)


def safe_text(data: bytes, name: str) -> str:
    """The file as text, after refusing what could make a parser expand or fetch anything."""
    if len(data) > MAX_FILE_BYTES:
        raise _error(name, 1, 1, f"larger than {MAX_FILE_BYTES // (1024 * 1024)} MB", fix="check the file")
    declared = _ENCODING_DECL.match(data.removeprefix(b"\xef\xbb\xbf"))
    if declared and declared.group(1).lower().replace(b"_", b"-") not in (b"utf-8", b"utf8", b"us-ascii", b"ascii"):
        raise _error(name, 1, declared.start(1) + 1, f"encoding {declared.group(1).decode()} is not supported",
                     fix='save the file as UTF-8 and write encoding="UTF-8"')
    try:
        text = data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise _error(name, line, exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1,
                     "not valid UTF-8 (test cases are UTF-8 text)", fix="save the file as UTF-8") from None
    danger = _DANGEROUS.search(text)
    if danger:
        line, column = _line_col(text, danger.start())
        raise _error(name, line, column,
                     f"<!{danger.group(1).upper()} declarations are refused (they enable entity expansion "
                     "and external entities)", fix="remove the DOCTYPE; test cases need no DTD or entities")
    return text


def hardened_parser() -> etree.XMLParser:
    # Belt and braces: safe_text already refused DTDs. No entity expansion, no
    # DTD loading, no network, default size limits (no huge_tree).
    return etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, dtd_validation=False,
                           huge_tree=False, attribute_defaults=False, remove_comments=True, remove_pis=True)


def parse_xml(data: bytes, name: str) -> etree._Element:
    try:
        root = etree.fromstring(data, hardened_parser())
    except etree.XMLSyntaxError as exc:
        line, column = exc.position if exc.position else (exc.lineno, None)
        message = re.sub(r", line \d+, column \d+$", "", exc.msg or str(exc))
        raise _error(name, line or 1, column or 1, f"not well-formed XML: {message}",
                     fix="fix the XML syntax here") from None
    docinfo = root.getroottree().docinfo
    if docinfo.internalDTD is not None or docinfo.externalDTD is not None or docinfo.doctype:
        raise _error(name, 1, 1, "DOCTYPE declarations are refused", fix="remove the DOCTYPE")
    return root


XS = "http://www.w3.org/2001/XMLSchema"


def schema_document() -> etree._ElementTree:
    """testcase.xsd with its Action group filled: one element per registered action, of the type it declares."""
    document = etree.parse(str(SCHEMA_PATH), hardened_parser())
    choice = document.find(f"{{{XS}}}group[@name='Action']/{{{XS}}}choice")
    assert choice is not None, "testcase.xsd lost its Action group"
    for name, action in ACTIONS.items():
        element = etree.SubElement(choice, f"{{{XS}}}element", name=name)
        element.append(etree.fromstring(f'<xs:schema xmlns:xs="{XS}">{action.schema}</xs:schema>',
                                        hardened_parser())[0])
    return document


def _schema() -> etree.XMLSchema:
    return _schema_of(ACTIONS.names())


@lru_cache(maxsize=2)
def _schema_of(actions: tuple[str, ...]) -> etree.XMLSchema:
    """The schema for this set of registered actions (built again when one is added, e.g. by a test)."""
    return etree.XMLSchema(schema_document())


# Hints for the schema's own types, keyed by the type name libxml2 quotes.
_TYPE_FIXES = {
    "Seconds": "seconds as a plain decimal from 0, e.g. 2.5 (no exponent, NaN or INF)",
    "Milliseconds": "milliseconds as a plain decimal above 0, e.g. 200",
    "Probability": "a plain decimal above 0 and at most 1, e.g. 0.25",
    "Fraction": "a plain decimal from 0 to below 1, e.g. 0.5",
    "Rate": "messages per second as a plain decimal above 0 and at most 1000, e.g. 20",
    "Count": "a whole number from 1, e.g. 3",
    "Copies": "a whole number from 1 to 100",
    "Seed": "a whole number from 0 to 2^64-1",
    "Id": "letters, digits, '_', '.' and '-' only",
    "Name": "a channel, type or module name from the spec: letters, digits, '_' and '-'",
}


# The schema type of each attribute, for messages that only name the attribute (facets).
_ATTRIBUTE_TYPES = {
    "from": "Seconds", "to": "Seconds", "ms": "Milliseconds", "max-hold-ms": "Milliseconds",
    "probability": "Probability", "keep": "Fraction", "rate": "Rate", "every": "Count", "limit": "Count",
    "message": "Count", "bytes": "Count", "copies": "Copies", "seed": "Seed", "id": "Id", "channel": "Name",
}
_POLICY_ORDER = ("a policy holds, in this order: <channel> (one or more) or <type>, <consumer>*, "
                 f"<window>?, <select>?, then exactly one action; see {DOCS}")


class _SchemaError(Protocol):
    """An entry of lxml's error log (lxml-stubs declare the log, not its entries)."""

    message: str
    path: str | None
    line: int


def validate_schema(root: etree._Element, checker: Checker) -> None:
    schema = _schema()
    if schema.validate(root.getroottree()):
        return
    for entry in cast("Iterable[_SchemaError]", schema.error_log):
        message = entry.message
        attribute = re.search(r"attribute '([^']+)'", message)
        element = _element_at(root, entry.path)
        line, column = (checker.locate(element, attribute.group(1) if attribute else None)
                        if element is not None else (entry.line, checker.first_column(entry.line)))
        parent = element.getparent() if element is not None else None
        in_policy = parent is not None and parent.tag == "policy"
        checker.report_at(line, column, message.rstrip("."),
                          _schema_fix(message, attribute.group(1) if attribute else None, in_policy))


def _element_at(root: etree._Element, path: str | None) -> etree._Element | None:
    if not path:
        return None
    try:
        found = root.getroottree().xpath(path)
    except etree.XPathError:
        return None
    return found[0] if isinstance(found, list) and found and isinstance(found[0], etree._Element) else None


def _schema_fix(message: str, attribute: str | None, in_policy: bool) -> str:
    typed = re.search(r"atomic type '(\w+)'", message)
    type_name = typed.group(1) if typed else _ATTRIBUTE_TYPES.get(attribute or "")
    if type_name in _TYPE_FIXES and "is not allowed" not in message:
        return _TYPE_FIXES[type_name]
    if "is not expected" in message:
        return _POLICY_ORDER if in_policy else f"remove it or move it where it belongs; see {DOCS}"
    missing = re.search(r"Missing child element\(s\)\. Expected is (.*)", message)
    if missing:
        names = [f"<{name}>" for name in re.findall(r"[\w:-]+", missing.group(1))]
        return f"add {' or '.join(names)}; see {DOCS}"
    if "Duplicate key-sequence" in message:
        return "give every policy of a test case its own id"
    if "is not allowed" in message or "is required but missing" in message:
        return f"see the element's attributes in {DOCS}"
    return f"see {DOCS}"


# ---------------------------------------------------------------- locating and reporting

class Checker:
    """Reports problems at the place of an element or attribute in the source text.

    lxml knows an element's line (where its start tag ends) but not columns,
    so the start tag and attribute are looked up in the text.
    """

    def __init__(self, name: str, text: str, spec: Spec | None, dictionary: Dictionary):
        self.name = name
        self.text = text
        self.spec = spec
        self.dictionary = dictionary
        self.problems: list[Problem] = []
        self._line_ends = [m.start() for m in re.finditer("\n", text)] + [len(text)]

    def report(self, element: etree._Element, message: str, fix: str = "", *,
               attribute: str | None = None, offset: int = 0) -> None:
        """A problem at ``element`` (its ``attribute``'s value, ``offset`` chars into it, when given)."""
        line, column = self.locate(element, attribute, offset)
        self.report_at(line, column, message, fix)

    def report_at(self, line: int | None, column: int | None, message: str, fix: str = "") -> None:
        self.problems.append(Problem(self.name, line, column, message, fix))

    def raise_if_problems(self) -> None:
        if self.problems:
            unique = list(dict.fromkeys(self.problems))
            raise InputError(sorted(unique, key=lambda p: (p.line or 0, p.column or 0)))

    def locate(self, element: etree._Element, attribute: str | None = None, offset: int = 0) -> tuple[int, int]:
        line = source_line(element) or 1
        limit = self._line_ends[min(line, len(self._line_ends)) - 1]
        tag = etree.QName(element).localname
        start = self._tag_start(f"{element.prefix}:{tag}" if element.prefix else tag, limit)
        if start is None:
            return line, 1
        position = start
        if attribute is not None:
            tag_end = self.text.find(">", start)
            found = re.compile(rf"\s{re.escape(attribute)}\s*=\s*[\"']").search(self.text, start, tag_end)
            if found:
                position = found.end() + offset
        return _line_col(self.text, position)

    def first_column(self, line: int) -> int:
        """The column of the first non-blank character of ``line`` (1 if none)."""
        start = self._line_ends[line - 2] + 1 if 1 < line <= len(self._line_ends) else 0
        text = self.text[start:self._line_ends[min(line, len(self._line_ends)) - 1]]
        return len(text) - len(text.lstrip()) + 1

    def _tag_start(self, tag: str, limit: int) -> int | None:
        """The last ``<tag`` that starts before ``limit`` (the end of the line its start tag ends on)."""
        pattern = re.compile(rf"<{re.escape(tag)}[\s/>]")
        start = None
        for match in pattern.finditer(self.text, 0, min(limit + 1, len(self.text))):
            start = match.start()
        return start


def source_line(element: etree._Element) -> int | None:
    """The line an element's start tag ends on (lxml-stubs leave ``sourceline`` untyped)."""
    return cast("int | None", element.sourceline)


class SchemaMismatch(AstaaDeftError):
    """The model is built from something the XSD does not guarantee: a bug here, never bad input."""


def required(element: etree._Element, attribute: str) -> str:
    """An attribute the XSD requires: present, as the schema is checked before the model is built."""
    value = element.get(attribute)
    if value is None:
        raise SchemaMismatch(f"<{element.tag}> has no '{attribute}', which testcase.xsd requires")
    return value


def required_child(element: etree._Element, tag: str) -> etree._Element:
    """A child element the XSD requires (see :func:`required`)."""
    child = element.find(tag)
    if child is None:
        raise SchemaMismatch(f"<{element.tag}> has no <{tag}>, which testcase.xsd requires")
    return child


def _line_col(text: str, position: int) -> tuple[int, int]:
    line = text.count("\n", 0, position) + 1
    return line, position - (text.rfind("\n", 0, position) + 1) + 1


# ---------------------------------------------------------------- writing

def write_testcase(testcase: TestCase) -> bytes:
    """The test case as an XML file (``TestCase.to_xml``); reading it back gives an equal ``TestCase``."""
    root = etree.Element("testcase", id=testcase.id, seed=str(testcase.seed))
    etree.SubElement(root, "description").text = testcase.description
    for policy in testcase.policies:
        element = etree.SubElement(root, "policy", id=policy.id)
        for channel in policy.channels:
            etree.SubElement(element, "channel").text = channel
        if policy.message_type is not None:
            etree.SubElement(element, "type").text = policy.message_type
        for consumer in policy.consumers:
            etree.SubElement(element, "consumer").text = consumer
        _write_window(element, policy.window)
        _write_selection(element, policy.selection)
        policy.action.write_xml(etree.SubElement(element, policy.action.name))
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + etree.tostring(root, encoding="UTF-8", pretty_print=True)


def _write_window(parent: etree._Element, window: Window) -> None:
    if window == Window():
        return
    element = etree.SubElement(parent, "window", {"from": decimal_text(window.start)})
    if window.end is not None:
        element.set("to", decimal_text(window.end))
    if window.anchor_channel is not None:
        etree.SubElement(element, "after", channel=window.anchor_channel, message=str(window.anchor_message))


def _write_selection(parent: etree._Element, selection: Selection) -> None:
    if selection == Selection():
        return
    element = etree.SubElement(parent, "select")
    if selection.every != 1:
        element.set("every", str(selection.every))
    if selection.probability != 1.0:
        element.set("probability", decimal_text(selection.probability))
    if selection.limit is not None:
        element.set("limit", str(selection.limit))
