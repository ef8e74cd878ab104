"""The interface every invariant kind implements, and what they share.

A kind (``kinds/<kind>.py``) brings three things: a frozen dataclass holding
the validated invariant (built once, when the spec loads), a parser that
builds it from YAML, and a ``Monitor`` that evaluates it over a run. The
monitor gets messages, process exits and clock ticks, and answers with
violations; it never raises on a bad message (that *is* a finding) and
never looks at the wall clock (only at the times it is given), so the same
monitor gives the same verdicts online, from the bus, and offline, from a
log.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar
from collections.abc import Hashable, Iterable

from astaa_deft.model.fields import FieldPath
from astaa_deft.model.json import JsonObject
from astaa_deft.model.records import ProcessExit, Verdict
from astaa_deft.model.vocabulary import TextEnum
from astaa_deft.model.sut import Spec
from astaa_deft.engine.monitor.violation import Violation, message_copy

NO_VIOLATIONS: list[Violation] = []  # returned (never mutated) on the hot path to avoid allocating


class ReplayJudges(TextEnum):
    """What a replay of one module can judge of an invariant (its kind's trait, :attr:`Invariant.replay_judges`).

    ``values``: the module's outputs, any replay of it (if the invariant reads
    nothing else). ``timing``: a module's silence or lateness — only a replay
    stepping every trigger (per-trigger frames) judges it, where the module
    hanging is the silence; after the module crashed, a silence is the
    crash's consequence. ``process``: a process's exit — only a replay that
    shows the module's crash (``exceptions: crash``) judges it.
    """

    VALUES = "values"
    TIMING = "timing"
    PROCESS = "process"


@dataclass(frozen=True, kw_only=True)
class Invariant:
    """What every invariant declares; kinds add their own fields.

    A kind's traits (class attributes) say what may judge it, so the
    minimiser, DeFT and the campaign ask the kind, never its name:
    ``replay_judges`` (:class:`ReplayJudges`), ``crash_kind`` (it watches a
    module dying or raising), and the margin hook (:meth:`margin_source`,
    :meth:`margin_of`: how close a run came to breaking it, which the guided
    strategy steers by).
    """

    kind: ClassVar[str] = "?"
    default_crash: ClassVar[Verdict] = Verdict.SILENT  # the CRASH class a violation of this kind points at
    replay_judges: ClassVar[ReplayJudges] = ReplayJudges.VALUES
    crash_kind: ClassVar[bool] = False  # a module dying or raising (an abnormal exit, its log, its exceptions)

    name: str
    severity: str = "high"
    crash: Verdict | None = None  # overrides default_crash (e.g. Hindering for a status channel that lies)
    description: str = ""
    line: int | None = None  # where the spec declares it

    def margin_source(self) -> tuple[str, FieldPath] | None:
        """(channel, field path) whose values :meth:`margin_of` measures, or None: no margin (the default)."""
        return None

    def margin_of(self, value: object) -> float | None:
        """How far one value of :meth:`margin_source` is from breaking this invariant, normalised (0: broken or
        not finite); None: not a value it bounds."""
        return None


@dataclass(frozen=True)
class LogLineInfo:
    """One line a module wrote on its output, and when the tool read it."""

    module: str
    text: str
    time_ns: int


@dataclass(frozen=True)
class MonitorContext:
    spec: Spec
    start_ns: int  # the run's start: deadlines 'after: start' and the temporal sampling grid count from it

    def producer(self, channel: str) -> str | None:
        return next((c.producer for c in self.spec.channels if c.name == channel), None)


class Monitor:
    """Runtime state of one invariant. Subclasses override what they need."""

    wants_ticks: ClassVar[bool] = False  # on_tick is only called on monitors that say so
    wants_log_lines: ClassVar[bool] = False  # on_log_line likewise
    # A message on its channels whose payload does not decode (passed as None): True when this monitor judges
    # it anyway (a violation, or only its arrival matters); False when it cannot read it — the message is then
    # unjudged, and the MonitorSet withholds a Pass (the run was not fully observed).
    judges_undecodable: ClassVar[bool] = False

    def __init__(self, invariant: Invariant, context: MonitorContext):
        self.invariant = invariant
        self.context = context
        self.evaluations = 0  # messages (or samples) judged
        self.violating = 0  # of those, how many broke the invariant

    def channels(self) -> set[str]:
        """The channels whose messages this monitor reads."""
        return set()

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        return NO_VIOLATIONS

    def on_process_exit(self, exit_: ProcessExit) -> list[Violation]:
        return NO_VIOLATIONS

    def on_log_line(self, line: LogLineInfo) -> list[Violation]:
        return NO_VIOLATIONS

    def on_tick(self, time_ns: int) -> list[Violation]:
        return NO_VIOLATIONS

    def finish(self, time_ns: int) -> list[Violation]:
        return NO_VIOLATIONS

    # -- helpers for subclasses ----------------------------------------------
    def violation(self, time_ns: int, detail: str, *, channel: str | None = None, seq: int | None = None,
                  message: object = None, context: JsonObject | None = None, module: str | None = None,
                  crash: Verdict | None = None, infer_module: bool = True) -> Violation:
        """A violation of this invariant; the module defaults to the channel's producer.

        ``message``: the offending message, stored as a bounded JSON-safe copy;
        ``context``: what a kind without one stores instead, as it is.
        """
        inv = self.invariant
        if module is None and infer_module and channel is not None:
            module = self.context.producer(channel)
        return Violation(
            invariant=inv.name, invariant_kind=inv.kind, severity=inv.severity, time_ns=time_ns, channel=channel,
            seq=seq, message=message_copy(message) if context is None else context, detail=detail,
            crash=inv.crash or crash or inv.default_crash, module=module,
        )


class EpisodeGate:
    """Report a broken invariant once per episode: when it breaks after holding.

    ``key`` separates independent episodes inside one invariant (an obstacle
    id for collisions); most monitors use the default key.
    """

    def __init__(self) -> None:
        self._broken: set[Hashable] = set()

    def broke(self, key: Hashable = None) -> bool:
        """Record a failure; True if it starts a new episode (so it should be reported)."""
        if key in self._broken:
            return False
        self._broken.add(key)
        return True

    def held(self, key: Hashable = None) -> None:
        self._broken.discard(key)

    def keep_only(self, keys: Iterable[Hashable]) -> None:
        """End the episodes of every key not in ``keys`` (they held, or are gone)."""
        self._broken.intersection_update(keys)
