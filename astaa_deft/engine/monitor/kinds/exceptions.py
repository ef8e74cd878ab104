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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.model.records import Verdict
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import MonitorContext
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.kinds.log import LogInvariant, LogMonitor, read_watched_output

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
    return LogMonitor(invariant, context)
