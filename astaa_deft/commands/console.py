"""Terminal output and Ctrl-C handling shared by the long-running commands."""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable

from ..errors import InputError
from ..log import records as rec


class StopSignal:
    """Turn SIGINT/SIGTERM into an Event so the main thread shuts down cleanly."""

    def __init__(self) -> None:
        self.received: str | None = None
        self._old: dict = {}

    def __enter__(self) -> StopSignal:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, _frame) -> None:
        # Only a plain assignment here: a handler that takes a lock (Event.set) can
        # deadlock against the main thread it interrupted.
        self.received = signal.Signals(signum).name

    def requested(self) -> bool:
        return self.received is not None

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def parse_params(items: Iterable[str]) -> dict[str, str]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(f"--param '{item}': write it as KEY=VALUE")
        out[key] = value
    return out


class StatusLine:
    """A one-line live status on a terminal; silent when output is not a terminal."""

    def __init__(self, render: Callable[[], str], period: float = 1.0, stream=sys.stderr):
        self.render = render
        self.period = period
        self.stream = stream
        self.enabled = stream.isatty()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> StatusLine:
        if self.enabled and not self._thread.is_alive():
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.stream.write("\r\033[K" + self.render())
            self.stream.flush()

    def clear(self) -> None:
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
            self.clear()


class RateMeter:
    """Messages per second per channel between two calls."""

    def __init__(self, counts: Callable[[], dict[str, int]]):
        self.counts = counts
        self._last = counts()
        self._last_t = time.monotonic()

    def rates(self) -> dict[str, float]:
        now, t = self.counts(), time.monotonic()
        dt = max(t - self._last_t, 1e-6)
        out = {k: (v - self._last.get(k, 0)) / dt for k, v in now.items()}
        self._last, self._last_t = now, t
        return out


def say(message: str) -> None:
    print(message, flush=True)


def format_event(record: rec.Record) -> str | None:
    """One event as the console shows it (None: not shown)."""
    if isinstance(record, rec.ProcessExitRecord):
        if record.during_shutdown:
            return None
        text = f"!! {record.describe()}"
        tail = record.stderr_tail.strip().splitlines()
        if tail:
            text += "\n   " + "\n   ".join(tail[-5:])
        return text
    if isinstance(record, rec.ViolationRecord):
        from ..monitor.violation import Violation, format_violation

        return format_violation(Violation.from_json(rec.encode(record)))
    if isinstance(record, rec.MutationRecord):
        fields = ", ".join(f"{c.path}: {_short(c.old)} → {_short(c.new)}" for c in record.fields)
        index = f" #{record.message_index}" if record.message_index is not None else ""
        return (f"~~ {record.action} on '{record.channel}'{index} (policy {record.policy})"
                + (f": {fields}" if fields else ""))
    if isinstance(record, rec.UndeclaredKey):
        return f"-- undeclared key '{record.key}' from '{record.module}': {record.note}"
    return None


def _short(value, limit: int = 40) -> str:
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"
