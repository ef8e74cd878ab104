"""What one run is asked to do (:class:`RunOptions`) and what it found (:class:`RunResult`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.model.records import ProcessExit, RunMode, RunVerdict, Verdict, Violation

if TYPE_CHECKING:  # types only: the command line builds options without loading Zenoh
    from astaa_deft.engine.bus.interception import Interceptor
    from astaa_deft.engine.bus.processes import ChildProcess
    from astaa_deft.io.log.records import PolicyApplicationsRecord


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """What one run is asked to do; read by the run from the thread that runs it.

    Keyword-only and frozen: a caller that needs another value makes a copy
    (``dataclasses.replace(options, time_limit=…)``).
    """

    mode: RunMode = RunMode.STAR  # in the middle, or an observer only (a string is read as its mode)
    launch: bool = True  # False: attach to an already running SUT
    record: Path | None = None  # the MCAP log; None: not recorded
    params: dict[str, str] = field(default_factory=dict)
    command_line: list[str] = field(default_factory=list)
    run_dir: Path | None = None  # module logs and configs; a fresh temp dir if None (one per session)
    interceptor: Interceptor | None = None  # an ASTAA test case engine (star mode only)
    stop_on_violation: bool = False
    attachments: dict[str, Path] = field(default_factory=dict)  # name in the log → file (policy, dictionaries)
    time_limit: float | None = None  # seconds; None: no limit from the caller
    # A recorder started ahead of the run (bus_run.warm_recorder), taken by this run if still alive.
    warm_recorder: ChildProcess | None = None
    # A module whose exit ends the run -> seconds its exit may come after its last message, as the caller learned
    # from clean runs (a campaign's baseline); the spec's own ``shutdown_delay`` wins (session/run_end.py).
    shutdown_delays: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # "star" or "passive" as text too; ValueError for anything else
        object.__setattr__(self, "mode", RunMode(self.mode))


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """One finished run, as a campaign or a command sees it."""

    end_reason: str  # "time limit", "signal SIGINT", "all modules exited", "violation", or stop_when's reason
    seconds: float  # wall time from the modules' launch to the end
    verdict: RunVerdict | None  # the CRASH-scale verdict (None if the run never started its monitors)
    violations: tuple[Violation, ...]
    exits: tuple[ProcessExit, ...]
    sent: dict[str, int]  # messages per channel that went through the star (or were observed)
    recorded: dict[str, int]  # messages per channel the recorder wrote
    mutations: int  # messages the interception changed
    log: Path | None  # the MCAP log, if recorded
    complete: bool  # the log was finished cleanly by its recorder (or nothing was recorded)
    observed: bool  # the monitors saw the run through to its end
    policies: tuple[PolicyApplicationsRecord, ...] = ()  # what each policy of the test case did (with a reason
    # for each that touched nothing)
    unjudged: str = ""  # why the monitors did not judge every message ("": they did); a Pass is then withheld
    # Per module whose exit ended the run: seconds from its last message on the bus to its exit (what a caller
    # learns a module's shutdown delay from).
    shutdowns: dict[str, float] = field(default_factory=dict)

    @property
    def crashes(self) -> tuple[ProcessExit, ...]:
        return tuple(e for e in self.exits if e.abnormal)

    @property
    def passed(self) -> bool:
        return (self.verdict is not None and self.verdict.klass == Verdict.PASS and self.complete and self.observed
                and not self.unjudged)
