"""``duplicate``: deliver the selected messages, then ``copies`` extra copies of each.

    <duplicate copies="2"/>

The real message passes untouched; each copy carries the event.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from .base import ActionConfig, ActionRuntime, MessageInfo, Pending, PolicyContext

if TYPE_CHECKING:
    from lxml import etree

    from ..testcase import ActionChecker


@dataclass(frozen=True)
class Duplicate(ActionConfig):
    name: ClassVar[str] = "duplicate"
    copies: int = 1

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Duplicate:
        return cls(int(element.get("copies", "1")))

    def write_xml(self, element: etree._Element) -> None:
        if self.copies != 1:
            element.set("copies", str(self.copies))

    def start(self, context: PolicyContext) -> ActionRuntime:
        return DuplicateRuntime(self, context)


class DuplicateRuntime(ActionRuntime):
    def __init__(self, config: Duplicate, context: PolicyContext):
        self.copies = config.copies
        self.context = context

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        out = [item]
        for number in range(1, self.copies + 1):
            twin = item.copy_for(item.consumers, extra=True)
            twin.events.append(self.context.event("duplicate", info, item.consumers, copy=number, copies=self.copies))
            out.append(twin)
        return out
