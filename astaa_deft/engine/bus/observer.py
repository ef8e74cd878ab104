"""Passive observation: count each declared channel, off the SUT's message path."""

from __future__ import annotations

from collections.abc import Callable

import zenoh

from astaa_deft.model.sut import Spec
from astaa_deft.engine.bus.topology import observed_keys


class ChannelCounter:
    """Messages per declared channel as seen on the bus (``mode`` picks the keys, see ``observed_keys``).

    Counted on Zenoh's threads; ``counts`` may be called from any thread, ``stop`` once.
    """

    def __init__(self, session: zenoh.Session, spec: Spec, mode: str):
        self._counts = {ch.name: 0 for ch in spec.channels}
        self._subs: list[zenoh.Subscriber[None]] = []
        for key_expr, channel in observed_keys(spec, mode):
            self._subs.append(session.declare_subscriber(key_expr, self._counter(channel.name)))

    def _counter(self, name: str) -> Callable[[zenoh.Sample], None]:
        counts = self._counts

        def on_sample(_sample: zenoh.Sample) -> None:
            counts[name] += 1

        return on_sample

    def counts(self) -> dict[str, int]:
        return dict(self._counts)

    def stop(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs = []
