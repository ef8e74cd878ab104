"""The one adapter between a campaign and the rest of the tool: run one case, get a typed outcome.

One call of :func:`astaa_deft.engine.session.run_session`: a fresh run with its
own router port (the spec's endpoints with port 0 → a free port), its own
run directory and its own log, ended by the spec's own ``run:`` section (a
module's exit, a channel's "done", its time limit — applied by the session
for every caller, no SUT-specific logic here), a mutated case's first broken
invariant (known baseline findings apart), a crashed module (as its on_crash
says), every module gone, or the campaign's time horizon.
Nothing else in the campaign package touches the bus.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import zenoh

from astaa_deft.model.records import RunMode, Verdict, Violation
from astaa_deft.model import fields
from astaa_deft.model.fields import FieldPath
from astaa_deft.engine.bus.processes import ChildProcess
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import Codec
from astaa_deft.model.errors import InputError
from astaa_deft.engine.intercept.dictionary import Dictionary, load_dictionary
from astaa_deft.engine.intercept.engine import Interceptor
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.io.log import layout
from astaa_deft.engine.monitor.base import Invariant
from astaa_deft.engine.monitor import MonitorSet
from astaa_deft.engine.monitor.error_signature import signature_of_output, violation_signature
from astaa_deft.engine.monitor.verdict import IMPLICIT
from astaa_deft.engine.session import RunOptions, RunResult, RunView, run_session
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.campaign.cost import RunCost
from astaa_deft.orchestration.journal.model import CaseOutcome, ChannelRate, Finding
from astaa_deft.orchestration.journal.model import testcase_text

POLL_SECONDS = 0.05
LOG_NAME = "run.mcap"
POLICY_NAME = "policy.xml"


def isolated(spec: Spec) -> Spec:
    """The spec with every listening endpoint on a free port: concurrent runs never share a router."""
    endpoints = []
    for endpoint in spec.zenoh.endpoints:
        proto, _, addr = endpoint.partition("/")
        host, _, _port = addr.rpartition(":")
        endpoints.append(f"{proto}/{host}:0")
    return replace(spec, zenoh=replace(spec.zenoh, endpoints=tuple(endpoints)))


@dataclass(frozen=True, kw_only=True)
class CaseLimits:
    """When a case's run ends.

    ``horizon``: seconds at most. ``known``: known baseline findings — a
    mutated run ends at its first broken invariant except these (the
    campaign judges them after the run). ``settle``: a mutated run ends this
    many seconds after its test case can mutate no more (its last window
    closed or its last one-message policy acted) — what the SUT does with a
    bad message shows within seconds, and a run's remaining minutes would be
    spent for nothing; None: it does not. ``shutdown_delays``: per module
    whose exit ends the run, the seconds its exit may come after its last
    message (learned from the baseline; the run's end is dated at that
    message when it does).
    """

    horizon: float
    settle: float | None = None
    known: frozenset[str] = frozenset()
    shutdown_delays: Mapping[str, float] | None = None


def run_case(spec: Spec, testcase: TestCase | None, params: dict[str, str], run_dir: Path, *, limits: CaseLimits,
             dictionary: Dictionary | None = None, warm_recorder: ChildProcess | None = None) -> CaseOutcome:
    """One fresh run of the SUT with ``testcase`` (None: clean), ending as ``limits`` say.

    A clean run (``testcase`` None) never ends at a violation: it runs to
    the scenario's end, so it measures how long the SUT is live, and its
    channels' timing (rates, longest gaps), and its memory.
    ``warm_recorder``: a recorder started ahead (session.bus_run.warm_recorder) for this run to take.
    A clean run's outcome carries what its own ending module took (``shutdowns``), the baseline learns from
    those.
    Every outcome carries the run's CPU seconds and wall seconds (:mod:`.cost`).
    Never raises for a run that does not start or is not observed to its end: the outcome says "error".
    """
    cost = RunCost(sample_rss=testcase is None)
    cost.start()
    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = run_dir / LOG_NAME
    options = replace(_run_options(spec, testcase, params, run_dir, dictionary=dictionary,
                                   warm_recorder=warm_recorder), time_limit=limits.horizon,
                      shutdown_delays=dict(limits.shutdown_delays or {}))
    watches = _Watches(spec, testcase, limits.settle, limits.known)
    try:
        # A crash ends the run as the spec's on_crash says (run_session applies it), as for `proxy`.
        result = run_session(isolated(spec), options, on_start=watches.on_start, stop_when=watches.stop_when)
    except InputError as exc:
        cost.stop()
        return CaseOutcome(status="error", verdict="?", summary="the run did not start",
                           error="; ".join(str(p) for p in exc.problems), cpu=cost.cpu, wall=cost.wall)
    cost.stop()
    reason = {"time limit": "horizon", SETTLED: "settled", VIOLATION: "violation"}.get(result.end_reason,
                                                                                      result.end_reason)
    if result.verdict is None or not result.observed or not result.complete:  # not fully observed: no Pass
        return CaseOutcome(status="error", verdict="?", summary="the run was not observed to its end",
                           seconds=result.seconds, log_path=str(log_path), reason=reason,
                           error="no verdict" if result.verdict is None else "the log was not finished", cpu=cost.cpu,
                           wall=cost.wall)
    if result.unjudged and result.verdict.klass == Verdict.PASS:  # messages no monitor could read: no Pass
        return CaseOutcome(status="error", verdict="?", summary="not every message was judged", seconds=result.seconds,
                           log_path=str(log_path), reason=reason, error=result.unjudged, cpu=cost.cpu, wall=cost.wall)
    timing = watches.timing
    return CaseOutcome(status="done", verdict=result.verdict.klass, summary=result.verdict.summary,
                       findings=watches.findings(result), seconds=result.seconds, log_path=str(log_path), reason=reason,
                       mutations=result.mutations, margins=watches.margins.margins(result.violations),
                       first_seen=timing.seconds() if timing is not None else {}, cpu=cost.cpu,
                       cpu_waited=round(cost.waited, 3), wall=cost.wall, rss_mb=round(cost.rss_mb, 1),
                       timing=timing.channels_timing() if timing is not None else {}, violating=watches.violating(),
                       shutdowns=result.shutdowns if testcase is None else {})


def _run_options(spec: Spec, testcase: TestCase | None, params: dict[str, str], run_dir: Path, *,
                 dictionary: Dictionary | None, warm_recorder: ChildProcess | None) -> RunOptions:
    """The session's options for a case run in ``run_dir``: launched, recorded, the test case (its policy file
    attached to the log) intercepting; the spec's own stop on violation off (the campaign decides)."""
    attachments = {}
    interceptor = None
    if testcase is not None and testcase.policies:
        policy_file = run_dir / POLICY_NAME
        policy_file.write_text(testcase_text(testcase) or "", encoding="utf-8")  # stored: the log attaches it
        attachments[layout.POLICY_ATTACHMENT] = policy_file
        interceptor = Interceptor(testcase, spec, dictionary or load_dictionary())
    return RunOptions(mode=RunMode.STAR, launch=True, record=run_dir / LOG_NAME, params=dict(params),
                      command_line=["astaa-deft", "fuzz"], run_dir=run_dir / "modules",
                      interceptor=interceptor, stop_on_violation=False, attachments=attachments,
                      warm_recorder=warm_recorder)


class _Watches:
    """What a case run watches while it runs: margins, when a mutated run has settled or broke an invariant
    (not a known one), a clean run's channel timing; and, after it, its findings and violation counts.
    ``on_start``/``stop_when`` are the session's callbacks (its thread); the readers are called after it."""

    def __init__(self, spec: Spec, testcase: TestCase | None, settle: float | None, known: frozenset[str]) -> None:
        self.margins = MarginWatch(spec)
        self.settled = SettleWatch(testcase, settle) if testcase is not None and settle is not None else None
        self.timing = ChannelTiming(spec) if testcase is None else None  # a clean run measures the stack's timing
        self.stop_at_violation = testcase is not None
        self.known = known
        self.t0_ns: int | None = None
        self.monitors: MonitorSet | None = None

    def on_start(self, bus: RunView) -> None:
        self.t0_ns = time.time_ns()
        self.monitors = bus.monitor_set
        self.margins.attach(bus)
        if self.settled is not None:
            self.settled.attach(bus)
        if self.timing is not None:
            self.timing.attach(bus)

    def stop_when(self, bus: RunView) -> str | None:
        if self.stop_at_violation and any(v.invariant not in self.known for v in list(bus.violations)):
            return VIOLATION
        return self.settled.check(bus) if self.settled is not None else None

    def _at(self, time_ns: int) -> float | None:
        """Seconds from the run's start (None: the run did not start)."""
        return round((time_ns - self.t0_ns) / 1e9, 3) if self.t0_ns is not None else None

    def findings(self, result: RunResult) -> list[Finding]:
        """The run's violations, and each crashed module no violation names (an implicit Abort)."""
        found = [Finding(invariant=v.invariant, crash=v.crash, module=v.module, channel=v.channel, detail=v.detail,
                         at=self._at(v.time_ns), severity=v.severity,
                         signature=violation_signature(v)) for v in result.violations]
        for exit_ in result.crashes:
            if not any(f.module == exit_.module for f in found):
                said = signature_of_output(exit_.stderr_tail.splitlines(), exit_.signal)
                found.append(Finding(invariant=IMPLICIT, crash=Verdict.ABORT, module=exit_.module, channel=None,
                                     detail=exit_.describe(), at=self._at(exit_.time_ns),
                                     signature=said.text() if said else ""))
        return found

    def violating(self) -> dict[str, int]:
        """Per invariant that broke: the messages (or samples) that broke it."""
        if self.monitors is None:
            return {}
        return {name: s["violating"] for name, s in self.monitors.stats().items() if s["violating"]}


SETTLED = "settled after the last mutation"
VIOLATION = "violation"


class ChannelTiming:
    """Per channel a module consumes: seconds from the run's start to its first message, its rate and its
    longest gap between two messages (from its first message on: a slow start is not a gap)."""

    def __init__(self, spec: Spec):
        self.channels = [c.name for c in spec.channels if c.consumers]
        self.t0 = 0.0
        self.first: dict[str, float] = {}
        self.last: dict[str, float] = {}
        self.count: dict[str, int] = {}
        self.max_gap: dict[str, float] = {}
        self._lock = threading.Lock()

    def attach(self, bus: RunView) -> None:
        self.t0 = time.monotonic()
        for channel in self.channels:
            def seen(sample: zenoh.Sample, channel: str = channel) -> None:
                now = time.monotonic()
                with self._lock:
                    if channel in self.last:
                        self.max_gap[channel] = max(self.max_gap.get(channel, 0.0), now - self.last[channel])
                    else:
                        self.first[channel] = now - self.t0
                    self.last[channel] = now
                    self.count[channel] = self.count.get(channel, 0) + 1

            try:
                bus.subscribe(channel, seen)
            except KeyError:
                continue

    def seconds(self) -> dict[str, float]:
        with self._lock:
            return {k: round(v, 3) for k, v in self.first.items()}

    def channels_timing(self) -> dict[str, ChannelRate]:
        with self._lock:
            out = {}
            for channel, count in self.count.items():
                span = self.last[channel] - self.t0 - self.first[channel]
                out[channel] = ChannelRate(count, round((count - 1) / span, 3) if span > 0 else 0.0,
                                           round(self.max_gap.get(channel, 0.0), 4))
            return out


class SettleWatch:
    """Ends a mutated run ``settle`` seconds after its test case can mutate no more.

    A policy is done at its window's end, or — when it changes a bounded
    number of messages — once its window opened and the interception's
    mutation count has stood still for ``settle`` seconds. Windows counted
    from a channel's first message start counting when the tool sees it.
    A policy with an open-ended window keeps the run to its usual end.
    """

    def __init__(self, testcase: TestCase, settle: float):
        self.settle = settle
        self.anchors = {p.window.anchor_channel for p in testcase.policies if p.window.anchor_channel is not None}
        self.policies = testcase.policies
        self.t0 = 0.0
        self.first: dict[str, float] = {}  # anchor channel → monotonic time of its first message
        self.mutations = -1
        self.changed = 0.0
        self._lock = threading.Lock()

    def attach(self, bus: RunView) -> None:
        self.t0 = time.monotonic()
        self.changed = self.t0
        for channel in self.anchors:
            def seen(sample: zenoh.Sample, channel: str = channel) -> None:
                with self._lock:
                    self.first.setdefault(channel, time.monotonic())

            try:
                bus.subscribe(channel, seen)
            except KeyError:  # not observable: the run keeps its usual end
                continue

    def _last_chance(self) -> float:
        """Monotonic time after which no policy can act (inf: not known yet, or never)."""
        last = self.t0
        for policy in self.policies:
            window = policy.window
            base = self.t0
            if window.anchor_channel is not None:
                with self._lock:
                    base = self.first.get(window.anchor_channel, math.inf)
            bounded = policy.selection.limit is not None
            end = window.start if bounded else window.end
            if end is None:
                return math.inf
            last = max(last, base + end)
        return last

    def check(self, bus: RunView) -> str | None:
        now = time.monotonic()
        mutations = bus.mutations
        if mutations != self.mutations:
            self.mutations, self.changed = mutations, now
        if now >= self._last_chance() + self.settle and now >= self.changed + self.settle:
            return SETTLED
        return None


class MarginWatch:
    """How close each invariant with a margin came to breaking: the smallest margin of its values in the run.

    An invariant kind says whether it has one (``Invariant.margin_source``:
    the channel and field it watches; a bound with a min or a max) and
    measures it (``Invariant.margin_of``: normalised so invariants compare, 0
    when a value is non-finite or out of bounds); every invariant that broke
    gets 0. The guided strategy steers by these numbers.
    """

    def __init__(self, spec: Spec):
        self.watched = [(inv, source) for inv in spec.invariants
                        if isinstance(inv, Invariant) and (source := inv.margin_source()) is not None]
        self.spec = spec
        self.closest: dict[str, float] = {}
        self._lock = threading.Lock()

    def attach(self, bus: RunView) -> None:
        for inv, (channel, path) in self.watched:
            codec = get_codec(self.spec.channel(channel).encoding)
            def seen(sample: zenoh.Sample, inv: Invariant = inv, path: FieldPath = path, codec: Codec = codec) -> None:
                self._seen(inv, path, codec, sample)

            try:
                bus.subscribe(channel, seen)
            except KeyError:  # not observable in this mode
                continue

    def _seen(self, inv: Invariant, path: FieldPath, codec: Codec, sample: zenoh.Sample) -> None:
        try:
            values = [v for _, v in fields.get(codec.decode(sample.payload.to_bytes()), path)]
        except Exception:  # noqa: BLE001 - a payload the monitors will report; not ours to judge
            return
        for value in values:
            margin = inv.margin_of(value)
            if margin is None:
                continue
            with self._lock:
                if margin < self.closest.get(inv.name, math.inf):
                    self.closest[inv.name] = margin

    def margins(self, violations: tuple[Violation, ...]) -> dict[str, float]:
        with self._lock:
            out = dict(self.closest)
        for v in violations:
            out[v.invariant] = 0.0
        return out
