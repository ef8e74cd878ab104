"""The spec's ``run:`` conditions during one run: when the run ends and what its end means.

A :class:`RunEndWatch` listens to the channels the conditions read (as their
producers published them) and to the modules' exits; the run loop asks it
every poll whether the run is over. A module whose exit ends the run is not
a crash: the session marks its exit as the run's own end, and its exit code
becomes the outcome (a pass, or a finding with the CRASH class the spec
gives it).

The end is dated when it happened, not when the tool noticed it: a channel
condition at its message's bus time; a module's exit at the module's last
message on the bus when the exit came within its shutdown delay after it (a
process takes a moment to write its results, close its sessions and exit,
and the modules it drove fall silent from its last message on), else at its
exit as waitpid saw it (it fell silent long before: that silence is part of
the run). A module's shutdown delay is the spec's ``shutdown_delay``, else
the one the caller learned from clean runs (``RunOptions.shutdown_delays``,
a campaign's baseline), else ``SHUTDOWN_GRACE_NS``. Until the end is known
the online monitors judge no further than :meth:`RunEndWatch.judged_until` —
a time the end cannot come before — so nothing of the shutdown is judged
online that ``check`` would not judge.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from typing import TYPE_CHECKING

import zenoh

from astaa_deft.model.records import Verdict
from astaa_deft.io.codecs import Codec, get_codec
from astaa_deft.engine.monitor.expression import RUNTIME_ERRORS
from astaa_deft.engine.monitor.order import sample_time_ns
from astaa_deft.engine.monitor.violation import RUN_END_KIND, Violation, message_copy
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.run_section import ChannelEnd, Outcome, RunSection

if TYPE_CHECKING:
    from astaa_deft.model.records import ProcessExit
    from astaa_deft.engine.session.view import RunView

SHUTDOWN_GRACE_NS = 1_000_000_000  # an exit this soon after the module's last message: its end is that message
# (unless the spec or the clean runs give the module its own shutdown delay)
NOTICE_SLACK_NS = 500_000_000  # how late the tool may learn of an exit (a loaded machine, its watcher thread)


@dataclass(frozen=True, kw_only=True)
class RunEnd:
    """The condition that ended a run."""

    reason: str
    outcome: Outcome
    time_ns: int
    channel: str | None = None
    module: str | None = None
    message: dict | None = None
    detail: str = ""

    def finding(self) -> Violation | None:
        """The end as a finding (None when it is a pass)."""
        if self.outcome.passed:
            return None
        return Violation(invariant=f"{RUN_END_KIND}:{self.outcome.name}", invariant_kind=RUN_END_KIND,
                         severity=self.outcome.severity, time_ns=self.time_ns, channel=self.channel, seq=None,
                         message=self.message, detail=self.detail, crash=self.outcome.crash or Verdict.SILENT,
                         module=self.module)


class RunEndWatch:
    """The spec's ``run:`` end conditions over one run; the first that holds is ``ended`` (set once, any thread)."""

    def __init__(self, spec: Spec, learned: Mapping[str, float] | None = None):
        """``learned``: an ending module -> the seconds its exit may come after its last message, as clean runs
        showed (the spec's own ``shutdown_delay`` wins)."""
        self.spec = spec
        self.section: RunSection = spec.run if spec.run is not None else RunSection()
        self.ended: RunEnd | None = None
        self._lock = threading.Lock()
        self._ending = {end.module for end in self.section.module_exits}
        self._grace_ns = {end.module: shutdown_grace_ns(end.shutdown_delay, (learned or {}).get(end.module))
                          for end in self.section.module_exits}
        self._last_ns: dict[str, int] = {}  # an ending module -> its last message's bus time
        self._exits: Callable[[], Sequence[ProcessExit]] = tuple

    @property
    def time_limit(self) -> float | None:
        return self.section.time_limit

    def attach(self, run: RunView) -> None:
        """Subscribe to every channel a condition reads, and to those of the modules whose exit ends the run
        (``run``: a started run)."""
        self._exits = lambda: run.exits
        by_channel: dict[str, list[ChannelEnd]] = {}
        for end in self.section.channel_ends:
            by_channel.setdefault(end.channel, []).append(end)
        for name, ends in by_channel.items():
            codec = get_codec(self.spec.channel(name).encoding)
            try:
                run.subscribe(name, functools.partial(self._seen, ends, codec))
            except KeyError:  # not observable in this mode: the condition cannot fire
                continue
        for channel in self.spec.channels:
            if channel.producer in self._ending:
                try:
                    run.subscribe(channel.name, functools.partial(self._spoke, channel.producer))
                except KeyError:  # not observable: its exit is dated by waitpid alone
                    continue

    def _spoke(self, module: str, sample: zenoh.Sample) -> None:
        at = sample_time_ns(sample.timestamp, time.time_ns())
        with self._lock:
            if at > self._last_ns.get(module, 0):
                self._last_ns[module] = at

    def grace_ns(self, module: str) -> int:
        """The ending module's shutdown delay in ns (the spec's, the learned one, else the default)."""
        return self._grace_ns.get(module, SHUTDOWN_GRACE_NS)

    def exit_time(self, exit_: ProcessExit) -> int:
        """When an ending module's exit ended the run: its last message, if its exit came within its shutdown
        delay after it; else the exit itself."""
        last = self._last_ns.get(exit_.module)
        if last is None or exit_.time_ns - last > self.grace_ns(exit_.module):
            return exit_.time_ns
        return min(last, exit_.time_ns)

    def shutdowns(self) -> dict[str, float]:
        """Per ending module that exited after a message: seconds from its last message to its exit."""
        with self._lock:
            last = dict(self._last_ns)
        return {e.module: round(max(0, e.time_ns - last[e.module]) / 1e9, 3) for e in self._exits()
                if e.module in self._ending and e.module in last}

    def judged_until(self, now_ns: int) -> int:
        """The latest time the online monitors may judge now: the end, once known, cannot come before it.

        An ending module still running ends the run, at the earliest, at its
        last message while its shutdown delay after it has not run out; after
        that at its exit, which is no earlier than now less the time the tool
        takes to learn of it.
        """
        if self.ended is not None:
            return self.ended.time_ns
        if not self._ending:
            return now_ns
        for exit_ in self._exits():
            if exit_.module in self._ending:
                return self.exit_time(exit_)
        with self._lock:
            last = dict(self._last_ns)
        unnoticed = now_ns - NOTICE_SLACK_NS  # an exit not noticed yet happened after this
        return min(last[module] if module in last and unnoticed - last[module] <= self.grace_ns(module)
                   else unnoticed for module in self._ending)

    def _seen(self, ends: list[ChannelEnd], codec: Codec, sample: zenoh.Sample) -> None:
        if self.ended is not None:
            return
        now = sample_time_ns(sample.timestamp, time.time_ns())  # its bus time, as the monitors date it
        try:
            value = codec.decode(sample.payload.to_bytes())
        except Exception:  # noqa: BLE001 - a malformed message ends nothing; the monitors report it
            return
        for end in ends:  # in the spec's order: the first condition that holds names the end
            try:
                holds = end.expr.evaluate(value) is True
            except RUNTIME_ERRORS:
                continue
            if holds:
                self._end(RunEnd(reason=end.reason, outcome=end.outcome, time_ns=now, channel=end.channel,
                                 message=message_copy(value), detail=f"'{end.expr.text}' held on {end.channel}"))
                return

    def check(self, exits: list[ProcessExit]) -> RunEnd | None:
        """The end, once a condition holds (``exits``: the run's ProcessExit records so far)."""
        for exit_ in exits:
            end = self.section.exit_end(exit_.module)
            if end is not None:
                outcome = end.outcome(exit_.returncode, exit_.signal)
                how = f"killed by {exit_.signal}" if exit_.signal else f"exit code {exit_.returncode}"
                self._end(RunEnd(reason=end.describe(), outcome=outcome, time_ns=self.exit_time(exit_),
                                 module=exit_.module, message={"returncode": exit_.returncode, "signal": exit_.signal},
                                 detail=f"module '{exit_.module}' ended the run with {how}: {outcome.name}"))
                break
        return self.ended

    def _end(self, end: RunEnd) -> None:
        with self._lock:
            if self.ended is None:
                self.ended = end


def shutdown_grace_ns(given: float | None, learned: float | None) -> int:
    """A module's shutdown delay in ns: the spec's (``given``), else the learned one, else the default."""
    seconds = given if given is not None else learned
    return SHUTDOWN_GRACE_NS if seconds is None else int(seconds * 1e9)
