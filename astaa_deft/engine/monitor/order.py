"""One evaluation order for online and offline monitors.

Both evaluate messages in **message-time** order: a message's time is the
Zenoh timestamp it carries (set once where it enters the bus and forwarded
unchanged by the proxy, so the tool's copy and the recorder's copy share
it), or the receive time where a message has none. Ties are broken by the
channel's position in the spec's ``channels`` list, then by the message's
sequence number on its channel. Receive times differ between the tool's
subscriber and the recorder's by scheduling noise, which used to reorder
messages of different channels and so change which finding came first.
Online, messages wait ``REORDER_WINDOW_NS`` in a buffer so that late
arrivals still take their place in this order.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from astaa_deft.model.sut import Spec

if TYPE_CHECKING:
    import zenoh

REORDER_WINDOW_NS = 100_000_000  # online: how long a message waits for earlier-stamped ones to arrive


def channel_ranks(spec: Spec) -> dict[str, int]:
    return {ch.name: rank for rank, ch in enumerate(spec.channels)}


def sample_time_ns(timestamp: zenoh.Timestamp | None, received_ns: int) -> int:
    """The message time of a Zenoh sample: its timestamp, else when it was received."""
    if timestamp is None:
        return received_ns
    return timestamp.get_time_as_ntp64().as_nanos()


def order_key(time_ns: int, rank: int, seq: int) -> tuple[int, int, int]:
    return time_ns, rank, seq
