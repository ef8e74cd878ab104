"""``set``: rewrite fields of the selected messages.

    <set>
      <field path="points[*].v" value="dict:float.nan"/>
      <field path="header.seq" value="0"/>
    </set>

A ``value`` is one of (see docs/policies.md):

* ``dict:GROUP.NAME``: a dictionary entry (``dict:float.nan``);
* ``json:JSON``: exactly this JSON value, whatever the declared type
  (type confusion on purpose: ``json:"fast"`` in a float field);
* ``str:TEXT``: this string, verbatim;
* otherwise a literal read as the field's declared type: ``2.5``, ``nan``,
  ``-inf`` for floats and times; ``-1`` for integers (beyond the width is
  allowed); ``true``/``false``; a declared enum value; base64 for bytes;
  JSON for arrays and structs; any text for strings.

The field machinery here (``Assignment``, ``plan_fields``, ``apply_plans``)
is shared with ``interleave``, which sets fields of the messages it injects.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, ClassVar

from lxml import etree

from astaa_deft.io.codecs import DecodeError, get_codec, json_fast
from astaa_deft.model.errors import AstaaDeftError, InputError, Problem, did_you_mean
from astaa_deft.model.fields import FieldPath, FieldPathError, get, set_field
from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS, Channel, FieldType
from astaa_deft.engine.intercept.dictionary import (
    DYNAMIC, GROUP_OF_KIND, REF_PREFIX, Dictionary, Dynamic, Entry, FieldSite, FieldValue, NotApplicable,
    UnknownEntry, ValueContext, field_site, is_field_value, wire_value,
)
from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionDetail, ActionRuntime, FastPath, FieldChange, MessageInfo,
    Pending, PinnedStep, PolicyContext, built, required,
)

if TYPE_CHECKING:
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy

_ENTRY_FIX = "entries are listed in dictionaries/default.yaml and your --dictionary files"
JSON_PREFIX = "json:"
STR_PREFIX = "str:"


# ---------------------------------------------------------------- assignments as written

@dataclass(frozen=True)
class Assignment:
    path: str
    value: str  # as written: a literal, dict:..., json:... or str:...


def value_text(value: object) -> str:
    """A ``<field value=…>`` that sets exactly ``value`` whatever the field's declared type.

    ``json:`` with ASCII escapes: the text stays valid XML (control
    characters and lone surrogates are escaped) and reads back to the same
    Python value (NaN and infinities included). Bytes go as base64, which a
    ``bytes`` field reads as binary.
    """
    if isinstance(value, (bytes, bytearray)):
        return base64.b64encode(bytes(value)).decode("ascii")
    return JSON_PREFIX + json.dumps(value, ensure_ascii=True, allow_nan=True, separators=(",", ":"))


def literal_assignments(changes: Sequence[FieldChange]) -> tuple[Assignment, ...]:
    """Assignments setting the values that were actually sent, never the rule that produced them.

    (``time.jump_back`` recomputed on another run would give another value.)
    """
    return tuple(Assignment(change.path, value_text(change.new)) for change in changes)


def pinned_as_set(step: PinnedStep) -> Set | None:
    """A field action's minimised step as a ``set`` of the values it sent (``swap``, ``hold``); None when none
    is kept."""
    return Set(literal_assignments(step.fields)) if step.fields else None


@dataclass(frozen=True)
class FieldsDetail(ActionDetail):
    """What ``set`` and ``interleave`` record beyond their field changes."""

    injection: int | None = None  # interleave: the number of this injection, from 1
    skipped_fields: tuple[dict[str, str], ...] | None = None  # assignments that did not apply, and why
    skipped: str | None = None  # why nothing was set (or injected)


def read_assignments(element: etree._Element) -> tuple[Assignment, ...]:
    return tuple(Assignment(required(child, "path"), required(child, "value"))
                 for child in element.iterfind("field"))


def write_assignments(element: etree._Element, assignments: Sequence[Assignment]) -> None:
    for assignment in assignments:
        etree.SubElement(element, "field", path=assignment.path, value=assignment.value)


def check_assignments(assignments: Sequence[Assignment], channels: Sequence[Channel],
                      checker: ActionChecker) -> None:
    """Paths exist in every target channel's type; values fit each field's declared type."""
    for assignment, child in zip(assignments, checker.element.iterfind("field"), strict=True):
        path = checker.field_path(child, assignment.path, "header.stamp, points[2].x or points[*].v")
        if path is None:
            continue
        if assignment.value.startswith(REF_PREFIX):
            try:  # even without a spec: a typo in a reference is always an error
                checker.dictionary.lookup(assignment.value)
            except UnknownEntry as exc:
                _report_value(checker, child, ValueProblem(str(exc), _ENTRY_FIX))
                continue
        for channel in channels:  # only given when checking against a spec
            site = checker.site(child, channel, path)
            if site is None:
                continue
            try:
                value_source(assignment.value, site, checker.dictionary)
            except ValueProblem as exc:
                _report_value(checker, child, ValueProblem(
                    f"field '{path}' ({site.field_type.describe()}) of channel '{channel.name}': {exc}", exc.fix))


def _report_value(checker: ActionChecker, element: etree._Element, problem: ValueProblem) -> None:
    checker.report(element, str(problem), problem.fix, attribute="value")


# ---------------------------------------------------------------- typing values

class ValueProblem(AstaaDeftError, ValueError):
    def __init__(self, message: str, fix: str = ""):
        super().__init__(message)
        self.fix = fix


@dataclass(frozen=True)
class Literal:
    value: FieldValue  # as the field's declared type reads it (parse_literal)


def value_source(text: str, site: FieldSite, dictionary: Dictionary) -> Literal | Entry:
    """What ``text`` means for a field: a dictionary entry or a typed literal (ValueProblem if neither)."""
    if text.startswith(REF_PREFIX):
        try:
            entry = dictionary.lookup(text)
        except UnknownEntry as exc:
            raise ValueProblem(str(exc), _ENTRY_FIX) from None
        problem = entry.problem(site)
        if problem:
            raise ValueProblem(f"{text}: {problem}", _group_hint(site, dictionary))
        return entry
    return Literal(parse_literal(text, site.field_type))


def _group_hint(site: FieldSite, dictionary: Dictionary) -> str:
    group = GROUP_OF_KIND.get(site.field_type.kind)
    names = [entry.ref for entry in dictionary.group(group)][:6] if group else []
    return ("values for this field include " + ", ".join(names)) if names else "pick another value"


def parse_literal(text: str, field_type: FieldType) -> FieldValue:
    """A literal value as the field's declared type reads it (ValueProblem if it cannot)."""
    if text.startswith(JSON_PREFIX):
        return _json_literal(text[len(JSON_PREFIX):])
    if text.startswith(STR_PREFIX):
        return text[len(STR_PREFIX):]
    kind = field_type.kind
    if kind in FLOAT_KINDS or kind == "time":
        try:
            number = float(text.strip())
        except ValueError:
            raise ValueProblem(f"{text!r} is not a number",
                               'write e.g. 2.5, -1e16, nan or -inf; json:"..." sends a string on purpose') from None
        if math.isinf(number) and not _SPELLS_INFINITY.fullmatch(text.strip()):
            raise ValueProblem(f"{text!r} is beyond the largest float ({sys.float_info.max:.4g})",
                               "write inf or -inf to send an infinity on purpose")
        return number
    if kind in INT_KINDS:
        if not re.fullmatch(r"\s*[+-]?[0-9]+\s*", text):
            raise ValueProblem(f"{text!r} is not a whole number",
                               "write e.g. -1 (values beyond the width are sent as written); "
                               "json:2.5 sends a non-integer on purpose")
        try:
            return int(text)
        except ValueError as exc:  # beyond Python's int-to-str digit limit
            raise ValueProblem(f"integer too long: {exc}", "use a shorter integer") from None
    if kind == "bool":
        if text.strip() in ("true", "false"):
            return text.strip() == "true"
        raise ValueProblem(f"{text!r} is not true or false", "dict:bool.* has other values, e.g. dict:bool.one")
    if kind == "enum":
        for declared in field_type.values:
            if str(declared) == text.strip():
                if not is_field_value(declared):  # a YAML date, say
                    raise ValueProblem(f"{text!r} is declared as a YAML {type(declared).__name__}, which no "
                                       "message encoding carries", "quote the value in the spec's enum")
                return declared
        hint = did_you_mean(text.strip(), [str(v) for v in field_type.values])
        raise ValueProblem(f"{text!r} is not a declared value" + (f"; {hint}" if hint else ""),
                           "dict:enum.undefined sends an undeclared value on purpose")
    if kind == "bytes":
        try:
            return base64.b64decode(text.strip(), validate=True)
        except (binascii.Error, ValueError):
            raise ValueProblem(f"{text!r} is not base64", "write base64 text (e.g. AAEC), or use dict:bytes.*") \
                from None
    if kind in ("array", "struct"):
        value = _json_literal(text)
        expected = list if kind == "array" else dict
        if type(value) is not expected:
            raise ValueProblem(f"{text!r} is not a JSON {'array' if kind == 'array' else 'object'}",
                               "write e.g. [] or [1, 2]" if kind == "array" else 'write e.g. {"x": 1}')
        return value
    return text  # string


_SPELLS_INFINITY = re.compile(r"[+-]?inf(inity)?", re.IGNORECASE)


def _json_literal(text: str) -> FieldValue:
    try:
        return json.loads(text)  # Python's reader also takes NaN and Infinity
    except (json.JSONDecodeError, ValueError) as exc:
        raise ValueProblem(f"not valid JSON: {exc}", 'e.g. json:null, json:"text", json:[1, 2]') from None
    except RecursionError:
        raise ValueProblem("JSON nested too deeply", "a field value needs no more than a few levels") from None


# ---------------------------------------------------------------- applying to messages

@dataclass(frozen=True, kw_only=True)
class FieldPlan:
    """One assignment on one channel, resolved once before the run."""

    path: FieldPath
    site: FieldSite
    source: Literal | Entry
    value: FieldValue | Dynamic  # the value to set, or DYNAMIC (computed per match)
    skip: str | None = None  # why this assignment never applies on the channel
    text: str = ""  # the path as written, rendered once (events name it per message)
    direct: bool = False  # one place and a scalar value: _set_one, not the general matcher


def plan_fields(assignments: Sequence[Assignment], channel: Channel, context: PolicyContext) -> tuple[FieldPlan, ...]:
    """Resolve assignments for one channel before the run.

    A test case read by ``load_testcase`` with the spec was checked already;
    one built in code may still be invalid: InputError naming its policy.
    """
    codec = get_codec(channel.encoding)
    plans = []
    for assignment in assignments:
        try:
            path = FieldPath.parse(assignment.path)
            site = field_site(context.spec.types, channel.type, path)
            source = value_source(assignment.value, site, context.dictionary)
        except (FieldPathError, ValueProblem) as exc:
            raise InputError(Problem(
                context.where, context.policy.line, None,
                f"policy '{context.policy.id}', channel '{channel.name}', field {assignment.path!r}: {exc}",
                getattr(exc, "fix", "") or "check the path against the channel's type")) from None
        value = source.value if isinstance(source, Literal) else source.static_value(site)
        skip = None
        if value is not DYNAMIC:
            value = wire_value(value, site.field_type, codec)
            skip = codec.carries(value)
        direct = path.is_concrete and value is not DYNAMIC and type(value) not in (dict, list)
        plans.append(FieldPlan(path=path, site=site, source=source, value=value, skip=skip, text=str(path),
                               direct=direct))
    return tuple(plans)


_MISSING = object()


def _set_one(message: dict, segments: tuple, value: Any) -> Any:
    """Set the one place a concrete path names; its old value, or _MISSING if it is not there.

    Same result as ``fields.set_field`` for a concrete path and a scalar
    value, at a third of the cost: this runs for every mutated message.
    """
    node: Any = message
    for segment in segments[:-1]:
        if type(segment) is str:
            node = node.get(segment, _MISSING) if type(node) is dict else _MISSING
        else:
            node = node[segment] if type(node) is list and segment < len(node) else _MISSING
        if node is _MISSING:
            return _MISSING
    last = segments[-1]
    if type(last) is str:
        if type(node) is not dict or last not in node:
            return _MISSING
    elif type(node) is not list or last >= len(node):
        return _MISSING
    old = node[last]
    node[last] = value
    return old


def apply_plans(message: dict, plans: Sequence[FieldPlan], info: MessageInfo) -> tuple[list[FieldChange], list[dict]]:
    """Set every planned field in ``message`` (in place); (changes, skipped places with reasons)."""
    changes: list[FieldChange] = []
    skipped: list[dict] = []
    for plan in plans:
        if plan.skip is not None:
            skipped.append({"path": str(plan.path), "reason": plan.skip})
        elif plan.direct:
            old = _set_one(message, plan.path.segments, plan.value)
            if old is _MISSING:
                skipped.append({"path": plan.text, "reason": "no such field in this message"})
            else:
                changes.append(built(FieldChange, path=plan.text, old=old, new=plan.value))
        elif plan.value is not DYNAMIC:
            replaced = set_field(message, plan.path, plan.value)
            changes.extend(FieldChange(str(where), old, plan.value) for where, old in replaced)
            if not replaced:
                skipped.append({"path": str(plan.path), "reason": "no such field in this message"})
        else:
            _apply_dynamic(message, plan, info, changes=changes, skipped=skipped)
    return changes, skipped


def _apply_dynamic(message: dict, plan: FieldPlan, info: MessageInfo, *,
                   changes: list[FieldChange], skipped: list[dict]) -> None:
    """Each place ``plan`` matches set to its rule's value now; appends to ``changes`` and ``skipped``."""
    matches = get(message, plan.path)
    if not matches:
        skipped.append({"path": str(plan.path), "reason": "no such field in this message"})
    for where, old in matches:
        parent_segments = where.segments[:-1]
        container = get(message, FieldPath._trusted(parent_segments))[0][1] if parent_segments else message
        context = ValueContext(site=plan.site, current=old, container=container, key=where.segments[-1],  # type: ignore[arg-type]
                               previous=partial(_previous_at, info, where))
        try:
            value = wire_value(plan.source.resolve(context), plan.site.field_type, info.codec)  # type: ignore[union-attr]
            reason = info.codec.carries(value)
        except NotApplicable as exc:
            reason = str(exc)
        if reason is not None:
            skipped.append({"path": str(where), "reason": reason})
            continue
        set_field(message, where, value)
        changes.append(FieldChange(str(where), old, value))


def _previous_at(info: MessageInfo, where: FieldPath) -> Any:
    found = get(info.previous_message(), where)
    if not found:
        raise NotApplicable(f"the previous message has no {where}")
    return found[0][1]


# ---------------------------------------------------------------- the action

@ACTIONS.register_class
@dataclass(frozen=True)
class Set(ActionConfig):
    name: ClassVar[str] = "set"
    # Its element's type in the test case schema (spliced into testcase.xsd's Action group).
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:sequence>
          <xs:element name="field" type="Field" maxOccurs="unbounded"/>
        </xs:sequence>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = FieldsDetail
    carries_fields: ClassVar[bool] = True
    fields: tuple[Assignment, ...]

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Set:
        return cls(read_assignments(element))

    def write_xml(self, element: etree._Element) -> None:
        write_assignments(element, self.fields)

    def field_paths(self) -> tuple[str, ...]:
        return tuple(a.path for a in self.fields)

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        check_assignments(self.fields, channels, checker)

    def start(self, context: PolicyContext) -> ActionRuntime:
        return SetRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Set | None:
        """The kept field changes as literals of the values sent; None when none is kept."""
        return cls(literal_assignments(step.fields)) if step.fields else None


class SetRuntime(ActionRuntime):
    def __init__(self, config: Set, context: PolicyContext):
        self.context = context
        self.plans = {channel.name: plan_fields(config.fields, channel, context)
                      for channel in context.channels}
        self._codecs = {channel.name: get_codec(channel.encoding) for channel in context.channels}

    def fast_path(self, channel: str) -> FastPath | None:
        """JSON, and every field one place set to a fixed scalar orjson writes as the codec does: see ``_fast_set``."""
        plans, codec = self.plans.get(channel), self._codecs.get(channel)
        if not plans or codec is None or codec.name != "json":
            return None
        if not all(plan.direct and plan.skip is None and json_fast.writes_alike(plan.value, codec.encode)
                   for plan in plans):
            return None
        return partial(_fast_set, tuple((plan.path.segments, plan.value, plan.text) for plan in plans))

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        decoded_here = item.message is None
        if decoded_here:
            try:
                item.message = info.codec.decode(item.payload)  # type: ignore[arg-type]
            except DecodeError as exc:
                item.events.append(self.context.event(
                    "set", info, item.consumers, detail=FieldsDetail(skipped=f"undecodable: {exc}").to_json()))
                return [item]
        changes, skipped = apply_plans(item.message, self.plans[info.channel], info)  # type: ignore[arg-type]
        if changes and not skipped:  # every field set (the common case): an empty detail, built for free
            detail: dict[str, Any] = {}
        else:
            detail = FieldsDetail(skipped_fields=tuple(skipped) if skipped else None,
                                  skipped=None if changes else "no field was set").to_json()
            if not changes and decoded_here:  # nothing changed: keep the real payload object (zero copy downstream)
                item.message = None
        item.events.append(self.context.event("set", info, item.consumers, tuple(changes), detail=detail))
        return [item]


_fast_loads, _fast_dumps, _exact_scalar = json_fast.loads, json_fast.dumps, json_fast.is_exact_scalar


def _fast_set(steps: tuple[tuple[tuple, Any, str], ...], payload: bytes) -> tuple[bytes, tuple] | None:
    """What ``SetRuntime.apply`` sends when every field is set, through orjson, and the changes; None: the general path.

    None whenever the result might differ by a byte or a value: orjson
    cannot read the payload exactly (``json_fast.loads``), a field is
    missing (the general path reports which), a replaced value might read
    differently with the stdlib, or the output might be written differently
    (``json_fast.dumps``). ``tests/test_json_fast.py`` holds it to the
    general path's deliveries and events.
    """
    message = _fast_loads(payload)
    if message is None:
        return None
    changes = []
    for segments, value, text in steps:  # each plan's path, value and rendered path (see fast_path)
        old = _set_one(message, segments, value)
        if old is _MISSING or not _exact_scalar(old):
            return None
        changes.append((text, old, value))
    out = _fast_dumps(message)
    return None if out is None else (out, tuple(changes))
