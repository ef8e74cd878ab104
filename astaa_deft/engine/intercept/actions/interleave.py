"""``interleave``: inject extra messages between the real ones.

    <interleave rate="20">
      <field path="header.stamp" value="dict:time.jump_back"/>
    </interleave>

While the policy's window is open, ``rate`` times per second, the consumers
get a copy of the channel's last real message with these fields set (none:
plain copies). The first injection comes one period after the first real
message in the window. The policy's ``<select>`` picks among injection slots
(every k-th slot, probability p, at most ``limit`` injections); the real
messages themselves pass untouched. For derive rules that look at "the
previous message", an injection's previous message is its template.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from astaa_deft.io.codecs import DecodeError, get_codec
from astaa_deft.engine.intercept.actions.base import (
    ACTIONS, ActionConfig, ActionDetail, ActionRuntime, MessageInfo, Pending, PinnedStep, PolicyContext,
    decimal_text, required,
)
from astaa_deft.engine.intercept.actions.set import (
    Assignment, FieldPlan, FieldsDetail, apply_plans, check_assignments, literal_assignments,
    plan_fields, read_assignments, write_assignments,
)

if TYPE_CHECKING:
    from lxml import etree

    from astaa_deft.model.sut import Channel
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy


DEFAULT_PINNED_RATE = 10.0  # Hz, for a pinned injection whose policy is unknown
MAX_RATE = 1000.0  # the schema's bound


@ACTIONS.register_class
@dataclass(frozen=True)
class Interleave(ActionConfig):
    name: ClassVar[str] = "interleave"
    # Inject copies of the channel's last real message, with these fields set, `rate` times per
    # second while the window is open.
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:sequence>
          <xs:element name="field" type="Field" minOccurs="0" maxOccurs="unbounded"/>
        </xs:sequence>
        <xs:attribute name="rate" type="Rate" use="required"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = FieldsDetail
    adds_delivery: ClassVar[bool] = True
    carries_fields: ClassVar[bool] = True
    rate: float  # injections per second
    fields: tuple[Assignment, ...] = ()

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Interleave:
        return cls(float(required(element, "rate")), read_assignments(element))

    def field_paths(self) -> tuple[str, ...]:
        return tuple(a.path for a in self.fields)

    def write_xml(self, element: etree._Element) -> None:
        element.set("rate", decimal_text(self.rate))
        write_assignments(element, self.fields)

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        check_assignments(self.fields, channels, checker)

    def start(self, context: PolicyContext) -> ActionRuntime:
        return InterleaveRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Interleave:
        """An injection in the first slot after its template message, at the original policy's rate."""
        rate = step.original.rate if isinstance(step.original, Interleave) else DEFAULT_PINNED_RATE
        return cls(min(rate, MAX_RATE), literal_assignments(step.fields))


@dataclass
class _Template:
    payload: bytes
    index: int  # of the real message on its channel
    undecodable: bool = False  # reported once; no copies until the next real message


@dataclass
class _Schedule:
    """Injection slots first + k * period (multiplied, not summed: no drift over long windows)."""

    first: float
    end: float
    period: float
    k: int = 0

    @property
    def next_slot(self) -> float | None:
        slot = self.first + self.k * self.period
        return slot if slot < self.end else None


class InterleaveRuntime(ActionRuntime):
    acts_on_messages = False  # time-driven: see on_tick

    def __init__(self, config: Interleave, context: PolicyContext):
        self.period = 1.0 / config.rate
        self.context = context
        self.plans: dict[str, tuple[FieldPlan, ...]] = {
            channel.name: plan_fields(config.fields, channel, context) for channel in context.channels}
        self.codecs = {channel.name: get_codec(channel.encoding) for channel in context.channels}
        self.templates: dict[str, _Template] = {}  # per channel: the last real message
        self.schedules: dict[str, _Schedule] = {}  # per channel, from its first real message in the window
        self.injected = 0

    def after_message(self, info: MessageInfo, payload: bytes) -> list[Pending]:
        # Slots that fell due before this message are copies of the one before it.
        out = self._due(info.channel, info.now, inclusive=False)
        self.templates[info.channel] = _Template(payload, info.index)
        if info.channel not in self.schedules:
            bounds = self.context.window_bounds()
            if bounds is not None and bounds[0] <= info.now < bounds[1]:
                self.schedules[info.channel] = _Schedule(info.now + self.period, bounds[1], self.period)
        return out

    def on_tick(self, now: float) -> list[Pending]:
        return [item for channel in self.schedules for item in self._due(channel, now, inclusive=True)]

    def _due(self, channel: str, now: float, inclusive: bool) -> list[Pending]:
        schedule = self.schedules.get(channel)
        out: list[Pending] = []
        while schedule is not None and (slot := schedule.next_slot) is not None and (
                slot <= now if inclusive else slot < now):
            schedule.k += 1
            if self.context.select_slot(channel, slot):
                out.extend(self._inject(channel, self.templates[channel], slot))
        return out

    def _inject(self, channel: str, template: _Template, slot: float) -> list[Pending]:
        if template.undecodable:
            return []
        codec = self.codecs[channel]
        consumers = self.context.consumers[channel]
        item = Pending(consumers, template.payload, slot, codec, extra=True)
        try:
            message = codec.decode(template.payload)
        except DecodeError as exc:  # an event-only delivery says why nothing is injected
            template.undecodable = True
            info = MessageInfo(channel, template.index, slot, codec, dict)
            item.consumers = ()
            item.events.append(self.context.event("interleave", info, consumers,
                                                  detail=FieldsDetail(skipped=f"undecodable: {exc}").to_json()))
            return [item]
        self.injected += 1
        info = MessageInfo(channel, template.index, slot, codec, lambda: codec.decode(template.payload))
        changes, skipped = apply_plans(message, self.plans[channel], info)
        item.message = message
        detail = FieldsDetail(injection=self.injected, skipped_fields=tuple(skipped) if skipped else None)
        item.events.append(self.context.event("interleave", info, consumers, tuple(changes), detail=detail.to_json()))
        return [item]
