"""``hold``: the selected messages carry stale values — the fields as they were in the real message before
the first one selected, held from then on (a producer sending a cached copy).

    <hold>
      <field path="odometer"/>
      <field path="pose.x"/>
    </hold>

On the first selected message the fields take the previous real message's
values (remembered per place); every later selected message gets the same
values again. With ``<select limit="1"/>`` it is one message one behind;
held over a window, the fields freeze. A place the previous message lacked
(or the first message of a channel, which has none) is skipped and said so.
The changes are logged as field changes (the values sent), so a restricted
test case redoes them as a ``set`` of those values.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from lxml import etree

from astaa_deft.model.fields import FieldPath, get, set_field
from astaa_deft.engine.intercept.dictionary import NotApplicable
from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, FIELD_PATHS_SCHEMA,
    ActionConfig, ActionDetail, ActionRuntime, FieldChange, MessageInfo, Pending, PinnedStep, PolicyContext,
    required,
)
from astaa_deft.engine.intercept.actions.set import FieldsDetail, Set, pinned_as_set

if TYPE_CHECKING:
    from astaa_deft.model.sut import Channel
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy


@ACTIONS.register_class
@dataclass(frozen=True)
class Hold(ActionConfig):
    name: ClassVar[str] = "hold"
    # Its element's type in the test case schema (spliced into testcase.xsd's Action group): the fields it acts on.
    schema: ClassVar[str] = FIELD_PATHS_SCHEMA
    detail_type: ClassVar[type[ActionDetail]] = FieldsDetail
    carries_fields: ClassVar[bool] = True
    paths: tuple[str, ...]

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Hold:
        return cls(tuple(required(child, "path") for child in element.iterfind("field")))

    def write_xml(self, element: etree._Element) -> None:
        for path in self.paths:
            etree.SubElement(element, "field", path=path)

    def field_paths(self) -> tuple[str, ...]:
        return self.paths

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        for text, child in zip(self.paths, checker.element.iterfind("field"), strict=True):
            path = checker.field_path(child, text, "odometer or points[*].x")
            if path is None:
                continue
            for channel in channels:
                checker.site(child, channel, path)

    def start(self, context: PolicyContext) -> ActionRuntime:
        return HoldRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Set | None:
        return pinned_as_set(step)


class HoldRuntime(ActionRuntime):
    def __init__(self, config: Hold, context: PolicyContext):
        self.context = context
        self.paths = tuple(FieldPath.parse(path) for path in config.paths)
        self.held: dict[str, dict[str, Any]] = {}  # per channel: the stale value of each concrete place

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        decoded_here = item.message is None
        undecodable = item.decode(info.codec)
        if undecodable is not None:
            item.events.append(self.context.event("hold", info, item.consumers,
                                                  detail=FieldsDetail(skipped=undecodable).to_json()))
            return [item]
        held = self.held.get(info.channel)
        skipped = None
        if held is None:  # the first selected message: what the previous real message had
            try:
                held = self.held[info.channel] = _stale_values(info.previous_message(), self.paths)
            except NotApplicable as exc:
                skipped = str(exc)
        changes = []
        for where, value in (held or {}).items():
            place = FieldPath.parse(where)
            found = get(item.message, place)
            if found:
                set_field(item.message, place, copy.deepcopy(value))
                changes.append(FieldChange(where, found[0][1], value))
        if not changes:
            if decoded_here:
                item.message = None
            skipped = skipped or "no such field in this message"
        detail = FieldsDetail(skipped=skipped).to_json() if skipped else {}
        item.events.append(self.context.event("hold", info, item.consumers, tuple(changes), detail=detail))
        return [item]


def _stale_values(previous: dict, paths: tuple[FieldPath, ...]) -> dict[str, Any]:
    """Each concrete place the paths match in ``previous``, with its value there."""
    return {str(where): copy.deepcopy(value) for path in paths for where, value in get(previous, path)}
