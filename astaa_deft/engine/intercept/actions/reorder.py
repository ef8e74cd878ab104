"""``reorder``: hold a selected message and deliver it right after the next one.

    <reorder max-hold-ms="1000"/>

Swaps pairs: with every message selected, consumers get 2 1 4 3 ... A
message selected while another is held is that "next" one and passes. If no
next message comes within ``max-hold-ms``, the held one is released anyway
(from ``on_tick``), as it is at the end of the run. Policies after this one
in the test case do not see a held message.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, ClassVar

from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionDetail, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext,
    decimal_text,
)

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.engine.intercept.testcase import ActionChecker


@dataclass(frozen=True)
class ReorderDetail(ActionDetail):
    swapped_with: int | None = None  # the index of the message that overtook the held one
    released: str | None = None  # why it went out without a successor


@ACTIONS.register_class
@dataclass(frozen=True)
class Reorder(ActionConfig):
    name: ClassVar[str] = "reorder"
    # Hold a message and deliver it right after the next one on its channel; released anyway after
    # max-hold-ms if no next message comes.
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:attribute name="max-hold-ms" type="Milliseconds" default="1000"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = ReorderDetail
    defers: ClassVar[bool] = True
    max_hold_ms: float = 1000.0

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Reorder:
        return cls(float(element.get("max-hold-ms", "1000")))

    def write_xml(self, element: etree._Element) -> None:
        if self.max_hold_ms != 1000.0:
            element.set("max-hold-ms", decimal_text(self.max_hold_ms))

    def start(self, context: PolicyContext) -> ActionRuntime:
        return ReorderRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Reorder:
        """The original policy's hold time (events do not record it), else the default."""
        return cls(step.original.max_hold_ms) if isinstance(step.original, Reorder) else cls()


@dataclass
class _Held:
    item: Pending
    index: int  # of the held message on its channel
    since: float


class ReorderRuntime(ActionRuntime):
    def __init__(self, config: Reorder, context: PolicyContext):
        self.max_hold = config.max_hold_ms / 1000.0
        self.context = context
        self.held: dict[str, _Held] = {}  # per channel: at most one message waits for its successor

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        if info.channel in self.held:
            return [item]  # the successor of the held message: it goes first
        item.events.append(self.context.event("reorder", info, item.consumers))
        item.deferred = True
        self.held[info.channel] = _Held(item, info.index, info.now)
        return []

    def after_message(self, info: MessageInfo, payload: bytes) -> list[Pending]:
        held = self.held.get(info.channel)
        if held is None or held.index >= info.index:
            return []
        return [self._release(info.channel, info.now, ReorderDetail(swapped_with=info.index))]

    def on_tick(self, now: float) -> list[Pending]:
        overdue = [channel for channel, held in self.held.items() if now - held.since >= self.max_hold]
        return [self._release(channel, now, ReorderDetail(released="no next message within max-hold-ms"))
                for channel in overdue]

    def flush(self, now: float) -> list[Pending]:
        return [self._release(channel, now, ReorderDetail(released="end of run")) for channel in list(self.held)]

    def _release(self, channel: str, now: float, detail: ReorderDetail) -> Pending:
        held = self.held.pop(channel)
        item = held.item
        item.at = max(item.at, now)
        event = item.events[-1]
        item.events[-1] = replace(event, detail={**event.detail, **detail.to_json()})
        return item
