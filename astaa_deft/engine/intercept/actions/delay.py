"""``delay``: deliver the selected messages later.

    <delay ms="200"/>

The engine holds a delayed message and releases it from ``on_tick`` once
due (so it lands within one tick, ~10 ms, of its time); later messages on
the channel overtake it meanwhile, as on a congested link.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionDetail, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext,
    decimal_text, required,
)

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.engine.intercept.testcase import ActionChecker


@dataclass(frozen=True)
class DelayDetail(ActionDetail):
    shown: ClassVar[tuple[str, ...]] = ("delay_ms",)
    delay_ms: float | None = None


@ACTIONS.register_class
@dataclass(frozen=True)
class Delay(ActionConfig):
    name: ClassVar[str] = "delay"
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:attribute name="ms" type="Milliseconds" use="required"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = DelayDetail
    defers: ClassVar[bool] = True
    ms: float

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Delay:
        return cls(float(required(element, "ms")))

    def write_xml(self, element: etree._Element) -> None:
        element.set("ms", decimal_text(self.ms))

    def start(self, context: PolicyContext) -> ActionRuntime:
        return DelayRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Delay | None:
        """The logged delay (else the original policy's)."""
        ms = DelayDetail.from_json(step.detail).delay_ms
        if ms is None and isinstance(step.original, Delay):
            ms = step.original.ms
        return cls(float(ms)) if ms else None


class DelayRuntime(ActionRuntime):
    def __init__(self, config: Delay, context: PolicyContext):
        self.seconds = config.ms / 1000.0
        self.ms = config.ms
        self.context = context

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        item.at += self.seconds  # delays of stacked policies add up
        item.deferred = True
        item.events.append(self.context.event("delay", info, item.consumers, detail=DelayDetail(self.ms).to_json()))
        return [item]
