"""The spec's ``run:`` section as typed records: how a run ends, and what its end means (read by
``engine/spec/run_section.py``, acted on by ``engine/session/run_end.py``). Pure data."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from astaa_deft.model.json import DecodedMessage
from astaa_deft.model.records import Verdict

PASS = "pass"
DEFAULT_SEVERITY = "high"


class Condition(Protocol):
    """A compiled condition on a channel's messages (``engine.monitor.expression.CompiledExpression``)."""

    @property
    def text(self) -> str: ...

    @property
    def evaluate(self) -> Callable[[DecodedMessage], object]: ...  # a decoded message -> its value


@dataclass(frozen=True)
class Outcome:
    """What a run's end means: a pass, or a finding with a CRASH class and a severity."""

    name: str
    crash: Verdict | None = None  # None: the end is a pass
    severity: str = DEFAULT_SEVERITY

    @property
    def passed(self) -> bool:
        return self.crash is None


PASS_OUTCOME = Outcome(PASS)
CRASHED = Outcome("crashed", Verdict.ABORT)  # an exit code the spec does not list, or a kill by a signal


@dataclass(frozen=True, kw_only=True)
class ModuleExitEnd:
    """The run ends when ``module`` exits; its exit code says how it went."""

    module: str
    exit_codes: Mapping[int, Outcome] = field(default_factory=lambda: {0: PASS_OUTCOME})
    other: Outcome = CRASHED
    reason: str = ""
    # Seconds the module may take from its last message to its exit (writing results, closing its sessions):
    # as the spec gives it (None: learned from clean runs, else the session's default shutdown grace).
    shutdown_delay: float | None = None

    def outcome(self, returncode: int, signal: str | None) -> Outcome:
        if signal:
            return Outcome(f"killed by {signal}", Verdict.ABORT)
        return self.exit_codes.get(returncode, self.other)

    def describe(self) -> str:
        return self.reason or f"module '{self.module}' exited"


@dataclass(frozen=True)
class ChannelEnd:
    """The run ends at the first message on ``channel`` for which ``expr`` holds."""

    channel: str
    expr: Condition  # an expression of the monitors' language, compiled against the channel's type
    reason: str
    outcome: Outcome = PASS_OUTCOME


@dataclass(frozen=True)
class RunSection:
    time_limit: float | None = None
    module_exits: tuple[ModuleExitEnd, ...] = ()
    channel_ends: tuple[ChannelEnd, ...] = ()

    def exit_end(self, module: str) -> ModuleExitEnd | None:
        """The condition that makes ``module``'s exit the end of the run (None: its exit is a crash)."""
        return next((m for m in self.module_exits if m.module == module), None)

    @property
    def empty(self) -> bool:
        return self.time_limit is None and not self.module_exits and not self.channel_ends
