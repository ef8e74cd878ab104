"""``drop``: the selected messages never reach the policy's consumers.

    <drop/>

The engine still returns a ``Delivery`` with no consumers carrying the
event, so the log records what was dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext,
)

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.engine.intercept.testcase import ActionChecker


@ACTIONS.register_class
@dataclass(frozen=True)
class Drop(ActionConfig):
    name: ClassVar[str] = "drop"
    schema: ClassVar[str] = "<xs:complexType/>"  # its element's type in the test case schema: empty
    fields_separable: ClassVar[bool] = False  # nothing is delivered

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Drop:
        return cls()

    def write_xml(self, element: etree._Element) -> None:
        pass

    def start(self, context: PolicyContext) -> ActionRuntime:
        return DropRuntime(context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Drop:
        return cls()


class DropRuntime(ActionRuntime):
    def __init__(self, context: PolicyContext):
        self.context = context

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        item.events.append(self.context.event("drop", info, item.consumers))
        item.consumers = ()  # an event-only delivery: nobody gets it
        return [item]
