"""``deadline``: a channel, or a module, keeps talking.

    # a channel silent for longer than 0.5 s once it has started
    - {name: planning_deadline, kind: deadline, channel: trajectory, max_gap: 0.5}
    # ... or counted from the run's start (module start-up included)
    - {name: first_plan, kind: deadline, channel: trajectory, max_gap: 30, after: start}
    # a module that stops answering: none of the channels it produces carries anything
    - {name: planning_alive, kind: deadline, module: planning, max_gap: 1.0}
    # request/response: after each 'localization' message a 'command' within 0.2 s
    - {name: control_answers, kind: deadline, channel: command, responds_to: localization, max_gap: 0.2}

The violation is dated when the deadline expired (the last message + max_gap),
whoever notices it (a clock tick online, the next message or the end of the
log offline), so online and offline agree on it. One violation per silence.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.model.records import Verdict
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import ReplayJudges, NO_VIOLATIONS, Invariant, Monitor, MonitorContext
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("channel", "module", "max_gap", "after", "responds_to")
REQUIRED = ("max_gap",)
MAX_GAP_S = 86_400.0  # a day: beyond it a deadline is a typo, and its nanoseconds would not fit an int64
AFTER = ("first", "start")


@dataclass(frozen=True, kw_only=True)
class DeadlineInvariant(Invariant):
    kind: ClassVar[str] = "deadline"
    replay_judges: ClassVar[ReplayJudges] = ReplayJudges.TIMING
    default_crash: ClassVar[Verdict] = Verdict.RESTART  # a module that stops talking hangs (CRASH: needs a restart)

    channels: tuple[str, ...]  # the watched channels: one, or every channel a module produces
    max_gap_ns: int
    after: str = "first"
    module: str | None = None  # set when watching a whole module
    responds_to: str | None = None


def parse(reader: InvariantReader, node: Node, common: dict) -> DeadlineInvariant | None:
    v = node.value
    if ("channel" in v) == ("module" in v):
        reader.problem(node, "a deadline watches either a 'channel' or a 'module'",
                       "give exactly one of channel: NAME or module: NAME")
        return None
    max_gap = reader.number(v.get("max_gap"), "'max_gap'", positive=True, maximum=MAX_GAP_S)
    after = reader.choice(v.get("after"), "'after'", AFTER) if "after" in v else "first"
    if max_gap is None or after is None:
        return None
    responds_to = None
    if "responds_to" in v:
        if "module" in v:
            reader.problem(v["responds_to"], "'responds_to' works with 'channel', not 'module'",
                           "name the answering channel with channel: NAME")
            return None
        request = reader.channel(v["responds_to"])
        if request is None:
            return None
        responds_to = request.name
    module = None
    if "module" in v:
        module = reader.module(v["module"])
        if module is None:
            return None
        channels = tuple(c.name for c in reader.channels.values() if c.producer == module)
        if not channels:
            reader.problem(v["module"], f"module '{module}' produces no declared channel, so it cannot be watched",
                           "use a 'process' invariant for it, or declare its channels")
            return None
    else:
        channel = reader.channel(v["channel"])
        if channel is None:
            return None
        if channel.name == responds_to:
            reader.problem(v["responds_to"], "a channel cannot answer itself", "name the request channel")
            return None
        channels = (channel.name,)
    return DeadlineInvariant(channels=channels, max_gap_ns=int(max_gap * 1e9), after=after, module=module,
                             responds_to=responds_to, **common)


class DeadlineMonitor(Monitor):
    judges_undecodable: ClassVar[bool] = True  # its arrival is all it reads
    wants_ticks = True

    def __init__(self, invariant: DeadlineInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._watched = frozenset(invariant.channels)
        self._gap = invariant.max_gap_ns
        # silence: the last message (or the start); response: the oldest unanswered request
        self._since: int | None = context.start_ns if (invariant.after == "start" and not invariant.responds_to) \
            else None
        self._since_seq: int | None = None
        self._since_channel: str | None = None
        self._reported = False

    def channels(self) -> set[str]:
        return set(self._watched) | ({self.inv.responds_to} if self.inv.responds_to else set())

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        out = self._expire(time_ns)
        if channel in self._watched:
            self.evaluations += 1
            if self.inv.responds_to:
                self._since = None  # answered: nothing pending
            else:
                self._since, self._since_seq, self._since_channel = time_ns, seq, channel
            self._reported = False
        elif channel == self.inv.responds_to and self._since is None:
            self._since, self._since_seq, self._since_channel = time_ns, seq, channel
            self._reported = False
        return out

    def on_tick(self, time_ns: int) -> list[Violation]:
        return self._expire(time_ns)

    def finish(self, time_ns: int) -> list[Violation]:
        return self._expire(time_ns)

    def _expire(self, now_ns: int) -> list[Violation]:
        if self._since is None or self._reported or now_ns - self._since <= self._gap:
            return NO_VIOLATIONS
        self._reported = True
        self.violating += 1
        return [self.violation(self._since + self._gap, self._detail(), channel=self._since_channel,
                               seq=self._since_seq, module=self._responsible(),
                               context={"since_ns": self._since, "max_gap_s": self._gap / 1e9})]

    def _detail(self) -> str:
        gap = f"{self._gap / 1e9:g} s"
        inv = self.inv
        if inv.responds_to:
            return f"no message on '{inv.channels[0]}' within {gap} of '{inv.responds_to}' #{self._since_seq}"
        what = f"module '{inv.module}' (channels {', '.join(inv.channels)})" if inv.module \
            else f"channel '{inv.channels[0]}'"
        since = "the run's start" if self._since_seq is None else f"'{self._since_channel}' #{self._since_seq}"
        return f"{what} silent for more than {gap} after {since}"

    def _responsible(self) -> str | None:
        return self.inv.module or self.context.producer(self.inv.channels[0])


def monitor(invariant: DeadlineInvariant, context: MonitorContext) -> DeadlineMonitor:
    return DeadlineMonitor(invariant, context)


Kind.register(DeadlineInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
