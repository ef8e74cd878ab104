"""Offline checking: the spec's invariants over a recorded log.

The log is replayed into the same ``MonitorSet`` the proxy uses online:

* bus messages of the channels invariants read, decoded with the channel's
  codec (an undecodable payload is passed as ``None``, as online), in
  message-time order (see ``order``: the same order online), with ``seq`` = the message's sequence number on its
  channel in the log (the recorder numbers them from 1);
* ``process_exit`` events at their ``time_ns``;
* a tick at every message time, then ``finish`` at the end of the run.

The run's start is its ``run_started`` event (the time the online monitors
counted from); its end is the ``run_stopping`` event if the tool logged one
(the moment it began shutting the SUT down, when online monitoring
stopped), else the last bus message. Messages after the end are shutdown
noise and are not judged.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from astaa_deft.model.records import Verdict
from astaa_deft.io.codecs import Codec, get_codec
from astaa_deft.io.codecs.base import DecodeError
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents
from astaa_deft.model.sut import Spec
from astaa_deft.engine.monitor.order import channel_ranks, order_key
from astaa_deft.engine.monitor.monitorset import MonitorSet
from astaa_deft.engine.monitor.verdict import BUS_LOST, RunVerdict
from astaa_deft.engine.monitor.violation import RUN_END_KIND, Violation



@dataclass(kw_only=True)
class CheckResult:
    violations: list[Violation]
    verdict: RunVerdict
    start_ns: int
    end_ns: int
    messages: int  # bus messages given to the monitors
    stats: dict[str, dict[str, int]]
    seconds: float  # time spent evaluating (decoding included, reading the file not)
    online_verdict: RunVerdict | None = None  # the verdict the proxy logged during the run, if any
    online_violations: list[rec.Violation] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    unjudged: str = ""  # why the monitors did not judge every message ("": they did): a Pass is then withheld

    @property
    def passed(self) -> bool:
        return self.verdict.klass == Verdict.PASS


def check_log(log: LogContents, spec: Spec) -> CheckResult:
    events = [rec.decode(e, where=str(log.path)) for e in log.events()]
    start_ns = _start(log, events)
    end_ns = _end(log, events)
    monitors = MonitorSet(spec, start_ns)
    wanted = monitors.channels()
    routes = _routes(log, spec, wanted)
    # Process exits and module output lines, fed at their times between the messages.
    side: list[rec.ProcessExit | rec.ModuleLogLine] = sorted(
        (e for e in events if isinstance(e, rec.ProcessExit)
         or (isinstance(e, rec.ModuleLogLine) and monitors.wants_log_lines())), key=lambda e: e.time_ns)

    clock = time.perf_counter()
    exit_index = 0
    ranks = channel_ranks(spec)
    ordered = sorted((m for m in log.messages if m.topic in routes),
                     key=lambda m: order_key(m.publish_time, ranks[routes[m.topic][0]], m.sequence))
    for message in ordered:
        at = message.publish_time  # the message time: the Zenoh timestamp the recorder kept (else log time)
        if at > end_ns:
            break
        while exit_index < len(side) and side[exit_index].time_ns <= at:
            _feed_side(monitors, side[exit_index])
            exit_index += 1
        channel, codec = routes[message.topic]
        try:
            value = codec.decode(message.data)
        except DecodeError:
            value = None
        monitors.on_tick(at)
        monitors.on_message(channel, at, value, message.sequence)
    for event in side[exit_index:]:
        if event.time_ns <= end_ns:
            _feed_side(monitors, event)
    monitors.finish(end_ns)
    for record in events:  # the spec's run: outcome (an exit code, a channel's end): judged once, when it happened
        if isinstance(record, rec.Violation) and record.invariant_kind == RUN_END_KIND:
            monitors.add_finding(record)
    seconds = time.perf_counter() - clock

    bus_lost = any(isinstance(e, rec.OtherEvent) and e.kind == BUS_LOST for e in events)
    online = [e for e in events if isinstance(e, RunVerdict)]
    return CheckResult(
        violations=sorted(monitors.violations, key=lambda v: v.time_ns), verdict=monitors.verdict(bus_lost=bus_lost),
        start_ns=start_ns, end_ns=end_ns, messages=monitors.messages, stats=monitors.stats(), seconds=seconds,
        online_verdict=online[-1] if online else None,
        online_violations=[e for e in events if isinstance(e, rec.Violation)],
        warnings=list(log.warnings) + monitors.warnings, unjudged=monitors.unjudged(),
    )


def _routes(log: LogContents, spec: Spec, wanted: set[str]) -> dict[str, tuple[str, Codec]]:
    """Log topic -> (channel name, codec) for the channels the invariants read."""
    out = {}
    for topic, info in log.channels.items():
        if topic.startswith("/astaa/"):
            continue
        name = info.metadata.get("channel")
        if name is None:
            declared = spec.channel_for_key(topic)
            name = declared.name if declared else None
        if name in wanted:
            out[topic] = (name, get_codec(spec.channel(name).encoding))
    return out


def _start(log: LogContents, events: list[rec.Record]) -> int:
    started = [e.time_ns for e in events if isinstance(e, rec.RunStarted) and e.time_ns]
    if started:
        return int(started[0])
    bus = [m.log_time for m in log.messages if not m.topic.startswith("/astaa/")]
    return min(bus) if bus else 0


def _end(log: LogContents, events: list[rec.Record]) -> int:
    # The run's end as the online monitors judged it: its run_end event (the shutdown that follows is not judged)
    ended = [e.time_ns for e in events if isinstance(e, (rec.RunEnd, rec.RunStopping)) and e.time_ns]
    if ended:
        return int(min(ended))
    bus = [m.log_time for m in log.messages if not m.topic.startswith("/astaa/")]
    return max(bus) if bus else _start(log, events)


def _feed_side(monitors: MonitorSet, event: rec.ProcessExit | rec.ModuleLogLine) -> None:
    if isinstance(event, rec.ModuleLogLine):
        monitors.on_log_line(event.module, event.line, event.time_ns)
    else:
        _feed_exit(monitors, event)


def _feed_exit(monitors: MonitorSet, event: rec.ProcessExit) -> None:
    monitors.on_process_exit(
        module=event.module, returncode=int(event.returncode or 0), signal=event.signal, time_ns=event.time_ns,
        during_shutdown=bool(event.during_shutdown), stderr_tail=str(event.stderr_tail or ""))

