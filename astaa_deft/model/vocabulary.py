"""The base of every closed vocabulary the tool writes as text (modes, kinds, statuses, verdicts).

A member *is* its text: it equals the string, and ``str()``, f-strings,
``json.dumps`` and SQLite write the plain value — so a journal, a log, a
report and a spec read the same whether a value came from an enum or from
text. (A bare ``class X(str, Enum)`` would print ``X.MEMBER`` in f-strings
on Python 3.11; hence the two overrides.)
"""

from __future__ import annotations

from enum import Enum


class TextEnum(str, Enum):
    """A vocabulary whose members compare, print and serialise as their text value."""

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)
