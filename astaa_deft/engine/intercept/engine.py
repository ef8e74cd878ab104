"""The interception engine: applies a test case's policies to the live message stream.

The proxy calls ``on_message`` once per real message on an affected
channel, in arrival order, ``on_tick`` about every 10 ms and ``flush`` at
the end, all from one thread at a time, and delivers what they return.

Cost model: a message no policy selects costs a counter and a few float
comparisons, and comes back as the very same payload object (the proxy
forwards it without a copy). Only a selected message is decoded.

Determinism: all randomness comes from ``random.Random`` generators seeded
with (test case seed, policy id), one for selection and one for the action,
drawn in arrival order. The same seed and the same sequence of calls (same
payloads, same ``now`` values) give the same deliveries and events.
"""

from __future__ import annotations

import heapq
import itertools
import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

from astaa_deft.io.codecs import Codec, DecodeError, get_codec
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.records import FieldChange, Mutation, MutationRow, MutationSource, Rewritten, mutation_row
from astaa_deft.model.sut import Spec
from astaa_deft.engine.intercept.actions.base import (
    ActionRuntime, Delivery, FastPath, MessageInfo, Pending, PolicyContext, built,
)
from astaa_deft.engine.intercept.applications import ChannelTraffic, PolicyApplications
from astaa_deft.engine.intercept.dictionary import Dictionary, NotApplicable, load_dictionary
from astaa_deft.engine.intercept.testcase import Policy, TestCase, load_testcase

__all__ = ["Delivery", "FieldChange", "Interceptor", "Lane", "Mutation", "PolicyGate", "load_interceptor"]

# What a lane answers for one message (see Interceptor.lane).
LaneResult = None | Rewritten | list[Delivery]
# Interceptor.lane's shortcut for one channel: lane(payload, now) -> LaneResult.
Lane = Callable[[bytes, float], LaneResult]


class PolicyGate:
    """A policy's window and selection: does it act on this message (or injection slot)?"""

    def __init__(self, policy: Policy, seed: int):
        window, selection = policy.window, policy.selection
        self._window = window
        self.every = selection.every
        self.probability = selection.probability
        self.limit = selection.limit if selection.limit is not None else math.inf
        self.rng = random.Random(f"{seed}/{policy.id}/select")
        self.taken = 0
        self._counts: dict[str, int] = {}  # per channel: messages seen inside the window
        # Absolute bounds; unknown (start = inf) until the anchor message arrives.
        self.start, self.end = math.inf, math.inf
        if window.anchor_channel is None:
            self.anchored_at(0.0)

    def anchored_at(self, time: float) -> None:
        self.start = time + self._window.start
        self.end = time + self._window.end if self._window.end is not None else math.inf

    def bounds(self) -> tuple[float, float] | None:
        return None if self.start == math.inf else (self.start, self.end)

    def seen_in_window(self) -> int:
        """Messages (and injection slots) of its channels that came while the window was open."""
        return sum(self._counts.values())

    def selects(self, channel: str, now: float) -> bool:
        # Ordered cheapest first: most messages fall outside the window.
        if not self.start <= now < self.end or self.taken >= self.limit:
            return False
        seen = self._counts.get(channel, 0)
        self._counts[channel] = seen + 1
        if seen % self.every:
            return False
        if self.probability < 1.0 and self.rng.random() >= self.probability:
            return False
        self.taken += 1
        return True


@dataclass
class _LivePolicy:
    policy: Policy
    gate: PolicyGate
    runtime: ActionRuntime
    channels: tuple[str, ...] = ()  # the channels it targets

    def split(self, consumers: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(affected, unaffected) consumers of a delivery."""
        wanted = self.policy.consumers
        if not wanted:
            return consumers, ()
        return (tuple(c for c in consumers if c in wanted), tuple(c for c in consumers if c not in wanted))


class _ChannelState:
    __slots__ = ("name", "codec", "count", "first_at", "last_at", "previous_payload", "_previous_cache", "acting",
                 "observers", "anchors", "held", "fast", "fast_source")

    def __init__(self, name: str, codec: Codec):
        self.name = name
        self.codec = codec
        self.count = 0
        self.first_at: float | None = None  # arrival of its first and last real message (run seconds)
        self.last_at: float | None = None
        self.previous_payload: bytes | None = None
        self._previous_cache: tuple[bytes, dict] | None = None
        self.acting: list[_LivePolicy] = []  # policies that may act on this channel's real messages
        self.observers: list[_LivePolicy] = []  # runtimes told about every real message
        self.anchors: list[tuple[int, PolicyGate]] = []  # windows counted from message N here
        self.held: list[tuple[float, int, Delivery]] = []  # delayed deliveries, a heap by due time
        # The acting policy's shortcut when it alone acts here, for every consumer (see ActionRuntime.fast_path).
        self.fast: FastPath | None = None
        self.fast_source: MutationSource | None = None  # the shortcut's mutations' fixed attributes (see _fast_message)

    def previous_message(self) -> dict:
        """The previous real message, decoded once (derive rules like time.jump_back read it)."""
        payload = self.previous_payload
        if payload is None:
            raise NotApplicable("no previous message on this channel")
        if self._previous_cache is None or self._previous_cache[0] is not payload:
            try:
                self._previous_cache = (payload, self.codec.decode(payload))
            except DecodeError as exc:
                raise NotApplicable(f"the previous message is undecodable: {exc}") from None
        return self._previous_cache[1]


class Interceptor:
    """Runs one test case against one run's message stream (see the module doc).

    Build a fresh one per run: policies keep state (counters, held messages).
    """

    def __init__(self, testcase: TestCase, spec: Spec, dictionary: Dictionary):
        self.testcase = testcase
        self._channels: dict[str, _ChannelState] = {}
        self._policies: list[_LivePolicy] = []
        self._sequence = itertools.count()  # orders same-time delayed deliveries
        self._touched: dict[str, int] = {}  # policy id → mutation events naming it
        for policy in testcase.policies:
            self._policies.append(self._start(policy, spec, dictionary))
        for state in self._channels.values():
            if len(state.acting) == 1 and not state.observers and not state.acting[0].policy.consumers:
                state.fast = state.acting[0].runtime.fast_path(state.name)

    # -- the proxy's interface ---------------------------------------------------------
    def channels(self) -> set[str]:
        """Channels any policy may touch (window anchors included); others need no call at all."""
        return set(self._channels)

    def on_message(self, channel: str, consumers: tuple[str, ...], payload: bytes, now: float) -> list[Delivery]:
        state = self._channels.get(channel)
        if state is None:
            return [Delivery(consumers, payload, now)]
        # Delayed messages of this channel that fell due go first (others wait for on_tick:
        # the caller routes what on_message returns by the message's channel).
        out = self._release_due(state, now) if state.held else []
        if state.fast is not None:  # one acting policy, no observers (see __init__): the short way
            done = self._fast_message(state, consumers, payload, now)
            if done is None:
                out.append(built(Delivery, consumers=consumers, payload=payload, at=now, original=None, event=None))
            elif isinstance(done, Rewritten):  # its event is the row _fast_message built
                out.append(built(Delivery, consumers=consumers, payload=done.payload, at=now, original=payload,
                                 event=Mutation.from_row(cast(MutationRow, done.event))))
            else:
                out.extend(done)
            return out
        index = self._arrived(state, now)
        selected = [live for live in state.acting if live.gate.selects(channel, now)]
        if selected:
            info = MessageInfo(channel, index, now, state.codec, state.previous_message)
            out.extend(self._deliver(self._apply(selected, consumers, payload, info), now))
        else:
            out.append(built(Delivery, consumers=consumers, payload=payload, at=now, original=None, event=None))
        if state.observers:
            info = MessageInfo(channel, index, now, state.codec, state.previous_message)
            for live in state.observers:
                out.extend(self._deliver(live.runtime.after_message(info, payload), now))
        state.previous_payload = payload
        return out

    def lane(self, channel: str, consumers: tuple[str, ...]) -> Lane | None:
        """``on_message`` for ``channel`` without the objects, where one policy alone rewrites it (else None).

        The proxy's common case, a message that goes to all of ``consumers``
        at once, rewritten or not, costs no ``Delivery``, event or field
        change objects: ``lane(payload, now)`` keeps the engine's state as
        ``on_message`` does and returns

        * None: the message goes to every consumer untouched, now;
        * ``Rewritten(payload, mutation row)``: the rewritten message goes to
          every consumer now; the mutation in its compact form
          (``model.records.MutationRow``, which the proxy's record carries as is);
        * anything else as ``on_message`` returns it, a list of deliveries.

        Offered where ``on_message`` takes its short way (one acting policy
        with a fast path, no observers, every consumer); ``tests/test_json_fast.py``
        holds the two to the same deliveries and events.
        """
        state = self._channels.get(channel)
        if state is None or state.fast is None:
            return None
        fast_message, on_message = self._fast_message, self.on_message

        def run(payload: bytes, now: float) -> LaneResult:
            if state.held:  # something delayed on this channel may fall due first: the general way
                return on_message(channel, consumers, payload, now)
            return fast_message(state, consumers, payload, now)

        return run

    def _arrived(self, state: _ChannelState, now: float) -> int:
        """A real message arrived on the channel: its traffic and the windows anchored to it; its index."""
        state.count += 1
        index = state.count
        if index == 1:
            state.first_at = now
        state.last_at = now
        for number, gate in state.anchors:
            if number == index:
                gate.anchored_at(now)
        return index

    def _fast_message(self, state: _ChannelState, consumers: tuple[str, ...], payload: bytes,
                      now: float) -> LaneResult:
        """A message on a channel with a shortcut (``state.fast``), as ``lane`` answers (delayed ones released)."""
        index = self._arrived(state, now)
        channel, live = state.name, state.acting[0]
        if not live.gate.selects(channel, now):
            state.previous_payload = payload
            return None
        assert state.fast is not None  # (called only where it is)
        done = state.fast(payload)
        if done is None:  # the shortcut declined this message
            info = MessageInfo(channel, index, now, state.codec, state.previous_message)
            out = self._deliver(self._apply(state.acting, consumers, payload, info), now)
            state.previous_payload = payload
            return out
        state.previous_payload = payload
        policy = live.policy
        self._count_touch(policy.id)
        source = state.fast_source  # built once per consumers tuple: a lane passes the same one every time
        if source is None or source[4] is not consumers:
            source = state.fast_source = (self.testcase.id, policy.id, policy.action.name, channel, consumers)
        return Rewritten(done[0], mutation_row(source, index, now, done[1]))

    @staticmethod
    def event(row: MutationRow) -> Mutation:
        """The mutation of a lane's compact form."""
        return Mutation.from_row(row)

    def on_tick(self, now: float) -> list[Delivery]:
        out = [d for state in self._channels.values() if state.held for d in self._release_due(state, now)]
        for live in self._policies:
            out.extend(self._deliver(live.runtime.on_tick(now), now))
        out.sort(key=lambda delivery: delivery.at)  # stable: same-time deliveries keep their order
        return out

    def flush(self, now: float) -> list[Delivery]:
        """End of run: everything still held, delivered now."""
        out: list[Delivery] = []
        for live in self._policies:
            out.extend(self._deliver(live.runtime.flush(now), now))
        for state in self._channels.values():
            out.extend(self._release_due(state, math.inf))
        return [delivery if delivery.at <= now else replace(delivery, at=now) for delivery in out]

    def applications(self, now: float) -> list[PolicyApplications]:
        """What each policy did so far (``now``: the end of the run), in document order."""
        out = []
        for live in self._policies:
            gate, window = live.gate, live.policy.window
            bounds = gate.bounds()
            traffic = []
            for channel in live.channels:
                state = self._channels[channel]
                traffic.append(ChannelTraffic(channel, state.count, state.first_at, state.last_at))
            anchor = (f"message {window.anchor_message or 1} on channel '{window.anchor_channel}'"
                      if window.anchor_channel is not None else None)
            out.append(PolicyApplications(
                testcase=self.testcase.id, policy=live.policy.id, action=live.policy.action.name,
                window_start_s=bounds[0] if bounds else None,
                window_end_s=bounds[1] if bounds and bounds[1] != math.inf else None, anchor=anchor,
                in_window=gate.seen_in_window(), touched=self._touched.get(live.policy.id, 0),
                traffic=tuple(traffic), run_end_s=now))
        return out

    # -- internals ---------------------------------------------------------------------
    @staticmethod
    def _release_due(state: _ChannelState, now: float) -> list[Delivery]:
        out = []
        while state.held and state.held[0][0] <= now:
            out.append(heapq.heappop(state.held)[2])
        return out

    def _apply(self, selected: list[_LivePolicy], consumers: tuple[str, ...], payload: bytes,
               info: MessageInfo) -> list[Pending]:
        """Run the message through the selected policies in document order."""
        items = [Pending(consumers, payload, info.now, info.codec)]
        for live in selected:
            after: list[Pending] = []
            for item in items:
                affected, unaffected = live.split(item.consumers)
                if not affected:
                    after.append(item)
                    continue
                if unaffected:
                    after.append(item.copy_for(unaffected))
                    item.consumers = affected
                after.extend(live.runtime.apply(item, info))
            items = after
        return items

    def _count_touch(self, policies: str) -> None:
        """One more message touched by each policy an event names (stacked policies share one event)."""
        for policy in policies.split("+"):
            self._touched[policy] = self._touched.get(policy, 0) + 1

    def _deliver(self, items: list[Pending], now: float) -> list[Delivery]:
        """Deliveries due now; later ones (delay) wait in the heap for on_tick."""
        out = []
        for item in items:
            delivery = item.to_delivery()
            if delivery.event is not None:
                self._count_touch(delivery.event.policy)
            if delivery.at > now and delivery.consumers:
                assert delivery.event is not None  # only an action (delay) postpones a delivery
                held = self._channels[delivery.event.channel].held
                heapq.heappush(held, (delivery.at, next(self._sequence), delivery))
            else:
                out.append(delivery)
        return out

    def _start(self, policy: Policy, spec: Spec, dictionary: Dictionary) -> _LivePolicy:
        where = self.testcase.source or self.testcase.id
        channels = policy.target_channels(spec)
        _check_policy(policy, spec, channels, where)
        gate = PolicyGate(policy, self.testcase.seed)
        context = PolicyContext(
            testcase=self.testcase.id, where=where, policy=policy, spec=spec, dictionary=dictionary,
            channels=channels,
            consumers={c.name: tuple(m for m in c.consumers if not policy.consumers or m in policy.consumers)
                       for c in channels},
            rng=random.Random(f"{self.testcase.seed}/{policy.id}/action"),
            window_bounds=gate.bounds, select_slot=gate.selects)
        live = _LivePolicy(policy, gate, policy.action.start(context), tuple(c.name for c in channels))
        for channel in channels:
            state = self._state(channel.name, spec)
            if live.runtime.acts_on_messages:
                state.acting.append(live)
            if type(live.runtime).after_message is not ActionRuntime.after_message:
                state.observers.append(live)
        if policy.window.anchor_channel is not None:
            anchor = self._state(policy.window.anchor_channel, spec)
            anchor.anchors.append((policy.window.anchor_message or 1, gate))
        return live

    def _state(self, channel: str, spec: Spec) -> _ChannelState:
        if channel not in self._channels:
            self._channels[channel] = _ChannelState(channel, get_codec(spec.channel(channel).encoding))
        return self._channels[channel]


def load_interceptor(path: Path | str, spec: Spec, dictionary_files: Sequence[Path | str] = ()) -> Interceptor:
    """The engine for a test case file, checked against the spec and the dictionary (InputError if not)."""
    dictionary = load_dictionary(dictionary_files)
    return Interceptor(load_testcase(path, spec, dictionary), spec, dictionary)


def _check_policy(policy: Policy, spec: Spec, channels: tuple[Any, ...], where: str) -> None:
    """The few checks a test case built in code (not read with the spec) could still fail."""
    known = {c.name for c in spec.channels}
    unknown = [name for name in (*policy.channels, policy.window.anchor_channel) if name and name not in known]
    problem = None
    if unknown:
        problem = f"policy '{policy.id}' names unknown channel(s) {', '.join(unknown)}"
    elif not channels:
        problem = f"policy '{policy.id}' targets no channel (no channel carries type {policy.message_type!r})"
    if problem:
        raise InputError(Problem(where, policy.line, None, problem, "run astaa-deft policy check with --spec"))
