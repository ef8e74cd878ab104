"""Regular expressions a user supplies (a spec's ``pattern:``, ``ready.log``, a log's embedded spec): RE2.

A pattern is data, and so is the log a spec travels in: whoever wrote it must
not be able to hang the tool. Python's ``re`` backtracks — ``(a+)+$`` against
5,000 ``a`` and a ``!`` runs for hours, inside one C call that holds the
interpreter, so not even SIGTERM's handler runs. RE2 (``google-re2``) matches
in time linear in the text whatever the pattern, and bounds the memory a
pattern may compile to. What it gives up — lookarounds (``(?=``, ``(?!``,
``(?<=``, ``(?<!``), backreferences (``\\1``), possessive and atomic groups —
is a clear input error naming the fix, never a silent fallback to ``re``.
``\\b`` and ``\\w`` are ASCII in RE2; ``\\Z`` is spelled ``\\z``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import re2

from astaa_deft.model.errors import AstaaDeftError

MAX_PATTERN = 1000  # characters: a pattern is a short regex, not a document
MAX_PROGRAM_BYTES = 8 << 20  # what one compiled pattern may take (RE2's own default)


class Match(Protocol):
    """A match found by RE2 (``re2._Match``): a group's text (None if the group took no part), its span."""

    def group(self, index: int | str = 0, /) -> str | None: ...  # pragma: no cover - a protocol

    def span(self, index: int | str = 0) -> tuple[int, int]: ...  # pragma: no cover - a protocol


class CompiledPattern(Protocol):
    """A pattern as RE2 compiled it (``re2._Regexp``; the binding ships no types)."""

    def search(self, text: str) -> Match | None: ...  # pragma: no cover - a protocol


class PatternError(AstaaDeftError):
    """A user pattern that cannot run: ``reason`` (what is wrong) and ``fix`` (what to write instead). The
    reader of the spec turns it into an InputError at the pattern's place."""

    def __init__(self, reason: str, fix: str) -> None:
        super().__init__(reason)
        self.reason = reason
        self.fix = fix


def _options() -> Any:
    options = re2.Options()
    options.log_errors = False  # the error comes back to us, as one input error; RE2 would print it too
    options.max_mem = MAX_PROGRAM_BYTES
    return options


_OPTIONS = _options()


@dataclass(frozen=True)
class UserPattern:
    """A compiled user pattern: ``search`` finds it anywhere in a text, in linear time."""

    pattern: str  # as written
    _regexp: CompiledPattern = field(repr=False, compare=False)

    def search(self, text: str) -> Match | None:
        return self._regexp.search(text)

    def __reduce__(self) -> tuple[Callable[[str], UserPattern], tuple[str]]:  # compiled again where it is unpickled
        return compile_user_pattern, (self.pattern,)


def compile_user_pattern(text: str, limit: int = MAX_PATTERN) -> UserPattern:
    """``text`` compiled by RE2; PatternError (what is wrong, the fix) for a pattern it cannot run."""
    if len(text) > limit:
        raise PatternError(f"is {len(text)} characters long", f"keep it under {limit}")
    try:
        return UserPattern(text, re2.compile(text, options=_OPTIONS))
    except re2.error as exc:
        raise PatternError(*_explain(exc)) from None
    except (TypeError, ValueError) as exc:  # e.g. a NUL the wrapper refuses
        raise PatternError(f"is not a regular expression: {exc}", "write it as plain text") from None


def _explain(exc: Exception) -> tuple[str, str]:
    """What RE2 said, as (reason, fix) a user can act on."""
    said = exc.args[0] if exc.args else str(exc)
    message = said.decode("utf-8", "replace") if isinstance(said, bytes) else str(said)
    reason = f"is not a regular expression the tool runs: {message}"
    if "(?=" in message or "(?!" in message or "(?<" in message:
        return reason, ("lookarounds are not supported (patterns run in linear time, RE2): match the text itself,"
                        " e.g. 'ERROR(?!S)' → 'ERROR\\b'")
    if "\\Z" in message:
        return reason, "write '\\z' (end of text) or '$'"
    if any(f"\\{d}" in message for d in "123456789"):
        return reason, "backreferences are not supported (patterns run in linear time, RE2): spell the text out"
    if "pattern too large" in message:
        return reason, "write a shorter pattern (fewer or smaller repetitions)"
    if "repetition" in message:
        return reason, "repetition counts go up to 1000, e.g. 'a{1,1000}'"
    return reason, "escape special characters with a backslash, e.g. 'ValueError\\('"
