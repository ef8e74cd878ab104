"""User-facing errors: each names the file, the place and the fix.

The CLI prints these without a traceback and exits 2; anything else escaping
is a bug in the tool.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable


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
        text = f"{where}: {self.message}"
        if self.fix:
            text += f" — {self.fix}"
        return text


class InputError(Exception):
    """Bad user input (a spec, a policy, a dictionary, a log, a path): exit code 2."""

    def __init__(self, problems: Iterable[Problem] | Problem | str):
        if isinstance(problems, (Problem, str)):
            problems = [problems]
        self.problems = [p if isinstance(p, Problem) else Problem("", None, None, p) for p in problems]
        super().__init__("\n".join(map(str, self.problems)))


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    choices = list(choices)
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if not close:  # 'sequence' for 'seq', 'readiness' for 'ready'
        close = [c for c in choices if len(c) >= 3 and (word.startswith(c[:4]) or c.startswith(word[:4]))][:1]
    return f"did you mean '{close[0]}'?" if close else ""


def display_path(path: Path | str) -> str:
    return str(path)
