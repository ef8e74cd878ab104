"""``corrupt``: damage the selected payloads' bytes.

    <corrupt mode="flip" bytes="3"/>      XOR 3 random bytes with random non-zero masks
    <corrupt mode="truncate" keep="0.5"/>  keep the first half (a random length if no keep)

Positions and masks come from the policy's seeded generator, so a test case
replays the same damage on the same message stream.
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

    from astaa_deft.model.sut import Channel
    from astaa_deft.engine.intercept.testcase import ActionChecker, Policy


@dataclass(frozen=True)
class CorruptDetail(ActionDetail):
    shown: ClassVar[tuple[str, ...]] = ("flipped_bytes", "truncated_to")
    skipped: str | None = None  # why the payload was left alone
    flipped_bytes: tuple[int, ...] | None = None  # flip: the positions damaged
    truncated_to: int | None = None  # truncate: the length kept …
    length: int | None = None  # … of this many bytes


# Truncation keeps less than the whole payload (the schema's bound on keep).
MAX_KEEP = 0.999999


@ACTIONS.register_class
@dataclass(frozen=True)
class Corrupt(ActionConfig):
    name: ClassVar[str] = "corrupt"
    # flip: XOR `bytes` random bytes with random non-zero masks; truncate: keep the first `keep`
    # fraction of the payload (random if omitted).
    schema: ClassVar[str] = """
      <xs:complexType>
        <xs:attribute name="mode" use="required">
          <xs:simpleType>
            <xs:restriction base="xs:token">
              <xs:enumeration value="flip"/>
              <xs:enumeration value="truncate"/>
            </xs:restriction>
          </xs:simpleType>
        </xs:attribute>
        <xs:attribute name="bytes" type="Count"/>
        <xs:attribute name="keep" type="Fraction"/>
      </xs:complexType>"""
    detail_type: ClassVar[type[ActionDetail]] = CorruptDetail
    fields_separable: ClassVar[bool] = False  # the delivery is damaged bytes, not a message
    mode: str  # "flip" | "truncate"
    bytes: int | None = None  # flip: how many bytes (default 1)
    keep: float | None = None  # truncate: the fraction kept (default: random)

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Corrupt:
        count, keep = element.get("bytes"), element.get("keep")
        return cls(required(element, "mode"), int(count) if count is not None else None,
                   float(keep) if keep is not None else None)

    def write_xml(self, element: etree._Element) -> None:
        element.set("mode", self.mode)
        if self.bytes is not None:
            element.set("bytes", str(self.bytes))
        if self.keep is not None:
            element.set("keep", decimal_text(self.keep))

    def check(self, policy: Policy, channels: tuple[Channel, ...], checker: ActionChecker) -> None:
        if self.mode == "flip" and self.keep is not None:
            checker.report(None, "'keep' belongs to mode=\"truncate\"", "remove it, or write bytes=\"N\"",
                           attribute="keep")
        if self.mode == "truncate" and self.bytes is not None:
            checker.report(None, "'bytes' belongs to mode=\"flip\"", "remove it, or write keep=\"0.5\"",
                           attribute="bytes")

    def start(self, context: PolicyContext) -> ActionRuntime:
        return CorruptRuntime(self, context)

    @classmethod
    def pinned(cls, step: PinnedStep) -> Corrupt | None:
        """The same damage as far as it is known: a truncation to the same length; as many bytes flipped.

        Flipped positions and masks are drawn afresh (the policy's generator
        decides them); the original policy's form when the event says neither.
        """
        detail = CorruptDetail.from_json(step.detail)
        if detail.truncated_to is not None and detail.length:
            keep = (int(detail.truncated_to) + 0.5) / int(detail.length)
            return cls("truncate", keep=min(keep, MAX_KEEP))
        if detail.flipped_bytes is not None:
            return cls("flip", bytes=max(len(detail.flipped_bytes), 1))
        return step.original if isinstance(step.original, Corrupt) else None


class CorruptRuntime(ActionRuntime):
    def __init__(self, config: Corrupt, context: PolicyContext):
        self.config = config
        self.context = context
        self.rng = context.rng

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        payload = bytearray(item.materialize())
        detail: CorruptDetail
        if not payload:
            detail = CorruptDetail(skipped="empty payload")
        elif self.config.mode == "flip":
            positions = sorted(self.rng.sample(range(len(payload)), min(self.config.bytes or 1, len(payload))))
            for position in positions:
                payload[position] ^= self.rng.randrange(1, 256)
            detail = CorruptDetail(flipped_bytes=tuple(positions))
        else:
            keep = (int(len(payload) * self.config.keep) if self.config.keep is not None
                    else self.rng.randrange(len(payload)))
            detail = CorruptDetail(truncated_to=keep, length=len(payload))
            del payload[keep:]
        if detail.skipped is None:
            item.payload = bytes(payload)
        item.events.append(self.context.event("corrupt", info, item.consumers, detail=detail.to_json()))
        return [item]
