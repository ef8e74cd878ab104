"""``exceptions``: a module logged an exception or an error — the ``log`` kind with the patterns built in.

    - {name: planner_errors, kind: exceptions, modules: [planning]}
    - {name: solver_errors, kind: exceptions, pattern: "solver failed", max_count: 2}

Every output line of the watched modules (all by default) is searched for
what runtimes write when something went wrong (``BUILT_IN``): a Python
traceback's first line, a ``Fatal Python error``, an ``ERROR``, ``FATAL``
or ``CRITICAL`` word (Python logging, ROS 2's ``[ERROR]``, most C++ loggers;
upper case and whole words only, so "0 errors" or "ERRORS: 0" do not count),
a line starting ``Error:`` (OMPL, Rust), C++'s ``terminate called …``, a
``Segmentation fault`` message, a Rust or Go panic and a Java exception. The
optional ``pattern`` (a regular expression, RE2: see ``log``) matches more lines;
``max_count`` (default 0) lines are tolerated. A Python traceback counts
once (its first line), not once per frame. Default CRASH class *Silent* (the
module carried on as if nothing happened; a module that died of it is the
``process`` kind's Abort as well), severity the invariants' default (high).
A multi-line report (a traceback) is one finding, which names the error:
its type and innermost frame (``error_signature``), the signature buckets,
twins and dedupe compare.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.model.json import JsonObject
from astaa_deft.model.records import Verdict
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import NO_VIOLATIONS, LogLineInfo, MonitorContext
from astaa_deft.engine.monitor.error_signature import (
    ErrorSignature, ReportReader, folded, line_signature, start_of_report,
)
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds.log import LogInvariant, LogMonitor, read_watched_output
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("modules", "pattern", "max_count")
REQUIRED = ()
BUILT_IN = "|".join((
    r"Traceback \(most recent call last\):",  # Python, uncaught or printed by logging.exception
    r"Fatal Python error",  # faulthandler: a segfault or abort inside Python
    r"\b(?:ERROR|FATAL|CRITICAL)\b",  # log levels
    r"^Error:",  # a line that starts so: OMPL's error log, Rust's main returning Err
    r"terminate called",  # C++: an uncaught exception (after throwing an instance of …) or no active one
    r"Segmentation fault",
    r"thread '[^']*' panicked at",  # Rust
    r"^panic: ",  # Go
    r'Exception in thread "',  # Java (Python's threads print "Exception in thread NAME:" and a traceback)
))


@dataclass(frozen=True, kw_only=True)
class ExceptionsInvariant(LogInvariant):
    kind: ClassVar[str] = "exceptions"
    crash_kind: ClassVar[bool] = True
    default_crash: ClassVar[Verdict] = Verdict.SILENT

    def what_matched(self) -> str:
        return "logged an exception or error"


def parse(reader: InvariantReader, node: Node, common: dict) -> ExceptionsInvariant | None:
    watched = read_watched_output(reader, node.value, built_in=BUILT_IN)
    if watched is None:
        return None
    return ExceptionsInvariant(modules=watched.modules, pattern=watched.pattern, max_count=watched.max_count,
                               **common)


def monitor(invariant: ExceptionsInvariant, context: MonitorContext) -> LogMonitor:
    return ExceptionsMonitor(invariant, context)


class ExceptionsMonitor(LogMonitor):
    """The ``log`` monitor that reads a multi-line report whole: one finding per traceback, naming its error.

    A report (a Python traceback, a Go panic, a Java exception, a faulthandler
    dump) gives one finding, dated by its first line, carrying its signature
    (``error_signature``): the exception's type and innermost frame. It is
    reported as soon as both are read (a traceback's exception line, a
    panic's first frame), else when the report ends — the next line of that
    module that is not part of it, or the run's end; what follows of it (a
    chained traceback) is read as part of it. Its other lines never count as
    matches of their own.
    """

    def __init__(self, invariant: LogInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        # module -> (first line, reader, counts, reported yet)
        self._open: dict[str, tuple[LogLineInfo, ReportReader, bool, bool]] = {}

    def on_log_line(self, line: LogLineInfo) -> list[Violation]:
        if line.module not in self.inv.modules:
            return NO_VIOLATIONS
        out: list[Violation] = []
        opened = self._open.get(line.module)
        if opened is not None:
            first, reader, counts, reported = opened
            if reader.feed(line.text):
                self.evaluations += 1
                if reader.done:
                    return self._close(line.module)
                if reader.named and not reported:  # its error is known: no need to wait for its end
                    self._open[line.module] = (first, reader, counts, True)
                    return [self._finding(first, reader.signature(), reader.message)] if counts else NO_VIOLATIONS
                return NO_VIOLATIONS
            out = self._close(line.module)
        self.evaluations += 1
        if self._search(line.text) is None:
            return out or NO_VIOLATIONS
        self.matches += 1
        counts = self.matches > self.inv.max_count
        started = start_of_report(line.text)
        if started is not None:
            self._open[line.module] = (line, started, counts, False)
            return out or NO_VIOLATIONS
        if counts:
            out.append(self._finding(line, line_signature(line.text), ""))
        return out or NO_VIOLATIONS

    def finish(self, time_ns: int) -> list[Violation]:
        out: list[Violation] = []
        for module in list(self._open):
            out.extend(self._close(module))
        return out or NO_VIOLATIONS

    def _close(self, module: str) -> list[Violation]:
        line, reader, counts, reported = self._open.pop(module)
        return [self._finding(line, reader.signature(), reader.message)] if counts and not reported else []

    def _finding(self, line: LogLineInfo, signature: ErrorSignature, message: str) -> Violation:
        self.violating += 1
        shown = line.text if len(line.text) <= 200 else line.text[:200] + "…"
        if signature.text() == folded(line.text):  # a one-line error: the line says it all
            detail = f"module '{line.module}' {self.inv.what_matched()}: {shown}"
        else:  # which error, where: "KeyError in planner.py:step — KeyError: 'lane'"
            said = message[:200] if message else shown
            detail = f"module '{line.module}' {self.inv.what_matched()}: {signature.text()} — {said}"
        context: JsonObject = {"line": line.text, "error": signature.error, "frame": signature.frame,
                   "signature": signature.text()}
        if message:
            context["message"] = message
        return self.violation(line.time_ns, detail, module=line.module, context=context)


Kind.register(ExceptionsInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
