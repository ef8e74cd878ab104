"""``log``: what a module writes on its output — a traceback, an ``ERROR`` line, a named exception.

    - {name: planner_quiet, kind: log, modules: [planning], pattern: "Traceback|ERROR"}
    - {name: no_solver_failure, kind: log, pattern: "SolverError", crash: Silent, max_count: 2}

A module that catches an exception, logs it and carries on publishes nothing
for that cycle; no message monitor can see it (the deadline monitor's gap is
too coarse for one lost cycle). Every output line of the watched modules
(all modules by default) is matched against ``pattern`` (a regular
expression run by RE2 — linear time, so no pattern can hang the tool; no
lookarounds or backreferences: ``model/patterns.py`` — searched anywhere in
the line); each matching line beyond the
first ``max_count`` (default 0) is a violation, dated by when the tool read
the line. The lines come from the modules' output files (stdout and stderr
together, as the launcher writes them) and are logged as ``module_log``
events, so ``check`` judges them again offline. Default CRASH class:
*Silent* — the module went on as if nothing happened.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.model.patterns import MAX_PATTERN, PatternError, UserPattern, compile_user_pattern
from astaa_deft.model.records import Verdict
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import NO_VIOLATIONS, Invariant, LogLineInfo, Monitor, MonitorContext
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("modules", "pattern", "max_count")
REQUIRED = ("pattern",)


@dataclass(frozen=True, kw_only=True)
class LogInvariant(Invariant):
    kind: ClassVar[str] = "log"
    crash_kind: ClassVar[bool] = True
    default_crash: ClassVar[Verdict] = Verdict.SILENT

    modules: tuple[str, ...]
    pattern: UserPattern
    max_count: int = 0

    def what_matched(self) -> str:
        """How a violation's detail says what the line was."""
        return f"wrote a line matching /{self.pattern.pattern}/"


@dataclass(frozen=True)
class WatchedOutput:
    """The keys every output-watching kind reads: which modules, which lines, how many tolerated."""

    modules: tuple[str, ...]
    pattern: UserPattern
    max_count: int


def parse(reader: InvariantReader, node: Node, common: dict) -> LogInvariant | None:
    watched = read_watched_output(reader, node.value)
    if watched is None:
        return None
    return LogInvariant(modules=watched.modules, pattern=watched.pattern, max_count=watched.max_count, **common)


def read_watched_output(reader: InvariantReader, v: dict[str, Node], built_in: str | None = None
                        ) -> WatchedOutput | None:
    """``modules`` (default: all), ``pattern`` and ``max_count`` (default 0) of an invariant's mapping ``v``;
    None after reporting a problem. ``built_in``: lines it always matches, the ``pattern`` (then optional)
    matching more lines."""
    modules = reader.module_list(v.get("modules"), "planning")
    if modules is None:
        return None
    text = reader.text(v.get("pattern"), "'pattern'", "Traceback|ERROR")
    if text is None and ("pattern" in v or built_in is None):  # a bad one reported; a missing one by REQUIRED
        return None
    try:
        pattern = compile_user_pattern(text) if text is not None else None
        if built_in is not None:  # the user's pattern checked alone first: its error names it, not the whole
            pattern = compile_user_pattern(built_in if pattern is None else f"{built_in}|(?:{pattern.pattern})",
                                           limit=len(built_in) + MAX_PATTERN + 10)
    except PatternError as exc:
        reader.problem(v["pattern"], f"'pattern' {exc.reason}", exc.fix)
        return None
    assert pattern is not None
    max_count = 0
    if "max_count" in v:
        value = v["max_count"].value
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            reader.problem(v["max_count"], "'max_count' must be a whole number ≥ 0",
                           "the matching lines tolerated before it counts, e.g. max_count: 2")
            return None
        max_count = value
    return WatchedOutput(modules, pattern, max_count)


class LogMonitor(Monitor):
    wants_log_lines: ClassVar[bool] = True

    def __init__(self, invariant: LogInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._search = invariant.pattern.search
        self.matches = 0

    def on_log_line(self, line: LogLineInfo) -> list[Violation]:
        if line.module not in self.inv.modules:
            return NO_VIOLATIONS
        self.evaluations += 1
        if self._search(line.text) is None:
            return NO_VIOLATIONS
        self.matches += 1
        if self.matches <= self.inv.max_count:
            return NO_VIOLATIONS
        self.violating += 1
        shown = line.text if len(line.text) <= 200 else line.text[:200] + "…"
        detail = f"module '{line.module}' {self.inv.what_matched()}: {shown}"
        pattern = f"/{self.inv.pattern.pattern}/"  # a log finding's signature: the pattern it matched
        return [self.violation(line.time_ns, detail, module=line.module,
                               context={"line": line.text, "pattern": pattern, "signature": pattern})]


def monitor(invariant: LogInvariant, context: MonitorContext) -> LogMonitor:
    return LogMonitor(invariant, context)


Kind.register(LogInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
