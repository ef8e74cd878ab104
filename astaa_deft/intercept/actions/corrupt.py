"""``corrupt``: damage the selected payloads' bytes.

    <corrupt mode="flip" bytes="3"/>      XOR 3 random bytes with random non-zero masks
    <corrupt mode="truncate" keep="0.5"/>  keep the first half (a random length if no keep)

Positions and masks come from the policy's seeded generator, so a test case
replays the same damage on the same message stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from .base import ActionConfig, ActionRuntime, MessageInfo, Pending, PolicyContext, decimal_text

if TYPE_CHECKING:
    from lxml import etree

    from ...spec.model import Channel
    from ..testcase import ActionChecker, Policy


@dataclass(frozen=True)
class Corrupt(ActionConfig):
    name: ClassVar[str] = "corrupt"
    mode: str  # "flip" | "truncate"
    bytes: int | None = None  # flip: how many bytes (default 1)
    keep: float | None = None  # truncate: the fraction kept (default: random)

    @classmethod
    def from_xml(cls, element: etree._Element, checker: ActionChecker) -> Corrupt:
        count, keep = element.get("bytes"), element.get("keep")
        return cls(element.get("mode"), int(count) if count is not None else None,
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


class CorruptRuntime(ActionRuntime):
    def __init__(self, config: Corrupt, context: PolicyContext):
        self.config = config
        self.context = context
        self.rng = context.rng

    def apply(self, item: Pending, info: MessageInfo) -> list[Pending]:
        payload = bytearray(item.materialize())
        detail: dict[str, Any]
        if not payload:
            detail = {"skipped": "empty payload"}
        elif self.config.mode == "flip":
            positions = sorted(self.rng.sample(range(len(payload)), min(self.config.bytes or 1, len(payload))))
            for position in positions:
                payload[position] ^= self.rng.randrange(1, 256)
            detail = {"flipped_bytes": positions}
        else:
            keep = (int(len(payload) * self.config.keep) if self.config.keep is not None
                    else self.rng.randrange(len(payload)))
            detail = {"truncated_to": keep, "length": len(payload)}
            del payload[keep:]
        if "skipped" not in detail:
            item.payload = bytes(payload)
        item.events.append(self.context.event("corrupt", info, item.consumers, **detail))
        return [item]
