"""The test case model: policies that select messages on channels and apply one action each.

Frozen records, read from and written to XML by :mod:`.xml_format`, built
and checked by :mod:`.loader`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from astaa_deft.model.sut import Channel, Spec
from astaa_deft.engine.intercept.actions.base import ActionConfig


@dataclass(frozen=True)
class Window:
    """[start, end) in seconds since the run started, or since the arrival of
    message ``anchor_message`` (1-based) on ``anchor_channel`` when given."""

    start: float = 0.0
    end: float | None = None
    anchor_channel: str | None = None
    anchor_message: int | None = None


@dataclass(frozen=True)
class Selection:
    """Inside the window: every ``every``-th message, then each with ``probability``, at most ``limit``."""

    every: int = 1
    probability: float = 1.0
    limit: int | None = None


@dataclass(frozen=True, kw_only=True)
class Policy:
    id: str
    action: ActionConfig
    channels: tuple[str, ...] = ()  # either channels...
    message_type: str | None = None  # ...or every channel carrying this type
    consumers: tuple[str, ...] = ()  # empty: every consumer of the channel
    window: Window = Window()
    selection: Selection = Selection()
    line: int | None = field(default=None, compare=False)

    def target_channels(self, spec: Spec) -> tuple[Channel, ...]:
        if self.message_type is not None:
            return tuple(c for c in spec.channels if c.type == self.message_type)
        return tuple(c for c in spec.channels if c.name in self.channels)


@dataclass(frozen=True, kw_only=True)
class TestCase:
    __test__ = False  # not a pytest test class

    id: str
    seed: int
    description: str
    policies: tuple[Policy, ...]
    source: str | None = field(default=None, compare=False)  # where it was read from

    def to_xml(self) -> bytes:
        from astaa_deft.engine.intercept.testcase.xml_format import (  # the file format builds on this model
            write_testcase,
        )

        return write_testcase(self)
