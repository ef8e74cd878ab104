"""Which error a module wrote: the exception's type and its innermost frame, read from the module's output.

A finding that says only "logged an exception" cannot tell two errors apart:
buckets, unmutated twins and dedupe compare findings on their *signature*
(after ClusterFuzz's crash state): the error's type and where it was raised,
file and function without line numbers (a line moves with every edit, a
function rarely).

* Python: a traceback — ``Traceback (most recent call last):``, its frames
  (``File "…/planner.py", line 42, in step``), its last line
  (``KeyError: 'lane'``): ``KeyError in planner.py:step``. A chained
  traceback ("During handling of the above exception…") is one report; its
  first exception (the cause) names it. ``Fatal Python error: …`` with the
  faulthandler's first frame.
* C++: ``terminate called after throwing an instance of 'std::runtime_error'``
  (``std::runtime_error``), ``terminate called without an active
  exception``, ``Segmentation fault`` (SIGSEGV); a module killed by a signal:
  the signal's name.
* Rust: ``thread 'main' panicked at src/main.rs:4:5`` (``Rust panic in
  main.rs``); Go: ``panic: …`` (the message, numbers folded) with the first
  frame of the panicking goroutine; Java: ``Exception in thread "main"
  java.lang.IllegalStateException`` with its first ``at`` frame.
* Any other error line: the line with its numbers folded (``ERROR planner:
  no path after N iterations``).

Multi-line reports are read line by line (:class:`ReportReader`), so the
``exceptions`` monitor judges the same lines the same way online and
offline. Pure: no I/O.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from astaa_deft.model.records import Violation

MAX_REPORT_LINES = 400  # a report longer than this is cut: its signature is what was read by then
MAX_TEXT = 120

_PY_START = "Traceback (most recent call last):"
_PY_CHAIN = ("During handling of the above exception, another exception occurred:",
             "The above exception was the direct cause of the following exception:")
_PY_FRAME = re.compile(r'^\s+File "([^"]+)", line \d+(?:, in (\S+))?')  # no function: a SyntaxError's
_PY_TYPE = re.compile(r"^([A-Za-z_][\w.]*)(?::\s|:$|$)")
_FAULT_START = re.compile(r"Fatal Python error: (.*)")
_FAULT_FRAME = re.compile(r'^\s+File "([^"]+)", line \d+ in (\S+)')
_TERMINATE = re.compile(r"terminate called after throwing an instance of '([^']+)'")
_RUST = re.compile(r"thread '[^']*' panicked at (?:'.*?', )?([^\s:]+?\.rs)")
_GO_START = re.compile(r"^panic: (.*)")
_GO_FUNC = re.compile(r"^([\w./*()\[\]-]+)\(.*\)$")
_GO_FILE = re.compile(r"^\s+(\S+\.go):\d+")
_JAVA_START = re.compile(r'Exception in thread "[^"]*" ([\w.$]+)')
_JAVA_FRAME = re.compile(r"^\s+at ([\w.$<>]+)\(([^:)]+)")
_NUMBERS = re.compile(r"0x[0-9a-fA-F]+|\d+(?:\.\d+)?")
_SIGNALS = {"Segmentation fault": "SIGSEGV", "Aborted": "SIGABRT", "Bus error": "SIGBUS",
            "Floating point exception": "SIGFPE", "Illegal instruction": "SIGILL"}


@dataclass(frozen=True)
class ErrorSignature:
    """An error's type and, when the report names one, its innermost frame (``file:function``)."""

    error: str
    frame: str = ""

    def text(self) -> str:
        """``KeyError in planner.py:step``, or the type alone."""
        return f"{self.error} in {self.frame}" if self.frame else self.error


def _base(path: str) -> str:
    return path.replace("\\", "/").rsplit("/", 1)[-1]


def _frame(path: str, function: str | None) -> str:
    return f"{_base(path)}:{function}" if function else _base(path)


def folded(line: str) -> str:
    """A line as a signature: numbers (times, counts, addresses) folded to N, cut short."""
    text = _NUMBERS.sub("N", line.strip())
    return text if len(text) <= MAX_TEXT else text[:MAX_TEXT] + "…"


class ReportReader:
    """One multi-line error report read line by line: ``feed`` says whether a line belongs to it."""

    def __init__(self, kind: str, error: str = "") -> None:
        self.kind = kind
        self.error = error
        self.frame = ""
        self.message = ""  # the line that says what went wrong (a Python exception's last line)
        self.done = False  # nothing more belongs to it
        self._lines = 1
        self._state = "frames"
        self._go_function = ""

    @property
    def named(self) -> bool:
        """Its signature is complete: what follows (a chained traceback) does not change it."""
        return self.done or (self.kind == "python" and self._state != "frames")

    def signature(self) -> ErrorSignature:
        return ErrorSignature(self.error or _UNREAD[self.kind], self.frame)

    def feed(self, line: str) -> bool:
        """True if ``line`` belongs to this report (then ``done`` may turn True); False: the report ended before
        it."""
        if self.done:
            return False
        self._lines += 1
        if self._lines > MAX_REPORT_LINES:
            self.done = True
            return False
        return {"python": self._python, "fault": self._fault, "go": self._go, "java": self._java}[self.kind](line)

    def _python(self, line: str) -> bool:
        stripped = line.strip()
        if self._state == "after":  # the exception's line was read: a chained traceback may follow
            if not stripped:
                return True
            if stripped in _PY_CHAIN:
                self._state = "chain"
                return True
            self.done = True
            return False
        if self._state == "chain":  # the chained traceback: part of this report, its own type not the name
            if not stripped or line[:1].isspace() or stripped in _PY_CHAIN or stripped == _PY_START:
                return True
            if _PY_TYPE.match(stripped):
                self._state = "after"
                return True
            self.done = True
            return False
        frame = _PY_FRAME.match(line)
        if frame:
            self.frame = _frame(frame.group(1), frame.group(2))
            return True
        if line[:1].isspace() or not stripped:
            return True
        match = _PY_TYPE.match(stripped)
        if match and self.frame:
            self.error, self.message, self._state = match.group(1), stripped, "after"
            return True
        self.done = True
        return False

    def _fault(self, line: str) -> bool:
        stripped = line.strip()
        frame = _FAULT_FRAME.match(line)
        if frame:
            self.frame = f"{_base(frame.group(1))}:{frame.group(2)}"
            self.done = True  # the first frame listed is the innermost
            return True
        if not stripped or line[:1].isspace() or stripped.startswith(("Current thread", "Thread 0x")):
            return True
        self.done = True
        return False

    def _go(self, line: str) -> bool:
        stripped = line.strip()
        file_line = _GO_FILE.match(line)
        if file_line and self._go_function:
            self.frame = f"{_base(file_line.group(1))}:{self._go_function}"
            self.done = True
            return True
        function = _GO_FUNC.match(stripped)
        if function and self._state == "goroutine":
            self._go_function = function.group(1)
            return True
        if stripped.startswith("goroutine ") and stripped.endswith(":"):
            self._state = "goroutine"
            return True
        if not stripped or stripped.startswith("[signal ") or line[:1].isspace():
            return True
        self.done = True
        return False

    def _java(self, line: str) -> bool:
        frame = _JAVA_FRAME.match(line)
        if frame:
            self.frame = f"{_base(frame.group(2))}:{frame.group(1)}"
            self.done = True
            return True
        self.done = True
        return False


_UNREAD = {"python": "Python exception", "fault": "Fatal Python error", "go": "Go panic", "java": "Java exception"}


def start_of_report(line: str) -> ReportReader | None:
    """A reader for the report ``line`` begins (a traceback, a Go panic, …); None for a one-line error."""
    if _PY_START in line:
        return ReportReader("python")
    fault = _FAULT_START.search(line)
    if fault:
        return ReportReader("fault", f"Fatal Python error: {fault.group(1).strip()}")
    go = _GO_START.match(line)
    if go:
        return ReportReader("go", f"Go panic: {folded(go.group(1))}")
    java = _JAVA_START.search(line)
    if java:
        return ReportReader("java", java.group(1))
    return None


def line_signature(line: str) -> ErrorSignature:
    """The signature of a one-line error report."""
    terminate = _TERMINATE.search(line)
    if terminate:
        return ErrorSignature(terminate.group(1), "C++ terminate")
    if "terminate called without an active exception" in line:
        return ErrorSignature("terminate without an active exception", "C++ terminate")
    rust = _RUST.search(line)
    if rust:
        return ErrorSignature("Rust panic", _base(rust.group(1)))
    for words, name in _SIGNALS.items():
        if words in line:
            return ErrorSignature(name)
    return ErrorSignature(folded(line))


def signature_of_output(lines: Iterable[str], signal: str | None = None) -> ErrorSignature | None:
    """The signature of the last error report in a module's last output lines (a crashed module's stderr
    tail), else of the signal that killed it; None when neither says."""
    lines = list(lines)
    found: ErrorSignature | None = None
    reader: ReportReader | None = None
    for line in lines:
        if reader is not None:
            if reader.feed(line):
                continue
            found, reader = reader.signature(), None
        reader = start_of_report(line)
        if reader is None and (_TERMINATE.search(line) or _RUST.search(line) or "terminate called" in line):
            found = line_signature(line)
    if reader is not None:
        found = reader.signature()
    if found is None:
        found = _cut_traceback(list(lines))
    if found is None and signal:
        return ErrorSignature(signal)
    return found


def _cut_traceback(lines: list[str]) -> ErrorSignature | None:
    """A Python traceback whose first lines the tail cut off: its last frame and the exception line after it."""
    frame = ""
    found = None
    for line in lines:
        match = _PY_FRAME.match(line)
        if match:
            frame = _frame(match.group(1), match.group(2))
            continue
        typed = _PY_TYPE.match(line.strip()) if frame and not line[:1].isspace() else None
        if typed:
            found, frame = ErrorSignature(typed.group(1), frame), ""
    return found


def violation_signature(violation: Violation) -> str:
    """The error signature a finding carries (``exceptions``, ``log``, ``process``), "" when it names none."""
    message = violation.message
    found = message.get("signature") if isinstance(message, dict) else None
    return found if isinstance(found, str) else ""
