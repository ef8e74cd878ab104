"""What `astaa-deft log info` shows: pure functions over a read log."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

from astaa_deft.io.log import layout
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents
from astaa_deft.engine.monitor.verdict import format_verdict


@dataclass(frozen=True, kw_only=True)
class TopicStats:
    topic: str
    channel: str
    count: int
    rate_hz: float
    first_ns: int
    last_ns: int


def topic_stats(log: LogContents) -> list[TopicStats]:
    by_topic: dict[str, list[int]] = {}
    for m in log.messages:
        by_topic.setdefault(m.topic, []).append(m.log_time)
    out = []
    for topic, info in log.channels.items():
        times = by_topic.get(topic, [])
        span = (times[-1] - times[0]) / 1e9 if len(times) > 1 else 0.0
        rate = (len(times) - 1) / span if span > 0 else 0.0
        out.append(TopicStats(topic=topic, channel=info.metadata.get("channel", ""), count=len(times), rate_hz=rate,
                              first_ns=times[0] if times else 0, last_ns=times[-1] if times else 0))
    return out


def untouched_policies(records: Iterable[rec.Record]) -> list[str]:
    """One line per policy of the test case that touched no message, with why it may not have.

    A window that closed without touching anything is a test that did not
    happen (the SUT started late, the channel was silent, the run ended
    first); "mutations applied: 0" alone does not say which policy or why.
    """
    return [f"policy '{r.policy}' ({r.action}) touched no message: {r.untouched_reason}"
            for r in records if isinstance(r, rec.PolicyApplicationsRecord) and r.untouched_reason]


def policy_lines(records: Iterable[rec.Record]) -> list[str]:
    """What each policy touched, then the untouched ones with their reasons (empty without a test case)."""
    apps = [r for r in records if isinstance(r, rec.PolicyApplicationsRecord)]
    if not apps:
        return []
    lines = ["policies: " + ", ".join(f"{r.policy} {r.touched} touched" for r in apps)]
    lines.extend("  " + line for line in untouched_policies(apps))
    return lines


def format_info(log: LogContents, with_warnings: bool = True) -> str:
    lines = [f"log: {log.path}"]
    if log.intact:
        state = "yes (every chunk CRC and index checked)"
    elif log.truncated and len(log.damage) == 1:
        state = f"NO (the file stops early; {log.describe_reading()})"
    else:
        state = f"NO — DAMAGED ({len(log.damage)} problem{'s' if len(log.damage) != 1 else ''} below; " \
                f"{log.describe_reading()})"
    lines.append("finished cleanly: " + state)
    run = log.metadata.get(layout.RUN_METADATA, {})
    if run:
        lines.append(f"run: spec {run.get('spec', '?')}, mode {run.get('mode', '?')}")
        if run.get("command_line"):
            lines.append(f"command: {run['command_line']}")
    bus = [m for m in log.messages if not m.topic.startswith("/astaa/")]
    if bus:
        start, end = bus[0].log_time, max(m.log_time for m in bus)
        lines.append(f"time span: {(end - start) / 1e9:.2f} s, {len(bus)} bus messages")
    lines.append("")
    lines.append(f"{'topic':44} {'channel':16} {'count':>7} {'rate/s':>8}")
    for s in topic_stats(log):
        if s.topic.startswith("/astaa/"):
            continue
        lines.append(f"{s.topic:44} {s.channel:16} {s.count:7d} {s.rate_hz:8.1f}")
    events = [rec.decode(e, where=str(log.path)) for e in log.events()]
    kinds = Counter(e.kind for e in events)
    lines.append("")
    lines.append("events: " + (", ".join(f"{k} ×{n}" for k, n in sorted(kinds.items())) or "none"))
    for e in events:
        if isinstance(e, rec.ProcessExit) and e.abnormal:
            how = f"signal {e.signal}" if e.signal else f"exit code {e.returncode}"
            lines.append(f"  crash: module '{e.module}' ({how})")
        elif isinstance(e, rec.UndeclaredKey):
            lines.append(f"  undeclared key '{e.key}' from module '{e.module}'")
        elif isinstance(e, rec.RunEnd):
            lines.append(f"  run ended: {e.reason}")
    violations = Counter(e.invariant for e in events if isinstance(e, rec.Violation))
    if violations:
        lines.append("violations: " + ", ".join(f"{name} ×{n}" for name, n in sorted(violations.items())))
    lines.extend(policy_lines(events))
    verdicts = [e for e in events if isinstance(e, rec.RunVerdict)]
    if verdicts:
        started = next((e.time_ns for e in events if isinstance(e, rec.RunStarted)), None)
        lines.append(format_verdict(rec.encode(verdicts[-1]), started))
    flags = [rec.decode(f, where=str(log.path)) for f in log.flags()]
    if flags:
        per = Counter(f.channel for f in flags if isinstance(f, rec.FlagRecord))
        lines.append("undecodable payloads (forwarded untouched): "
                     + ", ".join(f"{c} ×{n}" for c, n in sorted(per.items())))
    if log.attachments:
        lines.append("attachments: " + ", ".join(sorted(log.attachments)))
    for w in log.warnings if with_warnings else ():
        lines.append(f"warning: {w}")
    return "\n".join(lines)
