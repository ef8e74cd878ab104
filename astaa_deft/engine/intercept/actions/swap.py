"""``swap``: exchange the values of two fields of the selected messages (x sent as y, y as x).

    <swap a="ego.x" b="ego.y"/>
    <swap a="points[*].x" b="points[*].y"/>

Both paths exist in the channel's type. Sibling fields (the same path up to
their last name) may hold wildcards: each matching struct has its two
fields exchanged. Other pairs are concrete (no wildcards). A message missing
a field passes untouched, and the event says so. The
two changes are logged as field changes (the values sent), so a restricted
test case redoes them as a ``set`` of those values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from astaa_deft.model.fields import FieldPath, get, set_field
from astaa_deft.engine.intercept.actions.base import (
    ACTIONS,
    ActionConfig, ActionDetail, ActionRuntime, FieldChange, MessageInfo, Pending, PinnedStep, PolicyContext,
    required,
)
from astaa_deft.engine.intercept.actions.set import FieldsDetail, Set, pinned_as_set

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.model.sut import Channel
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy


@ACTIONS.register_class
@dataclass(frozen=True)
class Swap(ActionConfig):
    name: ClassVar[str] = "swap"
    # Its element's type in the test case schema (spliced into testcase.xsd's Action group): the two fields.
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:attribute name="a" type="FieldPath" use="required"/>
        <xs:attribute name="b" type="FieldPath" use="required"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = FieldsDetail
    carries_fields: ClassVar[bool] = True
    a: str
    b: str

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Swap:
        return cls(required(element, "a"), required(element, "b"))

    def write_xml(self, element: etree._Element) -> None:
        element.set("a", self.a)
        element.set("b", self.b)

    def field_paths(self) -> tuple[str, ...]:
        return (self.a, self.b)

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        paths = []
        for attribute in ("a", "b"):
            path = checker.field_path(None, getattr(self, attribute), "ego.x", attribute=attribute)
            if path is None:
                continue
            paths.append(path)
            for channel in channels:
                checker.site(None, channel, path, attribute=attribute)
        if len(paths) == 2 and paths[0] == paths[1]:
            checker.report(None, f"a and b are the same field {self.a!r}", "name two different fields",
                           attribute="b")
        elif len(paths) == 2 and not _siblings(*paths) and not (paths[0].is_concrete and paths[1].is_concrete):
            checker.report(None, f"{self.a!r} and {self.b!r}: wildcards are for two fields of one struct",
                           "write sibling paths (points[*].x, points[*].y) or two single places (ego.x, goal.y)",
                           attribute="a")

    def start(self, context: PolicyContext) -> ActionRuntime:
        return SwapRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Set | None:
        return pinned_as_set(step)


class SwapRuntime(ActionRuntime):
    def __init__(self, config: Swap, context: PolicyContext):
        self.context = context
        self.a, self.b = FieldPath.parse(config.a), FieldPath.parse(config.b)

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        decoded_here = item.message is None
        undecodable = item.decode(info.codec)
        if undecodable is not None:
            item.events.append(self.context.event("swap", info, item.consumers,
                                                  detail=FieldsDetail(skipped=undecodable).to_json()))
            return [item]
        changes = _swapped(item.message, self.a, self.b)
        if not changes:
            if decoded_here:
                item.message = None
            missing = FieldsDetail(skipped="no such field in this message")
            item.events.append(self.context.event("swap", info, item.consumers, detail=missing.to_json()))
            return [item]
        item.events.append(self.context.event("swap", info, item.consumers, changes))
        return [item]


def _siblings(a: FieldPath, b: FieldPath) -> bool:
    return (a.segments[:-1] == b.segments[:-1] and type(a.segments[-1]) is str
            and type(b.segments[-1]) is str)


def _swapped(message: Any, a: FieldPath, b: FieldPath) -> tuple[FieldChange, ...]:
    """Exchange the values at ``a`` and ``b`` in ``message`` (in place); the changes made."""
    if _siblings(a, b):
        parent = FieldPath._trusted(a.segments[:-1])
        holders = get(message, parent) if parent.segments else [(parent, message)]
        key_a, key_b = a.segments[-1], b.segments[-1]
        changes: list[FieldChange] = []
        for where, holder in holders:
            if type(holder) is dict and key_a in holder and key_b in holder:
                old_a, old_b = holder[key_a], holder[key_b]
                holder[key_a], holder[key_b] = old_b, old_a
                changes += [FieldChange(str(FieldPath._trusted((*where.segments, key_a))), old_a, old_b),
                            FieldChange(str(FieldPath._trusted((*where.segments, key_b))), old_b, old_a)]
        return tuple(changes)
    found_a, found_b = get(message, a), get(message, b)
    if not found_a or not found_b:
        return ()
    old_a, old_b = found_a[0][1], found_b[0][1]
    set_field(message, a, old_b)
    set_field(message, b, old_a)
    return (FieldChange(str(a), old_a, old_b), FieldChange(str(b), old_b, old_a))
