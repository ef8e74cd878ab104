"""The tool's errors: one base class, and the user-facing one that names the file, the place and the fix.

Every exception class of the package derives from :class:`AstaaDeftError`,
so a caller (the CLI, a campaign running thousands of sessions) can tell the
tool's own errors from anything else with one ``except``. Each class says
whether it is meant for the user (``exit_code`` set: printed as one line per
problem, no traceback) or is internal (``exit_code`` None: it is caught
inside the tool, and one escaping to the CLI is a bug, shown with its
traceback). Only :class:`InputError` (exit code 2) is meant for the user today.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar


class AstaaDeftError(Exception):
    """Base of every exception the tool raises on purpose."""

    # The CLI's exit code when this escapes to it; None: internal, a bug if it escapes.
    exit_code: ClassVar[int | None] = None

    def user_lines(self) -> list[str]:
        """What the CLI prints, one line each."""
        return [str(self)]


@dataclass(frozen=True)
class Problem:
    file: str
    line: int | None  # 1-based
    column: int | None  # 1-based
    message: str
    fix: str = ""

    def __str__(self) -> str:
        where = self.file
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        text = f"{where}: {_shortened(self.message)}"
        if self.fix:
            text += f" — {_shortened(self.fix)}"
        return text


_LONG_RUN = re.compile(r"\S{200,}")  # longer than any path a message names


def _shortened(text: str) -> str:
    """Quoted input can be huge (a 5,000-digit number, a mangled document): keep each run's ends, say how long."""
    return _LONG_RUN.sub(lambda m: f"{m.group()[:60]}…({len(m.group())} characters)…{m.group()[-30:]}", text)


class InputError(AstaaDeftError):
    """Bad user input (a spec, a policy, a dictionary, a log, a path): exit code 2."""

    exit_code = 2

    def __init__(self, problems: Iterable[Problem] | Problem | str):
        items: Iterable[Problem | str] = [problems] if isinstance(problems, (Problem, str)) else problems
        self.problems = [p if isinstance(p, Problem) else Problem("", None, None, p) for p in items]
        super().__init__("\n".join(map(str, self.problems)))

    def user_lines(self) -> list[str]:
        return [str(problem) for problem in self.problems]


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    choices = list(choices)
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if not close:  # 'sequence' for 'seq', 'readiness' for 'ready'
        close = [c for c in choices if len(c) >= 3 and (word.startswith(c[:4]) or c.startswith(word[:4]))][:1]
    return f"did you mean '{close[0]}'?" if close else ""


def display_path(path: Path | str) -> str:
    return str(path)
