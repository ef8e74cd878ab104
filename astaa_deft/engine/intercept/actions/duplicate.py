"""``duplicate``: deliver the selected messages, then ``copies`` extra copies of each.

    <duplicate copies="2"/>

The real message passes untouched; each copy carries the event.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionDetail, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext,
)

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.engine.intercept.testcase import ActionChecker


@dataclass(frozen=True)
class DuplicateDetail(ActionDetail):
    shown: ClassVar[tuple[str, ...]] = ("copies",)
    copy: int | None = None  # which copy this delivery is, from 1
    copies: int | None = None


@ACTIONS.register_class
@dataclass(frozen=True)
class Duplicate(ActionConfig):
    name: ClassVar[str] = "duplicate"
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:attribute name="copies" type="Copies" default="1"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = DuplicateDetail
    adds_delivery: ClassVar[bool] = True
    pins_copies: ClassVar[bool] = True
    copies: int = 1

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Duplicate:
        return cls(int(element.get("copies", "1")))

    def write_xml(self, element: etree._Element) -> None:
        if self.copies != 1:
            element.set("copies", str(self.copies))

    def start(self, context: PolicyContext) -> ActionRuntime:
        return DuplicateRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Duplicate:
        return cls(1)  # each extra copy is a mutation of its own

    @classmethod
    def pin_copies(cls, count: int) -> Duplicate:
        return cls(count)


class DuplicateRuntime(ActionRuntime):
    def __init__(self, config: Duplicate, context: PolicyContext):
        self.copies = config.copies
        self.context = context

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        out = [item]
        for number in range(1, self.copies + 1):
            twin = item.copy_for(item.consumers, extra=True)
            twin.events.append(self.context.event("duplicate", info, item.consumers,
                                                  detail=DuplicateDetail(number, self.copies).to_json()))
            out.append(twin)
        return out
