"""Reading a test case: the file, its XML, its schema, then its names and values.

Reading a test case goes through four gates, each reporting every problem
with file, line, column and a fix (``InputError``):

1. hostile input is refused before any XML parser sees it: anything but
   UTF-8, a DOCTYPE or ENTITY declaration (billion laughs, external
   entities), an oversized file;
2. lxml parses with entity resolution, DTD loading and network access off;
3. the XSD (``astaa_deft/data/policies/testcase.xsd``) checks the shape;
4. names, field paths and values are checked against the SUT spec (when
   given) and the dictionary, with "did you mean" suggestions.

Gates 1-3 are the file format (:mod:`.xml_format`); gate 4 builds the model
(:mod:`.model`) here, each action reading and checking its own element.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

from lxml import etree

from astaa_deft.model.errors import did_you_mean
from astaa_deft.io.inputfile import POLICY, read_input
from astaa_deft.model.fields import FieldPath, FieldPathError
from astaa_deft.model.sut import Channel, Spec
from astaa_deft.engine.intercept.actions import ACTIONS
from astaa_deft.engine.intercept.actions.base import decimal_text
from astaa_deft.engine.intercept.dictionary import Dictionary, field_site, load_dictionary
from astaa_deft.engine.intercept.dictionary.rules import FieldSite
from astaa_deft.engine.intercept.testcase.model import Policy, Selection, TestCase, Window
from astaa_deft.engine.intercept.testcase.xml_format import (
    Checker,
    parse_xml,
    required,
    required_child,
    safe_text,
    source_line,
    validate_schema,
)


def load_testcase(path: Path | str, spec: Spec | None = None, dictionary: Dictionary | None = None) -> TestCase:
    """Read and check a test case file (see the module doc). Without ``spec``,
    channel, consumer and field names are not checked."""
    path = Path(path)
    return parse_testcase(read_input(path, POLICY), str(path), spec, dictionary)


def parse_testcase(data: bytes, name: str = "<testcase>", spec: Spec | None = None,
                   dictionary: Dictionary | None = None) -> TestCase:
    text = safe_text(data, name)
    root = parse_xml(data, name)
    checker = Checker(name, text, spec, _default_dictionary() if dictionary is None else dictionary)
    validate_schema(root, checker)
    checker.raise_if_problems()
    testcase = _build(root, checker)
    checker.raise_if_problems()
    return testcase


@lru_cache(maxsize=1)
def _default_dictionary() -> Dictionary:
    return load_dictionary()


# ---------------------------------------------------------------- building the model

def _build(root: etree._Element, checker: Checker) -> TestCase:
    description = required_child(root, "description")
    policies = tuple(_policy(element, checker) for element in root.iterfind("policy"))
    return TestCase(id=required(root, "id"), seed=int(required(root, "seed")),
                    description=(description.text or "").strip(), policies=policies, source=checker.name)


def _policy(element: etree._Element, checker: Checker) -> Policy:
    action_element = next(child for child in element if child.tag in ACTIONS)
    action_checker = ActionChecker(checker, action_element)
    action = ACTIONS[action_element.tag].from_xml(action_element, action_checker)
    type_element = element.find("type")
    policy = Policy(
        id=required(element, "id"), action=action,
        channels=tuple(_text(child) for child in element.iterfind("channel")),
        message_type=_text(type_element) if type_element is not None else None,
        consumers=tuple(_text(child) for child in element.iterfind("consumer")),
        window=_window(element.find("window"), checker),
        selection=_selection(element.find("select")),
        line=source_line(element))
    channels = _check_targets(policy, element, checker)
    action.check(policy, channels, action_checker)
    return policy


def _text(element: etree._Element) -> str:
    return (element.text or "").strip()


def _window(element: etree._Element | None, checker: Checker) -> Window:
    if element is None:
        return Window()
    start = float(element.get("from", "0"))
    to = element.get("to")
    end = float(to) if to is not None else None
    if end is not None and end <= start:
        checker.report(element, f"the window ends ({decimal_text(end)} s) before it starts ({decimal_text(start)} s)",
                       "make 'to' larger than 'from'", attribute="to")
    after = element.find("after")
    if after is None:
        return Window(start, end)
    return Window(start, end, required(after, "channel"), int(required(after, "message")))


def _selection(element: etree._Element | None) -> Selection:
    if element is None:
        return Selection()
    limit = element.get("limit")
    return Selection(every=int(element.get("every", "1")), probability=float(element.get("probability", "1")),
                     limit=int(limit) if limit is not None else None)


def _check_targets(policy: Policy, element: etree._Element, checker: Checker) -> tuple[Channel, ...]:
    """Check the policy's channels, type, consumers and window anchor; its target channels."""
    spec = checker.spec
    if spec is None:
        return ()
    names = [c.name for c in spec.channels]
    for child in element.iterfind("channel"):
        if _text(child) not in names:
            _unknown(checker, child, "channel", _text(child), known=names)
    type_element = element.find("type")
    if type_element is not None:
        carried = sorted({c.type for c in spec.channels})
        if policy.message_type not in spec.types:
            _unknown(checker, type_element, "message type", policy.message_type, known=list(spec.types))
        elif policy.message_type not in carried:
            checker.report(type_element, f"no channel carries type '{policy.message_type}'",
                           "types carried by channels: " + ", ".join(carried))
    channels = policy.target_channels(spec)
    consumers = sorted({m for c in channels for m in c.consumers})
    for child in element.iterfind("consumer"):
        if _text(child) not in consumers:
            what = ", ".join(c.name for c in channels) or "the targeted channels"
            hint = did_you_mean(_text(child), consumers)
            checker.report(child, f"'{_text(child)}' does not consume {what}" + (f"; {hint}" if hint else ""),
                           "consumers there: " + (", ".join(consumers) or "none"))
    after = element.find("window/after")
    if after is not None and after.get("channel") not in names:
        _unknown(checker, after, "channel", after.get("channel"), known=names, attribute="channel")
    return channels


def _unknown(checker: Checker, element: etree._Element, what: str, name: str | None, *, known: Sequence[str],
             attribute: str | None = None) -> None:
    hint = did_you_mean(str(name), known)
    shown = ", ".join(list(known)[:12]) + (", ..." if len(known) > 12 else "")
    checker.report(element, f"unknown {what} '{name}'" + (f"; {hint}" if hint else ""),
                   f"the spec's {what}s: {shown}" if known else "the spec declares none", attribute=attribute)


class ActionChecker:
    """What an action's ``from_xml`` and ``check`` get: the spec (None when not
    checking names), the dictionary, its element, and ``report``, which
    defaults to the action's element."""

    def __init__(self, checker: Checker, element: etree._Element):
        self._checker = checker
        self.element = element
        self.spec = checker.spec
        self.dictionary = checker.dictionary

    def report(self, element: etree._Element | None, message: str, fix: str = "", *,
               attribute: str | None = None, offset: int = 0) -> None:
        self._checker.report(self.element if element is None else element, message, fix,
                             attribute=attribute, offset=offset)

    def field_path(self, element: etree._Element | None, text: str, example: str, *,
                   attribute: str = "path") -> FieldPath | None:
        """``text`` as a field path, or None with the problem reported (``example``: paths to write instead)."""
        try:
            return FieldPath.parse(text)
        except FieldPathError as exc:
            self.report(element, f"invalid field path {text!r}: {exc.reason}", f"write paths like {example}",
                        attribute=attribute, offset=exc.position or 0)
            return None

    def site(self, element: etree._Element | None, channel: Channel, path: FieldPath, *,
             attribute: str = "path") -> FieldSite | None:
        """Where ``path`` lands in ``channel``'s type, or None with the problem reported."""
        assert self.spec is not None  # channels are given only when checking against a spec
        try:
            return field_site(self.spec.types, channel.type, path)
        except FieldPathError as exc:
            self.report(element, f"channel '{channel.name}' ({channel.type}): {exc.reason}",
                        "field paths follow the channel's type in the spec", attribute=attribute,
                        offset=exc.position or 0)
            return None
