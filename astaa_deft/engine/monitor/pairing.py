"""On what time a monitor joins the messages of several channels: the bus's, or the one the spec declares.

A channel may name its messages' own time (``time: sim_time``: a field in
seconds, e.g. a simulator's clock) and the field that marks the messages of
several channels as one tick (``pair_by: header.seq``, or the time field).
A monitor that reads more than one channel (``collision``, ``temporal``)
asks a :class:`Join` for each message's place on the time it joins on:

* ``own time`` — every joined channel declares ``time``: the messages'
  own times (in ns). Two messages of one simulator tick sit at one instant
  however far apart the bus carried them; between ticks, the monitor
  interpolates on the simulator's clock.
* ``paired`` — every joined channel declares ``pair_by`` (or ``time``, used
  as the pairing value): a message sits at the bus time of the first
  message of its pair (equal values), on whichever channel that came. The
  second message of a tick thus joins the first, not the tick before.
* ``bus`` — otherwise: the bus time (the Zenoh timestamp). The messages of
  one tick published 20 ms apart are then joined 20 ms apart, and the
  monitor interpolates across the gap; a finding within what that can
  move an obstacle says so.

A message whose pairing value is missing or not a plain value sits at its
bus time; one whose own time is missing or not a finite number has no place
(None: the monitor skips it — a ``bound`` invariant reports such a field). The places are a pure
function of the messages in their evaluation order, so online and offline
agree.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterable
from typing import Any

from astaa_deft.model.fields import FieldPath
from astaa_deft.model.sut import Spec
from astaa_deft.engine.monitor.expression import RUNTIME_ERRORS, follow
from astaa_deft.engine.monitor.paths import is_number
from astaa_deft.model.vocabulary import TextEnum

MAX_OPEN_PAIRS = 4096  # pairing values remembered (a pair's partner comes within a few ticks, not thousands)


class JoinMode(TextEnum):
    BUS = "bus"
    OWN_TIME = "own time"
    PAIRED = "paired"


class Join:
    """Each message's place on the time a monitor joins its channels on (see the module's docstring)."""

    def __init__(self, spec: Spec, channels: Iterable[str], *, own_time: bool = True):
        """``own_time``: join on the declared times when every channel has one (a monitor that samples on the
        bus's grid, ``temporal``, pairs on them instead)."""
        names = sorted(set(channels))
        declared = [spec.channel(name) for name in names]
        self._fields: dict[str, tuple[Any, ...]] = {}
        if len(names) < 2:
            self.mode = JoinMode.BUS  # one channel: nothing to join
        elif own_time and all(ch.time for ch in declared):
            self.mode = JoinMode.OWN_TIME
            self._fields = {ch.name: FieldPath.parse(str(ch.time)).segments for ch in declared}
        elif all(ch.pair_by or ch.time for ch in declared):
            self.mode = JoinMode.PAIRED
            self._fields = {ch.name: FieldPath.parse(str(ch.pair_by or ch.time)).segments for ch in declared}
        else:
            self.mode = JoinMode.BUS
        self._first: OrderedDict[Any, int] = OrderedDict()  # pairing value -> its first message's bus time

    def describe(self) -> str:
        """How it joins, for a finding: 'by bus time', 'on the declared time (sim_time)', …."""
        return {JoinMode.BUS: "by bus time", JoinMode.OWN_TIME: "on the channels' declared time",
                JoinMode.PAIRED: "by the channels' pair_by"}[self.mode]

    def at(self, channel: str, bus_ns: int, value: object) -> int | None:
        """The message's place (ns) on the joined time; None when it has none."""
        path = self._fields.get(channel)
        if path is None:
            return bus_ns
        try:
            found = follow(value, path)
        except RUNTIME_ERRORS:
            return None if self.mode == JoinMode.OWN_TIME else bus_ns
        if self.mode == JoinMode.OWN_TIME:
            if not is_number(found) or not math.isfinite(found) or abs(found) > 9e9:
                return None
            return round(found * 1e9)
        if type(found) not in (int, float, str, bool) or (type(found) is float and not math.isfinite(found)):
            return bus_ns
        first = self._first.get(found)
        if first is not None:
            return first
        self._first[found] = bus_ns
        if len(self._first) > MAX_OPEN_PAIRS:
            self._first.popitem(last=False)
        return bus_ns
