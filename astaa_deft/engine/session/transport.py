"""The run's transport part: the star proxy (with the interception, given an interceptor) or the passive observer."""

from __future__ import annotations

import time

from astaa_deft.engine.bus.interception import InterceptionBridge
from astaa_deft.model.records import Mutation, RunMode
from astaa_deft.engine.bus.observer import ChannelCounter
from astaa_deft.engine.bus.proxy import StarProxy, plain_forwarder
from astaa_deft.engine.session.options import RunOptions
from astaa_deft.engine.session.parts import EventLog, RunPart, ToolSession
from astaa_deft.io.log import records as rec
from astaa_deft.model.sut import Spec


class Transport(RunPart):
    """Who talks to whom through the tool: every message forwarded (star) or counted (passive).

    At ``stopping`` the interception releases what it holds (consumers
    still listen) and logs what each policy did (``policies``). ``counts``
    and ``mutations`` may be read from any thread.
    """

    def __init__(self, spec: Spec, options: RunOptions, session: ToolSession, events: EventLog):
        self._spec, self._options, self._session, self._events = spec, options, session, events
        self.proxy: StarProxy | None = None
        self.counter: ChannelCounter | None = None
        self.interception: InterceptionBridge | None = None
        self.interceptor_epoch_ns: int | None = None  # the interceptor's clock origin, on the log's clock
        self.policies: list[rec.PolicyApplicationsRecord] = []  # per policy of the test case, at the end

    def start(self) -> None:
        session, interceptor = self._session.session, self._options.interceptor
        if self._options.mode != RunMode.STAR:
            self.counter = ChannelCounter(session, self._spec, self._options.mode)
            return
        make_forwarder = plain_forwarder
        if interceptor is not None:
            # One instant on both clocks: event times count from it, the log says where it is.
            epoch_monotonic, self.interceptor_epoch_ns = time.monotonic(), time.time_ns()
            self.interception = InterceptionBridge(session, interceptor, epoch_monotonic,
                                                   on_mutation=self._mutated if self._events.listening else None)
            make_forwarder = self.interception.make_forwarder
        self.proxy = StarProxy(session, self._spec, on_undeclared=self._undeclared, make_forwarder=make_forwarder)
        self.proxy.start()
        if self.interception is not None:
            self.interception.start()

    def stopping(self) -> None:
        if self.interception is not None:
            self.interception.stop()  # release held and delayed messages while consumers still listen
            self._log_applications(self.interception.t0)

    def close(self) -> None:
        for holder in (self.proxy, self.counter):
            if holder is not None:
                holder.stop()

    @property
    def intercepted(self) -> set[str]:
        """The channels the interception forwards (none without an interceptor)."""
        return self.interception.targets if self.interception is not None else set()

    @property
    def mutations(self) -> int:
        """Messages the interception changed so far."""
        return self.interception.mutations if self.interception is not None else 0

    def counts(self) -> dict[str, int]:
        """Messages per channel forwarded (star) or observed (passive) so far."""
        if self.proxy is not None:
            return self.proxy.counts()
        if self.counter is not None:
            return self.counter.counts()
        return {}

    def _log_applications(self, t0: float) -> None:
        """One event per policy: what it touched, and why it touched nothing if so (a window closed idle)."""
        assert self._options.interceptor is not None
        for app in self._options.interceptor.applications(time.monotonic() - t0):
            record = rec.decode({"kind": rec.PolicyApplicationsRecord.kind, "time_ns": time.time_ns(),
                                 **app.to_json()})
            assert isinstance(record, rec.PolicyApplicationsRecord)
            self.policies.append(record)
            self._events.emit(record)

    def _mutated(self, event: Mutation) -> None:
        # Not re-published: the interception's own record (with the original) is in the log already.
        self._events.on_event(rec.MutationRecord.of(event, time.time_ns()))

    def _undeclared(self, module: str, key: str) -> None:
        note = ("seen by every other module; declare it under 'liveliness' to route it precisely"
                if key.startswith("liveliness:") else
                "forwarded to every other module; declare it under 'channels' to route it precisely")
        self._events.emit(rec.UndeclaredKey(time.time_ns(), module, key, note))
