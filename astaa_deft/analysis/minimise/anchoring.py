"""Pinned mutations counted from the running stack, not from the run's start.

A restricted test case pins each kept mutation to the message it hit
(:mod:`.restrict`). Counted from the run's start (``<after channel="C"
message="N"/>``), the N-th message of a channel depends on how long the SUT
took to start: a simulator that publishes while it waits for the rest of the
stack sends more messages before the stack is live when the stack starts
later (a loaded machine, a slower disk), and the pinned mutation then hits
another message — one acceptance run called a localization reorder "not
reproduced" that way.

So a mutation that happened once the stack was live is pinned to the
*anchor* instead: the channel whose first message came last (when it
speaks, every module runs; a campaign's generated windows count from the
same channel). Its window opens at the anchor's M-th message — the last one
before the mutated message arrived — and takes the first message of its
channel after it; when more messages of its channel came in between (a
channel faster than the anchor), the window opens half-way in time between
the previous one and the mutated one instead. The anchor's own count is
stable: nothing of it comes before the stack is live. Mutations before the
anchor's first message, and those on the anchor channel itself, keep their
count from the run's start.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import Counter
from dataclasses import replace

from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.io.log.reader import LogContents
from astaa_deft.analysis.minimise.mutations import AnchorPin, MutationLog, sent_stream


def choose_anchor(log: LogContents, mlog: MutationLog, original: TestCase | None) -> str | None:
    """The channel the run's live phase counts from (None: none can be told).

    The logged test case's own window anchor when it has one (a campaign's
    cases count from the anchor its baseline measured); else the consumed
    channel whose first message came last in this run.
    """
    known = {c.name for c in mlog.spec.channels}
    if original is not None:
        anchors = Counter(p.window.anchor_channel for p in original.policies
                          if p.window.anchor_channel is not None and p.window.anchor_channel in known)
        if anchors:
            return max(anchors, key=lambda name: (anchors[name], name))
    firsts = {}
    for channel in mlog.spec.channels:
        if not channel.consumers:
            continue
        messages = sent_stream(mlog, log, channel.name)
        if messages:
            firsts[channel.name] = min(m.log_time for m in messages)
    return max(firsts, key=lambda name: (firsts[name], name)) if len(firsts) > 1 else None


def pin_to_anchor(mlog: MutationLog, log: LogContents, anchor: str | None) -> MutationLog:
    """``mlog`` with each mutation made after the anchor's first message pinned to the anchor (module doc)."""
    if anchor is None:
        return mlog
    anchor_times = sorted(m.log_time for m in sent_stream(mlog, log, anchor))
    times: dict[str, list[int]] = {}
    pinned = []
    for mutation in mlog.mutations:
        arrived = mutation.original_time_ns
        before = bisect_left(anchor_times, arrived)  # anchor messages that came before this one
        if mutation.channel == anchor or before == 0:
            pinned.append(mutation)
            continue
        if mutation.channel not in times:
            times[mutation.channel] = sorted(m.log_time for m in sent_stream(mlog, log, mutation.channel))
        own = times[mutation.channel]
        opened = anchor_times[before - 1]
        previous = bisect_left(own, arrived)  # the channel's messages before the mutated one
        between = previous - bisect_left(own, opened)
        after = 0.0 if between <= 0 else max(0.0, ((own[previous - 1] + arrived) / 2 - opened) / 1e9)
        pinned.append(replace(mutation, pin=AnchorPin(anchor, before, round(after, 6))))
    return replace(mlog, mutations=pinned)
